//! Jerk-limited positioning (`machine.max_jerk_mm_per_s3`) through the real `edmd run`, in
//! virtual time, measured from the pulse log alone: each axis's position sampled every 1 ms
//! and its third difference over the window cubed.
//!
//! The pulse log knows a position only to the step below it, so a measured jerk carries up to
//! `4 steps / w³` of quantisation (the third difference's weights 1, 3, 3, 1 on errors in
//! `[0, 1)` step). With 1 µm steps over 1 ms that is 4e6 mm/s³, more than a trapezoid at
//! `a_T = 2400 mm/s²` shows (about `a_T / w` = 2.4e6): the measure could not tell them apart.
//! The jerk tests therefore run on a machine of 0.1 µm steps and 10 µs ticks, where the
//! quantisation is 4e5 mm/s³, and each also shows that the trapezoid fails the same bound.

use crate::common;

use std::path::Path;

use edmd::output::read_pulse_log;
use serde_json::Value;

/// 0.1 µm steps on every axis, 10 µs ticks (one step per tick: 10 mm/s).
const FINE: [&str; 2] = [
    "machine.step_mm=[0.0001, 0.0001, 0.0001]",
    "fine.tick_us=10",
];

/// The measuring window (s).
const WINDOW_S: f64 = 1e-3;

/// What a job left: its summary and its pulse log, one position per tick.
struct Job {
    summary: Value,
    step_mm: f64,
    tick_s: f64,
    /// Position per axis (steps) and spark at every tick.
    at: Vec<[i64; 3]>,
    spark: Vec<bool>,
}

fn run(dir: &Path, program: &str, sets: &[&str]) -> Job {
    let path = dir.join("p.ngc");
    std::fs::write(&path, program).unwrap();
    let pulses = dir.join("pulses.csv");
    let summary = dir.join("summary.json");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_edmd"))
        .arg("run")
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
        .arg(format!("output.path=\"{}\"", pulses.display()))
        .args(sets.iter().flat_map(|s| ["--set", s]))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let summary: Value = serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    let (header, rows) = read_pulse_log(&pulses).unwrap();
    let mut at = Vec::new();
    let mut spark = Vec::new();
    let (mut here, mut sparking) = ([0i64; 3], false);
    for row in rows {
        while (at.len() as u64) < row.tick {
            at.push(here);
            spark.push(sparking);
        }
        for (p, s) in here.iter_mut().zip(&row.steps) {
            *p += *s as i64;
        }
        sparking = row.spark;
    }
    at.push(here);
    spark.push(sparking);
    Job {
        summary,
        step_mm: header.step_mm[0],
        tick_s: header.tick_us as f64 * 1e-6,
        at,
        spark,
    }
}

impl Job {
    /// The largest jerk of `axis` over 1 ms windows (mm/s³), every phase of the windows,
    /// counting only windows whose every tick `counts`; and how many windows counted.
    fn max_jerk(&self, axis: usize, counts: impl Fn(usize) -> bool) -> (f64, usize) {
        let w = (WINDOW_S / self.tick_s).round() as usize;
        let (mut worst, mut windows) = (0.0f64, 0);
        let n = self.at.len();
        let ok: Vec<bool> = (0..n).map(&counts).collect();
        for i in 0..n.saturating_sub(3 * w) {
            if !ok[i..=i + 3 * w].iter().all(|&b| b) {
                continue;
            }
            let p = |k: usize| self.at[i + k * w][axis] as f64 * self.step_mm;
            let d3 = p(3) - 3.0 * p(2) + 3.0 * p(1) - p(0);
            worst = worst.max(d3.abs() / WINDOW_S.powi(3));
            windows += 1;
        }
        (worst, windows)
    }

    /// What one step's rounding can add to a measured jerk.
    fn quantisation(&self) -> f64 {
        4.0 * self.step_mm / WINDOW_S.powi(3)
    }

    fn ints(&self, key: &str) -> Vec<i64> {
        self.summary[key]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_i64().unwrap())
            .collect()
    }
}

