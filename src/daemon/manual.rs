//! Motion the operator asks for by hand: a jog (one positioning move on one axis, spark off,
//! held to the soft limits) and MDI (G-code lines typed in). Both become jobs through the same
//! pipeline as a program (check, soft limits, servo, turn-back, checkpoints, the state
//! file's write-ahead), from program text the daemon makes.

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use super::Core;
use super::launch::{JobKind, Launch, Source};
use super::refusal::Refusal;
use crate::vocab::Axis;

/// Longest MDI text accepted, bytes.
const MAX_MDI_BYTES: usize = 16 * 1024;
/// Longest jog, mm (and how far a continuous jog aims on an axis without soft limits).
const MAX_JOG_MM: f64 = 1.0e4;
/// How long a continuous jog moves without a renewal.
pub(super) const DEAD_MAN: Duration = Duration::from_millis(250);

/// A continuous jog: its axis and direction, and when it stops unless renewed.
pub(super) struct ContinuousJog {
    pub axis: usize,
    pub positive: bool,
    pub deadline: Instant,
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
        if !distance_mm.is_finite() || distance_mm == 0.0 || distance_mm.abs() > MAX_JOG_MM {
            return Err(Refusal::BadArgument(format!(
                "jog distance {distance_mm} mm: give a move of up to ±{MAX_JOG_MM} mm"
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
        if let Some(c) = &mut self.jobs.continuous {
            if c.axis == i && c.positive == positive {
                c.deadline = Instant::now() + DEAD_MAN;
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
            deadline: Instant::now() + DEAD_MAN,
        });
        Ok(format!(
            "jog {letter}{} at {feed:.0} mm/min while renewed every {} ms{note} (check {id})",
            sign(positive),
            DEAD_MAN.as_millis()
        ))
    }

    /// `jog-stop`: the continuous jog brakes to a standstill now.
    pub(super) fn jog_stop(&mut self) -> Result<String, Refusal> {
        if self.jobs.continuous.is_none() {
            return Err(Refusal::BadArgument("no continuous jog is moving".into()));
        }
        self.stop_continuous("stopped");
        Ok("jog: braking to a standstill".into())
    }

    /// A continuous jog not renewed in time stops (from the control loop's period).
    pub(super) fn dead_man(&mut self) {
        if self
            .jobs
            .continuous
            .as_ref()
            .is_some_and(|c| Instant::now() >= c.deadline)
        {
            self.stop_continuous("not renewed for 250 ms: stopping (dead-man)");
        }
    }

    fn stop_continuous(&mut self, why: &str) {
        self.jobs.continuous = None;
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
        match feed {
            None => Ok(max),
            Some(f) if f.is_finite() && f > 0.0 => Ok(f.min(max)),
            Some(f) => Err(Refusal::BadArgument(format!(
                "jog feed {f} mm/min must be greater than 0"
            ))),
        }
    }

    /// Where a jog of `distance_mm` on axis `i` ends: clamped to the soft limit it would pass
    /// (with a note), refused when the axis already stands at or past it.
    fn jog_target(&self, i: usize, axis: Axis, distance_mm: f64) -> Result<(f64, String), Refusal> {
        let here = self.machine.state.position_mm()[i];
        let target = here + distance_mm;
        let Some(t) = self.config.machine.travel[i] else {
            return Ok((target, String::new()));
        };
        let clamped = target.clamp(t.min_mm, t.max_mm);
        if clamped == target {
            return Ok((target, String::new()));
        }
        let limit = if distance_mm > 0.0 {
            t.max_mm
        } else {
            t.min_mm
        };
        if (limit - here) * distance_mm <= 0.0 {
            return Err(Refusal::BadArgument(format!(
                "{axis} stands at {here:.4} mm, at or past its {} soft limit {limit} mm: \
                 jog the other way",
                if distance_mm > 0.0 { "upper" } else { "lower" }
            )));
        }
        Ok((clamped, format!(" (stops at the soft limit {limit} mm)")))
    }

    /// Starts the check of a jog to machine coordinate `target` on `axis`; its id.
    fn start_jog(&mut self, axis: Axis, target: f64, feed: f64) -> u64 {
        let text = format!("G21 G90\nG53 G0 {}{target:.6}\n", axis.letter());
        let launch = Launch {
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
