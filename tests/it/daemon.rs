//! The daemon end to end: the real `edmd serve` on a temporary socket, driven by the real
//! `edmd ctl` (and by raw sockets for what a well-behaved client never sends).
//!
//! Jobs run in real time (`fine.virtual_time=false`) at a feed that makes
//! `tests/data/runtime-path.nc` last a few seconds, so there is time to hold, stop and
//! resume it; the gap is always normal (`gap.kind="none"`) so runs are comparable pulse by
//! pulse, and the pulses go to a pulse log that the tests read back.

use crate::common;

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::{UnixDatagram, UnixStream};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

use common::daemon::*;
use edmd::output::read_pulse_log;

#[test]
fn run_hold_resume_abort_and_status() {
    let dir = scratch("hold");
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.push(format!(
        "daemon.report_dir=\"{}\"",
        dir.join("reports").display()
    ));
    let daemon = Daemon::start(&dir, &sets, &[]);
    let status = daemon.status();
    assert_eq!(status["state"], "idle");
    assert!(status.get("job").is_none());

    let reply = daemon.ok(&["run", PROGRAM]);
    assert!(
        reply["message"].as_str().unwrap().contains("running"),
        "{reply}"
    );
    // A second job while one runs is refused, the first carries on.
    let (reply, code) = daemon.ctl(&["run", PROGRAM]);
    assert_eq!((reply["ok"].as_bool(), code), (Some(false), 1));
    assert!(reply["error"].as_str().unwrap().contains("abort it first"));
    // As text: the reason first, then one line of what the daemon is doing; no status block.
    let out = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .args(["ctl", "--socket"])
        .arg(&daemon.socket)
        .args(["run", PROGRAM])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<&str> = stderr.lines().collect();
    assert!(
        lines[0].starts_with("edmd: error: ") && lines[0].contains("abort it first"),
        "{stderr}"
    );
    assert!(lines[1].starts_with("edmd: the daemon: "), "{stderr}");
    assert!(
        !String::from_utf8_lossy(&out.stdout).contains("state:"),
        "a status block printed"
    );

    let status = daemon.wait_for("cutting", is_moving);
    let job = &status["job"];
    assert_eq!(job["servo"], "forward");
    assert!(job["feed_mm_per_min"].as_f64().unwrap() > 0.0, "{job}");
    assert!(job["line"].as_u64().unwrap() >= 4, "{job}");
    assert!(job["buffer_capacity"].as_u64().unwrap() > 0);
    assert!(job["latency_max_us"].as_f64().is_some(), "real time: {job}");

    // Hold: brakes to a standstill, writes a checkpoint, stays put.
    daemon.ok(&["hold"]);
    let held = daemon.wait_for("held", |s| s["state"] == "held");
    let at = position(&held);
    std::thread::sleep(Duration::from_millis(300));
    let still = daemon.status();
    assert_eq!(still["state"], "held");
    assert_eq!(position(&still), at, "moved while held");
    assert_eq!(still["job"]["feed_mm_per_min"], 0.0);
    let cp = daemon.wait_for("the hold checkpoint", |s| {
        s["checkpoint"]["reason"] == "hold"
    });
    assert_eq!(ints(&cp["checkpoint"]["position_steps"]), at);
    assert_eq!(cp["checkpoint"]["still"], true);

    // Resume: moves on.
    daemon.ok(&["resume"]);
    let (reply, _) = daemon.ctl(&["resume"]);
    assert_eq!(reply["ok"], false, "not held any more: {reply}");
    daemon.wait_for("moving again", |s| {
        s["state"] == "running" && position(s) != at
    });

    // Abort: brakes, ends the job, keeps a checkpoint where it stopped.
    daemon.ok(&["abort"]);
    let idle = daemon.wait_for("idle", |s| s["state"] == "idle");
    let last = &idle["last_job"];
    assert_eq!(last["outcome"], "stopped", "{last}");
    let end = ints(&last["end_steps"]);
    assert_ne!(
        end,
        PROGRAM_END.to_vec(),
        "the abort came too late to test anything"
    );
    assert_eq!(idle["checkpoint"]["reason"], "abort");
    assert_eq!(ints(&idle["checkpoint"]["position_steps"]), end);
    // Every pulse in the log is in the ledger.
    let sum: Vec<i64> = (0..2)
        .map(|a| {
            moves(&dir.join("pulses.csv"))
                .iter()
                .map(|m| m[a] as i64)
                .sum()
        })
        .collect();
    assert_eq!(sum, end);
    // The job's report lists the operator's hold and its release, where they happened.
    let report = std::fs::read_dir(dir.join("reports"))
        .unwrap()
        .flatten()
        .next()
        .unwrap();
    let events = std::fs::read_to_string(report.path().join("events.csv")).unwrap();
    let kinds: Vec<&str> = events
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(3).unwrap())
        .collect();
    assert_eq!(kinds, ["hold", "released", "abort"], "{events}");

    // Nothing to hold or abort now; a human-readable status says so.
    let (reply, code) = daemon.ctl(&["hold"]);
    assert_eq!((reply["ok"].as_bool(), code), (Some(false), 1));
    let text = daemon.status_text();
    assert!(text.contains("state:        idle"), "{text}");
    assert!(
        text.contains("checkpoint:") && text.contains("(abort)"),
        "{text}"
    );

    let deadline = Instant::now() + Duration::from_secs(10);
    while !daemon.log().contains("INFO edmd::daemon: status: idle") {
        assert!(
            Instant::now() < deadline,
            "no periodic status line: {}",
            daemon.log()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    daemon.signal(libc::SIGTERM);
    let (code, log) = daemon.wait();
    assert_eq!(code, 0, "{log}");
    assert!(!dir.join("edmd.sock").exists(), "socket removed on exit");
}

#[test]
fn sigterm_mid_job_then_resume_after_a_restart_loses_and_doubles_no_pulse() {
    let dir = scratch("resume");
    let reference = uninterrupted(&dir);

    let first = Daemon::start(&dir, &base_sets(&dir, "first.csv"), &[]);
    first.ok(&["run", PROGRAM]);
    first.wait_for("cutting", is_moving);
    first.signal(libc::SIGTERM);
    let (code, log) = first.wait();
    assert_eq!(code, 0, "a controlled stop exits 0:\n{log}");
    assert!(log.contains("controlled stop"), "{log}");
    let cp: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("checkpoint.json")).unwrap())
            .unwrap();
    assert_eq!(cp["reason"], "stop");
    assert_eq!(cp["still"], true);
    assert_eq!(cp["program_sha256"].as_str().unwrap().len(), 64);
    let stopped_at = ints(&cp["position_steps"]);
    assert_ne!(
        stopped_at,
        PROGRAM_END.to_vec(),
        "stopped too late to test anything"
    );

    let second = Daemon::start(&dir, &base_sets(&dir, "second.csv"), &[]);
    assert_eq!(second.status()["checkpoint"]["reason"], "stop");
    let reply = second.ok(&["resume"]);
    assert!(
        reply["message"].as_str().unwrap().contains("resuming"),
        "{reply}"
    );
    let idle = second.wait_for("the resumed job's end", |s| s["state"] == "idle");
    let last = &idle["last_job"];
    assert_eq!(last["outcome"], "done", "{last}\n{}", second.log());
    assert_eq!(ints(&last["end_steps"]), PROGRAM_END.to_vec());
    assert!(
        idle.get("checkpoint").is_none(),
        "done removes the checkpoint"
    );
    assert!(!dir.join("checkpoint.json").exists());

    // The pulses of the stopped run followed by those of the resumed one are, step for
    // step, the pulses of the uninterrupted run.
    let mut joined = moves(&dir.join("first.csv"));
    let first_len = joined.len();
    joined.extend(moves(&dir.join("second.csv")));
    assert!(first_len > 100 && first_len + 100 < reference.len());
    eprintln!(
        "stopped at {stopped_at:?} steps after {first_len} of {} moving ticks; resumed run: {}",
        reference.len(),
        joined.len() - first_len
    );
    assert_eq!(joined.len(), reference.len());
    assert!(joined == reference, "the pulse sequences differ");
    second.signal(libc::SIGTERM);
    assert_eq!(second.wait().0, 0);
}

