//! Tabs (`wire.tab_mm`, issue [5/9]) through the real binary: a die and a punch cut in three
//! passes leaving a 1.5 mm tab. From the pulse log: every pass cuts at its own offset from
//! the contour, no pass before the tab's cut touches the tab, the tab is cut after the last
//! pass with its settings, and the job ends on the program's end point. Through `edmd serve`:
//! the job pauses for the slug at the tab with the message the operator needs, a stop in
//! pass 2 resumes, and the joined pulses are the uninterrupted run's.

use crate::common;

use common::daemon::{Daemon, base_sets};
use common::wire::{DIE, PUNCH, TABLE, inside_die, outside_punch, walk};

const TAB_MM: f64 = 1.5;

/// The table with a tab, and pass 2 and 3's directions as given.
fn table(reverse: [bool; 2]) -> String {
    let passes = format!(
        "[wire]\ntab_mm = {TAB_MM}\npass = [\n  {{ offset_mm = 0.2, condition = 3 }},\n  \
         {{ offset_mm = 0.15, condition = 2, reverse = {} }},\n  \
         {{ offset_mm = 0.12, condition = 1, reverse = {} }} ]\n",
        reverse[0], reverse[1]
    );
    let head = &TABLE[..TABLE.find("[wire]").unwrap()];
    format!("{head}{passes}")
}

/// A daemon's scratch directory `name` with the die and the tabbed table (pass 2 reversed):
/// the directory, the table's file and the `--config` arguments that read it.
fn die_daemon_dir(name: &str) -> (std::path::PathBuf, std::path::PathBuf, [String; 2]) {
    let dir = common::daemon::scratch(name);
    let config = dir.join("wire.toml");
    std::fs::write(&config, table([true, false])).unwrap();
    std::fs::write(dir.join("programs/die.ngc"), DIE).unwrap();
    let _ = std::fs::remove_file(dir.join("machine-state.json"));
    let args = ["--config".to_string(), config.display().to_string()];
    (dir, config, args)
}

/// Waits for the job's pause for the slug, at the tab's start on the last pass's path
/// on the die's bottom edge at 0.12 mm.
fn paused_at_the_tab(daemon: &Daemon) {
    let paused = daemon.wait_for("the slug's pause", |s| s["state"] == "paused");
    assert_eq!(paused["job"]["pause"], "secure the slug", "{paused}");
    let at = common::daemon::position(&paused);
    assert!(
        (at[0] + 1500).abs() <= 2 && (at[1] + 1880).abs() <= 2,
        "paused at {at:?}"
    );
}

type Distance = dyn Fn(&(i64, i64)) -> i64;

struct Part {
    name: &'static str,
    program: &'static str,
    distance: &'static Distance,
    /// The y (µm) of the contour's last edge, where the tab is, at offset `d` (µm).
    tab_y: fn(i64) -> i64,
    reverse: [bool; 2],
}

