//! Nothing from outside stops a cut, and a restart never resumes from a place the machine is
//! not at: the real `edmd serve` attacked as a careless operator and a hostile client would,
//! while a job runs (issue [1/9]). Each test drives the real binary through the interface
//! where the defect was seen: SIGKILL and restart, a failing disk, a FIFO, many idle
//! clients, a descriptor limit.

mod common;

use std::path::Path;
use std::time::{Duration, Instant};

use common::daemon::*;
use serde_json::Value;

/// The checkpoint file as JSON.
fn checkpoint(dir: &Path) -> Value {
    let text = std::fs::read_to_string(dir.join("checkpoint.json")).expect("a checkpoint");
    serde_json::from_str(&text).unwrap()
}

/// A wire-cut contour that ends at X2 Y4 (steps 2000, 4000), cut in about 3 s.
const CONTOUR: &str = "G21 G90\nG0 X1\nG1 X6 F300\nG1 Y4\nG1 X2\nM2\n";
const CONTOUR_END: [i64; 2] = [2000, 4000];

/// Sets without periodic checkpoints: what is on disk is only what the write-ahead rule and
/// the standstills wrote.
fn sets_without_periodic(dir: &Path) -> Vec<String> {
    let mut sets = base_sets(dir, "first.csv");
    sets.retain(|s| !s.starts_with("daemon.checkpoint_interval_s"));
    sets.push("daemon.checkpoint_interval_s=0".to_string());
    sets
}

/// The checkpoint is written before the first step, replaced by a still one at a hold and
/// by a moving one before the release; a SIGKILL after the release leaves a checkpoint a
/// restarted daemon refuses to resume without `--force`.
#[test]
fn a_kill_after_a_release_leaves_a_moving_checkpoint_that_asks_for_force() {
    let dir = scratch("write-ahead");
    std::fs::write(dir.join("programs/contour.ngc"), CONTOUR).unwrap();
    let sets = sets_without_periodic(&dir);
    let daemon = Daemon::start(&dir, &sets, &[]);
    // `ctl run` waits for the verdict: the job has started, and its checkpoint is there,
    // at the program's start, before the interval (never, here) would have written one.
    daemon.ok(&["run", "contour.ngc"]);
    let first = checkpoint(&dir);
    assert_eq!(
        (
            &first["reason"],
            &first["still"],
            &first["segment"],
            &first["step"]
        ),
        (
            &Value::from("moving"),
            &Value::from(false),
            &Value::from(0),
            &Value::from(0)
        ),
        "{first}"
    );
    assert_eq!(ints(&first["position_steps"]), vec![0, 0]);

    daemon.wait_for("cutting", |s| position(s)[0] > 2000);
    daemon.ok(&["hold"]);
    daemon.wait_for("the hold's checkpoint", |s| {
        s["state"] == "held" && s["checkpoint"]["still"] == true
    });
    assert_eq!(checkpoint(&dir)["reason"], "hold");
    // The release's reply comes after the moving checkpoint is on disk.
    daemon.ok(&["resume"]);
    let released = checkpoint(&dir);
    assert_eq!(
        (&released["reason"], &released["still"]),
        (&Value::from("moving"), &Value::from(false)),
        "{released}"
    );
    daemon.wait_for("moving again", |s| position(s)[0] > 5000);
    // SIGKILL: no chance to write anything.
    daemon.signal(libc::SIGKILL);
    let _ = daemon.wait();

    let daemon = Daemon::start(&dir, &sets, &[]);
    let (refused, code) = daemon.ctl(&["resume"]);
    assert_eq!(
        (refused["ok"].as_bool(), code),
        (Some(false), 1),
        "{refused}"
    );
    let why = refused["error"].as_str().unwrap();
    assert!(why.contains("--force"), "{why}");
    assert_eq!(daemon.status()["state"], "idle", "nothing started");
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
}