#[test]
fn a_changed_program_or_motion_setting_refuses_to_resume() {
    let dir = scratch("changed");
    let first = Daemon::start(&dir, &base_sets(&dir, "first.csv"), &[]);
    first.ok(&["run", PROGRAM]);
    first.wait_for("cutting", is_moving);
    first.ok(&["abort"]);
    first.wait_for("idle", |s| s["state"] == "idle");
    first.signal(libc::SIGTERM);
    assert_eq!(first.wait().0, 0);

    // Other motion settings: refused.
    let mut sets = base_sets(&dir, "second.csv");
    sets.push("interpolation.chord_tolerance_mm=0.002".to_string());
    let second = Daemon::start(&dir, &sets, &[]);
    let (reply, code) = second.ctl(&["resume"]);
    assert_eq!((reply["ok"].as_bool(), code), (Some(false), 1));
    let error = reply["error"].as_str().unwrap();
    assert!(
        error.contains("[interpolation]")
            && error.contains("interpolation.chord_tolerance_mm: 0.001 -> 0.002"),
        "the changed key named: {reply}"
    );
    second.signal(libc::SIGTERM);
    assert_eq!(second.wait().0, 0);

    // The program edited and the job's private copy gone: refused, and the checkpoint stays
    // for the right program. (With the copy there, the edit changes nothing: see
    // `edits_of_the_program_change_nothing_about_the_motion`.)
    let program = dir.join("programs").join(PROGRAM);
    let mut text = std::fs::read_to_string(&program).unwrap();
    text = text.replace("G1 X10 Y8", "G1 X10 Y8.001");
    std::fs::write(&program, text).unwrap();
    let copies = dir.join("job-programs");
    assert_eq!(
        std::fs::read_dir(&copies).unwrap().count(),
        1,
        "the checkpoint's copy"
    );
    std::fs::remove_dir_all(&copies).unwrap();
    let third = Daemon::start(&dir, &base_sets(&dir, "third.csv"), &[]);
    let (reply, _) = third.ctl(&["resume"]);
    let error = reply["error"].as_str().unwrap();
    assert!(
        error.contains("the program changed since the checkpoint"),
        "{error}"
    );
    assert!(dir.join("checkpoint.json").exists());
    assert!(!dir.join("third.csv").exists(), "nothing was started");
    third.signal(libc::SIGTERM);
    assert_eq!(third.wait().0, 0);
}

