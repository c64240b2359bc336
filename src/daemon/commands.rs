//! The machine's commands as the control loop runs them: each asks the desk
//! ([`super::desk`]) what to launch, and launches it when the loop is free; a continuous
//! jog's renewals, its dead-man and its latch follow the job in hand, so they live here.

use std::sync::atomic::Ordering;

use super::Core;
use super::desk::manual::{DEAD_MAN, sign};
use super::desk::{self, Desk, Order};
use super::launch::JobKind;
use super::refusal::Refusal;
use crate::runtime::JobSummary;
use crate::vocab::HomeSwitch;

/// A continuous jog: its axis and direction, and when it stops unless renewed (monotonic
/// ns: the job's thread holds the job at the same deadline, [`crate::runtime::Published`]).
pub(super) struct ContinuousJog {
    pub axis: usize,
    pub positive: bool,
    pub deadline_ns: u64,
}

/// A continuous jog that a hold or its dead-man stopped: the same request arriving again
/// within [`DEAD_MAN`] of the last is the stopped jog's client still renewing, and is
/// refused; a pause longer than that (the button let go) or `jog-stop` ends the latch, and
/// the next request starts a new jog.
pub(super) struct StoppedJog {
    pub axis: usize,
    pub positive: bool,
    pub last_ns: u64,
}

fn dead_man_ns() -> u64 {
    DEAD_MAN.as_nanos() as u64
}

