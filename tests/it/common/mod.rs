//! Helpers shared by the integration tests.

pub mod daemon;
pub mod linuxcnc;
pub mod web;
pub mod wire;

use std::path::PathBuf;

/// The repository root (where `edmd` runs in the tests).
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `edmd run PROGRAM` with no gap, its pulses into the pulse log `pulses`, and `args`.
pub fn run_to_pulse_log(
    program: &std::path::Path,
    pulses: &std::path::Path,
    args: &[&str],
) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_edmd"))
        .arg("run")
        .arg(program)
        .args([
            "--set",
            "gap.kind=\"none\"",
            "--set",
            "output.kind=\"file\"",
        ])
        .arg("--set")
        .arg(format!("output.path=\"{}\"", pulses.display()))
        .args(args)
        .output()
        .unwrap()
}

/// A scratch directory for one test of one test binary, kept apart by process id.
pub fn scratch(suite: &str, name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("edmd-{suite}-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}