#[test]
fn bad_requests_escapes_vanishing_and_too_many_clients() {
    let dir = scratch("bad");
    std::fs::write(dir.join("secret.nc"), "G1 X1 F60\n").unwrap();
    std::os::unix::fs::symlink(dir.join("secret.nc"), dir.join("programs/escape.nc")).unwrap();
    std::fs::write(dir.join("programs/broken.nc"), "G1 X1 F60\nG1 Q7\n").unwrap();
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.push("daemon.max_clients=2".to_string());
    let daemon = Daemon::start(&dir, &sets, &[]);

    let replies = raw_exchange(
        &daemon.socket,
        &[
            "this is not json",
            r#"{"cmd":"fly"}"#,
            r#"{"cmd":"run"}"#,
            r#"{"cmd":"run","program":"../secret.nc"}"#,
            r#"{"cmd":"run","program":"escape.nc"}"#,
            r#"{"cmd":"status"}"#,
        ],
    );
    let errors: Vec<&str> = replies[..5]
        .iter()
        .map(|r| {
            assert_eq!(r["ok"], false, "{r}");
            r["error"].as_str().unwrap()
        })
        .collect();
    assert!(errors[0].starts_with("request:1:"), "{}", errors[0]);
    assert!(errors[1].contains("unknown variant `fly`"), "{}", errors[1]);
    assert!(
        errors[2].contains("missing field `program`"),
        "{}",
        errors[2]
    );
    // `..` and a link out of the directory: the same answer as a missing program.
    assert_eq!(
        errors[3],
        "../secret.nc: no such program in the program directory"
    );
    assert_eq!(
        errors[4],
        "escape.nc: no such program in the program directory"
    );
    assert_eq!(replies[5]["ok"], true, "the connection still works");
    assert_eq!(replies[5]["status"]["state"], "idle");

    // A program with an error is accepted, then refused by its check, at its line.
    let (reply, code) = daemon.ctl(&["run", "broken.nc"]);
    assert_eq!((reply["ok"].as_bool(), code), (Some(false), 1), "{reply}");
    let error = reply["error"].as_str().unwrap();
    assert!(error.contains("broken.nc:2:"), "file:line:col: {error}");
    assert_eq!(reply["status"]["check"]["phase"], "refused");
    assert!(!dir.join("pulses.csv").exists(), "nothing moved");

    // A client that vanishes mid-request asked for nothing.
    {
        let mut s = UnixStream::connect(&daemon.socket).unwrap();
        s.write_all(br#"{"cmd":"run","program":"runtime"#).unwrap();
    }
    std::thread::sleep(Duration::from_millis(100));
    assert_eq!(daemon.status()["state"], "idle");
    assert!(!dir.join("pulses.csv").exists());

    // Two clients fill the daemon (each retried until served: a finished client's thread may
    // still hold its slot for a moment); a third makes room by closing the quietest of them.
    let served = || loop {
        let stream = UnixStream::connect(&daemon.socket).unwrap();
        if exchange(&stream, r#"{"cmd":"status"}"#)["ok"] == true {
            return stream;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    std::thread::sleep(Duration::from_millis(300));
    let a = served();
    std::thread::sleep(Duration::from_millis(20));
    let b = served();
    std::thread::sleep(Duration::from_millis(20));
    let c = served();
    assert_eq!(exchange(&c, r#"{"cmd":"status"}"#)["ok"], true);
    assert_eq!(exchange(&b, r#"{"cmd":"status"}"#)["ok"], true);
    // `a` asked nothing for the longest: it was closed for `c`.
    a.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let mut writer = &a;
    let _ = writeln!(writer, r#"{{"cmd":"status"}}"#);
    let mut answer = String::new();
    let _ = BufReader::new(&a).read_line(&mut answer);
    assert!(answer.is_empty(), "the evicted client got {answer:?}");

    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
}

#[test]
fn systemd_notify_watchdog_reload_and_usr1() {
    let dir = scratch("notify");
    let notify_path = dir.join("notify.sock");
    let _ = std::fs::remove_file(&notify_path);
    let notify = UnixDatagram::bind(&notify_path).unwrap();
    notify
        .set_read_timeout(Some(Duration::from_secs(20)))
        .unwrap();
    let config = dir.join("edmd.toml");
    std::fs::write(&config, "[log]\nlevel = \"info\"\n").unwrap();
    let sets = base_sets(&dir, "pulses.csv");
    let daemon = Daemon::start_with_config(
        &dir,
        &config,
        &sets,
        &[
            ("NOTIFY_SOCKET", notify_path.display().to_string()),
            ("WATCHDOG_USEC", "400000".to_string()),
        ],
    );
    // systemd reads its socket all the time; so does this thread.
    let seen = std::sync::Arc::new(std::sync::Mutex::new(Vec::<String>::new()));
    let reader = {
        let seen = seen.clone();
        std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            while let Ok(n) = notify.recv(&mut buf) {
                let message = String::from_utf8_lossy(&buf[..n]).into_owned();
                let last = message == "STOPPING=1";
                seen.lock().unwrap().push(message);
                if last {
                    return;
                }
            }
        })
    };
    let messages = || seen.lock().unwrap().clone();
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let m = messages();
        if m.iter().filter(|m| *m == "WATCHDOG=1").count() >= 2
            && m.iter().any(|m| m.starts_with("STATUS=idle"))
        {
            assert_eq!(m[0], "READY=1", "READY first: {m:?}");
            break;
        }
        assert!(Instant::now() < deadline, "{m:?}");
        std::thread::sleep(Duration::from_millis(20));
    }

    // SIGHUP: a live key applies, a job key is refused while a job runs.
    std::fs::write(&config, "[log]\nlevel = \"debug\"\n").unwrap();
    daemon.signal(libc::SIGHUP);
    daemon.ok(&["run", PROGRAM]);
    daemon.wait_for("cutting", is_moving);
    std::fs::write(
        &config,
        "[log]\nlevel = \"debug\"\n[servo]\nretract_feed_mm_per_min = 10.0\n",
    )
    .unwrap();
    daemon.signal(libc::SIGHUP);
    daemon.signal(libc::SIGUSR1);
    let deadline = Instant::now() + Duration::from_secs(20);
    let log = loop {
        let log = daemon.log();
        if log.contains("status: state:") && log.contains("reload refused") {
            break log;
        }
        assert!(Instant::now() < deadline, "{log}");
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(
        log.contains("reload: log.level: \"info\" -> \"debug\""),
        "{log}"
    );
    assert!(
        log.contains("servo.retract_feed_mm_per_min cannot change while a job runs"),
        "{log}"
    );
    assert!(log.contains("status: job:"), "SIGUSR1 status: {log}");
    daemon.ok(&["abort"]);
    daemon.wait_for("idle", |s| s["state"] == "idle");
    daemon.signal(libc::SIGTERM);
    let (code, log) = daemon.wait();
    assert_eq!(code, 0, "{log}");
    reader.join().unwrap();
    let m = messages();
    assert_eq!(m.last().map(String::as_str), Some("STOPPING=1"), "{m:?}");
    assert!(
        m.iter().any(|m| m.starts_with("STATUS=running")),
        "STATUS= follows the job: {m:?}"
    );
}

impl Daemon {
    fn start_with_config(
        dir: &Path,
        config: &Path,
        sets: &[String],
        env: &[(&str, String)],
    ) -> Daemon {
        Daemon::start_args(dir, &[format!("--config={}", config.display())], sets, env)
    }
}

#[test]
fn edits_of_the_program_change_nothing_about_the_motion() {
    let dir = scratch("edit");
    let reference = uninterrupted(&dir);
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.push(format!(
        "daemon.report_dir=\"{}\"",
        dir.join("reports").display()
    ));
    let daemon = Daemon::start(&dir, &sets, &[]);
    let reply = daemon.ok(&["run", PROGRAM]);
    assert!(
        reply["message"].as_str().unwrap().starts_with("running"),
        "{reply}"
    );
    daemon.wait_for("cutting", is_moving);
    // Overwritten in place with a 300 mm detour (the same file, the same inode), then
    // replaced and deleted: the job runs the copy it checked.
    let program = dir.join("programs").join(PROGRAM);
    let text = std::fs::read_to_string(&program).unwrap();
    let edited = text.replace("G1 X10 Y8", "G1 X310 Y8");
    assert_ne!(edited, text);
    std::fs::OpenOptions::new()
        .write(true)
        .open(&program)
        .unwrap()
        .write_all(edited.as_bytes())
        .unwrap();
    std::thread::sleep(Duration::from_millis(100));
    std::fs::remove_file(&program).unwrap();
    let idle = daemon.wait_for("the job's end", |s| s["state"] == "idle");
    assert_eq!(idle["last_job"]["outcome"], "done", "{idle}");
    assert_eq!(ints(&idle["last_job"]["end_steps"]), PROGRAM_END.to_vec());
    assert!(
        moves(&dir.join("pulses.csv")) == reference,
        "the pulses differ"
    );
    // Done: the private copy goes with the job.
    let copies = std::fs::read_dir(dir.join("job-programs")).unwrap().count();
    assert_eq!(copies, 0);
    // The job's report (daemon.report_dir): what ran, ending at the program's end.
    let reports: Vec<_> = std::fs::read_dir(dir.join("reports"))
        .unwrap()
        .flatten()
        .collect();
    assert_eq!(reports.len(), 1);
    let report = reports[0].path();
    // Named by the local date and time it started: 2026-11-23T20-10-03-runtime-path.
    let name = report.file_name().unwrap().to_string_lossy().into_owned();
    let stamp = name
        .strip_suffix("-runtime-path")
        .unwrap_or_else(|| panic!("{name}"));
    let shape: String = stamp
        .chars()
        .map(|c| if c.is_ascii_digit() { '9' } else { c })
        .collect();
    assert_eq!(shape, "9999-99-99T99-99-99", "{name}");
    // Times to the tick, positions to the step.
    let events = std::fs::read_to_string(report.join("events.csv")).unwrap();
    assert!(events.trim_end().ends_with("done,,7.500,8.250"), "{events}");
    let done = events.lines().last().unwrap();
    let time = done.split(',').nth(1).unwrap();
    assert_eq!(time.split('.').nth(1).map(str::len), Some(5), "{done}");
    for file in ["path.svg", "feed.svg", "summary.json"] {
        assert!(report.join(file).exists(), "{file}");
    }
    // The programmed path, drawn on its own thread while the job ran, under the executed one.
    let path = std::fs::read_to_string(report.join("path.svg")).unwrap();
    assert!(path.contains("programmed path"), "{path}");
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
}

/// Peak resident memory of a process (kB), from /proc.
fn peak_rss_kb(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap()
}

#[test]
fn a_large_program_never_blocks_the_daemon() {
    let dir = scratch("large");
    // A 200 MB program (EDMD_LARGE_MB to change it), written in 1 MB chunks.
    let mb: usize = std::env::var("EDMD_LARGE_MB")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(200);
    let big = dir.join("programs").join("big.nc");
    {
        let mut out = std::io::BufWriter::new(std::fs::File::create(&big).unwrap());
        writeln!(out, "G21 G90 F600").unwrap();
        let mut line = 0usize;
        let mut written = 0;
        while written < mb << 20 {
            let text = format!("G1 X{}.{:03} Y{}\n", line % 50, line % 1000, line % 7);
            out.write_all(text.as_bytes()).unwrap();
            written += text.len();
            line += 1;
        }
        writeln!(out, "M2").unwrap();
    }
    let notify_path = dir.join("notify.sock");
    let notify = UnixDatagram::bind(&notify_path).unwrap();
    notify
        .set_read_timeout(Some(Duration::from_secs(20)))
        .unwrap();
    let pings = std::sync::Arc::new(std::sync::Mutex::new(Vec::<Instant>::new()));
    let reader = {
        let pings = pings.clone();
        std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            while let Ok(n) = notify.recv(&mut buf) {
                let message = String::from_utf8_lossy(&buf[..n]).into_owned();
                if message == "WATCHDOG=1" {
                    pings.lock().unwrap().push(Instant::now());
                }
                if message == "STOPPING=1" {
                    return;
                }
            }
        })
    };
    let daemon = Daemon::start(
        &dir,
        &base_sets(&dir, "pulses.csv"),
        &[
            ("NOTIFY_SOCKET", notify_path.display().to_string()),
            ("WATCHDOG_USEC", "1000000".to_string()),
        ],
    );
    let timed = |args: &[&str]| {
        let t = Instant::now();
        let reply = daemon.ok(args);
        (reply, t.elapsed())
    };
    let (reply, took) = timed(&["run", "big.nc", "--no-wait"]);
    assert!(
        took < Duration::from_millis(500),
        "run --no-wait took {took:?}"
    );
    assert_eq!(reply["status"]["state"], "checking", "{reply}");
    let checking_since = Instant::now();
    let mut worst = Duration::ZERO;
    let mut progress = Vec::new();
    // Two seconds of status requests while the daemon copies and checks.
    while checking_since.elapsed() < Duration::from_secs(2) {
        let (reply, took) = timed(&["status"]);
        worst = worst.max(took);
        let check = &reply["status"]["check"];
        progress.push((
            check["phase"].as_str().unwrap_or_default().to_string(),
            check["bytes_done"].as_u64().unwrap_or(0),
        ));
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(
        worst < Duration::from_millis(500),
        "status took up to {worst:?}"
    );
    assert!(
        progress.windows(2).any(|w| w[1] != w[0]),
        "the check shows its progress: {progress:?}"
    );
    eprintln!("{mb} MB: status within {worst:?}; progress {progress:?}");
    // The emergency stop of a check: abort cancels it, nothing moves.
    daemon.ok(&["abort"]);
    let idle = daemon.wait_for("the check's end", |s| s["state"] == "idle");
    assert_eq!(idle["check"]["phase"], "refused", "{idle}");
    assert!(!dir.join("pulses.csv").exists(), "nothing moved");
    let rss = peak_rss_kb(daemon.child.id());
    let ping_gaps: Vec<Duration> = {
        let p = pings.lock().unwrap();
        p.windows(2).map(|w| w[1] - w[0]).collect()
    };
    let worst_gap = ping_gaps.iter().max().copied().unwrap_or_default();
    eprintln!(
        "peak RSS {rss} kB; {} watchdog pings, widest gap {worst_gap:?}",
        ping_gaps.len() + 1
    );
    assert!(rss < 64 * 1024, "peak RSS {rss} kB");
    assert!(ping_gaps.len() >= 2, "watchdog pings: {ping_gaps:?}");
    assert!(
        worst_gap < Duration::from_millis(1000),
        "watchdog gaps {ping_gaps:?}"
    );
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
    reader.join().unwrap();
}

#[test]
fn after_a_crash_at_a_hold_the_pulse_log_and_the_checkpoint_agree() {
    let dir = scratch("crash");
    let daemon = Daemon::start(&dir, &base_sets(&dir, "pulses.csv"), &[]);
    daemon.ok(&["run", PROGRAM]);
    daemon.wait_for("cutting", is_moving);
    daemon.ok(&["hold"]);
    daemon.wait_for("the hold checkpoint", |s| {
        s["state"] == "held" && s["checkpoint"]["reason"] == "hold"
    });
    // SIGKILL: nothing is flushed on the way out; what is on disk is all there is.
    let mut daemon = daemon;
    daemon.child.kill().unwrap();
    daemon.child.wait().unwrap();
    let cp: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("checkpoint.json")).unwrap())
            .unwrap();
    assert_eq!(cp["still"], true);
    let logged: Vec<i64> = (0..2)
        .map(|a| {
            moves(&dir.join("pulses.csv"))
                .iter()
                .map(|m| m[a] as i64)
                .sum()
        })
        .collect();
    assert_eq!(
        logged,
        ints(&cp["position_steps"]),
        "log on disk against the checkpoint"
    );
}

#[test]
fn a_corrupt_checkpoint_is_reported_in_the_reply_and_a_moving_one_asks_for_force() {
    let dir = scratch("corrupt");
    std::fs::write(
        dir.join("checkpoint.json"),
        "{\n  \"version\": 1,\n  \"oops\n",
    )
    .unwrap();
    let daemon = Daemon::start(&dir, &base_sets(&dir, "pulses.csv"), &[]);
    let (reply, code) = daemon.ctl(&["resume"]);
    assert_eq!((reply["ok"].as_bool(), code), (Some(false), 1));
    let error = reply["error"].as_str().unwrap();
    assert!(
        error.starts_with("nothing to resume: ")
            && error.contains("checkpoint.json:4:0: not a checkpoint"),
        "the reason, located: {error}"
    );
    // A periodic checkpoint written while cutting, then a crash: status says what it takes.
    daemon.ok(&["run", PROGRAM]);
    daemon.wait_for("a periodic checkpoint", |s| {
        s["checkpoint"]["reason"] == "periodic"
    });
    let mut daemon = daemon;
    daemon.child.kill().unwrap();
    daemon.child.wait().unwrap();
    let second = Daemon::start(&dir, &base_sets(&dir, "second.csv"), &[]);
    let text = second.status_text();
    assert!(
        text.contains("`edmd ctl resume --force` continues it"),
        "{text}"
    );
    let (reply, _) = second.ctl(&["resume"]);
    assert!(
        reply["error"].as_str().unwrap().contains("--force"),
        "{reply}"
    );
    second.signal(libc::SIGTERM);
    assert_eq!(second.wait().0, 0);
}

#[test]
fn a_refused_run_leaves_the_checkpoint_and_resume_continues_the_job() {
    let dir = scratch("refused");
    std::fs::write(
        dir.join("programs/broken.nc"),
        "G1 X1 F60\nG2 X5 Y0 I1 J0\n",
    )
    .unwrap();
    std::fs::write(dir.join("outside.nc"), "G1 X1 F60\n").unwrap();
    let reference = uninterrupted(&dir);
    let first = Daemon::start(&dir, &base_sets(&dir, "first.csv"), &[]);
    first.ok(&["run", PROGRAM]);
    first.wait_for("cutting", is_moving);
    first.ok(&["hold"]);
    first.wait_for("the hold checkpoint", |s| {
        s["checkpoint"]["reason"] == "hold"
    });
    first.ok(&["abort"]);
    first.wait_for("idle", |s| s["state"] == "idle");
    let before = std::fs::read(dir.join("checkpoint.json")).unwrap();
    // Refused for every kind of reason: a program error, a missing file, a path outside.
    let outside = dir.join("outside.nc").display().to_string();
    for program in ["broken.nc", "missing.nc", "../outside.nc", outside.as_str()] {
        let (reply, code) = first.ctl(&["run", program]);
        assert_eq!(
            (reply["ok"].as_bool(), code),
            (Some(false), 1),
            "{program}: {reply}"
        );
        assert_eq!(
            std::fs::read(dir.join("checkpoint.json")).unwrap(),
            before,
            "{program}: the checkpoint must stay byte-identical"
        );
    }
    assert!(!first.log().contains("discarded"), "{}", first.log());
    // The interrupted job goes on from where it stopped, and ends exactly.
    let reply = first.ok(&["resume"]);
    assert!(
        reply["message"].as_str().unwrap().contains("resuming"),
        "{reply}"
    );
    let idle = first.wait_for("the resumed job's end", |s| s["state"] == "idle");
    assert_eq!(idle["last_job"]["outcome"], "done", "{idle}");
    assert_eq!(ints(&idle["last_job"]["end_steps"]), PROGRAM_END.to_vec());
    // The resumed job's own log (the same file, started afresh) holds only the rest.
    assert!(moves(&dir.join("first.csv")).len() < reference.len());
    first.signal(libc::SIGTERM);
    assert_eq!(first.wait().0, 0);
}

#[test]
fn status_shows_progress_and_eta_and_monitor_prints_a_line_per_interval() {
    let dir = scratch("progress");
    let daemon = Daemon::start(&dir, &base_sets(&dir, "pulses.csv"), &[]);
    daemon.ok(&["run", PROGRAM]);
    daemon.wait_for("cutting", is_moving);
    std::thread::sleep(Duration::from_millis(1500));
    let job = daemon.wait_for("an ETA", |s| s["job"]["eta_s"].as_f64().is_some())["job"].clone();
    let progress = job["progress"].as_f64().unwrap();
    let total = job["path_total_mm"].as_f64().unwrap();
    assert!(progress > 0.0 && progress < 1.0, "{job}");
    // The program: lines, an arc and a NURBS curve, 17.13 mm of path.
    assert!((17.0..17.3).contains(&total), "{job}");
    let done = job["path_done_mm"].as_f64().unwrap();
    assert!((done - progress * total).abs() < 1e-9, "{job}");
    // The ETA is the plan's time for the path left (at most the servo's 300 mm/min), scaled
    // by the pace kept so far: at least the path left at 300 mm/min, and (the job has kept
    // up, a loaded machine's overruns aside) well within ten times that.
    let eta = job["eta_s"].as_f64().unwrap();
    let feed = job["recent_feed_mm_per_min"].as_f64().unwrap();
    assert!(feed > 0.0 && feed <= 300.0 * 1.01, "{job}");
    let fastest = (total - done) / (300.0 / 60.0);
    assert!(
        eta >= 0.25 * fastest && eta < 10.0 * fastest,
        "ETA {eta} s, the path left at 300 mm/min {fastest} s"
    );

    let out = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .args(["ctl", "--socket"])
        .arg(&daemon.socket)
        .args(["--json", "monitor", "--count", "3", "--interval", "0.2"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0));
    let lines: Vec<Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).expect("one JSON status per line"))
        .collect();
    assert_eq!(lines.len(), 3);
    assert!(lines.iter().all(|s| s["state"] == "running"), "{lines:?}");
    let p: Vec<f64> = lines
        .iter()
        .map(|s| s["job"]["progress"].as_f64().unwrap())
        .collect();
    assert!(p[0] <= p[1] && p[1] <= p[2], "progress only grows: {p:?}");
    let text = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .args(["ctl", "--socket"])
        .arg(&daemon.socket)
        .args(["monitor", "--count", "1"])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&text.stdout);
    assert!(
        text.starts_with("running ") && text.contains(" % ETA "),
        "{text}"
    );

    daemon.ok(&["abort"]);
    daemon.wait_for("idle", |s| s["state"] == "idle");
    let text = daemon.status_text();
    // Idle, the status shows where the machine stands (the DRO), in machine and work
    // coordinates; unhomed axes are marked.
    assert!(
        text.contains("machine:      X? ") && text.contains("work G54 "),
        "{text}"
    );
    // The monitor ends on its own when the daemon goes away.
    let monitor = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .args(["ctl", "--socket"])
        .arg(&daemon.socket)
        .args(["monitor", "--interval", "0.1"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(300));
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
    let out = monitor.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(0));
    assert!(String::from_utf8_lossy(&out.stderr).contains("went away"));
}

