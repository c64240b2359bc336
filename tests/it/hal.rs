//! LinuxCNC's HAL as the hardware layer (issue [3/8]), against the real HAL of Debian's
//! `linuxcnc-uspace`: `halrun` on the shipped `config/hal/sim.hal` loads `edmd serve` as a
//! userspace component beside two `stepgen`s in position mode (uspace threads, no hardware).
//! Through HAL's own tools (`halcmd getp`/`setp`/`unlinkp`):
//!
//! - a program cut through `stepgen` leaves its step counts on the program's end point, equal
//!   to edmd's ledger (`pos-cmd`) at the standstill;
//! - a short on `edmd.gap.short` turns back along the path and the job still ends exact;
//! - `edmd.estop-ok-in` false stops the job and drops `enable-out`, nothing moves after it,
//!   and `reset` takes the machine back once the input is released;
//! - a limit switch pin stops the job; only the jog away moves, and leaving it clears the trip;
//! - `pos-fb` unlinked mid-cut is a following error naming the axis;
//! - homing by a switch that HAL's `comp` makes from the X drive's feedback latches there;
//! - an E-stop while a program is being checked: the job does not start;
//! - a technology's passes set the generator's `edmd.gen.*` set-point pins to each pass's
//!   condition as it starts;
//! - run as `systemd/edmd-hal.service` runs it, the unit's `ExecStop` gives edmd its
//!   controlled stop and HAL unloads.
//!
//! HAL is one per machine: the benches take turns (`common::hal`). Skipped (said on stderr)
//! unless `EDMD_HAL_TESTS` is set. What keeps the machine off when edmd is not there:
//! `hal_safety.rs`.

use std::time::{Duration, Instant};

use crate::common;
use common::hal::HalBench;
use serde_json::Value;

const SQUARE: &str = "G21 G90\nG1 X2 Y0 F300\nG1 X2 Y1.5\nG1 X0.5 Y1.5\nM2\n";
/// 8 mm at 2 mm/s: long enough to act on in the middle.
const LONG: &str = "G21 G90\nG1 X8.5 Y1.5 F120\nM2\n";
const BACK: &str = "G21 G90\nG1 X0 Y0 F120\nM2\n";
/// 3 mm further in +X, from wherever the machine stands.
const PLUS: &str = "G21 G91\nG1 X3 F120\nM2\n";
const FERROR_OFF: (&str, &str) = (
    "max_following_error_mm = 0.5",
    "max_following_error_mm = 0.0",
);

fn ints(v: &Value) -> Vec<i64> {
    v.as_array()
        .unwrap_or_else(|| panic!("not an array: {v}"))
        .iter()
        .map(|x| x.as_i64().unwrap())
        .collect()
}

/// Runs `program` as the README does (`ctl run --wait-end`: back at the job's end); the
/// last job.
fn run_to_end(bench: &HalBench, program: &str) -> Value {
    let (reply, code) = bench.daemon().ctl(&["run", program, "--wait-end"]);
    let job = reply["status"]["last_job"].clone();
    assert!(
        job["program"]
            .as_str()
            .is_some_and(|p| p.ends_with(program)),
        "{reply}"
    );
    assert_eq!(code == 0, job["outcome"] == "done", "{reply}");
    job
}

/// Runs `program` and returns once it has moved 0.2 mm of its path.
fn start_and_move(bench: &HalBench, program: &str) {
    bench.daemon().ok(&["run", program]);
    bench.daemon().wait_for("moving", |s| {
        s["state"] == "running"
            && s["job"]["pulses"]
                .as_array()
                .is_some_and(|p| p.iter().filter_map(Value::as_u64).sum::<u64>() > 200)
    });
}

/// A die cut in the passes of its header's technology (the fast test table), in incremental
/// moves: it closes where the machine stands.
const TECH_DIE: &str = "(TECH material=testium height=30 wire=0.25)\nG21 G91 G17\n\
G41 D1 G1 X0 Y-2 F600\nG1 X2\nG1 Y4\nG1 X-4\nG1 Y-4\nG1 X2\nG40 G1 X0 Y2\nM2\n";

/// A program whose check takes a while (a million short moves, there and back).
fn big() -> String {
    let mut text = String::from("G21 G91\nG1 F100\n");
    for _ in 0..500_000 {
        text.push_str("X0.001\nX-0.001\n");
    }
    text + "M2\n"
}

