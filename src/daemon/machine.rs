//! The machine as the daemon keeps it between jobs: position (machine coordinates, steps),
//! homed axes, the work offset table and the active system, in `daemon.state_file`
//! ([`crate::machine`]), with the write-ahead rule: marked moving before a job leaves a
//! standstill, written at the standstill where it ends. The operator's commands that change
//! it without motion (`offsets`, `touch-off`, `home --here`) decide at the desk
//! ([`super::desk`]); the trips, the reset and a resume's start stay here.

use super::desk::unwritten;
use super::protocol::{FindStatus, MachineStatus};
use super::refusal::Refusal;
use super::{Core, DaemonError};
use crate::checkpoint;
use crate::config::Config;
use crate::gcode::WorkStart;
use crate::machine::{Found, Machine};
use crate::vocab::{Steps, Trip};

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

/// What the status shows of the machine; `live` is a running job's ledger, `find` the running
/// or last touch cycle.
pub(super) fn machine_status(
    machine: &Machine,
    config: &Config,
    live: Option<&Steps>,
    find: Option<FindStatus>,
) -> MachineStatus {
    let mut state = machine.state.clone();
    if let Some(p) = live {
        state.position = *p;
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

impl Core {
    /// Where the checkpoint's job started: the resume replays it from there. Refused when the
    /// work offsets it started with differ from the machine's now (unless `force`): the same
    /// program would resume in another place.
    pub(super) fn resume_start(
        &self,
        cp: &checkpoint::Checkpoint,
        force: bool,
    ) -> Result<WorkStart, Refusal> {
        let machine = &self.config.machine;
        // The machine must stand where the checkpoint's job stopped (a jog or MDI since
        // moved it): a resume walks there without moving.
        let here = &self.machine.state.position[..machine.axes.len()];
        if here != cp.position_steps.as_slice() {
            let mm = |steps: &[i64]| {
                steps
                    .iter()
                    .zip(&machine.step_mm)
                    .zip(&machine.axes)
                    .map(|((s, mm), a)| format!("{a}{:.4}", *s as f64 * mm))
                    .collect::<Vec<_>>()
                    .join(" ")
            };
            if !force {
                return Err(Refusal::NotAtCheckpoint {
                    here: mm(here),
                    checkpoint: mm(&cp.position_steps),
                });
            }
            tracing::warn!(
                "resume --force: the machine stands at {}, the checkpoint at {}",
                mm(here),
                mm(&cp.position_steps)
            );
        }
        let Some(record) = &cp.start else {
            return Ok(WorkStart::default());
        };
        let start = record
            .work_start(&machine.axes, &machine.step_mm)
            .map_err(|e| Refusal::MachineState(format!("the checkpoint's start: {e}")))?;
        let now = &self.machine.state.offsets;
        let mut changed = Vec::new();
        for system in crate::gcode::WorkSystem::all() {
            let (was, is) = (start.offsets.get(system), now.get(system));
            for (i, axis) in machine.axes.iter().enumerate() {
                if (was[i] - is[i]).abs() > 1e-9 {
                    changed.push(format!(
                        "{system} {axis}: {:.4} then, {:.4} now",
                        was[i], is[i]
                    ));
                }
            }
        }
        if !changed.is_empty() {
            if !force {
                return Err(Refusal::OffsetsChanged {
                    changed: changed.join("; "),
                });
            }
            tracing::warn!(
                "resume --force: the work offsets changed ({}); the job resumes with the \
                 offsets it started with",
                changed.join("; ")
            );
        }
        Ok(start)
    }

    /// `reset` after an E-stop: refused while the E-stop input still reads pressed (on the
    /// claimed device, whose inputs the fine thread reads between jobs).
    pub(super) fn reset(&mut self) -> Result<String, Refusal> {
        // Whatever the fine thread saw since the last look counts first: a reset must not
        // clear an E-stop pressed (and released) a moment ago that no trip records yet.
        self.watch_inputs();
        match self.machine.state.trip {
            None => return Err(Refusal::BadArgument("nothing to reset: no E-stop".into())),
            Some(Trip::Limit(switch)) => {
                return Err(Refusal::BadArgument(format!(
                    "limit switch {switch}: jog away from it (a jog towards {} on {}); reset \
                     is for the E-stop",
                    if switch.positive { "-" } else { "+" },
                    switch.axis
                )));
            }
            Some(Trip::EStop) => {}
        }
        if self.jobs.fine.has_claim()
            && self
                .jobs
                .fine
                .idle_watch()
                .reading()
                .is_none_or(|r| r.estop)
        {
            return Err(Refusal::BadArgument(
                "the E-stop input still reads pressed: release it first".into(),
            ));
        }
        self.set_trip(None);
        tracing::warn!(edmd_event = "reset", "reset: the E-stop is cleared");
        Ok("reset: the E-stop is cleared; the machine may move again".into())
    }

    /// The trip in force, kept in the state file (a restart does not forget it).
    fn set_trip(&mut self, trip: Option<Trip>) {
        if self.machine.state.trip != trip {
            self.machine.state.trip = trip;
            // A failed write is logged and shown in the status; the next one may succeed.
            let _ = self.machine.save(false).map_err(unwritten);
        }
    }

    /// What an ended job leaves: an E-stop or a limit switch holds the machine (an E-stop
    /// unhomes it with `homing.lost_on_estop`); a limit switch's trip is kept until the job's
    /// last reading shows the switch open (a jog away that left it).
    pub(super) fn note_trip(&mut self, summary: &crate::runtime::JobSummary) {
        use crate::runtime::Outcome;
        match summary.outcome {
            Outcome::Estop => {
                if self.config.homing.lost_on_estop {
                    self.machine.state.homed.iter_mut().for_each(|h| *h = false);
                }
                self.set_trip(Some(Trip::EStop));
            }
            Outcome::Limit => {
                if let Some(switch) = summary.limit_switch {
                    self.set_trip(Some(Trip::Limit(switch)));
                }
            }
            _ if summary.ticks > 0 => {
                if let Some(Trip::Limit(switch)) = self.machine.state.trip
                    && !summary.limits_closed.contains(&switch.to_string())
                {
                    tracing::info!("limit switch {switch} reads open: the trip is cleared");
                    self.set_trip(None);
                }
            }
            _ => {}
        }
    }

    /// Between jobs the fine thread reads the claimed device's inputs every millisecond and
    /// latches what it saw ([`crate::runtime::Claimed`]); here the control loop takes it, as
    /// LinuxCNC reads its inputs when nothing moves: an E-stop pressed (even a pulse already
    /// released) or a limit switch closed while idle trips the machine; a limit switch's trip
    /// ends when the switch reads open (the axis moved off it by hand, or the switch was
    /// freed). An E-stop's trip ends only with `reset`. A device that failed between jobs
    /// (HAL's real-time side gone, a port that stopped answering) trips it as an E-stop.
    /// Called every round of the loop and before any motion starts.
    pub(super) fn watch_inputs(&mut self) {
        if self.jobs.job.is_some() || !self.jobs.fine.has_claim() {
            return;
        }
        let seen = self.jobs.fine.idle_watch().take();
        if let Some(fault) = seen.fault {
            if self.machine.state.trip != Some(Trip::EStop) {
                tracing::error!(
                    edmd_event = "trip",
                    "{fault}: the drives are off and the machine is held as in an E-stop"
                );
                self.set_trip(Some(Trip::EStop));
            }
            return;
        }
        let Some(now) = seen.now else {
            return;
        };
        // An E-stop is decided on what was seen (a pulse latched), a limit switch on what
        // reads now (a switch bouncing while nothing moves stops nothing).
        let latched = crate::vocab::SafetyInputs {
            estop: seen.seen.estop || now.estop,
            limits: now.limits,
        };
        match self.machine.state.trip {
            Some(Trip::EStop) => {}
            Some(Trip::Limit(_)) if latched.estop => self.trip_idle(Trip::EStop, now.estop),
            Some(Trip::Limit(switch)) if !now.limits.contains(switch) => {
                let next = Trip::of(now);
                tracing::info!(
                    "limit switch {switch} reads open{}",
                    match next {
                        Some(t) => format!("; now {}", t.name()),
                        None => ": the trip is cleared".to_string(),
                    }
                );
                self.set_trip(next);
            }
            Some(Trip::Limit(_)) => {}
            None => {
                if let Some(trip) = Trip::of(latched) {
                    let still = match trip {
                        Trip::EStop => now.estop,
                        Trip::Limit(s) => now.limits.contains(s),
                    };
                    self.trip_idle(trip, still);
                }
            }
        }
    }

    /// An E-stop or a limit switch seen while idle; `still`: it reads so now (else it was a
    /// pulse the fine thread latched).
    fn trip_idle(&mut self, trip: Trip, still: bool) {
        tracing::warn!(
            edmd_event = "trip",
            "{}{} while idle: nothing moves until it is cleared",
            match trip {
                Trip::EStop => "E-stop pressed".to_string(),
                Trip::Limit(s) => format!("limit switch {s} closed"),
            },
            if still {
                ""
            } else {
                " (a pulse, released since)"
            }
        );
        // A continuous jog whose client keeps renewing through the trip must not start
        // again by itself once it is cleared.
        self.latch_stopped_jog();
        self.set_trip(Some(trip));
    }
}