#[test]
fn a_die_and_a_punch_in_three_passes_leave_the_tab_to_the_end() {
    let dir = common::scratch("tabs", "cli");
    let parts = [
        // Alternating: each pass starts where the last stopped.
        Part {
            name: "die",
            program: DIE,
            distance: &inside_die,
            tab_y: |d| -2000 + d,
            reverse: [true, false],
        },
        // Pass 2 forward again (it travels back along pass 1, spark off), pass 3 backward
        // (the tab is then cut backward from where the contour closes).
        Part {
            name: "punch",
            program: PUNCH,
            distance: &outside_punch,
            tab_y: |d| 2000 - d,
            reverse: [false, true],
        },
    ];
    for part in parts {
        let config = dir.join(format!("{}.toml", part.name));
        std::fs::write(&config, table(part.reverse)).unwrap();
        let program = dir.join(format!("{}.ngc", part.name));
        std::fs::write(&program, part.program).unwrap();
        let pulses = dir.join(format!("{}.csv", part.name));
        let out = common::run_to_pulse_log(
            &program,
            &pulses,
            &["--config", config.to_str().unwrap(), "--passes", "3"],
        );
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{err}");
        assert!(err.contains("secure the slug"), "{err}");
        let (rows, end) = walk(&pulses);
        let name = part.name;
        assert_eq!(
            end,
            (0, 0),
            "{name}: the job ends on the program's end point"
        );
        let cutting = |c: u16| -> Vec<(usize, (i64, i64))> {
            rows.iter()
                .enumerate()
                .filter(|(_, r)| r.1 == c && r.2)
                .map(|(i, r)| (i, r.0))
                .collect()
        };
        // The tab's stretch at an offset: the last edge, 0.1 mm clear of its ends.
        let in_tab = |p: &(i64, i64), d: i64| {
            (p.1 - (part.tab_y)(d)).abs() <= 2 && (-1400..=-100).contains(&p.0)
        };
        for (condition, d) in [(3u16, 200i64), (2, 150), (1, 120)] {
            let pts = cutting(condition);
            // Along the contour (away from the entry and exit at X0), at the pass's offset.
            let far: Vec<i64> = pts
                .iter()
                .filter(|(_, p)| p.0.abs() > 300)
                .map(|(_, p)| (part.distance)(p))
                .collect();
            assert!(far.len() > 1000, "{name} E{condition}");
            assert!(
                far.iter().all(|&x| (x - d).abs() <= 2),
                "{name} E{condition}: {:?} µm from the contour, want {d}",
                (far.iter().min(), far.iter().max())
            );
            // The direction, from the shoelace area of the pass's cut (+: counter-clockwise,
            // the programs' own direction): a reversed pass runs clockwise.
            let reversed = match condition {
                3 => false,
                2 => part.reverse[0],
                _ => part.reverse[1],
            };
            let area: f64 = pts
                .windows(2)
                .map(|w| (w[0].1.0 * w[1].1.1 - w[1].1.0 * w[0].1.1) as f64)
                .sum::<f64>()
                / 2e6;
            assert!(
                area * if reversed { -1.0 } else { 1.0 } > 5.0,
                "{name} E{condition}: signed area {area} mm²"
            );
            if condition == 1 {
                continue;
            }
            // Passes 1 and 2 leave the tab: they stop (or start) 1.5 mm before the contour
            // closes, at on the last edge.
            assert!(
                !pts.iter().any(|(_, p)| in_tab(p, d)),
                "{name} E{condition} cut into the tab"
            );
            let nearest = pts
                .iter()
                .filter(|(_, p)| (p.1 - (part.tab_y)(d)).abs() <= 2 && p.0 < -100)
                .map(|(_, p)| p.0)
                .max();
            assert!(
                nearest.is_some_and(|x| (x + 1500).abs() <= 3),
                "{name} E{condition}: the cut ends at X{nearest:?} µm, not at the tab"
            );
        }
        // The tab is cut with the last pass's settings, after everything else was cut.
        let last = cutting(1);
        let tab_rows: Vec<usize> = last
            .iter()
            .filter(|(_, p)| in_tab(p, 120))
            .map(|(i, _)| *i)
            .collect();
        assert!(tab_rows.len() > 1000, "{name}: the tab was not cut");
        let before_tab = cutting(2)
            .iter()
            .chain(last.iter().filter(|(_, p)| p.0 > 300))
            .map(|(i, _)| *i)
            .max()
            .unwrap();
        assert!(
            tab_rows[0] > before_tab,
            "{name}: the tab cut before the passes were done"
        );
    }
}

#[test]
fn a_sigterm_in_pass_2_resumes_and_the_slug_pause_holds_at_the_tab_with_the_same_pulses() {
    let (dir, config, args) = die_daemon_dir("tabs");
    let daemon = Daemon::start_args(&dir, &args, &base_sets(&dir, "first.csv"), &[]);
    daemon.ok(&["run", "die.ngc", "--passes", "3"]);
    daemon.wait_for("the second pass", |s| {
        s["state"] == "running" && s["job"]["progress"].as_f64().unwrap_or(0.0) > 0.45
    });
    // SIGTERM in pass 2: the job brakes, is checkpointed, and the daemon exits.
    daemon.signal(libc::SIGTERM);
    assert_eq!(daemon.wait().0, 0);
    let cp: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("checkpoint.json")).unwrap())
            .unwrap();
    assert_eq!(cp["tab_mm"], TAB_MM, "{cp}");

    let daemon = Daemon::start_args(&dir, &args, &base_sets(&dir, "second.csv"), &[]);
    daemon.ok(&["resume"]);
    paused_at_the_tab(&daemon);
    daemon.wait_for_log("secure the slug");
    daemon.resume_to_the_end(&[0, 0]);

    let reference = dir.join("reference.csv");
    let out = common::run_to_pulse_log(
        &dir.join("programs/die.ngc"),
        &reference,
        &["--config", config.to_str().unwrap(), "--passes", "3"],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    common::daemon::assert_joined_is(&dir, &common::daemon::moves(&reference));
}

/// The tab per job: a machine with no tab configured (`wire.tab_mm = 0`) cuts one because the
/// job asks (`--tab 1.5`), pausing for the slug where the configured tab would; a tab
/// without passes, or a negative one, is refused.
#[test]
fn a_job_asks_for_its_own_tab() {
    let (dir, _, args) = die_daemon_dir("tab-per-job");
    let mut sets = base_sets(&dir, "pulses.csv");
    sets.push("wire.tab_mm=0.0".into());
    let daemon = Daemon::start_args(&dir, &args, &sets, &[]);
    daemon.refused(&["run", "die.ngc", "--tab=-1"], "0 mm (none) or more");
    daemon.refused(
        &["run", "die.ngc", "--tab", "1.5"],
        "--tab 1.5: a tab is left by a job in passes",
    );
    daemon.ok(&["run", "die.ngc", "--passes", "3", "--tab", "1.5"]);
    paused_at_the_tab(&daemon);
    daemon.resume_to_the_end(&[0, 0]);
}
