//! The operator's overrides on their way to the tick: the daemon stores a percentage, the
//! consumer's loop loads both every tick (two relaxed loads, no lock) and hands a change to
//! the tick core, which uses it in that very tick.

use std::sync::atomic::{AtomicU32, Ordering};

use crate::fine::Overrides;

/// Highest feed override, percent.
pub const MAX_FEED_OVERRIDE_PCT: u32 = 200;
/// Highest rapid override, percent.
pub const MAX_RAPID_OVERRIDE_PCT: u32 = 100;

/// The feed and rapid overrides of a job, in percent.
#[derive(Debug)]
pub struct OverrideControl {
    feed_pct: AtomicU32,
    rapid_pct: AtomicU32,
}

impl Default for OverrideControl {
    fn default() -> Self {
        OverrideControl {
            feed_pct: AtomicU32::new(100),
            rapid_pct: AtomicU32::new(100),
        }
    }
}

impl OverrideControl {
    /// The supervisor: sets the feed override (clamped to 0–200 %).
    pub fn set_feed(&self, pct: u32) {
        self.feed_pct
            .store(pct.min(MAX_FEED_OVERRIDE_PCT), Ordering::Relaxed);
    }

    /// The supervisor: sets the rapid override (clamped to 0–100 %).
    pub fn set_rapid(&self, pct: u32) {
        self.rapid_pct
            .store(pct.min(MAX_RAPID_OVERRIDE_PCT), Ordering::Relaxed);
    }

    /// Feed and rapid override, percent.
    #[inline]
    pub fn percent(&self) -> (u32, u32) {
        (
            self.feed_pct.load(Ordering::Relaxed),
            self.rapid_pct.load(Ordering::Relaxed),
        )
    }
}

/// The tick core's overrides for percentages.
#[inline]
pub fn fractions((feed, rapid): (u32, u32)) -> Overrides {
    Overrides {
        feed: f64::from(feed) / 100.0,
        rapid: f64::from(rapid) / 100.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentages_are_clamped_and_become_fractions() {
        let c = OverrideControl::default();
        assert_eq!(c.percent(), (100, 100));
        c.set_feed(250);
        c.set_rapid(150);
        assert_eq!(c.percent(), (200, 100));
        c.set_feed(50);
        c.set_rapid(0);
        assert_eq!(
            fractions(c.percent()),
            Overrides {
                feed: 0.5,
                rapid: 0.0
            }
        );
    }
}
