//! edmd: a real-time NURBS interpolation daemon for PC-based EDM controllers.
//!
//! See `ARCHITECTURE.md` for the module map, the floors they stand on and the invariants.
//! The modules below are listed floor by floor, lowest first; a module imports only from its
//! own floor or below (`tests/it/architecture/` checks it).
//!
//! `unsafe` is denied everywhere except the kernel-facing modules that allow it by name:
//! [`sys`]'s clock, real-time, group look-up and descriptor-limit wrappers,
//! [`parport::ioctl`] and the HAL library's calls (`hal::ffi`).

#![deny(unsafe_code)]
#![warn(clippy::undocumented_unsafe_blocks)]

// Floor 0: vocabulary, kernel calls, the seeded generator, SVG charts and the terminal,
// importing nothing of edmd's above them (the terminal reads the local time through sys).
pub mod decimal;
pub mod plot;
pub mod rng;
pub mod sys;
pub mod term;
pub mod vocab;
pub mod words;
// Floor 1: curves.
pub mod geometry;
// Floor 2: programs.
pub mod gcode;
// Floor 3: the path, every rewrite of the program's blocks (wire offset, taper, orbit, passes,
// tabs, run from a line).
pub mod path;
// Floor 4: the producer's algorithm (segmentation, feed planning).
pub mod preprocess;
// Floor 5: the loop buffer.
pub mod buffer;
// Floor 6: the tick core, its servo and the process in force.
pub mod fine;
pub mod process;
pub mod servo;
// Floor 7: the machine's two sides (pulse outputs, gap and machine inputs), their devices and
// wrappers.
pub mod gap;
pub mod hal;
pub mod inputs;
pub mod output;
pub mod parport;
pub mod record;
pub mod sim;
pub mod trace;
// Floor 8: configuration, read at the edge and handed down as plain values.
pub mod config;
// Floor 9: reports, checkpoints, the machine state, the setup cycles and the job runner.
pub mod check;
pub mod checkpoint;
pub mod machine;
pub mod plan;
pub mod report;
pub mod runtime;
pub mod technology;
pub mod touch;
// Floor 10: the daemon.
pub mod daemon;
// Floor 11: the command line.
pub mod cli;
