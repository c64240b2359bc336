//! Running a program from a line: what the interpreter replays, and how the machine gets to
//! the line's start.
//!
//! The program is always interpreted from its first line, so everything a line depends on
//! (modal state, parameters, work offsets, the wire offset, the condition, the subroutine and
//! loop context) is exactly what a full run has there. The blocks before line N are then
//! either moved with the spark off or dropped, depending on the approach:
//!
//! ```text
//!  Approach::Path    start ══ prefix blocks, spark off, at the approach feed ══► N ─ cut ─►
//!  Approach::Direct  start ─► up to safe Z ─► across at safe Z ─► down ────────► N ─ cut ─►
//!                    (without Z or safe_z_mm: one straight move, spark off)
//! ```
//!
//! `Path` is the wire machine's way: the wire cannot cross uncut material, so it retraces the
//! programmed path from the start hole. `Direct` is the sinker's: the electrode lifts out of
//! the cavity, moves over the work and plunges back down the hole it burned.
//!
//! The cut starts at the first block, in execution order, whose source line is N or later
//! (a line that moves nothing starts at the next move; a NURBS curve is one block, so a line
//! inside one starts at the next block). Refused, at check time, with the line: a probing
//! move before N (where it stops decides everything after it), the wire offset's entry move
//! as the first block after moves skipped (its start is not on the offset path; the refusal
//! names the first line after it that can be run from), and no move at or after N. An entry
//! that is the program's first move starts the program itself: CAM posts write `G41 D1` on
//! the first move, and a line at or before it runs the whole program.
//!
//! Both approaches are a pure function of the program, the line and the job's start, so a
//! checkpoint that records the line and the approach resumes into the very same block
//! sequence (and an approach it interrupted goes on as an approach, never as a cut).

use serde::{Deserialize, Serialize};

use std::collections::VecDeque;

use super::{Stage, StageError};
use crate::gcode::{Block, BlockKind, Travel};
use crate::geometry::{NurbsCurve, Point};
use crate::vocab::Axis;

/// Where a job run from a line starts cutting, and how the machine gets there.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FromLine {
    /// The source line (1-based) the cut starts at.
    pub line: u64,
    pub approach: Approach,
    /// In a job in passes, the pass (from 1) the line is cut in: that pass from the line,
    /// then every later pass whole. `None` without passes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pass: Option<u8>,
}

impl FromLine {
    /// Where the cut starts, as the operator is told: "line 8", "line 8 in pass 2".
    pub fn text(&self) -> String {
        match self.pass {
            Some(pass) => format!("line {} in pass {pass}", self.line),
            None => format!("line {}", self.line),
        }
    }
}

/// How the machine reaches the start of the line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Approach {
    /// Along the programmed path from the program's start, spark off.
    Path,
    /// Retract to `machine.safe_z_mm`, move across, plunge; one straight move without Z.
    Direct,
}

impl Approach {
    pub const ALL: [Approach; 2] = [Approach::Path, Approach::Direct];

    pub fn name(self) -> &'static str {
        match self {
            Approach::Path => "path",
            Approach::Direct => "direct",
        }
    }

    /// The machine's usual approach: `Direct` where a safe Z is set (a sinker), `Path`
    /// otherwise (a wire machine).
    pub fn default_for(safe_z_mm: Option<f64>) -> Approach {
        match safe_z_mm {
            Some(_) => Approach::Direct,
            None => Approach::Path,
        }
    }

    pub fn parse(text: &str) -> Option<Approach> {
        Approach::ALL.into_iter().find(|a| a.name() == text)
    }
}

/// Why a program cannot be run from the line asked for.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FromLineError {
    #[error(
        "{program}:{probe_line}:1: the program probes here, before line {line}: where the probe \
         stops decides what follows, so it cannot be skipped; run the program from its start"
    )]
    ProbeBefore {
        program: String,
        probe_line: u64,
        line: u64,
    },
    #[error(
        "{program}:{line}:1: this is the wire offset's entry move (the first move after \
         G41/G42): its start is not on the offset path; run from {} or later, or from a \
         line before the G41/G42",
        next.map_or("the line after it".to_string(), |n| format!("line {n}"))
    )]
    CompEntry {
        program: String,
        line: u64,
        /// The line of the first move after the entry: the first that can be run from.
        next: Option<u64>,
    },
    #[error("{program}:{line}:1: no move at or after line {line} to start from")]
    NoMove { program: String, line: u64 },
}

