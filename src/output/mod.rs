//! Pulse outputs: where the consumer's steps go.
//!
//! A [`PulseOutput`] receives every tick's signed steps (at most one per axis) with the gap
//! state of that tick, from the consumer's thread loop. Outputs here: [`PulseLog`]
//! (`output.kind = "file"`, the CSV pulse log of `design.md`) and [`NullOutput`]
//! (`"null"`: steps are counted by the ledger and go nowhere). The parallel port and the
//! closed-loop simulator are issue [4/6].

mod pulse_log;

pub use pulse_log::{PulseLog, PulseLogHeader, PulseLogRow, read_pulse_log};

use crate::gap::GapState;
use crate::geometry::MAX_AXES;

/// An output that failed: which one and why.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("{path}: cannot write the pulse log: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
}

/// A destination for step pulses.
pub trait PulseOutput {
    /// The steps of tick `tick` (-1, 0 or 1 per axis, axes in machine order) and the gap state
    /// sampled for it. Called once per tick, in tick order.
    fn write(
        &mut self,
        tick: u64,
        steps: &[i8; MAX_AXES],
        gap: GapState,
    ) -> Result<(), OutputError>;

    /// The job is over: everything written reaches its destination, outputs go inactive.
    fn finish(&mut self) -> Result<(), OutputError>;
}

/// `output.kind = "null"`: discards everything.
#[derive(Debug, Clone, Copy, Default)]
pub struct NullOutput;

impl PulseOutput for NullOutput {
    fn write(&mut self, _: u64, _: &[i8; MAX_AXES], _: GapState) -> Result<(), OutputError> {
        Ok(())
    }

    fn finish(&mut self) -> Result<(), OutputError> {
        Ok(())
    }
}

impl<O: PulseOutput + ?Sized> PulseOutput for Box<O> {
    fn write(
        &mut self,
        tick: u64,
        steps: &[i8; MAX_AXES],
        gap: GapState,
    ) -> Result<(), OutputError> {
        (**self).write(tick, steps, gap)
    }

    fn finish(&mut self) -> Result<(), OutputError> {
        (**self).finish()
    }
}
