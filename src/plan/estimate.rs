//! The estimated machining time of a plan: the planner's profile is the fastest the path may
//! go, but a cut advances only as fast as the gap erodes, which the servo decides. Each cutting
//! segment is timed at the servo's nominal feed (the condition's sparking feed where it sets
//! one, else `servo.normal_feed_mm_per_min`) when that is slower than its plan; positioning
//! (rapids, spark-off travel) and probing moves at their plan. What the gap really does (open
//! stretches faster, shorts and turn-backs slower) makes the real time differ: README,
//! "What `plan`'s times mean".

use crate::config::Config;
use crate::gcode::BlockKind;
use crate::preprocess::Segment;

/// Sums the estimate segment by segment.
#[derive(Debug, Clone, Default)]
pub(super) struct CutTime {
    /// The nominal feed of cutting without a condition of its own (mm/s).
    normal: f64,
    /// Conditions' sparking feeds (number, mm/s).
    conditions: Vec<(u32, f64)>,
    /// Seconds so far.
    pub seconds: f64,
}

impl CutTime {
    pub fn new(config: &Config) -> CutTime {
        CutTime {
            normal: config.servo.normal_feed_mm_per_min / 60.0,
            conditions: config
                .conditions
                .iter()
                .map(|c| (c.number, c.feed_mm_per_min / 60.0))
                .collect(),
            seconds: 0.0,
        }
    }

    /// The nominal cutting feed of a move in `condition` (mm/s).
    fn nominal(&self, condition: u32) -> f64 {
        self.conditions
            .iter()
            .find(|(n, _)| *n == condition)
            .map_or(self.normal, |(_, f)| *f)
    }

    pub fn add(&mut self, seg: &Segment) {
        let b = &seg.block;
        let cutting =
            !matches!(b.kind, BlockKind::Rapid | BlockKind::Probe(_)) && b.spark_off.is_none();
        let at_feed = if cutting && seg.length > 0.0 {
            seg.length / self.nominal(b.condition)
        } else {
            0.0
        };
        self.seconds += seg.duration.max(at_feed);
    }
}