/// What to do with a block of a job run from a line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Route {
    /// Before the line: part of the approach (moved spark off, or dropped).
    Before,
    /// The first block of the cut: the approach ends at its start.
    First,
    /// After it: cut as programmed.
    Cut,
}

/// What the approach needs besides the program: where the job starts (machine mm), the
/// machine's axes, the safe height a direct approach crosses at, and the approach's feed.
#[derive(Debug, Clone, PartialEq)]
pub struct ApproachPlan {
    pub origin: Point,
    pub axes: Vec<Axis>,
    pub safe_z_mm: Option<f64>,
    pub feed_mm_per_min: f64,
}

/// The run-from-line stage: sorts a program's blocks, in execution order, into before and
/// after the line, and moves (or drops) the ones before as the approach says.
#[derive(Debug, Clone)]
pub struct Gate {
    from: FromLine,
    program: String,
    reached: bool,
    /// The block before carried a wire offset (the next one with one is no entry).
    offset_on: bool,
    /// Some block went before the line (an approach exists).
    skipped_any: bool,
    /// The line asked for fell on an entry move: refused, naming the next block's line.
    entry_refused: Option<u64>,
    approach: ApproachPlan,
    /// Path the approach left out and not yet told (mm; the direct approach's own moves
    /// count against it): progress and placed debris stay where a full run has them.
    skipped_mm: f64,
}

impl Gate {
    pub fn new(from: FromLine, program: &str, approach: ApproachPlan) -> Gate {
        Gate {
            from,
            program: program.to_string(),
            reached: false,
            offset_on: false,
            skipped_any: false,
            entry_refused: None,
            approach,
            skipped_mm: 0.0,
        }
    }

    /// The path left out since last asked, mm (negative where the approach added more).
    pub fn take_skipped_mm(&mut self) -> f64 {
        std::mem::take(&mut self.skipped_mm)
    }

    /// Routes the next block, in execution order.
    pub fn admit(&mut self, block: &Block) -> Result<Route, FromLineError> {
        let entry = block.wire_offset.is_some() && !self.offset_on;
        self.offset_on = block.wire_offset.is_some();
        if let Some(line) = self.entry_refused {
            return Err(FromLineError::CompEntry {
                program: self.program.clone(),
                line,
                next: Some(block.line),
            });
        }
        if self.reached {
            return Ok(Route::Cut);
        }
        if block.line < self.from.line {
            if matches!(block.kind, BlockKind::Probe(_)) {
                return Err(FromLineError::ProbeBefore {
                    program: self.program.clone(),
                    probe_line: block.line,
                    line: self.from.line,
                });
            }
            self.skipped_any = true;
            return Ok(Route::Before);
        }
        // The program's first move starts the program: from line 1, whatever the entry.
        if entry && self.skipped_any {
            // Refused once the next block names the first line that can be run from.
            self.entry_refused = Some(block.line);
            return Ok(Route::Before);
        }
        self.reached = true;
        Ok(Route::First)
    }

    /// At the program's end: the line was reached.
    pub fn finished(&self) -> Result<(), FromLineError> {
        if let Some(line) = self.entry_refused {
            return Err(FromLineError::CompEntry {
                program: self.program.clone(),
                line,
                next: None,
            });
        }
        if self.reached {
            Ok(())
        } else {
            Err(FromLineError::NoMove {
                program: self.program.clone(),
                line: self.from.line,
            })
        }
    }
}

