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
//! **Recovering a stopped job.** A wire stands in the kerf it cut, and the only way back into
//! the work is that kerf. The operator says where the wire stands ([`WireAt`]); where a job
//! of the same program stopped, the daemon knows the kerf ends there ([`ApproachPlan::kerf_end`]):
//!
//! ```text
//!  WireAt::StartHole  start hole ══ kerf, spark off ══► N ─ cut ─►      (N before the stop)
//!  WireAt::Stopped    N ◄══ kerf run backwards, spark off ══ stop;  N ─ cut ─► stop ─ cut ─►
//! ```
//!
//! From the start hole the path approach runs the kerf forward, so line N must start at or
//! before where the job stopped: past it the path crosses uncut material, and the run is
//! refused ([`FromLineError::PastTheStop`]). From where it stopped the wire runs the kerf
//! backwards: the blocks from N's start to the stop are held until the one the wire stands
//! on is met, then handed on reversed and spark off (the block in hand only up to where the
//! wire stands), then forward as the cut. A wire that stands on no block from N on is
//! refused ([`FromLineError::WireOffPath`]): the way back is not a kerf the program cut.
//!
//! Every approach is a pure function of the program, the line, the job's start and where
//! the kerf ends, so a checkpoint that records them resumes into the very same block
//! sequence (and an approach it interrupted goes on as an approach, never as a cut).

use serde::{Deserialize, Serialize};

use std::collections::VecDeque;

pub use super::approach::{ON_PATH_MM, locate, path_approach};
use super::approach::{direct_approach, retrace};
use super::{Stage, StageError};
use crate::gcode::{Block, BlockKind, WorkStart};
use crate::geometry::Point;
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
    /// Where the wire stands as the run starts (the operator confirms it).
    #[serde(default)]
    pub wire_at: WireAt,
}

/// Where the wire stands when a run from a line starts: what the operator confirms.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum WireAt {
    /// At the program's start hole (where the job starts): the approach runs the path
    /// forward from there.
    #[default]
    StartHole,
    /// Where a stopped job of the same program stopped, in its kerf: the approach runs the
    /// kerf backwards to the line.
    Stopped,
}

impl WireAt {
    pub const ALL: [WireAt; 2] = [WireAt::StartHole, WireAt::Stopped];

    pub fn name(self) -> &'static str {
        match self {
            WireAt::StartHole => "start-hole",
            WireAt::Stopped => "stopped",
        }
    }

    pub fn parse(text: &str) -> Option<WireAt> {
        WireAt::ALL.into_iter().find(|w| w.name() == text)
    }
}

impl FromLine {
    /// How the machine gets there, as the operator is told: "the path approach from the
    /// start hole", "back along the kerf from where the job stopped", "the direct approach".
    pub fn approach_text(&self) -> &'static str {
        match (self.approach, self.wire_at) {
            (Approach::Direct, _) => "the direct approach",
            (Approach::Path, WireAt::StartHole) => "the path approach from the start hole",
            (Approach::Path, WireAt::Stopped) => "back along the kerf from where the job stopped",
        }
    }

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
    #[error(
        "{program}:{line}:1: line {line} starts past where the job stopped (line \
         {stopped_line}, {stopped_at}): the material between is uncut and the wire cannot \
         cross it; run from line {stopped_line} or before, or `resume` the stopped job"
    )]
    PastTheStop {
        program: String,
        line: u64,
        stopped_line: u64,
        /// Where it stopped, in the work system the job starts in.
        stopped_at: String,
    },
    #[error(
        "{program}:{line}:1: the wire stands at {at}, on no move of the path from line {line} \
         on (within {ON_PATH_MM} mm): the way back to the line is not a kerf the program cut. \
         Run from a line the job cut before it stopped, in the pass it stopped in; or bring \
         the wire to the start hole along the kerf and say so (--wire-at start-hole)"
    )]
    WireOffPath {
        program: String,
        line: u64,
        /// Where the wire stands, in the work system the job starts in.
        at: String,
    },
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

/// What the approach needs besides the program: where the machine stands as the job starts
/// (machine mm), the machine's axes, the safe height a direct approach crosses at, the
/// approach's feed, and where a stopped job's kerf ends.
#[derive(Debug, Clone, PartialEq)]
pub struct ApproachPlan {
    pub origin: Point,
    pub axes: Vec<Axis>,
    pub safe_z_mm: Option<f64>,
    pub feed_mm_per_min: f64,
    /// Where a stopped job of this program stopped (machine mm): the kerf it cut ends there.
    /// `None`: no such job is known (the approach trusts the operator).
    pub kerf_end: Option<Point>,
    /// The job's start, to say points in the work system the program is written in.
    pub work: WorkStart,
}

