//! The integration tests, one crate: each file below drives the real binary or the public
//! API on real programs. One crate links once (36 crates linked the library 36 times).

mod common;
mod oracle;

mod architecture;
mod breakthrough;
mod chord_bound;
mod cli;
mod console;
mod corners;
mod daemon;
mod excursions;
mod from_line;
mod fuzz_regressions;
mod gcode_campaign;
mod gcode_errors;
mod gcode_linuxcnc;
mod hal;
mod hardening;
mod homing;
mod http;
mod http_attacks;
mod io;
mod jerk;
mod machine;
mod opcua;
mod orbit;
mod passes;
mod preprocess;
mod program_flow;
mod programs;
mod readme;
mod rethread;
mod runtime;
mod servo_laws;
mod soak;
mod tabs;
mod taper;
mod terminal;
mod touch;
mod trust;
mod turn_back;
mod wire_offset;
mod wire_offset_linuxcnc;
mod work_offsets;
