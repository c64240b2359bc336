//! Sinker jumps, probing and wire breaks through the real `edmd run`, in virtual time on the
//! simulated gap (or a gap script): what the summary says is checked against the pulse log
//! the job wrote and against positions worked out from the simulator's settings.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;

use edmd::output::read_pulse_log;

/// A job's summary, pulse log rows (steps and spark) and exit code.
struct Job {
    summary: Value,
    rows: Vec<(Vec<i8>, bool)>,
    code: i32,
    stderr: String,
}

fn scratch(name: &str) -> PathBuf {
    common::scratch("excursions", name)
}

/// `edmd run` on `program` (written into `dir`) on three 1 µm axes with `sets`, pulses to
/// a log, the simulated gap without placed debris unless `sets` say otherwise.
fn run(dir: &Path, program: &str, sets: &[&str]) -> Job {
    let path = dir.join("p.ngc");
    std::fs::write(&path, program).unwrap();
    let pulses = dir.join("pulses.csv");
    let summary = dir.join("summary.json");
    let _ = std::fs::remove_file(&summary);
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_edmd"));
    cmd.arg("run")
        .arg(&path)
        .arg("--config")
        .arg(common::repo().join("tests/data/xyz.toml"))
        .arg("--summary")
        .arg(&summary)
        .args([
            "--set",
            "sim.debris_shorts_per_mm=0",
            "--set",
            "sim.model=\"kinematic\"",
            "--set",
            "output.kind=\"file\"",
        ])
        .arg("--set")
        .arg(format!("output.path=\"{}\"", pulses.display()));
    for s in sets {
        cmd.args(["--set", s]);
    }
    let out = cmd.output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    let summary: Value = serde_json::from_str(
        &std::fs::read_to_string(&summary).unwrap_or_else(|e| panic!("{e}: {stderr}")),
    )
    .unwrap();
    let (_, rows) = read_pulse_log(&pulses).unwrap();
    Job {
        summary,
        rows: rows
            .into_iter()
            .filter(|r| r.steps.iter().any(|&s| s != 0))
            .map(|r| (r.steps, r.spark))
            .collect(),
        code: out.status.code().unwrap_or(-1),
        stderr,
    }
}

fn ints(v: &Value) -> Vec<i64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_i64().unwrap())
        .collect()
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// The stretches of the pulse log where the spark is off, as (rows, net Z steps).
fn spark_off_runs(rows: &[(Vec<i8>, bool)]) -> Vec<(usize, i64, i64)> {
    let mut runs = Vec::new();
    let mut current: Option<(usize, i64, i64)> = None;
    for (steps, spark) in rows {
        match (&mut current, spark) {
            (Some((n, up, down)), false) => {
                *n += 1;
                if steps[2] > 0 {
                    *up += 1;
                } else if steps[2] < 0 {
                    *down += 1;
                }
            }
            (None, false) => current = Some((1, (steps[2] > 0) as i64, (steps[2] < 0) as i64)),
            (_, true) => {
                if let Some(r) = current.take() {
                    runs.push(r);
                }
            }
        }
    }
    runs.extend(current);
    runs
}

const PLUNGE: &str = "G21 G90\nG0 Z0.05\nG1 Z-0.5 F30\nM2\n";

/// A plunge with jumps: each lifts the electrode exactly the jump height straight up the
/// plunge (spark off), comes back down to where it left, and the job ends on −0.5 mm to the
/// step with every pulse accounted for.
#[test]
fn a_plunge_with_jumps_ends_exactly_and_every_jump_is_in_the_pulse_log() {
    let dir = scratch("plunge");
    let job = run(
        &dir,
        PLUNGE,
        &["servo.jump_interval_s=0.2", "servo.jump_height_mm=0.1"],
    );
    let s = &job.summary;
    assert_eq!(s["outcome"], "done", "{}", job.stderr);
    assert_eq!(ints(&s["end_steps"]), vec![0, 0, -500]);
    assert_eq!(ints(&s["program_end_steps"]), vec![0, 0, -500]);
    let jumps = s["jumps"].as_u64().unwrap();
    assert!(jumps >= 2, "{jumps} jumps");
    assert_eq!(s["shorts"], 0);
    // Up 100 steps and down 100 per jump, nothing else backwards.
    assert_eq!(s["events_backward"].as_u64().unwrap(), 100 * jumps);
    assert_eq!(
        ints(&s["steps_per_axis"]),
        vec![0, 0, 50 + 550 + 200 * jumps as i64]
    );
    // In the pulse log: the rapid, then one spark-off stretch per jump, each 100 up and
    // 100 down (the step arriving back at the cut carries the spark again).
    // (The program's last step ends it: the spark goes off with it.)
    let runs = spark_off_runs(&job.rows);
    let lifts: Vec<_> = runs.iter().filter(|r| r.1 > 0 && r.2 > 0).collect();
    assert_eq!(lifts.len() as u64, jumps, "{runs:?}");
    for &&(_, up, down) in &lifts {
        assert_eq!((up, down), (100, 99), "{runs:?}");
    }
    assert!(
        job.stderr.is_empty() || !job.stderr.contains("ERROR"),
        "{}",
        job.stderr
    );
    // The text summary shows them.
    let text = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .args(["run", "--config"])
        .arg(common::repo().join("tests/data/xyz.toml"))
        .arg(dir.join("p.ngc"))
        .args([
            "--set",
            "sim.debris_shorts_per_mm=0",
            "--set",
            "sim.model=\"kinematic\"",
            "--set",
            "servo.jump_interval_s=0.2",
            "--report",
        ])
        .arg(dir.join("report"))
        .output()
        .unwrap();
    // The run report marks them and lists them.
    let svg = std::fs::read_to_string(dir.join("report/path.svg")).unwrap();
    assert!(
        svg.contains(&format!("jumps ({jumps})")),
        "no jumps in path.svg"
    );
    let events = std::fs::read_to_string(dir.join("report/events.csv")).unwrap();
    assert_eq!(
        events.lines().filter(|l| l.contains(",jump,")).count() as u64,
        jumps
    );
    let stdout = String::from_utf8_lossy(&text.stdout);
    assert!(
        stdout.contains(&format!("excursions:       {jumps} jumps")),
        "{stdout}"
    );
}

