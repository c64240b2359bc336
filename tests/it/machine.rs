//! The machine knows where it is: machine coordinates that last (the state file), work
//! offsets that move a program, soft limits held before anything moves, touch-off and
//! `home --here` on the daemon, and a state that is distrusted after a kill while moving.
//! Everything through the real binary; positions from the pulse log it writes.

use crate::common;

use std::path::Path;
use std::process::Command;

use common::daemon::{Daemon, base_sets, floats, scratch};
use edmd::output::read_pulse_log;
use serde_json::Value;

fn edmd(dir: &Path, args: &[&str]) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .args(args)
        .current_dir(dir)
        .env_remove("RUST_LOG")
        .output()
        .unwrap();
    let text =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    (out.status.code().unwrap_or(-1), text)
}

/// Every point the pulse log passes through, in steps, from its header's start.
fn points(log: &Path) -> Vec<Vec<i64>> {
    let (header, rows) = read_pulse_log(log).unwrap();
    let mut at = header.start.clone();
    let mut all = vec![at.clone()];
    for r in rows {
        if r.steps.iter().any(|&s| s != 0) {
            for (p, s) in at.iter_mut().zip(&r.steps) {
                *p += i64::from(*s);
            }
            all.push(at.clone());
        }
    }
    all
}

const STATE_G55: &str = r#"{
  "version": 1, "moving": false, "axes": ["X", "Y"], "step_mm": [0.001, 0.001],
  "position_steps": [1000, 1000], "homed": [true, true], "work_system": "G55",
  "offsets_mm": { "G55": { "X": 5.0, "Y": 3.0 } }
}
"#;

#[test]
fn a_program_runs_in_the_active_work_system_from_where_the_machine_stands() {
    let dir = scratch("work-system");
    std::fs::write(dir.join("state.json"), STATE_G55).unwrap();
    std::fs::write(
        dir.join("square.nc"),
        "G21 G90\nG0 X0 Y0\nG1 X2 F300\nG1 Y1\nG53 G0 X20 Y10\nM2\n",
    )
    .unwrap();
    let (code, text) = edmd(
        &dir,
        &[
            "run",
            "square.nc",
            "--state",
            "state.json",
            "--set",
            "output.kind=\"file\"",
            "--set",
            "output.path=\"pulses.csv\"",
            "--set",
            "gap.kind=\"none\"",
        ],
    );
    assert_eq!(code, 0, "{text}");
    let path = points(&dir.join("pulses.csv"));
    // The job starts where the machine stands, and program X0 Y0 is machine 5, 3 (G55).
    assert_eq!(path[0], [1000, 1000]);
    for corner in [[5000, 3000], [7000, 3000], [7000, 4000], [20000, 10000]] {
        assert!(
            path.iter().any(|p| *p == corner),
            "the path never reaches {corner:?} (program + offset in machine steps)"
        );
    }
    assert_eq!(
        path.last().unwrap(),
        &[20000, 10000],
        "G53 is machine coordinates"
    );
    // The state file now says where the machine stands; M2 returned to G54.
    let state: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("state.json")).unwrap()).unwrap();
    assert_eq!(state["position_steps"], serde_json::json!([20000, 10000]));
    assert_eq!(state["work_system"], "G54");
    assert_eq!(state["moving"], false);
    assert_eq!(state["offsets_mm"]["G55"]["X"], 5.0);
}

