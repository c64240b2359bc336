//! Why a job could not start.

use super::super::shaping::program;
use super::producer::ProducerError;
use crate::gap::ScriptError;
use crate::gcode::GcodeError;
use crate::output::OutputError;
use crate::parport::ParportError;

/// A job that could not start: bad program, gap script or output. Nothing has moved.
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    #[error(transparent)]
    Program(#[from] GcodeError),
    #[error(transparent)]
    Producer(#[from] ProducerError),
    #[error(transparent)]
    GapScript(#[from] ScriptError),
    #[error(transparent)]
    Iio(#[from] crate::gap::IioError),
    #[error(transparent)]
    Output(#[from] OutputError),
    #[error(transparent)]
    Parport(#[from] ParportError),
    #[error(transparent)]
    Hal(#[from] crate::hal::HalError),
    #[error("cannot start the fine interpolation thread: {0}")]
    Thread(std::io::Error),
    /// A combination of settings that cannot run (the validated configuration refuses it).
    #[error("{0}")]
    Config(String),
    #[error(transparent)]
    Copy(#[from] program::CopyError),
    #[error(transparent)]
    Travel(#[from] crate::machine::travel::TravelError),
    #[error("{program}: the check was cancelled")]
    Cancelled { program: String },
    #[error(transparent)]
    Path(#[from] crate::path::PathError),
}

impl From<crate::path::PassError> for JobError {
    fn from(e: crate::path::PassError) -> JobError {
        JobError::Path(e.into())
    }
}