impl Stage for Gate {
    fn push(&mut self, block: Block, out: &mut VecDeque<Block>) -> Result<(), StageError> {
        let direct = self.from.approach == Approach::Direct;
        let feed = self.approach.feed_mm_per_min;
        match (self.admit(&block)?, direct) {
            (Route::Cut, _) | (Route::First, false) => out.push_back(block),
            (Route::Before, true) => self.skipped_mm += block.curve.length(),
            (Route::Before, false) => out.push_back(path_approach(block, feed)),
            (Route::First, true) => {
                let a = &self.approach;
                let moves = direct_approach(&a.origin, &block, &a.axes, a.safe_z_mm, feed);
                self.skipped_mm -= moves.iter().map(|b| b.curve.length()).sum::<f64>();
                out.extend(moves);
                out.push_back(block);
            }
        }
        Ok(())
    }

    fn finish(&mut self, _: &mut VecDeque<Block>) -> Result<(), StageError> {
        Ok(self.finished()?)
    }
}

/// A block before the line as the path approach moves it: the same geometry, spark off, at
/// most `feed_mm_per_min` (a rapid too: the wire is in the work).
pub fn path_approach(mut block: Block, feed_mm_per_min: f64) -> Block {
    if block.kind == BlockKind::Rapid {
        block.kind = BlockKind::Line;
    }
    block.feed_mm_per_min = Some(
        block
            .feed_mm_per_min
            .map_or(feed_mm_per_min, |f| f.min(feed_mm_per_min)),
    );
    block.spark_off = Some(Travel::Kerf);
    block.pause = None;
    block.dwell_s = 0.0;
    block
}