/// A machining condition's own jump settings win over `[servo]`'s (here: none there).
#[test]
fn a_machining_condition_sets_its_own_jumps() {
    let dir = scratch("condition-jumps");
    let condition = "generator.condition=[{number=7,on_us=2.0,off_us=8.0,current_a=3.0,\
                     v_ref=25.0,feed_mm_per_min=60.0,jump_interval_s=0.1,jump_height_mm=0.05}]";
    let job = run(
        &dir,
        "G21 G90\nG0 Z0.05\nE7\nG1 Z-0.5 F30\nM2\n",
        &[condition],
    );
    let s = &job.summary;
    assert_eq!(s["outcome"], "done", "{}", job.stderr);
    assert_eq!(ints(&s["end_steps"]), vec![0, 0, -500]);
    let jumps = s["jumps"].as_u64().unwrap();
    assert!(jumps >= 3, "{jumps} jumps");
    assert_eq!(s["events_backward"].as_u64().unwrap(), 50 * jumps);
    let plain = run(&dir, PLUNGE, &[]);
    assert_eq!(plain.summary["jumps"], 0);
}

/// `G38.2` toward the simulated work: after a rapid the front is `sim.initial_gap_um`
/// (20 µm) ahead, and contact is a gap under `sim.short_gap_um` (1 µm): the probe stops 19 to
/// 20 µm on, within one step of that. `#5061` holds the point (the next move is planned from
/// it) and `G38.4` then backs off until contact is lost, one step later.
#[test]
fn probing_stops_at_contact_and_the_program_goes_on_from_there() {
    let dir = scratch("probe");
    let program = "G21 G90\nG0 X1\nG38.2 X3 F10\n#100=#5061\n#101=#5070\n\
                   G38.4 X0.5 F5\nG0 X[#100 - 0.2]\nG1 X[#100 - 0.2 + #101] F60\nM2\n";
    let job = run(&dir, program, &[]);
    let s = &job.summary;
    assert_eq!(s["outcome"], "done", "{}", job.stderr);
    assert_eq!(s["probes"], 2);
    assert_eq!(s["probe_contact"], true);
    // The first contact, read back through the end point: X = #5061 − 0.2 + #5070 (= 1).
    let end = floats(&s["end_mm"])[0];
    let contact = end + 0.2 - 1.0;
    assert!(
        (1.019 - 1e-9..=1.020 + 1e-9).contains(&contact),
        "contact at X{contact}"
    );
    // G38.4 lost contact one step back from the first contact.
    let away = floats(&s["probe_mm"])[0];
    assert!(
        (contact - away - 0.001).abs() < 1e-9,
        "G38.4 at {away}, contact at {contact}"
    );
    assert!(
        job.stderr.contains("p.ngc:3: probe contact at"),
        "{}",
        job.stderr
    );
    // Nothing sparks while probing: the spark comes on where the last G0 ends, the start
    // of the cut (its last step already carries the cut's spark).
    let spark_on = job.rows.iter().position(|r| r.1).unwrap();
    let x: i64 = job.rows[..spark_on].iter().map(|r| r.0[0] as i64).sum();
    let cut_start = ((contact - 0.2) * 1000.0).round() as i64;
    assert!(
        (x - cut_start).abs() <= 1,
        "spark on at {x} steps, the cut starts at {cut_start}"
    );
}

