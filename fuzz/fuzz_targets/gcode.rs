#![no_main]
//! `cargo +nightly fuzz run gcode`: see `fuzz/checks.rs` for what is checked.

#[path = "../checks.rs"]
mod checks;

libfuzzer_sys::fuzz_target!(|data: &[u8]| checks::gcode(data));
