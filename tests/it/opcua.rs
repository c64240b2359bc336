//! The OPC UA server end to end: the real `edmd serve` with `daemon.opcua` on a free
//! loopback port, and a real shop-floor client, Python's `asyncua` (PyPI), running
//! `tests/opcua/client.py` against it while a job cuts.
//!
//! `.ci/run` installs asyncua and sets `EDMD_OPCUA_TESTS=1`, which makes it required;
//! elsewhere the test says it is skipped when asyncua is missing.

use crate::common;

use std::process::Command;

use common::daemon::*;
use serde_json::Value;

fn have_asyncua() -> bool {
    Command::new("python3")
        .args(["-c", "import asyncua"])
        .output()
        .is_ok_and(|o| o.status.success())
}

fn free_port() -> u16 {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    listener.local_addr().unwrap().port()
}

/// Whether the OPC UA tests can run: Python's asyncua is there (required under
/// `EDMD_OPCUA_TESTS=1`).
fn asyncua_or_skip() -> bool {
    if have_asyncua() {
        return true;
    }
    assert!(
        std::env::var_os("EDMD_OPCUA_TESTS").is_none(),
        "EDMD_OPCUA_TESTS is set but Python's asyncua is not installed"
    );
    eprintln!("skipped: no asyncua (pip install asyncua)");
    false
}

/// A daemon of `dir` serving OPC UA on a free port, with a fresh certificate store and users
/// file: the daemon, its URL, the store, and the `operator`'s password it made.
fn opcua_daemon(dir: &std::path::Path) -> (Daemon, String, std::path::PathBuf, String) {
    let pki = dir.join("pki");
    let users = dir.join("opcua-users");
    let _ = std::fs::remove_dir_all(&pki);
    let _ = std::fs::remove_file(&users);
    let url = format!("opc.tcp://127.0.0.1:{}", free_port());
    let mut sets = base_sets(dir, "pulses.log");
    sets.extend([
        format!("daemon.opcua=\"{url}\""),
        format!("daemon.opcua_users_file=\"{}\"", users.display()),
        format!("daemon.opcua_pki_dir=\"{}\"", pki.display()),
    ]);
    let daemon = Daemon::start(dir, &sets, &[]);
    daemon.wait_for_log("opcua: the machine on");
    // The users file was made with one operator and a random password.
    let text = std::fs::read_to_string(&users).unwrap();
    let password = text
        .lines()
        .find_map(|l| l.strip_prefix("operator:"))
        .expect("an operator line")
        .to_string();
    (daemon, url, pki, password)
}

/// The JSON object a test client (`script`) printed, once it exited 0.
fn what_it_saw(script: &str, out: &std::process::Output) -> Value {
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{script} failed: {}\n{stdout}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    let seen: Value =
        serde_json::from_str(stdout.trim()).unwrap_or_else(|e| panic!("{e}: {stdout}"));
    eprintln!("{script} saw: {seen:#}");
    seen
}