impl Core {
    /// What the machine's commands read: the configuration and the machine.
    pub(super) fn desk(&self) -> Desk<'_> {
        Desk {
            config: &self.config,
            machine: &self.machine,
        }
    }

    /// Starts the check of what a command ordered; what the operator is told.
    fn launch(&mut self, order: Order) -> String {
        let Order {
            source,
            launch,
            said,
        } = order;
        let id = self.begin_check(source, None, launch);
        format!("{said} (check {id})")
    }

    /// `home [AXIS…] [--here]`.
    pub(super) fn home(
        &mut self,
        axes: &[String],
        here: bool,
        force: bool,
    ) -> Result<String, Refusal> {
        self.refuse_if_busy()?;
        self.desk().refuse_if_tripped(None)?;
        if here {
            return desk::homing::here(&self.config, &mut self.machine, axes, force);
        }
        let order = desk::homing::by_switch(self.desk(), axes)?;
        let names: Vec<String> = order
            .iter()
            .map(|&i| self.config.machine.axes[i].to_string())
            .collect();
        let (first, rest) = order.split_first().expect("at least one axis");
        self.machine.homing_queue = rest.to_vec();
        let job = desk::homing::axis_job(self.desk(), *first);
        let id = self.begin_check(job.source, None, job.launch);
        Ok(format!(
            "homing {} by their switches, in that order (check {id})",
            names.join(", ")
        ))
    }

    /// A job starts; a homing job's axis is unhomed until it latches.
    pub(super) fn homing_started(&mut self, switch: Option<&HomeSwitch>) {
        if let Some(switch) = switch {
            self.machine.state.homed[switch.axis] = false;
        }
    }

    /// A homing job ended: the next axis starts, if the latch says so.
    pub(super) fn homing_done(&mut self, switch: &HomeSwitch, summary: &JobSummary) {
        if let Some(next) =
            desk::homing::latched(&self.config, &mut self.machine, switch, summary.into())
        {
            let job = desk::homing::axis_job(self.desk(), next);
            self.begin_check(job.source, None, job.launch);
        }
    }

    /// `jog AXIS DISTANCE [--feed F]`.
    pub(super) fn jog(
        &mut self,
        axis: &str,
        distance_mm: f64,
        feed: Option<f64>,
    ) -> Result<String, Refusal> {
        self.refuse_if_busy()?;
        let order = desk::manual::jog(self.desk(), axis, distance_mm, feed)?;
        Ok(self.launch(order))
    }

    /// `mdi LINES`.
    pub(super) fn mdi(&mut self, lines: &str) -> Result<String, Refusal> {
        self.refuse_if_busy()?;
        let order = desk::manual::mdi(self.desk(), lines)?;
        Ok(self.launch(order))
    }

    /// `jog-continuous`: towards the soft limit (or [`MAX_JOG_MM`]) while renewed; the same
    /// request within [`DEAD_MAN`] renews it, silence stops it (a closed browser tab, a lost
    /// connection). Another axis or direction while one moves is refused.
    pub(super) fn jog_continuous(
        &mut self,
        axis: &str,
        positive: bool,
        feed: Option<f64>,
    ) -> Result<String, Refusal> {
        let (i, letter) = self.desk().axis(axis)?;
        let now = crate::sys::monotonic_ns();
        if let Some(stopped) = &mut self.jobs.stopped_jog {
            if stopped.axis == i
                && stopped.positive == positive
                && now.saturating_sub(stopped.last_ns) <= dead_man_ns()
            {
                stopped.last_ns = now;
                return Err(Refusal::BadArgument(format!(
                    "jog {letter}{} was stopped (a hold, its dead-man, a trip or its end): renewals are refused; \
                     let go and start it again",
                    sign(positive)
                )));
            }
            self.jobs.stopped_jog = None;
        }
        let stopped_in_job = self.jobs.job.as_ref().is_some_and(|job| {
            matches!(job.kind, JobKind::Jog { .. })
                && (job.published.hold.load(Ordering::Relaxed)
                    || job.published.dead_man_tripped.load(Ordering::Relaxed))
        });
        if let Some(c) = &mut self.jobs.continuous {
            if c.axis == i && c.positive == positive {
                if stopped_in_job {
                    self.stop_continuous("held: a renewal does not move it again", true);
                    return Err(Refusal::BadArgument(format!(
                        "jog {letter}{} was stopped (a hold, its dead-man, a trip or its end): renewals are \
                         refused; let go and start it again",
                        sign(positive)
                    )));
                }
                c.deadline_ns = now + dead_man_ns();
                if let Some(job) = &self.jobs.job {
                    job.published
                        .dead_man_ns
                        .store(c.deadline_ns, Ordering::Release);
                }
                return Ok(format!("jog {letter}{}: renewed", sign(positive)));
            }
            return Err(Refusal::BadArgument(format!(
                "a continuous jog of {}{} is moving: stop it first",
                self.config.machine.axes[c.axis],
                sign(c.positive)
            )));
        }
        self.refuse_if_busy()?;
        let order = desk::manual::continuous(self.desk(), i, letter, positive, feed)?;
        let reply = self.launch(order);
        self.jobs.continuous = Some(ContinuousJog {
            axis: i,
            positive,
            deadline_ns: crate::sys::monotonic_ns() + dead_man_ns(),
        });
        Ok(reply)
    }

    /// `jog-stop`: the continuous jog brakes to a standstill now.
    pub(super) fn jog_stop(&mut self) -> Result<String, Refusal> {
        // The client let go: the next press starts a new jog.
        let latched = self.jobs.stopped_jog.take().is_some();
        if self.jobs.continuous.is_none() {
            if latched {
                return Ok("jog: already stopped".into());
            }
            return Err(Refusal::BadArgument("no continuous jog is moving".into()));
        }
        self.stop_continuous("stopped", false);
        Ok("jog: braking to a standstill".into())
    }

    /// A continuous jog not renewed in time stops (from the control loop's period; the
    /// job's own thread has held it at the same deadline already).
    pub(super) fn dead_man(&mut self) {
        let now = crate::sys::monotonic_ns();
        let held_by_job = self
            .jobs
            .job
            .as_ref()
            .is_some_and(|job| job.published.dead_man_tripped.load(Ordering::Relaxed));
        if self
            .jobs
            .continuous
            .as_ref()
            .is_some_and(|c| now >= c.deadline_ns || held_by_job)
        {
            self.stop_continuous("not renewed for 250 ms: stopping (dead-man)", true);
        }
    }

    /// An E-stop or a limit switch ends the continuous jog (being checked or moving) for
    /// good: its client's renewals are refused until it lets go, so a client that keeps
    /// renewing through the trip does not start it again once the trip is cleared.
    pub(super) fn latch_stopped_jog(&mut self) {
        if self.jobs.continuous.is_some() {
            self.stop_continuous("a trip ends the continuous jog", true);
        }
    }

    /// A hold ends a continuous jog: it brakes and ends, and its renewals are refused.
    pub(super) fn hold_ends_jog(&mut self) -> bool {
        if self.jobs.continuous.is_none() {
            return false;
        }
        self.stop_continuous("held: stopping the continuous jog", true);
        true
    }

    /// Ends the continuous jog; `latch`: its client's renewals that follow are refused
    /// ([`StoppedJog`]).
    fn stop_continuous(&mut self, why: &str, latch: bool) {
        if let Some(c) = self.jobs.continuous.take()
            && latch
        {
            self.jobs.stopped_jog = Some(StoppedJog {
                axis: c.axis,
                positive: c.positive,
                last_ns: crate::sys::monotonic_ns(),
            });
        }
        if let Some(check) = &self.jobs.check {
            check.progress.cancel();
        }
        if let Some(job) = &self.jobs.job
            && matches!(job.kind, JobKind::Jog { .. })
        {
            job.stop.store(true, Ordering::Relaxed);
        }
        tracing::info!("jog: {why}");
    }
}
