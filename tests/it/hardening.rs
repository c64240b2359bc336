//! Nothing from outside stops a cut, and a restart never resumes from a place the machine is
//! not at: the real `edmd serve` attacked as a careless operator and a hostile client would,
//! while a job runs (issue [1/9]). Each test drives the real binary through the interface
//! where the defect was seen: SIGKILL and restart, a failing disk, a FIFO, many idle
//! clients, a descriptor limit.

use crate::common;

use std::path::Path;
use std::time::{Duration, Instant};

use common::daemon::*;
use serde_json::Value;

/// The checkpoint file as JSON.
fn checkpoint(dir: &Path) -> Value {
    let text = std::fs::read_to_string(dir.join("checkpoint.json")).expect("a checkpoint");
    serde_json::from_str(&text).unwrap()
}

/// Sets without periodic checkpoints: what is on disk is only what the write-ahead rule and
/// the standstills wrote.
fn sets_without_periodic(dir: &Path) -> Vec<String> {
    let mut sets = base_sets(dir, "first.csv");
    sets.retain(|s| !s.starts_with("daemon.checkpoint_interval_s"));
    sets.push("daemon.checkpoint_interval_s=0".to_string());
    sets
}

/// The checkpoint is written before the first step, replaced by a still one at a hold and
/// by a moving one before the release; a SIGKILL after the release leaves a checkpoint a
/// restarted daemon refuses to resume without `--force`.
#[test]
fn a_kill_after_a_release_leaves_a_moving_checkpoint_that_asks_for_force() {
    let dir = scratch("write-ahead");
    std::fs::write(dir.join("programs/contour.ngc"), CONTOUR).unwrap();
    let sets = sets_without_periodic(&dir);
    let daemon = Daemon::start(&dir, &sets, &[]);
    // `ctl run` waits for the verdict: the job has started, and its checkpoint is there,
    // at the program's start, before the interval (never, here) would have written one.
    daemon.ok(&["run", "contour.ngc"]);
    let first = checkpoint(&dir);
    assert_eq!(
        (
            &first["reason"],
            &first["still"],
            &first["segment"],
            &first["step"]
        ),
        (
            &Value::from("moving"),
            &Value::from(false),
            &Value::from(0),
            &Value::from(0)
        ),
        "{first}"
    );
    assert_eq!(ints(&first["position_steps"]), vec![0, 0]);

    daemon.wait_for("cutting", |s| position(s)[0] > 2000);
    daemon.ok(&["hold"]);
    daemon.wait_for("the hold's checkpoint", |s| {
        s["state"] == "held" && s["checkpoint"]["still"] == true
    });
    assert_eq!(checkpoint(&dir)["reason"], "hold");
    // The release's reply comes after the moving checkpoint is on disk.
    daemon.ok(&["resume"]);
    let released = checkpoint(&dir);
    assert_eq!(
        (&released["reason"], &released["still"]),
        (&Value::from("moving"), &Value::from(false)),
        "{released}"
    );
    daemon.wait_for("moving again", |s| position(s)[0] > 5000);
    // SIGKILL: no chance to write anything.
    daemon.signal(libc::SIGKILL);
    let _ = daemon.wait();

    let daemon = Daemon::start(&dir, &sets, &[]);
    let (refused, code) = daemon.ctl(&["resume"]);
    assert_eq!(
        (refused["ok"].as_bool(), code),
        (Some(false), 1),
        "{refused}"
    );
    let why = refused["error"].as_str().unwrap();
    assert!(why.contains("--force"), "{why}");
    assert_eq!(daemon.status()["state"], "idle", "nothing started");
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
}