#[test]
fn after_an_output_fault_a_restart_and_resume_finish_the_job_exactly() {
    let dir = scratch("fault");
    let reference = uninterrupted(&dir);
    // The output fails 1 s into the job (20,000 ticks of 50 µs, real time).
    let mut sets = base_sets(&dir, "first.csv");
    sets.push("output.fault_at_tick=20000".to_string());
    let first = Daemon::start(&dir, &sets, &[]);
    first.ok(&["run", PROGRAM]);
    let idle = first.wait_for("the fault", |s| s["state"] == "idle");
    assert_eq!(idle["last_job"]["outcome"], "output-error", "{idle}");
    assert_eq!(idle["checkpoint"]["reason"], "error", "{idle}");
    let at = ints(&idle["checkpoint"]["position_steps"]);
    assert_ne!(at, PROGRAM_END.to_vec());
    first.signal(libc::SIGTERM);
    assert_eq!(first.wait().0, 0);

    // The fault cleared (no injection), a new daemon: resume ends on the program's end.
    let second = Daemon::start(&dir, &base_sets(&dir, "second.csv"), &[]);
    let reply = second.ok(&["resume"]);
    assert!(
        reply["message"].as_str().unwrap().contains("resuming"),
        "{reply}"
    );
    let idle = second.wait_for("the resumed job's end", |s| s["state"] == "idle");
    assert_eq!(
        idle["last_job"]["outcome"],
        "done",
        "{idle}\n{}",
        second.log()
    );
    assert_eq!(ints(&idle["last_job"]["end_steps"]), PROGRAM_END.to_vec());
    // The pulses the drives received before the fault, then after the resume: the
    // uninterrupted run's, step for step.
    assert_joined_is(&dir, &reference);
    second.signal(libc::SIGTERM);
    assert_eq!(second.wait().0, 0);
}