/// SIGKILL during the way back to the start hole after a wire break: the rethread wrote a
/// moving checkpoint before it moved, so the restarted daemon does not resume from the
/// break's standstill.
#[test]
fn a_kill_during_rethreading_leaves_a_moving_checkpoint() {
    let dir = scratch("rethread-kill");
    std::fs::write(dir.join("programs/contour.ngc"), CONTOUR).unwrap();
    std::fs::write(dir.join("gap.txt"), "0 normal\n28000 wire-break\n").unwrap();
    let mut sets = script_sets(&dir, "first.csv");
    sets.retain(|s| !s.starts_with("daemon.checkpoint_interval_s"));
    sets.push("daemon.checkpoint_interval_s=0".to_string());
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["run", "contour.ngc"]);
    daemon.wait_for("the wire break's checkpoint", |s| {
        s["state"] == "wire-break" && s["checkpoint"]["still"] == true
    });
    daemon.ok(&["rethread"]);
    assert_eq!(checkpoint(&dir)["reason"], "moving");
    daemon.wait_for("on the way back", |s| s["state"] == "rethreading");
    // A hold on the way back is a hold, not "rethreading".
    daemon.ok(&["hold"]);
    let held = daemon.wait_for("held on the way back", |s| s["state"] == "held");
    assert_eq!(held["job"]["servo"], "retreat", "{held}");
    daemon.ok(&["resume"]);
    daemon.wait_for("rethreading again", |s| s["state"] == "rethreading");
    daemon.signal(libc::SIGKILL);
    let _ = daemon.wait();

    let daemon = Daemon::start(&dir, &sets, &[]);
    let (refused, _) = daemon.ctl(&["resume"]);
    assert_eq!(refused["ok"], false, "{refused}");
    assert!(refused["error"].as_str().unwrap().contains("--force"));
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
}

/// A checkpoint that cannot be written (here its temporary file's name is taken by a
/// directory) is in the status and the log; the release that would leave the standstill is
/// refused, and goes through once the disk takes the checkpoint again.
#[test]
fn a_failed_checkpoint_write_keeps_the_machine_still_and_is_reported() {
    let dir = scratch("write-fails");
    std::fs::write(dir.join("programs/contour.ngc"), CONTOUR).unwrap();
    let sets = sets_without_periodic(&dir);
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["run", "contour.ngc"]);
    daemon.wait_for("cutting", |s| position(s)[0] > 2000);
    let blocker = dir.join("checkpoint.json.tmp");
    std::fs::create_dir(&blocker).unwrap();
    daemon.ok(&["hold"]);
    let failed = daemon.wait_for("the failed write in the status", |s| {
        s["state"] == "held" && s["checkpoint_write_error"].is_string()
    });
    let error = failed["checkpoint_write_error"].as_str().unwrap();
    assert!(
        error.contains("cannot write the checkpoint (hold)"),
        "{error}"
    );
    assert!(failed["counters"]["checkpoint_failures"].as_u64().unwrap() >= 1);
    // What is on disk is still the moving checkpoint of the job's start: true.
    assert_eq!(checkpoint(&dir)["reason"], "moving");
    let held_at = position(&failed);
    let (refused, code) = daemon.ctl(&["resume"]);
    assert_eq!(
        (refused["ok"].as_bool(), code),
        (Some(false), 1),
        "{refused}"
    );
    assert!(
        refused["error"]
            .as_str()
            .unwrap()
            .contains("the job stays held"),
        "{refused}"
    );
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(
        position(&daemon.status()),
        held_at,
        "moved without a checkpoint"
    );
    daemon.wait_for_log("cannot write the checkpoint (hold)");

    // The disk is back: the hold's checkpoint is written on the next round, the release too.
    std::fs::remove_dir(&blocker).unwrap();
    let ok = daemon.wait_for("the hold's checkpoint", |s| {
        s["checkpoint"]["still"] == true && s.get("checkpoint_write_error").is_none()
    });
    assert_eq!(ok["checkpoint"]["reason"], "hold");
    daemon.resume_to_the_end(&CONTOUR_END);
    assert!(!blocker.exists());
}

/// Killed right after `run` answered, a job still leaves its checkpoint: the restarted
/// daemon knows which job was running (and asks for `--force`, since it was moving).
#[test]
fn a_kill_right_after_the_start_leaves_the_jobs_checkpoint() {
    let dir = scratch("early-kill");
    std::fs::write(dir.join("programs/contour.ngc"), CONTOUR).unwrap();
    let sets = sets_without_periodic(&dir);
    for _ in 0..3 {
        let _ = std::fs::remove_file(dir.join("checkpoint.json"));
        let daemon = Daemon::start(&dir, &sets, &[]);
        daemon.ok(&["run", "contour.ngc"]);
        daemon.signal(libc::SIGKILL);
        let _ = daemon.wait();
        let daemon = Daemon::start(&dir, &sets, &[]);
        let status = daemon.status();
        assert_eq!(status["checkpoint"]["still"], false, "{status}");
        assert!(
            status["checkpoint"]["program"]
                .as_str()
                .unwrap()
                .ends_with("contour.ngc")
        );
        daemon.signal(libc::SIGTERM);
        assert_eq!(daemon.wait().0, 0);
    }
}

