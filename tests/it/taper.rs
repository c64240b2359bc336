//! Taper cutting (`G51`/`G52 A<deg>`, issue [6/9]) checked independently of the code that
//! computes it: `edmd run` writes the pulse log of a four-axis machine (X/Y the lower guide,
//! U/V the upper guide relative to it); from each tick's positions the test intersects the
//! wire line with the program plane and measures that point's distance from the programmed
//! contour (the wire offset) and the wire's angle from vertical, and which side it leans to.

use crate::common;

use std::path::Path;

use edmd::output::read_pulse_log;

/// Lower guide to program plane, and guide to guide (mm).
const LOWER_MM: f64 = 10.0;
const SPAN_MM: f64 = 50.0;
const OFFSET_MM: f64 = 0.2;
const ANGLE_DEG: f64 = 2.0;

const CONFIG: &str = "[machine]\naxes = [\"X\", \"Y\", \"U\", \"V\"]\n\
    step_mm = [0.001, 0.001, 0.001, 0.001]\n\n[compensation]\nd_mm = [0.0, 0.2]\n\n\
    [wire]\nlower_guide_mm = 10.0\nupper_guide_mm = 40.0\n";

/// The die's rounded corner as an arc.
const ARC: &str = "G3 X10 Y0 I0 J5";
/// The same quarter circle as a rational quadratic NURBS curve (`G5.2`, weights 1, √½, 1).
const NURBS: &str = "G5.2 X10 Y-5 P0.7071067811865476 L3\nX10 Y0 P1\nG5.3";

/// A die opening: a 15 × 10 mm rectangle with its lower right corner a quarter circle of
/// 5 mm (`corner`), entered from the start hole at the origin with `G41` (inside),
/// counter-clockwise.
fn die(taper: &str, corner: &str) -> String {
    format!(
        "(tapered die)\nG21 G90 G17\n{taper} A{ANGLE_DEG}\nG41 D1\nG1 X0 Y-5 F300\nG1 X5 Y-5\n\
         {corner}\nG1 X10 Y5\nG1 X-5 Y5\nG1 X-5 Y-5\nG1 X0 Y-5\nG40 G50 G1 X0 Y0\nM2\n"
    )
}

/// The same die mirrored in X (Y negated): clockwise, `G42` inside.
fn mirrored_die(taper: &str, corner: &str) -> String {
    let ccw = die(taper, corner);
    let mut out = String::new();
    for line in ccw.lines() {
        let words: Vec<String> = line
            .split(' ')
            .map(|w| match (w.chars().next(), w.get(1..)) {
                (Some('Y' | 'J'), Some(v)) if v.parse::<f64>().is_ok() => {
                    let v: f64 = v.parse().unwrap();
                    format!("{}{}", &w[..1], -v)
                }
                _ => match w {
                    "G3" => "G2".into(),
                    "G41" => "G42".into(),
                    _ => w.into(),
                },
            })
            .collect();
        out.push_str(&words.join(" "));
        out.push('\n');
    }
    out
}

