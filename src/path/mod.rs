//! The path: every rewrite of the program's blocks between the G-code reader and the
//! preprocessor, as stages over blocks.
//!
//! The reader ([`crate::gcode`]) says what the program means: each move as programmed, with
//! the modes it is cut in stamped on it (the wire offset, the taper, the condition). What the
//! machine then cuts is those moves rewritten, in this order:
//!
//! ```text
//!  reader ─► wire offset ─► taper ─► orbit ─► pass ─► run from a line ─► reversal ─► blocks
//!            (G41/G42)     (G51/G52) (sinker) (condition, feed)  (approach)  (a pass cut
//!                                                                           the other way)
//! ```
//!
//! Each stage ([`Stage`]) takes blocks one at a time and hands on the ones it has made final,
//! holding what it must look ahead for (the wire offset one move, the taper one line, a
//! reversed pass all of it); at the program's end each stage hands on what it held, in order.
//! The geometric stages ([`wire_offset`], [`taper`], [`orbit`]) are the program's
//! ([`Pipeline`]); the job's ([`passes`], [`from_line`], [`tabs`]) are added by what the job
//! cuts ([`CutPlan`]). [`JobPath`] builds the whole of a job's path from one [`PathSpec`]:
//! the check before a job, the producer, `plan` and the report all read that one path, so
//! what is checked is what is cut, and a resume replays the same blocks.
//!
//! Nothing here reads a file other than through the reader, or knows the configuration: the
//! spec is plain settings.

mod approach;
pub mod from_line;
mod job;
pub mod orbit;
pub mod passes;
mod pipeline;
pub mod stages;
pub mod tabs;
pub mod taper;
pub mod wire_offset;

use std::collections::VecDeque;

use crate::gcode::{Block, GcodeError, GcodeErrorKind};

pub use from_line::{Approach, ApproachPlan, FromLine, FromLineError, Gate, WireAt};
pub use job::{CutPlan, JobPath, PathItem, PathSpec};
pub use passes::{PassError, WirePass};
pub use pipeline::Pipeline;
pub use stages::{MAX_STAGES, StageRow};
pub use tabs::TabError;

/// One rewrite of the program's blocks.
pub trait Stage {
    /// Takes the next block; hands the blocks it has made final to `out`, in order.
    fn push(&mut self, block: Block, out: &mut VecDeque<Block>) -> Result<(), StageError>;

    /// The program has ended: hands what it holds to `out`.
    fn finish(&mut self, _out: &mut VecDeque<Block>) -> Result<(), StageError> {
        Ok(())
    }

    /// [`push`](Self::push) would hand `block` on unchanged, at once, and change nothing:
    /// the path skips the stage (most blocks of most programs meet no offset, taper or
    /// orbit, and a block is a few hundred bytes to move).
    fn passes(&self, _block: &Block) -> bool {
        false
    }
}

/// Why a stage refused a block.
#[derive(Debug)]
pub enum StageError {
    /// What the move at `line` asks cannot be cut: the reader says where, with its calls.
    Move { line: u64, kind: GcodeErrorKind },
    /// What the job asks cannot be done with the program.
    Job(PathError),
}

impl From<FromLineError> for StageError {
    fn from(e: FromLineError) -> StageError {
        StageError::Job(e.into())
    }
}

impl From<PassError> for StageError {
    fn from(e: PassError) -> StageError {
        StageError::Job(e.into())
    }
}

/// Why a job's path could not be made.
#[derive(Debug, thiserror::Error)]
pub enum PathError {
    #[error(transparent)]
    Program(#[from] GcodeError),
    #[error(transparent)]
    FromLine(#[from] FromLineError),
    #[error(transparent)]
    Passes(#[from] PassError),
    #[error(transparent)]
    Tabs(#[from] TabError),
}

impl PathError {
    /// The reader was cancelled (a stop, an abort), nothing is wrong with the program.
    pub fn cancelled(&self) -> bool {
        matches!(self, PathError::Program(e) if matches!(e.kind, GcodeErrorKind::Cancelled))
    }
}
