//! The operator's controls over a running job that are not motion of their own: the feed
//! and rapid overrides, single block. They reach the tick through the job's published controls
//! ([`crate::runtime::controls`]); the daemon keeps them for the jobs after.

use super::jobs::JobControl;
use super::protocol::OverrideKind;
use super::refusal::Refusal;
use crate::runtime::controls::{MAX_FEED_OVERRIDE_PCT, MAX_RAPID_OVERRIDE_PCT};

impl JobControl {
    /// `override feed|rapid PERCENT`: in force from the running job's next tick (if one
    /// runs) and for every job after.
    pub(super) fn set_override(
        &mut self,
        kind: OverrideKind,
        percent: f64,
    ) -> Result<String, Refusal> {
        let (name, max) = match kind {
            OverrideKind::Feed => ("feed", MAX_FEED_OVERRIDE_PCT),
            OverrideKind::Rapid => ("rapid", MAX_RAPID_OVERRIDE_PCT),
        };
        // Whole percent, as every console shows them: a fraction would be shown as another
        // number than the one given.
        if !(percent.is_finite() && (0.0..=f64::from(max)).contains(&percent))
            || percent.fract() != 0.0
        {
            return Err(Refusal::BadArgument(format!(
                "{name} override {percent} %: give a whole percent from 0 to {max}"
            )));
        }
        let pct = percent as u32;
        let controls = &mut self.controls;
        let was = match kind {
            OverrideKind::Feed => std::mem::replace(&mut controls.feed_pct, pct),
            OverrideKind::Rapid => std::mem::replace(&mut controls.rapid_pct, pct),
        };
        let running = self.publish_controls();
        tracing::info!(
            edmd_event = "override",
            "{name} override {was} % -> {pct} %{}",
            if running {
                " (the running job takes it at its next tick)"
            } else {
                " (for the next job)"
            }
        );
        Ok(format!("{name} override {pct} %"))
    }

    /// `single-block on|off`: in force from the running job's next block end, and for every
    /// job after.
    pub(super) fn set_single_block(&mut self, on: bool) -> Result<String, Refusal> {
        self.controls.single_block = on;
        self.publish_controls();
        let state = if on { "on" } else { "off" };
        tracing::info!(edmd_event = "single_block", "single block {state}");
        Ok(format!(
            "single block {state}{}",
            if on {
                ": the job stops before each program block; `resume` runs the next"
            } else {
                ""
            }
        ))
    }

    /// A new job's published controls, at the controls in force.
    pub(super) fn published(&self) -> crate::runtime::consumer::Published {
        let published = crate::runtime::consumer::Published::new(4096);
        published.controls.set(self.controls);
        published
    }

    /// Hands the controls in force to the running job; `false` when none runs.
    fn publish_controls(&self) -> bool {
        self.job
            .as_ref()
            .map(|job| job.published.controls.set(self.controls))
            .is_some()
    }
}
