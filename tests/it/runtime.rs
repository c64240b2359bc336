//! `edmd run` end to end: the real binary with the pulse-log output and scripted gap
//! schedules. Every test replays the log and checks it against the program.
//!
//! Replay rule (the test program has no fold-backs, so the log alone tells the directions):
//! a move to the point before the current one on the forward path is a turn-back move; any
//! other move is forward and, after a turn-back, must revisit the retraced points in reverse.

use crate::common;

use std::path::{Path, PathBuf};

use common::repo;
use std::process::{Command, Output};
use std::time::Duration;

use edmd::gap::GapState;
use edmd::gcode::open_program;
use edmd::output::read_pulse_log;
use edmd::vocab::Axis;

const PROGRAM: &str = "tests/data/runtime-path.nc";
const STEP_MM: f64 = 0.001;
const TOLERANCE_MM: f64 = 0.001;

fn scratch(name: &str) -> PathBuf {
    common::scratch("runtime", name)
}

/// Runs `edmd run PROGRAM` with the pulse log in `dir`, a gap script (if any) and extra
/// overrides; returns the process output and the JSON summary. The servo feeds are the
/// defaults: 1 mm/s sparking (20 ticks per step along an axis), 2 mm/s turning back. At
/// these speeds braking at `a_T` takes 0.2 µm, less than a step, so a turn-back starts where
/// the short found the electrode.
fn run(dir: &Path, script: Option<&str>, extra: &[&str]) -> (Output, serde_json::Value) {
    let log = dir.join("pulses.csv");
    let summary = dir.join("summary.json");
    let mut args = vec![
        "run".to_string(),
        PROGRAM.to_string(),
        "--summary".to_string(),
        summary.display().to_string(),
        "--set".to_string(),
        "output.kind=file".to_string(),
        "--set".to_string(),
        format!("output.path={}", log.display()),
    ];
    match script {
        Some(text) => {
            let path = dir.join("gap.txt");
            std::fs::write(&path, text).unwrap();
            args.extend([
                "--set".to_string(),
                "gap.kind=script".to_string(),
                "--set".to_string(),
                format!("gap.script={}", path.display()),
            ]);
        }
        None => args.extend(["--set".to_string(), "gap.kind=none".to_string()]),
    }
    for e in extra {
        args.extend(["--set".to_string(), e.to_string()]);
    }
    let out = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .args(&args)
        .current_dir(repo())
        .output()
        .expect("edmd runs");
    let json = std::fs::read_to_string(&summary)
        .map(|t| serde_json::from_str(&t).expect("summary is JSON"))
        .unwrap_or(serde_json::Value::Null);
    (out, json)
}

/// The replayed pulse log.
#[derive(Debug, Default)]
struct Replay {
    /// Position after the last row.
    end: [i64; 2],
    /// The forward path at the end (every retraced point re-advanced over).
    forward: Vec<[i64; 2]>,
    /// Turn-back moves.
    backward_moves: u64,
    /// Tick of the first move of each turn-back episode and the point it left.
    turn_back_starts: Vec<(u64, [i64; 2])>,
    /// For each tick where the gap became short: how many retraced points were still to be
    /// re-advanced over (non-zero means the short came during a re-advance).
    pending_at_short: Vec<usize>,
    /// Tick of the first row at each position, forward moves only.
    first_reached: Vec<(u64, [i64; 2])>,
    last_tick: u64,
}

