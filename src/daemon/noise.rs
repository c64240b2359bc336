//! Log lines a stranger can cause: a refused host, a wrong password, a malformed protocol
//! message. Each kind has a [`Budget`]: the first [`PER_MINUTE`] of a minute are logged at
//! `warn`, the rest at `debug`, and the next line at `warn` says how many went to `debug`,
//! so a client that repeats itself cannot fill the journal, and an operator still sees that
//! it happens.

use std::sync::atomic::{AtomicU64, Ordering};

/// Lines of one kind logged at `warn` a minute.
pub const PER_MINUTE: u64 = 10;

/// A kind of noise's allowance: the minute it counts in and how many lines it has had.
#[derive(Debug, Default)]
pub struct Budget {
    /// The minute (monotonic) and the lines counted in it, packed: minute << 20 | count.
    state: AtomicU64,
    /// Lines sent to `debug` since the last `warn`.
    quiet: AtomicU64,
}

/// How a line is to be logged.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Loudness {
    /// At `warn`; with the number of lines of its kind logged at `debug` since the last one.
    Warn {
        quieted: u64,
    },
    Debug,
}

impl Budget {
    pub const fn new() -> Budget {
        Budget {
            state: AtomicU64::new(0),
            quiet: AtomicU64::new(0),
        }
    }

    /// How the next line is logged, at monotonic time `now_ns`.
    pub fn spend(&self, now_ns: u64) -> Loudness {
        let minute = now_ns / 60_000_000_000 + 1;
        let mut current = self.state.load(Ordering::Relaxed);
        loop {
            let (at, count) = (current >> 20, current & 0xF_FFFF);
            let next = if at == minute {
                minute << 20 | (count + 1).min(0xF_FFFF)
            } else {
                minute << 20 | 1
            };
            match self.state.compare_exchange_weak(
                current,
                next,
                Ordering::Relaxed,
                Ordering::Relaxed,
            ) {
                Ok(_) => {
                    return if next & 0xF_FFFF <= PER_MINUTE {
                        Loudness::Warn {
                            quieted: self.quiet.swap(0, Ordering::Relaxed),
                        }
                    } else {
                        self.quiet.fetch_add(1, Ordering::Relaxed);
                        Loudness::Debug
                    };
                }
                Err(seen) => current = seen,
            }
        }
    }

    /// Logs `line` as [`spend`](Self::spend) decides, now.
    pub fn log(&self, line: std::fmt::Arguments<'_>) {
        match self.spend(crate::sys::monotonic_ns()) {
            Loudness::Warn { quieted: 0 } => tracing::warn!("{line}"),
            Loudness::Warn { quieted } => {
                tracing::warn!("{line} ({quieted} more like it logged at debug)")
            }
            Loudness::Debug => tracing::debug!("{line}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ten_a_minute_at_warn_the_rest_at_debug_counted() {
        let budget = Budget::new();
        let minute = 60_000_000_000;
        for i in 0..PER_MINUTE {
            assert_eq!(budget.spend(i), Loudness::Warn { quieted: 0 });
        }
        for i in 0..5 {
            assert_eq!(budget.spend(1000 + i), Loudness::Debug);
        }
        assert_eq!(budget.spend(minute), Loudness::Warn { quieted: 5 });
        assert_eq!(budget.spend(minute + 1), Loudness::Warn { quieted: 0 });
    }
}
