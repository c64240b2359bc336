//! Die-sinking with an orbit (`[sinker.orbit]`, issue [7/9]), checked from the pulse log of
//! `edmd run` on an XYZ machine, against the orbit's own definition written out here: each
//! tick's electrode position, its depth below the start of the plunge and its offset from the
//! programmed axis (X5 Y5).

use crate::common;

use std::path::Path;

use edmd::output::read_pulse_log;

const STEP: f64 = 0.001;
const RADIUS: f64 = 0.2;
const DEPTH: f64 = 2.0;
const AXIS: (f64, f64) = (5.0, 5.0);

/// How far a tick may lie from the ideal orbit: the polyline's sag (a quarter of the 1 µm
/// chord tolerance), each segment's ends rounded to the step lattice (half a step on X and on
/// Y: √½ step across the path) and Bresenham's half step between them.
const BOUND: f64 = 0.25e-3 + (std::f64::consts::FRAC_1_SQRT_2 + 0.5) * STEP;

const PLUNGE: &str = "G21 G90\nG0 X5 Y5\nG0 Z0\nG1 Z-2 F10\nG0 Z1\nM2\n";

fn machine(extra: &[&str]) -> Vec<String> {
    let mut sets = vec![
        "machine.axes=[\"X\",\"Y\",\"Z\"]".to_string(),
        "machine.step_mm=[0.001,0.001,0.001]".to_string(),
        format!("sinker.orbit.radius_mm={RADIUS}"),
    ];
    sets.extend(extra.iter().map(|s| s.to_string()));
    sets
}

/// Runs `program` with `sets`; the position (mm) after every moving tick.
fn run(dir: &Path, name: &str, program: &str, sets: &[String]) -> Vec<[f64; 3]> {
    let path = dir.join(format!("{name}.ngc"));
    std::fs::write(&path, program).unwrap();
    let pulses = dir.join(format!("{name}.csv"));
    let mut args = Vec::new();
    for s in sets {
        args.push("--set");
        args.push(s.as_str());
    }
    let out = common::run_to_pulse_log(&path, &pulses, &args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (_, rows) = read_pulse_log(&pulses).unwrap();
    let mut at = [0i64; 3];
    let mut ticks = Vec::new();
    for r in rows.iter().filter(|r| r.steps.iter().any(|&s| s != 0)) {
        for (a, s) in at.iter_mut().zip(&r.steps) {
            *a += i64::from(*s);
        }
        ticks.push(at.map(|s| s as f64 * STEP));
    }
    ticks
}

/// Runs [`PLUNGE`] with `sets`: its summary, and the path of its pulse log.
fn plunge_with_summary(dir: &Path, sets: &[String]) -> (serde_json::Value, std::path::PathBuf) {
    let path = dir.join("p.ngc");
    std::fs::write(&path, PLUNGE).unwrap();
    let pulses = dir.join("p.csv");
    let summary = dir.join("summary.json");
    let mut args: Vec<&str> = Vec::new();
    for s in sets {
        args.extend(["--set", s.as_str()]);
    }
    args.extend(["--summary", summary.to_str().unwrap()]);
    let out = common::run_to_pulse_log(&path, &pulses, &args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let s = serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    (s, pulses)
}

/// The ticks of the plunge's orbit: below the top, until the bottom is reached (then the
/// return to the axis and the rapid up).
fn sinking(ticks: &[[f64; 3]]) -> impl Iterator<Item = (f64, f64, f64, f64)> + '_ {
    orbit_ticks(ticks).filter(|p| p.3 > -DEPTH + 1e-9)
}

/// The offsets at the bottom of the plunge (where the orbit ends at its full radius and
/// returns to the axis).
fn bottom(ticks: &[[f64; 3]]) -> impl Iterator<Item = (f64, f64)> + '_ {
    ticks
        .iter()
        .filter(|p| (p[2] + DEPTH).abs() < 1e-9)
        .map(|p| (p[0] - AXIS.0, p[1] - AXIS.1))
}

/// The plunge's ticks from below the top to the first at the bottom (included).
fn orbit_ticks(ticks: &[[f64; 3]]) -> impl Iterator<Item = (f64, f64, f64, f64)> + '_ {
    let first_bottom = ticks
        .iter()
        .position(|p| p[2] <= -DEPTH + 1e-9)
        .unwrap_or(ticks.len());
    ticks[..=first_bottom.min(ticks.len() - 1)]
        .iter()
        .filter(|p| p[2] < -1e-9)
        .map(|p| (p[0] - AXIS.0, p[1] - AXIS.1, -p[2], p[2]))
}