#[test]
fn a_program_past_the_travel_is_refused_before_any_pulse() {
    let dir = scratch("travel");
    std::fs::write(
        dir.join("far.nc"),
        "G21 G90\nG0 X10 Y10\nG1 X50 F300\nG3 X30 Y30 I-10 J10\nM2\n",
    )
    .unwrap();
    let sets = [
        "--set",
        "output.kind=\"file\"",
        "--set",
        "output.path=\"pulses.csv\"",
        "--set",
        "gap.kind=\"none\"",
    ];
    // The arc's top reaches Y 34.142 (centre 40, 20, radius 14.142) though its ends stay
    // below 34: the extent of the curve counts, not its end points.
    let mut args = vec![
        "run",
        "far.nc",
        "--set",
        "machine.travel_mm={X=[-1,60],Y=[-1,34]}",
    ];
    args.extend(sets);
    let (code, text) = edmd(&dir, &args);
    assert_eq!(code, 2, "{text}");
    assert!(
        text.contains("far.nc:4:1: the path leaves the machine's travel: axis Y reaches 34.14")
            && text.contains("above its upper limit 34 mm"),
        "{text}"
    );
    assert!(!dir.join("pulses.csv").exists(), "a pulse was written");

    // Work offsets and G92 count: the same program shifted by G92 leaves at X.
    std::fs::write(dir.join("g92.nc"), "G0 X0 Y0\nG92 X-20\nG1 X20 F300\nM2\n").unwrap();
    let mut args = vec![
        "run",
        "g92.nc",
        "--set",
        "machine.travel_mm={X=[-1,30],Y=[-1,34]}",
    ];
    args.extend(sets);
    let (code, text) = edmd(&dir, &args);
    assert_eq!(code, 2, "{text}");
    assert!(
        text.contains("g92.nc:3:1:") && text.contains("axis X reaches 40 mm"),
        "{text}"
    );

    // Inside the travel it runs.
    let mut args = vec![
        "run",
        "far.nc",
        "--set",
        "machine.travel_mm={X=[-1,60],Y=[-1,35]}",
    ];
    args.extend(sets);
    let (code, text) = edmd(&dir, &args);
    assert_eq!(code, 0, "{text}");
}

fn machine(status: &Value) -> &Value {
    &status["machine"]
}

#[test]
fn touch_off_and_home_here_on_the_daemon_last_over_a_restart_but_not_a_kill() {
    let dir = scratch("machine-state");
    std::fs::write(
        dir.join("programs/move.nc"),
        "G21 G90\nG1 X1 Y0.5 F600\nM2\n",
    )
    .unwrap();
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.push("homing.required=true".to_string());
    let daemon = Daemon::start(&dir, &sets, &[]);
    let s = daemon.status();
    assert_eq!(machine(&s)["homed"], serde_json::json!([false, false]));
    let (reply, code) = daemon.ctl(&["run", "move.nc"]);
    assert_eq!(code, 1);
    assert!(
        reply["error"]
            .as_str()
            .unwrap()
            .contains("axis X, Y not homed"),
        "{reply}"
    );

    daemon.ok(&["home", "--here"]);
    // G55's zero 2 mm left of where the machine stands: the program's X1 is machine X-1.
    daemon.ok(&["touch-off", "X", "2", "--system", "G55"]);
    let reply = daemon.ok(&["offsets"]);
    assert!(
        reply["message"]
            .as_str()
            .unwrap()
            .contains(" G55    X-2.0000 Y0.0000"),
        "{reply}"
    );
    // A program that selects G55 and moves: ends at program + offset in machine mm.
    std::fs::write(
        dir.join("programs/g55.nc"),
        "G21 G90 G55\nG1 X1 Y0.5 F600\n",
    )
    .unwrap();
    daemon.ok(&["run", "g55.nc"]);
    let idle = daemon.wait_for("the job's end", |s| {
        s["state"] == "idle" && s["last_job"]["outcome"] == "done"
    });
    assert_eq!(floats(&machine(&idle)["position_machine_mm"]), [-1.0, 0.5]);
    // No M2: the program leaves G55 active, and the work position reads the program's.
    assert_eq!(machine(&idle)["work_system"], "G55");
    assert_eq!(floats(&machine(&idle)["position_work_mm"]), [1.0, 0.5]);
    let text = daemon.ctl(&["status"]);
    assert_eq!(text.1, 0);
    daemon.signal(libc_sigterm());
    let (code, _) = daemon.wait();
    assert_eq!(code, 0);

    // A clean restart: the machine is where it was, homed, in G55.
    let daemon = Daemon::start(&dir, &sets, &[]);
    let s = daemon.status();
    assert_eq!(machine(&s)["homed"], serde_json::json!([true, true]));
    assert_eq!(floats(&machine(&s)["position_machine_mm"]), [-1.0, 0.5]);
    assert_eq!(machine(&s)["work_system"], "G55");
    // A long move, killed while it runs: the state file says moving, so the next daemon
    // keeps the believed position but unhomes every axis (and refuses to run).
    std::fs::write(
        dir.join("programs/long.nc"),
        "G21 G90 G54\nG1 X40 F300\nM2\n",
    )
    .unwrap();
    daemon.ok(&["run", "long.nc"]);
    daemon.wait_for("moving", common::daemon::is_moving);
    let state: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("machine-state.json")).unwrap())
            .unwrap();
    assert_eq!(
        state["moving"], true,
        "write-ahead: marked moving before the first step"
    );
    daemon.signal(9);
    let _ = daemon.wait();
    let daemon = Daemon::start(&dir, &sets, &[]);
    let s = daemon.status();
    assert_eq!(machine(&s)["homed"], serde_json::json!([false, false]));
    assert!(
        daemon
            .log()
            .contains("the machine was moving when edmd last stopped")
    );
    let (_, code) = daemon.ctl(&["run", "move.nc"]);
    assert_eq!(code, 1, "unhomed after a kill");
    daemon.signal(libc_sigterm());
    let _ = daemon.wait();
}

