//! The web side attacked as a hostile page, a careless client and a flood would, while a job
//! cuts: the real `edmd serve` on loopback, driven over raw TCP where a polite HTTP client
//! would not do what the attack does.

use crate::common;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::web::{Daemon, start, start_with};
use serde_json::json;

/// One request over a fresh connection with exactly these headers: the status code, the
/// response's head and its body.
fn exchange(d: &Daemon, request: &str) -> (u16, String, String) {
    let mut stream = TcpStream::connect(d.base.trim_start_matches("http://")).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(20)))
        .unwrap();
    stream.write_all(request.as_bytes()).unwrap();
    let mut text = String::new();
    let _ = stream.read_to_string(&mut text);
    let (head, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    let code = head
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    (code, head.to_ascii_lowercase(), body.to_string())
}

fn get(path: &str, host: &str) -> String {
    format!("GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n")
}

/// A page elsewhere cannot read the machine through the browser (DNS rebinding), frame it,
/// or have its content sniffed; the token's scheme is read in any case.
#[test]
fn only_the_machines_own_names_are_served_and_every_answer_carries_the_policy() {
    let (d, _dir) = start("hosts", &["daemon.http_allowed_hosts=[\"edm-7.shop.lan\"]"]);
    let port = d.port();
    for host in [
        format!("127.0.0.1:{port}"),
        format!("localhost:{port}"),
        format!("[::1]:{port}"),
        "edm-7.shop.lan".to_string(),
    ] {
        let (code, head, _) = exchange(&d, &get("/api/status", &host));
        assert_eq!(code, 200, "{host}: {head}");
    }
    for host in [
        "evil.example",
        "127.0.0.1.evil.example:80",
        "edm-7.shop.lan.evil.example",
    ] {
        let (code, _, body) = exchange(&d, &get("/api/status", host));
        assert_eq!(code, 403, "{host}");
        assert!(body.contains("daemon.http_allowed_hosts"), "{body}");
        // The page and the metrics too.
        assert_eq!(exchange(&d, &get("/", host)).0, 403);
        assert_eq!(exchange(&d, &get("/metrics", host)).0, 403);
    }
    // HTTP/1.0 without a Host: refused as well.
    let (code, ..) = exchange(&d, "GET /api/status HTTP/1.0\r\n\r\n");
    assert_eq!(code, 403);

    let host = format!("127.0.0.1:{port}");
    for path in ["/", "/api/status", "/no-such-page"] {
        let (_, head, _) = exchange(&d, &get(path, &host));
        for needle in [
            "content-security-policy: default-src 'none'; script-src 'sha256-",
            "frame-ancestors 'none'",
            "x-frame-options: deny",
            "x-content-type-options: nosniff",
        ] {
            assert!(head.contains(needle), "{path}: no {needle:?} in\n{head}");
        }
        assert!(!head.contains("unsafe-inline"), "{head}");
    }

    // `bearer` in lower case is the Bearer scheme.
    let hold = |auth: &str| {
        exchange(
            &d,
            &format!(
                "POST /api/hold HTTP/1.1\r\nHost: {host}\r\nAuthorization: {auth}\r\n\
                 Content-Length: 0\r\nConnection: close\r\n\r\n"
            ),
        )
        .0
    };
    assert_eq!(
        hold(&format!("bearer {}", d.token)),
        409,
        "no job: the daemon's refusal"
    );
    assert_eq!(hold(&format!("BEARER {}", d.token)), 409);
    assert_eq!(hold(&format!("Basic {}", d.token)), 401);
    assert_eq!(hold("bearer wrong"), 401);
}

