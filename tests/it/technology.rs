//! Technology tables through the real binary: `edmd tech` on the shipped example tables
//! (a row, a height between rows, a request outside the table refused naming the nearest
//! rows); a die whose header names a technology cut by the daemon in the table's passes, at
//! the interpolated offsets (from the pulse log, as the pass tests read it), with the
//! technology in the status, the history and the report; a resume of such a job; a sinker
//! stage's orbit; and the plan's estimate of a three-pass table against the simulated run.

use std::path::Path;
use std::process::Command;

use crate::common;
use common::daemon::{Daemon, base_sets};
use common::wire::{inside_die, positions_by_condition};

/// `edmd tech ARGS` on the shipped configuration (its tables: config/technology).
fn tech(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_edmd"))
        .arg("tech")
        .arg("--config")
        .arg(common::repo().join("config/edmd.toml"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn tech_explain_reads_the_shipped_tables_rows_between_rows_and_refuses_outside() {
    let out = tech(&["list"]);
    let list = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{list}");
    assert!(
        list.contains("material=steel wire=0.25 type=brass  heights 10, 20, 30, 40, 60 mm"),
        "{list}"
    );
    assert_eq!(list.matches("(example)").count(), 3, "{list}");

    // On a row: its passes as written.
    let out = tech(&["explain", "material=steel,height=30,wire=0.25"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    assert!(
        text.contains("height 30 mm: the row 30 mm (")
            && text.contains("wire-steel-brass-0.25.toml:100:1)"),
        "{text}"
    );
    assert!(
        text.contains("1     E21        0.1780     3.60         forward    30 mm row"),
        "{text}"
    );
    assert!(text.contains("EXAMPLE"), "{text}");

    // Between rows: offsets and feeds 20 % of the way from the 30 to the 40 mm row.
    let out = tech(&["explain", "material=steel height=32 wire=0.25"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("between the rows 30 mm"), "{text}");
    assert!(text.contains("1     E21        0.1786     3.46         forward    32 mm, between the 30 and 40 mm rows"), "{text}");
    assert!(
        text.contains("2     E22        0.1392     7.24         reverse"),
        "{text}"
    );

    // Outside the table: refused, exit 2, the nearest row named with its place.
    let out = tech(&["explain", "material=steel,height=75,wire=0.25"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("height 75 mm is outside the steel with 0.25 mm brass wire table (rows from 10 to 60 mm): the nearest row is 60 mm ("), "{err}");
    assert!(err.contains("wire-steel-brass-0.25.toml:116:1)"), "{err}");
    let out = tech(&["explain", "material=steel,height=30,wire=0.3"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(
            "no steel table for 0.3 mm wire: the nearest are steel with 0.25 mm brass wire"
        ),
        "{err}"
    );
    // A mistyped key is located in the request.
    let out = tech(&["explain", "material=steel,hieght=30,wire=0.25"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("request:1:16: technology: \"hieght\" is not a technology key"),
        "{err}"
    );
}

/// A fast table for a daemon in real time: a 4 mm die's passes take seconds.
pub const FAST_TABLE: &str = r#"kind = "wire"
material = "testium"
wire_diameter_mm = 0.25
wire_type = "brass"

[[condition]]
number = 51
on_time_us = 8.0
off_time_us = 8.0
peak_current_a = 10.0
servo_ref_v = 22.0
flushing_bar = 12.0

[[condition]]
number = 52
on_time_us = 3.0
off_time_us = 10.0
peak_current_a = 5.0
servo_ref_v = 30.0

[[condition]]
number = 53
on_time_us = 1.0
off_time_us = 12.0
peak_current_a = 1.0
servo_ref_v = 38.0

[[row]]
height_mm = 20.0
pass = [
  { offset_mm = 0.20, condition = 51, feed_mm_per_min = 600.0 },
  { offset_mm = 0.15, condition = 52, feed_mm_per_min = 600.0, reverse = true },
  { offset_mm = 0.12, condition = 53, feed_mm_per_min = 600.0 } ]

[[row]]
height_mm = 40.0
pass = [
  { offset_mm = 0.22, condition = 51, feed_mm_per_min = 400.0 },
  { offset_mm = 0.16, condition = 52, feed_mm_per_min = 400.0, reverse = true },
  { offset_mm = 0.13, condition = 53, feed_mm_per_min = 400.0 } ]
"#;

/// The die of the pass tests, with its technology in its header.
fn die_with_header() -> String {
    format!(
        "(die 7, customer 4711)\n(TECH material=testium height=30 wire=0.25)\n{}",
        common::wire::DIE.trim_start_matches("(die)\n")
    )
}

#[test]
fn a_header_comment_cuts_the_tables_passes_at_their_offsets_and_is_recorded() {
    let dir = common::daemon::scratch("technology");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    let _ = std::fs::remove_dir_all(dir.join("reports"));
    let _ = std::fs::remove_file(dir.join("jobs.jsonl"));
    std::fs::create_dir_all(dir.join("tech")).unwrap();
    std::fs::write(dir.join("tech/testium.toml"), FAST_TABLE).unwrap();
    std::fs::write(dir.join("programs/die.ngc"), die_with_header()).unwrap();
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.push(format!("technology.dir=\"{}\"", dir.join("tech").display()));
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["home", "--here"]);

    // What it would select, from the daemon's tables.
    let reply = daemon.ok(&["tech", "material=testium,height=30,wire=0.25"]);
    let text = reply["message"].as_str().unwrap();
    assert!(
        text.contains("1     E51        0.2100     500.00"),
        "{text}"
    );
    assert_eq!(
        reply["technology"][0]["heights_mm"],
        serde_json::json!([20.0, 40.0])
    );
    // Outside the table: the check refuses, naming the nearest row.
    let (reply, _) = daemon.ctl(&[
        "run",
        "die.ngc",
        "--technology",
        "material=testium,height=50,wire=0.25",
    ]);
    let refused = reply.to_string();
    assert!(
        refused.contains("height 50 mm is outside") && refused.contains("the nearest row is 40 mm"),
        "{refused}"
    );

    // The header's technology: all three passes, no --passes needed.
    daemon.ok(&["run", "die.ngc"]);
    let s = daemon.wait_for("the first pass", |s| s["job"]["condition"] == 51);
    let job = &s["job"];
    assert_eq!(job["passes"], 3, "{job}");
    assert_eq!(
        job["technology"],
        "material=testium height=30 wire=0.25 (testium with 0.25 mm brass wire)"
    );
    assert_eq!(job["generator"]["on_time_us"], 8.0, "{job}");
    assert_eq!(job["generator"]["flushing_bar"], 12.0, "{job}");
    let s = daemon.wait_for("the end", |s| {
        s["state"] == "idle" && s["last_job"].is_object()
    });
    assert_eq!(s["last_job"]["outcome"], "done", "{s}");

    // Each pass at its offset interpolated for 30 mm (halfway from 20 to 40 mm), in its
    // condition, the second the other way round.
    let (by, end) = positions_by_condition(&dir.join("pulses.csv"));
    assert_eq!(end, (0, 0));
    assert_eq!(by.keys().copied().collect::<Vec<_>>(), vec![51, 52, 53]);
    common::wire::assert_passes(
        &by,
        &[(51, 210, 1.0), (52, 155, -1.0), (53, 125, 1.0)],
        &inside_die,
    );

    // The history and the report carry the technology and each pass's row and condition.
    let jobs = daemon.ok(&["jobs", "--count", "1"]);
    let record = &jobs["jobs"][0];
    assert_eq!(
        record["technology"],
        "material=testium height=30 wire=0.25 (testium with 0.25 mm brass wire)"
    );
    assert_eq!(record["passes"][1]["condition"], 52, "{record}");
    assert_eq!(
        record["passes"][1]["row"], "30 mm, between the 20 and 40 mm rows",
        "{record}"
    );
    // Each pass's mean cut rate: what it advanced along the path (the contour, each pass
    // once) times the table's 30 mm, over its time; no wire broke.
    let first_mm = record["passes"][0]["cut_mm"].as_f64().unwrap();
    for pass in record["passes"].as_array().unwrap() {
        let (cut, time) = (
            pass["cut_mm"].as_f64().unwrap(),
            pass["time_s"].as_f64().unwrap(),
        );
        assert!(
            cut > 10.0 && (cut - first_mm).abs() < 0.1 * first_mm,
            "{pass}"
        );
        let rate = pass["mean_rate_mm2_per_min"].as_f64().unwrap();
        assert!(
            (rate - cut * 30.0 / time * 60.0).abs() < 1e-6 * rate,
            "{pass}"
        );
        assert_eq!(pass["wire_breaks"], 0, "{pass}");
    }
    let job_rate = record["mean_rate_mm2_per_min"].as_f64().unwrap();
    let job_mm: f64 = record["passes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["cut_mm"].as_f64().unwrap())
        .sum();
    let machine_s = record["machine_time_s"].as_f64().unwrap();
    // The job's approach and leave add a little path beyond the passes.
    let bare = job_mm * 30.0 / machine_s * 60.0;
    assert!((job_rate - bare).abs() < 0.1 * bare, "{job_rate} vs {bare}");
    let report = Path::new(record["report"].as_str().unwrap());
    let csv = std::fs::read_to_string(report.join("passes.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(
        lines[0],
        "pass,condition,row,time_s,cut_mm,mean_rate_mm2_per_min,wire_breaks"
    );
    assert!(
        lines[2].starts_with("2,E52,\"30 mm, between the 20 and 40 mm rows\","),
        "{csv}"
    );
    assert_eq!(lines.len(), 4, "{csv}");
}

/// The plan of a three-pass table (the shipped aluminium example, 30 mm) times each pass at
/// its table feed; the simulated gap's run takes within 10 % of it.
#[test]
fn a_technology_plan_is_within_ten_percent_of_the_simulated_run() {
    let dir = common::scratch("technology", "eta");
    let program = dir.join("die.ngc");
    std::fs::write(
        &program,
        die_with_header().replace("material=testium", "material=aluminium"),
    )
    .unwrap();
    // The plan's feeds against a run that keeps to them: the kinematic gap (on the discharge
    // model the process, not the plan, sets the speed).
    let (plan, run) = common::plan_and_run(&dir, &program, &["--set", "sim.model=\"kinematic\""]);
    let estimate = plan["estimated_time_s"].as_f64().unwrap();
    let passes: Vec<f64> = plan["passes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["estimated_time_s"].as_f64().unwrap())
        .collect();
    assert_eq!(passes.len(), 3, "{plan}");
    assert!(
        (passes.iter().sum::<f64>() - estimate).abs() < 1e-6 * estimate,
        "{passes:?} vs {estimate}"
    );
    // The rough cut at 8 mm/min is the slowest, the finish at 16 mm/min the fastest.
    assert!(passes[0] > passes[1] && passes[1] > passes[2], "{passes:?}");

    let ran = run["virtual_time_s"].as_f64().unwrap();
    eprintln!(
        "aluminium 30 mm, 3 passes: estimated {estimate:.1} s ({passes:.1?}), the simulated run {ran:.1} s"
    );
    assert!(estimate > 200.0, "{estimate}");
    assert!((estimate - ran).abs() / ran < 0.10, "{estimate} vs {ran}");
}

/// A job cut with a technology and stopped in its second pass resumes (a new daemon) with the
/// same technology, from the checkpoint: to the pulses of an uninterrupted run. A table
/// changed in between is refused.
#[test]
fn a_technology_job_stopped_in_its_second_pass_resumes_to_the_uninterrupted_pulses() {
    let dir = common::daemon::scratch("technology-resume");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    std::fs::create_dir_all(dir.join("tech")).unwrap();
    std::fs::write(dir.join("tech/testium.toml"), FAST_TABLE).unwrap();
    std::fs::write(dir.join("programs/die.ngc"), die_with_header()).unwrap();
    let tables = format!("technology.dir=\"{}\"", dir.join("tech").display());
    let sets = |pulses: &str| {
        let mut sets = base_sets(&dir, pulses);
        sets.push(tables.clone());
        sets
    };
    let daemon = Daemon::start(&dir, &sets("first.csv"), &[]);
    daemon.ok(&["home", "--here"]);
    daemon.ok(&["run", "die.ngc"]);
    daemon.wait_for("the second pass", |s| s["job"]["pass"] == 2);
    let cp = daemon.hold_abort_checkpoint(&dir);
    assert_eq!(
        cp["technology"], "material=testium height=30 wire=0.25",
        "{cp}"
    );
    assert_eq!(cp["passes"].as_array().map(Vec::len), Some(3), "{cp}");
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);

    // The table changed since: the passes are not the checkpoint's any more.
    std::fs::write(
        dir.join("tech/testium.toml"),
        FAST_TABLE.replace("offset_mm = 0.16,", "offset_mm = 0.17,"),
    )
    .unwrap();
    let daemon = Daemon::start(&dir, &sets("refused.csv"), &[]);
    let (reply, _) = daemon.ctl(&["resume"]);
    assert!(
        reply.to_string().contains("no longer the checkpoint's"),
        "{reply}"
    );
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);

    std::fs::write(dir.join("tech/testium.toml"), FAST_TABLE).unwrap();
    let daemon = Daemon::start(&dir, &sets("second.csv"), &[]);
    daemon.resume_to_the_end(&[0, 0]);
    let reference = dir.join("reference.csv");
    let out = common::run_to_pulse_log(
        &dir.join("programs/die.ngc"),
        &reference,
        &[
            "--set",
            &tables,
            "--set",
            "servo.normal_feed_mm_per_min=300.0",
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    common::daemon::assert_joined_is(&dir, &common::daemon::moves(&reference));
}

/// A cavity sunk with the shipped copper-on-steel table's condition 43 (a 2 cm² electrode).
const CAVITY: &str = "(TECH electrode=copper material=steel area=2)\nG21 G90\nG0 X5 Y5\nG0 Z0\n\
                      E43 G1 Z-0.5 F10\nG0 Z1\nM2\n";

/// `--set` for the shipped technology tables.
fn shipped_tables() -> String {
    format!(
        "technology.dir=\"{}\"",
        common::repo().join("config/technology").display()
    )
}

/// A sinker table's stage orbits its condition's sinking moves at the stage's radius: the
/// program's `E43` on a 2 cm² copper electrode (the 1 to 4 cm² row: 0.25 mm) walks a circle of
/// 0.25 mm about the programmed axis at the bottom of the plunge (from the pulse log).
#[test]
fn a_sinker_stage_orbits_its_condition_at_the_stages_radius() {
    let dir = common::scratch("technology", "sinker");
    let program = dir.join("cavity.ngc");
    std::fs::write(&program, CAVITY).unwrap();
    let pulses = dir.join("cavity.csv");
    let tables = shipped_tables();
    let out = common::run_to_pulse_log(
        &program,
        &pulses,
        &[
            "--set",
            "machine.axes=[\"X\",\"Y\",\"Z\"]",
            "--set",
            "machine.step_mm=[0.001,0.001,0.001]",
            "--set",
            &tables,
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (_, rows) = edmd::output::read_pulse_log(&pulses).unwrap();
    let mut at = [0i64; 3];
    let mut widest = 0.0f64;
    for r in rows.iter().filter(|r| r.steps.iter().any(|&s| s != 0)) {
        for (a, s) in at.iter_mut().zip(&r.steps) {
            *a += i64::from(*s);
        }
        // Below 0.45 mm (the radius has grown to nine tenths of the stage's and more).
        if at[2] < -450 {
            let (dx, dy) = ((at[0] - 5000) as f64, (at[1] - 5000) as f64);
            widest = widest.max((dx * dx + dy * dy).sqrt() / 1000.0);
        }
    }
    assert!(
        (widest - 0.25).abs() < 0.003,
        "the orbit reaches {widest} mm"
    );
}

/// `edmd check` says what the header's technology selects, and refuses one outside its table
/// (exit 2) as a run would.
#[test]
fn check_reads_the_header_technology() {
    let dir = common::scratch("technology", "check");
    let check = |text: &str| {
        let program = dir.join("die.ngc");
        std::fs::write(&program, text).unwrap();
        Command::new(env!("CARGO_BIN_EXE_edmd"))
            .args(["check", "--quiet", "--config"])
            .arg(common::repo().join("config/edmd.toml"))
            .arg(&program)
            .output()
            .unwrap()
    };
    let die =
        std::fs::read_to_string(common::repo().join("programs/die-aluminium-30.ngc")).unwrap();
    let out = check(&die);
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains(
        "technology: material=aluminium height=30 wire=0.25 (aluminium with 0.25 mm brass wire): 3 passes"
    ));
    let out = check(&die.replace("height=30", "height=99"));
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("the nearest row is 50 mm"));
}

/// `check` reads a sinker program as `plan` and `run` do: its header's table defines the E
/// words the program selects (before, check refused `E43` as a condition the configuration
/// does not have).
#[test]
fn check_takes_a_sinker_headers_conditions_as_plan_and_run_do() {
    let dir = common::scratch("technology", "check-sinker");
    let program = dir.join("cavity.ngc");
    std::fs::write(&program, CAVITY).unwrap();
    let tables = shipped_tables();
    let out = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .args(["check", "--quiet", "--config"])
        .arg(common::repo().join("config/edmd.toml"))
        .args(["--set", "machine.axes=[\"X\",\"Y\",\"Z\"]"])
        .args(["--set", "machine.step_mm=[0.001,0.001,0.001]"])
        .args(["--set", &tables])
        .arg(&program)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}{}",
        stdout,
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("technology: electrode=copper material=steel area=2"),
        "{stdout}"
    );
    assert!(stdout.contains("stages"), "{stdout}");
}

/// A run from a line of a die whose header names a technology cuts in the pass it is in:
/// from line 8 in pass 1, at the table's pass-1 offset and condition from that line only,
/// then passes 2 (the other way round) and 3 whole, back to the start hole; the status and
/// the history say the line and the pass. A line in the reversed pass, a pass the table does
/// not have and a pass without passes are refused.
#[test]
fn a_run_from_a_line_cuts_in_the_pass_it_is_in_then_the_later_passes_whole() {
    let dir = common::daemon::scratch("technology-from-line");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    let _ = std::fs::remove_file(dir.join("jobs.jsonl"));
    std::fs::create_dir_all(dir.join("tech")).unwrap();
    std::fs::write(dir.join("tech/testium.toml"), FAST_TABLE).unwrap();
    std::fs::write(dir.join("programs/die.ngc"), die_with_header()).unwrap();
    std::fs::write(dir.join("programs/plain.ngc"), common::wire::DIE).unwrap();
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.push(format!("technology.dir=\"{}\"", dir.join("tech").display()));
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["home", "--here"]);

    // Line 8 (G1 X-2 Y2: the top edge) in pass 1 (the default in passes).
    let reply = daemon.ok(&[
        "run",
        "die.ngc",
        "--from-line",
        "8",
        "--wire-at",
        "start-hole",
        "--force",
    ]);
    assert!(
        reply["message"]
            .as_str()
            .unwrap()
            .contains("from line 8 in pass 1"),
        "{reply}"
    );
    let s = daemon.wait_for("cutting in pass 1", |s| {
        s["job"]["condition"] == 51 && s["job"]["pass"] == 1
    });
    assert_eq!(s["job"]["from_line"]["pass"], 1, "{s}");
    assert_eq!(s["job"]["passes"], 3, "{s}");
    let s = daemon.wait_for("the end", |s| {
        s["state"] == "idle" && s["last_job"].is_object()
    });
    assert_eq!(s["last_job"]["outcome"], "done", "{s}");

    let (rows, end) = common::wire::walk(&dir.join("pulses.csv"));
    assert_eq!(end, (0, 0), "back at the start hole");
    // Pass 1 sparks from line 8's start on: at its offset (210 µm at 30 mm), never on the
    // right edge (lines 6 and 7, before line 8), which its approach went along dark.
    let cut1: Vec<(i64, i64)> = rows
        .iter()
        .filter(|(_, c, spark)| *c == 51 && *spark)
        .map(|(at, _, _)| *at)
        .collect();
    assert!(cut1.len() > 1000, "{} points of pass 1", cut1.len());
    assert!(
        cut1.iter()
            .filter(|p| p.0.abs() > 300)
            .all(|p| (inside_die(p) - 210).abs() <= 2),
        "pass 1 off its offset"
    );
    assert!(
        !cut1.iter().any(|p| p.0 > 2100 && p.1 < 2000),
        "pass 1 cut the right edge, before its line"
    );
    let (by, _) = positions_by_condition(&dir.join("pulses.csv"));
    common::wire::assert_passes(&by, &[(52, 155, -1.0), (53, 125, 1.0)], &inside_die);
    let jobs = daemon.ok(&["jobs", "--count", "1"]);
    let record = &jobs["jobs"][0];
    assert_eq!(record["from_line"], 8, "{record}");
    assert_eq!(record["from_pass"], 1, "{record}");

    // What cannot be cut so is refused before anything moves.
    for (program, pass, needle) in [
        (
            "die.ngc",
            "2",
            "pass 2 runs the contour the other way round",
        ),
        ("die.ngc", "4", "pass 4: the job cuts 3 passes"),
        ("plain.ngc", "2", "the job is not cut in passes"),
    ] {
        let args = [
            "run",
            program,
            "--from-line",
            "8",
            "--wire-at",
            "start-hole",
            "--pass",
            pass,
            "--force",
        ];
        let (reply, code) = daemon.ctl(&args);
        assert_eq!(code, 1, "{reply}");
        assert!(reply.to_string().contains(needle), "{args:?}: {reply}");
    }
}