/// SIGTERM in the middle of `G4 P3`: the checkpoint keeps what is left of the dwell and the
/// resumed job dwells that long before it moves on.
#[test]
fn a_dwell_stopped_part_way_is_finished_after_the_resume() {
    let dir = scratch("dwell");
    std::fs::write(
        dir.join("programs/dwell.ngc"),
        "G21 G90\nG1 X0.5 F300\nG4 P3\nG1 X1\nM2\n",
    )
    .unwrap();
    let daemon = Daemon::start(&dir, &base_sets(&dir, "first.csv"), &[]);
    daemon.ok(&["run", "dwell.ngc"]);
    daemon.wait_for("the dwell", |s| {
        position(s)[0] == 500 && s["job"]["feed_mm_per_min"] == 0.0
    });
    let dwelling = Instant::now();
    std::thread::sleep(Duration::from_millis(1600));
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
    let cp = checkpoint(&dir);
    let left = cp["dwell_s"].as_f64().expect("the dwell's rest");
    let waited = dwelling.elapsed().as_secs_f64();
    assert!(
        left > 0.5 && left < 3.0 - 1.5 + 0.2 && (left + waited - 3.0).abs() < 0.5,
        "{left} s left after {waited} s: {cp}"
    );
    assert_eq!(cp["still"], true);

    // The resumed job, in virtual time: its first step comes after the rest of the dwell.
    let mut sets = base_sets(&dir, "second.csv");
    sets.retain(|s| !s.starts_with("fine.virtual_time"));
    sets.push("fine.virtual_time=true".to_string());
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.resume_to_the_end(&[1000, 0]);
    let (header, rows) = edmd::output::read_pulse_log(&dir.join("second.csv")).unwrap();
    let first_step = rows
        .iter()
        .find(|r| r.steps.iter().any(|&s| s != 0))
        .expect("the resumed job moves");
    let dwelt = first_step.tick as f64 * header.tick_us as f64 * 1e-6;
    assert!(
        (dwelt - left).abs() < 0.05,
        "the resumed job stood {dwelt} s, the checkpoint owed {left} s"
    );
}

/// A resume the job itself refuses (the program probed before the checkpoint: where that
/// probe touched is not known to a new run) moves nothing: the status says the machine is
/// where the checkpoint says, and the checkpoint is still the exact one it was.
#[test]
fn a_resume_refused_past_a_probe_leaves_the_checkpoint_and_the_position_true() {
    let dir = scratch("probe-resume");
    std::fs::write(
        dir.join("programs/probe.ngc"),
        "G21 G90\nG38.2 X5 F30\nG1 X3 F300\nG1 Y3\nM2\n",
    )
    .unwrap();
    std::fs::write(dir.join("gap.txt"), "0 normal\n3000 short\n3040 normal\n").unwrap();
    let sets = script_sets(&dir, "first.csv");
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["run", "probe.ngc"]);
    daemon.wait_for("past the probe", |s| position(s)[0] > 1500);
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
    let stopped = checkpoint(&dir);
    assert_eq!(
        (&stopped["reason"], &stopped["still"]),
        (&Value::from("stop"), &Value::from(true))
    );
    let at = ints(&stopped["position_steps"]);

    let daemon = Daemon::start(&dir, &sets, &[]);
    let (reply, _) = daemon.ctl(&["resume"]);
    assert_eq!(reply["ok"], true, "the check passes: {reply}");
    let idle = daemon.wait_for("the refusal", |s| {
        s["state"] == "idle" && s["last_job"].is_object()
    });
    let last = &idle["last_job"];
    assert_eq!(last["outcome"], "resume-refused", "{last}");
    assert!(
        last["error"].as_str().unwrap().contains("probes at line 2"),
        "{last}"
    );
    assert_eq!(
        ints(&last["end_steps"]),
        at,
        "the machine stands where the checkpoint says"
    );
    assert_eq!(
        checkpoint(&dir),
        stopped,
        "the checkpoint is the one it was"
    );
    assert_eq!(idle["checkpoint"]["still"], true);
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
}
