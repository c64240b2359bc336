//! The turn-back as the pulse log shows it, on scripted shorts (`gap.kind = "script"`): a
//! straight cut along X at F3 (a wire cut), F60 and F600, 1 µm steps, 50 µs ticks. The
//! electrode backs off at `servo.retract_feed_mm_per_min` whatever F, reverses within the
//! braking time of `servo.reverse_accel_mm_per_s2`, backs off at least
//! `servo.min_retract_um` on a brief short, and the job ends exactly on its end point.

use std::path::Path;

use crate::common;
use crate::common::daemon::{Daemon, base_sets};
use edmd::output::read_pulse_log;

const TICK_S: f64 = 50e-6;
const STEP_MM: f64 = 0.001;
/// The built-in configuration's reversal acceleration: the machine's largest
/// (`max_normal_accel_mm_per_s2`).
const REVERSE_ACCEL: f64 = 4900.0;

/// What a run's pulse log says about its first short.
#[derive(Debug)]
struct TurnBack {
    /// Ticks from the short's first tick to the first backward step.
    first_back: u64,
    /// How far the electrode went on into the short before it turned back (steps).
    overrun: i64,
    /// The back-off speed (mm/min), from the second backward step to the last.
    back_off: f64,
    /// Ticks between consecutive backward steps, the longest.
    longest_back_interval: u64,
    /// How far it backed off in all (steps).
    backed: i64,
    /// Where the log ends on X (steps).
    end: i64,
}