/// SIGKILL during the way back to the start hole after a wire break: the rethread wrote a
/// moving checkpoint before it moved, so the restarted daemon does not resume from the
/// break's standstill.
#[test]
fn a_kill_during_rethreading_leaves_a_moving_checkpoint() {
    let dir = scratch("rethread-kill");
    std::fs::write(dir.join("programs/contour.ngc"), CONTOUR).unwrap();
    std::fs::write(dir.join("gap.txt"), "0 normal\n28000 wire-break\n").unwrap();
    let mut sets = script_sets(&dir, "first.csv");
    sets.retain(|s| !s.starts_with("daemon.checkpoint_interval_s"));
    sets.push("daemon.checkpoint_interval_s=0".to_string());
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["run", "contour.ngc"]);
    daemon.wait_for("the wire break's checkpoint", |s| {
        s["state"] == "wire-break" && s["checkpoint"]["still"] == true
    });
    daemon.ok(&["rethread"]);
    assert_eq!(checkpoint(&dir)["reason"], "moving");
    daemon.wait_for("on the way back", |s| s["state"] == "rethreading");
    // A hold on the way back is a hold, not "rethreading".
    daemon.ok(&["hold"]);
    let held = daemon.wait_for("held on the way back", |s| s["state"] == "held");
    assert_eq!(held["job"]["servo"], "retreat", "{held}");
    daemon.ok(&["resume"]);
    daemon.wait_for("rethreading again", |s| s["state"] == "rethreading");
    daemon.signal(libc::SIGKILL);
    let _ = daemon.wait();

    let daemon = Daemon::start(&dir, &sets, &[]);
    let (refused, _) = daemon.ctl(&["resume"]);
    assert_eq!(refused["ok"], false, "{refused}");
    assert!(refused["error"].as_str().unwrap().contains("--force"));
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
}

/// A checkpoint that cannot be written (here its temporary file's name is taken by a
/// directory) is in the status and the log; the release that would leave the standstill is
/// refused, and goes through once the disk takes the checkpoint again.
#[test]
fn a_failed_checkpoint_write_keeps_the_machine_still_and_is_reported() {
    let dir = scratch("write-fails");
    std::fs::write(dir.join("programs/contour.ngc"), CONTOUR).unwrap();
    let sets = sets_without_periodic(&dir);
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["run", "contour.ngc"]);
    daemon.wait_for("cutting", |s| position(s)[0] > 2000);
    let blocker = dir.join("checkpoint.json.tmp");
    std::fs::create_dir(&blocker).unwrap();
    daemon.ok(&["hold"]);
    let failed = daemon.wait_for("the failed write in the status", |s| {
        s["state"] == "held" && s["checkpoint_write_error"].is_string()
    });
    let error = failed["checkpoint_write_error"].as_str().unwrap();
    assert!(
        error.contains("cannot write the checkpoint (hold)"),
        "{error}"
    );
    assert!(failed["counters"]["checkpoint_failures"].as_u64().unwrap() >= 1);
    // What is on disk is still the moving checkpoint of the job's start: true.
    assert_eq!(checkpoint(&dir)["reason"], "moving");
    let held_at = position(&failed);
    let (refused, code) = daemon.ctl(&["resume"]);
    assert_eq!(
        (refused["ok"].as_bool(), code),
        (Some(false), 1),
        "{refused}"
    );
    assert!(
        refused["error"]
            .as_str()
            .unwrap()
            .contains("the job stays held"),
        "{refused}"
    );
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(
        position(&daemon.status()),
        held_at,
        "moved without a checkpoint"
    );
    daemon.wait_for_log("cannot write the checkpoint (hold)");

    // The disk is back: the hold's checkpoint is written on the next round, the release too.
    std::fs::remove_dir(&blocker).unwrap();
    let ok = daemon.wait_for("the hold's checkpoint", |s| {
        s["checkpoint"]["still"] == true && s.get("checkpoint_write_error").is_none()
    });
    assert_eq!(ok["checkpoint"]["reason"], "hold");
    daemon.resume_to_the_end(&CONTOUR_END);
    assert!(!blocker.exists());
}

