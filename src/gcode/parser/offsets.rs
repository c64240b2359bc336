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

use super::axes::MachineAxes;
use super::codes::OffsetCode;
use super::cycles::MoveList;
use super::params::{G28_PARAMS, G30_PARAMS, G92_ENABLED, param_slot, table_param};
use super::state::{BlockEnv, InterpState};
use super::{Fail, Letters, Step, whole_as};
use crate::gcode::error::GcodeErrorKind;
use crate::gcode::expr::ParamRef;
use crate::gcode::lexer::Word;
use crate::gcode::work::WorkSystem;
use crate::gcode::{Block, BlockKind, Probe};
use crate::geometry::{NurbsCurve, Point};
use crate::vocab::Axis;

/// The group-0 offset codes: `G10 L2`/`L20` and the `G92` family (LinuxCNC's semantics;
/// the values also go to their parameters).
pub(super) fn coordinate_offset(
    state: &mut InterpState,
    axes: &MachineAxes,
    code: OffsetCode,
    w: &Word,
    letters: &Letters,
) -> Step<()> {
    if code != OffsetCode::Table && state.modal.wire_offset.engaged() {
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
        OffsetCode::Table => return set_table(state, axes, w, letters),
        OffsetCode::Set => {
            let mut any = false;
            for (i, axis) in axes.iter().enumerate() {
                if let Some(v) = letters.get(axis.letter()) {
                    state.g92[i] = state.position[i] - state.g5x[i] - v.value * state.scale();
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
        }
        OffsetCode::Clear => state.g92 = Point::zeros(),
        OffsetCode::Suspend | OffsetCode::Restore => {
            state.apply_g92(axes, code == OffsetCode::Restore);
            return Ok(());
        }
    }
    // G92 and G92.1 write the offset into #5211… and say whether it is applied in #5210.
    let on = state.g92.iter().any(|&o| o != 0.0);
    state
        .params
        .set(&ParamRef::Numbered(G92_ENABLED), if on { 1.0 } else { 0.0 });
    for (i, &axis) in axes.iter().enumerate() {
        state
            .params
            .set(&ParamRef::Numbered(g92_param(axis)), state.g92[i]);
    }
    Ok(())
}

/// The parameter holding the `G92` offset of `axis` (`#5211` for X).
fn g92_param(axis: Axis) -> usize {
    G92_ENABLED + 1 + param_slot(axis)
}

impl InterpState {
    /// The `G92` offset is applied (`#5210`, LinuxCNC's flag).
    pub(super) fn g92_applied(&self) -> bool {
        self.params.numbered(G92_ENABLED) != 0.0
    }

    /// `G92.3` (`on`): the offset applied from `#5211`…, where `G92.2` left it (or a program
    /// wrote it); `G92.2`: not applied, its parameters kept. As LinuxCNC, which `M72` and a
    /// return from `M73` also call to put the flag back.
    pub(super) fn apply_g92(&mut self, axes: &[Axis], on: bool) {
        for (i, &axis) in axes.iter().enumerate() {
            self.g92[i] = if on {
                self.params.numbered(g92_param(axis))
            } else {
                0.0
            };
        }
        self.params
            .set(&ParamRef::Numbered(G92_ENABLED), if on { 1.0 } else { 0.0 });
    }
}

/// `G10 L2 P… X…` sets system `P`'s offset on the named axes; `G10 L20 P… X…` sets it so
/// that the current point reads the given coordinates in that system. `P0` is the active
/// system. Axis values are absolute whatever the distance mode (LinuxCNC's rule).
fn set_table(state: &mut InterpState, axes: &MachineAxes, w: &Word, letters: &Letters) -> Step<()> {
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
    let system = WorkSystem::from_number(n).unwrap_or(state.system);
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
    if state.modal.wire_offset.engaged() && system == state.system {
        return Err(fail(
            w.col,
            "G10: the active work system cannot change with the wire offset on (G40 first)".into(),
        ));
    }
    let mut offset = state.table_entry(axes, system);
    for (i, axis) in axes.iter().enumerate() {
        if let Some(v) = letters.get(axis.letter()) {
            let value = v.value * state.scale();
            offset[i] = if relative_to_here {
                state.position[i] - state.g92[i] - value
            } else {
                value
            };
        }
    }
    for (i, &axis) in axes.iter().enumerate() {
        let param = table_param(system, param_slot(axis));
        state.params.set(&ParamRef::Numbered(param), offset[i]);
    }
    if system == state.system {
        state.g5x = offset;
    }
    Ok(())
}

/// `G53`: this block's move is in machine coordinates. Only with `G0`/`G1`, in `G90`,
/// without the wire offset (LinuxCNC's three rules).
pub(super) fn check_machine_move(state: &InterpState, g53: &Word, straight: bool) -> Step<()> {
    let why = if !straight {
        "G53 needs G0 or G1 (one straight move in machine coordinates)"
    } else if state.modal.incremental {
        "G53 cannot be incremental: program it in G90"
    } else if state.modal.wire_offset.engaged() {
        "G53 cannot be used with the wire offset on (G40 first)"
    } else {
        return Ok(());
    };
    Err((g53.col, GcodeErrorKind::WorkOffset(why.into())).into())
}

/// `G28`/`G30` (`g30`), or `G28.1`/`G30.1` (`store`), at `w`.
pub(super) fn reference_point(
    state: &mut InterpState,
    env: &mut BlockEnv,
    g30: bool,
    store: bool,
    w: &Word,
    line_no: u64,
    letters: &Letters,
) -> Step<Vec<Block>> {
    let code = format!("G{}", w.text);
    let fail = |what: String| Fail::from((w.col, GcodeErrorKind::Cycle(what)));
    if state.modal.wire_offset.engaged() {
        return Err(fail(format!(
            "{code} cannot be used with the wire offset on (G40 first)"
        )));
    }
    if state.unhomed {
        return Err(fail(format!(
            "{code} goes to a stored machine position: the machine is not homed, so machine \
             coordinates mean nothing yet (home it first)"
        )));
    }
    let base = if g30 { G30_PARAMS } else { G28_PARAMS };
    let param = |axis: Axis| ParamRef::Numbered(base + param_slot(axis));
    if store {
        env.axes
            .check_letters(letters, false, "", &format!("with {code}"))?;
        for (i, &axis) in env.axes.iter().enumerate() {
            state.params.set(&param(axis), state.position[i]);
        }
        return Ok(Vec::new());
    }
    env.axes
        .check_letters(letters, true, "", &format!("with {code}"))?;
    let (via, named) = env.target_here(state, letters)?;
    let mut moves = MoveList::new(state.position, line_no, env.axes.len(), Vec::new());
    // With axis words only the named axes go on to the stored point (LinuxCNC 2.9).
    let axes: Vec<usize> = (0..env.axes.len())
        .filter(|&i| !named || letters.get(env.axes[i].letter()).is_some())
        .collect();
    moves.to(
        w.col,
        &axes.iter().map(|&i| (i, via[i])).collect::<Vec<_>>(),
    )?;
    let stored: Vec<(usize, f64)> = axes
        .iter()
        .map(|&i| (i, state.params.numbered(base + param_slot(env.axes[i]))))
        .collect();
    moves.to(w.col, &stored)?;
    state.position = moves.at();
    state.cycle.initial_level = None;
    Ok(moves.into_blocks())
}

/// A probing move: straight, at the programmed feed, never under a wire offset.
pub(super) fn probe_block(
    state: &mut InterpState,
    env: &mut BlockEnv,
    probe: Probe,
    line_no: u64,
    letters: &Letters,
    col: usize,
) -> Step<Option<Block>> {
    let code = probe.g_code();
    env.axes
        .check_letters(letters, true, "", "with a probing move")?;
    let fail = |what: String| Fail::from((col, GcodeErrorKind::Probing(what)));
    if state.modal.wire_offset.engaged() {
        return Err(fail(format!(
            "{code} under a wire offset: cancel G41/G42 with G40 before probing"
        )));
    }
    let Some(feed) = state.modal.feed else {
        return Err(fail(format!("{code} needs a feed F (the probing speed)")));
    };
    let (target, _) = env.target_here(state, letters)?;
    if target == state.position {
        if !probe.must_touch {
            // LinuxCNC: a probe that may end without contact (G38.3, G38.5) to where it
            // stands moves nothing and is no error; it ends without contact.
            state.probed(env.axes, &target, false);
            return Ok(None);
        }
        return Err(fail(format!(
            "{code} needs an end point away from where it starts"
        )));
    }
    let curve = NurbsCurve::line(env.axes.len(), &state.position, &target)
        .map_err(|e| Fail::from((col, e.into())))?;
    env.warn_once(
        "probing",
        col,
        format!(
            "{code}: the check and the plan take the probing move to its end point; the \
             machine goes on from where contact happens"
        ),
    );
    // Until the machine says where contact happened (`probed`), the program reads on
    // as LinuxCNC's reader alone does: at the end point, no contact (`#5070` 0).
    state.probed(env.axes, &target, false);
    Ok(Some(state.block(
        line_no,
        BlockKind::Probe(probe),
        curve,
        Some(feed),
    )))
}