/// Runs the technology die; the generator's (condition, on-time, servo reference) as the
/// set-point pins showed them, in order, each read whole (the on-time read on both sides
/// of the condition).
fn set_points_while_cutting(bench: &HalBench) -> Vec<(i64, f64, f64)> {
    bench.daemon().ok(&["run", "tech.ngc"]);
    let mut seen: Vec<(i64, f64, f64)> = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let on = bench.getp_f64("edmd.gen.on-time-us");
        let condition: i64 = bench.getp("edmd.condition").parse().unwrap();
        let servo = bench.getp_f64("edmd.gen.servo-ref-v");
        if on == bench.getp_f64("edmd.gen.on-time-us")
            && condition != 0
            && seen.last() != Some(&(condition, on, servo))
        {
            seen.push((condition, on, servo));
        }
        let s = bench.daemon().status();
        if s["state"] == "idle"
            && s["last_job"]["program"]
                .as_str()
                .is_some_and(|p| p.ends_with("tech.ngc"))
        {
            assert_eq!(s["last_job"]["outcome"], "done", "{s}");
            return seen;
        }
        assert!(Instant::now() < deadline, "the technology die: {s}");
    }
}

/// The step counts of both stepgens, once they have stood still for a few servo periods.
fn counts_at_rest(bench: &HalBench) -> Vec<i64> {
    let read = || {
        vec![
            bench.getp("stepgen.0.counts").parse::<i64>().unwrap(),
            bench.getp("stepgen.1.counts").parse::<i64>().unwrap(),
        ]
    };
    let deadline = Instant::now() + Duration::from_secs(5);
    let mut last = read();
    loop {
        std::thread::sleep(Duration::from_millis(20));
        let now = read();
        if now == last || Instant::now() > deadline {
            return now;
        }
        last = now;
    }
}

