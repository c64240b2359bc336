//! Nothing lost on disk (issue [1/7] of round five), against the running daemon:
//!
//! - two uploads of one new name at once: one saved, the other refused with 409, never a
//!   silent overwrite (30 of 30);
//! - a torn last line of `jobs.jsonl`: the next job's line is whole, the torn one skipped and
//!   named by where it starts;
//! - a history line that cannot be written (a directory in the file's place) is kept and
//!   written once it can be, the counters and the history agreeing;
//! - an unreadable `counters.json` is kept aside and the counters rebuilt from the history;
//! - `jobs.jsonl` and `counters.json` that are FIFOs neither hang the start nor the stop, and
//!   MQTT credentials or CA files that are FIFOs are refused at once;
//! - a `(TECH …)` header after 100 KiB of comments is read; one past 1 MiB is refused;
//! - a program name of 255 bytes uploads and runs, with its report.

use std::time::{Duration, Instant};

use crate::common;
use common::web::start;
use serde_json::Value;

fn upload(d: &common::web::Daemon, name: &str, text: &str) -> u16 {
    let token = d.token.clone();
    d.raw(
        "POST",
        &format!("/api/programs?name={}", urlencode(name)),
        Some(&token),
        Some(text),
    )
    .0
}

fn urlencode(text: &str) -> String {
    text.bytes()
        .map(|b| match b {
            b'a'..=b'z' | b'A'..=b'Z' | b'0'..=b'9' | b'-' | b'_' | b'.' => (b as char).to_string(),
            _ => format!("%{b:02X}"),
        })
        .collect()
}

fn jobs(d: &common::web::Daemon) -> Value {
    let (code, reply) = d.call("GET", "/api/jobs?count=50", None, None);
    assert_eq!(code, 200, "{reply}");
    reply
}

