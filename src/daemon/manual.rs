//! Motion the operator asks for by hand: a jog (one positioning move on one axis, spark off,
//! held to the soft limits) and MDI (G-code lines typed in). Both become jobs through the same
//! pipeline as a program (check, soft limits, servo, turn-back, checkpoints, the state
//! file's write-ahead), from program text the daemon makes.

use super::Core;
use super::launch::{JobKind, Launch, Source};
use super::refusal::Refusal;

/// Longest MDI text accepted, bytes.
const MAX_MDI_BYTES: usize = 16 * 1024;

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
        self.refuse_if_unhomed()?;
        let (i, axis) = self.machine_axis(axis)?;
        if !distance_mm.is_finite() || distance_mm == 0.0 || distance_mm.abs() > 1.0e4 {
            return Err(Refusal::BadArgument(format!(
                "jog distance {distance_mm} mm: give a move of up to ±10000 mm"
            )));
        }
        let max = self.config.machine.max_jog_feed_mm_per_min;
        let feed = match feed {
            None => max,
            Some(f) if f.is_finite() && f > 0.0 => f.min(max),
            Some(f) => {
                return Err(Refusal::BadArgument(format!(
                    "jog feed {f} mm/min must be greater than 0"
                )));
            }
        };
        let here = self.machine.state.position_mm()[i];
        let mut target = here + distance_mm;
        let mut note = String::new();
        if let Some(t) = self.config.machine.travel[i] {
            let clamped = target.clamp(t.min_mm, t.max_mm);
            if clamped != target {
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
                note = format!(" (stops at the soft limit {limit} mm)");
                target = clamped;
            }
        }
        let text = format!("G21 G90\nG53 G0 {}{target:.6}\n", axis.letter());
        let launch = Launch {
            start: self.machine.state.work_start(),
            kind: JobKind::Jog {
                feed_mm_per_min: feed,
            },
        };
        let id = self.begin_check(
            Source::Generated {
                text,
                name: "jog".into(),
            },
            None,
            launch,
        );
        Ok(format!(
            "jog {axis} {here:.4} -> {target:.4} mm at {feed:.0} mm/min{note} (check {id})"
        ))
    }

    /// `mdi LINES`: the lines as a job, checked like a program (soft limits included), in the
    /// work system and offsets of the machine and the units and distance mode the last MDI
    /// lines left.
    pub(super) fn mdi(&mut self, lines: &str) -> Result<String, Refusal> {
        self.refuse_if_busy()?;
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
