//! The real `edmd serve` with `daemon.http` on a free loopback port, for the tests of the
//! web side (`tests/it/http.rs`, `tests/it/http_attacks.rs`).

#![allow(dead_code)]

use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

/// A running `edmd serve` with HTTP on; killed on drop.
pub struct Daemon {
    pub child: Child,
    pub log: PathBuf,
    pub base: String,
    pub token: String,
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

pub fn start(name: &str, sets: &[&str]) -> (Daemon, PathBuf) {
    start_with(name, sets, |_, _| {})
}

/// [`start`], with `configure` applied to the command and the `--set` list first (limits, a
/// configuration file in place of a default).
pub fn start_with(
    name: &str,
    sets: &[&str],
    configure: impl FnOnce(&mut Command, &mut Vec<String>),
) -> (Daemon, PathBuf) {
    let dir = super::scratch("http", name);
    let programs = dir.join("programs");
    std::fs::create_dir_all(&programs).unwrap();
    std::fs::copy(
        super::repo().join("tests/data/runtime-path.nc"),
        programs.join("runtime-path.nc"),
    )
    .unwrap();
    std::fs::write(programs.join("short.nc"), "G21 G90\nG1 X0.2 F60\nM2\n").unwrap();
    let token_file = dir.join("http-token");
    let _ = std::fs::remove_file(&token_file);
    let log = dir.join("serve.log");
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_edmd"));
    cmd.arg("serve")
        .current_dir(&dir)
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&log).unwrap())
        .env_remove("NOTIFY_SOCKET")
        .env_remove("WATCHDOG_USEC")
        .env_remove("RUST_LOG");
    let mut all = vec![
        format!("daemon.socket=\"{}\"", dir.join("edmd.sock").display()),
        format!("daemon.program_dir=\"{}\"", programs.display()),
        format!("daemon.checkpoint=\"{}\"", dir.join("cp.json").display()),
        "daemon.http=\"127.0.0.1:0\"".to_string(),
        format!("daemon.http_token_file=\"{}\"", token_file.display()),
        "fine.virtual_time=false".to_string(),
        "gap.kind=\"none\"".to_string(),
        "output.kind=\"file\"".to_string(),
        format!("output.path=\"{}\"", dir.join("pulses.csv").display()),
        "servo.normal_feed_mm_per_min=120.0".to_string(),
        "log.format=\"plain\"".to_string(),
    ];
    all.extend(sets.iter().map(|s| s.to_string()));
    configure(&mut cmd, &mut all);
    for s in &all {
        cmd.args(["--set", s]);
    }
    let child = cmd.spawn().unwrap();
    let deadline = Instant::now() + Duration::from_secs(20);
    let base = loop {
        let text = std::fs::read_to_string(&log).unwrap_or_default();
        if let Some(at) = text.find("on http://") {
            let rest = &text[at + "on http://".len()..];
            let addr = rest.split_whitespace().next().unwrap();
            break format!("http://{addr}");
        }
        assert!(
            Instant::now() < deadline,
            "no HTTP address in the log:\n{text}"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    let token = std::fs::read_to_string(&token_file)
        .unwrap()
        .trim()
        .to_string();
    (
        Daemon {
            child,
            log,
            base,
            token,
        },
        dir,
    )
}

impl Daemon {
    /// A request: the status code and the JSON body (`Null` when it is not JSON).
    pub fn call(
        &self,
        method: &str,
        path: &str,
        token: Option<&str>,
        body: Option<&str>,
    ) -> (u16, Value) {
        let (code, text) = self.raw(method, path, token, body);
        (code, serde_json::from_str(&text).unwrap_or(Value::Null))
    }

    pub fn raw(
        &self,
        method: &str,
        path: &str,
        token: Option<&str>,
        body: Option<&str>,
    ) -> (u16, String) {
        let mut req = ureq::request(method, &format!("{}{path}", self.base));
        if let Some(t) = token {
            req = req.set("Authorization", &format!("Bearer {t}"));
        }
        let result = match body {
            Some(b) => req.set("Content-Type", "application/json").send_string(b),
            None => req.call(),
        };
        let response = match result {
            Ok(r) => r,
            Err(ureq::Error::Status(_, r)) => r,
            Err(e) => panic!("{method} {path}: {e}\n{}", self.log()),
        };
        let code = response.status();
        (code, response.into_string().unwrap())
    }

    pub fn post(&self, path: &str, body: &str) -> (u16, Value) {
        let token = self.token.clone();
        self.call("POST", path, Some(&token), Some(body))
    }

    pub fn status(&self) -> Value {
        let (code, reply) = self.call("GET", "/api/status", None, None);
        assert_eq!(code, 200);
        reply["status"].clone()
    }

    pub fn wait_for(&self, what: &str, pred: impl Fn(&Value) -> bool) -> Value {
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            let s = self.status();
            if pred(&s) {
                return s;
            }
            assert!(
                Instant::now() < deadline,
                "waiting for {what}: {s}\n{}",
                self.log()
            );
            std::thread::sleep(Duration::from_millis(25));
        }
    }

    pub fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    pub fn port(&self) -> u16 {
        self.base.rsplit(':').next().unwrap().parse().unwrap()
    }
}
