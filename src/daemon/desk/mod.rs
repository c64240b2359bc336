//! The desk: the machine's commands (homing, jog, MDI, the work offsets) as functions of what they read, the
//! configuration and the machine, that answer with what to launch or a refusal.
//!
//! A command at the desk decides; the control loop (`Core`) acts. Each function takes a
//! [`Desk`] (the configuration and the machine, read-only) and the request's arguments and
//! returns an [`Order`] (the program text a job is made of, how it starts, and what the
//! operator is told once its check has an id) or a [`Refusal`]. Whether the loop is free to
//! start a check is the loop's question (a job, a check or a cycle in hand); whether the
//! machine allows the motion (a trip, an unhomed axis, a distrusted position) is the desk's.
//! So every rule of a command can be tested with a configuration and a machine state, no
//! daemon, no threads.
//!
//! The functions that change the machine without motion (`home --here`, a homing job's
//! latch, `touch-off`) take the machine mutably and save it themselves: the write-ahead rule stays one
//! call (`Machine::save`).

pub(super) mod homing;
pub(super) mod manual;
pub(super) mod offsets;
pub(super) mod pendant;
mod resume;
pub(super) use resume::Recovery;
pub(super) mod touch;
pub(super) mod trips;

use super::launch::{JobKind, Launch, Source};
use super::refusal::Refusal;
use crate::config::Config;
use crate::machine::{Admission, Denial, Machine, WriteError};
use crate::vocab::Axis;

/// What a command reads: the daemon's configuration and the machine as it stands.
#[derive(Clone, Copy)]
pub(super) struct Desk<'a> {
    pub config: &'a Config,
    pub machine: &'a Machine,
}

/// What a command asks the control loop to launch: a generated program's check, then its
/// job.
pub(super) struct Order {
    pub source: Source,
    pub launch: Launch,
    /// What the operator is told, before the check's id (`… (check N)`).
    pub said: String,
}

impl Order {
    /// A job of `kind` from the program `text` (`name` in the log and the history), starting
    /// in the machine's work system and offsets.
    fn generated(desk: Desk, name: &str, text: String, kind: JobKind, said: String) -> Order {
        Order {
            source: Source::Generated {
                text,
                name: name.to_string(),
            },
            launch: Launch {
                technology: Default::default(),
                start: desk.machine.state.work_start(),
                kind,
                cut: Default::default(),
                recovers: None,
            },
            said,
        }
    }
}

impl Desk<'_> {
    /// The machine's axis named `name` and its index.
    pub fn axis(&self, name: &str) -> Result<(usize, Axis), Refusal> {
        let machine = &self.config.machine;
        let mut chars = name.trim().chars();
        let axis = match (chars.next(), chars.next()) {
            (Some(c), None) => Axis::from_letter(c.to_ascii_uppercase()),
            _ => None,
        };
        axis.and_then(|a| machine.axes.iter().position(|&x| x == a).map(|i| (i, a)))
            .ok_or_else(|| {
                Refusal::BadArgument(format!(
                    "{name:?} is not an axis of this machine ({})",
                    machine.axis_names().join(", ")
                ))
            })
    }

    /// The axes named (all of the machine's when none is).
    pub fn axes(&self, names: &[String]) -> Result<Vec<(usize, Axis)>, Refusal> {
        if names.is_empty() {
            return Ok(self
                .config
                .machine
                .axes
                .iter()
                .copied()
                .enumerate()
                .collect());
        }
        names.iter().map(|a| self.axis(a)).collect()
    }

    /// Motion refused while an E-stop or a limit switch holds the machine; `jog` names the
    /// axis and direction of a jog (the only motion a limit switch allows, away from it).
    pub fn refuse_if_tripped(&self, jog: Option<(Axis, bool)>) -> Result<(), Refusal> {
        self.machine
            .admit(Admission::Motion { jog })
            .map_err(|d| refusal(d, "move"))
    }

    /// `run` (and the motion made like a run: jog, MDI, a touch cycle) on a machine that must
    /// be homed first.
    pub fn refuse_if_unhomed(&self) -> Result<(), Refusal> {
        let homing_required = self.config.homing.required;
        self.machine
            .admit(Admission::Run { homing_required })
            .map_err(|d| refusal(d, "run"))
    }

    /// A job that does not taper starts with the wire vertical (the upper guide at machine
    /// U0 V0, where the taper stage puts it for no lean): one left leaning by an aborted
    /// taper job would cut tilted.
    pub fn refuse_if_leaning(&self) -> Result<(), Refusal> {
        let Some([u, v]) = self.config.machine.upper_guide_axes() else {
            return Ok(());
        };
        let position = &self.machine.state.position;
        if position[u] == 0 && position[v] == 0 {
            return Ok(());
        }
        let step = &self.config.machine.step_mm;
        Err(Refusal::Leaning {
            at: format!(
                "U{:.4} V{:.4}",
                position[u] as f64 * step[u],
                position[v] as f64 * step[v]
            ),
        })
    }

    /// A resume or a run from a line continues a cut where the machine is believed to stand:
    /// refused while an axis is unhomed under `homing.required`, or while the position is
    /// distrusted after an unclean stop, unless `force` says the operator checked it.
    pub fn refuse_if_untrusted(&self, what: &'static str, force: bool) -> Result<(), Refusal> {
        let homing_required = self.config.homing.required;
        let Err(denial) = self.machine.admit(Admission::Continue { homing_required }) else {
            return Ok(());
        };
        let refusal = match denial {
            Denial::Unhomed { axes } => Refusal::UnhomedResume { what, axes },
            other => refusal(other, what),
        };
        if !force {
            return Err(refusal);
        }
        tracing::warn!("{refusal} (forced: the operator says the position was checked)");
        Ok(())
    }
}

/// A failed write of the state file, as the operator is told (and the log says).
pub(in crate::daemon) fn unwritten(e: WriteError) -> Refusal {
    tracing::error!("{e}");
    Refusal::MachineState(e.to_string())
}

/// The operator's refusal for the machine's denial of `what`.
fn refusal(denial: Denial, what: &'static str) -> Refusal {
    match denial {
        Denial::EStop => Refusal::EStop,
        Denial::Limit { switch } => Refusal::Limit { switch },
        Denial::Unhomed { axes } => Refusal::Unhomed { axes },
        Denial::Distrusted => Refusal::Distrusted { what },
    }
}

#[cfg(test)]
pub(super) mod tests;
