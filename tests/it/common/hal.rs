//! A HAL bench: LinuxCNC's real HAL (Debian's `linuxcnc-uspace`) started by `halrun` on the
//! shipped `config/hal/sim.hal`, which loads `edmd serve` as a component beside two
//! `stepgen`s. The tests read and drive pins with `halcmd`, and talk to edmd on its socket.
//!
//! HAL is one per machine: only one bench may be up at a time. The HAL tests take turns by a
//! file lock ([`HalBench::start`] holds it for the bench's life), so a test runner may run
//! them as threads or processes.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::time::{Duration, Instant};

use super::daemon::Daemon;

/// The uid `rtapi_app` falls back to when started as root (it refuses root itself).
const RTAPI_UID: &str = "65534";

/// Whether the HAL tests run: `EDMD_HAL_TESTS=1` (CI sets it, having installed
/// linuxcnc-uspace), and `halrun` is there. A skip says why.
pub fn enabled(test: &str) -> bool {
    if std::env::var_os("EDMD_HAL_TESTS").is_none() {
        eprintln!("{test}: skipped: EDMD_HAL_TESTS is not set (needs Debian's linuxcnc-uspace)");
        return false;
    }
    let found = Command::new("halrun")
        .arg("-h")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok();
    assert!(
        found,
        "EDMD_HAL_TESTS is set but halrun is not installed (apt install linuxcnc-uspace)"
    );
    true
}

pub struct HalBench {
    pub dir: PathBuf,
    /// `edmd serve`, loaded by `halrun` (the child).
    pub daemon: Option<Daemon>,
    stdin: Option<ChildStdin>,
    /// This bench's turn at HAL (dropped last).
    _turn: std::fs::File,
}

/// A turn at HAL for the calling test: no other bench is up while it is held.
pub fn turn() -> std::fs::File {
    let turn = std::fs::File::options()
        .create(true)
        .truncate(false)
        .write(true)
        .open(std::env::temp_dir().join("edmd-tests-hal.lock"))
        .expect("the HAL lock file opens");
    turn.lock().expect("HAL's turn");
    turn
}

impl HalBench {
    /// `halrun -I -f config/hal/sim.hal` in a scratch directory holding the shipped
    /// `config/hal/sim.toml` with its paths moved there and each `(text, replacement)` of
    /// `edits` made, and `programs` (name, text).
    pub fn start(name: &str, edits: &[(&str, &str)], programs: &[(&str, &str)]) -> HalBench {
        HalBench::start_as(name, edits, programs, false)
    }

    /// As a service runs it (`systemd/edmd-hal.service`): `halrun -f` on `sim.hal` ending in
    /// `loadusr -w edmd hal-wait`, no prompt; HAL stays up while edmd runs. Right after edmd's
    /// `loadusr -W`, a `loadusr -w edmd ctl status` must find the control socket listening
    /// (else `halcmd` stops the file there and the bench never comes up).
    pub fn start_service(
        name: &str,
        edits: &[(&str, &str)],
        programs: &[(&str, &str)],
    ) -> HalBench {
        HalBench::start_as(name, edits, programs, true)
    }

