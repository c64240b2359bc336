//! Blocks that make several moves, as LinuxCNC's interpreter makes them
//! (`interp_cycles.cc`, `convert_home`):
//!
//! - the canned cycles `G81`, `G82`, `G83`, `G73` in the XY plane, for EDM hole drilling
//!   and a sinker's pecks: at each hole a rapid over it, a rapid down to the R plane, the
//!   plunge at the feed (under the servo, like any feed move; `G83` and `G73` in pecks of
//!   `Q`), and a rapid out to the R plane (`G99`, the default) or the level the series of
//!   cycles started at (`G98`). `R`, `Z`, `P` and `Q` hold until the mode changes; `L`
//!   repeats a hole (in `G91`, each one `X Y` further);
//! - `G28`/`G30`: a rapid to the block's point, if it names one, then to the position stored
//!   in `#5161`… (`#5181`… for `G30`), machine coordinates, on the named axes (all without
//!   axis words); `G28.1`/`G30.1` store where the machine stands. Only on a homed machine:
//!   elsewhere machine coordinates mean nothing yet.
//!
//! Neither under the wire offset (LinuxCNC refuses both with cutter compensation).

use std::io::{BufRead, Seek};

use super::codes::Cycle;
use super::offsets::param_slot;
use super::{BlockReader, Fail, Letters, Step};
use crate::gcode::error::GcodeErrorKind;
use crate::gcode::expr::ParamRef;
use crate::gcode::lexer::Word;
use crate::gcode::{Block, BlockKind, Plane};
use crate::geometry::{NurbsCurve, Point};
use crate::vocab::Axis;

/// `#5161`: `G28`'s stored position on the first parameter axis (`#5181` for `G30`).
const G28_PARAMS: usize = 5161;
const G30_PARAMS: usize = 5181;
/// How far above the last peck `G83` and `G73` come back down (or back off) at the rapid,
/// mm, unless the block gives `D`: LinuxCNC 2.9's `G83_RAPID_DELTA`, 0.010 inch. (Its later
/// versions default to 1 mm on a mm machine and take `D`, as edmd does.)
const PECK_CLEARANCE_MM: f64 = 0.010 * super::MM_PER_INCH;

/// What the canned cycles keep from block to block.
#[derive(Debug, Clone, Default)]
pub(super) struct CycleState {
    /// `G98`: out to the initial level after a hole; `G99` (false, the default): to R.
    pub retract_to_initial: bool,
    /// The Z (machine, mm) the series of cycles started at; cleared by any other motion.
    pub initial_level: Option<f64>,
    /// The last cycle's `R`, `Z`, `P` and `Q`, as written (program units).
    pub r: f64,
    pub z: f64,
    pub p: f64,
    pub q: f64,
}

