//! The estimated machining time of a plan: the planner's profile is the fastest the path may
//! go, but a cut advances only as fast as the gap erodes, which the servo decides. Each cutting
//! segment is timed at the servo's nominal feed (the condition's sparking feed where it sets
//! one, else `servo.normal_feed_mm_per_min`) when that is slower than its plan; positioning
//! (rapids, spark-off travel) and probing moves at their plan. What the gap really does (open
//! stretches faster, shorts and turn-backs slower) makes the real time differ: docs/commands.md,
//! "What `plan`'s times mean".

use crate::config::{Config, SparkingFeeds};
use crate::gcode::BlockKind;
use crate::geometry::running_max;
use crate::preprocess::Segment;

/// Sums the estimate segment by segment.
#[derive(Debug, Clone, Default)]
pub(super) struct CutTime {
    feeds: SparkingFeeds,
    /// The last condition looked up and its feed: a block's segments, forty-odd on an arc,
    /// and most programs' blocks, share one.
    last: Option<(u32, f64)>,
    /// Seconds so far.
    pub seconds: f64,
    /// In passes: the index of each pass's first block, and each pass's seconds.
    pass_starts: Vec<u64>,
    pub pass_seconds: Vec<f64>,
    /// Blocks seen so far, and the last one (its segments share it).
    blocks: u64,
    last_block: Option<std::sync::Arc<crate::gcode::Block>>,
}

impl CutTime {
    pub fn new(config: &Config) -> CutTime {
        CutTime {
            feeds: SparkingFeeds::new(config),
            last: None,
            seconds: 0.0,
            ..CutTime::default()
        }
    }

    /// The next block the path hands on starts a pass.
    pub fn pass_starts(&mut self, next_block: u64) {
        self.pass_starts.push(next_block);
        self.pass_seconds.push(0.0);
    }

    /// The nominal cutting feed of a move in `condition` (mm/s).
    fn nominal(&mut self, condition: u32) -> f64 {
        if let Some((n, feed)) = self.last
            && n == condition
        {
            return feed;
        }
        let feed = self.feeds.mm_per_s(condition);
        self.last = Some((condition, feed));
        feed
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
        // A running maximum from the duration, a number: `max`'s result, on every segment.
        let seconds = running_max(seg.duration, at_feed);
        self.seconds += seconds;
        if !self
            .last_block
            .as_ref()
            .is_some_and(|last| std::sync::Arc::ptr_eq(last, b))
        {
            self.last_block = Some(b.clone());
            self.blocks += 1;
        }
        // The pass of the block: the last one started at or before it.
        let block = self.blocks - 1;
        if let Some(k) = self.pass_starts.iter().rposition(|&s| s <= block) {
            self.pass_seconds[k] += seconds;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_conditions_feed_is_its_own_whatever_came_before() {
        let config = Config::load(None, &[]).unwrap();
        let feeds = SparkingFeeds::new(&config);
        let mut cut = CutTime::new(&config);
        for condition in [0, 2, 2, 4, 2, 9, 9, 4, 4, 0, 2, 77] {
            assert_eq!(
                cut.nominal(condition),
                feeds.mm_per_s(condition),
                "E{condition}"
            );
        }
        assert_eq!(
            feeds.mm_per_s(77),
            config.servo.normal_feed_mm_per_min / 60.0
        );
    }
}
