//! The fine interpolator's fixed parameters, as `config` hands them down.

use super::{BreakthroughSettings, ExcursionSettings};
use crate::servo::{Feeds, Law, ShortRules};
use crate::vocab::MAX_AXES;

/// The fine interpolator's fixed parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FineSettings {
    /// Tick period (s).
    pub dt: f64,
    /// Tangential acceleration limit (mm/s²).
    pub accel: f64,
    /// The servo's own acceleration (mm/s²): braking into a turn-back, the reversal, and the
    /// turn-back and re-advance themselves (`servo.reverse_accel_mm_per_s2`).
    pub reverse_accel: f64,
    pub feeds: Feeds,
    /// When a short is believed and how far a turn-back goes at least.
    pub shorts: ShortRules,
    /// Step size per axis (mm); unused axes 0.
    pub step_mm: [f64; MAX_AXES],
    /// A short lasting this many ticks raises the alarm (0: only the reserved history does).
    pub max_short_ticks: u64,
    /// The servo law (it reads what [`Interpolator::tick_measured`] is given).
    pub law: Law,
    /// Jumps, wire-break detection and rethreading.
    pub excursions: ExcursionSettings,
    /// A dry run: the program's moves at their planned feed with the spark off and the servo
    /// out of the loop (a short is a collision, as on a rapid).
    pub dry_run: bool,
    /// Breakthrough on drilling moves.
    pub breakthrough: BreakthroughSettings,
    /// Jerk limit of rapids, jumps and rethread returns (mm/s³); 0: trapezoids.
    pub jerk: f64,
    /// The tool axis (Z) a jump off an orbit lifts along; `None`: the machine has none.
    pub lift_axis: Option<usize>,
}
