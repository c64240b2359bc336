//! Coordinate offsets, LinuxCNC's way: the nine work systems (`G54`…`G59.3`) and their table
//! (`G10 L2`, `G10 L20`), one move in machine coordinates (`G53`), and the `G92` family.
//!
//! The reader keeps its position in machine coordinates; a program point is that minus the
//! active system's offset (`InterpState::g5x`, loaded when a system is selected, as LinuxCNC
//! loads it) minus the `G92` offset. The table itself lives in the parameters, where LinuxCNC
//! keeps it and where a program reads it: `#5220` the active system, `#5221 + 20·(n − 1) + k`
//! the offset of system `n` on axis `k` (`X Y Z A B C U V W`), `#5210`… the `G92` offset, all
//! in millimetres (the machine's units, LinuxCNC's "user units").
//!
//! Also the moves to and from points the parameters hold: `G28`/`G30` go to the positions
//! stored in `#5161`… and `#5181`… (machine coordinates, on a homed machine only),
//! `G28.1`/`G30.1` store them, and a probing move (`G38.x`, `G31`) leaves its point in
//! `#5061`… (program coordinates).

use std::io::{BufRead, Seek};

use super::codes::OffsetCode;
use super::cycles::MoveList;
use super::{BlockReader, Fail, Letters, Step, whole_as};
use crate::gcode::error::GcodeErrorKind;
use crate::gcode::expr::ParamRef;
use crate::gcode::lexer::Word;
use crate::gcode::work::{StartModes, WorkOffsets, WorkStart, WorkSystem};
use crate::gcode::{Block, BlockKind, Probe};
use crate::geometry::{NurbsCurve, Point};
use crate::vocab::Axis;

/// LinuxCNC's axis order in its parameter blocks (`#5061`…, `#5211`…, `#5221`…).
pub(super) const PARAM_AXES: [char; 9] = ['X', 'Y', 'Z', 'A', 'B', 'C', 'U', 'V', 'W'];

/// `#5210`: the `G92` offset is on; `#5211`… its value per axis.
const G92_ENABLED: usize = 5210;
/// LinuxCNC's probe result: `#5061`… per axis (`X Y Z A B C U V W`), `#5070` success.
const PROBE_PARAMS: usize = 5061;
/// `#5161`: `G28`'s stored position on the first parameter axis (`#5181` for `G30`).
const G28_PARAMS: usize = 5161;
const G30_PARAMS: usize = 5181;

/// `#5220`: the active work system (1 = `G54`).
pub(super) const ACTIVE_SYSTEM: usize = 5220;

/// The slot of `axis` in LinuxCNC's parameter blocks.
pub(super) fn param_slot(axis: Axis) -> usize {
    PARAM_AXES
        .iter()
        .position(|&l| l == axis.letter())
        .expect("every machine axis has a parameter slot")
}

/// The parameter that holds `system`'s offset on the axis in slot `k`.
pub(super) fn table_param(system: WorkSystem, k: usize) -> usize {
    ACTIVE_SYSTEM + 1 + 20 * system.index() + k
}

impl<R: BufRead + Seek> BlockReader<R> {
    /// Starts the program at `start`: the machine position, the work offsets (written to their
    /// parameters) and the active system. Call before the first block is read.
    pub fn start_at(&mut self, start: &WorkStart) {
        self.state.position = start.position_mm;
        for system in WorkSystem::all() {
            let offset = start.offsets.get(system);
            for (i, &axis) in self.axes.iter().enumerate() {
                let p = table_param(system, param_slot(axis));
                self.state.params.set(&ParamRef::Numbered(p), offset[i]);
            }
        }
        self.state.load_system(&self.axes, start.system);
        self.state.unhomed = start.unhomed;
        self.state.modal.inch = start.modes.inch;
        self.state.modal.incremental = start.modes.incremental;
    }

    /// The units and distance mode in force now (for the next MDI line).
    pub fn modes(&self) -> StartModes {
        StartModes {
            inch: self.state.modal.inch,
            incremental: self.state.modal.incremental,
        }
    }

    /// The work offsets as the program has left them (`G10` changes them), mm.
    pub fn work_offsets(&self) -> WorkOffsets {
        let mut table = WorkOffsets::default();
        for system in WorkSystem::all() {
            table.set(system, self.state.table_entry(&self.axes, system));
        }
        table
    }

    /// The active work system.
    pub fn work_system(&self) -> WorkSystem {
        self.state.system
    }
}