fn replay(log: &Path) -> Replay {
    let (header, rows) = read_pulse_log(log).expect("pulse log reads back");
    assert_eq!(header.axes, vec![Axis::X, Axis::Y]);
    assert_eq!(header.step_mm, vec![STEP_MM, STEP_MM]);
    let mut r = Replay::default();
    let mut pos = [header.start[0], header.start[1]];
    let mut stack = vec![pos];
    let mut undone: Vec<[i64; 2]> = Vec::new();
    let mut gap = GapState::Normal;
    let mut in_turn_back = false;
    let mut last_tick = None;
    for row in rows {
        assert!(
            last_tick.is_none_or(|t| row.tick > t),
            "ticks increase, one row per tick"
        );
        last_tick = Some(row.tick);
        if row.gap == GapState::Short && gap != GapState::Short {
            r.pending_at_short.push(undone.len());
        }
        gap = row.gap;
        if row.steps.iter().all(|&s| s == 0) {
            continue;
        }
        let q = [pos[0] + row.steps[0] as i64, pos[1] + row.steps[1] as i64];
        if stack.len() >= 2 && stack[stack.len() - 2] == q {
            if !in_turn_back {
                r.turn_back_starts.push((row.tick, pos));
                in_turn_back = true;
            }
            undone.push(stack.pop().unwrap());
            r.backward_moves += 1;
        } else {
            in_turn_back = false;
            match undone.pop() {
                Some(expected) => assert_eq!(
                    q, expected,
                    "tick {}: re-advance left the retraced path",
                    row.tick
                ),
                None => r.first_reached.push((row.tick, q)),
            }
            stack.push(q);
        }
        pos = q;
    }
    assert!(
        undone.is_empty() || gap == GapState::Short,
        "ended with {} retraced points not re-advanced over",
        undone.len()
    );
    r.end = pos;
    r.forward = stack;
    r.last_tick = last_tick.unwrap_or(0);
    r
}

/// Distance (mm) from every forward point to the program's true curves, sampled densely.
fn max_deviation_mm(forward: &[[i64; 2]]) -> f64 {
    let axes = [Axis::X, Axis::Y];
    let mut dense: Vec<[f64; 2]> = Vec::new();
    for block in open_program(&repo().join(PROGRAM), &axes).unwrap() {
        let curve = block.unwrap().curve;
        let n = ((curve.length() / 0.0005) as usize).max(2000);
        let (a, b) = (curve.u_min(), curve.u_max());
        for i in 0..=n {
            let p = curve.point(a + (b - a) * i as f64 / n as f64);
            dense.push([p[0], p[1]]);
        }
    }
    let seg_dist = |p: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        let d = [b[0] - a[0], b[1] - a[1]];
        let len2 = d[0] * d[0] + d[1] * d[1];
        let t = if len2 > 0.0 {
            (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        ((p[0] - a[0] - t * d[0]).powi(2) + (p[1] - a[1] - t * d[1]).powi(2)).sqrt()
    };
    // The path moves along the curve, so the nearest piece is found in a window that follows.
    let mut at = 0usize;
    let mut worst: f64 = 0.0;
    for q in forward {
        let p = [q[0] as f64 * STEP_MM, q[1] as f64 * STEP_MM];
        let lo = at.saturating_sub(200);
        let hi = (at + 4000).min(dense.len() - 1);
        let (best, dist) = (lo..hi)
            .map(|i| (i, seg_dist(p, dense[i], dense[i + 1])))
            .min_by(|x, y| x.1.total_cmp(&y.1))
            .unwrap();
        at = best;
        worst = worst.max(dist);
    }
    worst
}

fn program_end() -> [i64; 2] {
    [7500, 8250]
}

fn assert_finished_exactly(out: &Output, summary: &serde_json::Value, r: &Replay) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert_eq!(summary["outcome"], "done");
    assert_eq!(r.end, program_end(), "replayed end point");
    assert_eq!(summary["end_steps"], serde_json::json!(program_end()));
    assert_eq!(
        summary["program_end_steps"],
        serde_json::json!(program_end())
    );
    assert_eq!(
        summary["events_backward"].as_u64(),
        Some(r.backward_moves),
        "the log's turn-back moves are the interpolator's backward events"
    );
    let deviation = max_deviation_mm(&r.forward);
    let bound = TOLERANCE_MM + STEP_MM * 2f64.sqrt();
    eprintln!("replayed path: {deviation:.6} mm from the curve at most (bound {bound:.6})");
    assert!(
        deviation <= bound,
        "path {deviation:.6} mm from the curve (bound {bound:.6})"
    );
}

