//! Helpers shared by the integration tests.

pub mod daemon;
pub mod hal;
pub mod linuxcnc;
pub mod web;
pub mod wire;

use std::path::PathBuf;
use std::sync::{Condvar, Mutex};

/// The test machine's cores, shared by the daemons the tests start. The load test
/// (`tests/it/load.rs`) saturates both for seconds on purpose; a daemon whose timing another
/// test measures (a dead-man's 300 ms, an E-stop's milliseconds) must not run beside it.
/// Every daemon holds a share while it lives; the load test holds the whole machine: it
/// waits until no daemon runs (between two tests of the other test thread), and no daemon
/// starts until it is done. A share never waits for a test that only waits for the whole
/// machine, so a test that starts a second daemon beside its first cannot deadlock. Within
/// one test process, as `cargo test` runs the suite; a runner with a process per test does
/// not see it.
static MACHINE: Mutex<Holders> = Mutex::new(Holders {
    shares: 0,
    whole: false,
});
static MACHINE_CHANGED: Condvar = Condvar::new();

struct Holders {
    shares: usize,
    whole: bool,
}

/// A daemon's hold on the machine: a share, or all of it; given back on drop.
pub struct MachineHold {
    whole: bool,
}

impl MachineHold {
    fn take(whole: bool) -> MachineHold {
        let mut holders = MACHINE.lock().unwrap_or_else(|e| e.into_inner());
        while holders.whole || (whole && holders.shares > 0) {
            holders = MACHINE_CHANGED
                .wait(holders)
                .unwrap_or_else(|e| e.into_inner());
        }
        if whole {
            holders.whole = true;
        } else {
            holders.shares += 1;
        }
        MachineHold { whole }
    }

    /// A share: waits while a test holds the whole machine.
    pub fn share() -> MachineHold {
        MachineHold::take(false)
    }

    /// The whole machine: waits until no share is held.
    pub fn whole() -> MachineHold {
        MachineHold::take(true)
    }
}

impl Drop for MachineHold {
    fn drop(&mut self) {
        let mut holders = MACHINE.lock().unwrap_or_else(|e| e.into_inner());
        if self.whole {
            holders.whole = false;
        } else {
            holders.shares -= 1;
        }
        MACHINE_CHANGED.notify_all();
    }
}

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

/// `edmd plan` then `edmd run` of `program` on the shipped configuration (simulated gap,
/// virtual time), each with `args`: the plan's summary and the run's.
pub fn plan_and_run(
    dir: &std::path::Path,
    program: &std::path::Path,
    args: &[&str],
) -> (serde_json::Value, serde_json::Value) {
    let config = repo().join("config/edmd.toml");
    let edmd = |command: &str, out: &[&std::ffi::OsStr]| {
        let output = std::process::Command::new(env!("CARGO_BIN_EXE_edmd"))
            .arg(command)
            .arg("--config")
            .arg(&config)
            .args(args)
            .args(out)
            .arg(program)
            .output()
            .unwrap();
        assert!(
            output.status.success(),
            "edmd {command}: {}",
            String::from_utf8_lossy(&output.stderr)
        );
    };
    let read = |path: &std::path::Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
    };
    let plan = dir.join("plan");
    edmd(
        "plan",
        &["--quiet".as_ref(), "--out".as_ref(), plan.as_os_str()],
    );
    let summary = dir.join("summary.json");
    edmd("run", &["--summary".as_ref(), summary.as_os_str()]);
    (read(&plan.join("summary.json")), read(&summary))
}