impl<R: BufRead + Seek> BlockReader<R> {
    /// A canned cycle's block: its moves, the first returned and the others queued.
    /// `continuing`: the block is in the mode the last one set (its `R`, `Z`, `P`, `Q` hold).
    pub(super) fn cycle_block(
        &mut self,
        cycle: Cycle,
        continuing: bool,
        line_no: u64,
        letters: &Letters,
        col: usize,
    ) -> Step<Option<Block>> {
        let code = cycle.g_code();
        let fail = |col, what: String| Fail::from((col, GcodeErrorKind::Cycle(what)));
        let own: &[char] = match cycle {
            Cycle::Drill => &['R', 'L'],
            Cycle::DwellAtBottom => &['R', 'L', 'P'],
            Cycle::Peck | Cycle::ChipBreak => &['R', 'L', 'Q', 'D'],
        };
        self.check_letters(
            letters,
            true,
            &own.iter().collect::<String>(),
            &format!("with {code}"),
        )?;
        if self.state.modal.wire_offset.engaged() {
            return Err(fail(
                col,
                format!("{code} cannot run with the wire offset on (G40 first)"),
            ));
        }
        if self.state.modal.plane != Plane::XY {
            return Err(fail(
                col,
                format!(
                    "{code} in {}: edmd's canned cycles plunge along Z, in G17",
                    self.state.modal.plane.g_code()
                ),
            ));
        }
        let index = |axis| self.axes.iter().position(|&a| a == axis);
        let (Some(ix), Some(iy), Some(iz)) = (index(Axis::X), index(Axis::Y), index(Axis::Z))
        else {
            return Err(fail(
                col,
                format!(
                    "{code} needs the axes X, Y and Z (machine.axes has {})",
                    self.axes_list()
                ),
            ));
        };
        let s = self.state.scale();
        let word = |letter: char, held: f64, name: &str| -> Step<f64> {
            match letters.get(letter) {
                Some(w) => Ok(w.value),
                None if continuing => Ok(held),
                None => Err(fail(col, format!("{code} needs {letter}, {name}"))),
            }
        };
        let z_word = word('Z', self.state.cycle.z, "the bottom of the hole")?;
        let r_word = word(
            'R',
            self.state.cycle.r,
            "the R plane the plunge starts from",
        )?;
        let p_word = match cycle {
            Cycle::DwellAtBottom => word('P', self.state.cycle.p, "the dwell at the bottom (s)")?,
            _ => self.state.cycle.p,
        };
        let q_word = match cycle {
            Cycle::Peck | Cycle::ChipBreak => {
                let q = word('Q', self.state.cycle.q, "the depth of each peck")?;
                if q <= 0.0 {
                    let at = letters.get('Q').map_or(col, |w| w.col);
                    return Err(fail(at, format!("{code}'s peck Q must be more than 0")));
                }
                q
            }
            _ => self.state.cycle.q,
        };
        if !(0.0..=86_400.0).contains(&p_word) {
            return Err(fail(
                letters.get('P').map_or(col, |w| w.col),
                format!("{code}'s dwell P is 0 to 86400 s"),
            ));
        }
        let repeats = match letters.get('L') {
            Some(l) => super::whole_as(l, 1.0, 1e6, "a cycle's repeat count L")? as u32,
            None => 1,
        };
        let clearance = letters.get('D').map_or(PECK_CLEARANCE_MM, |d| d.value * s);
        let start = self.state.position;
        let offset = self.state.offset();
        let first_level = *self.state.cycle.initial_level.get_or_insert(start[iz]);
        let incremental = self.state.modal.incremental;
        let (r, bottom) = if incremental {
            let r = r_word * s + first_level;
            (r, r + z_word * s)
        } else {
            (r_word * s + offset[iz], z_word * s + offset[iz])
        };
        if r < bottom {
            return Err(fail(
                col,
                format!("{code}: the R plane is below the bottom Z"),
            ));
        }
        let (step_x, step_y) = if incremental {
            (
                letters.get('X').map_or(0.0, |w| w.value * s),
                letters.get('Y').map_or(0.0, |w| w.value * s),
            )
        } else {
            (0.0, 0.0)
        };
        let (mut x, mut y) = if incremental {
            (start[ix], start[iy])
        } else {
            let (target, _) = self.target(&start, letters, "Z")?;
            (target[ix], target[iy])
        };
        let feed = self.feed_limit(col);
        let mut moves = MoveList {
            at: start,
            dwell_s: 0.0,
            blocks: Vec::new(),
            line: line_no,
            axes: self.axes.len(),
        };
        let mut level = first_level;
        if level < r {
            moves.to(col, &[(iz, r)])?;
            level = r;
        }
        let clear = if self.state.cycle.retract_to_initial {
            level
        } else {
            r
        };
        for k in 0..repeats {
            x += step_x;
            y += step_y;
            if k == 0 && moves.at[iz] > r {
                moves.to(col, &[(ix, x), (iy, y)])?;
            } else {
                moves.to(col, &[(ix, x), (iy, y), (iz, clear)])?;
            }
            moves.to(col, &[(iz, r)])?;
            let mut depth = r - q_word * s;
            if matches!(cycle, Cycle::Peck | Cycle::ChipBreak) {
                while depth > bottom {
                    moves.feed_to(col, &[(iz, depth)], feed)?;
                    if cycle == Cycle::Peck {
                        moves.to(col, &[(iz, r)])?;
                    }
                    moves.to(col, &[(iz, depth + clearance)])?;
                    depth -= q_word * s;
                }
            }
            moves.feed_to(col, &[(iz, bottom)], feed)?;
            if cycle == Cycle::DwellAtBottom {
                moves.dwell_s = p_word;
            }
            moves.to(col, &[(iz, clear)])?;
        }
        self.state.cycle.r = r_word;
        self.state.cycle.z = z_word;
        self.state.cycle.p = p_word;
        self.state.cycle.q = q_word;
        self.state.position = moves.at;
        self.emit_all(moves.blocks)
    }