/// Distance (mm) of `p` from the die's programmed contour, and whether it lies inside.
fn die_distance(p: (f64, f64)) -> (f64, bool) {
    let seg = |a: (f64, f64), b: (f64, f64)| {
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let t = (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
        ((p.0 - a.0 - t * dx).powi(2) + (p.1 - a.1 - t * dy).powi(2)).sqrt()
    };
    let (cx, cy, r) = (5.0, 0.0, 5.0);
    let angle = (p.1 - cy).atan2(p.0 - cx);
    let arc = if (-std::f64::consts::FRAC_PI_2..=0.0).contains(&angle) {
        (((p.0 - cx).powi(2) + (p.1 - cy).powi(2)).sqrt() - r).abs()
    } else {
        f64::INFINITY
    };
    let d = [
        seg((0.0, -5.0), (5.0, -5.0)),
        arc,
        seg((10.0, 0.0), (10.0, 5.0)),
        seg((10.0, 5.0), (-5.0, 5.0)),
        seg((-5.0, 5.0), (-5.0, -5.0)),
        seg((-5.0, -5.0), (0.0, -5.0)),
    ]
    .into_iter()
    .fold(f64::INFINITY, f64::min);
    let in_box = (-5.0..=10.0).contains(&p.0) && (-5.0..=5.0).contains(&p.1);
    let in_corner = p.0 > cx && p.1 < cy && (p.0 - cx).powi(2) + (p.1 - cy).powi(2) > r * r;
    (d, in_box && !in_corner)
}

/// The guides' positions (mm) after every moving tick: (x, y, u, v).
fn guides(path: &Path) -> Vec<[f64; 4]> {
    let (_, rows) = read_pulse_log(path).unwrap();
    let mut at = [0i64; 4];
    let mut out = Vec::new();
    for r in rows.iter().filter(|r| r.steps.iter().any(|&s| s != 0)) {
        for (a, s) in at.iter_mut().zip(&r.steps) {
            *a += i64::from(*s);
        }
        out.push(at.map(|s| s as f64 * 1e-3));
    }
    out
}

#[test]
fn a_tapered_die_with_an_arc_or_a_nurbs_passes_through_its_offset_contour_at_its_angle() {
    let dir = common::scratch("taper", "die");
    std::fs::write(dir.join("wire.toml"), CONFIG).unwrap();
    let config = dir.join("wire.toml");
    // Both directions, each leaning to the outside of the corners (pivoted: the wire keeps
    // its angle throughout; leaning into them is the sharp-corner test below).
    let cases = [
        ("G52", false, "arc", ARC),
        ("G51", true, "arc", ARC),
        ("G52", false, "nurbs", NURBS),
        ("G51", true, "nurbs", NURBS),
    ];
    for (taper, mirrored, shape, corner) in cases {
        let program = dir.join(format!("die-{taper}-{shape}.ngc"));
        let text = if mirrored {
            mirrored_die(taper, corner)
        } else {
            die(taper, corner)
        };
        std::fs::write(&program, text).unwrap();
        let pulses = dir.join(format!("die-{taper}-{shape}.csv"));
        let taper = format!("{taper} {shape}");
        let out =
            common::run_to_pulse_log(&program, &pulses, &["--config", config.to_str().unwrap()]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let ticks = guides(&pulses);
        assert_eq!(
            ticks.last().unwrap(),
            &[0.0; 4],
            "{taper}: ends where it began"
        );
        let full_tilt = SPAN_MM * ANGLE_DEG.to_radians().tan();
        let (mut worst_mm, mut worst_deg, mut counted) = (0.0f64, 0.0f64, 0);
        for [x, y, u, v] in &ticks {
            let lean = u.hypot(*v);
            // The contour, corners included: the wire at its full tilt (not the entry and
            // exit, which ramp the angle from and to vertical).
            let k = LOWER_MM / SPAN_MM;
            // In the die's own frame (the mirrored die mirrored back).
            let f = if mirrored { -1.0 } else { 1.0 };
            let (y, v) = (y * f, v * f);
            let plane = (x + u * k, y + v * k);
            // The entry and exit ramp the tilt where they meet the contour (the entry at the
            // first edge's offset start, the exit at the last edge's offset end): their ticks
            // at nearly the full tilt lie within 0.1 mm of those points.
            let y = plane.1 + 5.0 - OFFSET_MM;
            let junction = (plane.0 - OFFSET_MM).hypot(y).min(plane.0.hypot(y));
            if (lean - full_tilt).abs() > 0.01 || junction < 0.1 {
                continue;
            }
            counted += 1;
            let (d, inside) = die_distance(plane);
            assert!(inside, "{taper}: the wire meets the plane outside the die");
            worst_mm = worst_mm.max((d - OFFSET_MM).abs());
            let angle = (lean / SPAN_MM).atan().to_degrees();
            worst_deg = worst_deg.max((angle - ANGLE_DEG).abs());
            // Which way it leans: a little way up the wire from the plane, away from the
            // opening's inside (G52 right of counter-clockwise travel, G51 left of clockwise).
            let up = (plane.0 + u / lean * 0.05, plane.1 + v / lean * 0.05);
            let (d_up, inside_up) = die_distance(up);
            // (At a corner's pivot the first and last lean run along an edge: no nearer.)
            let deeper = inside_up && d_up > d - 1e-4;
            assert!(!deeper, "{taper}: leans into the opening at {plane:?}");
        }
        assert!(counted > 10_000, "{taper}: {counted} ticks at full tilt");
        eprintln!(
            "{taper}: {counted} ticks, plane point within {:.2} µm of the offset, angle within \
             {:.5}°",
            worst_mm * 1e3,
            worst_deg
        );
        // The chord tolerance (1 µm), and each axis up to a step off the exact segment (half
        // a step rounding its ends, half a step of Bresenham between them): X/Y a step, U/V a
        // step scaled by lower/span, in two directions.
        let bound = 1e-3 + (1.0 + LOWER_MM / SPAN_MM) * 1e-3 * std::f64::consts::SQRT_2;
        assert!(
            worst_mm < bound,
            "{taper}: {worst_mm} mm off the offset contour"
        );
        assert!(worst_deg < 0.01, "{taper}: {worst_deg}° off the angle");
    }
}

#[test]
fn a_taper_the_machine_or_the_geometry_cannot_cut_is_refused_at_its_line() {
    let dir = common::scratch("taper", "refused");
    std::fs::write(dir.join("wire.toml"), CONFIG).unwrap();
    let config = dir.join("wire.toml");
    let check = |name: &str, text: &str, args: &[&str]| {
        let program = dir.join(name);
        std::fs::write(&program, text).unwrap();
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_edmd"))
            .arg("check")
            .arg(&program)
            .args(args)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{name}");
        String::from_utf8_lossy(&out.stderr).to_string()
    };
    let cfg = ["--config", config.to_str().unwrap()];
    // No U/V on the default machine.
    let err = check("xy.ngc", "G21 G90\nG51 A2\nG1 X5 F100\nM2\n", &[]);
    assert!(
        err.contains("xy.ngc:2:1: taper: G51 tilts the wire"),
        "{err}"
    );
    let err = check("steep.ngc", "G21 G90\nG52 A45\nG1 X5 F100\nM2\n", &cfg);
    assert!(err.contains("steep.ngc:2:5:"), "{err}");
    // An arc of 1 mm radius, the wire tilted 10° towards its centre: at the top of the work
    // (20 mm up) the wall's radius would be 1 - 20 tan 10° < 0.
    let err = check(
        "tight.ngc",
        "G21 G90\nG0 X-3 Y-1\nG51 A10\nG1 X0 Y-1 F100\nG3 X1 Y0 I0 J1\nM2\n",
        &cfg,
    );
    assert!(err.contains("tight.ngc:5:1: taper:"), "{err}");
    assert!(err.contains("leans into this arc"), "{err}");
    // Leaning into a corner where an arc meets a line: the walls do not meet along a line.
    let err = check(
        "into.ngc",
        "G21 G90\nG51 A3\nG1 X10 F100\nG3 X0 Y10 I-10 J0\nM2\n",
        &cfg,
    );
    assert!(
        err.contains("into.ngc:4:1: taper: the wire leans into this corner"),
        "{err}"
    );
}

/// The work's thickness above the program plane (the shipped `[wire] thickness_mm`).
const THICKNESS_MM: f64 = 20.0;

/// Leaning into the die's corners (`G51` left of its counter-clockwise travel, `G52` right of
/// the mirrored one: the opening narrows upwards), the corners between lines are cut sharp:
/// the wire meets the program plane on the offset contour and the top of the work on the
/// contour offset a further `thickness·tan(angle)` inwards, sharp corners and all, so the
/// walls stand at the programmed draft everywhere.
#[test]
fn leaning_into_the_die_corners_cuts_them_sharp_at_every_height() {
    let dir = common::scratch("taper", "sharp");
    std::fs::write(dir.join("wire.toml"), CONFIG).unwrap();
    let config = dir.join("wire.toml");
    let t = ANGLE_DEG.to_radians().tan();
    for (taper, mirrored) in [("G51", false), ("G52", true)] {
        let program = dir.join(format!("sharp-{taper}.ngc"));
        let text = if mirrored {
            mirrored_die(taper, ARC)
        } else {
            die(taper, ARC)
        };
        std::fs::write(&program, text).unwrap();
        let pulses = dir.join(format!("sharp-{taper}.csv"));
        let out =
            common::run_to_pulse_log(&program, &pulses, &["--config", config.to_str().unwrap()]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let ticks = guides(&pulses);
        assert_eq!(
            ticks.last().unwrap(),
            &[0.0; 4],
            "{taper}: ends where it began"
        );
        let f = if mirrored { -1.0 } else { 1.0 };
        let (mut worst_plane, mut worst_top, mut worst_draft, mut counted) =
            (0.0f64, 0.0f64, 0.0f64, 0);
        let mut sharpest = 0.0f64;
        for [x, y, u, v] in &ticks {
            let (y, v) = (y * f, v * f);
            // The wire at height z above the plane: the lower guide plus (u, v)·(L + z)/span.
            let at = |z: f64| {
                let k = (LOWER_MM + z) / SPAN_MM;
                (x + u * k, y + v * k)
            };
            let (plane, top) = (at(0.0), at(THICKNESS_MM));
            // Not the entry and exit, which ramp the angle: the entry from the start hole to
            // where it meets the first edge's offset (LinuxCNC's entry: offset across its own
            // direction, at (0.2, −5), met by the edge's offset line at (0.2, −4.8)), the exit
            // from the last edge's offset end (0, −4.8) back to the start hole.
            let off_line = |a: (f64, f64), b: (f64, f64)| {
                let (dx, dy) = (b.0 - a.0, b.1 - a.1);
                let s = (((plane.0 - a.0) * dx + (plane.1 - a.1) * dy) / (dx * dx + dy * dy))
                    .clamp(0.0, 1.0);
                (plane.0 - a.0 - s * dx).hypot(plane.1 - a.1 - s * dy)
            };
            let contour_y = -5.0 + OFFSET_MM;
            let junction = (plane.0 - OFFSET_MM)
                .hypot(plane.1 - contour_y)
                .min(plane.0.hypot(plane.1 - contour_y));
            if junction < 0.1
                || off_line((0.0, 0.0), (OFFSET_MM, contour_y)) < 0.01
                || off_line((0.0, 0.0), (0.0, contour_y)) < 0.01
            {
                continue;
            }
            let lean = u.hypot(v) / SPAN_MM;
            if lean < t * 0.999 {
                continue;
            }
            counted += 1;
            sharpest = sharpest.max(lean.atan().to_degrees());
            let (d0, in0) = die_distance(plane);
            let (d1, in1) = die_distance(top);
            assert!(
                in0 && in1,
                "{taper}: outside the die at {plane:?} / {top:?}"
            );
            worst_plane = worst_plane.max((d0 - OFFSET_MM).abs());
            worst_top = worst_top.max((d1 - OFFSET_MM - THICKNESS_MM * t).abs());
            let draft = ((d1 - d0) / THICKNESS_MM).atan().to_degrees();
            worst_draft = worst_draft.max((draft - ANGLE_DEG).abs());
        }
        assert!(counted > 10_000, "{taper}: {counted} ticks");
        eprintln!(
            "{taper} sharp: {counted} ticks, plane within {:.2} µm, top within {:.2} µm, draft \
             within {:.5}°, the wire up to {sharpest:.3}° from vertical at the corners",
            worst_plane * 1e3,
            worst_top * 1e3,
            worst_draft
        );
        // As in the die above: the tolerance and a step per axis, U/V scaled to the height.
        let bound =
            |z: f64| 1e-3 + (1.0 + (LOWER_MM + z) / SPAN_MM) * 1e-3 * std::f64::consts::SQRT_2;
        assert!(
            worst_plane < bound(0.0),
            "{taper}: {worst_plane} mm at the plane"
        );
        assert!(
            worst_top < bound(THICKNESS_MM),
            "{taper}: {worst_top} mm at the top"
        );
        assert!(worst_draft < 0.01, "{taper}: draft {worst_draft}° off");
        // The corner edges lean more than the walls (a 90° corner: √2 times the tilt).
        let edge = (t * std::f64::consts::SQRT_2).atan().to_degrees();
        assert!(
            (sharpest - edge).abs() < 0.01,
            "{taper}: {sharpest}° at the corners, {edge}° expected"
        );
    }
}

/// With the simulated gap's debris shorts, the turn-backs retrace all four axes and the job
/// still ends exactly where it began, in every axis.
#[test]
fn a_tapered_die_with_shorts_ends_exactly_on_its_end_point() {
    let dir = common::scratch("taper", "shorts");
    std::fs::write(dir.join("wire.toml"), CONFIG).unwrap();
    let program = dir.join("die.ngc");
    std::fs::write(&program, die("G52", ARC)).unwrap();
    let pulses = dir.join("die.csv");
    let config = dir.join("wire.toml");
    let out = common::run_to_pulse_log(
        &program,
        &pulses,
        &[
            "--config",
            config.to_str().unwrap(),
            "--set",
            "gap.kind=\"sim\"",
            "--set",
            "sim.debris_shorts_per_mm=0.1",
            "--set",
            "sim.model=\"kinematic\"",
            "--summary",
            dir.join("summary.json").to_str().unwrap(),
            "--report",
            dir.join("report").to_str().unwrap(),
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // The run's report draws both guides.
    let svg = std::fs::read_to_string(dir.join("report/path.svg")).unwrap();
    assert!(
        svg.contains("executed path (lower guide, X/Y)") && svg.contains("upper guide (X+U, Y+V)"),
        "{svg}"
    );
    let text = std::fs::read_to_string(dir.join("summary.json")).unwrap();
    let summary: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert!(summary["shorts"].as_u64().unwrap() >= 4, "{summary}");
    assert_eq!(summary["turn_backs"], summary["shorts"], "{summary}");
    assert_eq!(guides(&pulses).last().unwrap(), &[0.0; 4]);
}

/// A direct four-axis program (a CAM post's two contours as one `G06.2` curve in X, Y, U and
/// V): the lower guide (X/Y) and the upper guide (X/Y plus U/V) each stay within the chord
/// tolerance of their own curve, measured against this test's own evaluation of the
/// rational cubic, sampled densely.
#[test]
fn a_direct_xyuv_curve_holds_the_chord_tolerance_on_both_guides() {
    let dir = common::scratch("taper", "xyuv");
    std::fs::write(dir.join("wire.toml"), CONFIG).unwrap();
    let config = dir.join("wire.toml");
    // Control points (x, y, u, v) and weights of a rational cubic Bézier.
    let points = [
        [0.0, 0.0, 0.0, 0.0],
        [4.0, 8.0, 2.0, -1.0],
        [12.0, -6.0, -1.0, 2.0],
        [16.0, 2.0, 1.0, 1.0],
    ];
    let weights = [1.0, 2.0, 0.5, 1.0];
    let mut text = String::from("G21 G90 G17\nG1 X0 Y0 U0 V0 F300\n");
    for (i, (p, w)) in points.iter().zip(weights).enumerate() {
        let head = if i == 0 { "G06.2 P4 " } else { "" };
        text.push_str(&format!(
            "{head}K0 X{} Y{} U{} V{} R{w}\n",
            p[0], p[1], p[2], p[3]
        ));
    }
    text.push_str("K1\nK1\nK1\nK1\nG1 X0 Y0 U0 V0\nM2\n");
    let program = dir.join("xyuv.ngc");
    std::fs::write(&program, text).unwrap();
    let pulses = dir.join("xyuv.csv");
    let out = common::run_to_pulse_log(&program, &pulses, &["--config", config.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // The curve, densely: lower (x, y) and upper (x + u, y + v).
    let eval = |t: f64| {
        let b = [
            (1.0 - t).powi(3),
            3.0 * t * (1.0 - t).powi(2),
            3.0 * t * t * (1.0 - t),
            t.powi(3),
        ];
        let mut num = [0.0; 4];
        let mut den = 0.0;
        for i in 0..4 {
            for k in 0..4 {
                num[k] += b[i] * weights[i] * points[i][k];
            }
            den += b[i] * weights[i];
        }
        num.map(|c| c / den)
    };
    const SAMPLES: usize = 40_000;
    let curve: Vec<[f64; 4]> = (0..=SAMPLES)
        .map(|i| eval(i as f64 / SAMPLES as f64))
        .collect();
    let lower: Vec<(f64, f64)> = curve.iter().map(|c| (c[0], c[1])).collect();
    let upper: Vec<(f64, f64)> = curve.iter().map(|c| (c[0] + c[2], c[1] + c[3])).collect();
    let ticks = guides(&pulses);
    let end = [16.0, 2.0, 1.0, 1.0];
    let on_curve = ticks
        .iter()
        .take_while(|t| t.iter().zip(&end).any(|(a, b)| (a - b).abs() > 1e-9));
    // Distance to the sampled polyline near where the last tick was (the ticks go along it).
    let near = |path: &[(f64, f64)], at: &mut usize, p: (f64, f64)| {
        let lo = at.saturating_sub(200);
        let hi = (*at + 2_000).min(path.len() - 1);
        let mut best = (f64::INFINITY, *at);
        for i in lo..hi {
            let (a, b) = (path[i], path[i + 1]);
            let (dx, dy) = (b.0 - a.0, b.1 - a.1);
            let len2 = (dx * dx + dy * dy).max(f64::MIN_POSITIVE);
            let s = (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / len2).clamp(0.0, 1.0);
            let d = (p.0 - a.0 - s * dx).hypot(p.1 - a.1 - s * dy);
            if d < best.0 {
                best = (d, i);
            }
        }
        *at = best.1;
        best.0
    };
    let (mut at_lower, mut at_upper) = (0, 0);
    let (mut worst_lower, mut worst_upper, mut n) = (0.0f64, 0.0f64, 0);
    for [x, y, u, v] in on_curve {
        n += 1;
        worst_lower = worst_lower.max(near(&lower, &mut at_lower, (*x, *y)));
        worst_upper = worst_upper.max(near(&upper, &mut at_upper, (x + u, y + v)));
    }
    eprintln!(
        "{n} ticks on the curve: lower guide within {:.2} µm, upper within {:.2} µm",
        worst_lower * 1e3,
        worst_upper * 1e3
    );
    assert!(n > 1000, "{n} ticks");
    // The chord tolerance (1 µm), and a step of rounding and Bresenham per axis: one axis pair
    // for the lower guide, two for the upper.
    let step = 1e-3 * std::f64::consts::SQRT_2;
    assert!(
        worst_lower < 1e-3 + step,
        "lower guide {worst_lower} mm off"
    );
    assert!(
        worst_upper < 1e-3 + 2.0 * step,
        "upper guide {worst_upper} mm off"
    );
}

/// `edmd plan` on a tapered die: the trace carries U and V, the path plot draws the upper
/// guide over the lower one, and the wire's angle is drawn along the path.
#[test]
fn plan_draws_both_guides_and_the_wire_angle() {
    let dir = common::scratch("taper", "plan");
    std::fs::write(dir.join("wire.toml"), CONFIG).unwrap();
    let program = dir.join("die.ngc");
    std::fs::write(&program, die("G52", ARC)).unwrap();
    let out_dir = dir.join("plan");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_edmd"))
        .arg("plan")
        .arg(&program)
        .args(["--config", dir.join("wire.toml").to_str().unwrap()])
        .arg("--out")
        .arg(&out_dir)
        .arg("-q")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // The tolerance reported is the configured one; the tighter one the segmenter holds in
    // four axes (so that the upper guide keeps the configured one) is shown beside it.
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("summary.json")).unwrap())
            .unwrap();
    let configured = CONFIG
        .lines()
        .find_map(|l| l.trim().strip_prefix("chord_tolerance_mm = "))
        .map_or(0.001, |v| v.parse::<f64>().unwrap());
    assert_eq!(summary["chord_tolerance_mm"].as_f64(), Some(configured));
    let held = summary["chord_tolerance_held_mm"].as_f64().unwrap();
    assert!(
        (held - configured / std::f64::consts::SQRT_2).abs() < 1e-15,
        "held {held}"
    );
    let text = std::fs::read_to_string(out_dir.join("summary.txt")).unwrap();
    assert!(
        text.contains(&format!("tolerance {configured} mm (held as")),
        "{text}"
    );
    let trace = std::fs::read_to_string(out_dir.join("trace.csv")).unwrap();
    let mut lines = trace.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    // U and V by their letters in upper case (`u` is the curve parameter), once each.
    assert_eq!(&header[header.len() - 2..], ["U", "V"]);
    let mut names = header.clone();
    names.sort_unstable();
    names.dedup();
    assert_eq!(
        names.len(),
        header.len(),
        "a column named twice: {header:?}"
    );
    let steepest = lines
        .map(|l| {
            let f: Vec<f64> = l.rsplit(',').take(2).map(|x| x.parse().unwrap()).collect();
            (f[0].hypot(f[1]) / SPAN_MM).atan().to_degrees()
        })
        .fold(0.0f64, f64::max);
    assert!((steepest - ANGLE_DEG).abs() < 1e-6, "steepest {steepest}°");
    let path = std::fs::read_to_string(out_dir.join("path.svg")).unwrap();
    assert!(
        path.contains("upper guide"),
        "no upper guide on the path plot"
    );
    let angle = std::fs::read_to_string(out_dir.join("wire_angle.svg")).unwrap();
    assert!(angle.contains("angle from vertical"), "{angle}");
}

/// A tapered job held and aborted halfway, then resumed by a new daemon: the joined pulse
/// record, all four axes, is the uninterrupted run's.
#[test]
fn a_tapered_job_stopped_halfway_resumes_to_the_uninterrupted_pulses() {
    let dir = common::daemon::scratch("taper");
    std::fs::write(dir.join("wire.toml"), CONFIG).unwrap();
    let config = dir.join("wire.toml");
    // The wire test's small die (a 4 mm square), tilted 2° to the right (outwards).
    let program = common::wire::DIE.replace("G41 D1", &format!("G52 A{ANGLE_DEG}\nG41 D1"));
    let program = program.replace("G40 G1", "G40 G50 G1");
    std::fs::write(dir.join("programs/die.ngc"), &program).unwrap();
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    let args = ["--config".to_string(), config.display().to_string()];
    let daemon = common::daemon::Daemon::start_args(
        &dir,
        &args,
        &common::daemon::base_sets(&dir, "first.csv"),
        &[],
    );
    daemon.ok(&["run", "die.ngc"]);
    daemon.wait_for("halfway", |s| {
        s["state"] == "running" && s["job"]["progress"].as_f64().unwrap_or(0.0) > 0.45
    });
    let cp = daemon.hold_abort_checkpoint(&dir);
    let at: Vec<i64> = cp["position_steps"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_i64().unwrap())
        .collect();
    assert!(
        at[2] != 0 || at[3] != 0,
        "the wire is tilted at the stop: {cp}"
    );
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);

    let daemon = common::daemon::Daemon::start_args(
        &dir,
        &args,
        &common::daemon::base_sets(&dir, "second.csv"),
        &[],
    );
    daemon.resume_to_the_end(&[0, 0, 0, 0]);
    let reference = dir.join("reference.csv");
    let out = common::run_to_pulse_log(
        &dir.join("programs/die.ngc"),
        &reference,
        &["--config", config.to_str().unwrap()],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    common::daemon::assert_joined_is(&dir, &common::daemon::moves(&reference));
}

/// A wire left leaning by an aborted taper job: a program that does not taper is refused
/// (it would cut tilted) with the MDI line that brings the wire vertical; after it, the
/// program runs.
#[test]
fn a_straight_job_is_refused_while_the_wire_leans_until_it_is_brought_vertical() {
    let dir = common::daemon::scratch("taper-leaning");
    std::fs::write(dir.join("wire.toml"), CONFIG).unwrap();
    let config = dir.join("wire.toml");
    let tapered = common::wire::DIE.replace("G41 D1", &format!("G52 A{ANGLE_DEG}\nG41 D1"));
    let tapered = tapered.replace("G40 G1", "G40 G50 G1");
    std::fs::write(dir.join("programs/die.ngc"), &tapered).unwrap();
    std::fs::write(dir.join("programs/straight.ngc"), common::wire::DIE).unwrap();
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    let args = ["--config".to_string(), config.display().to_string()];
    let daemon = common::daemon::Daemon::start_args(
        &dir,
        &args,
        &common::daemon::base_sets(&dir, "pulses.csv"),
        &[],
    );
    daemon.ok(&["run", "die.ngc"]);
    daemon.wait_for("halfway", |s| {
        s["state"] == "running" && s["job"]["progress"].as_f64().unwrap_or(0.0) > 0.45
    });
    daemon.hold_abort_checkpoint(&dir);
    let refused = daemon.refused(&["run", "straight.ngc"], "the wire leans (U");
    assert!(
        refused.to_string().contains("G53 G0 U0 V0"),
        "says how to recover: {refused}"
    );
    daemon.ok(&["discard", "--yes"]);
    daemon.ok(&["mdi", "G53 G0 U0 V0"]);
    let s = daemon.wait_for("vertical", |s| s["state"] == "idle");
    let at = common::daemon::floats(&s["machine"]["position_machine_mm"]);
    assert_eq!((at[2], at[3]), (0.0, 0.0), "{s}");
    daemon.ok(&["run", "straight.ngc"]);
    let s = daemon.wait_for("the straight job's end", |s| {
        s["state"] == "idle" && s["last_job"]["outcome"] == "done"
    });
    assert_eq!(s["last_job"]["outcome"], "done");
}