/// One journal entry in the native protocol: `KEY=value` lines, and `KEY`, a 64-bit
/// little-endian length and the value for values with line breaks.
fn journal_fields(mut d: &[u8]) -> std::collections::BTreeMap<String, String> {
    let mut fields = std::collections::BTreeMap::new();
    while let Some(end) = d.iter().position(|&b| b == b'\n') {
        let line = String::from_utf8_lossy(&d[..end]).into_owned();
        d = &d[end + 1..];
        match line.split_once('=') {
            Some((k, v)) => {
                fields.insert(k.to_string(), v.to_string());
            }
            None => {
                let len = u64::from_le_bytes(d[..8].try_into().unwrap()) as usize;
                let value = String::from_utf8_lossy(&d[8..8 + len]).into_owned();
                fields.insert(line, value);
                d = &d[8 + len + 1..];
            }
        }
    }
    fields
}

#[test]
fn under_systemd_log_entries_carry_their_priority_and_fields() {
    let dir = scratch("journal");
    std::fs::write(dir.join("programs/broken.nc"), "G1 X1 F60\nG1 Q7\n").unwrap();
    let journal_path = dir.join("journal.sock");
    let journal = UnixDatagram::bind(&journal_path).unwrap();
    journal
        .set_read_timeout(Some(Duration::from_millis(500)))
        .unwrap();
    // journald reads all the time; so does this thread, until the daemon has exited.
    let done = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let reader = {
        let done = done.clone();
        std::thread::spawn(move || {
            let mut entries = Vec::new();
            let mut buf = vec![0u8; 65536];
            while !done.load(std::sync::atomic::Ordering::Relaxed) {
                if let Ok(n) = journal.recv(&mut buf) {
                    entries.push(journal_fields(&buf[..n]));
                }
            }
            entries
        })
    };
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.push("log.format=\"auto\"".to_string());
    // What systemd sets when it connects stderr to the journal.
    let daemon = Daemon::start(
        &dir,
        &sets,
        &[
            ("JOURNAL_STREAM", "8:12345".to_string()),
            ("EDMD_JOURNAL_SOCKET", journal_path.display().to_string()),
        ],
    );
    let (reply, _) = daemon.ctl(&["run", "broken.nc"]);
    assert_eq!(reply["ok"], false);
    daemon.ok(&["run", PROGRAM]);
    daemon.wait_for("cutting", is_moving);
    daemon.ok(&["abort"]);
    daemon.wait_for("idle", |s| s["state"] == "idle");
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
    done.store(true, std::sync::atomic::Ordering::Relaxed);
    let entries = reader.join().unwrap();
    let find = |event: &str| {
        entries
            .iter()
            .find(|e| e.get("EDMD_EVENT").map(String::as_str) == Some(event))
            .unwrap_or_else(|| panic!("no {event} entry in {entries:#?}"))
    };
    let refusal = find("refusal");
    assert_eq!(refusal["PRIORITY"], "3");
    assert!(
        refusal["EDMD_PROGRAM"].ends_with("broken.nc"),
        "{refusal:?}"
    );
    assert!(refusal["MESSAGE"].contains("broken.nc:2:"), "{refusal:?}");
    let start = find("job_start");
    assert_eq!(start["PRIORITY"], "6");
    assert!(start["EDMD_PROGRAM"].ends_with(PROGRAM), "{start:?}");
    // The operator's abort ends the job at warning priority, not as an error.
    let end = find("job_end");
    assert_eq!(end["PRIORITY"], "4", "{end:?}");
    assert_eq!(find("checkpoint")["SYSLOG_IDENTIFIER"], "edmd");
    // The text format stayed off: entries went to the journal (or, had it stalled, to
    // stderr in the fallback form).
    assert!(
        !daemon_log_has_entries(&dir),
        "no formatted log lines on stderr"
    );
}

