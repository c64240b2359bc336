//! The operator's console on the daemon: the feed and rapid overrides, through the real
//! binary, with the speed read back from the pulse log it writes.

use crate::common;

use common::daemon::{Daemon, base_sets, scratch};
use std::process::Command;

/// Steps of axis 0 per tick over the ticks `from..to` of the pulse log.
fn rate(log: &str, from: u64, to: u64) -> f64 {
    let steps: i64 = log
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("tick"))
        .filter_map(|l| {
            let mut f = l.split(',');
            let tick: u64 = f.next()?.parse().ok()?;
            let x: i64 = f.next()?.parse().ok()?;
            (from..to).contains(&tick).then_some(x.abs())
        })
        .sum();
    steps as f64 / (to - from) as f64
}

/// The tick an override took effect at, from the daemon's log (`… override P % from t=T s`).
fn override_tick(log: &str, what: &str) -> u64 {
    let line = log
        .lines()
        .find(|l| l.contains(what))
        .unwrap_or_else(|| panic!("no {what:?} in the log:\n{log}"));
    let t: f64 = line
        .split("from t=")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|t| t.parse().ok())
        .unwrap();
    (t / 50e-6).round() as u64
}

#[test]
fn the_feed_override_changes_the_speed_within_a_tick_and_is_reported() {
    let dir = scratch("override");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    std::fs::write(dir.join("programs/long.nc"), "G21 G90\nG1 X40 F300\nM2\n").unwrap();
    let mut sets = base_sets(&dir, "pulses.csv");
    // The servo's feed above the program's (a sparking gap that would allow more), so that
    // the planned ceiling is what the override moves.
    sets.push("servo.normal_feed_mm_per_min=1200.0".to_string());
    sets.push(format!(
        "daemon.report_dir=\"{}\"",
        dir.join("reports").display()
    ));
    let daemon = Daemon::start(&dir, &sets, &[]);
    // Out of range is refused, not clamped.
    daemon.refused(
        &["override", "feed", "250"],
        "give a whole percent from 0 to 200",
    );
    daemon.refused(
        &["override", "rapid", "120"],
        "give a whole percent from 0 to 100",
    );
    // A fraction would show as another number than the one given.
    daemon.refused(&["override", "feed", "100.5"], "give a whole percent");
    daemon.ok(&["run", "long.nc"]);
    // Paced by the job's own clock (its ticks), not the wall's: a loaded machine runs late.
    let machine_time = |s: &serde_json::Value| s["job"]["machine_time_s"].as_f64().unwrap_or(0.0);
    let wait_ticks = |secs: f64| {
        let from = machine_time(&daemon.status());
        daemon.wait_for("the job's time", |s| machine_time(s) >= from + secs);
    };
    daemon.wait_for("moving", common::daemon::is_moving);
    wait_ticks(0.4);
    let reply = daemon.ok(&["override", "feed", "50"]);
    assert_eq!(reply["status"]["overrides"]["feed_pct"], 50);
    daemon.wait_for_log("feed override 50 % from t=");
    wait_ticks(0.4);
    daemon.ok(&["override", "feed", "200"]);
    daemon.wait_for_log("feed override 200 % from t=");
    wait_ticks(0.4);
    daemon.ok(&["abort"]);
    daemon.wait_for("the job's end", |s| s["state"] == "idle");
    let text = daemon.ctl(&["status"]);
    assert_eq!(text.1, 0);

    let log = daemon.log();
    let half = override_tick(&log, "feed override 50 % from t=");
    let double = override_tick(&log, "feed override 200 % from t=");
    let pulses = std::fs::read_to_string(dir.join("pulses.csv")).unwrap();
    // 300 mm/min is 0.25 steps of 1 µm per 50 µs tick; half of it after braking, twice it
    // after accelerating (the machine's limits allow 600 mm/min on a line).
    let before = rate(&pulses, half - 4000, half);
    let slow = rate(&pulses, half + 1000, double);
    let fast = rate(&pulses, double + 1000, double + 6000);
    eprintln!(
        "steps per tick: {before:.4} at 100 %, {slow:.4} at 50 %, {fast:.4} at 200 %; \
         50 % from tick {half}, 200 % from tick {double}"
    );
    assert!((before - 0.25).abs() < 0.01, "before: {before}");
    assert!((slow - 0.125).abs() < 0.01, "at 50 %: {slow}");
    assert!((fast - 0.5).abs() < 0.01, "at 200 %: {fast}");
    // The tick it took effect at is in the run report's events.
    let report = std::fs::read_dir(dir.join("reports"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let events = std::fs::read_to_string(report.join("events.csv")).unwrap();
    let row = events
        .lines()
        .find(|l| l.contains(",feed_override,50,"))
        .unwrap_or_else(|| panic!("{events}"));
    let tick: u64 = row.split(',').next().unwrap().parse().unwrap();
    // The log prints t to 0.1 ms (two ticks).
    assert!(tick.abs_diff(half) <= 2, "{row} vs tick {half}");
    assert!(events.contains(",feed_override,200,"), "{events}");
    // Overrides outlast the job: the next one starts at 200 %.
    let s = daemon.status();
    assert_eq!(s["overrides"]["feed_pct"], 200);
    assert_eq!(s["overrides"]["rapid_pct"], 100);
}

#[test]
fn a_dry_run_moves_the_same_path_with_the_spark_off_at_the_dry_run_feed() {
    use edmd::output::read_pulse_log;
    let dir = scratch("dry-run");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    std::fs::write(
        dir.join("programs/part.nc"),
        "G21 G90\nG1 X1 Y0.5 F60\nG2 X2 Y0.5 I0.5 J0\nG1 X0 Y0\nM2\n",
    )
    .unwrap();
    // A cut goes at the program's 60 mm/min (the servo's feed is 300); a dry run at
    // machine.dry_run_feed_mm_per_min (600, the shipped value), not at the cutting feed.
    let daemon = Daemon::start(&dir, &base_sets(&dir, "pulses.csv"), &[]);
    let run = |args: &[&str]| {
        daemon.ok(args);
        let s = daemon.wait_for("the job's end", |s| {
            s["state"] == "idle" && s["last_job"]["outcome"] == "done"
        });
        let (_, rows) = read_pulse_log(&dir.join("pulses.csv")).unwrap();
        (s, rows)
    };
    let (cut, cut_rows) = run(&["run", "part.nc"]);
    assert!(cut["checkpoint"].is_null(), "a finished job leaves none");
    // Back to the start, then the dry run.
    daemon.ok(&["mdi", "G0 X0 Y0"]);
    daemon.wait_for("idle", |s| s["state"] == "idle");
    let (dry, dry_rows) = run(&["run", "part.nc", "--dry-run"]);
    let steps = |rows: &[edmd::output::PulseLogRow]| -> Vec<Vec<i8>> {
        rows.iter()
            .map(|r| r.steps.clone())
            .filter(|s| s.iter().any(|&x| x != 0))
            .collect()
    };
    assert_eq!(
        steps(&dry_rows),
        steps(&cut_rows),
        "the same path, step for step"
    );
    assert!(cut_rows.iter().any(|r| r.spark), "the cut sparks");
    assert!(dry_rows.iter().all(|r| !r.spark), "the dry run never does");
    // At the dry run's feed: a tenth of the cut's time and a little more (600 against 60
    // mm/min, and the accelerations).
    let (t_cut, t_dry) = (
        cut["last_job"]["virtual_time_s"].as_f64().unwrap(),
        dry["last_job"]["virtual_time_s"].as_f64().unwrap(),
    );
    assert!(t_dry < 0.2 * t_cut, "dry {t_dry} s, cut {t_cut} s");
    // The history and the status tell it from a cut.
    let text = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .args(["ctl", "jobs", "--socket"])
        .arg(&daemon.socket)
        .output()
        .unwrap();
    assert!(String::from_utf8_lossy(&text.stdout).contains("(dry run)"));
    assert!(
        daemon
            .log()
            .contains("(dry run: spark off, the servo out of the loop)")
    );
    // A dry run stopped part way leaves no checkpoint to resume (a cut stopped so does).
    std::fs::write(dir.join("programs/long.nc"), "G21 G90\nG1 X30 F120\nM2\n").unwrap();
    daemon.ok(&["run", "long.nc", "--dry-run"]);
    daemon.wait_for("moving", common::daemon::is_moving);
    assert_eq!(daemon.status()["job"]["dry_run"], true);
    let text = daemon.status_text();
    assert!(
        text.contains("DRY RUN: spark off, nothing is cut"),
        "{text}"
    );
    daemon.ok(&["abort"]);
    let s = daemon.wait_for("the abort", |s| s["state"] == "idle");
    assert!(s["checkpoint"].is_null(), "{s}");
    assert!(!dir.join("checkpoint.json").exists());
}

#[test]
fn single_block_stops_at_each_block_end_and_resume_runs_the_next() {
    let dir = scratch("single-block");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    std::fs::write(
        dir.join("programs/square.nc"),
        "G21 G90\nG1 X0.5 F300\nG1 Y0.5\nG1 X0 Y0\nM2\n",
    )
    .unwrap();
    let daemon = Daemon::start(&dir, &base_sets(&dir, "pulses.csv"), &[]);
    let reply = daemon.ok(&["single-block", "on"]);
    assert_eq!(reply["status"]["single_block"], true);
    daemon.ok(&["run", "square.nc"]);
    for (line, at) in [(3, [500, 0]), (4, [500, 500])] {
        let s = daemon.wait_for("the single-block stop", |s| s["state"] == "paused");
        assert_eq!(s["job"]["paused_before_line"], line, "{s}");
        // At the block's end point exactly, and checkpointed at that standstill.
        assert_eq!(common::daemon::position(&s), at, "{s}");
        let s = daemon.wait_for("its checkpoint", |s| {
            s["checkpoint"]["still"] == true
                && s["checkpoint"]["position_steps"] == serde_json::json!(at)
        });
        assert_eq!(s["checkpoint"]["resumable"], false, "the running job's own");
        daemon.ok(&["resume"]);
        daemon.wait_for("moving on", |s| s["state"] != "paused");
    }
    let s = daemon.wait_for("the job's end", |s| {
        s["state"] == "idle" && s["last_job"]["outcome"] == "done"
    });
    assert_eq!(s["last_job"]["end_steps"], serde_json::json!([0, 0]));
    assert!(
        daemon
            .log()
            .contains("square.nc:3: single block: stopped before this line"),
        "{}",
        daemon.log()
    );
    daemon.ok(&["single-block", "off"]);
}

/// Single block and run from a line: the approach is the job's, not the program's, so the
/// first stop is before the line asked for, not before every block of the approach.
#[test]
fn single_block_from_a_line_stops_first_before_that_line() {
    let dir = scratch("single-block-from-line");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    std::fs::write(
        dir.join("programs/square.nc"),
        "G21 G90\nG1 X0.5 F300\nG1 Y0.5\nG1 X0 Y0.5\nG1 X0 Y0\nM2\n",
    )
    .unwrap();
    let daemon = Daemon::start(&dir, &base_sets(&dir, "pulses.csv"), &[]);
    daemon.ok(&["single-block", "on"]);
    daemon.ok(&[
        "run",
        "square.nc",
        "--from-line",
        "4",
        "--wire-at",
        "start-hole",
    ]);
    let s = daemon.wait_for("the single-block stop", |s| s["state"] == "paused");
    assert_eq!(s["job"]["paused_before_line"], 4, "{s}");
    assert_eq!(common::daemon::position(&s), [500, 500], "{s}");
    daemon.ok(&["resume"]);
    let s = daemon.wait_for("the next stop", |s| s["state"] == "paused");
    assert_eq!(s["job"]["paused_before_line"], 5, "{s}");
    daemon.ok(&["single-block", "off"]);
    daemon.ok(&["resume"]);
    daemon.wait_for("the job's end", |s| {
        s["state"] == "idle" && s["last_job"]["outcome"] == "done"
    });
}

/// A stop tells the operator what the program says there: a pause M-code's message, an
/// `M0`'s `(MSG, …)` on the lines since the move before; a stop with nothing said, nothing.
#[test]
fn a_pause_shows_the_programs_message_for_it() {
    let dir = scratch("pause-message");
    std::fs::write(
        dir.join("programs/thread.nc"),
        "G21 G90\n(MSG, not this one: a move follows)\nG1 X0.2 F300\nM60\nG1 Y0.2\n\
         (MSG, check the slug)\nM0\nG1 X0\nM0\nG1 Y0\nM2\n",
    )
    .unwrap();
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.push(
        "program.mcode=[{number=60, action=\"pause\", message=\"thread the wire, then resume\"}]"
            .to_string(),
    );
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["run", "thread.nc"]);
    for (line, message) in [
        (5, Some("M60: thread the wire, then resume")),
        (8, Some("check the slug")),
        (10, None),
    ] {
        let s = daemon.wait_for("the stop", |s| {
            s["state"] == "paused" && s["job"]["paused_before_line"] == line
        });
        assert_eq!(s["job"]["pause_message"].as_str(), message, "{s}");
        let text = daemon.status_text();
        match message {
            Some(m) => assert!(text.contains(&format!("message:      {m}")), "{text}"),
            None => assert!(!text.contains("message:"), "{text}"),
        }
        daemon.ok(&["resume"]);
    }
    daemon.wait_for("the job's end", |s| {
        s["state"] == "idle" && s["last_job"]["outcome"] == "done"
    });
}