#[test]
fn without_shorts_the_path_follows_the_curve_and_ends_exactly() {
    let dir = scratch("plain");
    let (out, summary) = run(&dir, None, &[]);
    let r = replay(&dir.join("pulses.csv"));
    assert_finished_exactly(&out, &summary, &r);
    assert_eq!(r.backward_moves, 0);
    assert_eq!(summary["shorts"], 0);
    assert!(summary["segments"].as_u64().unwrap() > 6);
    for key in [
        "turn_backs",
        "deepest_turn_back_blocks",
        "alarms",
        "starvations",
        "overruns",
    ] {
        assert_eq!(summary[key], 0, "{key}");
    }
}

#[test]
fn a_short_mid_block_turns_back_and_re_advances_over_the_same_points() {
    let dir = scratch("mid");
    // About 8 mm in (on the NURBS curve), 6000 ticks at the 2 mm/s retract feed: about
    // 600 µm back, across segment boundaries.
    let (out, summary) = run(&dir, Some("160000 short\n166000 normal\n"), &[]);
    let r = replay(&dir.join("pulses.csv"));
    assert_finished_exactly(&out, &summary, &r);
    assert_eq!(summary["shorts"], 1);
    assert_eq!(summary["turn_backs"], 1);
    assert!(r.backward_moves > 100, "{} moves back", r.backward_moves);
    assert!(summary["deepest_turn_back_blocks"].as_u64().unwrap() >= 1);
    assert_eq!(r.turn_back_starts.len(), 1);
}

#[test]
fn a_short_exactly_at_a_block_boundary() {
    // Where does the path reach the end of the first line (2, 0), a block boundary?
    let dir = scratch("boundary-find");
    let (out, _) = run(&dir, None, &[]);
    assert!(out.status.success());
    let plain = replay(&dir.join("pulses.csv"));
    let corner = [2000, 0];
    let (tick, _) = *plain
        .first_reached
        .iter()
        .find(|(_, q)| *q == corner)
        .expect("the path passes the corner");
    // The short is sampled on the next tick, with the electrode exactly on the corner.
    let dir = scratch("boundary");
    let script = format!("{} short\n{} normal\n", tick + 1, tick + 2000);
    let (out, summary) = run(&dir, Some(&script), &[]);
    let r = replay(&dir.join("pulses.csv"));
    assert_finished_exactly(&out, &summary, &r);
    assert_eq!(summary["shorts"], 1);
    assert_eq!(r.turn_back_starts.len(), 1);
    assert_eq!(
        r.turn_back_starts[0].1, corner,
        "the turn-back leaves from the block boundary"
    );
    assert!(r.backward_moves > 10);
}

#[test]
fn a_short_during_re_advance_turns_back_again_and_still_ends_exactly() {
    let dir = scratch("readvance");
    // Cleared at 162000 after 2000 ticks back (~200 µm); re-advancing at 1 mm/s takes
    // ~4000 ticks for that, so at 163000 the electrode is still on retraced ground.
    let (out, summary) = run(
        &dir,
        Some("160000 short\n162000 normal\n163000 short\n164000 open\n"),
        &[],
    );
    let r = replay(&dir.join("pulses.csv"));
    assert_finished_exactly(&out, &summary, &r);
    assert_eq!(summary["shorts"], 2);
    assert_eq!(summary["turn_backs"], 2);
    assert_eq!(r.pending_at_short.len(), 2);
    assert_eq!(
        r.pending_at_short[0], 0,
        "the first short comes in new ground"
    );
    assert!(
        r.pending_at_short[1] > 0,
        "the second short comes during the re-advance"
    );
}

