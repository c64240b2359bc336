//! A wire die and punch with their technology table, shared by the tests of passes and tabs,
//! and the pulse log read back as positions per condition.

#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::Path;

use edmd::output::read_pulse_log;

/// A die: from the start hole at the centre, `G41` inside a 4 mm square, out again.
pub const DIE: &str = "(die)\nG21 G90 G17\nG41 D1\nG1 X0 Y-2 F600\nG1 X2 Y-2\nG1 X2 Y2\nG1 X-2 Y2\n\
                   G1 X-2 Y-2\nG1 X0 Y-2\nG40 G1 X0 Y0\nM2\n";
/// A punch: from the start hole below it, `G42` around the 4 mm square at (0, 4), back out.
pub const PUNCH: &str = "(punch)\nG21 G90 G17\nG42 D1\nG1 X0 Y2 F600\nG1 X2 Y2\nG1 X2 Y6\nG1 X-2 Y6\n\
                     G1 X-2 Y2\nG1 X0 Y2\nG40 G1 X0 Y0\nM2\n";
pub const HALF_MM: f64 = 2.0;

/// The technology table (fast conditions: the test is about paths, not burn rates).
pub const TABLE: &str = "[compensation]\nd_mm = [0.0, 0.2]\n\n[generator]\ncondition = [\n\
  { number = 1, on_us = 1.0, off_us = 12.0, current_a = 1.0, v_ref = 35.0, feed_mm_per_min = 600.0 },\n\
  { number = 2, on_us = 2.0, off_us = 10.0, current_a = 2.5, v_ref = 30.0, feed_mm_per_min = 600.0 },\n\
  { number = 3, on_us = 4.0, off_us = 8.0, current_a = 5.0, v_ref = 25.0, feed_mm_per_min = 600.0 } ]\n\n\
[wire]\npass = [\n  { offset_mm = 0.2, condition = 3 },\n  { offset_mm = 0.15, condition = 2, reverse = true },\n\
  { offset_mm = 0.12, condition = 1 } ]\n";
/// Offset and direction (+1 counter-clockwise) of each pass's condition.
pub const PASSES: [(u16, f64, f64); 3] = [(3, 0.2, 1.0), (2, 0.15, -1.0), (1, 0.12, 1.0)];

/// Positions (µm, X and Y) after each moving tick, in order.
pub type Walk = Vec<(i64, i64)>;

/// A moving row of a pulse log: position after the row (µm, X and Y), condition, spark.
pub type Row = ((i64, i64), u16, bool);

/// The moving rows of a pulse log, and where it ends.
pub fn walk(path: &Path) -> (Vec<Row>, (i64, i64)) {
    let (_, rows) = read_pulse_log(path).unwrap();
    let (mut x, mut y) = (0i64, 0i64);
    let mut out = Vec::new();
    for r in rows.iter().filter(|r| r.steps.iter().any(|&s| s != 0)) {
        x += i64::from(r.steps[0]);
        y += i64::from(r.steps[1]);
        out.push(((x, y), r.condition, r.spark));
    }
    (out, (x, y))
}

/// The walk of each condition the ticks cut in, and where the log ends.
pub fn positions_by_condition(path: &Path) -> (BTreeMap<u16, Walk>, (i64, i64)) {
    let (rows, end) = walk(path);
    let mut by = BTreeMap::new();
    for (at, condition, _) in rows {
        by.entry(condition).or_insert_with(Vec::new).push(at);
    }
    (by, end)
}

/// Distance (µm) of a point (µm) from the die's square, inside it.
pub fn inside_die(p: &(i64, i64)) -> i64 {
    let half = (HALF_MM * 1000.0) as i64;
    (half - p.0.abs()).min(half - p.1.abs())
}

/// Distance (µm) of a point (µm) from the punch's square, outside it.
pub fn outside_punch(p: &(i64, i64)) -> i64 {
    let half = (HALF_MM * 1000.0) as i64;
    let (dx, dy) = (
        (p.0.abs() - half).max(0),
        ((p.1 - 2 * half).abs() - half).max(0),
    );
    ((dx * dx + dy * dy) as f64).sqrt().round() as i64
}

/// Each pass `(condition, offset_um, direction)` of `by` (the walks by condition) as
/// [`assert_pass`] holds it.
pub fn assert_passes(
    by: &BTreeMap<u16, Walk>,
    passes: &[(u16, i64, f64)],
    distance: &dyn Fn(&(i64, i64)) -> i64,
) {
    for &(condition, offset_um, direction) in passes {
        assert_pass(
            &format!("E{condition}"),
            &by[&condition],
            distance,
            offset_um,
            direction,
        );
    }
}

/// One pass's walk lies `offset_um` from the part's contour (`distance`, on the scrap side)
/// along the contour (away from the entry and exit line at X0): to the step on the straight
/// edges, within the chord tolerance (1 µm) and a step's rounding on corner arcs; and it
/// runs `direction` round (+1 counter-clockwise, from the shoelace area of its path).
pub fn assert_pass(
    label: &str,
    pts: &Walk,
    distance: &dyn Fn(&(i64, i64)) -> i64,
    offset_um: i64,
    direction: f64,
) {
    let along: Vec<i64> = pts
        .iter()
        .filter(|p| p.0.abs() > 300)
        .map(distance)
        .collect();
    assert!(along.len() > 1000, "{label}: {} points", along.len());
    assert!(
        along.iter().all(|&d| (d - offset_um).abs() <= 2),
        "{label}: {:?} µm from the contour, want {offset_um}",
        (along.iter().min(), along.iter().max())
    );
    let area: f64 = pts
        .windows(2)
        .map(|w| (w[0].0 * w[1].1 - w[1].0 * w[0].1) as f64)
        .sum::<f64>()
        / 2e6;
    assert!(area * direction > 10.0, "{label}: signed area {area} mm²");
}