#[test]
fn a_circular_expanding_orbit_stays_on_its_path_and_ends_on_the_axis() {
    let dir = common::scratch("orbit", "circle");
    let ticks = run(
        &dir,
        "circle",
        PLUNGE,
        &machine(&["sinker.orbit.shape=\"circle\""]),
    );
    let (mut worst, mut n, mut over_a_step) = (0.0f64, 0, 0);
    for (dx, dy, depth, _) in sinking(&ticks) {
        let off = (dx.hypot(dy) - RADIUS * depth / DEPTH).abs();
        worst = worst.max(off);
        over_a_step += usize::from(off > STEP);
        n += 1;
    }
    let widest = bottom(&ticks)
        .map(|(dx, dy)| dx.hypot(dy))
        .fold(0.0, f64::max);
    eprintln!(
        "circle: {n} ticks within {:.3} µm of the orbit ({over_a_step} over a step), widest \
         {widest:.4} mm",
        worst * 1e3
    );
    assert!(n > 5_000, "{n} ticks on the orbit");
    assert!(worst <= BOUND, "{worst} mm off the expanding circle");
    assert!(
        (widest - RADIUS).abs() <= STEP,
        "the orbit reaches its radius: {widest}"
    );
    // Back on the axis, up and out: the program's end point exactly.
    assert_eq!(ticks.last().unwrap(), &[5.0, 5.0, 1.0]);
}

#[test]
fn with_shorts_the_turn_backs_retrace_the_orbit_and_the_job_ends_on_its_end_point() {
    let dir = common::scratch("orbit", "shorts");
    let sets = machine(&[
        "sinker.orbit.shape=\"circle\"",
        "gap.kind=\"sim\"",
        "sim.debris_shorts_per_mm=0.6",
    ]);
    let (s, pulses) = plunge_with_summary(&dir, &sets);
    assert!(s["shorts"].as_u64().unwrap() >= 3, "{s}");
    assert_eq!(s["turn_backs"], s["shorts"]);
    // Every tick, turn-backs and re-advances included, on the orbit; the end exact.
    let (_, rows) = read_pulse_log(&pulses).unwrap();
    let mut at = [0i64; 3];
    let mut backward = 0;
    let mut worst = 0.0f64;
    let mut bottom = false;
    for r in rows.iter().filter(|r| r.steps.iter().any(|&s| s != 0)) {
        for (a, s) in at.iter_mut().zip(&r.steps) {
            *a += i64::from(*s);
        }
        let p = at.map(|s| s as f64 * STEP);
        bottom |= p[2] <= -DEPTH + 1e-9;
        if !bottom && p[2] < -1e-9 {
            let r = (p[0] - AXIS.0).hypot(p[1] - AXIS.1);
            worst = worst.max((r - RADIUS * -p[2] / DEPTH).abs());
        }
        backward += usize::from(r.gap == edmd::vocab::GapState::Short);
    }
    assert!(backward > 0);
    assert!(worst <= BOUND, "{worst} mm off the orbit");
    assert_eq!(at, [5000, 5000, 1000]);
}

/// How far an offset `(dx, dy)` at `depth` below the top lies from `shape`'s definition.
fn off_shape(shape: &str, dx: f64, dy: f64, depth: f64) -> f64 {
    // Expanding: the radius the plunge's progress gives.
    let r = RADIUS * depth / DEPTH;
    match shape {
        "square" => (dx.abs().max(dy.abs()) - r).abs(),
        "vector-x" => dy.abs().max((dx.abs() - r).max(0.0)),
        "vector-y" => dx.abs().max((dy.abs() - r).max(0.0)),
        _ => {
            // The sphere: the tool axis at progress s is −D·s + R − √(R² − (R·s)²) (the
            // plunge and the lift); find s from the depth seen (monotonic up to s = 0.99 at
            // this depth and radius), its radius R·s against the plane radius.
            let z_at = |s: f64| -DEPTH * s + RADIUS - (RADIUS * RADIUS * (1.0 - s * s)).sqrt();
            let (mut lo, mut hi) = (0.0, 0.99);
            if z_at(hi) > -depth {
                return 0.0; // the very bottom, where the lift outruns the plunge
            }
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if z_at(mid) > -depth {
                    lo = mid
                } else {
                    hi = mid
                }
            }
            (dx.hypot(dy) - RADIUS * lo).abs()
        }
    }
}