#[test]
fn edmd_drives_stepgen_through_hal_and_obeys_its_inputs() {
    if !common::hal::enabled("hal") {
        return;
    }
    // Without the following-error check: uspace threads on a loaded machine (the rest of the
    // suite runs beside this test) can stall HAL's servo thread for long enough that a
    // position-mode stepgen overshoots and comes back; the check gets a bench of its own.
    // The fast technology table beside the bench's configuration (technology.dir is
    // "technology", the configuration file's folder's).
    let tables = common::scratch("hal", "drive").join("config/hal/technology");
    std::fs::create_dir_all(&tables).unwrap();
    std::fs::write(tables.join("testium.toml"), crate::technology::FAST_TABLE).unwrap();
    let bench = HalBench::start(
        "drive",
        &[FERROR_OFF],
        &[
            ("square.ngc", SQUARE),
            ("long.ngc", LONG),
            ("back.ngc", BACK),
            ("plus.ngc", PLUS),
            ("tech.ngc", TECH_DIE),
            ("big.ngc", &big()),
        ],
    );
    let log = || bench.log();

    // A program through stepgen: its counts are the ledger, on the program's end point.
    let job = run_to_end(&bench, "square.ngc");
    assert_eq!(job["outcome"], "done", "{job}\n{}", log());
    assert_eq!(ints(&job["end_steps"]), [500, 1500]);
    assert_eq!(counts_at_rest(&bench), [500, 1500], "{}", log());
    assert!((bench.getp_f64("edmd.axis.x.pos-cmd") - 0.5).abs() < 1e-9);
    assert!((bench.getp_f64("edmd.axis.y.pos-cmd") - 1.5).abs() < 1e-9);
    // The machine stays on: the drives hold (and finish reaching) the last command.
    assert_eq!(bench.getp("edmd.enable-out"), "TRUE");
    assert_eq!(bench.getp("edmd.spark-on"), "FALSE");

    // A technology's three passes: the set-point pins follow each pass's condition (E51 on
    // 8 µs at 22 V, E52 3 µs at 30 V, E53 1 µs at 38 V), and keep the last one's after.
    let seen = set_points_while_cutting(&bench);
    assert_eq!(
        seen,
        [(51, 8.0, 22.0), (52, 3.0, 30.0), (53, 1.0, 38.0)],
        "{}",
        log()
    );
    assert_eq!(bench.getp_f64("edmd.gen.peak-current-a"), 1.0);
    assert_eq!(
        counts_at_rest(&bench),
        [500, 1500],
        "the die closes where it started"
    );

    // A short on the generator's pin: the electrode turns back along the path, then cuts on.
    // 3 mm in first: the turn-back retraces at 2 mm/s and may not run past the job's start
    // (the reserved history ends there: an alarm), and on a loaded machine the 60 ms short
    // lasts as long as the halcmd that ends it takes to start.
    start_and_move(&bench, "long.ngc");
    bench.daemon().wait_for("3 mm cut", |s| {
        s["job"]["pulses"][0].as_u64().is_some_and(|x| x > 3000)
    });
    bench.setp("edmd.gap.short", "true");
    std::thread::sleep(Duration::from_millis(60));
    bench.setp("edmd.gap.short", "false");
    let job = bench
        .daemon()
        .wait_for("the long job's end", |s| s["state"] == "idle")["last_job"]
        .clone();
    assert_eq!(job["outcome"], "done", "{job}\n{}", log());
    assert!(job["turn_backs"].as_u64().unwrap() >= 1, "{job}");
    assert!(job["events_backward"].as_u64().unwrap() > 0, "{job}");
    assert_eq!(ints(&job["end_steps"]), [8500, 1500]);
    assert_eq!(counts_at_rest(&bench), [8500, 1500], "{}", log());

    // The E-stop input: the job stops where it is, the drives go off, nothing moves after.
    start_and_move(&bench, "back.ngc");
    bench.setp("edmd.estop-ok-in", "false");
    assert_eq!(
        bench.getp("edmd.enable-out"),
        "FALSE",
        "enable-out drops at once"
    );
    let s = bench
        .daemon()
        .wait_for("the E-stop", |s| s["state"] == "estop");
    let job = &s["last_job"];
    assert_eq!(job["outcome"], "estop", "{job}");
    let stopped = ints(&job["end_steps"]);
    assert!(stopped[0] > 0 && stopped[0] < 8500, "{job}");
    // The drives went off at once: a position-mode stepgen stops where it stood, up to its
    // lag (speed × servo period and thread latency) short of the ledger; then nothing moves.
    let frozen = counts_at_rest(&bench);
    for (c, l) in frozen.iter().zip(&stopped) {
        assert!(
            (c - l).abs() <= 100,
            "stepgen {frozen:?}, ledger {stopped:?}"
        );
    }
    std::thread::sleep(Duration::from_millis(100));
    assert_eq!(counts_at_rest(&bench), frozen, "nothing moves in an E-stop");
    bench.daemon().refused(&["run", "back.ngc"], "");
    bench.setp("edmd.estop-ok-in", "true");
    bench.daemon().ok(&["reset"]);
    bench.daemon().wait_for("reset", |s| s["state"] == "idle");

    // An E-stop while a program is being checked: the check's verdict does not start it.
    let before = counts_at_rest(&bench);
    bench.daemon().ok(&["run", "big.ngc", "--no-wait"]);
    bench.setp("edmd.estop-ok-in", "false");
    let s = bench.daemon().wait_for("the check's verdict", |s| {
        s["check"]["program"]
            .as_str()
            .is_some_and(|p| p.ends_with("big.ngc"))
            && matches!(s["check"]["phase"].as_str(), Some("refused" | "started"))
    });
    assert_eq!(s["check"]["phase"], "refused", "{s}");
    assert!(
        s["check"]["error"].as_str().unwrap().starts_with("E-stop"),
        "{s}"
    );
    assert_eq!(counts_at_rest(&bench), before, "nothing moved");
    bench.setp("edmd.estop-ok-in", "true");
    bench.daemon().ok(&["reset"]);
    bench.daemon().wait_for("reset", |s| s["state"] == "idle");

    // A limit switch on its pin: the job stops; with the switch still closed only the jog
    // away moves, and the jog that leaves it (the pin open again) clears the trip.
    start_and_move(&bench, "plus.ngc");
    bench.setp("edmd.axis.x.pos-lim-sw", "true");
    let s = bench
        .daemon()
        .wait_for("the limit", |s| s["state"] == "limit");
    assert_eq!(s["last_job"]["outcome"], "limit", "{s}");
    assert_eq!(s["last_job"]["limit_switch"], "X+");
    bench
        .daemon()
        .refused(&["jog", "X", "0.2"], "limit switch X+");
    let before = bench.getp_f64("edmd.axis.x.pos-cmd");
    bench.daemon().ok(&["jog", "X", "-0.5"]);
    let away = bench.daemon().wait_for("the jog's end", |s| {
        s["state"] != "jogging" && s["last_job"]["outcome"] == "done"
    });
    assert_eq!(away["state"], "limit", "still closed: still tripped");
    assert!((bench.getp_f64("edmd.axis.x.pos-cmd") - (before - 0.5)).abs() < 1e-9);
    bench.setp("edmd.axis.x.pos-lim-sw", "false");
    bench.daemon().ok(&["jog", "X", "-0.5"]);
    bench.daemon().wait_for("cleared", |s| s["state"] == "idle");

    // Homing by a switch in HAL: `comp` closes edmd.axis.x.home-sw once the X drive's
    // feedback passes 1 mm beyond where it stands (the default [[homing.axis]] for X:
    // search +, latch, home position 200 mm, final move -5 mm).
    let switch = bench.getp_f64("edmd.axis.x.pos-cmd") + 1.0;
    bench.halcmd(&["loadrt", "comp", "names=xhome"]);
    bench.halcmd(&["addf", "xhome", "servo-thread"]);
    bench.setp("xhome.in0", &switch.to_string());
    bench.halcmd(&["net", "x-pos-fb", "xhome.in1"]);
    bench.halcmd(&["net", "x-home", "xhome.out", "edmd.axis.x.home-sw"]);
    bench.daemon().ok(&["home", "X"]);
    let s = bench.daemon().wait_for("X homed", |s| {
        s["state"] == "idle" && s["machine"]["homed"][0] == true
    });
    let x = s["machine"]["position_machine_mm"][0].as_f64().unwrap();
    assert!((x - 195.0).abs() < 1e-9, "{s}");
    // The drive stands 5 mm back from where the switch closed: pos-cmd is the motor position,
    // homing moved only edmd's idea of it. The switch is seen late, never early: the command
    // goes on at the latch feed (30 mm/min, 0.5 mm/s) while stepgen, the feedback and `comp`
    // wait for HAL's servo thread, and on a loaded machine (two cores, the suite beside this
    // test) a uspace thread can stall for a few hundred milliseconds: 0.25 mm is 0.5 s of it.
    let motor = bench.getp_f64("edmd.axis.x.pos-cmd");
    let late = motor - (switch - 5.0);
    assert!(
        (-0.002..0.25).contains(&late),
        "pos-cmd {motor}, switch at {switch}: latched {late} mm past it"
    );
    assert_eq!(bench.getp("edmd.axis.x.home-sw"), "FALSE");
    drop(bench);

    // With the check (sim.toml's 0.5 mm): the feedback unlinked mid-cut stays where it was,
    // the command goes on, and the job stops on a following error naming X.
    let bench = HalBench::start("ferror", &[], &[("square.ngc", SQUARE)]);
    let log = || bench.log();
    start_and_move(&bench, "square.ngc");
    bench.halcmd(&["unlinkp", "edmd.axis.x.pos-fb"]);
    let job = bench
        .daemon()
        .wait_for("the following error", |s| s["state"] != "running")["last_job"]
        .clone();
    assert_eq!(job["outcome"], "output-error", "{job}\n{}", log());
    let error = job["error"].as_str().unwrap_or_default();
    assert!(error.contains("following error on X"), "{job}");
    assert_eq!(bench.getp("edmd.enable-out"), "FALSE");
    assert_eq!(bench.getp("edmd.state"), "2", "the state pin says alarm");
    drop(bench);

    // As the service runs it: `halrun -f` on the file ending in `loadusr -w edmd hal-wait`,
    // stopped by the unit's own ExecStop mid-cut: edmd's controlled stop (checkpoint), then
    // hal-wait ends with success, HAL unloads and halrun exits 0.
    let mut service = HalBench::start_service("service", &[FERROR_OFF], &[("long.ngc", LONG)]);
    start_and_move(&service, "long.ngc");
    let unit = std::fs::read_to_string(common::repo().join("systemd/edmd-hal.service")).unwrap();
    let stop = unit
        .lines()
        .find_map(|l| l.strip_prefix("ExecStop=/bin/sh -c '"))
        .and_then(|l| l.strip_suffix('\''))
        .expect("the unit's ExecStop");
    // Narrowed to this bench's daemon: the suite runs others (by their full path, so the
    // unit's pattern would miss them, but a readme sample might not).
    let stop = stop.replace("^edmd serve", "^edmd serve --config config/hal/sim.toml");
    assert!(stop.contains("pkill -TERM"), "{stop}");
    let stopped = std::process::Command::new("sh")
        .args(["-c", &stop])
        .status()
        .unwrap();
    assert!(stopped.success());
    let code = service.wait_halrun(Duration::from_secs(20));
    let log = service.log();
    assert_eq!(code, Some(0), "{log}");
    assert!(log.contains("controlled stop"), "{log}");
    let checkpoint = std::fs::read_to_string(service.dir.join("checkpoint.json")).unwrap();
    assert!(checkpoint.contains("\"stop\""), "{checkpoint}");
}

