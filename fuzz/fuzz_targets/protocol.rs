#![no_main]
//! `cargo +nightly fuzz run protocol`: see `fuzz/checks.rs` for what is checked.

#[path = "../checks.rs"]
mod checks;

libfuzzer_sys::fuzz_target!(|data: &[u8]| checks::protocol(data));
