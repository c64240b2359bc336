//! What shapes the program a job cuts: the private copy and its reading progress, passes from
//! the technology table, tabs, the approach of a run from a line, and the stages of a sinker
//! job.

pub mod from_line;
pub mod passes;
pub mod program;
pub mod progress;
pub mod stages;
pub mod tabs;
