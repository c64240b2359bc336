//! The operator's layer around the machine functions, through the real binary: what is
//! cutting now (condition, pass n of N, wire offset), the job history kept across a restart
//! with each pass's time, the hour counters, report folders for jobs only, and an ETA that
//! a hold does not stretch and that times each pass at its own feed.

use crate::common;

use std::time::Duration;

use common::daemon::{Daemon, base_sets, scratch};
use serde_json::Value;

/// A die opening as CAM posts write it: `G41 D1` on the entry move from the start hole.
pub const DIE: &str = "(a die opening: the G41 on the entry move)\nG21 G90 G17\n\
G41 D1 G1 X2 Y0 F600\nG1 X2 Y2\nG1 X-2 Y2\nG1 X-2 Y-2\nG1 X2 Y-2\nG1 X2 Y0\n\
G40 G1 X0 Y0\nM2\n";

/// Three passes, the second the other way round.
pub const PASSES: &str = "wire.pass=[{offset_mm=0.145, condition=4}, \
{offset_mm=0.135, condition=3, reverse=true}, {offset_mm=0.128, condition=1}]";

/// The passes' conditions with a fast sparking feed, so a test's passes take seconds.
pub const FAST_CONDITIONS: &str = "generator.condition=[\
{number=1, on_us=1.0, off_us=12.0, current_a=1.0, v_ref=35.0, feed_mm_per_min=600.0}, \
{number=3, on_us=4.0, off_us=8.0, current_a=5.0, v_ref=25.0, feed_mm_per_min=600.0}, \
{number=4, on_us=8.0, off_us=8.0, current_a=10.0, v_ref=22.0, feed_mm_per_min=600.0}, \
{number=9, on_us=0.5, off_us=30.0, current_a=0.2, v_ref=40.0, feed_mm_per_min=5.0}]";

fn sets(dir: &std::path::Path) -> Vec<String> {
    let mut sets = base_sets(dir, "pulses.csv");
    sets.push(format!(
        "daemon.state_dir=\"{}\"",
        dir.join("state").display()
    ));
    sets.push(PASSES.to_string());
    sets.push(FAST_CONDITIONS.to_string());
    sets
}

