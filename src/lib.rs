//! edmd: a real-time NURBS interpolation daemon for PC-based EDM controllers.
//!
//! See `ARCHITECTURE.md` for the module map and the invariants.

pub mod buffer;
pub mod check;
pub mod checkpoint;
pub mod cli;
pub mod config;
pub mod daemon;
pub mod fine;
pub mod gap;
pub mod gcode;
pub mod geometry;
pub mod output;
pub mod parport;
pub mod plan;
pub mod plot;
pub mod preprocess;
pub mod rng;
pub mod runtime;
pub mod servo;
pub mod sim;
pub mod trace;
