//! The work offsets as the operator sets them without motion: `offsets` (the table) and
//! `touch-off` (`G10 L20` for where the machine stands).

use super::super::refusal::Refusal;
use super::{Desk, unwritten};
use crate::config::Config;
use crate::gcode::WorkSystem;
use crate::machine::Machine;
use crate::machine::travel::offset_allowed;
use crate::vocab::Axis;

/// `offsets`: the table, one system a line, the active one marked `*`.
pub(in crate::daemon) fn table(machine: &Machine) -> String {
    format!(
        "work offsets (mm, machine coordinates of each system's zero):\n{}",
        machine.state.offsets_text()
    )
}

/// `touch-off AXIS VALUE [SYSTEM]`: `G10 L20` for where the machine stands: the system's
/// offset on `axis` is set so that the current position reads `value` (mm) in it. The
/// machine is saved (and the offset left as it was if it cannot be).
pub(in crate::daemon) fn touch_off(
    config: &Config,
    machine: &mut Machine,
    axis: &str,
    value: f64,
    system: Option<&str>,
) -> Result<String, Refusal> {
    let desk = Desk { config, machine };
    // An offset set while the machine is stopped by an E-stop or a limit is set from a
    // position nobody has checked since.
    desk.refuse_if_tripped(None)?;
    let (i, axis) = desk.axis(axis)?;
    if !value.is_finite() || value.abs() > 1.0e6 {
        return Err(Refusal::BadArgument(format!(
            "touch-off value {value} is not a coordinate (±1000000 mm)"
        )));
    }
    let offset_mm = machine.state.position_mm()[i] - value;
    in_travel(config, i, axis, offset_mm)?;
    let state = &mut machine.state;
    let system = match system {
        None => state.system,
        Some(name) => WorkSystem::parse(name).ok_or_else(|| {
            Refusal::BadArgument(format!("{name:?} is not a work system (G54 … G59.3)"))
        })?,
    };
    let mut offset = *state.offsets.get(system);
    let before = offset[i];
    offset[i] = state.position_mm()[i] - value;
    state.offsets.set(system, offset);
    if let Err(e) = machine.save(false) {
        machine.state.offsets.set(system, {
            let mut o = offset;
            o[i] = before;
            o
        });
        return Err(unwritten(e));
    }
    tracing::info!(
        edmd_event = "touch_off",
        "touch-off: {system} {axis} offset {before:.4} -> {:.4} mm (here reads {axis}{value:.4})",
        offset[i]
    );
    Ok(format!(
        "{system} {axis} offset is {:.4} mm: here reads {axis}{value:.4}",
        offset[i]
    ))
}

/// A work offset must put the system's zero within the axis's travel (soft limits, or
/// ±[`crate::machine::travel::MAX_OFFSET_MM`] without them): a zero beyond it is a typing
/// error or a position nobody trusts, and every program would run from there.
fn in_travel(config: &Config, i: usize, axis: Axis, offset_mm: f64) -> Result<(), Refusal> {
    let travel = config.machine.travel.get(i).copied().flatten();
    offset_allowed(travel, offset_mm).map_err(|(min, max)| {
        Refusal::BadArgument(format!(
            "the {axis} offset would be {offset_mm:.4} mm, outside the axis's travel \
             [{min}, {max}] mm: check the value and where the machine stands"
        ))
    })
}
