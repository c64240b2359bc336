//! The operator's console on the daemon: the feed and rapid overrides, through the real
//! binary, with the speed read back from the pulse log it writes.

mod common;

use common::daemon::{Daemon, base_sets, scratch};

/// Steps of axis 0 per tick over the ticks `from..to` of the pulse log.
fn rate(log: &str, from: u64, to: u64) -> f64 {
    let steps: i64 = log
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("tick"))
        .filter_map(|l| {
            let mut f = l.split(',');
            let tick: u64 = f.next()?.parse().ok()?;
            let x: i64 = f.next()?.parse().ok()?;
            (from..to).contains(&tick).then_some(x.abs())
        })
        .sum();
    steps as f64 / (to - from) as f64
}

/// The tick an override took effect at, from the daemon's log (`… override P % from t=T s`).
fn override_tick(log: &str, what: &str) -> u64 {
    let line = log
        .lines()
        .find(|l| l.contains(what))
        .unwrap_or_else(|| panic!("no {what:?} in the log:\n{log}"));
    let t: f64 = line
        .split("from t=")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|t| t.parse().ok())
        .unwrap();
    (t / 50e-6).round() as u64
}

#[test]
fn the_feed_override_changes_the_speed_within_a_tick_and_is_reported() {
    let dir = scratch("override");
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    std::fs::write(dir.join("programs/long.nc"), "G21 G90\nG1 X40 F300\nM2\n").unwrap();
    let mut sets = base_sets(&dir, "pulses.csv");
    // The servo's feed above the program's (a sparking gap that would allow more), so that
    // the planned ceiling is what the override moves.
    sets.push("servo.normal_feed_mm_per_min=1200.0".to_string());
    sets.push(format!(
        "daemon.report_dir=\"{}\"",
        dir.join("reports").display()
    ));
    let daemon = Daemon::start(&dir, &sets, &[]);
    // Out of range is refused, not clamped.
    daemon.refused(&["override", "feed", "250"], "give 0 to 200 %");
    daemon.refused(&["override", "rapid", "120"], "give 0 to 100 %");
    daemon.ok(&["run", "long.nc"]);
    daemon.wait_for("moving", common::daemon::is_moving);
    std::thread::sleep(std::time::Duration::from_millis(400));
    let reply = daemon.ok(&["override", "feed", "50"]);
    assert_eq!(reply["status"]["overrides"]["feed_pct"], 50);
    daemon.wait_for_log("feed override 50 % from t=");
    std::thread::sleep(std::time::Duration::from_millis(400));
    daemon.ok(&["override", "feed", "200"]);
    daemon.wait_for_log("feed override 200 % from t=");
    std::thread::sleep(std::time::Duration::from_millis(400));
    daemon.ok(&["abort"]);
    daemon.wait_for("the job's end", |s| s["state"] == "idle");
    let text = daemon.ctl(&["status"]);
    assert_eq!(text.1, 0);

    let log = daemon.log();
    let half = override_tick(&log, "feed override 50 % from t=");
    let double = override_tick(&log, "feed override 200 % from t=");
    let pulses = std::fs::read_to_string(dir.join("pulses.csv")).unwrap();
    // 300 mm/min is 0.25 steps of 1 µm per 50 µs tick; half of it after braking, twice it
    // after accelerating (the machine's limits allow 600 mm/min on a line).
    let before = rate(&pulses, half - 4000, half);
    let slow = rate(&pulses, half + 2000, double);
    let fast = rate(&pulses, double + 2000, double + 6000);
    assert!((before - 0.25).abs() < 0.01, "before: {before}");
    assert!((slow - 0.125).abs() < 0.01, "at 50 %: {slow}");
    assert!((fast - 0.5).abs() < 0.01, "at 200 %: {fast}");
    // The tick it took effect at is in the run report's events.
    let report = std::fs::read_dir(dir.join("reports"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let events = std::fs::read_to_string(report.join("events.csv")).unwrap();
    let row = events
        .lines()
        .find(|l| l.contains(",feed_override,50,"))
        .unwrap_or_else(|| panic!("{events}"));
    let tick: u64 = row.split(',').next().unwrap().parse().unwrap();
    // The log prints t to 0.1 ms (two ticks).
    assert!(tick.abs_diff(half) <= 2, "{row} vs tick {half}");
    assert!(events.contains(",feed_override,200,"), "{events}");
    // Overrides outlast the job: the next one starts at 200 %.
    let s = daemon.status();
    assert_eq!(s["overrides"]["feed_pct"], 200);
    assert_eq!(s["overrides"]["rapid_pct"], 100);
}