/// Whether the daemon's stderr log files in `dir` hold lines of the text format.
fn daemon_log_has_entries(dir: &Path) -> bool {
    std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with("serve-"))
        .any(|e| {
            std::fs::read_to_string(e.path())
                .unwrap_or_default()
                .contains(" INFO edmd::")
        })
}

/// A program whose motion comes from subroutine calls inside a loop, then a dwell and an `M0`.
const LOOP_PROGRAM: &str = "\
(edmd daemon test: subroutine calls in a loop, a dwell, a programmed stop)
G21 G90 G17
G0 X0 Y0
F600
o<leg> sub
  G91 G1 X#1 Y#2
  G90
o<leg> endsub
#<n> = 0
o1 repeat [4]
  #<n> = [#<n> + 1]
  o<leg> call [#<n> * 0.5] [0]
  o<leg> call [0] [#<n> * 0.5]
  o<leg> call [#<n> * -0.25] [0]
o1 endrepeat
G4 P0.3
G1 X0 Y10
M0
G1 X1 Y11
M2
";

#[test]
fn a_job_stopped_inside_a_subroutine_resumes_exactly_and_m0_pauses_it() {
    let dir = scratch("loop-pause");
    std::fs::write(dir.join("programs/loop.ngc"), LOOP_PROGRAM).unwrap();
    let reference = uninterrupted_run(&dir, "loop.ngc");

    // Stopped while the loop runs: the checkpoint's line is the subroutine's move.
    let first = Daemon::start(&dir, &base_sets(&dir, "first.csv"), &[]);
    first.ok(&["run", "loop.ngc"]);
    first.wait_for("cutting in the loop", |s| {
        is_moving(s) && position(s)[1] > 1000
    });
    first.signal(libc::SIGTERM);
    assert_eq!(first.wait().0, 0);
    let cp: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("checkpoint.json")).unwrap())
            .unwrap();
    assert_eq!(cp["line"], 6, "stopped inside o<leg>: {cp}");
    assert!(
        ints(&cp["position_steps"])[1] < 5000,
        "stopped too late: {cp}"
    );

    // Resumed by a new daemon: the replay rebuilds the loop count and the call, so the job
    // goes on from the very step, then the M0 holds it before line 19.
    let second = Daemon::start(&dir, &base_sets(&dir, "second.csv"), &[]);
    second.ok(&["resume"]);
    let paused = second.wait_for("the M0 pause", |s| s["state"] == "paused");
    assert_eq!(paused["job"]["paused_before_line"], 19, "{paused}");
    assert_eq!(position(&paused), vec![0, 10000]);
    let cp = second.wait_for("the pause's checkpoint", |s| {
        s["checkpoint"]["reason"] == "hold"
    });
    assert_eq!(ints(&cp["checkpoint"]["position_steps"]), vec![0, 10000]);
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(
        position(&second.status()),
        vec![0, 10000],
        "moved while paused"
    );
    let text = second.status_text();
    assert!(text.contains("state:        paused"), "{text}");
    assert!(text.contains("before line 19"), "{text}");
    second.ok(&["resume"]);
    let idle = second.wait_for("the end", |s| s["state"] == "idle");
    assert_eq!(idle["last_job"]["outcome"], "done", "{idle}");
    assert_eq!(ints(&idle["last_job"]["end_steps"]), vec![1000, 11000]);

    assert_joined_is(&dir, &reference);
    second.signal(libc::SIGTERM);
    assert_eq!(second.wait().0, 0);
}

/// A short that outlasts `servo.max_short_s` holds the job instead of ending it: a hold
/// checkpoint, the alarm in the log; once the gap is clear `resume` re-advances and the job
/// ends exactly on the program's end point.
#[test]
fn a_long_short_holds_the_job_and_resume_finishes_it() {
    let dir = scratch("long-short");
    // Shorted from 0.5 s to 3 s of the job's time (ticks of 50 µs).
    std::fs::write(dir.join("gap.txt"), "0 normal\n10000 short\n60000 normal\n").unwrap();
    let mut sets = script_sets(&dir, "pulses.csv");
    sets.push("servo.max_short_s=0.5".into());
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["run", PROGRAM]);
    let held = daemon.wait_for("the alarm's hold", |s| {
        s["state"] == "held" && s["job"]["servo"] == "alarm"
    });
    assert_eq!(held["job"]["alarms"], 1, "{held}");
    let cp = daemon.wait_for("the hold checkpoint", |s| {
        s["checkpoint"]["reason"] == "hold"
    });
    assert_eq!(ints(&cp["checkpoint"]["position_steps"]), position(&held));
    daemon.wait_for_log("the short outlasted servo.max_short_s");
    // Wait for the script's short to be over (3 s of job time), then resume.
    daemon.wait_for("the gap to clear", |s| {
        s["job"]["ticks"].as_u64().unwrap_or(0) > 62_000
    });
    daemon.resume_to_the_end(&PROGRAM_END);
}

