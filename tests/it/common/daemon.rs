//! The real `edmd serve` on a temporary socket, driven by the real `edmd ctl`, for the
//! integration tests that need a daemon (`tests/it/daemon.rs`, `tests/it/hardening.rs`).
//!
//! Jobs run in real time (`fine.virtual_time=false`) at a feed that makes
//! `tests/data/runtime-path.nc` last a few seconds, so there is time to hold, stop and
//! resume it; the gap is always normal (`gap.kind="none"`) so runs are comparable pulse by
//! pulse, and the pulses go to a pulse log that the tests read back.

#![allow(dead_code)]

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

use edmd::output::read_pulse_log;

pub const PROGRAM: &str = "runtime-path.nc";
/// The program's end in steps (1 µm).
pub const PROGRAM_END: [i64; 2] = [7500, 8250];
/// A wire-cut contour from a start hole at X1: a rapid, three cuts, in about 3 s.
pub const CONTOUR: &str = "G21 G90\nG0 X1\nG1 X6 F300\nG1 Y4\nG1 X2\nM2\n";
/// Its end in steps.
pub const CONTOUR_END: [i64; 2] = [2000, 4000];

pub fn scratch(name: &str) -> PathBuf {
    let dir = super::scratch("daemon", name);
    let programs = dir.join("programs");
    std::fs::create_dir_all(&programs).unwrap();
    std::fs::copy(
        super::repo().join("tests/data").join(PROGRAM),
        programs.join(PROGRAM),
    )
    .unwrap();
    let _ = std::fs::remove_file(dir.join("checkpoint.json"));
    dir
}

/// A running `edmd serve`; killed if a test fails before it stops it.
pub struct Daemon {
    pub child: Child,
    pub socket: PathBuf,
    pub log: PathBuf,
    /// A share of the test machine's cores while the daemon lives.
    _machine: super::MachineHold,
}

/// The `--set` arguments every daemon of `dir` runs with.
pub fn base_sets(dir: &Path, pulses: &str) -> Vec<String> {
    vec![
        format!("daemon.socket=\"{}\"", dir.join("edmd.sock").display()),
        format!("daemon.program_dir=\"{}\"", dir.join("programs").display()),
        format!(
            "daemon.checkpoint=\"{}\"",
            dir.join("checkpoint.json").display()
        ),
        // The job history, the hour counters and the reports.
        format!("daemon.state_dir=\"{}\"", dir.display()),
        "daemon.status_interval_s=0.5".to_string(),
        "daemon.checkpoint_interval_s=0.5".to_string(),
        "fine.virtual_time=false".to_string(),
        // Many daemons run at once on the test machine: at the normal scheduler and with
        // pageable memory. The shipped real-time settings are the load test's (load.rs) and
        // the HAL benches'.
        "fine.rt_priority=0".to_string(),
        "fine.lock_memory=false".to_string(),
        // Ten ticks per wake-up: a virtual machine's timer wake-ups cost tens of µs each, and
        // twenty thousand a second took most of a core per daemon in the kernel; the pulse
        // file does not mind bursts. The HAL tests and the load test wake at every tick.
        "fine.ticks_per_wake=10".to_string(),
        "gap.kind=\"none\"".to_string(),
        "output.kind=\"file\"".to_string(),
        format!("output.path=\"{}\"", dir.join(pulses).display()),
        "servo.normal_feed_mm_per_min=300.0".to_string(),
        "log.format=\"plain\"".to_string(),
        // No home switches: `home --here` makes where the machine stands machine zero.
        "homing.axis=[]".to_string(),
    ]
}

pub static DAEMONS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

impl Daemon {
    /// A daemon that `child` started (`halrun` loading `edmd serve`), reached at `socket`,
    /// `child`'s output in `log`: waits for the socket.
    pub fn adopt(child: Child, socket: PathBuf, log: PathBuf) -> Daemon {
        let daemon = Daemon {
            child,
            socket,
            log,
            _machine: super::MachineHold::share(),
        };
        let deadline = Instant::now() + Duration::from_secs(30);
        while UnixStream::connect(&daemon.socket).is_err() {
            assert!(
                Instant::now() < deadline,
                "no socket; log:\n{}",
                daemon.log()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        daemon
    }

    pub fn start(dir: &Path, sets: &[String], env: &[(&str, String)]) -> Daemon {
        Daemon::start_args(dir, &[], sets, env)
    }

    /// `edmd serve ARGS --set SETS...` in `dir` with `env`, its log in `dir/serve-N.log`.
    pub fn start_args(
        dir: &Path,
        args: &[String],
        sets: &[String],
        env: &[(&str, String)],
    ) -> Daemon {
        let n = DAEMONS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let log = dir.join(format!("serve-{n}.log"));
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_edmd"));
        cmd.arg("serve")
            .args(args)
            .current_dir(dir)
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).unwrap())
            .env_remove("NOTIFY_SOCKET")
            .env_remove("WATCHDOG_USEC")
            .env_remove("RUST_LOG");
        for s in sets {
            cmd.args(["--set", s]);
        }
        for (k, v) in env {
            cmd.env(k, v);
        }
        let child = cmd.spawn().expect("edmd serve starts");
        Daemon::adopt(child, dir.join("edmd.sock"), log)
    }