/// Killed right after `run` answered, a job still leaves its checkpoint: the restarted
/// daemon knows which job was running (and asks for `--force`, since it was moving).
#[test]
fn a_kill_right_after_the_start_leaves_the_jobs_checkpoint() {
    let dir = scratch("early-kill");
    std::fs::write(dir.join("programs/contour.ngc"), CONTOUR).unwrap();
    let sets = sets_without_periodic(&dir);
    for _ in 0..3 {
        let _ = std::fs::remove_file(dir.join("checkpoint.json"));
        let daemon = Daemon::start(&dir, &sets, &[]);
        daemon.ok(&["run", "contour.ngc"]);
        daemon.signal(libc::SIGKILL);
        let _ = daemon.wait();
        let daemon = Daemon::start(&dir, &sets, &[]);
        let status = daemon.status();
        assert_eq!(status["checkpoint"]["still"], false, "{status}");
        assert!(
            status["checkpoint"]["program"]
                .as_str()
                .unwrap()
                .ends_with("contour.ngc")
        );
        daemon.signal(libc::SIGTERM);
        assert_eq!(daemon.wait().0, 0);
    }
}

/// SIGTERM in the middle of `G4 P3`: the checkpoint keeps what is left of the dwell and the
/// resumed job dwells that long before it moves on.
#[test]
fn a_dwell_stopped_part_way_is_finished_after_the_resume() {
    let dir = scratch("dwell");
    std::fs::write(
        dir.join("programs/dwell.ngc"),
        "G21 G90\nG1 X0.5 F300\nG4 P3\nG1 X1\nM2\n",
    )
    .unwrap();
    let daemon = Daemon::start(&dir, &base_sets(&dir, "first.csv"), &[]);
    daemon.ok(&["run", "dwell.ngc"]);
    daemon.wait_for("the dwell", |s| {
        position(s)[0] == 500 && s["job"]["feed_mm_per_min"] == 0.0
    });
    let dwelling = Instant::now();
    std::thread::sleep(Duration::from_millis(1600));
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
    let cp = checkpoint(&dir);
    let left = cp["dwell_s"].as_f64().expect("the dwell's rest");
    let waited = dwelling.elapsed().as_secs_f64();
    // The dwell's clock is the tick count: a deadline skipped after an overrun (a loaded
    // machine, no real-time priority) counts no dwell time, so the wall time waited is a bound
    // on what passed, not a measure of it. Some of it passed, never more than the wall time.
    assert!(
        left > 3.0 - waited - 0.2 && left < 3.0 - 0.5,
        "{left} s left after {waited} s: {cp}"
    );
    assert_eq!(cp["still"], true);

    // The resumed job, in virtual time: its first step comes after the rest of the dwell.
    let mut sets = base_sets(&dir, "second.csv");
    sets.retain(|s| !s.starts_with("fine.virtual_time"));
    sets.push("fine.virtual_time=true".to_string());
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.resume_to_the_end(&[1000, 0]);
    let (header, rows) = edmd::output::read_pulse_log(&dir.join("second.csv")).unwrap();
    let first_step = rows
        .iter()
        .find(|r| r.steps.iter().any(|&s| s != 0))
        .expect("the resumed job moves");
    let dwelt = first_step.tick as f64 * header.tick_us as f64 * 1e-6;
    assert!(
        (dwelt - left).abs() < 0.05,
        "the resumed job stood {dwelt} s, the checkpoint owed {left} s"
    );
}

