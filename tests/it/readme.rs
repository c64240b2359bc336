//! The documentation's sample outputs are what the binary prints: each block marked
//! `<!-- sample: NAME -->` in `docs/commands.md` is made by running its command here, and must
//! match but for what changes from run to run (wall time, the producer's busy time, memory).
//! The README itself stays a front door: the samples are in the commands' reference.
//!
//! `scripts/readme-samples.sh` (`EDMD_UPDATE_README=1 cargo test --test it readme`) writes
//! the fresh outputs into the document instead of comparing: after a change to what a command
//! prints, run it and commit the document with the change.

use crate::common;

use std::path::Path;
use std::process::Command;

/// A sample: the command as the README shows it, the arguments it runs with, and which of
/// its output lines the README keeps (`None`: all, stdout then stderr).
struct Sample {
    name: &'static str,
    shown: &'static str,
    args: &'static [&'static str],
    keep: Option<fn(&str) -> bool>,
}

const SAMPLES: &[Sample] = &[
    Sample {
        name: "tech-explain",
        shown: "edmd tech explain material=steel,height=50,wire=0.25",
        args: &["tech", "explain", "material=steel,height=50,wire=0.25"],
        keep: None,
    },
    Sample {
        name: "plan-technology",
        shown: "edmd plan programs/die-aluminium-30.ngc --out /tmp/die",
        args: &["plan", "programs/die-aluminium-30.ngc", "--out", "OUT"],
        keep: Some(|l| l.starts_with("estimated time") || l.starts_with("  pass ")),
    },
    Sample {
        name: "check-bad",
        shown: "edmd check bad.nc",
        args: &["check", "bad.nc"],
        keep: None,
    },
    Sample {
        name: "run-jin",
        shown: "edmd run programs/jin-table1-g06_2.nc",
        args: &["run", "programs/jin-table1-g06_2.nc"],
        keep: None,
    },
    Sample {
        name: "run-fault",
        shown: "edmd run programs/huang-table1-g38.nc --set output.fault_at_tick=500000",
        args: &[
            "run",
            "programs/huang-table1-g38.nc",
            "--set",
            "output.fault_at_tick=500000",
        ],
        keep: Some(|l| l.contains("end position:") || l.starts_with("edmd: error")),
    },
    Sample {
        name: "plan-jin",
        shown: "edmd plan programs/jin-table1-g06_2.nc --out /tmp/jin --set interpolation.segmentation=period --set fine.tick_us=3",
        args: &[
            "plan",
            "programs/jin-table1-g06_2.nc",
            "--out",
            "OUT",
            "--set",
            "interpolation.segmentation=period",
            "--set",
            "fine.tick_us=3",
        ],
        keep: Some(|l| {
            [
                "motion time",
                "estimated time",
                "time-optimal bound",
                "max chord",
                "max feed",
                "fluctuation",
            ]
            .iter()
            .any(|k| l.starts_with(k))
        }),
    },
];

/// A bad program for `check-bad`: an arc with both a radius and a centre on line 4.
const BAD: &str = "G21 G90\nG0 X0 Y0\nG1 X5 F100\nG2 X10 Y0 I5 R5\nM2\n";