impl ApproachPlan {
    /// `X1.2000 Y-3.0000 (G54)`: a machine point as the program's work system has it.
    fn work_text(&self, at: &Point) -> String {
        self.work.text_of(at, &self.axes)
    }
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
    /// The line of a move before the line that the kerf ends inside: the line starts past
    /// the stop.
    stopped_before: Option<u64>,
    /// From where it stopped: the cut's blocks from the line's start, held until the one the
    /// wire stands on (`None` once met).
    held: Option<Vec<Block>>,
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
            stopped_before: None,
            held: None,
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
            self.note_stop_before(block);
            return Ok(Route::Before);
        }
        // The program's first move starts the program: from line 1, whatever the entry.
        if entry && self.skipped_any {
            // Refused once the next block names the first line that can be run from.
            self.entry_refused = Some(block.line);
            return Ok(Route::Before);
        }
        if let (Some(stopped_line), Some(end)) = (self.stopped_before, &self.approach.kerf_end) {
            return Err(FromLineError::PastTheStop {
                program: self.program.clone(),
                line: self.from.line,
                stopped_line,
                stopped_at: self.approach.work_text(end),
            });
        }
        self.reached = true;
        Ok(Route::First)
    }

    /// A move before the line: the kerf ending inside it (short of its end) means the line
    /// starts where nothing was cut. The first such move counts.
    fn note_stop_before(&mut self, block: &Block) {
        let Some(end) = &self.approach.kerf_end else {
            return;
        };
        if self.stopped_before.is_none()
            && locate(&block.curve, end).is_some()
            && (block.end() - end).norm() > ON_PATH_MM
        {
            self.stopped_before = Some(block.line);
        }
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
        if !self.reached {
            return Err(FromLineError::NoMove {
                program: self.program.clone(),
                line: self.from.line,
            });
        }
        if self.held.is_some() {
            return Err(FromLineError::WireOffPath {
                program: self.program.clone(),
                line: self.from.line,
                at: self.approach.work_text(&self.approach.origin),
            });
        }
        Ok(())
    }

    /// From where it stopped: holds `block`, a block of the cut, until the wire stands on
    /// one; then hands on the way back (the held blocks reversed, spark off) and the held
    /// blocks as cut.
    fn hold(&mut self, block: Block, out: &mut VecDeque<Block>) {
        let held = self.held.get_or_insert_with(Vec::new);
        let on = locate(&block.curve, &self.approach.origin);
        held.push(block);
        let Some(u) = on else {
            return;
        };
        let held = self.held.take().expect("held");
        let back = retrace(&held, u, self.approach.feed_mm_per_min);
        self.skipped_mm -= back.iter().map(|b| b.curve.length()).sum::<f64>();
        out.extend(back);
        out.extend(held);
    }
}

impl Stage for Gate {
    fn push(&mut self, block: Block, out: &mut VecDeque<Block>) -> Result<(), StageError> {
        let feed = self.approach.feed_mm_per_min;
        let route = self.admit(&block)?;
        if self.from.wire_at == WireAt::Stopped {
            match route {
                Route::Before => self.skipped_mm += block.curve.length(),
                Route::First => self.hold(block, out),
                Route::Cut if self.held.is_some() => self.hold(block, out),
                Route::Cut => out.push_back(block),
            }
            return Ok(());
        }
        let direct = self.from.approach == Approach::Direct;
        match (route, direct) {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gcode::Travel;
    use crate::geometry::NurbsCurve;

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
            kerf_end: None,
            work: WorkStart::default(),
        }
    }

    /// A die from the start hole at the origin: line 3 the entry to (0,-2), then round the
    /// 4 mm square (lines 4 to 8) and back out (line 9).
    fn die() -> Vec<Block> {
        let corners = [
            [0.0, 0.0],
            [0.0, -2.0],
            [2.0, -2.0],
            [2.0, 2.0],
            [-2.0, 2.0],
            [-2.0, -2.0],
            [0.0, -2.0],
            [0.0, 0.0],
        ];
        corners
            .windows(2)
            .zip(3..)
            .map(|(w, n)| {
                line(
                    n,
                    [w[0][0], w[0][1], 0.0],
                    [w[1][0], w[1][1], 0.0],
                    BlockKind::Line,
                )
            })
            .collect()
    }

    fn at(x: f64, y: f64) -> Point {
        Point::from_fn(|i, _| [x, y].get(i).copied().unwrap_or(0.0))
    }