fn run_to_end(d: &common::web::Daemon, program: &str) -> Value {
    let jobs_before = d.status()["counters"]["jobs"].as_u64().unwrap_or(0);
    let (code, reply) = d.post("/api/run", &format!(r#"{{"program":"{program}"}}"#));
    assert_eq!(code, 200, "{reply}");
    d.wait_for("the job's end", |s| {
        s["state"] == "idle" && s["counters"]["jobs"].as_u64().unwrap_or(0) > jobs_before
    })
}

#[test]
fn two_uploads_of_one_new_name_never_overwrite_each_other() {
    let (d, dir) = start("upload-race", &[]);
    for round in 0..30 {
        let name = format!("race-{round}.nc");
        let (a, b) = std::thread::scope(|s| {
            let a = s.spawn(|| upload(&d, &name, "G21 G90\nG1 X0.1 F60\nM2\n"));
            let b = s.spawn(|| upload(&d, &name, "G21 G90\nG1 X0.2 F60\nM2\n"));
            (a.join().unwrap(), b.join().unwrap())
        });
        let mut codes = [a, b];
        codes.sort();
        assert_eq!(codes, [200, 409], "round {round}");
        let kept = std::fs::read_to_string(dir.join("programs").join(&name)).unwrap();
        assert!(kept.contains("X0.1") || kept.contains("X0.2"), "{kept}");
    }
    let stray: Vec<_> = std::fs::read_dir(dir.join("programs"))
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(".upload"))
        .collect();
    assert!(stray.is_empty(), "temporary files left: {stray:?}");
}

#[test]
fn the_history_loses_no_job_torn_unwritable_or_its_counters_gone() {
    let (d, dir) = start("history", &[]);
    let history = dir.join("jobs.jsonl");
    run_to_end(&d, "short.nc");
    // A power cut in the middle of the next line.
    use std::io::Write;
    let mut f = std::fs::OpenOptions::new()
        .append(true)
        .open(&history)
        .unwrap();
    f.write_all(br#"{"program":"torn.nc","started":"2026-"#)
        .unwrap();
    drop(f);
    let torn_at = std::fs::metadata(&history).unwrap().len()
        - br#"{"program":"torn.nc","started":"2026-"#.len() as u64;
    run_to_end(&d, "short.nc");
    let listed = jobs(&d);
    assert_eq!(listed["jobs"].as_array().unwrap().len(), 2, "{listed}");
    assert_eq!(
        listed["unreadable"][0],
        format!("byte {torn_at}: not a job (a torn line)"),
        "{listed}"
    );
    // The socket's `jobs` names it too.
    let ctl = std::process::Command::new(env!("CARGO_BIN_EXE_edmd"))
        .args(["ctl", "--socket"])
        .arg(dir.join("edmd.sock"))
        .arg("jobs")
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&ctl.stdout);
    assert!(text.contains("a torn line"), "{text}");

    // The history cannot be written: the line waits, and is written once it can be.
    std::fs::rename(&history, dir.join("jobs.aside")).unwrap();
    std::fs::create_dir(&history).unwrap();
    let s = run_to_end(&d, "short.nc");
    assert!(
        s["history_write_error"].as_str().is_some(),
        "the status says so: {s}"
    );
    assert_eq!(s["hours"]["jobs"], 3);
    std::fs::remove_dir(&history).unwrap();
    std::fs::rename(dir.join("jobs.aside"), &history).unwrap();
    let s = d.wait_for("the history written again", |s| {
        s["history_write_error"].is_null()
    });
    assert_eq!(jobs(&d)["jobs"].as_array().unwrap().len(), 3, "{s}");
    drop(d);

    // Counters that do not read: kept aside, rebuilt from the history's three jobs.
    std::fs::write(dir.join("counters.json"), "{\"jobs\": 3, \"machine_s\"").unwrap();
    let (d, dir) = start("history", &[]);
    let s = d.status();
    assert_eq!(s["hours"]["jobs"], 3, "{s}");
    assert!(s["hours"]["machine_s"].as_f64().unwrap() > 0.0);
    let aside = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .filter(|e| {
            e.file_name()
                .to_string_lossy()
                .starts_with("counters.json.bad-")
        })
        .count();
    assert_eq!(aside, 1);
    assert!(d.log().contains("rebuilt from the history"), "{}", d.log());
}

#[test]
fn fifos_in_the_place_of_the_daemon_s_files_hang_nothing() {
    let dir = common::scratch("http", "fifo-files");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    for name in ["jobs.jsonl", "counters.json"] {
        let made = std::process::Command::new("mkfifo")
            .arg(dir.join(name))
            .status()
            .unwrap();
        assert!(made.success());
    }
    let started = Instant::now();
    let (mut d, _) = start("fifo-files", &[]);
    assert!(started.elapsed() < Duration::from_secs(10));
    run_to_end(&d, "short.nc");
    let s = d.status();
    assert!(
        s["history_write_error"]
            .as_str()
            .is_some_and(|e| e.contains("not a regular file")),
        "{s}"
    );
    // SIGTERM still stops it at once.
    // SAFETY: kill(2) on our own child.
    unsafe { libc::kill(d.child.id() as i32, libc::SIGTERM) };
    let deadline = Instant::now() + Duration::from_secs(10);
    while d.child.try_wait().unwrap().is_none() {
        assert!(Instant::now() < deadline, "SIGTERM ignored:\n{}", d.log());
        std::thread::sleep(Duration::from_millis(20));
    }

    // The MQTT credentials and CA as FIFOs: the start is refused at once, naming the file.
    for (key, name) in [
        ("daemon.mqtt.credentials_file", "mqtt-credentials"),
        ("daemon.mqtt.ca_file", "mqtt-ca.pem"),
    ] {
        let fifo = dir.join(name);
        let _ = std::fs::remove_file(&fifo);
        assert!(
            std::process::Command::new("mkfifo")
                .arg(&fifo)
                .status()
                .unwrap()
                .success()
        );
        let broker = if key.ends_with("ca_file") {
            "mqtts://127.0.0.1:1"
        } else {
            "mqtt://127.0.0.1:1"
        };
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_edmd"))
            .arg("serve")
            .current_dir(&dir)
            .args([
                "--set",
                &format!("daemon.socket=\"{}\"", dir.join("m.sock").display()),
            ])
            .args([
                "--set",
                &format!("daemon.state_dir=\"{}\"", dir.join("m").display()),
            ])
            .args(["--set", &format!("daemon.mqtt.broker=\"{broker}\"")])
            .args(["--set", &format!("{key}=\"{}\"", fifo.display())])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{err}");
        assert!(err.contains("a FIFO, not a regular file"), "{err}");
    }
}

#[test]
fn a_technology_header_is_read_wherever_it_stands_in_the_header_or_refused_past_its_bound() {
    let (d, dir) = start("tech-header", &[]);
    let tech = dir.join("technology");
    std::fs::create_dir_all(&tech).unwrap();
    std::fs::write(tech.join("testium.toml"), crate::technology::FAST_TABLE).unwrap();
    drop(d);
    let tables = format!("technology.dir=\"{}\"", tech.display());
    let (d, dir) = start("tech-header", &[&tables]);
    let comments = "(a note that the customer's drawing came with)\n".repeat(2500);
    assert!(comments.len() > 100 * 1024);
    // A closed square: the table's three passes go round it.
    let program = format!(
        "{comments}(TECH material=testium height=30 wire=0.25)\nG21 G91\n\
         G1 X0.2 F60\nG1 Y0.2\nG1 X-0.2\nG1 Y-0.2\nM2\n"
    );
    std::fs::write(dir.join("programs/late.ngc"), &program).unwrap();
    let s = run_to_end(&d, "late.ngc");
    assert_eq!(s["last_job"]["outcome"], "done", "{s}");
    let listed = jobs(&d);
    assert!(
        listed["jobs"][0]["technology"]
            .as_str()
            .is_some_and(|t| t.starts_with("material=testium")),
        "{listed}"
    );

    let endless = "(a note)\n".repeat(130_000);
    assert!(endless.len() > 1024 * 1024);
    std::fs::write(
        dir.join("programs/endless.ngc"),
        format!("{endless}(TECH material=testium height=30 wire=0.25)\nG1 X1 F60\nM2\n"),
    )
    .unwrap();
    let (_, reply) = d.post("/api/run", r#"{"program":"endless.ngc"}"#);
    let said = reply.to_string();
    let s = d.wait_for("the refusal", |s| {
        s["check"]["phase"] == "refused" || said.contains("runs past")
    });
    let text = format!("{said} {s}");
    assert!(text.contains("runs past 1024 KiB"), "{text}");
    assert!(text.contains("endless.ngc:"), "{text}");
}

#[test]
fn a_program_name_of_255_bytes_uploads_and_runs_with_its_report() {
    let dir = common::scratch("http", "long-name");
    let reports = format!("daemon.report_dir=\"{}\"", dir.join("reports").display());
    let (d, _) = start("long-name", &[&reports]);
    let name = format!("{}.ngc", "p".repeat(251));
    assert_eq!(name.len(), 255);
    assert_eq!(upload(&d, &name, "G21 G91\nG1 X0.05 F60\nM2\n"), 200);
    let s = run_to_end(&d, &name);
    assert_eq!(s["last_job"]["outcome"], "done", "{s}");
    let report = std::fs::read_dir(dir.join("reports"))
        .unwrap()
        .flatten()
        .next()
        .expect("a report folder");
    assert!(report.file_name().len() <= 255);
}

#[test]
fn a_credentials_file_others_may_read_is_used_with_a_warning() {
    let dir = common::scratch("http", "loose-credentials");
    let credentials = dir.join("mqtt-credentials");
    std::fs::write(&credentials, "edm:secret\n").unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&credentials, std::fs::Permissions::from_mode(0o644)).unwrap();
    let sets = [
        "daemon.mqtt.broker=\"mqtt://127.0.0.1:1\"".to_string(),
        format!("daemon.mqtt.credentials_file=\"{}\"", credentials.display()),
    ];
    let sets: Vec<&str> = sets.iter().map(String::as_str).collect();
    let (d, _) = start("loose-credentials", &sets);
    let deadline = Instant::now() + Duration::from_secs(10);
    while !d
        .log()
        .contains("is mode 0644: others on this computer may read it")
    {
        assert!(Instant::now() < deadline, "no warning:\n{}", d.log());
        std::thread::sleep(Duration::from_millis(20));
    }
}