/// Without LinuxCNC's HAL library (here: a path with nothing at it), `edmd serve` with
/// `output.kind = "hal"` refuses to start and says what to install. Needs no HAL.
#[test]
fn without_the_hal_library_the_daemon_refuses_to_start_and_names_the_package() {
    let dir = common::scratch("hal", "no-library");
    let mut sets = common::daemon::base_sets(&dir, "p.csv");
    sets.extend([
        "output.kind=\"hal\"".to_string(),
        // HAL's drives take each step at its own tick.
        "fine.ticks_per_wake=1".to_string(),
        "homing.required=false".to_string(),
        format!("hal.library=\"{}\"", dir.join("nothing.so.0").display()),
    ]);
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_edmd"));
    cmd.arg("serve").current_dir(&dir);
    for s in &sets {
        cmd.args(["--set", s]);
    }
    let out = cmd.output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("needs LinuxCNC's HAL library"), "{err}");
    assert!(err.contains("apt install linuxcnc-uspace"), "{err}");
    assert!(!dir.join("edmd.sock").exists(), "nothing listens");
}

/// A cut in E4 (off time 16 µs), the adaptive law on: 8 mm at 2 mm/s.
const ADAPT: &str = "G21 G90\nE4\nG1 X8.5 Y1.5 F120\nM2\n";

