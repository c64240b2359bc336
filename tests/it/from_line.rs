//! Running a program from a line (`--from-line N`): the interpreter replays the program up
//! to the line without cutting, the machine approaches the line's start (along the path with
//! the spark off, or directly over the safe Z), and from there the pulses are the full run's.
//! Through the real binary: `edmd run` in virtual time, and `edmd ctl run` on a daemon, whose
//! checkpoint taken during the approach resumes into the approach, never into a cut.

use crate::common;

use std::path::{Path, PathBuf};

use common::daemon::{Daemon, base_sets, ints};
use edmd::output::{PulseLogRow, read_pulse_log};

const DIE: &str = "die-from-line.ngc";
const SINK: &str = "sink-from-line.ngc";

fn data(name: &str) -> PathBuf {
    common::repo().join("tests/data").join(name)
}

/// `edmd run PROGRAM ARGS` with no gap into `pulses`; the exit code and standard error.
fn run(program: &Path, pulses: &Path, args: &[&str]) -> (i32, String) {
    let mut all = vec!["--set", "compensation.d_mm=[0.0, 0.15]"];
    all.extend(args);
    let out = common::run_to_pulse_log(program, pulses, &all);
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Every moving tick of a pulse log with the position after it.
fn walk(path: &Path) -> Vec<(Vec<i64>, PulseLogRow)> {
    let (_, rows) = read_pulse_log(path).unwrap();
    let mut here = vec![0i64; rows.first().map_or(0, |r| r.steps.len())];
    rows.into_iter()
        .filter(|r| r.steps.iter().any(|&s| s != 0))
        .map(|r| {
            for (h, s) in here.iter_mut().zip(&r.steps) {
                *h += i64::from(*s);
            }
            (here.clone(), r)
        })
        .collect()
}

/// The positions of `walk` from the first time it stands at `at` (exclusive) to the end.
fn tail_from(walk: &[(Vec<i64>, PulseLogRow)], at: &[i64]) -> Vec<Vec<i64>> {
    let i = walk
        .iter()
        .position(|(p, _)| p == at)
        .unwrap_or_else(|| panic!("the path never reaches {at:?}"));
    walk[i + 1..].iter().map(|(p, _)| p.clone()).collect()
}

#[test]
fn from_a_line_inside_a_loop_the_path_approach_is_dark_and_the_cut_is_the_full_runs() {
    let dir = common::scratch("from_line", "path");
    let (full, from) = (dir.join("full.csv"), dir.join("from13.csv"));
    assert_eq!(run(&data(DIE), &full, &[]).0, 0);
    let (code, err) = run(&data(DIE), &from, &["--from-line", "13"]);
    assert_eq!(code, 0, "{err}");
    let (full, from) = (walk(&full), walk(&from));
    // The path approach moves the whole path: the same lattice points, in the same order.
    let points =
        |w: &[(Vec<i64>, PulseLogRow)]| w.iter().map(|(p, _)| p.clone()).collect::<Vec<_>>();
    assert_eq!(points(&from), points(&full));
    // Dark up to the start of line 13's first pass: the arc's offset end (15 - 0.15, 6),
    // then sparking in E1, which line 11 selected before the loop.
    let start = vec![14850, 6000];
    // (The tick that arrives there already sparks: the cut's block is in hand at its end.)
    let i = from.iter().position(|(p, _)| *p == start).unwrap();
    assert!(
        from[..i].iter().all(|(_, r)| !r.spark),
        "a spark during the approach"
    );
    assert!(from[i + 1].1.spark, "no spark after the approach");
    assert_eq!(from[i + 1].1.condition, 1);
    // The full run sparked along all of it; the approach ran slower (the rethread feed
    // below the program's F300) and faster than nothing.
    assert!(full[..=i].iter().filter(|(_, r)| r.spark).count() > i / 2);
    let ticks = |w: &[(Vec<i64>, PulseLogRow)], i: usize| w[i].1.tick;
    let approach = ticks(&from, i) as f64;
    let cut = ticks(&full, i) as f64;
    assert!(approach > 0.0 && cut > 0.0);
    assert_eq!(tail_from(&from, &start), tail_from(&full, &start));
}

#[test]
fn the_direct_approach_rises_to_the_safe_z_crosses_and_plunges_then_cuts_the_tail() {
    let dir = common::scratch("from_line", "direct");
    let (full, from) = (dir.join("full.csv"), dir.join("from6.csv"));
    let xyz = data("xyz.toml");
    let machine = [
        "--config",
        xyz.to_str().unwrap(),
        "--set",
        "machine.safe_z_mm=10.0",
    ];
    assert_eq!(run(&data(SINK), &full, &machine).0, 0);
    let mut args = machine.to_vec();
    args.extend(["--from-line", "6"]);
    let (code, err) = run(&data(SINK), &from, &args);
    assert_eq!(code, 0, "{err}");
    let from = walk(&from);
    // The corners of the approach: straight up to Z10, across at Z10, down to line 6's
    // start (5, 0, -1), all dark; the rest is the full run's tail from there.
    let corners: Vec<Vec<i64>> = from
        .windows(3)
        .filter(|w| {
            let d = |a: &Vec<i64>, b: &Vec<i64>| {
                a.iter().zip(b).map(|(x, y)| y - x).collect::<Vec<_>>()
            };
            d(&w[0].0, &w[1].0) != d(&w[1].0, &w[2].0)
        })
        .map(|w| w[1].0.clone())
        .collect();
    let start = vec![5000, 0, -1000];
    assert_eq!(corners[..2], [vec![0, 0, 10000], vec![5000, 0, 10000]]);
    let i = from.iter().position(|(p, _)| *p == start).unwrap();
    assert!(
        from[..i].iter().all(|(_, r)| !r.spark),
        "a spark during the approach"
    );
    assert!(from[i + 1].1.spark);
    assert_eq!(tail_from(&from, &start), tail_from(&walk(&full), &start));
}

/// As CAM posts write a wire program: `G41 D1` on the first move. Every line up to the entry
/// runs the whole program (there is nothing to approach along); the contour's lines run
/// from their start.
#[test]
fn a_program_whose_first_move_is_the_entry_runs_from_any_line_up_to_it_and_after_it() {
    let dir = common::scratch("from_line", "entry_first");
    let program = dir.join("g41-first.ngc");
    std::fs::write(
        &program,
        "G21 G90 G17\nG41 D1 G1 X0 Y1 F300\nG1 X10 Y1\nG1 X10 Y11\nG1 X0 Y11\nG1 X0 Y1\n\
         G40 G1 X-5 Y1\nM2\n",
    )
    .unwrap();
    let full = dir.join("full.csv");
    assert_eq!(run(&program, &full, &[]).0, 0);
    let full = walk(&full);
    for line in ["1", "2"] {
        let p = dir.join(format!("from{line}.csv"));
        let (code, err) = run(&program, &p, &["--from-line", line]);
        assert_eq!(code, 0, "from line {line}: {err}");
        let from = walk(&p);
        let points =
            |w: &[(Vec<i64>, PulseLogRow)]| w.iter().map(|(p, _)| p.clone()).collect::<Vec<_>>();
        assert_eq!(
            points(&from),
            points(&full),
            "from line {line}: the whole program"
        );
        assert!(
            from.iter().take(5).all(|(_, r)| r.spark),
            "from line {line} cuts from the start"
        );
    }
    // From the second contour line: dark along the first, cutting from (10, 11) less the
    // offset, exactly the full run's tail.
    let p = dir.join("from4.csv");
    let (code, err) = run(&program, &p, &["--from-line", "4"]);
    assert_eq!(code, 0, "{err}");
    let from = walk(&p);
    let start = vec![9850, 1150];
    let i = from.iter().position(|(p, _)| *p == start).unwrap();
    assert!(
        from[..i].iter().all(|(_, r)| !r.spark),
        "a spark during the approach"
    );
    assert_eq!(tail_from(&from, &start), tail_from(&full, &start));
}

#[test]
fn lines_a_run_cannot_start_from_are_refused_at_their_line_before_anything_moves() {
    let dir = common::scratch("from_line", "refused");
    let pulses = dir.join("p.csv");
    // The entry move of the wire offset (line 8; line 7 holds the G41, so it starts there too).
    for line in ["7", "8"] {
        let (code, err) = run(&data(DIE), &pulses, &["--from-line", line]);
        assert_eq!(code, 2, "{err}");
        assert!(
            err.contains("die-from-line.ngc:8:1: this is the wire offset's entry move"),
            "{err}"
        );
        // It names the first line that can be run from: the next move's.
        assert!(err.contains("run from line 9 or later"), "{err}");
    }
    let (code, err) = run(&data(DIE), &pulses, &["--from-line", "18"]);
    assert_eq!(code, 2);
    assert!(
        err.contains("die-from-line.ngc:18:1: no move at or after line 18"),
        "{err}"
    );
    let probing = dir.join("probe.ngc");
    std::fs::write(&probing, "G21 G90\nG38.3 X3 F100\nG1 X5 F100\nM2\n").unwrap();
    let (code, err) = run(&probing, &pulses, &["--from-line", "3"]);
    assert_eq!(code, 2);
    assert!(
        err.contains("probe.ngc:2:1: the program probes here, before line 3"),
        "{err}"
    );
    let (code, err) = run(&data(DIE), &pulses, &["--approach", "direct"]);
    assert_eq!(code, 2, "--approach without --from-line: {err}");
}

#[test]
fn a_checkpoint_taken_during_the_approach_resumes_into_the_approach() {
    let dir = common::daemon::scratch("from-line");
    // The program without its conditions (E1's 10 mm/min would make the cut minutes long).
    let text = std::fs::read_to_string(data(DIE)).unwrap();
    let text = text
        .replace("\nE2\n", "\n(E2)\n")
        .replace("\nE1\n", "\n(E1)\n");
    std::fs::write(dir.join("programs").join(DIE), text).unwrap();
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    let mut sets = base_sets(&dir, "first.csv");
    sets.push("compensation.d_mm=[0.0, 0.15]".into());
    // A slow approach, so a hold lands inside it.
    sets.push("servo.rethread_feed_mm_per_min=300.0".into());
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.refused(&["run", DIE, "--from-line", "0"], "");
    daemon.refused(
        &["run", DIE, "--dry-run", "--from-line", "13"],
        "does not start from a line",
    );
    daemon.ok(&["run", DIE, "--from-line", "13", "--wire-at", "start-hole"]);
    daemon.wait_for("moving", |s| {
        // On the way from the start (X0) to the start hole: moved, still approaching.
        s["state"] == "running" && s["job"]["position_steps"][0].as_i64().unwrap_or(0) < -1000
    });
    let cp = daemon.hold_abort_checkpoint(&dir);
    assert_eq!(cp["from_line"]["line"], 13, "{cp}");
    assert_eq!(cp["from_line"]["approach"], "path", "{cp}");
    assert!(
        cp["line"].as_u64().unwrap() < 13,
        "held before line 13: {cp}"
    );
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);

    let mut sets = base_sets(&dir, "second.csv");
    sets.push("compensation.d_mm=[0.0, 0.15]".into());
    sets.push("servo.rethread_feed_mm_per_min=300.0".into());
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["resume"]);
    let idle = daemon.wait_for("the job's end", |s| s["state"] == "idle");
    assert_eq!(idle["last_job"]["outcome"], "done", "{idle}");
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);

    // Joined, the two runs are `edmd run --from-line 13`: dark up to line 13's start, the
    // same lattice points, sparking after.
    let reference = walk(&{
        let p = dir.join("reference.csv");
        assert_eq!(
            run(&dir.join("programs").join(DIE), &p, &["--from-line", "13"]).0,
            0
        );
        p
    });
    let mut joined = walk(&dir.join("first.csv"));
    let last = joined.last().map(|(p, _)| p.clone()).unwrap();
    joined.extend(
        walk(&dir.join("second.csv"))
            .into_iter()
            .map(|(p, r)| (p.iter().zip(&last).map(|(a, b)| a + b).collect(), r)),
    );
    let points =
        |w: &[(Vec<i64>, PulseLogRow)]| w.iter().map(|(p, _)| p.clone()).collect::<Vec<_>>();
    assert_eq!(points(&joined), points(&reference));
    let sparks = |w: &[(Vec<i64>, PulseLogRow)]| w.iter().map(|(_, r)| r.spark).collect::<Vec<_>>();
    assert_eq!(sparks(&joined), sparks(&reference));
}