/// A short during a rapid holds the daemon's job (a collision: no turn-back), and `resume`
/// carries on to the end once the contact is gone.
#[test]
fn a_collision_in_a_rapid_holds_the_job() {
    let dir = scratch("collision");
    std::fs::write(
        dir.join("programs/rapid.ngc"),
        "G21 G90\nG0 X20\nG1 X20.5 F60\nG0 X0\nM2\n",
    )
    .unwrap();
    // Contact 0.25 s into the first rapid, for 1 s.
    std::fs::write(dir.join("gap.txt"), "0 normal\n5000 short\n25000 normal\n").unwrap();
    let sets = script_sets(&dir, "pulses.csv");
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["run", "rapid.ngc"]);
    let held = daemon.wait_for("the collision's hold", |s| s["state"] == "held");
    assert_eq!(held["job"]["collisions"], 1, "{held}");
    assert_eq!(held["job"]["shorts"], 0, "no turn-back: {held}");
    let x = position(&held)[0];
    assert!((4000..6000).contains(&x), "stopped at {x} steps");
    daemon.wait_for_log("COLLISION");
    daemon.wait_for("the contact to clear", |s| {
        s["job"]["ticks"].as_u64().unwrap_or(0) > 26_000
    });
    assert_eq!(position(&daemon.status())[0], x, "moved while held");
    daemon.resume_to_the_end(&[0, 0]);
}

/// `edmd run --checkpoint FILE`: a job that ends on an alarm (a short longer than
/// `servo.max_short_s`) exits 1 and leaves a checkpoint where the electrode stands; a daemon
/// with that file as its checkpoint resumes the job and ends it on the program's end point,
/// the two pulse logs together being the uninterrupted run's, step for step.
#[test]
fn an_alarm_in_edmd_run_leaves_a_checkpoint_the_daemon_resumes() {
    let dir = scratch("run-checkpoint");
    let reference = uninterrupted(&dir);
    std::fs::write(dir.join("gap.txt"), "0 normal\n20000 short\n").unwrap();
    let checkpoint = dir.join("checkpoint.json");
    let out = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .arg("run")
        .arg(dir.join("programs").join(PROGRAM))
        .arg("--checkpoint")
        .arg(&checkpoint)
        .args([
            "--set",
            "gap.kind=\"script\"",
            "--set",
            "servo.max_short_s=0.2",
        ])
        .arg("--set")
        .arg(format!("gap.script=\"{}\"", dir.join("gap.txt").display()))
        .args(["--set", "output.kind=\"file\""])
        .arg("--set")
        .arg(format!(
            "output.path=\"{}\"",
            dir.join("first.csv").display()
        ))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("the short outlasted servo.max_short_s"),
        "{stderr}"
    );
    assert!(stderr.contains("checkpoint written to"), "{stderr}");
    let cp: Value = serde_json::from_str(&std::fs::read_to_string(&checkpoint).unwrap()).unwrap();
    assert_eq!(
        (cp["reason"].as_str(), cp["still"].as_bool()),
        (Some("alarm"), Some(true))
    );

    let daemon = Daemon::start(&dir, &base_sets(&dir, "second.csv"), &[]);
    assert_eq!(daemon.status()["checkpoint"]["reason"], "alarm");
    daemon.resume_to_the_end(&PROGRAM_END);
    // The resumed run's moves are the rest of the uninterrupted run's, step for step.
    let second = moves(&dir.join("second.csv"));
    assert!(
        reference.ends_with(&second),
        "the resumed run is not the rest of the path"
    );
}