/// What the README shows for `sample`, made now.
fn fresh(sample: &Sample, scratch: &Path) -> String {
    let args: Vec<String> = sample
        .args
        .iter()
        .map(|a| match *a {
            "OUT" => scratch.join("plan").display().to_string(),
            a => a.to_string(),
        })
        .collect();
    // The repository's programs by their relative names; `bad.nc` where it was written.
    let cwd = if sample.args.contains(&"bad.nc") {
        scratch.to_path_buf()
    } else {
        common::repo()
    };
    let out = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .args(&args)
        .current_dir(cwd)
        .env_remove("RUST_LOG")
        .output()
        .expect("edmd runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    // Logging goes to stderr with time stamps; the README shows the summary and the errors.
    let stderr = stderr
        .lines()
        .filter(|l| l.starts_with("edmd: error") || l.starts_with(' '));
    let lines: Vec<String> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .chain(stderr)
        .map(str::to_string)
        .collect();
    let mut text = format!("$ {}\n", sample.shown);
    match sample.keep {
        None => lines.iter().for_each(|l| text += &format!("{l}\n")),
        Some(keep) => {
            text += "...\n";
            lines
                .iter()
                .filter(|l| keep(l))
                .for_each(|l| text += &format!("{l}\n"));
        }
    }
    text
}

/// `text` with what changes from run to run blanked: wall times, the producer's busy time
/// and its ratio, memory.
fn steady(text: &str) -> String {
    text.lines()
        .map(|l| {
            let volatile = ["producer:", "memory:", "wall time", "peak RSS"]
                .iter()
                .any(|k| l.trim_start().starts_with(k));
            if volatile {
                // A run of digits becomes one `#`: a ratio of 96900x and one of 169915x agree.
                let mut steady = String::new();
                for c in l.chars() {
                    if !c.is_ascii_digit() {
                        steady.push(c);
                    } else if !steady.ends_with('#') {
                        steady.push('#');
                    }
                }
                steady
            } else if let Some((head, _)) = l.split_once(" s machine (") {
                // `time: 1088.752 s machine (… ticks of 50 µs), 1.671 s wall`: the wall part.
                let tail = l.rsplit_once(", ").map_or("", |t| t.0);
                format!("{head}{}", &tail[head.len()..])
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// The README's block after `<!-- sample: NAME -->`: its byte range (inside the fence).
fn block(readme: &str, name: &str) -> std::ops::Range<usize> {
    let marker = format!("<!-- sample: {name} -->\n```text\n");
    let start = readme
        .find(&marker)
        .unwrap_or_else(|| panic!("docs/commands.md has no sample {name}"))
        + marker.len();
    let end = start + readme[start..].find("```\n").expect("the block ends");
    start..end
}

#[test]
fn readme_samples_are_what_the_binary_prints() {
    let scratch = common::scratch("readme", "samples");
    std::fs::write(scratch.join("bad.nc"), BAD).unwrap();
    let path = common::repo().join("docs/commands.md");
    let mut readme = std::fs::read_to_string(&path).unwrap();
    let update = std::env::var_os("EDMD_UPDATE_README").is_some_and(|v| v == "1");
    let mut stale = Vec::new();
    for sample in SAMPLES {
        let made = fresh(sample, &scratch);
        let range = block(&readme, sample.name);
        if steady(&readme[range.clone()]) != steady(&made) {
            stale.push(format!(
                "{}:\n--- docs/commands.md\n{}--- edmd prints\n{made}",
                sample.name,
                &readme[range.clone()]
            ));
            if update {
                readme.replace_range(range, &made);
            }
        }
    }
    if update {
        std::fs::write(&path, &readme).unwrap();
        eprintln!("{} sample(s) rewritten", stale.len());
    } else {
        assert!(
            stale.is_empty(),
            "docs/commands.md samples differ from what edmd prints (scripts/readme-samples.sh \
             rewrites them):\n{}",
            stale.join("\n")
        );
    }
}

/// The README's tour, run in the order it is written, as a reader on a fresh machine would
/// type it: every `edmd` command of its shell blocks (and the `mkdir`/`cp` that set up the
/// daemon's directory) succeeds, the daemon's jobs end done. `/tmp/edmd`, `/tmp/jin` and
/// `/tmp/die` become this test's scratch directory; `cargo build` is the build that ran the
/// test; the HAL machine (it needs root and LinuxCNC) is `tests/it/hal.rs`'s.
#[test]
fn the_readme_tour_runs_in_the_order_it_is_written() {
    let scratch = common::scratch("readme", "tour");
    let readme = std::fs::read_to_string(common::repo().join("README.md")).unwrap();
    let tour = &readme[readme.find("## A tour").expect("a tour")..];
    let tour = &tour[..tour[3..].find("\n## ").map_or(tour.len(), |i| i + 3)];
    let bin = std::path::Path::new(env!("CARGO_BIN_EXE_edmd"))
        .parent()
        .unwrap();
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let here = |line: &str| {
        line.replace("/tmp/edmd", &scratch.join("edmd").display().to_string())
            .replace("/tmp/jin", &scratch.join("jin").display().to_string())
            .replace("/tmp/die", &scratch.join("die").display().to_string())
    };
    let mut daemon: Option<std::process::Child> = None;
    let mut ran = Vec::new();
    for block in tour.split("```sh\n").skip(1) {
        let block = &block[..block.find("```").expect("the block ends")];
        if block.contains("halrun") {
            continue;
        }
        for command in block.replace("\\\n", " ").lines() {
            let command = command.trim();
            if !(command.starts_with("edmd ") || command.starts_with("mkdir ")) {
                continue;
            }
            let command = here(command);
            if let Some(serve) = command.strip_suffix('&') {
                let log = std::fs::File::create(scratch.join("serve.log")).unwrap();
                daemon = Some(
                    Command::new("sh")
                        .args(["-c", &format!("exec {serve}")])
                        .current_dir(common::repo())
                        .env("PATH", &path)
                        .env_remove("RUST_LOG")
                        .stdout(std::process::Stdio::null())
                        .stderr(log)
                        .spawn()
                        .unwrap(),
                );
                let socket = scratch.join("edmd/edmd.sock");
                let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
                while std::os::unix::net::UnixStream::connect(&socket).is_err() {
                    assert!(std::time::Instant::now() < deadline, "the tour's daemon");
                    std::thread::sleep(std::time::Duration::from_millis(50));
                }
                ran.push(command);
                continue;
            }
            let out = Command::new("sh")
                .args(["-c", &command])
                .current_dir(common::repo())
                .env("PATH", &path)
                .env_remove("RUST_LOG")
                .output()
                .unwrap();
            assert!(
                out.status.success(),
                "the tour stops at `{command}` (after {ran:?}):\n{}{}",
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
            ran.push(command);
        }
    }
    let mut daemon = daemon.expect("the tour serves");
    let _ = Command::new("kill")
        .args(["-TERM", &daemon.id().to_string()])
        .status();
    assert!(
        daemon.wait().unwrap().success(),
        "the tour's daemon stops cleanly"
    );
    assert!(
        ran.iter().filter(|c| c.contains(" ctl ")).count() >= 5,
        "the tour's commands: {ran:?}"
    );
}