#[test]
fn each_orbit_shape_follows_its_definition() {
    let dir = common::scratch("orbit", "shapes");
    for shape in ["square", "vector-x", "vector-y", "sphere"] {
        let ticks = run(
            &dir,
            shape,
            PLUNGE,
            &machine(&[&format!("sinker.orbit.shape=\"{shape}\"")]),
        );
        let (mut worst, mut n) = (0.0f64, 0);
        for (dx, dy, depth, _) in sinking(&ticks) {
            // The sphere's last turn, where its lift outruns the plunge (from 0.985 of the
            // radius on: the depth no longer tells the progress), ends at Z−1.8 and returns
            // from there: its ticks are checked up to that radius.
            if shape == "sphere" && dx.hypot(dy) > 0.985 * RADIUS {
                break;
            }
            worst = worst.max(off_shape(shape, dx, dy, depth));
            n += 1;
        }
        let widest = if shape == "sphere" {
            ticks
                .iter()
                .filter(|p| p[2] < -1e-9)
                .map(|p| (p[0] - AXIS.0).hypot(p[1] - AXIS.1))
                .fold(0.0, f64::max)
        } else {
            bottom(&ticks)
                .map(|(dx, dy)| dx.abs().max(dy.abs()))
                .fold(0.0, f64::max)
        };
        eprintln!(
            "{shape}: {n} ticks within {:.3} µm of its definition",
            worst * 1e3
        );
        assert!(n > 2_000, "{shape}: {n} ticks");
        assert!(worst <= BOUND, "{shape}: {worst} mm off");
        assert!((widest - RADIUS).abs() <= STEP, "{shape}: reaches {widest}");
        assert_eq!(
            ticks.last().unwrap(),
            &[5.0, 5.0, 1.0],
            "{shape}: ends on its end point"
        );
    }
}

