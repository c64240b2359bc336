//! Motion the operator asks for by hand: a jog (one positioning move on one axis, spark off,
//! held to the soft limits) and MDI (G-code lines typed in). Both become jobs through the same
//! pipeline as a program (check, soft limits, servo, turn-back, checkpoints, the state
//! file's write-ahead), from program text the daemon makes.

use std::sync::atomic::Ordering;
use std::time::Duration;

use super::Core;
use super::launch::{JobKind, Launch, Source};
use super::refusal::Refusal;
use crate::machine::travel::{JogEnd, jog_end};
use crate::vocab::Axis;

/// Longest MDI text accepted, bytes.
const MAX_MDI_BYTES: usize = 16 * 1024;
/// Longest jog, mm (and how far a continuous jog aims on an axis without soft limits).
const MAX_JOG_MM: f64 = 1.0e4;
/// How long a continuous jog moves without a renewal.
pub(super) const DEAD_MAN: Duration = Duration::from_millis(250);

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

fn sign(positive: bool) -> char {
    if positive { '+' } else { '-' }
}

impl Core {
    /// `jog AXIS DISTANCE [--feed F]`: a `G53 G0` to where the axis would be, at the jog feed
    /// (at most `machine.max_jog_feed_mm_per_min`), stopped at the soft limit it would pass.
    pub(super) fn jog(
        &mut self,
        axis: &str,
        distance_mm: f64,
        feed: Option<f64>,
    ) -> Result<String, Refusal> {
        self.refuse_if_busy()?;
        let (i, axis) = self.machine_axis(axis)?;
        self.refuse_if_tripped(Some((axis, distance_mm > 0.0)))?;
        self.refuse_if_unhomed()?;
        // Less than a step moves nothing: it would be a jog that never ends or never starts.
        let step = self.config.machine.step_mm[i];
        if !distance_mm.is_finite() || distance_mm.abs() < step || distance_mm.abs() > MAX_JOG_MM {
            return Err(Refusal::BadArgument(format!(
                "jog distance {distance_mm} mm: give a move of at least one step ({step} mm on \
                 {axis}) and at most {MAX_JOG_MM} mm, either way"
            )));
        }
        let feed = self.jog_feed(feed)?;
        let here = self.machine.state.position_mm()[i];
        let (target, note) = self.jog_target(i, axis, distance_mm)?;
        let id = self.start_jog(axis, target, feed);
        Ok(format!(
            "jog {axis} {here:.4} -> {target:.4} mm at {feed:.0} mm/min{note} (check {id})"
        ))
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
        let (i, letter) = self.machine_axis(axis)?;
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
        self.refuse_if_tripped(Some((letter, positive)))?;
        self.refuse_if_unhomed()?;
        let feed = self.jog_feed(feed)?;
        let way = if positive { MAX_JOG_MM } else { -MAX_JOG_MM };
        let (target, note) = self.jog_target(i, letter, way)?;
        let id = self.start_jog(letter, target, feed);
        self.jobs.continuous = Some(ContinuousJog {
            axis: i,
            positive,
            deadline_ns: crate::sys::monotonic_ns() + dead_man_ns(),
        });
        Ok(format!(
            "jog {letter}{} at {feed:.0} mm/min while renewed every {} ms{note} (check {id})",
            sign(positive),
            DEAD_MAN.as_millis()
        ))
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

    /// The jog feed asked for, capped at `machine.max_jog_feed_mm_per_min`.
    fn jog_feed(&self, feed: Option<f64>) -> Result<f64, Refusal> {
        let max = self.config.machine.max_jog_feed_mm_per_min;
        let min = crate::vocab::MIN_FEED_MM_PER_MIN;
        match feed {
            None => Ok(max),
            Some(f) if f.is_finite() && f >= min => Ok(f.min(max)),
            Some(f) => Err(Refusal::BadArgument(format!(
                "jog feed {f} mm/min: at least {min} mm/min (a micrometre a minute), at most \
                 machine.max_jog_feed_mm_per_min = {max}"
            ))),
        }
    }

    /// Where a jog of `distance_mm` on axis `i` ends: clamped to the soft limit it would pass
    /// (with a note), refused when the axis already stands at or past it.
    fn jog_target(&self, i: usize, axis: Axis, distance_mm: f64) -> Result<(f64, String), Refusal> {
        let here = self.machine.state.position_mm()[i];
        match jog_end(here, distance_mm, self.config.machine.travel[i]) {
            JogEnd::Full(target) => Ok((target, String::new())),
            JogEnd::AtLimit(limit) => Ok((limit, format!(" (stops at the soft limit {limit} mm)"))),
            JogEnd::Past(limit) => Err(Refusal::BadArgument(format!(
                "{axis} stands at {here:.4} mm, at or past its {} soft limit {limit} mm: \
                 jog the other way",
                if distance_mm > 0.0 { "upper" } else { "lower" }
            ))),
        }
    }

    /// Starts the check of a jog to machine coordinate `target` on `axis`; its id.
    fn start_jog(&mut self, axis: Axis, target: f64, feed: f64) -> u64 {
        let text = format!("G21 G90\nG53 G0 {}{target:.6}\n", axis.letter());
        let launch = Launch {
            technology: Default::default(),
            start: self.machine.state.work_start(),
            kind: JobKind::Jog {
                feed_mm_per_min: feed,
            },
            cut: Default::default(),
        };
        self.begin_check(
            Source::Generated {
                text,
                name: "jog".into(),
            },
            None,
            launch,
        )
    }

    /// `mdi LINES`: the lines as a job, checked like a program (soft limits included), in the
    /// work system and offsets of the machine and the units and distance mode the last MDI
    /// lines left.
    pub(super) fn mdi(&mut self, lines: &str) -> Result<String, Refusal> {
        self.refuse_if_busy()?;
        self.refuse_if_tripped(None)?;
        self.refuse_if_unhomed()?;
        if lines.trim().is_empty() || lines.len() > MAX_MDI_BYTES {
            return Err(Refusal::BadArgument(format!(
                "MDI needs 1 to {MAX_MDI_BYTES} bytes of G-code"
            )));
        }
        let mut start = self.machine.state.work_start();
        start.modes = self.machine.mdi_modes;
        let launch = Launch {
            technology: Default::default(),
            start,
            kind: JobKind::Mdi,
            cut: Default::default(),
        };
        let text = format!("{}\n", lines.trim_end());
        let id = self.begin_check(
            Source::Generated {
                text,
                name: "mdi".into(),
            },
            None,
            launch,
        );
        Ok(format!("mdi: checking (check {id})"))
    }
}