/// A resume the job itself refuses (the program probed before the checkpoint: where that
/// probe touched is not known to a new run) moves nothing: the status says the machine is
/// where the checkpoint says, and the checkpoint is still the exact one it was.
#[test]
fn a_resume_refused_past_a_probe_leaves_the_checkpoint_and_the_position_true() {
    let dir = scratch("probe-resume");
    std::fs::write(
        dir.join("programs/probe.ngc"),
        "G21 G90\nG38.2 X5 F30\nG1 X3 F300\nG1 Y3\nM2\n",
    )
    .unwrap();
    std::fs::write(dir.join("gap.txt"), "0 normal\n3000 short\n3040 normal\n").unwrap();
    let sets = script_sets(&dir, "first.csv");
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["run", "probe.ngc"]);
    daemon.wait_for("past the probe", |s| position(s)[0] > 1500);
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
    let stopped = checkpoint(&dir);
    assert_eq!(
        (&stopped["reason"], &stopped["still"]),
        (&Value::from("stop"), &Value::from(true))
    );
    let at = ints(&stopped["position_steps"]);

    let daemon = Daemon::start(&dir, &sets, &[]);
    let (reply, _) = daemon.ctl(&["resume"]);
    assert_eq!(reply["ok"], true, "the check passes: {reply}");
    let idle = daemon.wait_for("the refusal", |s| {
        s["state"] == "idle" && s["last_job"].is_object()
    });
    let last = &idle["last_job"];
    assert_eq!(last["outcome"], "resume-refused", "{last}");
    assert!(
        last["error"].as_str().unwrap().contains("probes at line 2"),
        "{last}"
    );
    assert_eq!(
        ints(&last["end_steps"]),
        at,
        "the machine stands where the checkpoint says"
    );
    assert_eq!(
        checkpoint(&dir),
        stopped,
        "the checkpoint is the one it was"
    );
    assert_eq!(idle["checkpoint"]["still"], true);
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
}

/// Clients that stay connected and ask nothing (monitors, forgotten sessions) and reconnect
/// the moment they are closed, `attackers` of them, against `max_clients`, plus one that
/// connects and drops in a loop: `status`, `hold` and `abort` each answer within half a
/// second.
fn controls_get_through_idle_clients(name: &str, max_clients: usize, attackers: usize) {
    use std::io::Write;
    use std::os::unix::net::UnixStream;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    let dir = scratch(name);
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.push(format!("daemon.max_clients={max_clients}"));
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["run", PROGRAM]);
    daemon.wait_for("cutting", is_moving);
    let stop = Arc::new(AtomicBool::new(false));
    let mut threads: Vec<_> = (0..attackers)
        .map(|_| {
            let (socket, stop) = (daemon.socket.clone(), stop.clone());
            std::thread::spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    let Ok(mut stream) = UnixStream::connect(&socket) else {
                        std::thread::sleep(Duration::from_millis(1));
                        continue;
                    };
                    // Blank lines are not requests: the client stays idle.
                    while !stop.load(Ordering::Relaxed) && stream.write_all(b"\n").is_ok() {
                        std::thread::sleep(Duration::from_millis(50));
                    }
                    std::thread::sleep(Duration::from_millis(1));
                }
            })
        })
        .collect();
    let (socket, churn_stop) = (daemon.socket.clone(), stop.clone());
    threads.push(std::thread::spawn(move || {
        while !churn_stop.load(Ordering::Relaxed) {
            let _ = UnixStream::connect(&socket);
            std::thread::sleep(Duration::from_millis(1));
        }
    }));
    std::thread::sleep(Duration::from_millis(500));
    for command in ["status", "hold", "abort"] {
        let started = Instant::now();
        daemon.ok(&[command]);
        let took = started.elapsed();
        assert!(took < Duration::from_millis(500), "{command} took {took:?}");
        if command == "hold" {
            daemon.wait_for("held", |s| s["state"] == "held");
        }
    }
    daemon.wait_for("idle", |s| s["state"] == "idle");
    stop.store(true, Ordering::Relaxed);
    for t in threads {
        t.join().unwrap();
    }
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
}

/// A hundred idle clients under the default limit: none is even closed.
#[test]
fn a_hundred_idle_clients_never_lock_out_hold_and_abort() {
    controls_get_through_idle_clients("idle-clients", 256, 100);
}

/// Twice as many reconnecting idle clients as the limit: the quietest makes room each time
/// and the operator's client, the newest, is served.
#[test]
fn reconnecting_idle_clients_past_the_limit_never_lock_out_hold_and_abort() {
    controls_get_through_idle_clients("reconnecting-clients", 8, 16);
}