/// Missing programs and programs outside the directory get one answer with no path in it;
/// the listing follows no link out of the directory, survives a dangling one, and names with
/// control characters (a forged log line) are refused.
#[test]
fn program_names_reveal_nothing_and_forge_nothing() {
    let (d, dir) = start("names", &[]);
    let programs = dir.join("programs");
    std::os::unix::fs::symlink("/etc", programs.join("etc-link")).unwrap();
    std::os::unix::fs::symlink(dir.join("nowhere.nc"), programs.join("dangling.nc")).unwrap();
    std::os::unix::fs::symlink("/etc/hostname", programs.join("host.nc")).unwrap();
    std::fs::create_dir(programs.join("sub")).unwrap();
    std::fs::write(programs.join("sub/part.nc"), "G1 X1 F60\nM2\n").unwrap();
    std::os::unix::fs::symlink(programs.join("sub/part.nc"), programs.join("alias.nc")).unwrap();

    let (code, list) = d.call("GET", "/api/programs", None, None);
    assert_eq!(code, 200, "{list}");
    let names: Vec<&str> = list["programs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        ["alias.nc", "runtime-path.nc", "short.nc", "sub/part.nc"]
    );

    for name in [
        "missing.nc",
        "../http-token",
        "/etc/passwd",
        "etc-link/passwd",
        "host.nc",
        "dangling.nc",
        "sub",
    ] {
        let (code, reply) = d.call(
            "GET",
            &format!("/api/path?program={}", urlencode(name)),
            None,
            None,
        );
        assert_eq!(code, 404, "{name}: {reply}");
        let error = reply["error"].as_str().unwrap();
        assert_eq!(
            error,
            format!("{name}: no such program in the program directory")
        );
        assert!(!error.contains("/etc/hostname") && !error.contains(dir.to_str().unwrap()));
    }
    let forged = "short.nc\n2026-11-23T00:00:00Z  INFO edmd::daemon::jobs: job end: done";
    let (code, reply) = d.post("/api/run", &json!({ "program": forged }).to_string());
    assert_eq!(code, 400, "{reply}");
    assert!(
        reply["error"]
            .as_str()
            .unwrap()
            .contains("no control characters")
    );
    std::thread::sleep(Duration::from_millis(100));
    assert!(
        !d.log()
            .lines()
            .any(|l| l.starts_with("2026-11-23T00:00:00Z")),
        "a forged line in the log:\n{}",
        d.log()
    );
}

fn urlencode(text: &str) -> String {
    text.bytes()
        .map(|b| match b {
            b'a'..=b'z' | b'A'..=b'Z' | b'0'..=b'9' | b'.' | b'-' | b'_' => (b as char).to_string(),
            _ => format!("%{b:02X}"),
        })
        .collect()
}