fn libc_sigterm() -> i32 {
    15
}

#[test]
fn jogs_stop_at_the_soft_limits_and_mdi_lines_share_their_modes() {
    let dir = scratch("jog-mdi");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.push("machine.travel_mm={X=[-1.0,2.0],Y=[-1.0,1.0]}".to_string());
    sets.push("homing.required=true".to_string());
    let daemon = Daemon::start(&dir, &sets, &[]);
    let (reply, code) = daemon.ctl(&["jog", "X", "0.5"]);
    assert_eq!(code, 1, "unhomed: {reply}");
    daemon.ok(&["home", "--here"]);
    let idle = |d: &Daemon| {
        d.wait_for("idle", |s| s["state"] == "idle");
        floats(&machine(&d.status())["position_machine_mm"])
    };
    // MDI: G91 stays in force for the next MDI line, as in LinuxCNC.
    daemon.ok(&["mdi", "G91"]);
    assert_eq!(idle(&daemon), [0.0, 0.0]);
    daemon.ok(&["mdi", "G1 X0.5 Y0.25 F600"]);
    assert_eq!(idle(&daemon), [0.5, 0.25]);
    daemon.ok(&["mdi", "G1 X0.5"]);
    assert_eq!(
        idle(&daemon),
        [1.0, 0.25],
        "the second MDI line was incremental too"
    );
    // MDI is checked like a program: past the travel, refused before anything moves.
    let (reply, code) = daemon.ctl(&["mdi", "G1 Y5"]);
    assert_eq!(code, 1, "{reply}");
    assert!(
        reply["error"]
            .as_str()
            .unwrap()
            .contains("mdi:1:1: the path leaves the machine's travel"),
        "{reply}"
    );
    assert_eq!(idle(&daemon), [1.0, 0.25]);
    // A jog, then a jog that would pass the limit stops at it, then one into it is refused.
    let reply = daemon.ok(&["jog", "X", "-0.25", "--feed", "300"]);
    assert!(
        reply["message"].as_str().unwrap().contains("running jog"),
        "{reply}"
    );
    assert_eq!(idle(&daemon), [0.75, 0.25]);
    // 0.25 mm at 300 mm/min is 50 ms of ticks: the jog feed, not the rapid.
    let last = &daemon.status()["last_job"];
    let secs = last["virtual_time_s"].as_f64().unwrap();
    assert!((0.049..0.06).contains(&secs), "{last}");
    daemon.ok(&["jog", "X", "5"]);
    assert_eq!(idle(&daemon), [2.0, 0.25], "stopped at the soft limit");
    let (reply, code) = daemon.ctl(&["jog", "X", "0.1"]);
    assert_eq!(code, 1);
    assert!(
        reply["error"]
            .as_str()
            .unwrap()
            .contains("jog the other way"),
        "{reply}"
    );
    daemon.ok(&["jog", "X", "-0.5"]);
    assert_eq!(idle(&daemon), [1.5, 0.25], "away from the limit is allowed");
}