/// The discriminator's pulse counters (`edmd.gap.pulses-*`), driven through HAL: a burst of
/// arcs lengthens the off time to the bound at once, and normal pulses under the breakage
/// limit shorten it again; the generator's `edmd.gen.off-time-us` pin follows the law, and
/// the status counts the pulses.
#[test]
fn the_pulse_count_pins_drive_the_adaptive_law() {
    if !common::hal::enabled("hal adaptive") {
        return;
    }
    let bench = HalBench::start(
        "adaptive",
        &[("[homing]", "[adaptive]\nenabled = true\n\n[homing]")],
        &[("adapt.ngc", ADAPT)],
    );
    let log = || bench.log();
    start_and_move(&bench, "adapt.ngc");
    let off = || bench.getp_f64("edmd.gen.off-time-us");
    assert_eq!(off(), 16.0, "E4's off time before any pulse: {}", log());
    // A thousand arcs in one tick: the window is all arcs.
    bench.setp("edmd.gap.pulses-arc", "1000");
    let deadline = Instant::now() + Duration::from_secs(5);
    while off() != 60.0 {
        assert!(
            Instant::now() < deadline,
            "off time {} µs: {}",
            off(),
            log()
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    // A few normal pulses, far under the limit: each window with them shortens it.
    for n in 1..=5 {
        bench.setp("edmd.gap.pulses-normal", &n.to_string());
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(50));
    let shortened = off();
    assert!(shortened < 60.0 && shortened > 40.0, "{shortened} µs");
    // The status counts the pulses and shows the off time in force.
    let s = bench.daemon().status();
    assert_eq!(s["job"]["process"]["pulses"]["arc"], 1000, "{s}");
    assert_eq!(s["job"]["process"]["pulses"]["normal"], 5, "{s}");
    let shown = s["job"]["process"]["off_time_us"].as_f64().unwrap();
    assert!(
        (shown - shortened).abs() < 1e-3,
        "{shown} against the pin's {shortened}"
    );
    let job = bench
        .daemon()
        .wait_for("the job's end", |s| s["state"] == "idle")["last_job"]
        .clone();
    assert_eq!(job["outcome"], "done", "{job}\n{}", log());
}