/// Work that is not the machine's (drawing programs that loop for ever, a million circles)
/// is bounded in time, memory and number, and never delays status, hold or metrics; nesting
/// that would overflow a stack is an error; a SIGTERM during a check that would run for
/// minutes ends the daemon at once.
#[test]
fn runaway_and_deep_programs_never_delay_or_kill_the_daemon() {
    let (d, dir) = start("runaway", &["program.max_loop_iterations=1000000000"]);
    let programs = dir.join("programs");
    std::fs::write(
        programs.join("runaway.nc"),
        "o1 repeat [1000000]\no2 repeat [1000000]\n#1=[#1+1]\no2 endrepeat\no1 endrepeat\nM2\n",
    )
    .unwrap();
    std::fs::write(
        programs.join("circles.nc"),
        "#1=0\no1 while [#1 LT 1000000]\nG2 X0 Y0 I1 J0 F60\n#1=[#1+1]\no1 endwhile\nM2\n",
    )
    .unwrap();
    let deep = format!(
        "#1={}1{}\nG1 X#1 F60\nM2\n",
        "[".repeat(6000),
        "]".repeat(6000)
    );
    std::fs::write(programs.join("deep.nc"), deep).unwrap();

    assert_eq!(
        d.post("/api/run", r#"{"program":"runtime-path.nc"}"#).0,
        200
    );
    d.wait_for("cutting", |s| s["state"] == "running");

    // 12 KB of brackets, no token needed: an error, not a dead daemon.
    let (code, reply) = d.call("GET", "/api/path?program=deep.nc", None, None);
    assert_eq!(code, 400, "{reply}");
    assert!(
        reply["error"]
            .as_str()
            .unwrap()
            .starts_with("deep.nc:1:260: expression nested deeper than 256"),
        "{reply}"
    );

    // Eight drawings of a program that never ends, at once.
    let base = d.base.clone();
    let previews: Vec<_> = (0..8)
        .map(|_| {
            let url = format!("{base}/api/path?program=runaway.nc");
            std::thread::spawn(move || {
                let started = Instant::now();
                let code = match ureq::get(&url).call() {
                    Ok(r) => r.status(),
                    Err(ureq::Error::Status(c, _)) => c,
                    Err(e) => panic!("{e}"),
                };
                (code, started.elapsed())
            })
        })
        .collect();
    std::thread::sleep(Duration::from_millis(200));
    for path in ["/api/status", "/metrics", "/api/status"] {
        let started = Instant::now();
        let (code, _) = d.raw("GET", path, None, None);
        assert_eq!(code, 200);
        let took = started.elapsed();
        assert!(took < Duration::from_millis(500), "{path} took {took:?}");
    }
    let started = Instant::now();
    assert_eq!(d.post("/api/hold", "").0, 200);
    assert!(started.elapsed() < Duration::from_millis(500));
    let codes: Vec<(u16, Duration)> = previews.into_iter().map(|t| t.join().unwrap()).collect();
    let served = codes.iter().filter(|(c, _)| *c == 200).count();
    let busy = codes.iter().filter(|(c, _)| *c == 503).count();
    assert_eq!((served, busy), (2, 6), "{codes:?}");
    for (code, took) in &codes {
        if *code == 200 {
            assert!(*took < Duration::from_secs(4), "a drawing took {took:?}");
        }
    }
    d.wait_for("held", |s| s["state"] == "held");

    // A million circles: the drawing is the circle, thinned in the plane, not one spot of it.
    let (code, path) = d.call("GET", "/api/path?program=circles.nc", None, None);
    assert_eq!(code, 200, "{path}");
    let points: Vec<(f64, f64)> = path["strokes"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|s| s["points"].as_array().unwrap().iter())
        .map(|p| (p[0].as_f64().unwrap(), p[1].as_f64().unwrap()))
        .collect();
    assert!(points.len() <= 20_000, "{} points", points.len());
    assert!(path["blocks"].as_u64().unwrap() > 1000, "{path}");
    let span = |f: fn(&(f64, f64)) -> f64| {
        let v: Vec<f64> = points.iter().map(f).collect();
        v.iter().cloned().fold(f64::MIN, f64::max) - v.iter().cloned().fold(f64::MAX, f64::min)
    };
    assert!(
        (span(|p| p.0) - 2.0).abs() < 0.05 && (span(|p| p.1) - 2.0).abs() < 0.05,
        "the circle of radius 1 is drawn whole: {points:?}"
    );
    for (x, y) in &points {
        let r = ((x - 1.0).powi(2) + y.powi(2)).sqrt();
        assert!((r - 1.0).abs() < 1e-9, "({x}, {y}) is off the circle");
    }
    let pid = d.child.id();
    let peak = std::fs::read_to_string(format!("/proc/{pid}/status"))
        .unwrap()
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches(" kB").trim().parse::<u64>().ok())
        .unwrap();
    assert!(peak < 64 * 1024, "peak RSS {peak} kB");

    // A check that would run for minutes: SIGTERM ends the daemon within 2 s all the same.
    assert_eq!(d.post("/api/abort", "").0, 200);
    d.wait_for("idle", |s| s["state"] == "idle");
    assert_eq!(d.post("/api/run", r#"{"program":"runaway.nc"}"#).0, 200);
    d.wait_for("checking", |s| s["state"] == "checking");
    std::thread::sleep(Duration::from_millis(300));
    let signalled = Instant::now();
    // SAFETY: kill(2) on our own child's pid.
    assert_eq!(unsafe { libc::kill(pid as i32, libc::SIGTERM) }, 0);
    let mut d = d;
    let code = loop {
        if let Some(status) = d.child.try_wait().unwrap() {
            break status.code();
        }
        assert!(
            signalled.elapsed() < Duration::from_secs(2),
            "still running:\n{}",
            d.log()
        );
        std::thread::sleep(Duration::from_millis(10));
    };
    assert_eq!(code, Some(0), "{}", d.log());
}

/// More half-open connections than the descriptor limit allows: the daemon keeps its
/// descriptors for checkpoints and the socket, the newest client (a Hold) is always served,
/// and a connection that never finishes its request head is closed.
#[test]
fn half_open_connections_cannot_starve_the_daemon() {
    // This test holds 1,100 connections open itself.
    raise_own_descriptor_limit(4096);
    let (d, dir) = start_with("flood", &[], |cmd, _| limit_descriptors(cmd, 1024));
    assert_eq!(
        d.post("/api/run", r#"{"program":"runtime-path.nc"}"#).0,
        200
    );
    d.wait_for("cutting", |s| s["state"] == "running");
    let addr = d.base.trim_start_matches("http://").to_string();
    let flood: Vec<TcpStream> = (0..1100)
        .filter_map(|_| {
            let mut s = TcpStream::connect(&addr).ok()?;
            let _ = s.write_all(b"GET /api/status HTTP/1.1\r\nHo");
            Some(s)
        })
        .collect();
    assert!(flood.len() > 1024, "{} connections made", flood.len());
    std::thread::sleep(Duration::from_millis(300));
    let started = Instant::now();
    assert_eq!(d.post("/api/hold", "").0, 200);
    let took = started.elapsed();
    assert!(took < Duration::from_millis(500), "hold took {took:?}");
    // The checkpoint of the hold is written: the daemon had descriptors to spare.
    let held = d.wait_for("the hold's checkpoint", |s| {
        s["state"] == "held" && s["checkpoint"]["still"] == true
    });
    assert!(held.get("checkpoint_write_error").is_none(), "{held}");
    let ctl = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .args(["ctl", "--json", "--socket"])
        .arg(dir.join("edmd.sock"))
        .arg("status")
        .output()
        .unwrap();
    assert!(
        ctl.status.success(),
        "{}",
        String::from_utf8_lossy(&ctl.stderr)
    );
    let open = std::fs::read_dir(format!("/proc/{}/fd", d.child.id()))
        .unwrap()
        .count();
    assert!(open < 1024 - 100, "{open} descriptors open");
    drop(flood);

    // One client that never finishes its head is closed by the header timeout.
    let mut slow = TcpStream::connect(&addr).unwrap();
    slow.write_all(b"GET / HTTP/1.1\r\nHo").unwrap();
    slow.set_read_timeout(Some(Duration::from_secs(20)))
        .unwrap();
    let started = Instant::now();
    let mut rest = Vec::new();
    let _ = slow.read_to_end(&mut rest);
    let after = started.elapsed();
    assert!(
        after >= Duration::from_secs(9) && after < Duration::from_secs(15),
        "closed after {after:?}"
    );
    assert_eq!(d.post("/api/abort", "").0, 200);
}

fn raise_own_descriptor_limit(to: u64) {
    let mut limit = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit/setrlimit on a valid struct for this test process.
    unsafe {
        libc::getrlimit(libc::RLIMIT_NOFILE, &mut limit);
        limit.rlim_cur = limit.rlim_max.min(to.max(limit.rlim_cur));
        libc::setrlimit(libc::RLIMIT_NOFILE, &limit);
    }
}

/// The child starts with soft and hard descriptor limits of `n` (as `prlimit --nofile=n`).
fn limit_descriptors(cmd: &mut Command, n: u64) {
    use std::os::unix::process::CommandExt;
    // SAFETY: setrlimit is async-signal-safe and touches only the child's limits.
    unsafe {
        cmd.pre_exec(move || {
            let limit = libc::rlimit {
                rlim_cur: n,
                rlim_max: n,
            };
            if libc::setrlimit(libc::RLIMIT_NOFILE, &limit) == 0 {
                Ok(())
            } else {
                Err(std::io::Error::last_os_error())
            }
        });
    }
}

/// A token a person can guess is refused at startup; SIGHUP reads the token file again, and
/// a new program directory, and HTTP uses them from the next request.
#[test]
fn the_token_is_long_and_a_reload_puts_token_and_directory_in_force() {
    let dir = common::scratch("http", "token");
    let short = dir.join("short-token");
    std::fs::write(&short, "abc\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .arg("serve")
        .args([
            "--set",
            &format!("daemon.socket=\"{}\"", dir.join("s.sock").display()),
        ])
        .args(["--set", "daemon.http=\"127.0.0.1:0\""])
        .args([
            "--set",
            &format!("daemon.http_token_file=\"{}\"", short.display()),
        ])
        .args([
            "--set",
            &format!("daemon.program_dir=\"{}\"", dir.display()),
        ])
        .args([
            "--set",
            &format!("daemon.checkpoint=\"{}\"", dir.join("cp.json").display()),
        ])
        .args(["--set", &format!("daemon.state_dir=\"{}\"", dir.display())])
        .stdin(Stdio::null())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("the HTTP token is 3 characters; a token needs at least 32"),
        "{stderr}"
    );

    // A configuration file, so that a reload can change the program directory.
    let config = dir.join("edmd.toml");
    let other = dir.join("other-programs");
    std::fs::create_dir_all(&other).unwrap();
    std::fs::write(other.join("elsewhere.nc"), "G1 X1 F60\nM2\n").unwrap();
    let programs = |d: &Daemon| -> Vec<String> {
        let (_, list) = d.call("GET", "/api/programs", None, None);
        list["programs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p["name"].as_str().unwrap().to_string())
            .collect()
    };
    let programs_dir = common::scratch("http", "token").join("programs");
    std::fs::write(
        &config,
        format!("[daemon]\nprogram_dir = \"{}\"\n", programs_dir.display()),
    )
    .unwrap();
    let config_arg = config.clone();
    let (d, dir) = start_with("token", &[], move |cmd, sets| {
        // The program directory comes from the file, which a reload reads again.
        sets.retain(|s| !s.starts_with("daemon.program_dir"));
        cmd.arg("--config").arg(&config_arg);
    });
    assert_eq!(programs(&d), ["runtime-path.nc", "short.nc"]);
    let old = d.token.clone();
    let hold = |token: &str| d.call("POST", "/api/hold", Some(token), Some("")).0;
    assert_eq!(hold(&old), 409);
    let new = "f".repeat(40);
    std::fs::write(dir.join("http-token"), format!("{new}\n")).unwrap();
    std::fs::write(
        &config,
        format!("[daemon]\nprogram_dir = \"{}\"\n", other.display()),
    )
    .unwrap();
    // SAFETY: kill(2) on our own child's pid.
    assert_eq!(unsafe { libc::kill(d.child.id() as i32, libc::SIGHUP) }, 0);
    let deadline = Instant::now() + Duration::from_secs(10);
    while hold(&new) != 409 {
        assert!(
            Instant::now() < deadline,
            "the new token is not in force:\n{}",
            d.log()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(hold(&old), 401, "the old token is gone");
    assert_eq!(programs(&d), ["elsewhere.nc"], "the new program directory");
    let (code, _) = d.call("GET", "/api/path?program=elsewhere.nc", None, None);
    assert_eq!(code, 200);
    // A reload with a token that is too short keeps the one in force.
    std::fs::write(dir.join("http-token"), "abc\n").unwrap();
    // SAFETY: as above.
    assert_eq!(unsafe { libc::kill(d.child.id() as i32, libc::SIGHUP) }, 0);
    let deadline = Instant::now() + Duration::from_secs(10);
    while !d.log().contains("the previous token stays in force") {
        assert!(Instant::now() < deadline, "{}", d.log());
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(hold(&new), 409);
}
