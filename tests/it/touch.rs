//! The wire-touch cycles (`edmd ctl find`) on the daemon, through the real binary against the
//! simulator's part: a block X −20…60, Y −40…30 with a ⌀10 mm hole at (12.345, −6.789), and a
//! 0.25 mm wire. Each result is checked against the simulated geometry: the hole's centre
//! within one step and its diameter within two, an edge within one step of the face (the
//! wire's centre a radius before it), a corner on both faces; the work offset written; a
//! bounce on the first approach retried; a search that finds nothing reported.

use crate::common;

use common::daemon::{Daemon, base_sets, floats, scratch};
use serde_json::Value;

const STEP: f64 = 0.001;
const WIRE_RADIUS: f64 = 0.125;

fn touch_sets(dir: &std::path::Path, extra: &[&str]) -> Vec<String> {
    let mut sets = base_sets(dir, "pulses.csv");
    sets.retain(|s| !s.starts_with("gap.kind"));
    sets.extend(
        [
            "gap.kind=\"sim\"",
            "sim.part_edge_mm={X=[-20.0,60.0],Y=[-40.0,30.0]}",
            "sim.hole_center_mm=[12.345,-6.789]",
            "sim.hole_diameter_mm=10.0",
            "wire.diameter_mm=0.25",
            "wire.touch_feed_mm_per_min=900.0",
        ]
        .iter()
        .chain(extra)
        .map(|s| s.to_string()),
    );
    sets
}

/// Jogs to (x, y) machine coordinates and waits for the standstill.
fn go_to(daemon: &Daemon, x: f64, y: f64) {
    for (axis, to) in [("X", x), ("Y", y)] {
        let here = floats(&daemon.status()["machine"]["position_machine_mm"]);
        let i = if axis == "X" { 0 } else { 1 };
        let d = to - here[i];
        if d.abs() > 1e-9 {
            daemon.ok(&["jog", axis, &format!("{d}")]);
            daemon.wait_for("the jog's end", |s| s["state"] == "idle");
        }
    }
}

/// `ctl find ARGS` (waiting): the cycle's status as `ctl --json` prints it, and the exit code.
fn find(daemon: &Daemon, args: &[&str]) -> (Value, i32) {
    let mut all = vec!["find"];
    all.extend(args);
    daemon.ctl(&all)
}

fn near(v: &Value, want: f64, within: f64) -> bool {
    v.as_f64().is_some_and(|x| (x - want).abs() <= within)
}

#[test]
fn find_center_measures_the_hole_and_writes_g55() {
    let dir = scratch("touch-center");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    let daemon = Daemon::start(&dir, &touch_sets(&dir, &[]), &[]);
    daemon.ok(&["home", "--here"]);
    go_to(&daemon, 11.0, -5.0);
    let (f, code) = find(&daemon, &["center", "--system", "G55"]);
    assert_eq!(code, 0, "{f}\n{}", daemon.log());
    assert_eq!(f["state"], "found", "{f}");
    eprintln!("find center: {}", f["message"]);
    let p = &f["point_mm"];
    assert!(
        near(&p[0], 12.345, STEP) && near(&p[1], -6.789, STEP),
        "{f}"
    );
    let d = &f["diameter_mm"];
    assert!(
        near(&d[0], 10.0, 2.0 * STEP) && near(&d[1], 10.0, 2.0 * STEP),
        "{f}"
    );
    assert_eq!(f["system"], "G55");
    // Written as G10 L20 would: the centre reads X0 Y0 in G55.
    let offsets = daemon.ok(&["offsets"])["message"]
        .as_str()
        .unwrap()
        .to_string();
    let g55 = offsets.lines().find(|l| l.contains("G55")).unwrap();
    let numbers: Vec<f64> = g55
        .split_whitespace()
        .filter_map(|w| w.trim_start_matches(['X', 'Y']).parse().ok())
        .collect();
    assert!(
        (numbers[0] - 12.345).abs() <= STEP && (numbers[1] + 6.789).abs() <= STEP,
        "{g55}"
    );
    // The wire stands at the centre, and the log says what was found.
    let at = floats(&daemon.status()["machine"]["position_machine_mm"]);
    assert!(
        (at[0] - 12.345).abs() <= STEP && (at[1] + 6.789).abs() <= STEP,
        "{at:?}"
    );
    let log = daemon.log();
    assert!(log.contains("hole centre X12.34"), "{log}");
    assert!(log.contains("; G55 X0 Y0 there"), "{log}");
    // Every move ran in the touch condition (E9 of the shipped table).
    // A round is 4 touches (an approach and a retouch each) and 2 moves to the middle.
    let rounds: usize = log
        .split(" rounds, ")
        .next()
        .unwrap()
        .rsplit(' ')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    let moves = log.matches("job start: find-").count();
    assert!(
        rounds >= 2 && moves == 10 * rounds,
        "{rounds} rounds, {moves} moves"
    );
    assert_eq!(
        log.matches("machining condition E9 from").count(),
        moves,
        "{log}"
    );
    assert!(!log.contains("ERROR"), "{log}");
    // An abort ends a cycle: failed, and said so; nothing more moves.
    go_to(&daemon, 11.0, -5.0);
    daemon.ok(&["find", "center", "--no-wait"]);
    daemon.wait_for("a find move", |s| s["state"] == "finding");
    daemon.ok(&["abort"]);
    let s = daemon.wait_for("the cycle's end", |s| {
        s["state"] == "idle" && s["machine"]["find"]["state"] != "running"
    });
    let f = &s["machine"]["find"];
    assert_eq!(f["state"], "failed", "{f}");
    assert!(f["id"].as_u64() == Some(2), "{f}");
    assert!(f["message"].as_str().unwrap().contains("stopped"), "{f}");
    let before = floats(&s["machine"]["position_machine_mm"]);
    std::thread::sleep(std::time::Duration::from_millis(300));
    assert_eq!(
        floats(&daemon.status()["machine"]["position_machine_mm"]),
        before
    );
}

