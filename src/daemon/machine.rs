//! The machine as the daemon keeps it between jobs: position (machine coordinates, steps),
//! homed axes, the work offset table and the active system, in `daemon.state_file`
//! ([`crate::machine`]), with the write-ahead rule: marked moving before a job leaves a
//! standstill, written at the standstill where it ends. The operator's commands that change
//! it (`offsets`, `touch-off`, `home --here`, `reset`) and its trips are the desk's
//! ([`super::desk`]); here it is opened and shown.

use super::DaemonError;
use super::protocol::{FindStatus, MachineStatus};
use crate::checkpoint;
use crate::config::Config;
use crate::gcode::{WorkOffsets, WorkSystem};
use crate::machine::{Found, Machine};
use crate::vocab::Steps;

/// Opens the machine of `config` (`daemon.state_file`): a clean standstill restores position
/// and homed axes (unless `homing.require_after_start`), a moving one restores the position but
/// unhomes every axis, none starts at machine zero, unhomed. A file that cannot be read or
/// belongs to another machine configuration stops the daemon.
///
/// Without a state file but with a checkpoint (one `edmd run --checkpoint` wrote, or an older
/// edmd's), the machine is believed to stand where the checkpoint's job stopped.
pub(super) fn open_machine(
    config: &Config,
    checkpoint: Option<&checkpoint::Checkpoint>,
) -> Result<Machine, DaemonError> {
    let path = &config.daemon.state_file;
    let (mut machine, found) = Machine::open(Some(path), &config.machine)
        .map_err(|e| DaemonError::MachineState(e.to_string()))?;
    match found {
        Found::Nothing => {
            let state = &mut machine.state;
            match checkpoint.filter(|cp| cp.position_steps.len() == state.axes.len()) {
                Some(cp) => {
                    state.position[..cp.position_steps.len()].copy_from_slice(&cp.position_steps);
                    tracing::info!(
                        "{}: no machine state yet: the machine is believed to stand where the \
                         checkpoint's job stopped, no axis homed",
                        path.display()
                    );
                }
                None => tracing::info!(
                    "{}: no machine state yet: at machine zero, no axis homed",
                    path.display()
                ),
            }
        }
        Found::Moving => tracing::warn!(
            "{}: the machine was moving when edmd last stopped: its position is only believed, \
             every axis is unhomed",
            path.display()
        ),
        Found::Standstill if config.homing.require_after_start => {
            tracing::info!("homing.require_after_start: every axis is unhomed");
            machine.state.homed.iter_mut().for_each(|h| *h = false);
        }
        Found::Standstill => {}
    }
    // The file now says what the daemon believes (an unhomed state stays unhomed after a
    // second crash).
    machine
        .save(false)
        .map_err(|e| DaemonError::MachineState(e.to_string()))?;
    Ok(machine)
}

/// edmd joins a HAL that kept running after an earlier edmd (`why`), and the drives may have
/// moved while no edmd watched them. `pos-cmd` takes up where they stand (no jump); the
/// machine position is kept as believed but distrusted, every axis unhomed, until homing (or
/// `home --here`) confirms it.
pub(super) fn distrust_moved_drives(machine: &mut Machine, why: &str) {
    tracing::warn!(
        "{why}: pos-cmd takes up where the drives stand, and the machine position is untrusted \
         and every axis unhomed until homed (or confirmed with `edmd ctl home --here`)"
    );
    machine.state = machine.state.clone().distrusted();
    if let Err(e) = machine.save(false) {
        tracing::error!("{e}");
    }
}

/// What the status shows of the machine; `live` is a running job's ledger with the work
/// offsets and system its program is in (the DRO's work position is in that system), `find`
/// the running or last touch cycle.
pub(super) fn machine_status(
    machine: &Machine,
    config: &Config,
    live: Option<(Steps, &(WorkOffsets, WorkSystem))>,
    find: Option<FindStatus>,
) -> MachineStatus {
    let mut state = machine.state.clone();
    if let Some((p, (offsets, system))) = live {
        state.position = p;
        state.offsets = offsets.clone();
        state.system = *system;
    }
    let n = state.axes.len();
    MachineStatus {
        position_machine_mm: state.position_mm().as_slice()[..n].to_vec(),
        position_work_mm: state.position_work_mm().as_slice()[..n].to_vec(),
        work_system: state.system.name().to_string(),
        work_offsets: crate::gcode::WorkSystem::all()
            .map(|s| super::protocol::WorkOffsetRow {
                system: s.name().to_string(),
                offset_mm: state.offsets.get(s).as_slice()[..n].to_vec(),
            })
            .collect(),
        homed: state.homed.clone(),
        position_trusted: state.position_trusted,
        travel_mm: config
            .machine
            .travel
            .iter()
            .map(|t| t.map(|t| [t.min_mm, t.max_mm]))
            .collect(),
        state_write_error: machine.write_error.clone(),
        find,
    }
}