impl<R: BufRead + Seek> BlockReader<R> {
    /// The group-0 offset codes: `G10 L2`/`L20` and the `G92` family (LinuxCNC's semantics;
    /// the values also go to their parameters).
    pub(super) fn coordinate_offset(
        &mut self,
        code: OffsetCode,
        w: &Word,
        letters: &Letters,
    ) -> Step<()> {
        if code != OffsetCode::Table && self.state.modal.wire_offset.engaged() {
            // LinuxCNC: "Cannot change axis offsets with cutter radius comp" for G92. It takes
            // G92.1, G92.2 and G92.3 but never tells motion (no SET_G92_OFFSET), so its cut
            // goes on with the old offset: edmd refuses the whole family.
            return Err((
                w.col,
                GcodeErrorKind::WorkOffset(format!(
                    "G{}: the G92 offset cannot change with the wire offset on (G40 first)",
                    w.text
                )),
            )
                .into());
        }
        match code {
            OffsetCode::Table => return self.set_table(w, letters),
            OffsetCode::Set => {
                let mut any = false;
                for (i, axis) in self.axes.iter().enumerate() {
                    if let Some(v) = letters.get(axis.letter()) {
                        self.state.g92[i] = self.state.position[i]
                            - self.state.g5x[i]
                            - v.value * self.state.scale();
                        any = true;
                    }
                }
                if !any {
                    return Err((
                        w.col,
                        GcodeErrorKind::MissingCoordinate {
                            what: "G92 needs the axis words that name the current point".into(),
                        },
                    )
                        .into());
                }
                self.state.saved_g92 = None;
            }
            OffsetCode::Clear => {
                self.state.g92 = Point::zeros();
                self.state.saved_g92 = None;
            }
            OffsetCode::Suspend => {
                self.state.saved_g92 = Some(self.state.g92);
                self.state.g92 = Point::zeros();
            }
            OffsetCode::Restore => {
                if let Some(saved) = self.state.saved_g92.take() {
                    self.state.g92 = saved;
                }
            }
        }
        let on = self.state.g92.iter().any(|&o| o != 0.0);
        self.state
            .params
            .set(&ParamRef::Numbered(G92_ENABLED), if on { 1.0 } else { 0.0 });
        for (i, &axis) in self.axes.iter().enumerate() {
            let p = G92_ENABLED + 1 + param_slot(axis);
            self.state
                .params
                .set(&ParamRef::Numbered(p), self.state.g92[i]);
        }
        Ok(())
    }

    /// `G10 L2 P… X…` sets system `P`'s offset on the named axes; `G10 L20 P… X…` sets it so
    /// that the current point reads the given coordinates in that system. `P0` is the active
    /// system. Axis values are absolute whatever the distance mode (LinuxCNC's rule).
    fn set_table(&mut self, w: &Word, letters: &Letters) -> Step<()> {
        let fail = |col: usize, what: String| Fail::from((col, GcodeErrorKind::WorkOffset(what)));
        let Some(l) = letters.get('L') else {
            return Err(fail(
                w.col,
                "G10 needs L2 (set a work offset) or L20 (set it from the current point)".into(),
            ));
        };
        let relative_to_here = match whole_as(l, 0.0, 99.0, "G10's L")? as u32 {
            2 => false,
            20 => true,
            1 | 10 | 11 => {
                return Err(fail(
                    l.col,
                    format!(
                        "G10 L{}: edmd has no tool table (its offsets are the wire offset's D \
                         registers, compensation.d_mm)",
                        l.text
                    ),
                ));
            }
            _ => {
                return Err(fail(
                    l.col,
                    format!("G10 L{}: edmd knows G10 L2 and G10 L20", l.text),
                ));
            }
        };
        let Some(p) = letters.get('P') else {
            return Err(fail(
                w.col,
                "G10 needs P, the work system (1 = G54 … 9 = G59.3, 0 = the active one)".into(),
            ));
        };
        let n = whole_as(p, 0.0, 9.0, "G10's work system P")? as u8;
        let system = WorkSystem::from_number(n).unwrap_or(self.state.system);
        if let Some(r) = letters.get('R') {
            if r.value != 0.0 {
                return Err(fail(
                    r.col,
                    "G10 R: rotated work systems are not supported (R0 only)".into(),
                ));
            }
            if relative_to_here {
                return Err(fail(r.col, "R is not allowed with G10 L20".into()));
            }
        }
        if self.state.modal.wire_offset.engaged() && system == self.state.system {
            return Err(fail(
                w.col,
                "G10: the active work system cannot change with the wire offset on (G40 first)"
                    .into(),
            ));
        }
        let mut offset = self.state.table_entry(&self.axes, system);
        for (i, axis) in self.axes.iter().enumerate() {
            if let Some(v) = letters.get(axis.letter()) {
                let value = v.value * self.state.scale();
                offset[i] = if relative_to_here {
                    self.state.position[i] - self.state.g92[i] - value
                } else {
                    value
                };
            }
        }
        for (i, &axis) in self.axes.iter().enumerate() {
            let param = table_param(system, param_slot(axis));
            self.state.params.set(&ParamRef::Numbered(param), offset[i]);
        }
        if system == self.state.system {
            self.state.g5x = offset;
        }
        Ok(())
    }