/// `G1 X5 F<feed>` with the gap script `script`, the servo's sparking and open feeds above F
/// (so F is the cutting speed), and `sets`. The pulse log and the summary.
fn cut(name: &str, feed: u32, script: &str, sets: &[&str]) -> (Vec<(u64, i64)>, serde_json::Value) {
    let dir = common::scratch("turn-back", name);
    let program = dir.join("cut.ngc");
    std::fs::write(&program, format!("G21 G90\nG1 X5 F{feed}\nM2\n")).unwrap();
    std::fs::write(dir.join("gap.txt"), script).unwrap();
    let pulses = dir.join("pulses.csv");
    let summary = dir.join("summary.json");
    let mut args = vec![
        "--set".to_string(),
        "gap.kind=\"script\"".to_string(),
        "--set".to_string(),
        format!("gap.script=\"{}\"", dir.join("gap.txt").display()),
        "--set".to_string(),
        "servo.normal_feed_mm_per_min=1000".to_string(),
        "--set".to_string(),
        "servo.open_feed_mm_per_min=1000".to_string(),
        "--set".to_string(),
        "servo.max_short_s=0".to_string(),
        "--summary".to_string(),
        summary.display().to_string(),
    ];
    for s in sets {
        args.extend(["--set".to_string(), s.to_string()]);
    }
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    // `run_to_pulse_log` sets gap.kind = "none"; the script's --set comes after it and wins.
    let out = common::run_to_pulse_log(&program, &pulses, &args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    (x_steps(&pulses), read_summary(&summary))
}

fn read_summary(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The ticks that stepped X and where X stood after each (steps).
fn x_steps(pulses: &Path) -> Vec<(u64, i64)> {
    let (_, rows) = read_pulse_log(pulses).unwrap();
    let mut x = 0;
    rows.iter()
        .filter(|r| r.steps[0] != 0)
        .map(|r| {
            x += i64::from(r.steps[0]);
            (r.tick, x)
        })
        .collect()
}

/// The tick a cut at `feed` mm/min is `mm` into the program (after its start at rest).
fn tick_at(feed: u32, mm: f64) -> u64 {
    (mm / (f64::from(feed) / 60.0) / TICK_S).round() as u64
}

fn turn_back(steps: &[(u64, i64)], short_at: u64) -> TurnBack {
    let at_short = steps
        .iter()
        .take_while(|(t, _)| *t < short_at)
        .last()
        .map_or(0, |s| s.1);
    let mut back = Vec::new();
    let mut prev = at_short;
    for &(t, x) in steps.iter().filter(|(t, _)| *t >= short_at) {
        if x < prev {
            back.push((t, x));
        } else if !back.is_empty() {
            break; // the re-advance
        }
        prev = x;
    }
    let (first_tick, first_x) = back[0];
    let (last_tick, lowest) = *back.last().unwrap();
    let peak = first_x + 1;
    let back_off = if back.len() > 2 {
        (back.len() - 1) as f64 * STEP_MM / ((last_tick - first_tick) as f64 * TICK_S) * 60.0
    } else {
        0.0
    };
    TurnBack {
        first_back: first_tick - short_at,
        overrun: peak - at_short,
        back_off,
        longest_back_interval: back.windows(2).map(|w| w[1].0 - w[0].0).max().unwrap_or(0),
        backed: peak - lowest,
        end: steps.last().unwrap().1,
    }
}

/// The ticks a standstill from `v` (mm/s) takes at `a` (mm/s²), and then the first event
/// from rest.
fn reversal_ticks(v: f64, a: f64) -> u64 {
    let braking = v / a;
    let first_event = (2.0 * STEP_MM / a).sqrt();
    ((braking + first_event) / TICK_S).ceil() as u64
}

/// A 500 ms short 2.5 mm into the cut: the electrode backs off at the retract feed (within
/// one step interval), starts back within the braking time at the reversal acceleration
/// plus its first step and a tick, overruns no more than `v²/2a`, and ends exactly.
#[test]
fn a_short_backs_off_at_the_retract_feed_whatever_f() {
    for feed in [3u32, 60, 600] {
        let short_at = tick_at(feed, 2.5);
        let script = format!("0 normal\n{short_at} short\n{} normal\n", short_at + 10_000);
        let (steps, summary) = cut(&format!("f{feed}"), feed, &script, &[]);
        let tb = turn_back(&steps, short_at);
        let retract = 120.0;
        // One step interval at the retract feed: 0.5 ms of 30.
        let interval = STEP_MM / (retract / 60.0);
        assert!((tb.back_off - retract).abs() < 1.0, "F{feed}: {tb:?}");
        assert!(
            tb.longest_back_interval as f64 * TICK_S <= interval + TICK_S,
            "F{feed}: {tb:?}"
        );
        let v = f64::from(feed) / 60.0;
        assert!(
            tb.first_back <= reversal_ticks(v, REVERSE_ACCEL) + 1,
            "F{feed}: first backward step after {} ticks, braking and a step {}: {tb:?}",
            tb.first_back,
            reversal_ticks(v, REVERSE_ACCEL)
        );
        let overrun_bound = (v * v / (2.0 * REVERSE_ACCEL) / STEP_MM).ceil() as i64 + 1;
        assert!(tb.overrun <= overrun_bound, "F{feed}: {tb:?}");
        // 500 ms at 2 mm/s: 1 mm back.
        assert!((995..=1001).contains(&tb.backed), "F{feed}: {tb:?}");
        assert_eq!(tb.end, 5000, "F{feed}");
        assert_eq!(summary["end_steps"], summary["program_end_steps"]);
        assert_eq!(summary["shorts"], 1);
    }
}

/// `servo.retract_feed_mm_per_min` sets the back-off whatever F (at F60 it once stayed at
/// 60 mm/min).
#[test]
fn the_retract_feed_is_the_setting() {
    let short_at = tick_at(60, 2.5);
    let script = format!("0 normal\n{short_at} short\n{} normal\n", short_at + 4_000);
    let (steps, _) = cut(
        "f60-240",
        60,
        &script,
        &["servo.retract_feed_mm_per_min=240"],
    );
    let tb = turn_back(&steps, short_at);
    assert!((tb.back_off - 240.0).abs() < 2.0, "{tb:?}");
}

/// A 2 ms short at F3 (40 ticks, one step of the cut takes 400) still backs off at least
/// `servo.min_retract_um`, and no more than the braking from the retract feed past it.
#[test]
fn a_brief_short_retracts_at_least_min_retract() {
    let short_at = tick_at(3, 2.5);
    let script = format!("0 normal\n{short_at} short\n{} normal\n", short_at + 40);
    for (min_um, sets) in [(5, vec![]), (12, vec!["servo.min_retract_um=12"])] {
        let (steps, summary) = cut(&format!("brief-{min_um}"), 3, &script, &sets);
        let tb = turn_back(&steps, short_at);
        assert!(
            tb.backed >= min_um && tb.backed <= min_um + 2,
            "{min_um} µm: {tb:?}"
        );
        assert_eq!(tb.end, 5000);
        assert_eq!(summary["shorts"], 1);
    }
    // Without a least retraction, a short of 40 ticks backs off what 40 ticks allow.
    let (steps, _) = cut("brief-0", 3, &script, &["servo.min_retract_um=0"]);
    assert!(turn_back(&steps, short_at).backed < 5);
}

/// `servo.short_confirm_ticks`: a short shorter than it brakes the cut but does not turn
/// back (counted as brief); one that lasts turns back as usual.
#[test]
fn a_short_is_believed_after_the_confirmation_ticks() {
    let short_at = tick_at(600, 2.5);
    let script = format!(
        "0 normal\n{short_at} short\n{} normal\n{} short\n{} normal\n",
        short_at + 15,
        short_at + 2_000,
        short_at + 2_100
    );
    let (steps, summary) = cut("confirm", 600, &script, &["servo.short_confirm_ticks=20"]);
    assert_eq!(summary["brief_shorts"], 1, "{summary}");
    assert_eq!(summary["shorts"], 1, "{summary}");
    let backward: Vec<u64> = steps
        .windows(2)
        .filter(|w| w[1].1 < w[0].1)
        .map(|w| w[1].0)
        .collect();
    assert!(
        backward.iter().all(|&t| t > short_at + 2_000),
        "the brief short turned back: {backward:?}"
    );
    assert!(!backward.is_empty());
    // The brief short braked the cut: a step every 2 ticks at F600, up to 3 after it.
    let during: Vec<u64> = steps
        .iter()
        .filter(|(t, _)| (short_at..short_at + 40).contains(t))
        .map(|s| s.0)
        .collect();
    let slowest = during.windows(2).map(|w| w[1] - w[0]).max().unwrap();
    assert!(slowest >= 3, "{during:?}");
    assert_eq!(steps.last().unwrap().1, 5000);
}

/// Fifty shorts of 1 to 25 ms along the cut: the job ends exactly on its end point.
#[test]
fn fifty_shorts_and_the_cut_ends_exact() {
    let mut script = String::from("0 normal\n");
    let mut t = tick_at(60, 0.1);
    for k in 0..50u64 {
        let len = 20 * (1 + k % 25);
        script.push_str(&format!("{t} short\n{} normal\n", t + len));
        t += len + 1_500;
    }
    let (steps, summary) = cut("fifty", 60, &script, &[]);
    assert_eq!(summary["shorts"], 50, "{summary}");
    assert_eq!(summary["turn_backs"], 50);
    assert_eq!(summary["alarms"], 0);
    assert_eq!(summary["end_steps"], summary["program_end_steps"]);
    assert_eq!(steps.last().unwrap().1, 5000);
}

/// A short MDI move on the default simulator (its debris by the mm: none in the first
/// `sim.debris_clear_um`, none on a move of a few mm) completes; it once met five debris
/// bridges it could not back away from and ended in an alarm.
#[test]
fn a_short_mdi_move_on_the_default_simulator_completes() {
    let dir = common::scratch("turn-back", "mdi");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.retain(|s| !s.starts_with("gap.kind") && !s.starts_with("output."));
    sets.retain(|s| !s.starts_with("servo.normal_feed"));
    sets.push("gap.kind=\"sim\"".to_string());
    sets.push("output.kind=\"sim\"".to_string());
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["home", "--here"]);
    daemon.ok(&["mdi", "G91 G1 X0.5 F60"]);
    let x = |s: &serde_json::Value| s["machine"]["position_machine_mm"][0].as_f64();
    let status = daemon.wait_for("the MDI move's end", |s| {
        s["state"] == "held" || (s["state"] == "idle" && x(s).is_some_and(|x| x > 0.25))
    });
    assert_eq!(status["state"], "idle", "{status}");
    assert!((x(&status).unwrap() - 0.5).abs() < 1e-9, "{status}");
}
