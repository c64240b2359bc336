//! edmd: a real-time NURBS interpolation daemon for PC-based EDM controllers.
//!
//! See `ARCHITECTURE.md` for the module map and the invariants.

pub mod check;
pub mod cli;
pub mod config;
pub mod gcode;
pub mod geometry;
pub mod plan;
pub mod plot;
pub mod preprocess;