#[test]
fn a_short_longer_than_the_reserved_area_is_an_alarm_that_keeps_position() {
    let dir = scratch("alarm");
    let (out, summary) = run(&dir, Some("160000 short\n"), &["buffer.reserved=2"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("ALARM"), "{stderr}");
    assert_eq!(summary["outcome"], "alarm");
    assert_eq!(summary["alarms"], 1);
    // Two reserved blocks plus the partly executed one were retraced.
    assert_eq!(summary["deepest_turn_back_blocks"], 2);
    let r = replay(&dir.join("pulses.csv"));
    assert_eq!(
        summary["end_steps"],
        serde_json::json!(r.end),
        "the ledger equals the replayed position"
    );
    assert_eq!(summary["events_backward"].as_u64(), Some(r.backward_moves));
    let ticks = summary["ticks"].as_u64().unwrap();
    assert!(
        r.last_tick < ticks,
        "nothing was emitted after the alarm (last row {}, {ticks} ticks)",
        r.last_tick
    );
    assert_ne!(r.end, program_end());
}

#[test]
fn the_main_job_runs_on_the_default_config() {
    // README: `edmd run programs/jin-table1-g06_2.nc` with the simulated gap. The shorter
    // Huang program keeps the suite quick; both use the same code.
    let dir = scratch("default");
    let summary_path = dir.join("s.json");
    let out = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .args([
            "run",
            "programs/huang-table1-g38.nc",
            "--summary",
            summary_path.to_str().unwrap(),
        ])
        .current_dir(repo())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{stdout}");
    assert!(
        stdout.contains("programs/huang-table1-g38.nc: done"),
        "{stdout}"
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&summary_path).unwrap()).unwrap();
    assert_eq!(summary["end_steps"], summary["program_end_steps"]);
    assert!(summary["shorts"].as_u64().unwrap() > 0, "{stdout}");
    assert_eq!(summary["shorts"], summary["turn_backs"]);
    assert_eq!(summary["virtual_time"], true);
}

#[test]
fn bad_gap_scripts_and_programs_are_located_before_anything_moves() {
    let dir = scratch("bad");
    let (out, _) = run(&dir, Some("100 short\n50 normal\n"), &[]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("gap.txt:2:1: tick 50 comes before the previous line's tick 100"),
        "{stderr}"
    );
    assert!(!dir.join("summary.json").exists());

    let program = dir.join("bad.nc");
    std::fs::write(&program, "G1 X1 F100\nG1 X2\nG1 X3 Q7\n").unwrap();
    let log = dir.join("never.csv");
    let out = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .args([
            "run",
            program.to_str().unwrap(),
            "--set",
            "output.kind=file",
            "--set",
            &format!("output.path={}", log.display()),
        ])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("bad.nc:3:7:"), "{stderr}");
    assert!(
        !log.exists(),
        "no pulse log for a program that never started"
    );
}

/// `run`, but killed (and failed) if it has not ended within `limit`: a wedge is a failure,
/// not a hung test.
fn run_within(
    dir: &Path,
    script: Option<&str>,
    extra: &[&str],
    limit: Duration,
) -> (Output, serde_json::Value) {
    let (tx, rx) = std::sync::mpsc::channel();
    let (dir2, script2) = (dir.to_path_buf(), script.map(str::to_string));
    let extra2: Vec<String> = extra.iter().map(|s| s.to_string()).collect();
    std::thread::spawn(move || {
        let extra: Vec<&str> = extra2.iter().map(String::as_str).collect();
        let _ = tx.send(run(&dir2, script2.as_deref(), &extra));
    });
    rx.recv_timeout(limit)
        .unwrap_or_else(|_| panic!("{extra:?}: no end within {limit:?} (wedged)"))
}