#[test]
fn find_edge_and_corner_add_the_wire_radius_and_retry_a_bounce() {
    let dir = scratch("touch-edge");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    let daemon = Daemon::start(&dir, &touch_sets(&dir, &["sim.touch_bounce_mm=0.5"]), &[]);
    daemon.ok(&["home", "--here"]);
    go_to(&daemon, -30.0, 0.0);
    let (f, code) = find(&daemon, &["edge", "X+", "--system", "G56"]);
    assert_eq!(code, 0, "{f}\n{}", daemon.log());
    // The face is at X−20: the contact plus the radius lands within a step past it.
    let x = f["point_mm"][0].as_f64().unwrap();
    assert!((-20.0..-20.0 + STEP).contains(&x), "{f}");
    assert!(f["point_mm"][1].is_null(), "an edge measures one axis: {f}");
    let message = f["message"].as_str().unwrap();
    eprintln!("find edge X+: {message}");
    // The bounce 0.5 mm before the face was a false contact: retouched away, approached again.
    assert!(message.contains("1 touch, 1 retry"), "{message}");
    let wire = message.split("touched at X").nth(1).unwrap();
    let wire: f64 = wire.split([' ', ',']).next().unwrap().parse().unwrap();
    assert!((wire - (-20.0 - WIRE_RADIUS)).abs() <= STEP, "{message}");
    // Backed off the face.
    let at = floats(&daemon.status()["machine"]["position_machine_mm"]);
    assert!((at[0] - (wire - 0.1)).abs() < 1e-9, "{at:?}");

    // The corner X+Y+ (X−20, Y−40), from off it.
    go_to(&daemon, -24.0, -43.0);
    let (f, code) = find(&daemon, &["corner", "X+Y+"]);
    assert_eq!(code, 0, "{f}\n{}", daemon.log());
    let p = floats(&f["point_mm"]);
    assert!(
        (p[0] + 20.0).abs() <= STEP && (p[1] + 40.0).abs() <= STEP,
        "{f}"
    );
    assert!(f["system"].is_null());
    let at = floats(&daemon.status()["machine"]["position_machine_mm"]);
    assert_eq!(at, [-24.0, -43.0], "back where it started");

    // Nothing within the search: failed, and said so.
    go_to(&daemon, -45.0, 0.0);
    let (f, code) = find(&daemon, &["edge", "X+"]);
    assert_eq!(code, 1);
    assert_eq!(f["state"], "failed");
    assert_eq!(
        f["message"],
        "edge X+ failed: X+: no contact within 20.000 mm"
    );
    // Refusals before anything moves.
    daemon.refused(&["find", "edge", "Z+"], "is not something to find");
    daemon.refused(
        &["find", "center", "--system", "G60"],
        "is not a work system",
    );
}

#[test]
fn find_is_refused_unhomed_and_without_its_condition() {
    let dir = scratch("touch-refused");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    let sets = touch_sets(&dir, &["homing.required=true", "wire.touch_condition=7"]);
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.refused(&["find", "center"], "not homed");
    daemon.ok(&["home", "--here"]);
    daemon.refused(
        &["find", "center"],
        "wire.touch_condition = 7 is not one of [generator] condition",
    );
    assert_eq!(daemon.status()["state"], "idle");
}