/// A wire break (scripted on the wire-break input) holds the job where it broke; `resume` is
/// refused until a rethread; `rethread` goes back along the cut path with the spark off to
/// the start hole (the end of the rapid) and parks for threading; `resume` returns along the
/// path to the break point and the job ends exactly on the program's end point, every step
/// of the way back matched by one on the way forward.
#[test]
fn a_wire_break_holds_rethread_returns_to_the_start_hole_and_resume_finishes_exactly() {
    let dir = scratch("wire-break");
    std::fs::write(dir.join("programs/contour.ngc"), CONTOUR).unwrap();
    // The wire breaks 1.4 s into the job (ticks of 50 µs): on the second cut.
    std::fs::write(dir.join("gap.txt"), "0 normal\n28000 wire-break\n").unwrap();
    let sets = script_sets(&dir, "pulses.csv");
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["run", "contour.ngc"]);
    let broken = daemon.wait_for("the wire break's hold", |s| {
        s["state"] == "wire-break" && s["job"]["feed_mm_per_min"] == 0.0
    });
    assert_eq!(broken["job"]["wire_breaks"], 1, "{broken}");
    let at_break = position(&broken);
    assert_eq!(at_break[0], 6000, "on the second cut: {broken}");
    assert!((1..4000).contains(&at_break[1]), "{broken}");
    daemon.wait_for_log("WIRE BREAK");
    daemon.wait_for("the hold checkpoint", |s| {
        s["checkpoint"]["reason"] == "hold" && s["checkpoint"]["still"] == true
    });
    let (refused, code) = daemon.ctl(&["resume"]);
    assert_eq!(
        (refused["ok"].as_bool(), code),
        (Some(false), 1),
        "{refused}"
    );
    assert!(
        refused["error"].as_str().unwrap().contains("rethread"),
        "{refused}"
    );
    assert_eq!(position(&daemon.status()), at_break, "moved while broken");

    daemon.ok(&["rethread"]);
    let threading = daemon.wait_for("the start hole", |s| s["state"] == "threading");
    assert_eq!(position(&threading), vec![1000, 0], "{threading}");
    daemon.wait_for_log("thread the wire, then `edmd ctl resume`");
    daemon.resume_to_the_end(&CONTOUR_END);

    // The pulse record: 1 mm of rapid, the cut to the break, back to X1 Y0 and forward
    // again to the break (spark off both ways), the rest of the cut: every pulse accounted.
    let yb = at_break[1];
    let (_, rows) = read_pulse_log(&dir.join("pulses.csv")).unwrap();
    let moving: Vec<_> = rows
        .iter()
        .filter(|r| r.steps.iter().any(|&s| s != 0))
        .collect();
    let pulses = |axis: usize| -> i64 { moving.iter().map(|r| r.steps[axis].abs() as i64).sum() };
    assert_eq!(
        (pulses(0), pulses(1)),
        (1000 + 5000 + 4000 + 2 * 5000, 4000 + 2 * yb)
    );
    // A row's spark is the one in force after its step: the step that arrives where
    // cutting starts (the rapid's last, the return's last) already carries the spark.
    let spark_off = moving.iter().filter(|r| !r.spark).count() as i64;
    let expected = 1000 + 2 * (5000 + yb);
    assert!(
        (expected - 2..=expected).contains(&spark_off),
        "{spark_off} spark-off steps: rapid, way back and return are {expected}"
    );
}

/// `ctl run --wait-end` returns when the job ends: 0 and its outcome when it ended done, 1
/// and the outcome when it did not (an abort from another shell).
#[test]
fn ctl_run_wait_end_returns_at_the_jobs_end_with_its_outcome() {
    let dir = scratch("wait-end");
    std::fs::write(dir.join("programs/contour.ngc"), CONTOUR).unwrap();
    let daemon = Daemon::start(&dir, &base_sets(&dir, "pulses.csv"), &[]);
    let ctl = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_edmd"))
            .args(["ctl", "--socket"])
            .arg(&daemon.socket)
            .args(args)
            .output()
            .unwrap()
    };
    let out = ctl(&["run", "contour.ngc", "--wait-end"]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{stdout}");
    // The verdict, then the end: the job is over when ctl returns.
    assert!(stdout.contains("running"), "{stdout}");
    assert!(stdout.contains("contour.ngc: done after"), "{stdout}");
    let status = daemon.status();
    assert_eq!(status["state"], "idle");
    assert_eq!(status["last_job"]["end_steps"][0], CONTOUR_END[0]);

    // The long program, aborted from another shell while ctl waits.
    let waiting = std::thread::scope(|s| {
        let waiting = s.spawn(|| ctl(&["run", PROGRAM, "--wait-end"]));
        daemon.wait_for("the job", |s| s["state"] == "running");
        daemon.ok(&["abort"]);
        waiting.join().unwrap()
    });
    let stderr = String::from_utf8_lossy(&waiting.stderr);
    assert_eq!(waiting.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("stopped after"), "{stderr}");
    // --wait-end and --no-wait ask opposite things.
    let both = ctl(&["run", PROGRAM, "--wait-end", "--no-wait"]);
    assert_eq!(both.status.code(), Some(2));
}

/// An aborted job's checkpoint outlives another program's job: kept aside while it runs, the
/// checkpoint again once it is done, resumed then to the aborted job's end. A third program
/// is refused while two stopped jobs wait (the same program started again replaces its own);
/// `discard` asks for a confirmation and brings the kept one back.
#[test]
fn an_aborted_jobs_checkpoint_is_kept_across_another_job_until_discarded() {
    let dir = scratch("kept-checkpoint");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    std::fs::write(dir.join("programs/contour.ngc"), CONTOUR).unwrap();
    std::fs::write(
        dir.join("programs/other.ngc"),
        format!("(other)\n{CONTOUR}"),
    )
    .unwrap();
    let daemon = Daemon::start(&dir, &base_sets(&dir, "pulses.csv"), &[]);
    daemon.ok(&["run", PROGRAM]);
    daemon.wait_for("moving", is_moving);
    let aborted = daemon.hold_abort_checkpoint(&dir);
    assert_eq!(
        aborted["program"].as_str().map(|p| p.ends_with(".nc")),
        Some(true)
    );

    // Another program: the aborted job's checkpoint is kept aside, not discarded.
    let reply = daemon.ok(&["run", "contour.ngc"]);
    assert!(
        reply["message"].as_str().unwrap().contains("is kept"),
        "{reply}"
    );
    let s = daemon.status();
    assert_eq!(s["kept_checkpoint"]["line"], aborted["line"], "{s}");
    let s = daemon.wait_for("the contour's end", |s| {
        s["state"] == "idle" && s["last_job"]["outcome"] == "done"
    });
    // Done: the aborted job's checkpoint is the checkpoint again, on disk too.
    assert_eq!(s["checkpoint"]["line"], aborted["line"], "{s}");
    assert!(s.get("kept_checkpoint").is_none(), "{s}");
    let on_disk: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("checkpoint.json")).unwrap())
            .unwrap();
    assert_eq!(on_disk["position_steps"], aborted["position_steps"]);

    // The contour again, aborted too: two stopped jobs, and a third program is refused.
    daemon.ok(&["run", "contour.ngc"]);
    daemon.wait_for("moving", is_moving);
    daemon.hold_abort_checkpoint(&dir);
    daemon.refused(&["run", "other.ngc"], "are both resumable");
    // Discard asks for a confirmation, then brings the kept checkpoint back.
    daemon.refused(&["discard"], "cannot be undone");
    let reply = daemon.ok(&["discard", "--yes"]);
    assert!(
        reply["message"]
            .as_str()
            .unwrap()
            .contains("is the checkpoint again"),
        "{reply}"
    );
    let s = daemon.status();
    assert_eq!(s["checkpoint"]["line"], aborted["line"], "{s}");
    // The machine moved since (the contour): the operator confirms where it stands.
    daemon.ok(&["mdi", "G90 G0 X0 Y0"]);
    daemon.wait_for("idle", |s| s["state"] == "idle");
    let back: Vec<String> = ints(&aborted["position_steps"])
        .iter()
        .zip(["X", "Y"])
        .map(|(s, a)| format!("{a}{:.3}", *s as f64 / 1000.0))
        .collect();
    daemon.ok(&["mdi", &format!("G0 {}", back.join(" "))]);
    daemon.wait_for("idle", |s| s["state"] == "idle");
    daemon.resume_to_the_end(&PROGRAM_END);
}
