//! The daemon's web side end to end: the real `edmd serve` with `daemon.http` on a free
//! loopback port, the API over HTTP, `/metrics` read by Prometheus' own `promtool` and
//! scraped by a real Prometheus server, and the page in headless Chromium driven through
//! ChromeDriver (a screenshot and the DOM after its scripts ran).
//!
//! `.ci/run` installs Chromium, ChromeDriver and Prometheus from Debian and sets
//! `EDMD_WEB_TESTS=1`, which makes those parts required; elsewhere a test whose tool is
//! missing says so and checks the rest.

use crate::common;

use common::web::{Browser, Daemon, base64_decode, start, tool};

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{Value, json};

#[test]
fn the_api_answers_as_the_socket_does_and_control_needs_the_token() {
    let (d, dir) = start("api", &[]);
    // The token file: 256 bits in hex, readable by its owner only.
    use std::os::unix::fs::PermissionsExt;
    let mode = std::fs::metadata(dir.join("http-token"))
        .unwrap()
        .permissions()
        .mode();
    assert_eq!((d.token.len(), mode & 0o777), (64, 0o600));

    // GET /api/status is `edmd ctl status --json`'s reply.
    let (code, reply) = d.call("GET", "/api/status", None, None);
    assert_eq!((code, reply["ok"].as_bool()), (200, Some(true)));
    assert_eq!(reply["status"]["state"], "idle");
    let ctl = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .args(["ctl", "--json", "--socket"])
        .arg(dir.join("edmd.sock"))
        .arg("status")
        .output()
        .unwrap();
    let ctl: Value = serde_json::from_slice(&ctl.stdout).unwrap();
    let keys = |v: &Value| {
        let mut k: Vec<String> = v["status"].as_object().unwrap().keys().cloned().collect();
        k.sort();
        k
    };
    assert_eq!(keys(&ctl), keys(&reply));

    let (code, list) = d.call("GET", "/api/programs", None, None);
    assert_eq!(code, 200);
    let names: Vec<&str> = list["programs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["runtime-path.nc", "short.nc"]);

    // Control without the token, or with another: 401, and nothing happens.
    let run = r#"{"program":"runtime-path.nc"}"#;
    let (code, reply) = d.call("POST", "/api/run", None, Some(run));
    assert_eq!(code, 401, "{reply}");
    assert!(
        reply["error"].as_str().unwrap().contains("Bearer"),
        "{reply}"
    );
    let wrong = "0".repeat(64);
    assert_eq!(d.call("POST", "/api/run", Some(&wrong), Some(run)).0, 401);
    assert_eq!(d.call("POST", "/api/hold", None, None).0, 401);
    assert_eq!(d.status()["state"], "idle");

    // Bad requests: 404 no such program (missing and outside alike, no path in the reply),
    // 400 malformed, 413 too big, 409 the wrong state.
    for (name, shown) in [
        ("nope.nc", "nope.nc"),
        ("../http-token", "../http-token"),
        ("/etc/passwd", "/etc/passwd"),
    ] {
        let body = serde_json::json!({ "program": name }).to_string();
        let (code, reply) = d.post("/api/run", &body);
        assert_eq!(code, 404, "{reply}");
        assert_eq!(
            reply["error"],
            format!("{shown}: no such program in the program directory")
        );
    }
    let (code, reply) = d.post("/api/run", r#"{"program": 7}"#);
    assert_eq!(code, 400, "{reply}");
    let error = reply["error"].as_str().unwrap();
    // The place once: serde's own " at line L column C" is not repeated after it.
    assert_eq!(
        error, "request body:1:13: invalid type: integer `7`, expected a string",
        "{reply}"
    );
    let (code, reply) = d.post("/api/run", r#"{"program":"short.nc","fly":1}"#);
    assert_eq!(code, 400, "{reply}");
    let big = format!(r#"{{"program":"{}"}}"#, "a".repeat(20_000));
    let (code, reply) = d.post("/api/run", &big);
    assert_eq!(code, 413, "{reply}");
    assert_eq!(reply["ok"], false);
    let (code, reply) = d.post("/api/hold", "");
    assert_eq!(
        (code, reply["error"].as_str()),
        (409, Some("no job is running"))
    );
    let (code, reply) = d.post("/api/rethread", r#"{"here":true}"#);
    assert_eq!(code, 409, "{reply}");
    assert_eq!(d.call("GET", "/nothing", None, None).0, 404);

    // A job through HTTP: run, 409 for a second run, hold, resume, abort.
    let (code, reply) = d.post("/api/run", run);
    assert_eq!(code, 200, "{reply}");
    d.wait_for("the job", |s| s["state"] == "running");
    assert_eq!(d.post("/api/run", run).0, 409);
    assert_eq!(d.post("/api/hold", "{}").0, 200);
    d.wait_for("the hold", |s| s["state"] == "held");
    let (code, reply) = d.post("/api/resume", r#"{"force":false}"#);
    assert_eq!(code, 200, "{reply}");
    d.wait_for("running again", |s| s["state"] == "running");
    assert_eq!(d.post("/api/abort", "").0, 200);
    let idle = d.wait_for("the abort", |s| s["state"] == "idle");
    assert_eq!(idle["last_job"]["outcome"], "stopped");
    assert_eq!(idle["counters"]["jobs"], 1);
    // The operator's hold (an abort brakes to a stop: not a hold).
    assert_eq!(idle["counters"]["holds"].as_u64(), Some(1), "{idle}");
}

/// `/api/events` sends the status at least every second when nothing changes, and on every
/// change (at most ten a second) while a job moves.
#[test]
fn home_touch_off_and_mdi_over_http() {
    // X homes by the simulator's switch (believed at X3, really at X10, then 1 mm back);
    // Y has no switch.
    let (d, _dir) = start(
        "machine",
        &[
            "gap.kind=\"sim\"",
            "homing.axis=[{axis=\"X\", direction=\"+\", search_feed_mm_per_min=600.0, \
             latch_feed_mm_per_min=30.0, home_position_mm=10.0, final_move_mm=-1.0, \
             search_distance_mm=20.0, latch_distance_mm=0.5}]",
            "sim.home_switch_mm={X=3.0}",
            "sim.part_edge_mm={X=[12.0,60.0]}",
        ],
    );
    // The machine's commands: the body is the socket request's fields.
    let (code, reply) = d.post("/api/home", r#"{"axes":["Y"]}"#);
    assert_eq!(code, 409, "{reply}");
    assert!(
        reply["error"]
            .as_str()
            .unwrap()
            .contains("Y has no home switch"),
        "{reply}"
    );
    let (code, reply) = d.post("/api/home", r#"{"axes":["X"]}"#);
    assert_eq!(code, 200, "{reply}");
    d.wait_for("X homed", |s| {
        s["state"] == "idle" && s["machine"]["homed"] == json!([true, false])
    });
    let (code, reply) = d.post("/api/home", r#"{"axes":["Y"],"here":true}"#);
    assert_eq!(code, 200, "{reply}");
    assert_eq!(reply["status"]["machine"]["homed"], json!([true, true]));
    assert_eq!(
        reply["status"]["machine"]["position_machine_mm"],
        json!([9.0, 0.0])
    );
    let (code, reply) = d.post("/api/touch-off", r#"{"axis":"X","value":0.5}"#);
    assert_eq!(code, 200, "{reply}");
    assert_eq!(reply["status"]["machine"]["position_work_mm"][0], 0.5);
    let (code, reply) = d.post("/api/touch-off", r#"{"axis":"Q","value":1}"#);
    assert_eq!(code, 409, "{reply}");
    assert!(
        reply["error"].as_str().unwrap().contains("not an axis"),
        "{reply}"
    );
    let (code, reply) = d.post("/api/mdi", r#"{"line":"G1 X1 F600","extra":1}"#);
    assert_eq!(code, 400, "{reply}");
    let (code, reply) = d.post("/api/mdi", r#"{"line":"G0 X1 Y0"}"#);
    assert_eq!(code, 200, "{reply}");
    d.wait_for("the MDI move", |s| {
        s["state"] == "idle" && s["machine"]["position_work_mm"][0] == 1.0
    });
    assert_eq!(d.status()["machine"]["position_machine_mm"][0], 9.5);
    // The overrides: the body names the kind and the percentage.
    let (code, reply) = d.post("/api/override", r#"{"kind":"feed","percent":80}"#);
    assert_eq!(code, 200, "{reply}");
    assert_eq!(reply["status"]["overrides"]["feed_pct"], 80);
    let (code, reply) = d.post("/api/override", r#"{"kind":"rapid","percent":101}"#);
    assert_eq!(code, 409, "{reply}");
    let (code, reply) = d.post("/api/override", r#"{"kind":"spindle","percent":50}"#);
    assert_eq!(code, 400, "{reply}");
    // Upload: written whole into the program directory, listed, and run like any other.
    let (code, reply) = d.post("/api/programs?name=up.nc", "G21 G90\nG0 X2\nM2\n");
    assert_eq!(code, 200, "{reply}");
    assert_eq!(
        std::fs::read_to_string(_dir.join("programs/up.nc")).unwrap(),
        "G21 G90\nG0 X2\nM2\n"
    );
    // A program of that name is not written over unless asked to be.
    let (code, reply) = d.post("/api/programs?name=up.nc", "G21 G90\nG0 X3\nM2\n");
    assert_eq!(code, 409, "{reply}");
    assert!(
        reply["error"]
            .as_str()
            .unwrap()
            .contains("upload it with replace"),
        "{reply}"
    );
    let (code, reply) = d.post(
        "/api/programs?name=up.nc&replace=true",
        "G21 G90\nG0 X3\nM2\n",
    );
    assert_eq!(code, 200, "{reply}");
    assert!(
        reply["message"].as_str().unwrap().contains("replacing"),
        "{reply}"
    );
    let (_, list) = d.call("GET", "/api/programs", None, None);
    assert!(list.to_string().contains("up.nc"), "{list}");
    for bad in ["..%2Fescape.nc", ".hidden.nc", "a%2Fb.nc", ""] {
        let (code, reply) = d.post(&format!("/api/programs?name={bad}"), "G0 X1\n");
        assert_eq!(code, 400, "{bad}: {reply}");
    }
    assert!(!_dir.join("escape.nc").exists());
    let (code, _) = d.call("POST", "/api/programs?name=x.nc", None, Some("G0 X1\n"));
    assert_eq!(code, 401, "no token, no upload");
    // An upload over the limit (16 MiB) is refused from its declared length, before its body
    // is read. (Sending the body too races the refusal: the server answers and closes while
    // the client is still writing, and the client sees a broken pipe, not the 413.)
    let mut stream = TcpStream::connect(d.base.trim_start_matches("http://")).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    write!(
        stream,
        "POST /api/programs?name=big.nc HTTP/1.1\r\nHost: 127.0.0.1\r\n\
         Authorization: Bearer {}\r\nContent-Length: {}\r\n\r\n",
        d.token,
        18 * 1024 * 1024
    )
    .unwrap();
    let mut head = [0u8; 64];
    let n = stream.read(&mut head).unwrap();
    let status = String::from_utf8_lossy(&head[..n]).to_string();
    assert!(status.starts_with("HTTP/1.1 413"), "{status}");
    assert!(!_dir.join("programs/big.nc").exists());
    // A wire-touch cycle: the simulator's part has its X− face at X12; the wire (0.25 mm)
    // stands at X9.5.
    let (code, reply) = d.post("/api/find", r#"{"target":"edge W+"}"#);
    assert_eq!(code, 409, "{reply}");
    assert!(
        reply["error"]
            .as_str()
            .unwrap()
            .contains("is not something to find")
    );
    let (code, reply) = d.post("/api/find", r#"{"target":"edge X+","system":"G57"}"#);
    assert_eq!(code, 200, "{reply}");
    let s = d.wait_for("the find", |s| {
        s["state"] == "idle" && s["machine"]["find"]["state"] != "running"
    });
    let find = &s["machine"]["find"];
    assert_eq!(find["state"], "found", "{find}");
    let x = find["point_mm"][0].as_f64().unwrap();
    assert!((12.0..12.001).contains(&x), "{find}");
    assert_eq!(find["system"], "G57");
}

#[test]
fn server_sent_events_carry_the_status() {
    let (d, _dir) = start("events", &[]);
    let count = |d: &Daemon, secs: f64| -> Vec<Value> {
        let mut stream = TcpStream::connect(d.base.trim_start_matches("http://")).unwrap();
        write!(
            stream,
            "GET /api/events HTTP/1.1\r\nHost: 127.0.0.1\r\nAccept: text/event-stream\r\n\r\n"
        )
        .unwrap();
        stream
            .set_read_timeout(Some(Duration::from_millis(100)))
            .unwrap();
        let mut reader = BufReader::new(stream);
        let until = Instant::now() + Duration::from_secs_f64(secs);
        let mut events = Vec::new();
        let mut line = String::new();
        while Instant::now() < until {
            line.clear();
            match reader.read_line(&mut line) {
                Ok(0) => break,
                Ok(_) => {
                    if let Some(data) = line.trim_end().strip_prefix("data: ") {
                        events.push(serde_json::from_str(data).unwrap());
                    }
                }
                Err(_) => continue,
            }
        }
        events
    };
    let idle = count(&d, 2.5);
    assert!(
        (2..=4).contains(&idle.len()),
        "{} events while idle",
        idle.len()
    );
    assert_eq!(idle[0]["status"]["state"], "idle");
    assert_eq!(
        d.post("/api/run", r#"{"program":"runtime-path.nc"}"#).0,
        200
    );
    d.wait_for("the job", |s| s["state"] == "running");
    let moving = count(&d, 1.0);
    assert!(
        moving.len() >= 5,
        "{} events in a second of motion",
        moving.len()
    );
    let x = |e: &Value| e["status"]["job"]["position_mm"][0].as_f64().unwrap_or(0.0);
    assert!(
        x(moving.last().unwrap()) > x(&moving[0]),
        "the position moves"
    );
}

#[test]
fn metrics_are_read_by_promtool_and_scraped_by_prometheus() {
    // The edge node on, its broker absent (port 1 refuses): its metrics are there, at 0. A
    // wake-up at every tick: the latency histogram counts wake-ups, here one per tick.
    let (d, dir) = start(
        "metrics",
        &[
            "daemon.mqtt.broker=\"mqtt://127.0.0.1:1\"",
            "fine.ticks_per_wake=1",
        ],
    );
    // While a job runs, its gauges are there too.
    assert_eq!(
        d.post("/api/run", r#"{"program":"runtime-path.nc"}"#).0,
        200
    );
    d.wait_for("the job's ETA", |s| s["job"]["eta_s"].is_number());
    let (_, running) = d.raw("GET", "/metrics", None, None);
    for needle in [
        "edmd_job_progress_ratio ",
        "edmd_position_mm{axis=\"X\"} ",
        "edmd_job_info{",
    ] {
        assert!(running.contains(needle), "no {needle:?} in\n{running}");
    }
    assert_eq!(d.post("/api/abort", "").0, 200);
    d.wait_for("the abort", |s| s["state"] == "idle");
    assert_eq!(d.post("/api/run", r#"{"program":"short.nc"}"#).0, 200);
    d.wait_for("the job's end", |s| s["last_job"]["outcome"] == "done");
    let (code, text) = d.raw("GET", "/metrics", None, None);
    assert_eq!(code, 200);
    for needle in [
        "edmd_up 1\n",
        "edmd_state{state=\"idle\"} 1\n",
        "edmd_jobs_total 2\n",
        "edmd_shorts_total 0\n",
        "edmd_gap_ticks_total{state=\"normal\"}",
        "edmd_tick_latency_seconds_bucket{le=\"+Inf\"}",
        "# TYPE edmd_tick_latency_seconds histogram",
    ] {
        assert!(text.contains(needle), "no {needle:?} in\n{text}");
    }
    // Every tick of the job is in the histogram and in the gap counts.
    let value = |name: &str| -> f64 {
        text.lines()
            .find_map(|l| l.strip_prefix(name).and_then(|r| r.trim().parse().ok()))
            .unwrap_or_else(|| panic!("no {name}"))
    };
    let ticks = value("edmd_ticks_total ");
    assert!(ticks > 0.0);
    assert_eq!(value("edmd_tick_latency_seconds_count "), ticks);
    assert_eq!(value("edmd_gap_ticks_total{state=\"normal\"} "), ticks);

    // Every metric the shipped Grafana dashboard queries exists.
    let dashboard =
        std::fs::read_to_string(common::repo().join("contrib/grafana-dashboard.json")).unwrap();
    let mut queried = 0;
    for (at, _) in dashboard.match_indices("edmd_") {
        let name: String = dashboard[at..]
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect();
        let exposed = |t: &str| t.contains(&format!("\n{name}"));
        assert!(
            exposed(&text) || exposed(&running),
            "the dashboard queries {name}"
        );
        queried += 1;
    }
    assert!(queried >= 9, "{queried} metrics in the dashboard");

    if let Some(promtool) = tool("promtool") {
        let mut check = Command::new(&promtool)
            .args(["check", "metrics"])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        check
            .stdin
            .take()
            .unwrap()
            .write_all(text.as_bytes())
            .unwrap();
        let out = check.wait_with_output().unwrap();
        for shipped in [
            "contrib/prometheus.yml",
            "contrib/prometheus-federation.yml",
        ] {
            let checked = Command::new(&promtool)
                .args(["check", "config"])
                .arg(common::repo().join(shipped))
                .output();
            assert!(checked.unwrap().status.success(), "{shipped}");
        }
        assert!(
            out.status.success(),
            "promtool: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    assert!(
        text.contains("\nedmd_mqtt_connected 0\n"),
        "the edge node's metrics: {text}"
    );
    let Some(prometheus) = tool("prometheus") else {
        return;
    };
    // A hall's Prometheus scrapes the machine; the plant's federates the hall's with the
    // shipped contrib/prometheus-federation.yml (its targets pointed at the hall's).
    let hall = Prometheus::start(
        &prometheus,
        &dir.join("hall"),
        &format!(
            "global:\n  scrape_interval: 1s\nscrape_configs:\n  - job_name: edmd\n    \
             static_configs:\n      - targets: ['127.0.0.1:{}']\n        labels:\n          \
             floor: 'hall-a'\n",
            d.port()
        ),
    );
    let hall_jobs = hall.first("edmd_jobs_total");
    assert_eq!(
        hall_jobs.as_ref().map(|s| s["value"][1].clone()),
        Some(json!("2")),
        "the hall's Prometheus did not scrape edmd_jobs_total:\n{}",
        hall.log()
    );
    let federation =
        std::fs::read_to_string(common::repo().join("contrib/prometheus-federation.yml"))
            .unwrap()
            .replace("scrape_interval: 15s", "scrape_interval: 1s");
    let targets = federation
        .lines()
        .find(|l| l.trim_start().starts_with("- targets:"))
        .expect("the federation file's targets");
    let federation = federation.replace(
        targets,
        &format!("      - targets: ['127.0.0.1:{}']", hall.port),
    );
    let plant = Prometheus::start(&prometheus, &dir.join("plant"), &federation);
    let federated = plant.first("edmd_jobs_total");
    let sample = federated.unwrap_or_else(|| panic!("nothing federated:\n{}", plant.log()));
    assert_eq!(sample["value"][1], "2");
    // The machine's own labels came through: the dashboard's machine and floor filters work.
    assert_eq!(
        sample["metric"]["instance"],
        format!("127.0.0.1:{}", d.port())
    );
    assert_eq!(sample["metric"]["floor"], "hall-a");
    // Every query of the dashboard is PromQL the plant's Prometheus answers, for all machines.
    let dashboard: Value = serde_json::from_str(&dashboard).unwrap();
    for panel in dashboard["panels"].as_array().unwrap() {
        for target in panel["targets"].as_array().unwrap() {
            let expr = target["expr"].as_str().unwrap().replace("$instance", ".*");
            let answer = plant.query(&expr);
            assert_eq!(answer["status"], "success", "{expr}: {answer}");
        }
    }
}

/// A Prometheus server on a free loopback port with `config`, its data under `dir`; killed
/// when dropped.
struct Prometheus {
    child: std::process::Child,
    port: u16,
    dir: PathBuf,
}

impl Prometheus {
    fn start(binary: &Path, dir: &Path, config: &str) -> Prometheus {
        std::fs::create_dir_all(dir).unwrap();
        let file = dir.join("prometheus.yml");
        std::fs::write(&file, config).unwrap();
        let listen = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let port = listen.local_addr().unwrap().port();
        drop(listen);
        let child = Command::new(binary)
            .arg(format!("--config.file={}", file.display()))
            .arg(format!(
                "--storage.tsdb.path={}",
                dir.join("tsdb").display()
            ))
            .arg(format!("--web.listen-address=127.0.0.1:{port}"))
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(dir.join("prometheus.log")).unwrap())
            .spawn()
            .unwrap();
        Prometheus {
            child,
            port,
            dir: dir.to_path_buf(),
        }
    }

    fn log(&self) -> String {
        std::fs::read_to_string(self.dir.join("prometheus.log")).unwrap_or_default()
    }

    /// The answer to an instant query (`null` while the server is not up).
    fn query(&self, expr: &str) -> Value {
        let url = format!("http://127.0.0.1:{}/api/v1/query", self.port);
        match ureq::get(&url).query("query", expr).call() {
            Ok(r) => serde_json::from_str(&r.into_string().unwrap()).unwrap(),
            Err(ureq::Error::Status(_, r)) => {
                serde_json::from_str(&r.into_string().unwrap()).unwrap_or(Value::Null)
            }
            Err(_) => Value::Null,
        }
    }

    /// The first sample of `expr`, waited for 40 s at most.
    fn first(&self, expr: &str) -> Option<Value> {
        let deadline = Instant::now() + Duration::from_secs(40);
        loop {
            if let Some(sample) = self.query(expr)["data"]["result"].get(0) {
                return Some(sample.clone());
            }
            if Instant::now() > deadline {
                return None;
            }
            std::thread::sleep(Duration::from_millis(250));
        }
    }
}

impl Drop for Prometheus {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The page in a real browser: live state over SSE, the program list, the backplot with
/// the programmed path under the executed one, and the controls through the API with the
/// token the page keeps.
#[test]
fn the_page_in_headless_chromium() {
    let Some(chromedriver) = tool("chromedriver") else {
        return;
    };
    let (d, dir) = start(
        "page",
        &[
            "servo.normal_feed_mm_per_min=60.0",
            "wire.touch_search_mm=0.5",
        ],
    );
    // A program the check refuses: past the travel.
    std::fs::write(dir.join("programs/far.nc"), "G21 G90\nG1 X900 F100\n").unwrap();
    let browser = Browser::start(&chromedriver);
    browser.command("POST", "/url", Some(json!({"url": format!("{}/", d.base)})));
    let wait = |what: &str, script: &str| browser.wait(what, script);
    wait(
        "the idle state",
        "return document.getElementById('state').textContent === 'idle'",
    );
    // The DRO shows machine and work coordinates when idle, unhomed axes marked.
    let dro = wait(
        "the DRO",
        "const m = document.getElementById('position-machine').textContent; \
         const w = document.getElementById('position-work').textContent; \
         return m.includes('X? 0.0000') && w.startsWith('work G54') ? [m, w] : false",
    );
    eprintln!("DRO: {dro}");
    let options = browser.eval(
        "return Array.from(document.getElementById('program-list').options).map(o => o.value)",
    );
    assert_eq!(options, json!(["far.nc", "runtime-path.nc", "short.nc"]));
    // Not logged in: the login field shows (no prompt), and control asks for it.
    wait(
        "the login field",
        "return document.getElementById('login').className === 'on'",
    );
    browser.eval(&format!(
        "document.getElementById('token').value = '{}'; document.getElementById('login-save').click(); return true",
        d.token
    ));
    wait(
        "the login accepted",
        "return document.getElementById('login').className === '' && localStorage.getItem('edmd-token') !== null",
    );
    // A refused program: its file:line:col on the page.
    browser.eval(
        "document.getElementById('program-list').value = 'far.nc'; document.getElementById('run').click(); return true",
    );
    let refused = wait(
        "the refusal",
        "const m = document.getElementById('message'); return m.className === 'error' && m.textContent.includes('far.nc:2:1') ? m.textContent : false",
    );
    eprintln!("refusal on the page: {refused}");
    // … and in the event list, which keeps it.
    wait(
        "the refusal in the event list",
        "return document.getElementById('events').textContent.includes('far.nc:2:1')",
    );
    let shot = browser.command("GET", "/screenshot", None);
    std::fs::write(
        dir.join("page-refused.png"),
        base64_decode(shot.as_str().unwrap()),
    )
    .unwrap();
    // Upload from the page (the file chooser's handler, given the file's name and text).
    browser.eval("upload('uploaded.nc', 'G21 G90\\nG1 X0.2 F60\\nM2\\n'); return true");
    wait(
        "the upload listed and picked",
        "return document.getElementById('program-list').value === 'uploaded.nc'",
    );
    assert!(dir.join("programs/uploaded.nc").exists());
    // Picked, the program is previewed before it runs: its path over a grid in mm (work
    // coordinates), with the soft limits' box.
    browser.eval(
        "const s = document.getElementById('program-list'); s.value = 'runtime-path.nc'; \
         s.dispatchEvent(new Event('change')); return true",
    );
    let preview = wait(
        "the preview",
        "const b = document.getElementById('backplot').dataset; \
         return b.preview === 'runtime-path.nc' && Number(b.plannedPoints) > 10 && Number(b.gridMm) > 0 ? [b.plannedPoints, b.gridMm] : false",
    );
    eprintln!("preview: {preview}");
    let shot = browser.command("GET", "/screenshot", None);
    std::fs::write(
        dir.join("page-idle.png"),
        base64_decode(shot.as_str().unwrap()),
    )
    .unwrap();
    // Run from the page.
    browser.eval(
        "document.getElementById('program-list').value = 'runtime-path.nc'; document.getElementById('run').click(); return true",
    );
    wait(
        "the running state",
        "return document.getElementById('state').textContent === 'running'",
    );
    // The listing follows the line in hand.
    let listing = wait(
        "the listing at the current line",
        "const ol = document.getElementById('listing'); const c = ol.querySelector('li.current'); \
         return c && Number(ol.dataset.lines) > 3 && Number(ol.dataset.current) >= 2 ? [ol.dataset.current, c.textContent] : false",
    );
    eprintln!("listing: {listing}");
    let plot = wait(
        "the backplot",
        "const b = document.getElementById('backplot').dataset; \
         return Number(b.plannedPoints) > 10 && Number(b.executedPoints) > 5 ? b : false",
    );
    // A page opened mid-job shows everything cut so far: the path is the daemon's.
    browser.command("POST", "/refresh", Some(json!({})));
    wait(
        "the executed path after a reload",
        "const b = document.getElementById('backplot').dataset; return Number(b.executedPoints) > 5 ? b.executedPoints : false",
    );
    let progress = wait(
        "progress",
        "const t = document.getElementById('progress').textContent; return t.endsWith('%') ? t : false",
    );
    let shot = browser.command("GET", "/screenshot", None);
    let png = base64_decode(shot.as_str().unwrap());
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    std::fs::write(dir.join("page.png"), &png).unwrap();
    let dom = browser.command("GET", "/source", None);
    let dom = dom.as_str().unwrap();
    assert!(dom.contains("data-state=\"running\""), "{dom}");
    // While it runs, Run is disabled and Hold is not.
    wait(
        "the running buttons",
        "return document.getElementById('run').disabled && !document.getElementById('hold').disabled",
    );
    // The feed override slider and the single-block switch reach the daemon.
    browser.eval(
        "const f = document.getElementById('feed-override'); f.value = 80; f.dispatchEvent(new Event('change')); return true",
    );
    d.wait_for("the override", |s| s["overrides"]["feed_pct"] == 80);
    // Single block: the job stops at the end of each block; Resume runs the next. Twice.
    browser.eval(
        "const b = document.getElementById('single-block'); b.checked = true; b.dispatchEvent(new Event('change')); return true",
    );
    d.wait_for("single block", |s| s["single_block"] == true);
    let mut stops = Vec::new();
    for _ in 0..2 {
        let s = d.wait_for("a single-block stop", |s| s["state"] == "paused");
        stops.push(s["job"]["paused_before_line"].as_u64().unwrap());
        wait(
            "Resume enabled",
            "return document.getElementById('state').textContent === 'paused: single block' && !document.getElementById('resume').disabled",
        );
        browser.press("resume");
        d.wait_for("the next block", |s| s["state"] != "paused");
    }
    assert!(stops[1] > stops[0], "stepped block by block: {stops:?}");
    browser.eval(
        "const b = document.getElementById('single-block'); b.checked = false; b.dispatchEvent(new Event('change')); return true",
    );
    d.wait_for("single block off", |s| s["single_block"] == false);
    // Hold from the page: the daemon holds (the socket says so too).
    browser.press("hold");
    d.wait_for("the hold", |s| s["state"] == "held");
    wait(
        "held on the page",
        "return document.getElementById('state').textContent === 'held'",
    );
    // Abort asks to be pressed twice: one press does nothing but arm it.
    browser.press("abort");
    wait(
        "the armed abort",
        "return document.getElementById('abort').textContent === 'Confirm abort'",
    );
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(d.status()["state"], "held", "one press aborts nothing");
    let shot = browser.command("GET", "/screenshot", None);
    std::fs::write(
        dir.join("page-held.png"),
        base64_decode(shot.as_str().unwrap()),
    )
    .unwrap();
    browser.press("abort");
    d.wait_for("the abort", |s| s["state"] == "idle");
    wait(
        "the last job's outcome",
        "const o = document.getElementById('outcome').textContent; return o.includes('runtime-path.nc: stopped') ? o : false",
    );
    // The job's own events (from its recording) in the list: the hold and the abort.
    let events = wait(
        "the job's events",
        "const t = document.getElementById('events').textContent; return t.includes(' hold') && t.includes(' abort') ? t : false",
    );
    eprintln!("events: {events}");
    // One timeline, newest first: the job's abort above the page's note of the hold pressed
    // before it.
    let order = wait(
        "the job's events among the page's notes",
        "const rows = Array.from(document.querySelectorAll('#events li')).map((li) => li.textContent); \
         const abort = rows.findIndex((t) => / line \\d+ +abort/.test(t)); \
         const asked = rows.findIndex((t) => t.includes('holding: braking to a standstill')); \
         return abort >= 0 && asked >= 0 ? [abort, asked] : false",
    );
    assert!(
        order[0].as_i64() < order[1].as_i64(),
        "the abort listed below the hold pressed before it: {order}"
    );
    // Run from a line from the page's run dialog: the job stopped on the arc (line 6), where
    // the wire stands; back along the kerf to line 5, never past the stop.
    browser.eval(
        "document.getElementById('program-list').value = 'runtime-path.nc'; \
         document.getElementById('from-line').value = '5'; \
         document.getElementById('wire-at').value = 'stopped'; \
         document.getElementById('run').click(); return true",
    );
    let s = d.wait_for("the run from line 5", |s| {
        s["job"]["from_line"]["line"] == 5
    });
    assert_eq!(s["job"]["from_line"]["approach"], "path");
    assert_eq!(s["job"]["from_line"]["wire_at"], "stopped");
    browser.eval(
        "document.getElementById('from-line').value = ''; \
         document.getElementById('wire-at').value = ''; return true",
    );
    browser.press("abort");
    browser.press("abort");
    d.wait_for("its abort", |s| s["state"] == "idle");
    // Passes from the run dialog reach the daemon (the table has three).
    wait(
        "Run enabled",
        "return !document.getElementById('run').disabled",
    );
    browser.eval(
        "document.getElementById('passes').value = '5'; document.getElementById('run').click(); return true",
    );
    wait(
        "the passes refused",
        "const m = document.getElementById('message'); return m.className === 'error' && m.textContent.includes('--passes 5: [wire] pass has 3 passes')",
    );
    browser.eval("document.getElementById('passes').value = ''; return true");
    // Jog from the page: one step of 0.1 mm, then held for a while (a continuous jog the
    // page renews), released: it stops.
    let x = |d: &Daemon| {
        d.status()["machine"]["position_machine_mm"][0]
            .as_f64()
            .unwrap()
    };
    let x0 = x(&d);
    browser.press("jog-plus");
    d.wait_for("the jog", |s| {
        s["state"] == "idle"
            && (s["machine"]["position_machine_mm"][0].as_f64().unwrap() - x0 - 0.1).abs() < 1e-9
    });
    let x1 = x(&d);
    browser.eval(
        "document.getElementById('jog-hold-plus').dispatchEvent(new PointerEvent('pointerdown')); return true",
    );
    d.wait_for("jogging", |s| s["state"] == "jogging");
    std::thread::sleep(Duration::from_millis(400));
    browser.eval(
        "document.getElementById('jog-hold-plus').dispatchEvent(new PointerEvent('pointerup')); return true",
    );
    d.wait_for("the jog's stop", |s| s["state"] == "idle");
    let x2 = x(&d);
    std::thread::sleep(Duration::from_millis(400));
    assert!(x2 > x1, "the held jog moved: {x1} -> {x2}");
    assert_eq!(x(&d), x2, "and stays stopped after the release");
    // An MDI line from the page.
    browser.eval("document.getElementById('mdi-line').value = 'G0 Y0.05'; return true");
    browser.press("mdi-send");
    d.wait_for("the MDI move", |s| {
        s["state"] == "idle"
            && (s["machine"]["position_machine_mm"][1].as_f64().unwrap() - 0.05).abs() < 1e-9
    });
    // A find cycle from the page: the gap input here ("none") never reads contact, so the
    // short search (wire.touch_search_mm) fails, and the page says so.
    wait(
        "the find button",
        "return !document.getElementById('find').disabled",
    );
    browser.eval(
        "document.getElementById('find-target').value = 'edge X+'; document.getElementById('find-system').value = 'G57'; document.getElementById('find').click(); return true",
    );
    let found = wait(
        "the find's outcome",
        "const f = document.getElementById('find-result'); return f.className === 'kv error' && f.textContent.includes('edge X+ failed: X+: no contact within 0.500 mm') ? f.textContent : false",
    );
    eprintln!("find on the page: {found}");
    d.wait_for("the find's end", |s| s["state"] == "idle");
    eprintln!(
        "backplot {plot}, progress {progress}, screenshot {}",
        dir.join("page.png").display()
    );
    // A phone: nothing wider than the screen, the controls still there.
    browser.command(
        "POST",
        "/window/rect",
        Some(json!({"width": 390, "height": 844})),
    );
    // Hold and Abort on screen without scrolling (a bar at the bottom edge).
    let fits = wait(
        "the phone layout",
        "const h = document.getElementById('hold').getBoundingClientRect(); \
         const a = document.getElementById('abort').getBoundingClientRect(); \
         return document.documentElement.scrollWidth <= window.innerWidth + 1 \
         && h.width > 0 && h.bottom <= window.innerHeight && a.bottom <= window.innerHeight \
         ? [document.documentElement.scrollWidth, window.innerWidth] : false",
    );
    eprintln!("on a phone: {fits}");
    // `edmd ctl web-link`: a one-time link logs a browser in; the second use does not.
    let link = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .args(["ctl", "--socket"])
        .arg(dir.join("edmd.sock"))
        .arg("web-link")
        .output()
        .unwrap();
    assert!(link.status.success());
    let link = String::from_utf8(link.stdout).unwrap();
    let url = link.split_whitespace().next().unwrap().to_string();
    assert!(url.contains("/#login="), "{link}");
    browser.eval("localStorage.removeItem('edmd-token'); return true");
    browser.command("POST", "/url", Some(json!({ "url": url })));
    wait(
        "the login by link",
        &format!(
            "return localStorage.getItem('edmd-token') === '{}' && document.getElementById('login').className === ''",
            d.token
        ),
    );
    browser.eval("localStorage.removeItem('edmd-token'); return true");
    browser.command("POST", "/url", Some(json!({ "url": url })));
    wait(
        "the used link refused",
        "return document.getElementById('message').textContent.includes('used up') && localStorage.getItem('edmd-token') === null",
    );
    let shot = browser.command("GET", "/screenshot", None);
    std::fs::write(
        dir.join("page-phone.png"),
        base64_decode(shot.as_str().unwrap()),
    )
    .unwrap();
    let mut page = String::new();
    ureq::get(&format!("{}/", d.base))
        .call()
        .unwrap()
        .into_reader()
        .read_to_string(&mut page)
        .unwrap();
    for outside in ["src=\"http", "href=\"http", "url(http", "@import"] {
        assert!(
            !page.contains(outside),
            "the page refers outside: {outside}"
        );
    }
}

/// Editing while a job runs: another program is read, checked and saved; the running job's
/// own program is not written over (409) and stays as it was run.
#[test]
fn while_a_job_runs_another_program_is_edited_and_the_running_one_is_kept() {
    let (d, dir) = start("background-edit", &[]);
    std::fs::write(dir.join("programs/other.nc"), "G21 G90\nG1 X1 F60\nM2\n").unwrap();
    let (code, _) = d.post("/api/run", r#"{"program": "runtime-path.nc"}"#);
    assert_eq!(code, 200);
    d.wait_for("running", |s| s["state"] == "running");
    let (code, listing) = d.call("GET", "/api/program?name=other.nc", None, None);
    assert_eq!(code, 200, "{listing}");
    let (code, reply) = d.post(
        "/api/programs?name=other.nc&replace=true&check=true",
        "G21 G90\nG1 X2 F60\nM2\n",
    );
    assert_eq!(code, 200, "{reply}");
    assert_eq!(
        std::fs::read_to_string(dir.join("programs/other.nc")).unwrap(),
        "G21 G90\nG1 X2 F60\nM2\n"
    );
    let before = std::fs::read_to_string(dir.join("programs/runtime-path.nc")).unwrap();
    let (code, reply) = d.post(
        "/api/programs?name=runtime-path.nc&replace=true&check=true",
        "G21 G90\nG1 X2 F60\nM2\n",
    );
    assert_eq!(code, 409, "{reply}");
    assert!(
        reply["error"]
            .as_str()
            .unwrap()
            .contains("the running job's program"),
        "{reply}"
    );
    assert_eq!(
        std::fs::read_to_string(dir.join("programs/runtime-path.nc")).unwrap(),
        before
    );
    d.post("/api/abort", "{}");
    d.wait_for("idle", |s| s["state"] == "idle");
}