    fn start_as(
        name: &str,
        edits: &[(&str, &str)],
        programs: &[(&str, &str)],
        service: bool,
    ) -> HalBench {
        let turn = turn();
        let dir = super::scratch("hal", name);
        let home = dir.join("home");
        std::fs::create_dir_all(dir.join("config/hal")).unwrap();
        std::fs::create_dir_all(dir.join("programs")).unwrap();
        std::fs::create_dir_all(&home).unwrap();
        let _ = std::fs::remove_file(dir.join("checkpoint.json"));
        let _ = std::fs::remove_file(dir.join("machine-state.json"));
        // rtapi_app, running as RTAPI_UID, keeps its socket under $HOME.
        let chowned = Command::new("chown")
            .args([RTAPI_UID, home.to_str().unwrap()])
            .status()
            .unwrap();
        assert!(chowned.success());
        let shipped = std::fs::read_to_string(super::repo().join("config/hal/sim.toml")).unwrap();
        let mut config = shipped.replace("/tmp/edmd-hal", dir.to_str().unwrap());
        for (text, replacement) in edits {
            assert!(config.contains(text), "sim.toml has no {text:?}");
            config = config.replace(text, replacement);
        }
        std::fs::write(dir.join("config/hal/sim.toml"), config).unwrap();
        for (name, text) in programs {
            std::fs::write(dir.join("programs").join(name), text).unwrap();
        }
        // Whatever a bench that died left behind.
        let _ = hal_command("halrun", &["-U"], &home);
        let log = dir.join("halrun.log");
        let bin = PathBuf::from(env!("CARGO_BIN_EXE_edmd"));
        let path = format!(
            "{}:{}",
            bin.parent().unwrap().display(),
            std::env::var("PATH").unwrap_or_default()
        );
        let hal_file = if service {
            let sim = std::fs::read_to_string(super::repo().join("config/hal/sim.hal")).unwrap();
            let socket = dir.join("edmd.sock");
            let load = "loadusr -Wn edmd edmd serve --config config/hal/sim.toml\n";
            assert!(sim.contains(load), "sim.hal loads edmd as {load:?}");
            let sim = sim.replace(
                load,
                &format!(
                    "{load}loadusr -w edmd ctl --socket {} status\n",
                    socket.display()
                ),
            );
            let file = dir.join("machine.hal");
            std::fs::write(
                &file,
                sim + "loadusr -w edmd hal-wait --config config/hal/sim.toml\n",
            )
            .unwrap();
            file
        } else {
            super::repo().join("config/hal/sim.hal")
        };
        let mut child: Child = Command::new("halrun")
            .args(if service {
                &["-f"][..]
            } else {
                &["-I", "-f"][..]
            })
            .arg(hal_file)
            .current_dir(&dir)
            .env("RTAPI_UID", RTAPI_UID)
            .env("HOME", &home)
            .env("PATH", path)
            .env("RUST_LOG", "info")
            .env_remove("NOTIFY_SOCKET")
            .stdin(if service {
                Stdio::null()
            } else {
                Stdio::piped()
            })
            .stdout(std::fs::File::create(&log).unwrap())
            .stderr(std::fs::File::options().append(true).open(&log).unwrap())
            .spawn()
            .expect("halrun starts");
        let stdin = child.stdin.take();
        let daemon = Daemon::adopt(child, dir.join("edmd.sock"), log);
        let bench = HalBench {
            dir,
            daemon: Some(daemon),
            stdin,
            _turn: turn,
        };
        // The HAL file sets edmd.estop-ok-in after edmd is up: until then the E-stop input
        // reads false, and a daemon that read it so (an E-stop at power-up) waits for reset,
        // as a machine would.
        let deadline = Instant::now() + Duration::from_secs(20);
        while bench.getp("edmd.estop-ok-in") != "TRUE" {
            assert!(
                Instant::now() < deadline,
                "the HAL file never set estop-ok-in"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        if bench.daemon().status()["state"] == "estop" {
            bench.daemon().ok(&["reset"]);
        }
        bench
    }

    pub fn daemon(&self) -> &Daemon {
        self.daemon.as_ref().expect("up")
    }

    /// A pin's or parameter's value as `halcmd getp` prints it.
    pub fn getp(&self, name: &str) -> String {
        hal_command("halcmd", &["getp", name], &self.dir.join("home"))
            .unwrap_or_else(|e| panic!("halcmd getp {name}: {e}"))
    }

    pub fn getp_f64(&self, name: &str) -> f64 {
        let text = self.getp(name);
        text.parse()
            .unwrap_or_else(|_| panic!("{name} = {text:?} is not a number"))
    }

    pub fn setp(&self, name: &str, value: &str) {
        hal_command("halcmd", &["setp", name, value], &self.dir.join("home"))
            .unwrap_or_else(|e| panic!("halcmd setp {name} {value}: {e}"));
    }

    /// Any `halcmd` command (`unlinkp`, `net`, …).
    pub fn halcmd(&self, args: &[&str]) {
        hal_command("halcmd", args, &self.dir.join("home"))
            .unwrap_or_else(|e| panic!("halcmd {args:?}: {e}"));
    }

    pub fn log(&self) -> String {
        std::fs::read_to_string(self.dir.join("halrun.log")).unwrap_or_default()
    }

    /// What `halcmd ARGS` prints (standard output), or why it failed.
    pub fn halcmd_output(&self, args: &[&str]) -> Result<String, String> {
        hal_command("halcmd", args, &self.dir.join("home"))
    }

    /// The pid of the edmd holding the component, from its owner record.
    pub fn edmd_pid(&self) -> u32 {
        let record = self.dir.join("state/hal-edmd.json");
        let text = std::fs::read_to_string(&record)
            .unwrap_or_else(|e| panic!("{}: {e}", record.display()));
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        v["pid"].as_u64().unwrap() as u32
    }

    /// `edmd hal-reap`, then `loadusr -Wn edmd edmd serve --config config/hal/sim.toml` into
    /// the running HAL, as its file does, edmd's log going to the bench's; returns once edmd is
    /// ready.
    pub fn load_edmd_again(&self) {
        self.loadusr(&["-w", "edmd", "hal-reap"]);
        self.loadusr(&["-Wn", "edmd", "edmd", "serve"]);
    }

    /// `edmd serve --config config/hal/sim.toml` started directly (not by `loadusr`), as an
    /// operator might: its exit code and what it said, once it ended (10 s at most).
    pub fn serve_directly(&self) -> (Option<i32>, String) {
        let mut child = Command::new(env!("CARGO_BIN_EXE_edmd"))
            .args(["serve", "--config", "config/hal/sim.toml"])
            .current_dir(&self.dir)
            .env("RTAPI_UID", RTAPI_UID)
            .env("HOME", self.dir.join("home"))
            .env_remove("NOTIFY_SOCKET")
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let deadline = Instant::now() + Duration::from_secs(10);
        while child.try_wait().unwrap().is_none() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = child.kill();
        let out = child.wait_with_output().unwrap();
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    }

    /// `halcmd loadusr ARGS --config config/hal/sim.toml` from the bench's folder, with edmd
    /// on the `PATH` and the program's output in the bench's log.
    fn loadusr(&self, args: &[&str]) {
        let bin = PathBuf::from(env!("CARGO_BIN_EXE_edmd"));
        let log = std::fs::File::options()
            .append(true)
            .open(self.dir.join("halrun.log"))
            .unwrap();
        let status = Command::new("halcmd")
            .arg("loadusr")
            .args(args)
            .args(["--config", "config/hal/sim.toml"])
            .current_dir(&self.dir)
            .env("RTAPI_UID", RTAPI_UID)
            .env("HOME", self.dir.join("home"))
            .env(
                "PATH",
                format!(
                    "{}:{}",
                    bin.parent().unwrap().display(),
                    std::env::var("PATH").unwrap_or_default()
                ),
            )
            .env("RUST_LOG", "info")
            .env_remove("NOTIFY_SOCKET")
            .stdout(log.try_clone().unwrap())
            .stderr(log)
            .status()
            .expect("halcmd runs");
        assert!(status.success(), "loadusr {args:?}:\n{}", self.log());
    }

    /// Waits until `pin` reads `value` (`halcmd getp`), up to `limit`; how long it took.
    pub fn wait_pin(&self, pin: &str, value: &str, limit: Duration) -> Duration {
        let started = Instant::now();
        loop {
            if self.getp(pin) == value {
                return started.elapsed();
            }
            assert!(
                started.elapsed() < limit,
                "{pin} still reads {} after {limit:?}\n{}",
                self.getp(pin),
                self.log()
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Waits up to `limit` for `halrun` to exit; its exit code.
    pub fn wait_halrun(&mut self, limit: Duration) -> Option<i32> {
        let daemon = self.daemon.as_mut().expect("up");
        let deadline = Instant::now() + limit;
        while Instant::now() < deadline {
            if let Ok(Some(status)) = daemon.child.try_wait() {
                return status.code();
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        None
    }
}

/// Runs a HAL tool with the bench's environment; its standard output, trimmed.
fn hal_command(tool: &str, args: &[&str], home: &Path) -> Result<String, String> {
    let out = Command::new(tool)
        .args(args)
        .env("RTAPI_UID", RTAPI_UID)
        .env("HOME", home)
        .output()
        .map_err(|e| e.to_string())?;
    if !out.status.success() {
        return Err(String::from_utf8_lossy(&out.stderr).into_owned());
    }
    Ok(String::from_utf8_lossy(&out.stdout).trim().to_string())
}

impl Drop for HalBench {
    /// `exit` to halrun: it stops edmd (SIGTERM, a controlled stop) and unloads HAL.
    fn drop(&mut self) {
        if let Some(mut stdin) = self.stdin.take() {
            let _ = stdin.write_all(b"exit\n");
        }
        if let Some(mut daemon) = self.daemon.take() {
            let deadline = Instant::now() + Duration::from_secs(30);
            while Instant::now() < deadline {
                if let Ok(Some(_)) = daemon.child.try_wait() {
                    break;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
        }
        let _ = hal_command("halrun", &["-U"], &self.dir.join("home"));
    }
}
