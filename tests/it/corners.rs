//! Corner control (a condition's `corner_angle_deg`, `corner_feed_factor`,
//! `corner_distance_mm`, `corner_dwell_ms`) through the public preprocessor: the planned feed
//! is lowered within the distance around corners sharper than the angle, and nowhere else;
//! a dwell stops the path at the corner; the configuration refuses an incomplete rule.

use std::io::Cursor;
use std::sync::Arc;

use edmd::config::{Config, CornerControl};
use edmd::gcode::{BlockReader, ProgramOptions};
use edmd::preprocess::{PlanSettings, Preprocessor, Segment};

/// A 90° corner at 10 mm of path, a 10° one at 20 mm, at 600 mm/min in E1.
const PROGRAM: &str = "G21 G90 G17\nE1\nG1 X10 Y0 F600\nG1 X10 Y10\nG1 X11.7365 Y19.8481\nM2\n";
const FEED: f64 = 10.0;

fn config(corner: Option<CornerControl>) -> Config {
    let mut cfg = Config::default();
    cfg.interpolation.max_segment_mm = 0.1;
    let e1 = cfg.conditions.iter_mut().find(|c| c.number == 1).unwrap();
    e1.corner = corner;
    cfg
}

/// The planned segments and the path length at each one's start.
fn plan(cfg: &Config) -> Vec<(f64, Segment)> {
    let options = ProgramOptions::from_config(cfg);
    let reader = BlockReader::with_options(
        Cursor::new(PROGRAM.as_bytes()),
        "c.ngc",
        &cfg.machine.axes,
        options,
    );
    let mut pre = Preprocessor::new(PlanSettings::from_config(cfg));
    let mut out = Vec::new();
    for block in reader {
        pre.push_block(Arc::new(block.unwrap()), |s| out.push(s));
    }
    pre.finish(|s| out.push(s));
    let mut s = 0.0;
    out.into_iter()
        .map(|seg| {
            let at = s;
            s += seg.length;
            (at, seg)
        })
        .collect()
}

const RULE: CornerControl = CornerControl {
    angle_deg: 150.0,
    feed_factor: 0.5,
    distance_mm: 1.0,
    dwell_ms: 0.0,
};

#[test]
fn the_feed_is_lowered_within_the_distance_around_sharp_corners_only() {
    let plain = plan(&config(None));
    let slowed = plan(&config(Some(RULE)));
    assert_eq!(
        plain.len(),
        slowed.len(),
        "corner control moves no end point"
    );
    let (mut inside, mut outside) = (0, 0);
    for ((s, a), (_, b)) in plain.iter().zip(&slowed) {
        assert_eq!(a.end, b.end);
        let (start, end) = (*s, s + b.length);
        if start >= 9.0 - 1e-9 && end <= 11.0 + 1e-9 {
            // Inside the zone of the square corner: at most half the feed.
            assert!(
                b.v_peak <= FEED * 0.5 + 1e-9,
                "{start:.2}..{end:.2}: {}",
                b.v_peak
            );
            assert!(
                a.v_peak > FEED * 0.5 + 1.0,
                "the plain plan is faster there"
            );
            inside += 1;
        } else if end < 8.8 || start > 11.2 {
            // Outside it (one segment of slack for the zone's ends, where the speed changes
            // under a_T): the plan without corner control, the 10° corner included.
            assert!(
                (a.v_peak - b.v_peak).abs() < 1e-9,
                "{start:.2}..{end:.2}: {} without, {} with",
                a.v_peak,
                b.v_peak
            );
            outside += 1;
        }
    }
    assert!(
        inside >= 19 && outside > 250,
        "{inside} inside, {outside} outside"
    );
    // Around the 10° corner at 20 mm the feed stays up: it is not sharper than 150°.
    let near_shallow: Vec<f64> = slowed
        .iter()
        .filter(|(s, seg)| *s > 19.3 && s + seg.length < 19.9)
        .map(|(_, seg)| seg.v_peak)
        .collect();
    assert!(!near_shallow.is_empty());
    assert!(
        near_shallow.iter().all(|&v| v > FEED * 0.99),
        "{near_shallow:?}"
    );
    // And the square corner's zone is slow on both sides.
    let before = slowed
        .iter()
        .find(|(s, _)| (*s - 9.5).abs() < 0.051)
        .unwrap();
    let after = slowed
        .iter()
        .find(|(s, _)| (*s - 10.5).abs() < 0.051)
        .unwrap();
    assert!(before.1.v_peak <= 5.0 + 1e-9 && after.1.v_peak <= 5.0 + 1e-9);
}

#[test]
fn a_corner_dwell_stops_the_path_at_the_corner() {
    let slowed = plan(&config(Some(CornerControl {
        dwell_ms: 40.0,
        ..RULE
    })));
    let dwells: Vec<(f64, f64, f64)> = slowed
        .iter()
        .filter(|(_, seg)| seg.corner_dwell_s > 0.0)
        .map(|(s, seg)| (*s, seg.corner_dwell_s, seg.v_entry))
        .collect();
    assert_eq!(dwells.len(), 1, "{dwells:?}");
    let (at, dwell, v_entry) = dwells[0];
    assert!((at - 10.0).abs() < 1e-9, "at the corner: {at}");
    assert_eq!(dwell, 0.04);
    assert_eq!(v_entry, 0.0, "the path stops there");
}

#[test]
fn an_incomplete_corner_rule_is_refused_with_what_it_needs() {
    let load = |condition: &str| {
        let text = format!("[generator]\ncondition = [{condition}]\n");
        let path = std::env::temp_dir().join(format!("edmd-corners-{}.toml", std::process::id()));
        std::fs::write(&path, text).unwrap();
        let result = Config::load(Some(&path), &[]);
        let _ = std::fs::remove_file(&path);
        result.map(|_| ()).map_err(|e| e.to_string())
    };
    let base = "number = 1, on_us = 1.0, off_us = 12.0, current_a = 1.0, v_ref = 35.0, feed_mm_per_min = 10.0";
    assert!(load(&format!("{{ {base}, corner_angle_deg = 120.0, corner_feed_factor = 0.5, corner_distance_mm = 0.5 }}")).is_ok());
    let e = load(&format!("{{ {base}, corner_angle_deg = 120.0 }}")).unwrap_err();
    assert!(
        e.contains("corner_angle_deg needs corner_feed_factor"),
        "{e}"
    );
    let e = load(&format!("{{ {base}, corner_feed_factor = 0.5 }}")).unwrap_err();
    assert!(e.contains("need corner_angle_deg"), "{e}");
    let e = load(&format!(
        "{{ {base}, corner_angle_deg = 200.0, corner_feed_factor = 0.5, corner_distance_mm = 0.5 }}"
    ))
    .unwrap_err();
    assert!(e.contains("between 0 and 180"), "{e}");
}