/// The direct approach from `origin` to the start of `first` (machine mm): up to `safe_z`
/// (if the machine has Z and it is set, and Z stands below it) and across as rapids, then
/// down to the start at `feed_mm_per_min`; without a safe height, one straight move at that
/// feed. Every move has the spark off and carries `first`'s line and condition.
fn direct_approach(
    origin: &Point,
    first: &Block,
    axes: &[Axis],
    safe_z: Option<f64>,
    feed_mm_per_min: f64,
) -> Vec<Block> {
    let target = first.start();
    let dim = axes.len();
    let z = axes.iter().position(|&a| a == Axis::Z);
    let mut corners = vec![*origin];
    let mut rapid_legs = 0;
    if let (Some(z), Some(safe)) = (z, safe_z) {
        let high = origin[z].max(safe).max(target[z]);
        let mut up = *origin;
        up[z] = high;
        let mut across = target;
        across[z] = high;
        corners.push(up);
        corners.push(across);
        rapid_legs = 2;
    }
    corners.push(target);
    let mut moves = Vec::new();
    for (leg, pair) in corners.windows(2).enumerate() {
        let (a, b) = (pair[0], pair[1]);
        if (0..dim).all(|i| (a[i] - b[i]).abs() < 1e-9) {
            continue;
        }
        let Ok(curve) = NurbsCurve::line(dim, &a, &b) else {
            continue;
        };
        let (kind, feed) = if leg < rapid_legs {
            (BlockKind::Rapid, None)
        } else {
            (BlockKind::Line, Some(feed_mm_per_min))
        };
        let mut block = Block::new(first.line, kind, curve, feed);
        block.spark_off = Some(Travel::Open);
        block.condition = first.condition;
        moves.push(block);
    }
    moves
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(n: u64, a: [f64; 3], b: [f64; 3], kind: BlockKind) -> Block {
        let p = |v: [f64; 3]| Point::from_fn(|i, _| v.get(i).copied().unwrap_or(0.0));
        Block::new(
            n,
            kind,
            NurbsCurve::line(3, &p(a), &p(b)).unwrap(),
            Some(100.0),
        )
    }

    fn plan() -> ApproachPlan {
        ApproachPlan {
            origin: Point::zeros(),
            axes: vec![Axis::X, Axis::Y, Axis::Z],
            safe_z_mm: None,
            feed_mm_per_min: 60.0,
        }
    }

    /// A run from line 5 of `p.ngc` by the path.
    fn gate_at_5() -> Gate {
        let from = FromLine {
            pass: None,
            line: 5,
            approach: Approach::Path,
        };
        Gate::new(from, "p.ngc", plan())
    }

    #[test]
    fn the_gate_routes_by_line_and_refuses_a_probe_before_it() {
        let mut gate = gate_at_5();
        let b = line(3, [0.0; 3], [1.0, 0.0, 0.0], BlockKind::Line);
        assert_eq!(gate.admit(&b), Ok(Route::Before));
        assert!(gate.finished().is_err());
        let b = line(7, [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], BlockKind::Line);
        assert_eq!(gate.admit(&b), Ok(Route::First));
        let b = line(2, [2.0, 0.0, 0.0], [3.0, 0.0, 0.0], BlockKind::Line);
        assert_eq!(
            gate.admit(&b),
            Ok(Route::Cut),
            "after the line, lines may run back"
        );
        assert!(gate.finished().is_ok());

        let mut gate = gate_at_5();
        let probe = BlockKind::Probe(crate::gcode::Probe {
            away: false,
            must_touch: true,
        });
        let e = gate
            .admit(&line(4, [0.0; 3], [0.0, 0.0, -1.0], probe))
            .unwrap_err();
        assert!(
            e.to_string()
                .starts_with("p.ngc:4:1: the program probes here, before line 5"),
            "{e}"
        );
        // The first move carrying a wire offset is its entry: after moves the approach
        // skips, refused, naming the next move's line as the first that can be run from.
        let entry = |n: u64| {
            let mut b = line(n, [0.0; 3], [1.0, 0.0, 0.0], BlockKind::Line);
            b.wire_offset = Some(crate::gcode::WireOffset {
                left: true,
                d_mm: 0.1,
            });
            b
        };
        let mut gate = gate_at_5();
        assert_eq!(
            gate.admit(&line(3, [0.0; 3], [0.0, 1.0, 0.0], BlockKind::Line)),
            Ok(Route::Before)
        );
        assert_eq!(gate.admit(&entry(5)), Ok(Route::Before));
        let e = gate.admit(&entry(7)).unwrap_err();
        assert!(
            e.to_string()
                .contains("p.ngc:5:1: this is the wire offset's entry move")
                && e.to_string().contains("run from line 7 or later"),
            "{e}"
        );
        // As the program's first move, it starts the program.
        let mut gate = gate_at_5();
        assert_eq!(gate.admit(&entry(5)), Ok(Route::First));
        assert!(gate.finished().is_ok());
    }

    #[test]
    fn a_direct_approach_lifts_crosses_and_plunges_and_a_path_one_keeps_the_geometry() {
        let axes = [Axis::X, Axis::Y, Axis::Z];
        let first = line(9, [10.0, 5.0, -2.0], [11.0, 5.0, -2.0], BlockKind::Line);
        let origin = Point::from_fn(|i, _| [0.0, 0.0, -1.0].get(i).copied().unwrap_or(0.0));
        let moves = direct_approach(&origin, &first, &axes, Some(5.0), 300.0);
        let ends: Vec<[f64; 3]> = moves
            .iter()
            .map(|b| [b.end()[0], b.end()[1], b.end()[2]])
            .collect();
        assert_eq!(
            ends,
            vec![[0.0, 0.0, 5.0], [10.0, 5.0, 5.0], [10.0, 5.0, -2.0]]
        );
        assert_eq!(moves[0].kind, BlockKind::Rapid);
        assert_eq!(moves[2].kind, BlockKind::Line);
        assert_eq!(moves[2].feed_mm_per_min, Some(300.0));
        assert!(
            moves
                .iter()
                .all(|b| b.spark_off == Some(Travel::Open) && b.line == 9)
        );
        // No safe height: one straight move.
        let moves = direct_approach(&origin, &first, &axes, None, 300.0);
        assert_eq!(moves.len(), 1);
        assert_eq!(moves[0].kind, BlockKind::Line);

        let rapid = line(2, [0.0; 3], [1.0, 0.0, 0.0], BlockKind::Rapid);
        let moved = path_approach(rapid.clone(), 120.0);
        assert_eq!(moved.kind, BlockKind::Line);
        assert_eq!(moved.curve, rapid.curve);
        assert_eq!(moved.feed_mm_per_min, Some(100.0));
        assert_eq!(moved.spark_off, Some(Travel::Kerf));
        assert_eq!(path_approach(rapid, 60.0).feed_mm_per_min, Some(60.0));
    }
}
