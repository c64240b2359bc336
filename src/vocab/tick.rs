//! The fine interpolator's tick period.

/// The fine interpolator's tick period: the one place a tick is converted to seconds or
/// nanoseconds.
///
/// The configuration gives it in whole microseconds (`fine.tick_us`, 1 to 1,000,000); the
/// tick core integrates speed over [`secs`](Self::secs), the real-time loop sleeps in
/// [`ns`](Self::ns), and reports turn tick counts into seconds with
/// [`ticks_to_secs`](Self::ticks_to_secs). Every conversion goes through these methods, so
/// the rounding is the same everywhere (a pulse log replayed against a summary agrees to the
/// last bit).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TickPeriod {
    us: u32,
}

impl TickPeriod {
    /// Longest period accepted (1 s).
    pub const MAX_US: u32 = 1_000_000;

    /// A period of `us` microseconds, `None` outside 1 to [`MAX_US`](Self::MAX_US).
    pub const fn from_us(us: u32) -> Option<TickPeriod> {
        if us >= 1 && us <= Self::MAX_US {
            Some(TickPeriod { us })
        } else {
            None
        }
    }

    /// The period in whole microseconds (as configured, and as the pulse log records it).
    pub const fn us(self) -> u32 {
        self.us
    }

    /// The period in nanoseconds (the real-time loop's deadlines).
    pub const fn ns(self) -> u64 {
        self.us as u64 * 1000
    }

    /// The period in seconds (the tick core's `dt`).
    pub fn secs(self) -> f64 {
        self.us as f64 * 1e-6
    }

    /// The time `ticks` ticks take, in seconds.
    pub fn ticks_to_secs(self, ticks: u64) -> f64 {
        ticks as f64 * self.secs()
    }
}

impl std::fmt::Display for TickPeriod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} µs", self.us)
    }
}
