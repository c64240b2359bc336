//! The operator's controls on their way to the tick: the feed and rapid overrides and single
//! block, and a rethread after a wire break. The daemon stores them in one word; the consumer's loop loads it every tick (one
//! relaxed load, no lock) and hands a change to the tick core, which uses it in that very
//! tick.

use std::sync::atomic::{AtomicU8, AtomicU64, Ordering};

use crate::fine::Overrides;
use crate::servo::Rethread;

/// Highest feed override, percent.
pub const MAX_FEED_OVERRIDE_PCT: u32 = 200;
/// Highest rapid override, percent.
pub const MAX_RAPID_OVERRIDE_PCT: u32 = 100;

/// The controls as the word holds them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Controls {
    pub feed_pct: u32,
    pub rapid_pct: u32,
    pub single_block: bool,
}

impl Default for Controls {
    fn default() -> Self {
        Controls {
            feed_pct: 100,
            rapid_pct: 100,
            single_block: false,
        }
    }
}

impl Controls {
    fn pack(self) -> u64 {
        u64::from(self.feed_pct.min(MAX_FEED_OVERRIDE_PCT))
            | u64::from(self.rapid_pct.min(MAX_RAPID_OVERRIDE_PCT)) << 16
            | u64::from(self.single_block) << 32
    }

    fn unpack(word: u64) -> Controls {
        Controls {
            feed_pct: (word & 0xffff) as u32,
            rapid_pct: (word >> 16 & 0xffff) as u32,
            single_block: word >> 32 & 1 == 1,
        }
    }

    /// The tick core's overrides.
    pub fn overrides(self) -> Overrides {
        Overrides {
            feed: f64::from(self.feed_pct) / 100.0,
            rapid: f64::from(self.rapid_pct) / 100.0,
        }
    }
}

/// A job's controls: written by its supervisor, read by its consumer's loop.
#[derive(Debug)]
pub struct ControlWord(AtomicU64);

impl Default for ControlWord {
    fn default() -> Self {
        ControlWord(AtomicU64::new(Controls::default().pack()))
    }
}

impl ControlWord {
    /// The supervisor: the controls from now on (overrides clamped to their ranges).
    pub fn set(&self, controls: Controls) {
        self.0.store(controls.pack(), Ordering::Relaxed);
    }

    /// The controls in force.
    #[inline]
    pub fn get(&self) -> Controls {
        Controls::unpack(self.0.load(Ordering::Relaxed))
    }

    /// The word itself: what the loop compares tick by tick.
    #[inline]
    pub fn word(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }
}

/// The controls of a word the loop loaded.
#[inline]
pub fn controls_of(word: u64) -> Controls {
    Controls::unpack(word)
}

/// A rethread asked for by the supervisor and taken by the consumer's loop, once: one
/// atomic, so the real-time loop never waits for it.
#[derive(Debug, Default)]
pub struct RethreadRequest(AtomicU8);

impl RethreadRequest {
    pub fn ask(&self, at: Rethread) {
        let code = match at {
            Rethread::AtStart => 1,
            Rethread::Here => 2,
        };
        self.0.store(code, Ordering::Release);
    }

    /// The request, if one is waiting (it is taken).
    pub fn take(&self) -> Option<Rethread> {
        match self.0.swap(0, Ordering::Acquire) {
            1 => Some(Rethread::AtStart),
            2 => Some(Rethread::Here),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_word_round_trips_and_clamps() {
        let w = ControlWord::default();
        assert_eq!(w.get(), Controls::default());
        w.set(Controls {
            feed_pct: 250,
            rapid_pct: 150,
            single_block: true,
        });
        assert_eq!(
            w.get(),
            Controls {
                feed_pct: 200,
                rapid_pct: 100,
                single_block: true
            }
        );
        w.set(Controls {
            feed_pct: 50,
            rapid_pct: 0,
            single_block: false,
        });
        assert_eq!(
            w.get().overrides(),
            Overrides {
                feed: 0.5,
                rapid: 0.0
            }
        );
        assert_eq!(controls_of(w.word()), w.get());
    }
}