/// 12 KB of nested brackets sent through `ctl run` while another job cuts: the run is
/// refused at the place, the cut carries on, the daemon lives; `edmd check` says the same
/// with exit 2 for 32,000 brackets or 60,000 signs.
#[test]
fn a_program_nested_too_deep_is_refused_and_kills_nothing() {
    let dir = scratch("deep");
    let deep = format!(
        "#1={}1{}\nG1 X#1 F60\nM2\n",
        "[".repeat(6000),
        "]".repeat(6000)
    );
    std::fs::write(dir.join("programs/deep.nc"), &deep).unwrap();
    std::fs::write(dir.join("programs/other.nc"), CONTOUR).unwrap();
    let daemon = Daemon::start(&dir, &base_sets(&dir, "pulses.csv"), &[]);
    daemon.ok(&["run", "other.nc"]);
    daemon.wait_for("cutting", |s| position(s)[0] > 1000);
    daemon.ok(&["hold"]);
    daemon.wait_for("held", |s| s["state"] == "held");
    daemon.ok(&["abort"]);
    daemon.wait_for("idle", |s| s["state"] == "idle");
    let (refused, code) = daemon.ctl(&["run", "deep.nc"]);
    assert_eq!(
        (refused["ok"].as_bool(), code),
        (Some(false), 1),
        "{refused}"
    );
    let error = refused["error"].as_str().unwrap();
    assert!(
        error.contains("deep.nc:1:260: expression nested deeper than 256 levels"),
        "{error}"
    );
    assert_eq!(daemon.status()["state"], "idle");
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);

    for (name, text) in [
        (
            "brackets",
            format!("#1={}1{}\nM2\n", "[".repeat(32_000), "]".repeat(32_000)),
        ),
        (
            "signs",
            format!("#1={}1\nG1 X#1 F60\nM2\n", "-".repeat(60_000)),
        ),
        ("hashes", format!("#1={}1\nM2\n", "#".repeat(60_000))),
    ] {
        let file = dir.join(format!("{name}.nc"));
        std::fs::write(&file, text).unwrap();
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_edmd"))
            .args(["check", "--quiet"])
            .arg(&file)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        if name == "signs" {
            // Signs cost no depth: 60,000 of them are just a sign.
            assert_eq!(out.status.code(), Some(0), "{stderr}");
        } else {
            assert_eq!(out.status.code(), Some(2), "{name}: {stderr}");
            assert!(stderr.contains("nested deeper than 256 levels"), "{stderr}");
        }
    }
}

/// The IIO input replaced by a FIFO mid-job: the job stops on the gap error, and the daemon
/// stays answerable and ends on SIGTERM at once. A FIFO as the token file is an error at
/// startup, not a daemon waiting for a writer.
#[test]
fn a_fifo_in_place_of_a_device_or_token_file_blocks_nothing() {
    let dir = scratch("fifo");
    let dev = dir.join("iio:device0");
    std::fs::create_dir_all(&dev).unwrap();
    std::fs::write(dev.join("in_voltage0_raw"), "1500\n").unwrap();
    std::fs::write(dev.join("in_voltage_scale"), "1.000000\n").unwrap();
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.retain(|s| !s.starts_with("gap.kind"));
    sets.extend([
        "gap.kind=\"iio\"".to_string(),
        format!("gap.iio_device=\"{}\"", dev.display()),
        "gap.iio_gain=20.0".to_string(),
    ]);
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["run", PROGRAM]);
    daemon.wait_for("cutting", is_moving);
    let fifo = dir.join("fifo");
    assert!(
        std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    std::fs::rename(&fifo, dev.join("in_voltage0_raw")).unwrap();
    let ended = daemon.wait_for("the gap error", |s| s["state"] == "idle");
    assert_eq!(ended["last_job"]["outcome"], "gap-error", "{ended}");
    assert!(
        ended["last_job"]["error"]
            .as_str()
            .unwrap()
            .contains("a FIFO, not a regular file"),
        "{ended}"
    );
    let signalled = Instant::now();
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
    assert!(signalled.elapsed() < Duration::from_secs(2));

    let token = dir.join("token-fifo");
    assert!(
        std::process::Command::new("mkfifo")
            .arg(&token)
            .status()
            .unwrap()
            .success()
    );
    let started = Instant::now();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_edmd"))
        .arg("serve")
        .args([
            "--set",
            &format!("daemon.socket=\"{}\"", dir.join("t.sock").display()),
        ])
        .args([
            "--set",
            &format!("daemon.program_dir=\"{}\"", dir.join("programs").display()),
        ])
        .args([
            "--set",
            &format!("daemon.checkpoint=\"{}\"", dir.join("t.json").display()),
        ])
        .args(["--set", &format!("daemon.state_dir=\"{}\"", dir.display())])
        .args(["--set", "daemon.http=\"127.0.0.1:0\""])
        .args([
            "--set",
            &format!("daemon.http_token_file=\"{}\"", token.display()),
        ])
        .output()
        .unwrap();
    assert!(started.elapsed() < Duration::from_secs(5));
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("a FIFO, not a regular file"), "{stderr}");
}

