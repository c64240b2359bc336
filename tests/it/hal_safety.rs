//! The machine is off when edmd is not there (issue [1/7] of round five), against the real
//! HAL of Debian's `linuxcnc-uspace` on the shipped `config/hal/sim.hal` (its `watchdog`,
//! `and2` gates and `charge_pump`):
//!
//! - an E-stop while idle drops `enable-out` (and the gated drives' enable) within a few
//!   milliseconds, and it stays off after the reset until the next motion;
//! - an E-stop pulse of 50 ms while idle is latched: a run sent right after it is refused and
//!   nothing moves;
//! - a continuous jog whose client keeps renewing through an E-stop does not start again by
//!   itself on `reset`, only after the client lets go and presses again;
//! - HAL's threads stopped (`halcmd stop`): edmd notices by `rt-beat-in` and holds the
//!   machine as in an E-stop;
//! - SIGKILL: the watchdog drops the drives' enable and the spark within its timeout;
//! - edmd loaded again into the live HAL takes the dead one's name back, starts `pos-cmd`
//!   where the drives stand (stepgen's counts do not move), distrusts the position, and a
//!   jog moves on from there;
//! - a NaN on `pos-fb` is a following error, not a pass;
//! - as the service runs it (`loadusr -w edmd hal-wait` as the file's last line), a `ctl` on
//!   the line after `loadusr -W` finds the socket, and a SIGKILL makes `halrun` exit with a
//!   failure, HAL unloaded.
//!
//! Skipped (said on stderr) unless `EDMD_HAL_TESTS` is set; the benches take turns.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::common;
use common::hal::HalBench;
use serde_json::Value;

const SQUARE: &str = "G21 G90\nG1 X2 Y0 F300\nG1 X2 Y1.5\nG1 X0.5 Y1.5\nM2\n";
const PLUS: &str = "G21 G91\nG1 X3 F120\nM2\n";
const LONG: &str = "G21 G90\nG1 X8.5 Y1.5 F120\nM2\n";
const FERROR_OFF: (&str, &str) = (
    "max_following_error_mm = 0.5",
    "max_following_error_mm = 0.0",
);

/// stepgen's counts, once they stand still.
fn counts(bench: &HalBench) -> Vec<i64> {
    let read = || {
        vec![
            bench.getp("stepgen.0.counts").parse::<i64>().unwrap(),
            bench.getp("stepgen.1.counts").parse::<i64>().unwrap(),
        ]
    };
    let mut last = read();
    let deadline = Instant::now() + Duration::from_secs(5);
    loop {
        std::thread::sleep(Duration::from_millis(30));
        let now = read();
        if now == last || Instant::now() > deadline {
            return now;
        }
        last = now;
    }
}

fn run_to_end(bench: &HalBench, program: &str) -> Value {
    bench.daemon().ok(&["run", program]);
    bench.daemon().wait_for("the job's end", |s| {
        s["state"] == "idle"
            && s["last_job"]["program"]
                .as_str()
                .is_some_and(|p| p.ends_with(program))
    })["last_job"]
        .clone()
}

/// One continuous-jog request on the socket: its reply.
fn jog_request(bench: &HalBench) -> Value {
    jog_on(&bench.dir.join("edmd.sock"))
}

