//! The program a job reads: the private copy, and how far the check has read it.

pub mod program;
pub mod progress;