#[test]
fn every_ring_the_configuration_accepts_runs_to_the_end_with_turn_backs() {
    // Every (capacity, reserved) pair up to 4 slots, and the "reserved = capacity - 1" ones
    // that used to wedge; short segments so the ring turns over thousands of times, and a
    // short that turns back across segments.
    let mut pairs: Vec<(usize, usize)> =
        (2..=4).flat_map(|c| (0..c).map(move |r| (c, r))).collect();
    pairs.extend([(8, 7), (64, 63)]);
    for (capacity, reserved) in pairs {
        let dir = scratch(&format!("ring-{capacity}-{reserved}"));
        let (c, r) = (
            format!("buffer.capacity={capacity}"),
            format!("buffer.reserved={reserved}"),
        );
        let (out, summary) = run_within(
            &dir,
            Some("160000 short\n160600 normal\n"),
            &[&c, &r, "interpolation.max_segment_mm=0.05"],
            Duration::from_secs(60),
        );
        let stderr = String::from_utf8_lossy(&out.stderr);
        let outcome = summary["outcome"].as_str().unwrap_or_default();
        let r = replay(&dir.join("pulses.csv"));
        eprintln!(
            "capacity {capacity}, reserved {reserved}: {outcome}, {} moves back",
            r.backward_moves
        );
        match outcome {
            "done" => assert_finished_exactly(&out, &summary, &r),
            // Too small a reserved area for the turn-back: the alarm keeps the position.
            "alarm" => assert_eq!(summary["end_steps"], serde_json::json!(r.end), "{stderr}"),
            other => panic!("capacity {capacity}, reserved {reserved}: {other}\n{stderr}"),
        }
        if reserved >= 3 {
            assert_eq!(
                outcome, "done",
                "capacity {capacity}, reserved {reserved}: {stderr}"
            );
            assert!(r.backward_moves > 0);
        }
    }
}

#[test]
fn sigterm_ends_edmd_run_within_a_second_while_it_checks_a_large_program() {
    let dir = scratch("sigterm-check");
    let big = dir.join("big.nc");
    {
        use std::io::Write;
        let mut out = std::io::BufWriter::new(std::fs::File::create(&big).unwrap());
        for i in 0..3_000_000u32 {
            writeln!(out, "G1 X{}.{:03} Y{} F600", i % 50, i % 1000, i % 7).unwrap();
        }
    }
    let child = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .arg("run")
        .arg(&big)
        .args(["--set", "gap.kind=none", "--set", "output.kind=null"])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(700));
    // SAFETY: kill(2) on our own child's pid.
    assert_eq!(unsafe { libc::kill(child.id() as i32, libc::SIGTERM) }, 0);
    let signalled = std::time::Instant::now();
    let out = child.wait_with_output().unwrap();
    let took = signalled.elapsed();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        took < Duration::from_secs(1),
        "ended {took:?} after SIGTERM: {stderr}"
    );
    assert!(!out.status.success());
    assert!(stderr.contains("cancelled"), "{stderr}");
}

