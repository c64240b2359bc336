//! The shared vocabulary: the few plain types that every floor of edmd speaks.
//!
//! Axis letters, the two predictor and segmentation kinds, the spark gap's state and the
//! tick period are named by the G-code reader, the preprocessor, the tick core, the devices
//! and the configuration alike. They live here, in a module that imports nothing of edmd's,
//! so that no lower floor has to reach up into `config` (or `gap`) for a word: the
//! configuration *reads* these values at the edge and hands them down.
//!
//! Must never: import another edmd module, do I/O, or grow behaviour beyond naming,
//! parsing and converting its own values.

mod gap;
mod modes;
mod motion;
mod safety;
mod text;
mod tick;

pub use gap::{GapState, GapVolts, GeneratorSetPoints, PulseCounts};
pub use modes::{OrbitShape, Predictor, Segmentation};
pub use motion::{Axis, Guides, MAX_AXES, MIN_FEED_MM_PER_MIN, Steps};
pub use safety::{HomeSwitch, LimitSet, LimitSwitch, ProbeReads, SafetyInputs, Trip};
pub use text::{BOM, Num, without_bom};
pub use tick::TickPeriod;

#[cfg(test)]
mod tests;