/// Rough to finish: E3 sinks to Z−1 on a 0.3 mm orbit, E1 on to Z−2 on 0.1 mm; each stage's
/// radius from its condition, and `plan` lists the stages.
#[test]
fn stages_take_their_orbit_from_the_condition_and_plan_lists_them() {
    let dir = common::scratch("orbit", "stages");
    let conditions = "generator.condition=[\
        {number=3, on_us=4.0, off_us=8.0, current_a=5.0, v_ref=25.0, feed_mm_per_min=60.0, orbit_radius_mm=0.3},\
        {number=1, on_us=1.0, off_us=12.0, current_a=1.0, v_ref=35.0, feed_mm_per_min=10.0, orbit_radius_mm=0.1}]";
    let program = "G21 G90\nG0 X5 Y5\nG0 Z0\nE3 G1 Z-1 F10\nE1 G1 Z-2\nG0 Z1\nM2\n";
    let sets = machine(&["sinker.orbit.shape=\"circle\"", conditions]);
    let ticks = run(&dir, "stages", program, &sets);
    let widest = |from: f64, to: f64| {
        ticks
            .iter()
            .filter(|p| p[2] < from - 1e-9 && p[2] > to + 1e-9)
            .map(|p| (p[0] - AXIS.0).hypot(p[1] - AXIS.1))
            .fold(0.0f64, f64::max)
    };
    assert!((widest(0.0, -1.0) - 0.3).abs() <= STEP, "E3's stage");
    assert!((widest(-1.0, -2.0) - 0.1).abs() <= STEP, "E1's stage");
    let path = dir.join("stages.ngc");
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_edmd"));
    cmd.arg("plan")
        .arg(&path)
        .arg("--out")
        .arg(dir.join("plan"))
        .arg("-q");
    for s in &sets {
        cmd.args(["--set", s]);
    }
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // The run's summary (and its report's summary.json) lists the stages too.
    let summary = dir.join("summary.json");
    let mut args: Vec<&str> = Vec::new();
    for s in &sets {
        args.extend(["--set", s.as_str()]);
    }
    args.extend(["--summary", summary.to_str().unwrap()]);
    let out = common::run_to_pulse_log(&path, &dir.join("again.csv"), &args);
    assert!(out.status.success());
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    let radii: Vec<f64> = s["stages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|st| st["radius_mm"].as_f64().unwrap())
        .collect();
    assert_eq!(radii, [0.3, 0.1], "{s}");
    assert_eq!(s["stages"][1]["condition"], 1);
    let text = std::fs::read_to_string(dir.join("plan/summary.txt")).unwrap();
    assert!(
        text.contains(
            "orbit stage        line 4: Z 0.0000 -> -1.0000 mm in E3, circle of 0.3000 mm"
        ) && text.contains(
            "orbit stage        line 5: Z -1.0000 -> -2.0000 mm in E1, circle of 0.1000 mm"
        ),
        "{text}"
    );
}

/// Jumps while orbiting lift straight up the tool axis from the orbit's current point and
/// come straight back down to it (retracing the spiral would rub the wall just cut); the
/// orbit carries on from there on its path, and the job ends exactly on its end point. With
/// a jerk limit too, which the lift keeps.
#[test]
fn jumps_off_an_orbit_lift_along_the_tool_axis_and_come_back_to_it() {
    let dir = common::scratch("orbit", "jumps");
    let sets = machine(&[
        "sinker.orbit.shape=\"circle\"",
        "servo.jump_interval_s=0.5",
        "servo.jump_height_mm=0.1",
        "machine.max_jerk_mm_per_s3=1e5",
    ]);
    let (s, pulses) = plunge_with_summary(&dir, &sets);
    let jumps = s["jumps"].as_u64().unwrap();
    assert!(jumps >= 3, "{jumps} jumps");
    let (_, rows) = read_pulse_log(&pulses).unwrap();
    let mut at = [0i64; 3];
    let mut worst = 0.0f64;
    // Each spark-off stretch below the top (but the rapid out at the end, which no spark
    // closes): the path steps of the cut braking before it, then
    // where the lift left the orbit, how far up it went, and whether X or Y moved after.
    let mut lifts: Vec<(usize, [i64; 3], i64, bool)> = Vec::new();
    let mut lift: Option<(usize, Option<[i64; 3]>, i64, bool)> = None;
    let mut bottom = false;
    for r in rows.iter().filter(|r| r.steps.iter().any(|&s| s != 0)) {
        let before = at;
        for (a, s) in at.iter_mut().zip(&r.steps) {
            *a += i64::from(*s);
        }
        let p = at.map(|s| s as f64 * STEP);
        bottom |= p[2] <= -DEPTH + 1e-9;
        let sideways = r.steps[..2] != [0, 0];
        if !r.spark && lift.is_none() && before[2] < 0 {
            lift = Some((0, None, 0, false));
        }
        match (r.spark, &mut lift) {
            (false, Some((braking, from, up, moved))) => match from {
                // Forward along the orbit (sideways or down) until it stands still.
                None if sideways || r.steps[2] < 0 => *braking += 1,
                None => *from = Some(before),
                Some(f) => {
                    *up = (*up).max(at[2] - f[2]);
                    *moved |= sideways;
                }
            },
            (true, Some((braking, from, up, moved))) => {
                // Back where it left the orbit, sparking again (the step that arrives
                // there carries the spark).
                let from = from.expect("a jump without a lift");
                assert_eq!(at, from, "a jump came back elsewhere");
                assert_eq!(r.steps, [0, 0, -1]);
                lifts.push((*braking, from, *up, *moved));
                lift = None;
            }
            _ => {}
        }
        if r.spark && !bottom && p[2] < -1e-9 {
            let r = (p[0] - AXIS.0).hypot(p[1] - AXIS.1);
            worst = worst.max((r - RADIUS * -p[2] / DEPTH).abs());
        }
    }
    eprintln!(
        "{jumps} jumps off the orbit, each straight up 0.1 mm and back; the orbit within \
         {:.3} µm",
        worst * 1e3
    );
    assert_eq!(lifts.len() as u64, jumps, "{lifts:?}");
    for (braking, from, up, sideways) in &lifts {
        // The cut at 10 mm/min stops within a step or two of where the jump began.
        assert!(
            *braking <= 2,
            "{braking} steps of braking before the jump from {from:?}"
        );
        assert_eq!(*up, 100, "a jump from {from:?} lifted {up} steps");
        assert!(!sideways, "a jump from {from:?} moved in X or Y");
    }
    assert!(worst <= BOUND, "{worst} mm off the orbit");
    assert_eq!(at, [5000, 5000, 1000]);
}