#[test]
fn a_continuous_jog_stops_when_its_renewals_stop() {
    use std::time::{Duration, Instant};
    let dir = scratch("dead-man");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.push("machine.travel_mm={X=[-1.0,100.0],Y=[-1.0,1.0]}".to_string());
    sets.push("machine.max_jog_feed_mm_per_min=600.0".to_string());
    let daemon = Daemon::start(&dir, &sets, &[]);
    let request = r#"{"cmd":"jog-continuous","axis":"X","positive":true}"#;
    let x = |s: &Value| machine(s)["position_machine_mm"][0].as_f64().unwrap();
    // Renewed every 100 ms for a second: it keeps moving.
    let mut last = Instant::now();
    for _ in 0..10 {
        let reply = &common::daemon::raw_exchange(&daemon.socket, &[request])[0];
        assert_eq!(reply["ok"], true, "{reply}");
        last = Instant::now();
        std::thread::sleep(Duration::from_millis(100));
    }
    let moving = daemon.status();
    assert_eq!(moving["state"], "jogging", "{moving}");
    assert!(x(&moving) > 0.5, "10 mm/s for about a second: {moving}");
    // Then silence: it halts within 300 ms of the last renewal and stays halted. The status
    // is read from the board the control loop posts every POST_EVERY while something moves, so
    // the last change is seen up to that much later than it happened.
    let mut position = x(&moving);
    let mut halted_at = Instant::now();
    while Instant::now() < last + Duration::from_millis(1200) {
        let p = x(&daemon.status());
        if p != position {
            position = p;
            halted_at = Instant::now();
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let after = halted_at.duration_since(last);
    assert!(
        after <= Duration::from_millis(300) + edmd::daemon::board::POST_EVERY,
        "halted {after:?} after the last renewal"
    );
    let idle = daemon.wait_for("idle", |s| s["state"] == "idle");
    assert!(
        daemon.log().contains("not renewed for 250 ms"),
        "{}",
        daemon.log()
    );
    assert_eq!(x(&idle), position);
    eprintln!("halted {after:?} after the last renewal, at X {position}");
    // jog-stop stops one at once; another direction while one moves is refused.
    common::daemon::raw_exchange(&daemon.socket, &[request]);
    let reply = &common::daemon::raw_exchange(
        &daemon.socket,
        &[r#"{"cmd":"jog-continuous","axis":"X","positive":false}"#],
    )[0];
    assert_eq!(reply["ok"], false, "{reply}");
    let reply = &common::daemon::raw_exchange(&daemon.socket, &[r#"{"cmd":"jog-stop"}"#])[0];
    assert_eq!(reply["ok"], true, "{reply}");
    daemon.wait_for("idle", |s| s["state"] == "idle");
}

#[test]
fn a_resume_is_refused_after_the_offsets_changed_or_the_machine_moved() {
    let dir = scratch("resume-offsets");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    std::fs::write(
        dir.join("programs/slow.nc"),
        "G21 G90\nG1 X3 Y0 F120\nG1 Y1\nM2\n",
    )
    .unwrap();
    let daemon = Daemon::start(&dir, &base_sets(&dir, "pulses.csv"), &[]);
    daemon.ok(&["home", "--here"]);
    daemon.ok(&["run", "slow.nc"]);
    daemon.wait_for("moving", common::daemon::is_moving);
    daemon.ok(&["abort"]);
    let idle = daemon.wait_for("idle", |s| s["state"] == "idle");
    let stopped = floats(&machine(&idle)["position_machine_mm"]);
    assert!(stopped[0] > 0.0 && stopped[0] < 3.0, "{idle}");
    assert_eq!(idle["checkpoint"]["reason"], "abort");

    // The offsets changed: refused, naming the system and axis.
    daemon.ok(&["touch-off", "X", "5"]);
    let (reply, code) = daemon.ctl(&["resume"]);
    assert_eq!(code, 1);
    let error = reply["error"].as_str().unwrap();
    assert!(
        error.contains("the work offsets changed") && error.contains("G54 X: 0.0000 then"),
        "{error}"
    );
    daemon.ok(&["touch-off", "X", &format!("{}", stopped[0])]);

    // A jog away (it leaves the checkpoint alone, and says nothing of discarding it):
    // refused until the machine is back.
    let reply = daemon.ok(&["jog", "Y", "0.5"]);
    assert!(
        !reply["message"].as_str().unwrap().contains("discarded"),
        "{reply}"
    );
    daemon.wait_for("idle", |s| s["state"] == "idle");
    assert_eq!(daemon.status()["checkpoint"]["reason"], "abort");
    let (reply, code) = daemon.ctl(&["resume"]);
    assert_eq!(code, 1);
    assert!(
        reply["error"]
            .as_str()
            .unwrap()
            .contains("the machine stands at"),
        "{reply}"
    );
    daemon.ok(&["jog", "Y", "-0.5"]);
    daemon.wait_for("idle", |s| s["state"] == "idle");
    // Back where it stopped, offsets as they were: the job resumes and ends at its end.
    daemon.ok(&["resume"]);
    let done = daemon.wait_for("the job's end", |s| {
        s["state"] == "idle" && s["last_job"]["outcome"] == "done"
    });
    assert_eq!(floats(&machine(&done)["position_machine_mm"]), [3.0, 1.0]);
}

/// The ticks of a pulse log at which some axis stepped.
fn stepping_ticks(log: &Path) -> Vec<u64> {
    let (_, rows) = read_pulse_log(log).unwrap();
    rows.into_iter()
        .filter(|r| r.steps.iter().any(|&s| s != 0))
        .map(|r| r.tick)
        .collect()
}

#[test]
fn an_estop_stops_within_its_tick_and_nothing_moves_until_reset() {
    let dir = scratch("estop");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    std::fs::write(
        dir.join("programs/line.nc"),
        "G21 G90\nG1 X3 F600\nG1 Y1\nM2\n",
    )
    .unwrap();
    // 10 mm/s at 50 µs ticks: a step every other tick; the E-stop at tick 4001.
    std::fs::write(dir.join("gap.txt"), "0 normal\n4001 estop\n").unwrap();
    let daemon = Daemon::start(&dir, &common::daemon::script_sets(&dir, "pulses.csv"), &[]);
    daemon.ok(&["run", "line.nc"]);
    let stopped = daemon.wait_for("the E-stop", |s| s["state"] == "estop");
    let last = &stopped["last_job"];
    assert_eq!(last["outcome"], "estop", "{last}");
    assert!(
        last["error"]
            .as_str()
            .unwrap()
            .contains("E-stop: motion stopped in the tick"),
        "{last}"
    );
    // No step at or after the tick the E-stop was seen.
    let ticks = stepping_ticks(&dir.join("pulses.csv"));
    assert!(ticks.len() > 900, "it moved before: {} steps", ticks.len());
    assert!(
        *ticks.last().unwrap() < 4001,
        "a step after the E-stop: {:?}",
        ticks.last()
    );
    // The position is kept (the machine state and the alarm checkpoint agree with the log).
    let end = last["end_steps"].clone();
    assert_eq!(
        machine(&stopped)["position_machine_mm"][0],
        end[0].as_f64().unwrap() / 1000.0
    );
    assert_eq!(stopped["checkpoint"]["position_steps"], end);
    // Nothing moves: run, MDI, jog, resume are refused until reset.
    for args in [
        &["run", "line.nc"][..],
        &["mdi", "G1 X0"],
        &["jog", "X", "-1"],
        &["resume"],
    ] {
        let (reply, code) = daemon.ctl(args);
        assert_eq!(code, 1, "{args:?}: {reply}");
        assert!(
            reply["error"].as_str().unwrap().contains("E-stop"),
            "{args:?}: {reply}"
        );
    }
    daemon.ok(&["reset"]);
    assert_eq!(daemon.status()["state"], "idle");
    // After the reset the job resumes from its checkpoint (a new script: no E-stop).
    std::fs::write(dir.join("gap.txt"), "0 normal\n").unwrap();
    daemon.ok(&["resume"]);
    let done = daemon.wait_for("the end", |s| {
        s["state"] == "idle" && s["last_job"]["outcome"] == "done"
    });
    assert_eq!(floats(&machine(&done)["position_machine_mm"]), [3.0, 1.0]);
}

#[test]
fn a_limit_switch_stops_the_job_and_allows_only_the_jog_away() {
    let dir = scratch("limit");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    std::fs::write(dir.join("programs/line.nc"), "G21 G90\nG1 X3 F600\nM2\n").unwrap();
    std::fs::write(dir.join("gap.txt"), "0 normal\n3000 limit X+\n").unwrap();
    let daemon = Daemon::start(&dir, &common::daemon::script_sets(&dir, "pulses.csv"), &[]);
    daemon.ok(&["run", "line.nc"]);
    let stopped = daemon.wait_for("the limit", |s| s["state"] == "limit");
    let last = &stopped["last_job"];
    assert_eq!(last["outcome"], "limit", "{last}");
    assert_eq!(last["limit_switch"], "X+");
    assert!(
        last["error"]
            .as_str()
            .unwrap()
            .contains("limit switch X+ (upper end of axis X)"),
        "{last}"
    );
    assert!(*stepping_ticks(&dir.join("pulses.csv")).last().unwrap() < 3000);
    for args in [
        &["run", "line.nc"][..],
        &["jog", "X", "0.5"],
        &["jog", "Y", "0.5"],
    ] {
        let (reply, code) = daemon.ctl(args);
        assert_eq!(code, 1, "{args:?}: {reply}");
        assert!(
            reply["error"].as_str().unwrap().contains("limit switch X+"),
            "{reply}"
        );
    }
    // The jog away (a new script: the switch released) is allowed and clears the alarm.
    std::fs::write(dir.join("gap.txt"), "0 normal\n").unwrap();
    daemon.ok(&["jog", "X", "-0.5"]);
    daemon.wait_for("idle", |s| s["state"] == "idle");
    daemon.ok(&["jog", "Y", "0.5"]);
    daemon.wait_for("idle", |s| s["state"] == "idle");
}

#[test]
fn the_simulator_raises_an_estop_and_edmd_run_stops_in_that_tick() {
    let dir = scratch("sim-estop");
    std::fs::write(dir.join("events.txt"), "30000 estop\n").unwrap();
    let (code, text) = edmd(
        &dir,
        &[
            "run",
            common::repo()
                .join("programs/huang-table1-g38.nc")
                .to_str()
                .unwrap(),
            "--set",
            "sim.events=\"events.txt\"",
            "--set",
            "output.kind=\"file\"",
            "--set",
            "output.path=\"pulses.csv\"",
            "--summary",
            "summary.json",
        ],
    );
    assert_eq!(code, 1, "{text}");
    assert!(
        text.contains("E-stop: motion stopped in the tick it was seen"),
        "{text}"
    );
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["outcome"], "estop");
    assert_eq!(summary["ticks"], 30000, "stopped in the tick it was seen");
    assert!(*stepping_ticks(&dir.join("pulses.csv")).last().unwrap() < 30000);
}