/// The address families a systemd unit's `RestrictAddressFamilies=` allows.
fn unit_families(unit: &str) -> Vec<i32> {
    let line = unit
        .lines()
        .find_map(|l| l.strip_prefix("RestrictAddressFamilies="))
        .expect("the unit restricts address families");
    line.split_whitespace()
        .map(|f| match f {
            "AF_UNIX" => libc::AF_UNIX,
            "AF_INET" => libc::AF_INET,
            "AF_INET6" => libc::AF_INET6,
            "AF_NETLINK" => libc::AF_NETLINK,
            other => panic!("an address family this test does not know: {other}"),
        })
        .collect()
}

/// A seccomp filter that does what systemd's `RestrictAddressFamilies=` does: `socket(2)`
/// with a family not in `allowed` fails with EAFNOSUPPORT.
fn restrict_address_families(cmd: &mut std::process::Command, allowed: &[i32]) {
    use std::os::unix::process::CommandExt;
    #[cfg(target_arch = "x86_64")]
    const ARCH: u32 = 0xc000_003e;
    #[cfg(target_arch = "aarch64")]
    const ARCH: u32 = 0xc000_00b7;
    const LD_ABS: u16 = 0x20; // BPF_LD | BPF_W | BPF_ABS
    const JEQ: u16 = 0x15; // BPF_JMP | BPF_JEQ | BPF_K
    const RET: u16 = 0x06; // BPF_RET | BPF_K
    const ALLOW: u32 = 0x7fff_0000;
    const ERRNO: u32 = 0x0005_0000;
    let n = allowed.len();
    let allow_at = 6 + n;
    let op = |code, jt, jf, k| libc::sock_filter { code, jt, jf, k };
    let mut filter = vec![
        op(LD_ABS, 0, 0, 4),
        op(JEQ, 0, (allow_at - 2) as u8, ARCH),
        op(LD_ABS, 0, 0, 0),
        op(JEQ, 0, (allow_at - 4) as u8, libc::SYS_socket as u32),
        op(LD_ABS, 0, 0, 16),
    ];
    for (k, family) in allowed.iter().enumerate() {
        filter.push(op(JEQ, (allow_at - (5 + k + 1)) as u8, 0, *family as u32));
    }
    filter.push(op(RET, 0, 0, ERRNO | libc::EAFNOSUPPORT as u32));
    filter.push(op(RET, 0, 0, ALLOW));
    let filter = Box::leak(filter.into_boxed_slice());
    let program = Box::leak(Box::new(libc::sock_fprog {
        len: filter.len() as u16,
        filter: filter.as_mut_ptr(),
    }));
    let program = program as *const libc::sock_fprog as usize;
    // SAFETY: prctl is async-signal-safe; the filter program lives for the whole test
    // (leaked above) and is only read by the kernel.
    unsafe {
        cmd.pre_exec(move || {
            if libc::prctl(libc::PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) != 0
                || libc::prctl(libc::PR_SET_SECCOMP, libc::SECCOMP_MODE_FILTER, program) != 0
            {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
}

/// Under the shipped unit's `RestrictAddressFamilies=` (the kernel's seccomp filter, as
/// systemd installs it) the daemon serves HTTP; under the old setting (`AF_UNIX` alone) it
/// refuses to start and names the setting.
#[test]
fn the_shipped_unit_lets_http_work_and_a_stricter_one_is_named() {
    let dir = scratch("unit");
    let unit = std::fs::read_to_string(common::repo().join("systemd/edmd.service")).unwrap();
    let serve = |families: &[i32], log: &str| {
        let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_edmd"));
        cmd.arg("serve")
            .args([
                "--set",
                &format!("daemon.socket=\"{}\"", dir.join("u.sock").display()),
            ])
            .args([
                "--set",
                &format!("daemon.program_dir=\"{}\"", dir.join("programs").display()),
            ])
            .args([
                "--set",
                &format!("daemon.checkpoint=\"{}\"", dir.join("u.json").display()),
            ])
            .args(["--set", &format!("daemon.state_dir=\"{}\"", dir.display())])
            .args(["--set", "daemon.http=\"127.0.0.1:0\""])
            .args([
                "--set",
                &format!("daemon.http_token_file=\"{}\"", dir.join("token").display()),
            ])
            .args(["--set", "log.format=\"plain\""])
            .env_remove("NOTIFY_SOCKET")
            .stdout(std::process::Stdio::null())
            .stderr(std::fs::File::create(dir.join(log)).unwrap());
        restrict_address_families(&mut cmd, families);
        cmd.spawn().unwrap()
    };
    let mut child = serve(&unit_families(&unit), "shipped.log");
    let deadline = Instant::now() + Duration::from_secs(20);
    let addr = loop {
        let log = std::fs::read_to_string(dir.join("shipped.log")).unwrap_or_default();
        if let Some(at) = log.find("on http://") {
            break log[at + 10..]
                .split_whitespace()
                .next()
                .unwrap()
                .to_string();
        }
        assert!(child.try_wait().unwrap().is_none(), "it stopped:\n{log}");
        assert!(Instant::now() < deadline, "{log}");
        std::thread::sleep(Duration::from_millis(20));
    };
    let body = ureq::get(&format!("http://{addr}/api/status"))
        .call()
        .unwrap()
        .into_string()
        .unwrap();
    let reply: Value = serde_json::from_str(&body).unwrap();
    assert_eq!(reply["status"]["state"], "idle");
    // SAFETY: kill(2) on our own child's pid.
    assert_eq!(unsafe { libc::kill(child.id() as i32, libc::SIGTERM) }, 0);
    assert_eq!(child.wait().unwrap().code(), Some(0));

    let mut child = serve(&[libc::AF_UNIX], "strict.log");
    assert_eq!(child.wait().unwrap().code(), Some(1));
    let log = std::fs::read_to_string(dir.join("strict.log")).unwrap();
    assert!(
        log.contains("Address family not supported")
            && log.contains("RestrictAddressFamilies= must allow AF_INET and AF_INET6"),
        "{log}"
    );
}

/// A report folder that cannot be made refuses the job before it moves, not at its end.
#[test]
fn a_report_folder_that_cannot_be_made_refuses_the_job_at_its_start() {
    let dir = scratch("report-dir");
    std::fs::write(dir.join("not-a-folder"), "").unwrap();
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.push(format!(
        "daemon.report_dir=\"{}\"",
        dir.join("not-a-folder/reports").display()
    ));
    let daemon = Daemon::start(&dir, &sets, &[]);
    let (refused, code) = daemon.ctl(&["run", PROGRAM]);
    assert_eq!(
        (refused["ok"].as_bool(), code),
        (Some(false), 1),
        "{refused}"
    );
    let error = refused["error"].as_str().unwrap();
    assert!(
        error.starts_with("daemon.report_dir: cannot make ")
            && error.contains("without its report"),
        "{error}"
    );
    assert!(!dir.join("pulses.csv").exists(), "nothing moved");
    assert!(
        !dir.join("checkpoint.json").exists(),
        "no job, no checkpoint"
    );
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
}
