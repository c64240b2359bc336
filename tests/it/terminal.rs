//! `edmd run` on a real terminal (a tmux pane): the progress bar and the log lines printed
//! during the job do not share a line, one bar is left, and log lines carry the local time
//! without module paths. Needs tmux; under `EDMD_TMUX_TESTS=1` (CI) its absence fails the
//! test, otherwise it is skipped with a note.

use crate::common;

use std::process::Command;
use std::time::{Duration, Instant};

fn have_tmux() -> bool {
    Command::new("tmux")
        .arg("-V")
        .output()
        .is_ok_and(|o| o.status.success())
}

/// A log line as a terminal shows it: `2026-11-23 20:10:03.512  INFO …`.
fn is_log_line(line: &str) -> bool {
    let b = line.as_bytes();
    b.len() > 24
        && b[..4].iter().all(u8::is_ascii_digit)
        && b[4] == b'-'
        && b[10] == b' '
        && b[13] == b':'
        && b[19] == b'.'
}

/// The bar as `term` draws it: `[####>----]  67 %  line 28 …`.
fn is_bar(line: &str) -> bool {
    line.contains("] ") && line.contains(" %  line ") && line.contains('[')
}

#[test]
fn the_progress_bar_and_the_log_never_share_a_line() {
    if !have_tmux() {
        assert!(
            std::env::var_os("EDMD_TMUX_TESTS").is_none(),
            "EDMD_TMUX_TESTS is set but tmux is not installed"
        );
        eprintln!("skipped: no tmux");
        return;
    }
    let dir = common::scratch("terminal", "bar");
    let program = dir.join("zigzag.ngc");
    let mut text = String::from("G21 G90\n");
    for i in 1..=40 {
        text.push_str(&format!(
            "G1 X{:.1} Y{:.2} F120\n",
            0.1 * f64::from(i),
            0.02 * f64::from(i % 2)
        ));
    }
    text.push_str("M2\n");
    std::fs::write(&program, text).unwrap();
    let marker = dir.join("exit");
    let _ = std::fs::remove_file(&marker);
    // Real time, so the bar is drawn while the simulator's debris shorts are logged.
    let command = format!(
        "cd '{}' && '{}' run '{}' --set fine.virtual_time=false --set sim.debris_shorts_per_mm=1.6; \
         echo $? > '{}'; sleep 120",
        common::repo().display(),
        env!("CARGO_BIN_EXE_edmd"),
        program.display(),
        marker.display()
    );
    let socket = format!("edmd-test-{}", std::process::id());
    let tmux = |args: &[&str]| {
        Command::new("tmux")
            .args(["-L", &socket])
            .args(args)
            .output()
            .unwrap()
    };
    let started = tmux(&[
        "new-session",
        "-d",
        "-s",
        "t",
        "-x",
        "160",
        "-y",
        "60",
        &command,
    ]);
    assert!(started.status.success(), "{started:?}");
    let deadline = Instant::now() + Duration::from_secs(90);
    while !marker.exists() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(200));
    }
    std::thread::sleep(Duration::from_millis(300));
    let pane = tmux(&["capture-pane", "-p", "-J", "-S", "-1000", "-t", "t"]);
    let _ = tmux(&["kill-server"]);
    let screen = String::from_utf8_lossy(&pane.stdout).to_string();
    assert!(marker.exists(), "the run did not end:\n{screen}");
    assert_eq!(
        std::fs::read_to_string(&marker).unwrap().trim(),
        "0",
        "{screen}"
    );
    let lines: Vec<&str> = screen.lines().filter(|l| !l.trim().is_empty()).collect();
    let logs: Vec<&&str> = lines.iter().filter(|l| is_log_line(l)).collect();
    let shorts = logs.iter().filter(|l| l.contains("short circuit")).count();
    assert!(shorts >= 2, "no log lines during the job:\n{screen}");
    for line in &lines {
        assert!(
            !(is_bar(line) && (line.contains(" INFO ") || line.contains(" WARN "))),
            "a log line on the bar's line: {line:?}\n{screen}"
        );
    }
    let bars = lines.iter().filter(|l| is_bar(l)).count();
    assert_eq!(bars, 1, "{bars} bars:\n{screen}");
    // Local time, and no module paths on a terminal.
    assert!(logs.iter().all(|l| !l.contains("edmd::")), "{screen}");
    assert!(
        !logs
            .iter()
            .any(|l| l.contains('T') && l.as_bytes()[10] == b'T')
    );
    // The run's summary follows, whole and on lines of its own.
    assert!(
        lines
            .iter()
            .any(|l| l.ends_with("zigzag.ngc: done") && !is_bar(l)),
        "{screen}"
    );
}
