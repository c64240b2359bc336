//! Helpers shared by the integration tests.

pub mod daemon;
pub mod hal;
pub mod linuxcnc;
pub mod web;
pub mod wire;

use std::path::PathBuf;

/// The blocks a program's own path makes (wire offset, taper, orbit) from what `reader`
/// reads, its errors as the reader's: the path a job of the whole program cuts.
pub fn program_path<R: std::io::BufRead + std::io::Seek>(
    reader: edmd::gcode::BlockReader<R>,
) -> impl Iterator<Item = Result<edmd::gcode::Block, edmd::gcode::GcodeError>> {
    edmd::path::Pipeline::new(reader).map(|item| {
        item.map_err(|e| match e {
            edmd::path::PathError::Program(e) => e,
            other => panic!("a program's own path fails only as a program: {other}"),
        })
    })
}

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
