//! Trust, round four (issue [1/8]): the real `edmd serve`, driven by the real `edmd ctl` and
//! raw socket clients, where the adversarial pass found it wanting: a plain resume after a
//! kill mid-jog or mid-MDI, a SIGHUP that reads a FIFO while a continuous jog's client is
//! gone, a limit switch that stays closed (and a restart), a hold during a continuous jog,
//! absurd feeds, an abort during homing, a touch-off in a trip.

use crate::common;

use std::path::Path;
use std::time::{Duration, Instant};

use common::daemon::*;
use serde_json::Value;

fn machine(status: &Value) -> &Value {
    &status["machine"]
}

fn x_mm(status: &Value) -> f64 {
    machine(status)["position_machine_mm"][0].as_f64().unwrap()
}

fn state_file(dir: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("machine-state.json")).unwrap()).unwrap()
}

/// A cut held and aborted (a standstill checkpoint remains), then `what` started and the
/// daemon killed while it moves: after a restart a plain `resume` is refused (the position
/// is only believed), saying why and how out; `--force` is the operator's word that it was
/// checked, and homing gives the trust back.
fn kill_mid_motion_then_resume(name: &str, what: &[&str]) {
    let dir = scratch(name);
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    std::fs::write(dir.join("programs/contour.ngc"), CONTOUR).unwrap();
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.push("machine.max_jog_feed_mm_per_min=300.0".to_string());
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["home", "--here"]);
    daemon.ok(&["run", "contour.ngc"]);
    daemon.wait_for("cutting", |s| position(s)[0] > 2000);
    daemon.ok(&["hold"]);
    daemon.wait_for("held", |s| s["state"] == "held");
    daemon.ok(&["abort"]);
    daemon.wait_for("idle", |s| s["state"] == "idle");
    daemon.ok(what);
    daemon.wait_for("moving by hand", |s| {
        s["state"] != "idle" && s["state"] != "checking" && s["job"].is_object()
    });
    std::thread::sleep(Duration::from_millis(200));
    daemon.signal(libc::SIGKILL);
    let _ = daemon.wait();
    assert_eq!(state_file(&dir)["moving"], true, "killed while moving");

    let daemon = Daemon::start(&dir, &sets, &[]);
    let refused = daemon.refused(&["resume"], "the position is not trusted");
    let why = refused["error"].as_str().unwrap();
    assert!(
        why.contains("home every axis") && why.contains("--force"),
        "says how out: {why}"
    );
    assert_eq!(daemon.status()["state"], "idle", "nothing started");
    assert_eq!(state_file(&dir)["position_trusted"], false);
    // A run from a line is the same cut from a believed place.
    daemon.refused(
        &["run", "contour.ngc", "--from-line", "4"],
        "the position is not trusted",
    );
    // After a second restart the distrust is still there (the file keeps it).
    daemon.signal(libc::SIGTERM);
    let _ = daemon.wait();
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.refused(&["resume"], "the position is not trusted");
    // Homing gives the trust back; the machine is not where the checkpoint stopped, which
    // the resume then says.
    daemon.ok(&["home", "--here"]);
    assert_eq!(state_file(&dir)["position_trusted"], true);
    daemon.refused(&["resume"], "move back there");
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
}

#[test]
fn a_plain_resume_after_a_kill_mid_jog_is_refused() {
    kill_mid_motion_then_resume("kill-mid-jog", &["jog", "Y", "20"]);
}

#[test]
fn a_plain_resume_after_a_kill_mid_mdi_is_refused() {
    kill_mid_motion_then_resume("kill-mid-mdi", &["mdi", "G91 G1 Y20 F300"]);
}