#[test]
fn the_job_history_keeps_each_job_and_its_passes_across_a_restart() {
    let dir = scratch("job-history");
    let _ = std::fs::remove_dir_all(dir.join("state"));
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    std::fs::write(dir.join("programs/die.ngc"), DIE).unwrap();
    let daemon = Daemon::start(&dir, &sets(&dir), &[]);
    daemon.ok(&["home", "--here"]);
    daemon.ok(&["run", "die.ngc", "--passes", "3"]);
    // While the second pass runs, the status says so: its condition and its offset.
    // (Its first move is the exit move reversed, out of the start hole, with no offset.)
    let s = daemon.wait_for("the second pass's contour", |s| {
        s["job"]["pass"] == 2 && s["job"]["wire_offset"].is_object()
    });
    let job = &s["job"];
    assert_eq!(job["passes"], 3, "{job}");
    assert_eq!(job["condition"], 3, "{job}");
    assert_eq!(job["wire_offset"]["mm"], 0.135, "{job}");
    daemon.wait_for("the job's end", |s| {
        s["state"] == "idle" && s["last_job"]["outcome"] == "done"
    });
    // A jog and an MDI line are the machine's, not jobs: no history line, no report.
    daemon.ok(&["jog", "X", "0.1"]);
    daemon.wait_for("the jog's end", |s| s["state"] == "idle");
    daemon.ok(&["mdi", "G0 X0"]);
    daemon.wait_for("the MDI line's end", |s| s["state"] == "idle");
    let reports: Vec<_> = std::fs::read_dir(dir.join("state/reports"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(reports.len(), 1, "{reports:?}");
    assert!(reports[0].ends_with("-die"), "{reports:?}");
    let check = |daemon: &Daemon| {
        let reply = daemon.ok(&["jobs"]);
        let jobs = reply["jobs"].as_array().unwrap().clone();
        assert_eq!(jobs.len(), 1, "{reply}");
        let job = &jobs[0];
        assert_eq!(job["program"], "die.ngc");
        assert_eq!(job["outcome"], "done");
        let passes = job["passes"].as_array().unwrap();
        let conditions: Vec<&Value> = passes.iter().map(|p| &p["condition"]).collect();
        assert_eq!(conditions, [4, 3, 1], "{job}");
        let sum: f64 = passes.iter().map(|p| p["time_s"].as_f64().unwrap()).sum();
        let total = job["machine_time_s"].as_f64().unwrap();
        assert!(
            passes.iter().all(|p| p["time_s"].as_f64().unwrap() > 0.5),
            "{job}"
        );
        assert!(sum <= total + 1e-9 && sum > 0.9 * total, "{sum} of {total}");
        let text = reply["message"].as_str().unwrap();
        assert!(
            text.contains("done     die.ngc") && text.contains("    pass 2 E3  "),
            "{text}"
        );
        reply["status"]["hours"].clone()
    };
    let hours = check(&daemon);
    assert_eq!(hours["jobs"], 1, "{hours}");
    assert!(hours["machine_s"].as_f64().unwrap() > 1.0, "{hours}");
    drop(daemon);
    // After a restart: the same history, the same counters.
    let daemon = Daemon::start(&dir, &sets(&dir), &[]);
    assert_eq!(check(&daemon), hours);
}

/// A hold is not slow cutting: the ETA after a 20 s hold is the one before it (within 5 %).
#[test]
fn a_hold_does_not_stretch_the_eta() {
    let dir = scratch("eta-hold");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    std::fs::write(dir.join("programs/line.nc"), "G21 G90\nG1 X40 F60\nM2\n").unwrap();
    let daemon = Daemon::start(&dir, &base_sets(&dir, "pulses.csv"), &[]);
    daemon.ok(&["run", "line.nc"]);
    daemon.wait_for("four seconds of cutting", |s| {
        s["job"]["path_done_mm"].as_f64().is_some_and(|d| d > 4.0)
    });
    let eta = |daemon: &Daemon| daemon.status()["job"]["eta_s"].as_f64().unwrap();
    let before = eta(&daemon);
    // 36 mm left at 1 mm/s; a loaded test machine's late ticks (overruns) make the job, and
    // so its ETA, slower.
    assert!((30.0..90.0).contains(&before), "ETA {before} s");
    daemon.ok(&["hold"]);
    daemon.wait_for("the hold", |s| s["state"] == "held");
    std::thread::sleep(Duration::from_secs(20));
    let held = eta(&daemon);
    daemon.ok(&["resume"]);
    // Read as it cuts again: later the ETA moves with the pace it keeps, as it should (on a
    // loaded test machine, late ticks slow the job and the ETA follows).
    let after = daemon.wait_for("cutting again", |s| {
        s["state"] == "running"
            && s["job"]["feed_mm_per_min"]
                .as_f64()
                .is_some_and(|f| f > 0.0)
    })["job"]["eta_s"]
        .as_f64()
        .unwrap();
    eprintln!("ETA before the hold {before:.1} s, held {held:.1} s, after {after:.1} s");
    assert!(
        (after - before).abs() / before < 0.05,
        "before {before}, after {after}"
    );
    assert!((held - before).abs() / before < 0.05, "held {held}");
    daemon.ok(&["abort"]);
}

/// A run in passes: the plan times each pass at its feed (the third pass's feed cap and the
/// conditions' sparking feeds), within 10 % of the simulated gap's run.
#[test]
fn a_three_pass_estimate_is_within_ten_percent_of_the_simulated_run() {
    let dir = scratch("eta-passes");
    let program = dir.join("die.ngc");
    std::fs::write(&program, DIE).unwrap();
    // The shipped configuration: the simulated gap, its d_mm and three-pass table; the gap's
    // kinematic model, which keeps to the plan's feeds (on the discharge model the process
    // sets the speed, and a skim cuts as if through the full stock).
    let (plan, run) = common::plan_and_run(
        &dir,
        &program,
        &["--passes", "3", "--set", "sim.model=\"kinematic\""],
    );
    let estimate = plan["estimated_time_s"].as_f64().unwrap();
    let ran = run["virtual_time_s"].as_f64().unwrap();
    eprintln!("3 passes: estimated {estimate:.1} s, the simulated run {ran:.1} s");
    // The finish pass at its 6 mm/min cap is most of it: a plan at the rough cut's feed
    // would say a fraction of this.
    assert!(estimate > 150.0, "{estimate}");
    assert!((estimate - ran).abs() / ran < 0.10, "{estimate} vs {ran}");
}

/// The gap voltage the input measures is in the status (the page draws it live): the
/// simulator's, within its open-circuit 80 V.
#[test]
fn the_status_carries_the_measured_gap_voltage() {
    let dir = scratch("gap-volts");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    std::fs::write(dir.join("programs/line.nc"), "G21 G90\nG1 X20 F60\nM2\n").unwrap();
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.retain(|s| !s.starts_with("gap.kind"));
    sets.push("gap.kind=\"sim\"".to_string());
    // The estimate models the kinematic gap (on the discharge model the process sets the
    // speed).
    sets.push("sim.model=\"kinematic\"".to_string());
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["run", "line.nc"]);
    let s = daemon.wait_for("a measured gap voltage", |s| {
        s["job"]["gap_volts"].is_number()
    });
    let volts = s["job"]["gap_volts"].as_f64().unwrap();
    assert!((0.0..=80.0).contains(&volts), "{volts} V");
    daemon.ok(&["abort"]);
    // An input that reads states only measures no voltage: none is shown.
    let dir = scratch("gap-no-volts");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    std::fs::write(dir.join("programs/line.nc"), "G21 G90\nG1 X20 F60\nM2\n").unwrap();
    let daemon = Daemon::start(&dir, &base_sets(&dir, "pulses.csv"), &[]);
    daemon.ok(&["run", "line.nc"]);
    let s = daemon.wait_for("cutting", |s| {
        s["job"]["feed_mm_per_min"]
            .as_f64()
            .is_some_and(|f| f > 0.0)
    });
    assert!(s["job"].get("gap_volts").is_none(), "{}", s["job"]);
    daemon.ok(&["abort"]);
}