    /// `G53`: this block's move is in machine coordinates. Only with `G0`/`G1`, in `G90`,
    /// without the wire offset (LinuxCNC's three rules).
    pub(super) fn check_machine_move(&self, g53: &Word, straight: bool) -> Step<()> {
        let why = if !straight {
            "G53 needs G0 or G1 (one straight move in machine coordinates)"
        } else if self.state.modal.incremental {
            "G53 cannot be incremental: program it in G90"
        } else if self.state.modal.wire_offset.engaged() {
            "G53 cannot be used with the wire offset on (G40 first)"
        } else {
            return Ok(());
        };
        Err((g53.col, GcodeErrorKind::WorkOffset(why.into())).into())
    }
}

impl<R: BufRead + Seek> BlockReader<R> {
    /// The probing move just read ended at `at` (mm, machine axes; with `contact`, or at its
    /// end point without): the program goes on from there. LinuxCNC's `#5061`… (`X Y Z A B C
    /// U V W`, program coordinates) hold the point and `#5070` is 1 with contact, 0 without.
    pub fn probed(&mut self, at: &Point, contact: bool) {
        self.state.position = *at;
        let scale = self.state.scale();
        let program = self.state.program_point(at);
        for (i, axis) in self.axes.iter().enumerate() {
            if let Some(k) = PARAM_AXES.iter().position(|&l| l == axis.letter()) {
                let v = program[i] / scale;
                self.state
                    .params
                    .set(&ParamRef::Numbered(PROBE_PARAMS + k), v);
            }
        }
        self.state.params.set(
            &ParamRef::Numbered(PROBE_PARAMS + 9),
            if contact { 1.0 } else { 0.0 },
        );
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
            self.axes
                .check_letters(letters, false, "", &format!("with {code}"))?;
            for (i, &axis) in self.axes.iter().enumerate() {
                self.state.params.set(&param(axis), self.state.position[i]);
            }
            return Ok(None);
        }
        self.axes
            .check_letters(letters, true, "", &format!("with {code}"))?;
        let (via, named) =
            self.state
                .target_here(&self.axes, self.scratch.machine_move, letters)?;
        let mut moves = MoveList::new(self.state.position, line_no, self.axes.len());
        // With axis words only the named axes go on to the stored point (LinuxCNC 2.9).
        let axes: Vec<usize> = (0..self.axes.len())
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
        self.state.position = moves.at();
        self.state.cycle.initial_level = None;
        self.emit_all(moves.into_blocks())
    }

    /// A probing move: straight, at the programmed feed, never under a wire offset.
    pub(super) fn probe_block(
        &mut self,
        probe: Probe,
        line_no: u64,
        letters: &Letters,
        col: usize,
    ) -> Step<Option<Block>> {
        let code = probe.g_code();
        self.axes
            .check_letters(letters, true, "", "with a probing move")?;
        let fail = |what: String| Fail::from((col, GcodeErrorKind::Probing(what)));
        if self.state.modal.wire_offset.engaged() {
            return Err(fail(format!(
                "{code} under a wire offset: cancel G41/G42 with G40 before probing"
            )));
        }
        let Some(feed) = self.state.modal.feed else {
            return Err(fail(format!("{code} needs a feed F (the probing speed)")));
        };
        let (target, _) = self
            .state
            .target_here(&self.axes, self.scratch.machine_move, letters)?;
        if target == self.state.position {
            if !probe.must_touch {
                // LinuxCNC: a probe that may end without contact (G38.3, G38.5) to where it
                // stands moves nothing and is no error; it ends without contact.
                self.probed(&target, false);
                return Ok(None);
            }
            return Err(fail(format!(
                "{code} needs an end point away from where it starts"
            )));
        }
        let curve = NurbsCurve::line(self.axes.len(), &self.state.position, &target)
            .map_err(|e| Fail::from((col, e.into())))?;
        self.diag.once_about(
            self.scratch.line_no,
            "probing",
            col,
            format!(
                "{code}: the check and the plan take the probing move to its end point; the \
                 machine goes on from where contact happens"
            ),
        );
        // Until the machine says where contact happened (`probed`), the program reads on
        // as LinuxCNC's reader alone does: at the end point, no contact (`#5070` 0).
        self.probed(&target, false);
        Ok(Some(self.state.block(
            line_no,
            BlockKind::Probe(probe),
            curve,
            Some(feed),
        )))
    }
}
