//! Homing by switches on the daemon, through the real binary with the simulated machine:
//! the sequence order, the latch point becoming the home position, the final move, a re-home
//! that finds the switch where homing put it, a search that finds no switch, and the
//! refusals.

use crate::common;

use common::daemon::{Daemon, base_sets, floats, scratch};
use serde_json::Value;

/// Two switched axes: Y (sequence 0) searches towards −, X (sequence 1) towards +.
fn homing_sets(dir: &std::path::Path, sim_switches: &str) -> Vec<String> {
    let mut sets = base_sets(dir, "pulses.csv");
    sets.retain(|s| !s.starts_with("gap.kind"));
    sets.push("gap.kind=\"sim\"".to_string());
    sets.push("homing.required=true".to_string());
    sets.push(
        "homing.axis=[\
         {axis=\"X\", direction=\"+\", search_feed_mm_per_min=600.0, latch_feed_mm_per_min=30.0, \
          home_position_mm=10.0, final_move_mm=-1.0, sequence=1, search_distance_mm=20.0, \
          latch_distance_mm=0.5},\
         {axis=\"Y\", direction=\"-\", search_feed_mm_per_min=600.0, latch_feed_mm_per_min=30.0, \
          home_position_mm=-5.0, final_move_mm=0.5, sequence=0, search_distance_mm=20.0, \
          latch_distance_mm=0.5}]"
            .to_string(),
    );
    sets.push(format!("sim.home_switch_mm={sim_switches}"));
    sets
}

fn idle_machine(daemon: &Daemon) -> Value {
    daemon.wait_for("idle", |s| s["state"] == "idle");
    daemon.status()["machine"].clone()
}

#[test]
fn switches_home_the_axes_in_sequence_and_the_latch_point_becomes_home() {
    let dir = scratch("homing");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    let daemon = Daemon::start(&dir, &homing_sets(&dir, "{X=3.0,Y=-2.0}"), &[]);
    let reply = daemon.ok(&["home"]);
    assert!(
        reply["message"]
            .as_str()
            .unwrap()
            .contains("homing Y, X by their switches"),
        "{reply}"
    );
    // Homing is one job per axis: wait for both to have latched.
    daemon.wait_for_log("homed X");
    let m = idle_machine(&daemon);
    assert_eq!(m["homed"], serde_json::json!([true, true]));
    // The switches were found where the machine believed X3 and Y-2; they are X10 and Y-5,
    // and each axis then made its final move away from the switch.
    assert_eq!(floats(&m["position_machine_mm"]), [9.0, -4.5]);
    let log = daemon.log();
    let y = log.find("homed Y: the switch latched where the machine believed -2.0000 mm");
    let x = log.find("homed X: the switch latched where the machine believed 3.0000 mm");
    assert!(y.is_some() && x.is_some(), "{log}");
    assert!(y < x, "sequence 0 (Y) homes before sequence 1 (X)");
    assert!(log.contains("a correction of +7.0000 mm"), "{log}");
    // The back-off really left the switch (one step: the simulated switch has no
    // hysteresis) before the slow approach latched it again.
    assert!(
        log.contains("home-X:3: probe contact lost") && log.contains("X2.9990 Y-4.5000"),
        "{log}"
    );

    // Homed now: the switch is where homing put it, so a re-home corrects nothing.
    daemon.ok(&["home", "X"]);
    daemon.wait_for_log("a correction of +0.0000 mm");
    let m = idle_machine(&daemon);
    assert_eq!(floats(&m["position_machine_mm"]), [9.0, -4.5]);
    let state: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("machine-state.json")).unwrap())
            .unwrap();
    assert_eq!(state["moving"], false);
    assert_eq!(state["homed"], serde_json::json!([true, true]));
    assert_eq!(state["position_steps"], serde_json::json!([9000, -4500]));

    // `--here` on an axis with a switch, or on none named while every axis has one, is
    // refused: it would shift the machine's coordinates (soft limits, offsets) silently.
    daemon.refused(
        &["home", "--here", "Y"],
        "Y has a home switch: `home Y` homes by it; `home --here Y --force`",
    );
    daemon.refused(&["home", "--here"], "every axis has a home switch");
    assert_eq!(
        floats(&daemon.status()["machine"]["position_machine_mm"]),
        [9.0, -4.5]
    );
    // With --force it declares the named axis (only) at its home position, and says by
    // how much that shifted it.
    let reply = daemon.ok(&["home", "--here", "Y", "--force"]);
    assert!(
        reply["message"]
            .as_str()
            .unwrap()
            .contains("Y-5.0000 (was -4.5000: shifted -0.5000 mm)"),
        "{reply}"
    );
    let m = daemon.status()["machine"].clone();
    assert_eq!(floats(&m["position_machine_mm"]), [9.0, -5.0]);
}

#[test]
fn a_search_that_finds_no_switch_leaves_the_axis_unhomed_and_stops_the_sequence() {
    let dir = scratch("homing-missed");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    // Y's switch is 30 mm away: past its 20 mm search.
    let daemon = Daemon::start(&dir, &homing_sets(&dir, "{X=3.0,Y=-30.0}"), &[]);
    daemon.ok(&["home"]);
    daemon.wait_for_log("homing Y: the home switch did not close");
    let m = idle_machine(&daemon);
    assert_eq!(m["homed"], serde_json::json!([false, false]));
    // It searched the whole 20 mm and stopped there; X never started.
    assert_eq!(floats(&m["position_machine_mm"]), [0.0, -20.0]);
    assert!(!daemon.log().contains("homing X: searching"));
    // Said in homing's words, not as a probing move's line, segment and step.
    let last = &daemon.status()["last_job"];
    let error = last["error"].as_str().unwrap_or_default();
    assert!(
        error.starts_with("homing Y: the home switch did not close within the search, 20.0 mm -"),
        "{last}"
    );
    assert!(!error.contains("segment"), "{error}");
    assert!(daemon.log().contains("the axis stays unhomed"));
    daemon.refused(&["run", "nothing.nc"], "not homed");
}

#[test]
fn homing_refusals_say_what_to_do() {
    let dir = scratch("homing-refusals");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    let mut sets = homing_sets(&dir, "{}");
    sets.push("machine.axes=[\"X\",\"Y\",\"Z\"]".to_string());
    sets.push("machine.step_mm=[0.001,0.001,0.001]".to_string());
    sets.push("machine.travel_mm={X=[-1.0,5.0]}".to_string());
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.refused(
        &["home"],
        "homing X would end at 9 mm (home_position_mm + final_move_mm), outside",
    );
    daemon.refused(
        &["home", "Z"],
        "Z has no home switch ([[homing.axis]]): `home --here Z`",
    );
    daemon.refused(&["home", "W"], "\"W\" is not an axis of this machine");
    daemon.ok(&["home", "--here", "Z"]);
    let m = daemon.status()["machine"].clone();
    assert_eq!(m["homed"], serde_json::json!([false, false, true]));
    drop(daemon);

    // A gap input that reads no switches cannot home by them.
    let dir = scratch("homing-no-switches");
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.push("homing.required=true".to_string());
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.refused(&["home"], "gap.kind = \"none\" reads no home switches");
}