    /// The die through a gate from `line`, the wire at `wire_at`, the kerf ending at `end`.
    fn through(line: u64, wire_at: WireAt, end: Point) -> Result<(Vec<Block>, f64), String> {
        let from = FromLine {
            line,
            approach: Approach::Path,
            pass: None,
            wire_at,
        };
        let origin = match wire_at {
            WireAt::StartHole => Point::zeros(),
            WireAt::Stopped => end,
        };
        let approach = ApproachPlan {
            origin,
            kerf_end: Some(end),
            ..plan()
        };
        let mut gate = Gate::new(from, "die.ngc", approach);
        let mut out = VecDeque::new();
        let said = |e: StageError| match e {
            StageError::Job(e) => e.to_string(),
            other => format!("{other:?}"),
        };
        for block in die() {
            gate.push(block, &mut out).map_err(said)?;
        }
        gate.finish(&mut out).map_err(said)?;
        Ok((out.into(), gate.take_skipped_mm()))
    }

    fn ends(blocks: &[Block]) -> Vec<[f64; 2]> {
        blocks.iter().map(|b| [b.end()[0], b.end()[1]]).collect()
    }

    #[test]
    fn from_where_it_stopped_the_wire_goes_back_along_the_kerf_then_cuts_on() {
        // Stopped at (2, 1), part-way up line 5; run from line 4.
        let (out, skipped) = through(4, WireAt::Stopped, at(2.0, 1.0)).unwrap();
        let back: Vec<&Block> = out.iter().take_while(|b| b.spark_off.is_some()).collect();
        assert_eq!(back.len(), 2, "{:?}", ends(&out));
        assert!(
            (back[0].start() - at(2.0, 1.0)).norm() < 1e-9,
            "from where it stands"
        );
        assert_eq!(ends(&out[..2]), vec![[2.0, -2.0], [0.0, -2.0]]);
        assert!(back.iter().all(|b| b.spark_off == Some(Travel::Kerf)));
        assert_eq!((back[0].line, back[1].line), (5, 4));
        // Then the cut from line 4's start, all of it, sparking.
        let cut = &out[2..];
        assert_eq!(
            cut.iter().map(|b| b.line).collect::<Vec<_>>(),
            [4, 5, 6, 7, 8, 9]
        );
        assert!(cut.iter().all(|b| b.spark_off.is_none()));
        // The entry (2 mm) was left out, the way back (3 + 2 mm) added.
        assert!((skipped - (2.0 - 5.0)).abs() < 1e-6, "{skipped}");

        // Where it stands on line 4's start: no way back at all.
        let (out, _) = through(4, WireAt::Stopped, at(0.0, -2.0)).unwrap();
        assert_eq!(out[0].line, 4);
        assert!(out[0].spark_off.is_none());
    }

    #[test]
    fn a_line_past_the_stop_and_a_wire_off_the_path_are_refused() {
        // From the start hole the kerf runs forward to (2, 1) on line 5: line 5 is fine...
        let (out, _) = through(5, WireAt::StartHole, at(2.0, 1.0)).unwrap();
        assert_eq!(ends(&out[..2]), vec![[0.0, -2.0], [2.0, -2.0]]);
        // ...line 6 starts past the stop, whichever way the wire comes.
        for wire_at in WireAt::ALL {
            let e = through(6, wire_at, at(2.0, 1.0)).unwrap_err();
            assert!(
                e.starts_with(
                    "die.ngc:6:1: line 6 starts past where the job stopped (line 5, \
                               X2.0000 Y1.0000 Z0.0000 (G54))"
                ),
                "{e}"
            );
        }
        // A wire that stands on no move from the line on: refused at the end.
        let e = through(4, WireAt::Stopped, at(1.0, 1.0)).unwrap_err();
        assert!(
            e.starts_with(
                "die.ngc:4:1: the wire stands at X1.0000 Y1.0000 Z0.0000 (G54), on no move"
            ),
            "{e}"
        );
        // Within the tolerance of the path it is on it; beyond it, not.
        assert!(locate(&die()[2].curve, &at(2.0 + 0.9 * ON_PATH_MM, 1.0)).is_some());
        assert!(locate(&die()[2].curve, &at(2.0 + 1.5 * ON_PATH_MM, 1.0)).is_none());
    }

    /// A run from line 5 of `p.ngc` by the path.
    fn gate_at_5() -> Gate {
        let from = FromLine {
            pass: None,
            line: 5,
            approach: Approach::Path,
            wire_at: WireAt::StartHole,
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
