//! The real `edmd serve` with `daemon.http` on a free loopback port, for the tests of the
//! web side (`tests/it/http.rs`, `tests/it/http_attacks.rs`).

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{Value, json};

/// A running `edmd serve` with HTTP on; killed on drop.
pub struct Daemon {
    pub child: Child,
    pub log: PathBuf,
    pub base: String,
    pub token: String,
    /// A share of the test machine's cores, or all of them (the load test).
    _machine: super::MachineHold,
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

/// [`start`] with the test machine's cores to itself: it waits until no other test's daemon
/// runs, and none starts until it ends (the load test).
pub fn start_alone(name: &str, sets: &[&str]) -> (Daemon, PathBuf) {
    start_holding(super::MachineHold::whole(), name, sets, |_, _| {})
}

/// [`start`], with `configure` applied to the command and the `--set` list first (limits, a
/// configuration file in place of a default).
pub fn start_with(
    name: &str,
    sets: &[&str],
    configure: impl FnOnce(&mut Command, &mut Vec<String>),
) -> (Daemon, PathBuf) {
    start_holding(super::MachineHold::share(), name, sets, configure)
}

fn start_holding(
    machine: super::MachineHold,
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
        format!("daemon.state_dir=\"{}\"", dir.display()),
        "daemon.http=\"127.0.0.1:0\"".to_string(),
        format!("daemon.http_token_file=\"{}\"", token_file.display()),
        "fine.virtual_time=false".to_string(),
        // As common::daemon::base_sets: the load test asks for the shipped settings.
        "fine.rt_priority=0".to_string(),
        "fine.lock_memory=false".to_string(),
        "fine.ticks_per_wake=10".to_string(),
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
            _machine: machine,
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

/// Whether the web tools are required here (CI), or may be missing.
pub fn required() -> bool {
    std::env::var_os("EDMD_WEB_TESTS").is_some_and(|v| v == "1")
}

pub fn tool(name: &str) -> Option<PathBuf> {
    let found = std::env::split_paths(&std::env::var_os("PATH").unwrap_or_default())
        .map(|d| d.join(name))
        .find(|p| p.is_file());
    if found.is_none() {
        assert!(
            !required(),
            "{name} is not installed (EDMD_WEB_TESTS=1 needs it)"
        );
        eprintln!("{name} is not installed: that part of the test is skipped");
    }
    found
}

/// A WebDriver session on a ChromeDriver of our own.
pub struct Browser {
    driver: Child,
    url: String,
    session: String,
}

impl Browser {
    pub fn start(chromedriver: &Path) -> Browser {
        let listen = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let port = listen.local_addr().unwrap().port();
        drop(listen);
        let driver = Command::new(chromedriver)
            .arg(format!("--port={port}"))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let url = format!("http://127.0.0.1:{port}");
        let caps = json!({"capabilities": {"alwaysMatch": {"goog:chromeOptions": {
            "binary": "/usr/bin/chromium",
            "args": ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                     "--no-first-run", "--disable-background-networking",
                     "--disable-component-update", "--disable-sync", "--window-size=1280,800"]
        }}}});
        let deadline = Instant::now() + Duration::from_secs(30);
        let session = loop {
            if let Ok(r) = ureq::post(&format!("{url}/session"))
                .set("Content-Type", "application/json")
                .send_string(&caps.to_string())
            {
                let v: Value = serde_json::from_str(&r.into_string().unwrap()).unwrap();
                break v["value"]["sessionId"].as_str().unwrap().to_string();
            }
            assert!(
                Instant::now() < deadline,
                "ChromeDriver did not start a session"
            );
            std::thread::sleep(Duration::from_millis(100));
        };
        Browser {
            driver,
            url,
            session,
        }
    }

    pub fn command(&self, method: &str, path: &str, body: Option<Value>) -> Value {
        let url = format!("{}/session/{}{path}", self.url, self.session);
        let req = ureq::request(method, &url);
        let r = match body {
            Some(b) => req
                .set("Content-Type", "application/json")
                .send_string(&b.to_string()),
            None => req.call(),
        }
        .unwrap_or_else(|e| panic!("{method} {path}: {e}"));
        let v: Value = serde_json::from_str(&r.into_string().unwrap()).unwrap();
        v["value"].clone()
    }

    /// Polls `script` until it returns something other than null or false (at most 60 s).
    pub fn wait(&self, what: &str, script: &str) -> Value {
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            let v = self.eval(script);
            if v != Value::Null && v != Value::Bool(false) {
                return v;
            }
            assert!(Instant::now() < deadline, "the page never showed {what}");
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Clicks the control `id` once the page has enabled it. The page enables a control from
    /// its own last status, which can trail the daemon's by a poll on a busy machine, and a
    /// click on a disabled button does nothing.
    pub fn press(&self, id: &str) {
        self.wait(
            &format!("#{id} enabled"),
            &format!("return !document.getElementById('{id}').disabled"),
        );
        self.eval(&format!(
            "document.getElementById('{id}').click(); return true"
        ));
    }

    pub fn eval(&self, script: &str) -> Value {
        self.command(
            "POST",
            "/execute/sync",
            Some(json!({"script": script, "args": []})),
        )
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let url = format!("{}/session/{}", self.url, self.session);
        let _ = ureq::request("DELETE", &url).call();
        let _ = self.driver.kill();
        let _ = self.driver.wait();
    }
}

/// A WebDriver screenshot's base64 as bytes.
pub fn base64_decode(text: &str) -> Vec<u8> {
    let value = |c: u8| -> u32 {
        match c {
            b'A'..=b'Z' => (c - b'A') as u32,
            b'a'..=b'z' => (c - b'a' + 26) as u32,
            b'0'..=b'9' => (c - b'0' + 52) as u32,
            b'+' => 62,
            _ => 63,
        }
    };
    let clean: Vec<u8> = text
        .bytes()
        .filter(|&c| c != b'=' && !c.is_ascii_whitespace())
        .collect();
    let mut out = Vec::with_capacity(clean.len() * 3 / 4);
    for chunk in clean.chunks(4) {
        let mut n = 0u32;
        for (i, &c) in chunk.iter().enumerate() {
            n |= value(c) << (18 - 6 * i);
        }
        let bytes = [(n >> 16) as u8, (n >> 8) as u8, n as u8];
        out.extend_from_slice(&bytes[..chunk.len() - 1]);
    }
    out
}