/// `G38.2` toward a scripted contact (the gap reads short from tick 3000): the probe reports
/// the point where the pulses stood when contact came, to the step, and the next move leaves
/// from there (the contact it rests on is not taken for a collision).
#[test]
fn a_scripted_contact_stops_the_probe_where_the_pulses_stood() {
    let dir = scratch("scripted-contact");
    std::fs::write(dir.join("gap.txt"), "0 normal\n3000 short\n3040 normal\n").unwrap();
    let script = format!("gap.script=\"{}\"", dir.join("gap.txt").display());
    let job = run(
        &dir,
        "G21 G90\nG38.2 X5 F30\nG0 X0\nM2\n",
        &["gap.kind=\"script\"", &script],
    );
    assert_eq!(job.summary["outcome"], "done", "{}", job.stderr);
    let (_, rows) = read_pulse_log(&dir.join("pulses.csv")).unwrap();
    let before: i64 = rows
        .iter()
        .filter(|r| r.tick < 3000)
        .map(|r| r.steps[0] as i64)
        .sum();
    let probed = floats(&job.summary["probe_mm"])[0];
    // 30 mm/min for 0.15 s, less the start's acceleration: about 75 µm.
    assert!(
        (60..=76).contains(&before),
        "{before} steps before the contact"
    );
    assert!(
        (probed * 1000.0 - before as f64).abs() <= 1.0,
        "probe at {probed} mm, the pulses at {before} steps"
    );
    assert_eq!(job.summary["collisions"], 0);
    assert_eq!(ints(&job.summary["end_steps"]), vec![0, 0, 0]);
}

/// `G38.2` that never touches is an error at its line; `G38.3` goes on with `#5070` = 0.
#[test]
fn a_probe_without_contact() {
    let dir = scratch("no-contact");
    let job = run(
        &dir,
        "G21 G90\nG38.2 X2 F60\nG0 X0\nM2\n",
        &["gap.kind=\"none\""],
    );
    assert_eq!(job.code, 1, "{}", job.stderr);
    assert_eq!(job.summary["outcome"], "probe-missed");
    assert_eq!(ints(&job.summary["end_steps"]), vec![2000, 0, 0]);
    assert!(
        job.stderr
            .contains("line 2: the probing move reached its end point without contact"),
        "{}",
        job.stderr
    );

    let program =
        "G21 G90\nG38.3 X2 F60\no1 if [#5070 EQ 0]\nG1 Y1\no1 else\nG1 Y5\no1 endif\nM2\n";
    let job = run(&dir, program, &["gap.kind=\"none\""]);
    assert_eq!(job.summary["outcome"], "done", "{}", job.stderr);
    assert_eq!(job.summary["probe_contact"], false);
    assert_eq!(ints(&job.summary["end_steps"]), vec![2000, 1000, 0]);
}

/// The simulator breaks the wire at a seeded point of the cut; `edmd run` (no operator)
/// stops there, says so, exits 1 and leaves a checkpoint.
#[test]
fn a_wire_break_stops_edmd_run_with_a_checkpoint() {
    let dir = scratch("wire-break");
    let checkpoint = dir.join("cp.json");
    let program = "G21 G90\nG0 X1\nG1 X5 F60\nG1 Y3\nM2\n";
    let path = dir.join("w.ngc");
    std::fs::write(&path, program).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .arg("run")
        .arg(&path)
        .arg("--checkpoint")
        .arg(&checkpoint)
        .args([
            "--set",
            "sim.debris_shorts_per_mm=0",
            "--set",
            "sim.model=\"kinematic\"",
            "--set",
            "sim.wire_breaks_per_m=300",
        ])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("WIRE BREAK"), "{stderr}");
    assert!(stderr.contains("wire break: line"), "{stderr}");
    let cp: Value = serde_json::from_str(&std::fs::read_to_string(&checkpoint).unwrap()).unwrap();
    assert_eq!(cp["still"], true);
    let x = cp["position_steps"][0].as_i64().unwrap();
    assert!((1001..5000).contains(&x), "broke at {x}");
}

/// With `servo.max_open_mm`, an open gap over that much cutting travel is a broken wire;
/// the approach through air from a rapid is open too, so it is off by default.
#[test]
fn an_open_gap_over_max_open_mm_is_a_wire_break() {
    let dir = scratch("open");
    std::fs::write(dir.join("gap.txt"), "0 normal\n2000 open\n").unwrap();
    let script = format!("gap.script=\"{}\"", dir.join("gap.txt").display());
    let sets = [
        "gap.kind=\"script\"",
        script.as_str(),
        "servo.max_open_mm=0.3",
    ];
    let job = run(&dir, "G21 G90\nG1 X5 F60\nM2\n", &sets);
    assert_eq!(job.summary["outcome"], "wire-break", "{}", job.stderr);
    assert!(
        job.stderr
            .contains("the gap stayed open over servo.max_open_mm"),
        "{}",
        job.stderr
    );
    // From tick 2000 (0.1 s at 60 mm/min: 0.1 mm) the gap is open; 0.3 mm later it breaks.
    let x = ints(&job.summary["end_steps"])[0];
    assert!((390..=420).contains(&x), "broke at {x}");
    let off = run(&dir, "G21 G90\nG1 X5 F60\nM2\n", &sets[..2]);
    assert_eq!(off.summary["outcome"], "done");
}