    /// `G28`/`G30` (`g30`), or `G28.1`/`G30.1` (`store`), at `w`.
    pub(super) fn reference_point(
        &mut self,
        g30: bool,
        store: bool,
        w: &Word,
        line_no: u64,
        letters: &Letters,
    ) -> Step<Option<Block>> {
        let code = format!("G{}", w.text);
        let fail = |what: String| Fail::from((w.col, GcodeErrorKind::Cycle(what)));
        if self.state.modal.wire_offset.engaged() {
            return Err(fail(format!(
                "{code} cannot be used with the wire offset on (G40 first)"
            )));
        }
        if self.state.unhomed {
            return Err(fail(format!(
                "{code} goes to a stored machine position: the machine is not homed, so machine \
                 coordinates mean nothing yet (home it first)"
            )));
        }
        let base = if g30 { G30_PARAMS } else { G28_PARAMS };
        let param = |axis: Axis| ParamRef::Numbered(base + param_slot(axis));
        if store {
            self.check_letters(letters, false, "", &format!("with {code}"))?;
            for (i, &axis) in self.axes.iter().enumerate() {
                self.state.params.set(&param(axis), self.state.position[i]);
            }
            return Ok(None);
        }
        self.check_letters(letters, true, "", &format!("with {code}"))?;
        let (via, named) = self.target(&self.state.position, letters, "")?;
        let mut moves = MoveList {
            at: self.state.position,
            dwell_s: 0.0,
            blocks: Vec::new(),
            line: line_no,
            axes: self.axes.len(),
        };
        let all: Vec<usize> = (0..self.axes.len()).collect();
        let axes: Vec<usize> = all
            .into_iter()
            .filter(|&i| !named || letters.get(self.axes[i].letter()).is_some())
            .collect();
        moves.to(
            w.col,
            &axes.iter().map(|&i| (i, via[i])).collect::<Vec<_>>(),
        )?;
        let stored: Vec<(usize, f64)> = axes
            .iter()
            .map(|&i| {
                (
                    i,
                    self.state.params.numbered(base + param_slot(self.axes[i])),
                )
            })
            .collect();
        moves.to(w.col, &stored)?;
        self.state.position = moves.at;
        self.state.cycle.initial_level = None;
        self.emit_all(moves.blocks)
    }

    /// The first of `blocks` (with the dwell and pause waiting for a motion), the others
    /// queued behind it.
    fn emit_all(&mut self, blocks: Vec<Block>) -> Step<Option<Block>> {
        let mut blocks = blocks.into_iter();
        let Some(first) = blocks.next() else {
            return Ok(None);
        };
        let first_block = self.block(first.line, first.kind, first.curve, first.feed_mm_per_min);
        for mut b in blocks {
            b.flushing = first_block.flushing;
            b.condition = first_block.condition;
            self.out.queued.push_back(b);
        }
        Ok(Some(first_block))
    }
}

/// Moves being built from where the last one ended.
struct MoveList {
    at: Point,
    /// A dwell for the next move to wait (`G82`'s at the bottom).
    dwell_s: f64,
    blocks: Vec<Block>,
    line: u64,
    axes: usize,
}

impl MoveList {
    /// A rapid setting the axes `to` (index, mm); a move that goes nowhere is left out.
    fn to(&mut self, col: usize, to: &[(usize, f64)]) -> Step<()> {
        self.straight(col, to, BlockKind::Rapid, None)
    }

    /// A feed move (at `feed`, `None`: no `F` programmed) setting the axes `to`.
    fn feed_to(&mut self, col: usize, to: &[(usize, f64)], feed: Option<f64>) -> Step<()> {
        self.straight(col, to, BlockKind::Line, feed)
    }

    fn straight(
        &mut self,
        col: usize,
        to: &[(usize, f64)],
        kind: BlockKind,
        feed: Option<f64>,
    ) -> Step<()> {
        let mut target = self.at;
        for &(i, v) in to {
            target[i] = v;
        }
        if target == self.at {
            return Ok(());
        }
        let curve = NurbsCurve::line(self.axes, &self.at, &target)
            .map_err(|e| Fail::from((col, e.into())))?;
        let mut block = Block::new(self.line, kind, curve, feed);
        block.dwell_s = std::mem::take(&mut self.dwell_s);
        self.blocks.push(block);
        self.at = target;
        Ok(())
    }
}