/// A 10 mm die opening cut inward with `G41 D1` (0.15 mm) from a start hole at its centre:
/// a point of the executed path lies in the slug, not the kerf, when it is more than the
/// kerf's half-width (0.15 mm, twice the offset's margin) inside the wire's path (the square
/// at ±4.85 mm) and off the entry and exit line (offset to X0.15, Y below 0).
fn in_the_slug(x_mm: f64, y_mm: f64) -> bool {
    let inside = x_mm.abs() < 4.7 && y_mm.abs() < 4.7;
    let on_the_entry = (x_mm - 0.15).abs() < 0.2 && y_mm < 0.15;
    inside && !on_the_entry
}

/// Recovery after an abort mid-contour: the operator says where the wire stands; from where
/// the job stopped the wire goes back along its kerf to the line, spark off, then cuts from
/// there; no executed point crosses the uncut slug. Asking with the wire elsewhere than it
/// says, or for a line past the stop, is refused with what to do.
#[test]
fn after_an_abort_a_run_from_a_line_goes_back_along_the_kerf_never_through_the_slug() {
    const PROGRAM: &str = "die-recover.ngc";
    let dir = common::daemon::scratch("recover");
    std::fs::copy(data(PROGRAM), dir.join("programs").join(PROGRAM)).unwrap();
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.push("compensation.d_mm=[0.0, 0.15]".into());
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["run", PROGRAM]);
    // Stopped up the right side (line 8), a millimetre past the middle.
    daemon.wait_for("the right side", |s| {
        s["state"] == "running" && s["job"]["position_steps"][1].as_i64().unwrap_or(0) > 1000
    });
    let cp = daemon.hold_abort_checkpoint(&dir);
    assert_eq!(cp["line"], 8, "{cp}");
    let stopped = ints(&cp["position_steps"]);
    let first = walk(&dir.join("pulses.csv"));
    assert!(first.iter().all(|(p, _)| !in_the_slug(mm(p[0]), mm(p[1]))));

    // Where the wire stands is asked, and held to the checkpoint.
    let args = |wire_at: &'static str, line: &'static str| {
        let mut a = vec!["run", PROGRAM, "--from-line", line];
        if !wire_at.is_empty() {
            a.extend(["--wire-at", wire_at]);
        }
        a
    };
    daemon.refused(&args("", "7"), "say where that is");
    // The old way (the program re-based at the wire, the entry across the slug): refused.
    let e = daemon.refused(
        &args("start-hole", "7"),
        "not at the start hole X0.0000 Y0.0000",
    );
    assert!(e.to_string().contains("--wire-at stopped"), "{e}");
    // Line 9 (the top) was never cut: the wire cannot get there.
    daemon.refused(
        &args("stopped", "9"),
        "die-recover.ngc:9:1: line 9 starts past where the job stopped (line 8",
    );
    daemon.ok(&args("stopped", "7"));
    let idle = daemon.wait_for("the job's end", |s| s["state"] == "idle");
    assert_eq!(idle["last_job"]["outcome"], "done", "{idle}");
    assert_eq!(
        ints(&idle["last_job"]["end_steps"]),
        [0, 0],
        "back at the start hole"
    );
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);

    let second: Vec<(f64, f64, bool)> = walk(&dir.join("pulses.csv"))
        .into_iter()
        .map(|(p, r)| (mm(p[0] + stopped[0]), mm(p[1] + stopped[1]), r.spark))
        .collect();
    let slug: Vec<_> = second
        .iter()
        .filter(|(x, y, _)| in_the_slug(*x, *y))
        .collect();
    assert!(
        slug.is_empty(),
        "{} points in the slug: {:?}",
        slug.len(),
        &slug[..slug.len().min(5)]
    );
    // Dark down the right side and back along the bottom to line 7's start (X0.15 Y-4.85,
    // where the entry's offset meets the bottom's), every point on the first run's path...
    let lit = second.iter().position(|p| p.2).expect("a cut");
    let (x, y, _) = second[lit];
    assert!(
        (x - 0.15).abs() < 0.01 && (y + 4.85).abs() < 0.01,
        "the cut starts at ({x}, {y})"
    );
    let cut: std::collections::HashSet<(i64, i64)> =
        first.iter().map(|(p, _)| (p[0] / 5, p[1] / 5)).collect();
    let off_the_kerf = second[..lit].iter().filter(|(x, y, _)| {
        let (i, j) = (
            (x * 1000.0).round() as i64 / 5,
            (y * 1000.0).round() as i64 / 5,
        );
        !(-1..=1).any(|di| (-1..=1).any(|dj| cut.contains(&(i + di, j + dj))))
    });
    assert_eq!(
        off_the_kerf.count(),
        0,
        "the way back is the first run's path (to 10 µm)"
    );
    let (bx, by) = second[..lit]
        .iter()
        .fold((f64::MIN, f64::MAX), |(bx, by), p| {
            (bx.max(p.0), by.min(p.1))
        });
    assert!(
        (bx - 4.85).abs() < 0.01 && (by + 4.85).abs() < 0.01,
        "by the corner"
    );
    // ...then round the whole contour, sparking, and out to the start hole.
    let top = second[lit..].iter().map(|p| p.1).fold(f64::MIN, f64::max);
    assert!((top - 4.85).abs() < 0.01, "the top side cut: {top}");
}

fn mm(steps: i64) -> f64 {
    steps as f64 * 0.001
}