/// One continuous-jog request on the daemon's socket at `socket`: its reply.
fn jog_on(socket: &std::path::Path) -> Value {
    let reply = common::daemon::raw_exchange(
        socket,
        &[r#"{"cmd":"jog-continuous","axis":"X","positive":true,"feed_mm_per_min":60}"#],
    );
    reply[0].clone()
}

/// One continuous-jog request on the socket; whether it was taken.
fn jog_plus(bench: &HalBench) -> bool {
    jog_request(bench)["ok"] == true
}

/// Holds the jog button: renews the continuous jog every 100 ms (well inside its 250 ms
/// dead-man, however long the check and the status take on a loaded machine) until the
/// daemon says it is jogging, then for `then` more; whether every renewal was taken.
fn press_until_jogging(bench: &HalBench, then: Duration) -> bool {
    let until = Instant::now() + Duration::from_secs(30);
    while bench.daemon().status()["state"] != "jogging" {
        if !jog_plus(bench) || Instant::now() > until {
            return false;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let until = Instant::now() + then;
    while Instant::now() < until {
        if !jog_plus(bench) {
            return false;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    true
}

#[test]
fn the_drives_follow_the_machine_between_jobs_and_edmd_s_life() {
    if !common::hal::enabled("hal_safety") {
        return;
    }
    let bench = HalBench::start(
        "safety",
        &[FERROR_OFF],
        &[("square.ngc", SQUARE), ("plus.ngc", PLUS)],
    );
    let log = |b: &HalBench| b.log();

    // Enabled by a job, as LinuxCNC's machine is on after a move.
    assert_eq!(run_to_end(&bench, "square.ngc")["outcome"], "done");
    assert_eq!(bench.getp("edmd.enable-out"), "TRUE");
    assert_eq!(bench.getp("drives-ok.out"), "TRUE", "the gate passes it");
    assert_eq!(counts(&bench), [500, 1500]);

    // An E-stop while idle: the fine thread drops the enable within its idle poll.
    bench.setp("edmd.estop-ok-in", "false");
    let took = bench.wait_pin("edmd.enable-out", "FALSE", Duration::from_millis(500));
    eprintln!("hal_safety: enable-out off {took:?} after an idle E-stop");
    bench.wait_pin("drives-ok.out", "FALSE", Duration::from_millis(100));
    bench
        .daemon()
        .wait_for("the idle E-stop", |s| s["state"] == "estop");
    bench.setp("edmd.estop-ok-in", "true");
    bench.daemon().ok(&["reset"]);
    assert_eq!(
        bench.getp("edmd.enable-out"),
        "FALSE",
        "off after the reset too, until something moves"
    );

    // A pulse of 50 ms while idle, then at once a run: refused, nothing moves.
    bench.setp("edmd.estop-ok-in", "false");
    std::thread::sleep(Duration::from_millis(50));
    bench.setp("edmd.estop-ok-in", "true");
    bench.daemon().refused(&["run", "plus.ngc"], "E-stop");
    assert_eq!(counts(&bench), [500, 1500], "nothing moved");
    bench.daemon().ok(&["reset"]);

    // A continuous jog renewed through an E-stop does not start again by itself on reset.
    bench.daemon().wait_for("idle", |s| s["state"] == "idle");
    let first = jog_request(&bench);
    assert_eq!(first["ok"], true, "the jog starts: {first}");
    assert!(
        press_until_jogging(&bench, Duration::from_millis(150)),
        "{}",
        log(&bench)
    );
    // The client goes on pressing every 100 ms from a thread of its own, through the trip,
    // the reset and after, as a held button does: the test's own steps (a `halcmd`, an
    // `edmd ctl`) take as long as a loaded machine makes them without a gap in the presses
    // that would read as the button let go. A press sent once the E-stop is seen is refused,
    // before the reset and after it.
    let socket = bench.dir.join("edmd.sock");
    let tripped = AtomicBool::new(false);
    let held = AtomicBool::new(true);
    let (taken, stopped) = std::thread::scope(|scope| {
        let presser = scope.spawn(|| {
            let mut taken = 0;
            while held.load(Ordering::SeqCst) {
                let after_trip = tripped.load(Ordering::SeqCst);
                if jog_on(&socket)["ok"] == true && after_trip {
                    taken += 1;
                }
                std::thread::sleep(Duration::from_millis(100));
            }
            taken
        });
        bench.setp("edmd.estop-ok-in", "false");
        bench
            .daemon()
            .wait_for("the E-stop", |s| s["state"] == "estop");
        tripped.store(true, Ordering::SeqCst);
        std::thread::sleep(Duration::from_millis(400));
        bench.setp("edmd.estop-ok-in", "true");
        bench.daemon().ok(&["reset"]);
        let stopped = counts(&bench);
        std::thread::sleep(Duration::from_millis(800));
        held.store(false, Ordering::SeqCst);
        (presser.join().unwrap(), stopped)
    });
    assert_eq!(
        taken, 0,
        "the client still pressing is refused: presses taken after the trip"
    );
    assert_eq!(counts(&bench), stopped, "nothing moved after the reset");
    // Let go, press again: a new jog.
    std::thread::sleep(Duration::from_millis(400));
    assert!(
        press_until_jogging(&bench, Duration::from_millis(200)),
        "{}",
        log(&bench)
    );
    let stopped_jog =
        common::daemon::raw_exchange(&bench.dir.join("edmd.sock"), &[r#"{"cmd":"jog-stop"}"#]);
    assert_eq!(stopped_jog[0]["ok"], true, "{stopped_jog:?}");
    bench.daemon().wait_for("idle", |s| s["state"] == "idle");
    let here = counts(&bench);
    assert!(here[0] > stopped[0], "{here:?} after {stopped:?}");

    // HAL's threads stop: the charge pump stands still, edmd holds the machine.
    bench.halcmd(&["stop"]);
    let s = bench
        .daemon()
        .wait_for("HAL's threads stopped", |s| s["state"] == "estop");
    assert_eq!(bench.getp("edmd.enable-out"), "FALSE", "{s}");
    bench.daemon().wait_for_log("real-time side stopped");
    bench.halcmd(&["start"]);
    std::thread::sleep(Duration::from_millis(50));
    bench.daemon().ok(&["reset"]);

    // Enabled again, then edmd killed: the watchdog (0.5 s) takes the enable and the spark.
    bench.daemon().ok(&["jog", "X", "0.01"]);
    bench
        .daemon()
        .wait_for("the jog's end", |s| s["state"] == "idle");
    assert_eq!(bench.getp("drives-ok.out"), "TRUE");
    let before = counts(&bench);
    let pid = bench.edmd_pid();
    // SAFETY: kill(2) on the bench's own edmd.
    assert_eq!(unsafe { libc::kill(pid as i32, libc::SIGKILL) }, 0);
    let took = bench.wait_pin("drives-ok.out", "FALSE", Duration::from_secs(2));
    eprintln!("hal_safety: drives off {took:?} after SIGKILL (watchdog timeout 0.5 s)");
    assert_eq!(bench.getp("watchdog.ok-out"), "FALSE");
    assert_eq!(bench.getp("spark-ok.out"), "FALSE");
    assert!(
        bench
            .halcmd_output(&["show", "comp", "edmd"])
            .unwrap()
            .contains("edmd"),
        "the dead component stays in HAL"
    );

    // Started as it is, a new edmd refuses the dead one's name and says how to free it.
    let (code, said) = bench.serve_directly();
    assert_eq!(code, Some(1), "{said}");
    assert!(said.contains("edmd hal-reap"), "{said}");

    // Loaded again into the live HAL as its file does it (hal-reap, then loadusr -W): the
    // name is free again, pos-cmd takes up where the drives stand, nothing moves, the
    // position is distrusted.
    bench.load_edmd_again();
    let sim = std::fs::read_to_string(common::repo().join("config/hal/sim.hal")).unwrap();
    for line in sim.lines().filter(|l| l.starts_with("net ")) {
        let words: Vec<&str> = line.split_whitespace().collect();
        let ours: Vec<&str> = words[2..]
            .iter()
            .copied()
            .filter(|w| w.starts_with("edmd."))
            .collect();
        if !ours.is_empty() {
            let mut args = vec!["net", words[1]];
            args.extend(ours);
            bench.halcmd(&args);
        }
    }
    bench.setp("edmd.estop-ok-in", "true");
    bench.setp("watchdog.enable-in", "false");
    std::thread::sleep(Duration::from_millis(20));
    bench.setp("watchdog.enable-in", "true");
    assert_eq!(counts(&bench), before, "stepgen did not move");
    let s = bench.daemon().status();
    assert_eq!(s["machine"]["position_trusted"], false, "{s}");
    assert!(
        log(&bench).contains("which did not stop, removed from HAL"),
        "the dead component was removed: {}",
        log(&bench)
    );
    if s["state"] == "estop" {
        bench.daemon().ok(&["reset"]);
    }
    bench.daemon().ok(&["jog", "X", "0.01"]);
    bench
        .daemon()
        .wait_for("the jog's end", |s| s["state"] == "idle");
    assert_eq!(
        counts(&bench),
        [before[0] + 10, before[1]],
        "pos-cmd {}, drives {}, watchdog {}",
        bench.getp("edmd.axis.x.pos-cmd"),
        bench.getp("drives-ok.out"),
        bench.getp("watchdog.ok-out")
    );
}

#[test]
fn a_feedback_that_is_not_a_number_is_a_following_error() {
    if !common::hal::enabled("hal_safety") {
        return;
    }
    let bench = HalBench::start("nan", &[], &[("long.ngc", LONG)]);
    bench.daemon().ok(&["run", "long.ngc"]);
    bench.daemon().wait_for("moving", |s| {
        s["state"] == "running"
            && s["job"]["pulses"]
                .as_array()
                .is_some_and(|p| p.iter().filter_map(Value::as_u64).sum::<u64>() > 100)
    });
    bench.halcmd(&["unlinkp", "edmd.axis.x.pos-fb"]);
    bench.setp("edmd.axis.x.pos-fb", "nan");
    let job = bench
        .daemon()
        .wait_for("the following error", |s| s["state"] != "running")["last_job"]
        .clone();
    assert_eq!(job["outcome"], "output-error", "{job}\n{}", bench.log());
    assert!(
        job["error"]
            .as_str()
            .unwrap_or_default()
            .contains("following error on X"),
        "{job}"
    );
    assert_eq!(bench.getp("edmd.enable-out"), "FALSE");
}

#[test]
fn as_a_service_the_socket_listens_when_hal_continues_and_a_kill_fails_the_service() {
    if !common::hal::enabled("hal_safety") {
        return;
    }
    // The bench's HAL file runs `edmd ctl status` on the line after `loadusr -W`: the bench
    // is up only if it found the socket listening.
    let mut service = HalBench::start_service("kill", &[FERROR_OFF], &[("long.ngc", LONG)]);
    assert!(service.log().contains("state:"), "{}", service.log());
    service.daemon().ok(&["run", "long.ngc"]);
    service
        .daemon()
        .wait_for("moving", |s| s["state"] == "running");
    let pid = service.edmd_pid();
    // SAFETY: kill(2) on the bench's own edmd.
    assert_eq!(unsafe { libc::kill(pid as i32, libc::SIGKILL) }, 0);
    let code = service.wait_halrun(Duration::from_secs(20));
    let log = service.log();
    assert!(
        code.is_some_and(|c| c != 0),
        "halrun ends with a failure: {code:?}\n{log}"
    );
    assert!(log.contains("ended without a clean stop"), "{log}");
    assert!(log.contains("removed from HAL"), "{log}");
}

#[test]
fn without_hal_running_edmd_makes_no_component_and_says_how_to_start() {
    if !common::hal::enabled("hal_safety") {
        return;
    }
    // No bench is up while this turn is held: no rtapi_app runs.
    let _turn = common::hal::turn();
    let dir = common::scratch("hal", "not-running");
    let mut sets = common::daemon::base_sets(&dir, "p.csv");
    sets.extend([
        "output.kind=\"hal\"".to_string(),
        // HAL's drives take each step at its own tick.
        "fine.ticks_per_wake=1".to_string(),
        "gap.kind=\"none\"".to_string(),
        "homing.required=false".to_string(),
    ]);
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_edmd"));
    cmd.arg("serve")
        .current_dir(&dir)
        .env_remove("NOTIFY_SOCKET");
    for s in &sets {
        cmd.args(["--set", s]);
    }
    let out = cmd.output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("HAL is not running"), "{err}");
    assert!(!err.contains("component edmd ready"), "{err}");
    assert!(!dir.join("edmd.sock").exists(), "nothing listens");
}
