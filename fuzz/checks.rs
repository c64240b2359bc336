//! What each fuzz target checks, shared with `tests/it/fuzz_regressions.rs` (which replays the
//! saved inputs on stable Rust in CI) so the two can never drift apart.
//!
//! Each check feeds untrusted input to one of edmd's front doors and panics if the door
//! panics, hangs on its own, or breaks a promise it makes about what it lets through:
//!
//! - G-code: every block handed out has finite geometry and a finite length (what `edmd check`
//!   and the planner compute first; a slow length is a hang, which libFuzzer's `-timeout`
//!   reports) and starts where the previous one ended; every error carries `source:line:col`.
//! - configuration: any TOML text plus any `--set` overrides either loads into a configuration
//!   whose derived values are usable, or fails with `origin: message`.
//! - control protocol: any byte stream from a client is cut into bounded lines; each line is a
//!   request that round-trips through its JSON form, or an error located `request:L:C`; a
//!   `run` path is either refused or confined to the program directory.

#![allow(dead_code)] // each fuzz target uses one of these

use std::io::{BufRead, BufReader, Cursor, Read};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use edmd::config::Config;
use edmd::daemon::protocol::Request;
use edmd::gcode::{BlockReader, CURVE_START_TOLERANCE_MM};
use edmd::vocab::Axis;

/// Blocks read from one input at most: generated inputs of many tiny lines are cheap per
/// block, and this keeps one input's time bounded without hiding any per-block behaviour.
const MAX_BLOCKS: usize = 10_000;

/// The G-code parser over arbitrary bytes (not necessarily UTF-8), on a 3-axis machine.
pub fn gcode(data: &[u8]) {
    let axes = [Axis::X, Axis::Y, Axis::Z];
    let mut reader = BlockReader::new(BufReader::new(Cursor::new(data)), "fuzz.nc", &axes);
    let mut previous_end: Option<edmd::geometry::Point> = None;
    for item in reader.by_ref().take(MAX_BLOCKS) {
        match item {
            Ok(block) => {
                let curve = &block.curve;
                assert!(curve.u_min() < curve.u_max(), "empty parameter range");
                for u in [
                    curve.u_min(),
                    0.5 * (curve.u_min() + curve.u_max()),
                    curve.u_max(),
                ] {
                    let d = curve.derivs(u);
                    for k in 0..axes.len() {
                        assert!(
                            d.point[k].is_finite() && d.d1[k].is_finite() && d.d2[k].is_finite(),
                            "line {}: non-finite geometry at u = {u}: {d:?}",
                            block.line
                        );
                    }
                }
                if let Some(feed) = block.feed_mm_per_min {
                    assert!(feed.is_finite() && feed > 0.0, "feed {feed}");
                }
                let length = curve.length();
                assert!(
                    length.is_finite() && length >= 0.0,
                    "line {}: length {length}",
                    block.line
                );
                let start = block.start();
                if let Some(end) = previous_end {
                    let gap = (start - end).norm();
                    let scale = 1.0 + start.norm().max(1.0) * 1e-12;
                    assert!(
                        gap <= CURVE_START_TOLERANCE_MM * scale,
                        "line {}: block starts {gap} mm from where the previous ended",
                        block.line
                    );
                }
                previous_end = Some(block.end());
            }
            Err(err) => {
                let text = err.to_string();
                assert!(text.starts_with("fuzz.nc:"), "unlocated error: {text}");
                if err.line > 0 {
                    let prefix = format!("fuzz.nc:{}:{}: ", err.line, err.col);
                    assert!(text.starts_with(&prefix), "error not at line:col: {text}");
                }
                break;
            }
        }
    }
}

/// The configuration loader: the input is TOML text, then optionally a NUL byte and one
/// `section.key=value` override per line.
pub fn config(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return; // the loader reads files with read_to_string, which refuses non-UTF-8 first
    };
    let (toml, overrides) = match text.split_once('\0') {
        Some((toml, rest)) => (toml, rest.lines().map(str::to_string).collect()),
        None => (text, Vec::new()),
    };
    match Config::from_toml_str(toml, "fuzz.toml", &overrides) {
        Ok(config) => {
            // Derived values every command computes from a loaded configuration.
            let names = config.machine.axis_names();
            assert!(!names.is_empty(), "a configuration with no axes loaded");
            let _ = edmd::checkpoint::motion_hash(&config);
        }
        Err(err) => {
            let text = err.to_string();
            assert!(
                text.starts_with("fuzz.toml") || text.starts_with("--set "),
                "unlocated configuration error: {text}"
            );
        }
    }
}

/// The control protocol as the daemon's socket reads it: bounded lines, each parsed as a
/// request; `run` paths confined to a program directory.
pub fn protocol(data: &[u8]) {
    let mut reader = BufReader::new(Cursor::new(data));
    let limit = edmd::daemon::protocol::MAX_REQUEST_BYTES as u64 + 1;
    loop {
        // As the daemon reads: at most the limit, up to a newline.
        let mut bytes = Vec::new();
        if (&mut reader)
            .take(limit)
            .read_until(b'\n', &mut bytes)
            .is_err()
        {
            break;
        }
        let Some(line) = edmd::daemon::socket::request_line(bytes) else {
            break;
        };
        let Ok(line) = line else {
            continue; // not UTF-8 or too long: answered with an error, as the tests show
        };
        match Request::parse(&line) {
            Ok(request) => {
                let again = serde_json::to_string(&request).expect("a request serialises");
                assert_eq!(
                    Request::parse(&again),
                    Ok(request.clone()),
                    "round trip of {line:?}"
                );
                if let Request::Run { program, .. } = &request {
                    let dir = program_dir();
                    if let Ok(path) = edmd::daemon::confine(dir, program) {
                        assert!(path.starts_with(dir), "{program:?} escaped to {path:?}");
                        assert!(
                            path.is_file(),
                            "{program:?} confined to a non-file {path:?}"
                        );
                    }
                }
            }
            Err(err) => assert!(
                err.to_string().starts_with("request:"),
                "unlocated error: {err}"
            ),
        }
    }
}

/// A program directory with one program and a symlink pointing out of it, created once.
fn program_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("edmd-fuzz-programs-{}", std::process::id()));
        let programs = dir.join("programs");
        std::fs::create_dir_all(programs.join("sub")).expect("temp dir");
        std::fs::write(programs.join("part.nc"), "G1 X1\n").expect("temp file");
        std::fs::write(programs.join("sub/part.nc"), "G1 X1\n").expect("temp file");
        std::fs::write(dir.join("outside.nc"), "G1 X1\n").expect("temp file");
        let _ = std::os::unix::fs::symlink(dir.join("outside.nc"), programs.join("escape.nc"));
        programs.canonicalize().expect("canonical temp dir")
    })
}
