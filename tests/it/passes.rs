//! Skim passes from the technology table (`[[wire.pass]]`, `--passes N`), through the real
//! binary on a die: from the pulse log, every pass's path lies at its own offset from the
//! contour, the direction alternates where the table says `reverse`, each pass cuts in its
//! condition, the job ends on the program's end point; programs that cannot be cut in passes
//! are refused before anything moves; a job stopped in its second pass resumes (a new daemon)
//! to the same pulses as an uninterrupted run.

use crate::common;

use std::path::Path;

use common::daemon::{Daemon, base_sets};
use common::wire::{DIE, PASSES, PUNCH, TABLE, inside_die, outside_punch, positions_by_condition};

fn setup(name: &str) -> std::path::PathBuf {
    let dir = common::scratch("passes", name);
    std::fs::write(dir.join("wire.toml"), TABLE).unwrap();
    std::fs::write(dir.join("die.ngc"), DIE).unwrap();
    std::fs::write(dir.join("punch.ngc"), PUNCH).unwrap();
    dir
}

fn run(dir: &Path, program: &str, pulses: &str, args: &[&str]) -> std::process::Output {
    let config = dir.join("wire.toml");
    let mut all = vec!["--config", config.to_str().unwrap()];
    all.extend(args);
    common::run_to_pulse_log(&dir.join(program), &dir.join(pulses), &all)
}

/// How far a point (µm) lies from the part's contour, on the scrap side.
type Distance = dyn Fn(&(i64, i64)) -> i64;

#[test]
fn each_pass_cuts_at_its_offset_in_its_condition_and_direction_and_ends_at_the_start() {
    let dir = setup("cli");
    let parts: [(&str, &Distance); 2] = [("die", &inside_die), ("punch", &outside_punch)];
    for (part, distance) in parts {
        let report = dir.join(format!("report-{part}"));
        let pulses = format!("{part}.csv");
        let out = run(
            &dir,
            &format!("{part}.ngc"),
            &pulses,
            &["--passes", "3", "--report", report.to_str().unwrap()],
        );
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        // The report marks where each pass starts.
        let events = std::fs::read_to_string(report.join("events.csv")).unwrap();
        let marks: Vec<&str> = events
            .lines()
            .filter_map(|l| {
                let f: Vec<&str> = l.split(',').collect();
                (f.get(3) == Some(&"pass")).then(|| f[4])
            })
            .collect();
        assert_eq!(marks, ["1", "2", "3"], "{part}: {events}");
        let (by, end) = positions_by_condition(&dir.join(&pulses));
        assert_eq!(
            end,
            (0, 0),
            "{part}: the job ends on the program's end point"
        );
        assert_eq!(by.keys().copied().collect::<Vec<_>>(), vec![1, 2, 3]);
        for (condition, offset, direction) in PASSES {
            common::wire::assert_pass(
                &format!("{part} E{condition}"),
                &by[&condition],
                distance,
                (offset * 1000.0).round() as i64,
                direction,
            );
        }
    }
}

#[test]
fn what_cannot_be_cut_in_passes_is_refused_before_anything_moves() {
    let dir = setup("refused");
    let out = run(&dir, "die.ngc", "p.csv", &["--passes", "4"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--passes 4: [wire] pass has 3 passes"));
    std::fs::write(dir.join("open.ngc"), "G21 G90\nG1 X3 F600\nM2\n").unwrap();
    let out = run(&dir, "open.ngc", "p.csv", &["--passes", "2"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("passes need a program that ends where it starts"),
        "{err}"
    );
    // In the work system the job starts in, and what to do about it.
    assert!(err.contains("ends at X3.0000 Y0.0000 (G54)"), "{err}");
    assert!(
        err.contains("Start the job with the wire at the program's start hole"),
        "{err}"
    );
    assert!(
        !dir.join("p.csv").exists() || std::fs::metadata(dir.join("p.csv")).unwrap().len() < 200
    );
    std::fs::write(dir.join("probe.ngc"), "G21 G90\nG38.3 X3 F100\nG0 X0\nM2\n").unwrap();
    let out = run(&dir, "probe.ngc", "p.csv", &["--passes", "1"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("probe.ngc:2:1: a probing move cannot be cut in passes"),
        "{err}"
    );
}

#[test]
fn a_job_stopped_in_its_second_pass_resumes_to_the_uninterrupted_pulses() {
    let dir = common::daemon::scratch("passes");
    std::fs::write(dir.join("wire.toml"), TABLE).unwrap();
    std::fs::write(dir.join("programs/die.ngc"), DIE).unwrap();
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    let config = dir.join("wire.toml");
    let args = ["--config".to_string(), config.display().to_string()];
    let daemon = Daemon::start_args(&dir, &args, &base_sets(&dir, "first.csv"), &[]);
    daemon.refused(&["run", "die.ngc", "--passes", "0"], "counts from 1");
    daemon.ok(&["run", "die.ngc", "--passes", "3"]);
    let s = daemon.wait_for("the second pass", |s| {
        s["state"] == "running" && s["job"]["progress"].as_f64().unwrap_or(0.0) > 0.45
    });
    assert_eq!(s["job"]["passes"], 3, "{s}");
    let cp = daemon.hold_abort_checkpoint(&dir);
    assert_eq!(cp["passes"].as_array().map(Vec::len), Some(3), "{cp}");
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);

    let daemon = Daemon::start_args(&dir, &args, &base_sets(&dir, "second.csv"), &[]);
    daemon.resume_to_the_end(&[0, 0]);
    let reference = dir.join("reference.csv");
    let out = common::run_to_pulse_log(
        &dir.join("programs/die.ngc"),
        &reference,
        &["--config", config.to_str().unwrap(), "--passes", "3"],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    common::daemon::assert_joined_is(&dir, &common::daemon::moves(&reference));
}