#[test]
fn a_shop_floor_client_reads_subscribes_and_only_a_user_may_hold() {
    if !asyncua_or_skip() {
        return;
    }
    let dir = scratch("opcua");
    // About 20 s at the servo's 300 mm/min: the client reads it moving, then holds it.
    std::fs::write(
        dir.join("programs/long.ngc"),
        "G21 G90\nE3 G1 X80 Y60 F300\nM2\n",
    )
    .unwrap();
    let (daemon, url, pki, password) = opcua_daemon(&dir);
    daemon.ok(&["run", "long.ngc"]);
    daemon.wait_for("the job to move", is_moving);

    let out = Command::new("python3")
        .arg(common::repo().join("tests/opcua/client.py"))
        .args([&url, &pki.display().to_string(), "operator", &password])
        .arg(env!("CARGO_BIN_EXE_edmd"))
        .arg(&daemon.socket)
        .arg(&dir)
        .output()
        .expect("python3 runs");
    let seen = what_it_saw("client.py", &out);

    // Browsed: the machine after OPC 40501's layout, an axis object per configured axis.
    let tree: Vec<&str> = seen["tree"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p.as_str().unwrap())
        .collect();
    for path in [
        "Identification/SoftwareRevision",
        "Monitoring/MachineTool/State",
        "Monitoring/Channel/Feed",
        "Monitoring/Channel/FeedOverride",
        "Monitoring/EDMGenerator/GapState",
        "Monitoring/EDMGenerator/Condition",
        "Monitoring/EDMGenerator/WireOffset",
        "Monitoring/EDMGenerator/GapVoltage",
        "Production/ActiveProgram/Pass",
        "Production/ActiveProgram/Passes",
        "Production/ActiveProgram/Technology",
        "Monitoring/EDMGenerator/OnTime",
        "Monitoring/EDMGenerator/PeakCurrent",
        "Monitoring/Axes/X/ActualPosition",
        "Monitoring/Axes/Y/ActualPosition",
        "Production/ActiveProgram/Name",
        "Production/ActiveProgram/Line",
        "Production/ActiveProgram/Progress",
        "Production/ActiveProgram/RemainingTime",
        "Production/Hold",
        "Production/Abort",
        "Notification",
    ] {
        assert!(tree.contains(&path), "{path} not browsed: {tree:?}");
    }
    assert_eq!(seen["software_revision"], env!("CARGO_PKG_VERSION"));
    // Read while the job runs: its state, program, gap, and an X that moves.
    assert_eq!(seen["state_running"], "running");
    assert!(seen["program"].as_str().unwrap().ends_with("long.ngc"));
    assert_eq!(seen["gap"], "normal", "gap.kind = none reads normal");
    assert_eq!(seen["line"], 2);
    // What is cutting: E3, no wire offset, not in passes.
    assert_eq!(seen["condition"], 3);
    // E3's set points in the shipped [generator]: on 4 µs, the servo's reference 25 V.
    assert_eq!(seen["on_time"], 4.0);
    assert_eq!(seen["servo_ref"], 25.0);
    assert_eq!(seen["wire_offset"], 0.0);
    assert_eq!(seen["pass"], 0);
    let xs: Vec<f64> = seen["x_while_running"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!(
        xs.windows(2).all(|w| w[1] > w[0]),
        "X moves forward between reads 0.3 s apart: {xs:?}"
    );
    // Anonymous: Hold is visible but not executable, and a call is refused without effect.
    assert_eq!(seen["hold_user_executable_anonymous"], false);
    assert_eq!(seen["hold_anonymous"]["ok"], false);
    assert_eq!(seen["hold_anonymous"]["status"], "BadUserAccessDenied");
    assert_eq!(seen["state_after_anonymous_hold"], "running");
    // `ctl hold`: the subscription to the state sees held, an event says why, X stands.
    assert_eq!(seen["ctl_hold_exit"], 0);
    let states: Vec<&str> = seen["states"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|s| s.as_str())
        .collect();
    assert!(states.contains(&"running"), "{states:?}");
    assert_eq!(states.last(), Some(&"held"), "{states:?}");
    let events = seen["events"].as_array().unwrap();
    assert!(
        events.iter().any(|e| e["type"] == "EdmHoldEventType"
            && e["message"].as_str().unwrap().contains("at line 2")
            && e["severity"] == 400),
        "{events:?}"
    );
    assert_eq!(seen["x_held"][0], seen["x_held"][1], "held: X stands");
    // The encrypted endpoint: an unknown client certificate is rejected and kept for the
    // administrator; once trusted, a wrong password is refused and the operator may abort.
    assert_eq!(seen["unknown_certificate"], "BadCertificateUntrusted");
    assert_eq!(seen["rejected"], 1);
    assert_eq!(seen["wrong_password"], "BadUserAccessDenied");
    assert_eq!(seen["hold_user_executable_signed_in"], true);
    assert_eq!(
        seen["abort_signed_in"]["ok"], true,
        "{}",
        seen["abort_signed_in"]
    );
    assert_eq!(seen["state_after_abort"], "idle");
    assert_eq!(seen["last_outcome"], "stopped");
    // A method the control loop refuses (hold with no job) is an error status, not success.
    assert_eq!(seen["hold_when_idle"]["status"], "BadInvalidState");
    let status = daemon.status();
    assert_eq!(status["state"], "idle");
    let log = daemon.log();
    assert!(log.contains("opcua: operator signed in"), "{log}");
    assert!(log.contains("opcua: Abort: aborting"), "{log}");
    assert!(
        !log.contains("INFO opcua_server"),
        "the library's chatter stays out at info"
    );
}

#[test]
fn an_mes_stores_starts_pauses_and_aborts_job_orders_and_reads_their_results() {
    if !asyncua_or_skip() {
        return;
    }
    let dir = scratch("opcua-jobs");
    // A short cut (about 4 s at 300 mm/min) and a long one (about 40 s).
    std::fs::write(dir.join("programs/short.ngc"), "G21 G90\nG1 X20 F300\nM2\n").unwrap();
    std::fs::write(
        dir.join("programs/long.ngc"),
        "G21 G90\nG1 X150 Y100 F300\nM2\n",
    )
    .unwrap();
    let (daemon, url, pki, password) = opcua_daemon(&dir);
    // G55 is 5 mm along X from G54: J1, stored with WorkSystem G55, ends at machine X 25.
    daemon.ok(&["mdi", "G10 L2 P2 X5"]);
    daemon.wait_for("the MDI line", |s| s["state"] == "idle");
    let out = Command::new("python3")
        .arg(common::repo().join("tests/opcua/jobs.py"))
        .args([&url, &pki.display().to_string(), "operator", &password])
        .arg(&dir)
        .output()
        .expect("python3 runs");
    let seen = what_it_saw("jobs.py", &out);
    let code = |k: &str| seen[k][0].as_u64().unwrap_or_else(|| panic!("{k}: {seen}"));
    // Only a signed-in user dispatches.
    assert_eq!(seen["anonymous_store"]["status"], "BadUserAccessDenied");
    // Store: once per id, programs of program_dir only.
    assert_eq!(code("store"), 0);
    assert_eq!(code("store_twice"), 2);
    assert_eq!(code("store_missing"), 2);
    assert_eq!(code("store_escape"), 2);
    assert_eq!(seen["list_stored"]["J1"], "AllowedToStart");
    // Start, Pause (a hold), Resume, to its end; one order at a time.
    assert_eq!(code("start"), 0, "{}", seen["start"]);
    assert_eq!(seen["running"], true, "{}", daemon.log());
    assert_eq!(code("pause"), 0);
    assert_eq!(seen["interrupted"], true);
    assert_eq!(
        code("start_while_running"),
        3,
        "{}",
        seen["start_while_running"]
    );
    assert_eq!(code("resume"), 0);
    assert_eq!(seen["ended"], true);
    // Its result is its line of the job history.
    let r = &seen["result_j1"];
    assert_eq!(r[0], 0);
    assert_eq!(r[1], "Ended");
    assert_eq!(r[2], "done");
    assert!(r[3].as_f64().unwrap() > 3.0, "machine time: {r}");
    assert!(!r[4].as_str().unwrap().is_empty(), "started: {r}");
    // StoreAndStart was refused while J1 ran, but J2 was stored: started and aborted now.
    assert_eq!(code("start_j2"), 0, "{}", seen["start_j2"]);
    assert_eq!(seen["j2_running"], true);
    assert_eq!(code("abort_j2"), 0);
    assert_eq!(seen["j2_aborted"], true);
    assert_eq!(seen["result_j2"][1], "Aborted");
    assert_eq!(seen["result_j2"][2], "stopped");
    // A stored order aborted before it ran, then cleared from the list.
    assert_eq!(code("store_j3"), 0);
    assert_eq!(code("abort_j3"), 0);
    assert_eq!(code("clear_j3"), 0);
    assert_eq!(code("result_unknown"), 1);
    assert_eq!(
        seen["list_end"],
        serde_json::json!({"J1": "Ended", "J2": "Aborted"})
    );
    // J1 selected its work system before it started: it ended at machine X 25 (its X20 in
    // G55), where J2 (G54 again after J1's M2) began and was aborted on its way to X150.
    let status = daemon.status();
    let x = status["last_job"]["end_mm"][0].as_f64().unwrap();
    assert!((25.0..30.0).contains(&x), "J2 stopped at X {x}: {status}");
    let log = daemon.log();
    assert!(
        log.contains("opcua: Start: job order \"J1\" started"),
        "{log}"
    );
}