fn sets<'a>(jerk: &'a str, more: &[&'a str]) -> Vec<&'a str> {
    let mut v: Vec<&str> = FINE.to_vec();
    v.push(jerk);
    v.extend_from_slice(more);
    v
}

#[test]
fn a_jerk_limited_rapid_stays_within_the_jerk_and_ends_exactly() {
    let dir = common::scratch("jerk", "rapid");
    let program = "G21 G90\nG0 X5\nM2\n";
    for (jerk, set) in [
        (1e5, "machine.max_jerk_mm_per_s3=1e5"),
        (1e6, "machine.max_jerk_mm_per_s3=1e6"),
    ] {
        let job = run(&dir, program, &sets(set, &[]));
        assert_eq!(job.summary["outcome"], "done");
        assert_eq!(job.ints("end_steps"), vec![50_000, 0, 0]);
        let (measured, windows) = job.max_jerk(0, |_| true);
        let bound = jerk + job.quantisation();
        println!(
            "G0 X5, limit {jerk:.0e} mm/s³: {measured:.3e} mm/s³ over {windows} windows \
             (bound {bound:.1e}), {:.4} s",
            job.summary["virtual_time_s"].as_f64().unwrap()
        );
        assert!(measured <= bound, "{measured:.3e} > {bound:.3e}");
    }
    // The measure tells a trapezoid from it: the same move without the limit breaks the
    // lower bound many times over.
    let job = run(&dir, program, &sets("machine.max_jerk_mm_per_s3=0", &[]));
    let (measured, _) = job.max_jerk(0, |_| true);
    println!("G0 X5, trapezoid: {measured:.3e} mm/s³");
    assert!(
        measured > 2.0 * (1e5 + job.quantisation()),
        "{measured:.3e}"
    );
}

#[test]
fn jumps_lift_and_come_down_within_the_jerk() {
    let dir = common::scratch("jerk", "jumps");
    let program = "G21 G90\nG0 Z0.05\nG1 Z-0.5 F30\nM2\n";
    let jumps = [
        "servo.jump_interval_s=0.2",
        "servo.jump_height_mm=0.1",
        "servo.jump_feed_mm_per_min=600",
    ];
    let measure = |job: &Job| job.max_jerk(2, |t| !job.spark[t]);
    let job = run(
        &dir,
        program,
        &sets("machine.max_jerk_mm_per_s3=1e5", &jumps),
    );
    assert_eq!(job.summary["outcome"], "done");
    assert_eq!(job.ints("end_steps"), vec![0, 0, -5_000]);
    let count = job.summary["jumps"].as_u64().unwrap();
    assert!(count >= 3, "{count} jumps");
    assert_eq!(job.summary["shorts"], 0);
    // Every jump lifts exactly its height: 1000 steps up and 1000 down.
    assert_eq!(
        job.summary["events_backward"].as_u64().unwrap(),
        1000 * count
    );
    let (measured, windows) = measure(&job);
    let bound = 1e5 + job.quantisation();
    println!(
        "{count} jumps of 0.1 mm at 600 mm/min, limit 1e5 mm/s³: {measured:.3e} mm/s³ over \
         {windows} spark-off windows (bound {bound:.1e})"
    );
    assert!(windows > 1000, "{windows} windows");
    assert!(measured <= bound, "{measured:.3e} > {bound:.3e}");
    let job = run(&dir, program, &sets("machine.max_jerk_mm_per_s3=0", &jumps));
    let (trapezoid, _) = measure(&job);
    println!("the same jumps as trapezoids: {trapezoid:.3e} mm/s³");
    assert!(trapezoid > 2.0 * bound, "{trapezoid:.3e}");
}

/// On the test machine of 1 µm steps and 50 µs ticks (rapids at 20 mm/s), `G0 X50` under a
/// jerk limit takes less than twice the trapezoid's time.
#[test]
fn the_rapid_g0_x50_takes_less_than_twice_the_trapezoid() {
    let dir = common::scratch("jerk", "time");
    let program = "G21 G90\nG0 X50\nM2\n";
    let time = |jerk: &str| {
        let job = run(&dir, program, &[jerk]);
        assert_eq!(job.ints("end_steps"), vec![50_000, 0, 0]);
        job.summary["virtual_time_s"].as_f64().unwrap()
    };
    let trapezoid = time("machine.max_jerk_mm_per_s3=0");
    for jerk in ["1e4", "1e5"] {
        let s_curve = time(&format!("machine.max_jerk_mm_per_s3={jerk}"));
        println!(
            "G0 X50: trapezoid {trapezoid:.4} s, jerk {jerk} mm/s³ {s_curve:.4} s ({:.3}×)",
            s_curve / trapezoid
        );
        assert!(s_curve < 2.0 * trapezoid);
        assert!(s_curve > trapezoid);
    }
}

/// Under a jerk limit the planner brings positioning moves to rest at their ends (the S-curve
/// stops there), where without one two collinear rapids blend at full speed.
#[test]
fn the_plan_stops_at_the_ends_of_rapids_under_a_jerk_limit() {
    let dir = common::scratch("jerk", "plan");
    let program = dir.join("p.ngc");
    std::fs::write(&program, "G21 G90\nG0 X10\nG0 X20\nG1 X30 F600\nM2\n").unwrap();
    let feed_at = |jerk: &str, x: &str| {
        let out = dir.join(format!("plan-{jerk}"));
        let status = std::process::Command::new(env!("CARGO_BIN_EXE_edmd"))
            .arg("plan")
            .arg(&program)
            .arg("--out")
            .arg(&out)
            .args(["--quiet", "--config"])
            .arg(common::repo().join("tests/data/xyz.toml"))
            .args(["--set", &format!("machine.max_jerk_mm_per_s3={jerk}")])
            .output()
            .unwrap();
        assert!(status.status.success());
        let trace = std::fs::read_to_string(out.join("trace.csv")).unwrap();
        let row = trace
            .lines()
            .find(|l| l.split(',').nth(3) == Some(x))
            .unwrap_or_else(|| panic!("no row at X{x}"))
            .to_string();
        row.split(',').nth(7).unwrap().parse::<f64>().unwrap()
    };
    assert_eq!(feed_at("0", "10"), 1200.0);
    assert_eq!(feed_at("1e5", "10"), 0.0);
    assert_eq!(feed_at("1e5", "20"), 0.0);
}