/// With the position distrusted, `resume --force` is accepted (and logged): the operator
/// checked the machine stands where the checkpoint says.
#[test]
fn resume_force_is_the_operators_word() {
    let dir = scratch("force-distrusted");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    std::fs::write(dir.join("programs/contour.ngc"), CONTOUR).unwrap();
    let sets = base_sets(&dir, "pulses.csv");
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["home", "--here"]);
    daemon.ok(&["run", "contour.ngc"]);
    daemon.wait_for("cutting", |s| position(s)[0] > 2000);
    // Killed while cutting: the state file says moving, the checkpoint is a moving one.
    daemon.signal(libc::SIGKILL);
    let _ = daemon.wait();
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.refused(&["resume"], "the position is not trusted");
    daemon.ok(&["resume", "--force"]);
    let done = daemon.wait_for("the end", |s| {
        s["state"] == "idle" && s["last_job"]["outcome"] == "done"
    });
    assert_eq!(
        floats(&machine(&done)["position_machine_mm"]),
        CONTOUR_END.map(|s| s as f64 / 1000.0).to_vec()
    );
    let log = daemon.log();
    assert!(
        log.contains("resume: the position is not trusted") && log.contains("(forced: "),
        "{log}"
    );
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
}

/// The configuration path becomes a FIFO nobody writes, SIGHUP, and the continuous jog's
/// client vanishes: status still answers within 0.5 s, and the jog stops within its
/// dead-man time.
#[test]
fn a_fifo_config_and_a_vanished_jog_client_freeze_nothing() {
    let dir = scratch("fifo-sighup");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    let config = dir.join("edmd.toml");
    let _ = std::fs::remove_file(&config);
    std::fs::write(&config, "").unwrap();
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.push("machine.max_jog_feed_mm_per_min=600.0".to_string());
    let daemon = Daemon::start_args(
        &dir,
        &["--config".to_string(), config.display().to_string()],
        &sets,
        &[],
    );
    let request = r#"{"cmd":"jog-continuous","axis":"X","positive":true}"#;
    let mut last = Instant::now();
    for _ in 0..5 {
        let reply = &raw_exchange(&daemon.socket, &[request])[0];
        assert_eq!(reply["ok"], true, "{reply}");
        last = Instant::now();
        std::thread::sleep(Duration::from_millis(100));
    }
    // The file becomes a FIFO, then the reload: the client is gone from here on.
    std::fs::remove_file(&config).unwrap();
    let c = std::ffi::CString::new(config.display().to_string()).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    daemon.signal(libc::SIGHUP);
    let mut position = x_mm(&daemon.status());
    let mut halted_at = Instant::now();
    while Instant::now() < last + Duration::from_millis(1500) {
        let asked = Instant::now();
        let status = daemon.status();
        let took = asked.elapsed();
        assert!(took < Duration::from_millis(500), "status took {took:?}");
        let p = x_mm(&status);
        if p != position {
            position = p;
            halted_at = Instant::now();
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    // The dead-man's 250 ms, then the braking; a loaded machine's scheduling on top.
    let after = halted_at.saturating_duration_since(last);
    assert!(
        after <= Duration::from_millis(400),
        "halted {after:?} after the last renewal"
    );
    daemon.wait_for_log("reload refused, configuration unchanged");
    assert!(
        daemon.log().contains("a FIFO, not a regular file"),
        "{}",
        daemon.log()
    );
    let _ = std::fs::remove_file(&config);
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
}

/// A hold ends a continuous jog, and the client's renewals after it move nothing; once the
/// client lets go (no request for longer than the dead-man), a new press starts a new jog.
#[test]
fn a_hold_ends_a_continuous_jog_and_renewals_move_nothing() {
    let dir = scratch("hold-jog");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.push("machine.max_jog_feed_mm_per_min=600.0".to_string());
    let daemon = Daemon::start(&dir, &sets, &[]);
    let request = r#"{"cmd":"jog-continuous","axis":"X","positive":true}"#;
    for _ in 0..4 {
        raw_exchange(&daemon.socket, &[request]);
        std::thread::sleep(Duration::from_millis(100));
    }
    assert_eq!(daemon.status()["state"], "jogging");
    let held = &raw_exchange(&daemon.socket, &[r#"{"cmd":"hold"}"#])[0];
    assert!(
        held["message"].as_str().unwrap().contains("continuous jog"),
        "{held}"
    );
    // The client did not see the hold: it renews on, every 50 ms (the page's 100 ms, with
    // room for a loaded machine), for a second.
    for _ in 0..20 {
        let reply = &raw_exchange(&daemon.socket, &[request])[0];
        assert_eq!(reply["ok"], false, "{reply}");
        assert!(
            reply["error"]
                .as_str()
                .unwrap()
                .contains("renewals are refused"),
            "{reply}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let stopped = daemon.wait_for("idle", |s| s["state"] == "idle");
    let at = x_mm(&stopped);
    assert_eq!(
        stopped["last_job"]["outcome"], "stopped",
        "the jog ended at the hold: {stopped}"
    );
    std::thread::sleep(Duration::from_millis(100));
    assert_eq!(x_mm(&daemon.status()), at, "no motion after the hold");
    // The same after the dead-man: silence, then the stale renewals.
    std::thread::sleep(Duration::from_millis(400));
    let reply = &raw_exchange(&daemon.socket, &[request])[0];
    assert_eq!(reply["ok"], true, "a new press after letting go: {reply}");
    // A renewal that comes late (300 ms: past the dead-man), then renewals on time: the
    // stale client moves nothing.
    std::thread::sleep(Duration::from_millis(300));
    for _ in 0..3 {
        let reply = &raw_exchange(&daemon.socket, &[request])[0];
        assert_eq!(reply["ok"], false, "{reply}");
        std::thread::sleep(Duration::from_millis(100));
    }
    let stopped = daemon.wait_for("the dead-man", |s| s["state"] == "idle");
    let at = x_mm(&stopped);
    std::thread::sleep(Duration::from_millis(200));
    assert_eq!(x_mm(&daemon.status()), at, "no motion after the dead-man");
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
}

/// A limit switch that stays closed where the axis stopped: the jog away moves, the jog
/// towards is refused, and a restart remembers the trip; once the switch reads open the
/// trip is gone.
#[test]
fn a_limit_switch_that_stays_closed_can_be_left_and_is_not_forgotten() {
    let dir = scratch("limit-stays");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    std::fs::write(dir.join("programs/line.nc"), "G21 G90\nG1 X3 F600\nM2\n").unwrap();
    // Closed at tick 3000 of the run, and at the start of every job after.
    std::fs::write(dir.join("gap.txt"), "0 normal\n3000 limit X+\n").unwrap();
    let sets = script_sets(&dir, "pulses.csv");
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["run", "line.nc"]);
    let stopped = daemon.wait_for("the limit", |s| s["state"] == "limit");
    assert_eq!(stopped["last_job"]["limit_switch"], "X+");
    assert_eq!(state_file(&dir)["tripped"], "X+");
    let at = x_mm(&stopped);
    std::fs::write(dir.join("gap.txt"), "0 limit X+\n").unwrap();
    daemon.refused(&["jog", "X", "0.2"], "limit switch X+");
    // Away: it moves, although the switch reads closed all the way.
    daemon.ok(&["jog", "X", "-0.5"]);
    let away = daemon.wait_for("the jog's end", |s| {
        s["state"] != "jogging" && s["last_job"]["outcome"] == "done"
    });
    assert!((x_mm(&away) - (at - 0.5)).abs() < 1e-9, "{away}");
    assert_eq!(away["state"], "limit", "still closed: still tripped");
    daemon.refused(&["jog", "X", "0.2"], "limit switch X+");
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);

    // A restart does not forget it.
    let daemon = Daemon::start(&dir, &sets, &[]);
    assert_eq!(daemon.status()["state"], "limit");
    daemon.refused(&["jog", "X", "0.2"], "limit switch X+");
    daemon.refused(&["run", "line.nc"], "limit switch X+");
    // Far enough away, the switch opens: the jog that left it clears the trip.
    std::fs::write(dir.join("gap.txt"), "0 limit X+\n100 release X+\n").unwrap();
    daemon.ok(&["jog", "X", "-0.5"]);
    let clear = daemon.wait_for("cleared", |s| s["state"] == "idle");
    assert_eq!(clear["last_job"]["outcome"], "done");
    assert!(state_file(&dir).get("tripped").is_none());
    std::fs::write(dir.join("gap.txt"), "0 normal\n").unwrap();
    daemon.ok(&["jog", "X", "0.1"]);
    daemon.wait_for("idle", |s| s["state"] == "idle");
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
}

/// A jog towards a closed switch that the daemon did not know of (a job's first reading)
/// stops in its first tick, without a step into the switch.
#[test]
fn a_job_starting_on_a_closed_switch_takes_no_step_into_it() {
    let dir = scratch("limit-into");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    std::fs::write(dir.join("gap.txt"), "0 limit X+\n").unwrap();
    let daemon = Daemon::start(&dir, &script_sets(&dir, "pulses.csv"), &[]);
    daemon.ok(&["jog", "X", "0.5"]);
    let stopped = daemon.wait_for("the limit", |s| s["state"] == "limit");
    assert_eq!(stopped["last_job"]["outcome"], "limit");
    assert_eq!(x_mm(&stopped), 0.0, "no step into the switch");
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
}

/// Feeds and distances below the minimum are refused, naming the bound.
#[test]
fn absurd_feeds_and_distances_are_refused_with_the_bound() {
    let dir = scratch("minima");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    let daemon = Daemon::start(&dir, &base_sets(&dir, "pulses.csv"), &[]);
    daemon.refused(
        &["jog", "X", "1", "--feed", "1e-300"],
        "at least 0.001 mm/min",
    );
    daemon.refused(&["jog", "X", "1e-300"], "at least one step (0.001 mm on X)");
    let reply = daemon.refused(&["mdi", "G1 X1 F0.0000001"], "at least 0.001 mm/min");
    assert!(
        reply["error"].as_str().unwrap().contains("mdi:1:"),
        "{reply}"
    );
    let request = r#"{"cmd":"jog-continuous","axis":"X","positive":true,"feed_mm_per_min":1e-300}"#;
    let reply = &raw_exchange(&daemon.socket, &[request])[0];
    assert_eq!(reply["ok"], false, "{reply}");
    assert_eq!(daemon.status()["state"], "idle");
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
    // The configuration's feeds too.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_edmd"))
        .args(["check", "--set", "machine.max_jog_feed_mm_per_min=0.000001"])
        .arg(common::repo().join("tests/data/runtime-path.nc"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("machine.max_jog_feed_mm_per_min") && stderr.contains("at least 0.001"),
        "{stderr}"
    );
}

/// An abort at any moment of a homing sequence cancels the whole sequence: the later axis
/// never moves.
#[test]
fn an_abort_during_homing_cancels_the_sequence() {
    let dir = scratch("abort-homing");
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.retain(|s| !s.starts_with("gap.kind") && !s.starts_with("homing.axis"));
    sets.push("gap.kind=\"sim\"".to_string());
    sets.push(
        "homing.axis=[\
         {axis=\"Y\", direction=\"-\", search_feed_mm_per_min=600.0, latch_feed_mm_per_min=60.0, \
          home_position_mm=-5.0, final_move_mm=0.5, sequence=0, search_distance_mm=20.0, \
          latch_distance_mm=0.5},\
         {axis=\"X\", direction=\"+\", search_feed_mm_per_min=600.0, latch_feed_mm_per_min=60.0, \
          home_position_mm=10.0, final_move_mm=-1.0, sequence=1, search_distance_mm=20.0, \
          latch_distance_mm=0.5}]"
            .to_string(),
    );
    sets.push("sim.home_switch_mm={X=3.0,Y=-2.0}".to_string());
    let mut aborted = 0;
    for delay_ms in (0..).step_by(50).take_while(|&d| d <= 600) {
        let _ = std::fs::remove_file(dir.join("machine-state.json"));
        let daemon = Daemon::start(&dir, &sets, &[]);
        daemon.ok(&["home"]);
        std::thread::sleep(Duration::from_millis(delay_ms));
        let (reply, _) = daemon.ctl(&["abort"]);
        if reply["ok"] == true {
            aborted += 1;
        }
        // Whatever the abort hit (Y's search, back-off, latch or final move, the check of
        // X, X's search), once idle nothing moves again, and no axis's search starts after
        // the abort.
        let idle = daemon.wait_for("idle", |s| s["state"] == "idle");
        std::thread::sleep(Duration::from_millis(300));
        let status = daemon.status();
        assert_eq!(status["state"], "idle", "{delay_ms} ms: {status}");
        assert_eq!(
            machine(&status)["position_machine_mm"],
            machine(&idle)["position_machine_mm"],
            "{delay_ms} ms: moved after the abort"
        );
        if reply["ok"] == true {
            let log = daemon.log();
            let abort = log.find("abort:").expect("the abort is logged");
            assert!(
                !log[abort..].contains(": searching"),
                "{delay_ms} ms: a search started after the abort:\n{log}"
            );
        }
        daemon.signal(libc::SIGTERM);
        assert_eq!(daemon.wait().0, 0);
    }
    assert!(aborted >= 5, "the aborts hit the sequence {aborted} times");
}

/// A touch-off is refused while an E-stop or a limit holds the machine, and an offset is
/// held to the axis's travel.
#[test]
fn touch_off_is_refused_in_a_trip_and_held_to_the_travel() {
    let dir = scratch("touch-off-trip");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    std::fs::write(dir.join("programs/line.nc"), "G21 G90\nG1 X3 F600\nM2\n").unwrap();
    std::fs::write(dir.join("gap.txt"), "0 normal\n3000 estop\n").unwrap();
    let mut sets = script_sets(&dir, "pulses.csv");
    sets.push("machine.travel_mm={X=[-1.0,100.0],Y=[-1.0,50.0]}".to_string());
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.refused(&["touch-off", "X", "-200"], "outside the axis's travel");
    daemon.ok(&["run", "line.nc"]);
    daemon.wait_for("the E-stop", |s| s["state"] == "estop");
    daemon.refused(&["touch-off", "X", "0"], "E-stop");
    daemon.ok(&["reset"]);
    daemon.ok(&["touch-off", "X", "0"]);
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
}

/// Protocol noise a stranger can make does not fill the log: thirty malformed OPC UA
/// connections (each several ERROR lines of the OPC UA library) leave at most ten of them at
/// the default level.
#[test]
fn malformed_opcua_connections_are_held_to_a_noise_budget() {
    use std::io::Write;
    let dir = scratch("opcua-noise");
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.extend([
        format!("daemon.opcua=\"opc.tcp://127.0.0.1:{port}\""),
        format!(
            "daemon.opcua_users_file=\"{}\"",
            dir.join("opcua-users").display()
        ),
        format!("daemon.opcua_pki_dir=\"{}\"", dir.join("pki").display()),
    ]);
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.wait_for_log("opcua: the machine on");
    for _ in 0..30 {
        let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap();
        let _ = s.write_all(b"HELF\x10\x00\x00\x00garbage!");
        std::thread::sleep(Duration::from_millis(20));
    }
    // The library logs from its own tasks: on a loaded machine its lines come late, so wait
    // for the first (up to 10 s) and then a while for any more.
    let noise_of = |log: &str| {
        log.lines()
            .filter(|l| l.contains(" opcua_") && (l.contains("ERROR") || l.contains("WARN")))
            .count()
    };
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    while noise_of(&daemon.log()) == 0 && std::time::Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_millis(500));
    let log = daemon.log();
    let noise = noise_of(&log);
    assert!(
        (1..=10).contains(&noise),
        "{noise} lines of library noise:\n{log}"
    );
    assert_eq!(daemon.status()["state"], "idle");
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
}

/// `edmd run --state FILE --from-line N` on a state an unclean stop left (`moving: true`)
/// is refused: it would cut from a believed place.
#[test]
fn edmd_run_from_a_line_on_a_moving_state_is_refused() {
    let dir = scratch("run-state-moving");
    let program = dir.join("programs/contour.ngc");
    std::fs::write(&program, CONTOUR).unwrap();
    let state = dir.join("state.json");
    let _ = std::fs::remove_file(&state);
    let run = |extra: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_edmd"))
            .arg("run")
            .arg(&program)
            .arg("--state")
            .arg(&state)
            .args([
                "--set",
                "output.kind=\"null\"",
                "--set",
                "gap.kind=\"none\"",
            ])
            .args(extra)
            .output()
            .unwrap()
    };
    assert!(run(&[]).status.success());
    let mut file: Value = serde_json::from_str(&std::fs::read_to_string(&state).unwrap()).unwrap();
    file["moving"] = Value::Bool(true);
    std::fs::write(&state, serde_json::to_string(&file).unwrap()).unwrap();
    let out = run(&["--from-line", "4"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("the position is not trusted"), "{stderr}");
}