    pub fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// `resume`, then waits for the job to end done at `end` (steps), and stops the daemon.
    pub fn resume_to_the_end(self, end: &[i64]) {
        self.ok(&["resume"]);
        let idle = self.wait_for("the job's end", |s| s["state"] == "idle");
        assert_eq!(
            idle["last_job"]["outcome"],
            "done",
            "{idle}\n{}",
            self.log()
        );
        assert_eq!(ints(&idle["last_job"]["end_steps"]), end.to_vec());
        self.signal(libc::SIGTERM);
        assert_eq!(self.wait().0, 0);
    }

    /// Holds the running job, aborts it and returns the checkpoint it left (in `dir`).
    pub fn hold_abort_checkpoint(&self, dir: &Path) -> Value {
        self.ok(&["hold"]);
        self.wait_for("held", |s| s["state"] == "held");
        self.ok(&["abort"]);
        self.wait_for("idle", |s| s["state"] == "idle");
        let text = std::fs::read_to_string(dir.join("checkpoint.json")).unwrap();
        serde_json::from_str(&text).unwrap()
    }

    /// Waits until the log holds `needle` (the supervisor logs events a little after the
    /// status shows them).
    pub fn wait_for_log(&self, needle: &str) {
        let deadline = Instant::now() + Duration::from_secs(10);
        while !self.log().contains(needle) {
            assert!(
                Instant::now() < deadline,
                "no {needle:?} in the log:\n{}",
                self.log()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// `edmd ctl --socket S --json ARGS`: the reply and the exit code.
    pub fn ctl(&self, args: &[&str]) -> (Value, i32) {
        let out = Command::new(env!("CARGO_BIN_EXE_edmd"))
            .arg("ctl")
            .arg("--socket")
            .arg(&self.socket)
            .arg("--json")
            .args(args)
            .output()
            .expect("edmd ctl runs");
        let text = String::from_utf8_lossy(&out.stdout);
        let reply = serde_json::from_str(text.trim()).unwrap_or_else(|e| {
            panic!(
                "ctl {args:?}: {e}: {text:?} {}",
                String::from_utf8_lossy(&out.stderr)
            )
        });
        (reply, out.status.code().unwrap_or(-1))
    }

    pub fn ok(&self, args: &[&str]) -> Value {
        let (reply, code) = self.ctl(args);
        assert_eq!(
            reply["ok"],
            true,
            "ctl {args:?}: {reply}\nlog:\n{}",
            self.log()
        );
        assert_eq!(code, 0);
        reply
    }

    /// `ctl ARGS` is refused with an error that contains `needle`.
    pub fn refused(&self, args: &[&str], needle: &str) -> Value {
        let (reply, code) = self.ctl(args);
        assert_eq!(code, 1, "ctl {args:?}: {reply}");
        let error = reply["error"].as_str().unwrap_or_default();
        assert!(error.contains(needle), "ctl {args:?}: {reply}");
        reply
    }

    /// `edmd ctl status` as the operator reads it (text).
    pub fn status_text(&self) -> String {
        let out = Command::new(env!("CARGO_BIN_EXE_edmd"))
            .args(["ctl", "status", "--socket"])
            .arg(&self.socket)
            .output()
            .expect("edmd ctl runs");
        String::from_utf8_lossy(&out.stdout).into_owned()
    }

    pub fn status(&self) -> Value {
        self.ok(&["status"])["status"].clone()
    }

    /// Polls the status until `pred` holds (a minute at most).
    pub fn wait_for(&self, what: &str, pred: impl Fn(&Value) -> bool) -> Value {
        self.wait_for_within(what, Duration::from_secs(60), pred)
    }

    /// Polls the status until `pred` holds, `limit` at most.
    pub fn wait_for_within(
        &self,
        what: &str,
        limit: Duration,
        pred: impl Fn(&Value) -> bool,
    ) -> Value {
        let deadline = Instant::now() + limit;
        loop {
            let status = self.status();
            if pred(&status) {
                return status;
            }
            assert!(
                Instant::now() < deadline,
                "waiting for {what}: {status}\nlog:\n{}",
                self.log()
            );
            std::thread::sleep(Duration::from_millis(25));
        }
    }

    pub fn signal(&self, signal: i32) {
        // SAFETY: kill(2) on our own child's pid.
        let rc = unsafe { libc::kill(self.child.id() as i32, signal) };
        assert_eq!(rc, 0);
    }

    /// Waits for the process to end; its exit code.
    pub fn wait(mut self) -> (i32, String) {
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                return (status.code().unwrap_or(-1), self.log());
            }
            assert!(
                Instant::now() < deadline,
                "daemon did not exit:\n{}",
                self.log()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

pub fn position(status: &Value) -> Vec<i64> {
    status["job"]["position_steps"]
        .as_array()
        .expect("a job")
        .iter()
        .map(|v| v.as_i64().unwrap())
        .collect()
}

pub fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap_or_else(|| panic!("not an array: {v}"))
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

pub fn ints(v: &Value) -> Vec<i64> {
    v.as_array()
        .unwrap_or_else(|| panic!("not an array: {v}"))
        .iter()
        .map(|x| x.as_i64().unwrap())
        .collect()
}

/// The steps of a pulse log: one vector per moving tick, in order.
pub fn moves(path: &Path) -> Vec<Vec<i8>> {
    let (_, rows) = read_pulse_log(path).unwrap();
    rows.into_iter()
        .map(|r| r.steps)
        .filter(|s| s.iter().any(|&x| x != 0))
        .collect()
}

/// The reference: the same program uninterrupted through `edmd run` (virtual time).
/// [`base_sets`] with the gap read from the script `dir/gap.txt`.
pub fn script_sets(dir: &Path, pulses: &str) -> Vec<String> {
    let mut sets = base_sets(dir, pulses);
    sets.retain(|s| !s.starts_with("gap.kind"));
    sets.push("gap.kind=\"script\"".into());
    sets.push(format!("gap.script=\"{}\"", dir.join("gap.txt").display()));
    sets
}

/// The stopped run's pulses (`first.csv`) followed by the resumed run's (`second.csv`) are,
/// step for step, the uninterrupted run's.
pub fn assert_joined_is(dir: &Path, reference: &[Vec<i8>]) {
    let mut joined = moves(&dir.join("first.csv"));
    joined.extend(moves(&dir.join("second.csv")));
    assert_eq!(joined.len(), reference.len());
    assert!(joined == reference, "the pulse sequences differ");
}

pub fn uninterrupted(dir: &Path) -> Vec<Vec<i8>> {
    uninterrupted_run(dir, PROGRAM)
}

/// The pulses of `edmd run` on `program` (in `dir/programs`), uninterrupted.
pub fn uninterrupted_run(dir: &Path, program: &str) -> Vec<Vec<i8>> {
    let pulses = dir.join("reference.csv");
    let out = super::run_to_pulse_log(&dir.join("programs").join(program), &pulses, &[]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    moves(&pulses)
}

pub fn is_moving(s: &Value) -> bool {
    s["state"] == "running" && s["job"]["position_steps"][0].as_i64().unwrap_or(0) > 300
}

/// Sends raw lines on one connection and reads one reply per line.
pub fn raw_exchange(socket: &Path, lines: &[&str]) -> Vec<Value> {
    let stream = UnixStream::connect(socket).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(30)))
        .unwrap();
    let mut writer = stream.try_clone().unwrap();
    let mut reader = BufReader::new(stream);
    lines
        .iter()
        .map(|line| {
            writer.write_all(line.as_bytes()).unwrap();
            writer.write_all(b"\n").unwrap();
            let mut answer = String::new();
            reader.read_line(&mut answer).unwrap();
            serde_json::from_str(&answer).unwrap()
        })
        .collect()
}

/// One request and its reply on an open connection.
pub fn exchange(stream: &UnixStream, line: &str) -> Value {
    let mut writer = stream;
    writeln!(writer, "{line}").unwrap();
    let mut answer = String::new();
    BufReader::new(stream).read_line(&mut answer).unwrap();
    serde_json::from_str(&answer).unwrap()
}