#[test]
fn run_report_shows_what_ran_turn_backs_included() {
    let dir = scratch("report");
    std::fs::write(dir.join("gap.txt"), "160000 short\n166000 normal\n").unwrap();
    let report = dir.join("report");
    let out = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .args(["run", PROGRAM, "--report"])
        .arg(&report)
        .args([
            "--set",
            "output.kind=null",
            "--set",
            "gap.kind=script",
            "--set",
        ])
        .arg(format!("gap.script={}", dir.join("gap.txt").display()))
        .current_dir(repo())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(report.join("summary.json")).unwrap())
            .unwrap();
    assert_eq!(summary["outcome"], "done");
    // events.csv: the short, the turn-back and the resume, in that order, with time, line
    // and a position on the path.
    let events = std::fs::read_to_string(report.join("events.csv")).unwrap();
    let mut lines = events.lines();
    assert_eq!(lines.next(), Some("tick,time_s,line,event,depth,x_mm,y_mm"));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    let kinds: Vec<&str> = rows.iter().map(|r| r[3]).collect();
    assert_eq!(kinds, ["short", "turn_back", "resumed", "done"], "{events}");
    assert_eq!(rows[0][0], "160000");
    assert_eq!(
        rows[0][1].parse::<f64>().unwrap(),
        8.0,
        "160000 ticks of 50 µs"
    );
    assert!(
        rows[1][4].parse::<u64>().unwrap() >= 1,
        "turned back over blocks"
    );
    let line: u64 = rows[0][2].parse().unwrap();
    assert!((5..=9).contains(&line), "the short's source line: {line}");
    let x: f64 = rows[0][5].parse().unwrap();
    assert!(x > 4.0 && x < 10.0, "{events}");
    // The last event sits at the program's end.
    let end: Vec<f64> = rows[3][5..].iter().map(|v| v.parse().unwrap()).collect();
    assert_eq!(end, [7.5, 8.25]);
    let path = std::fs::read_to_string(report.join("path.svg")).unwrap();
    assert!(path.contains("turned back and re-advanced") && path.contains(">start</text>"));
    assert!(path.contains("short circuits (1)"));
    // The legend names only what happened: no jumps, wire breaks or probes in this job.
    for absent in ["jumps (", "wire breaks (", "probe contacts ("] {
        assert!(!path.contains(absent), "{absent} in the legend");
    }
    // The programmed path under the executed one, in the same (machine) coordinates: drawn
    // first, and over the same ground.
    let (programmed, executed) = (
        svg_path_box(&path, "#b8b8b8"),
        svg_path_box(&path, "#1f5fbf"),
    );
    assert!(path.contains("programmed path"), "named in the legend");
    assert!(
        path.find("stroke=\"#b8b8b8\"").unwrap() < path.find("stroke=\"#1f5fbf\"").unwrap(),
        "drawn under the executed path"
    );
    for (p, e) in programmed.iter().zip(&executed) {
        assert!((p - e).abs() < 3.0, "{programmed:?} vs {executed:?} (px)");
    }
    // The gap state on a band of its own, the short on it, not on the feed's axis.
    let feed = std::fs::read_to_string(report.join("feed.svg")).unwrap();
    assert!(feed.contains("machine time (s)") && feed.contains("feed (mm/min)"));
    assert!(feed.contains(">gap</text>"), "the band's label");
    for state in [">gap open</text>", ">normal</text>", ">short</text>"] {
        assert!(feed.contains(state), "{state} in the legend");
    }
    let shorts = feed
        .lines()
        .filter(|l| l.starts_with("<rect") && l.contains("height=\"16\" fill=\"#d02020\""))
        .count();
    assert_eq!(shorts, 1, "one short span on the band");
    assert_eq!(
        feed.matches("<path d=").count(),
        1,
        "the feed alone on the mm/min axis"
    );
}

/// The bounding box (min x, min y, max x, max y; px) of the `<path>`s drawn in `color`.
fn svg_path_box(svg: &str, color: &str) -> [f64; 4] {
    let mut b = [f64::MAX, f64::MAX, f64::MIN, f64::MIN];
    for line in svg
        .lines()
        .filter(|l| l.starts_with("<path d=") && l.contains(&format!("stroke=\"{color}\"")))
    {
        let d = line.split('"').nth(1).unwrap();
        for point in d.split_whitespace() {
            let (x, y) = point[1..].split_once(',').unwrap();
            let (x, y): (f64, f64) = (x.parse().unwrap(), y.parse().unwrap());
            b = [b[0].min(x), b[1].min(y), b[2].max(x), b[3].max(y)];
        }
    }
    assert!(b[0] <= b[2], "a {color} path");
    b
}

#[test]
fn run_report_dashes_the_rapids_it_ran() {
    let dir = scratch("report-rapids");
    let program = dir.join("rapids.nc");
    std::fs::write(&program, "G0 X2 Y2\nG1 X3 F600\nG0 X0 Y0\nM2\n").unwrap();
    let report = dir.join("report");
    let out = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .arg("run")
        .arg(&program)
        .arg("--report")
        .arg(&report)
        .args(["--set", "output.kind=null", "--set", "gap.kind=none"])
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let path = std::fs::read_to_string(report.join("path.svg")).unwrap();
    assert!(path.contains("rapids (G0)"), "named in the legend");
    // Two rapid strokes, dashed: from the start to (2, 2) and from (3, 2) home.
    let dashed: Vec<&str> = path
        .lines()
        .filter(|l| l.contains("stroke-dasharray=\"5 4\""))
        .collect();
    assert_eq!(dashed.len(), 1, "{path}");
    assert_eq!(
        dashed[0].matches('M').count(),
        2,
        "two strokes: {}",
        dashed[0]
    );
}
