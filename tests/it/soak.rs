//! Soak: a long generated program through `edmd run` in virtual time with the simulated gap
//! shorting all the way, twice, at a tenth of the length and at full length.
//!
//! Checked for each: the job ends done, exactly on the program's end point (the pulse ledger
//! loses and doubles nothing through every turn-back); the simulated gap shorted at least
//! once per 100 blocks; no starvation; the producer worked many times faster than real time;
//! and peak RSS stays under 32 MiB and flat in the program length (the longer run within
//! 2 MiB of the shorter).
//!
//! CI runs 20,000 blocks. The soak of issue [6/6], 1,000,000 blocks and ≥ 10,000 shorts:
//!
//! ```text
//! EDMD_SOAK_BLOCKS=1000000 cargo test --release --test it soak:: -- --nocapture
//! ```

use crate::common;

use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;

/// A zig-zag of `blocks` moves 20 µm apart in X, alternating `G01` lines and `G02` arcs,
/// about 22 µm of path each: every block becomes one to a few loop-buffer segments, so the
/// program exercises block hand-over, arcs and turn-backs across many blocks.
fn write_program(path: &Path, blocks: u64) {
    let mut text = String::with_capacity(blocks as usize * 32);
    text.push_str("(soak: generated)\nG21 G90 G17\nG01 X0 Y0 F300\n");
    for i in 1..=blocks {
        let x = i as f64 * 0.02;
        if i % 2 == 1 {
            let y = if i % 4 == 1 { 0.01 } else { 0.0 };
            let _ = writeln!(text, "G01 X{x:.3} Y{y:.3}");
        } else {
            let _ = writeln!(text, "G02 X{x:.3} Y0.005 R0.02");
        }
    }
    text.push_str("M30\n");
    std::fs::write(path, text).unwrap();
}

struct Soak {
    summary: serde_json::Value,
}

impl Soak {
    fn u(&self, key: &str) -> u64 {
        self.summary[key]
            .as_u64()
            .unwrap_or_else(|| panic!("{key}"))
    }

    fn f(&self, key: &str) -> f64 {
        self.summary[key]
            .as_f64()
            .unwrap_or_else(|| panic!("{key}"))
    }
}

fn soak(dir: &Path, blocks: u64) -> Soak {
    let program = dir.join(format!("soak-{blocks}.nc"));
    let summary = dir.join(format!("soak-{blocks}.json"));
    write_program(&program, blocks);
    // About 0.022 mm of path per block at the default 60 mm/min normal feed: 22 ms of
    // machine time per block. Debris shorts at 2 per second of sparking give ≈ 4 per 100
    // blocks, each turning back 300 µm (≈ 14 blocks) and re-advancing.
    let out = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .current_dir(common::repo())
        .args(["run", program.to_str().unwrap(), "--summary"])
        .arg(&summary)
        .args([
            "--set",
            "fine.virtual_time=true",
            "--set",
            "gap.kind=\"sim\"",
            "--set",
            "sim.debris_shorts_per_mm=0",
            "--set",
            "sim.model=\"kinematic\"",
            "--set",
            "sim.debris_shorts_per_s=2.0",
            "--set",
            "output.kind=\"sim\"",
            "--set",
            "log.level=\"warn\"",
            // The program runs along X far past any table: no soft limits.
            "--set",
            "machine.travel_mm={}",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "edmd run failed: {}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    let _ = std::fs::remove_file(&program);
    Soak { summary }
}

#[test]
fn a_long_program_with_many_shorts_ends_exactly_in_flat_memory() {
    let blocks: u64 = std::env::var("EDMD_SOAK_BLOCKS")
        .ok()
        .map(|v| v.parse().expect("EDMD_SOAK_BLOCKS: a number of blocks"))
        .unwrap_or(20_000);
    let dir = common::scratch("soak", "run");
    let mut peaks = Vec::new();
    for n in [blocks / 10, blocks] {
        let s = soak(&dir, n);
        let summary = &s.summary;
        println!(
            "{n} blocks: {} segments, {} shorts, {} turn-backs (deepest {} blocks), \
             {:.0} s machine in {:.1} s wall, producer busy {:.2} s ({:.0}x real time), \
             buffer high water {}, peak RSS {:.1} MiB, end {} steps",
            s.u("segments"),
            s.u("shorts"),
            s.u("turn_backs"),
            s.u("deepest_turn_back_blocks"),
            s.f("virtual_time_s"),
            s.f("wall_time_s"),
            s.f("producer_busy_s"),
            s.f("virtual_time_s") / s.f("producer_busy_s"),
            s.u("buffer_high_water"),
            s.u("peak_rss_kib") as f64 / 1024.0,
            summary["end_steps"],
        );
        assert_eq!(summary["outcome"], "done", "{summary:#}");
        assert_eq!(
            s.u("blocks"),
            n,
            "the program's blocks (the G01 to the start is empty)"
        );
        assert_eq!(
            summary["end_steps"], summary["program_end_steps"],
            "the ledger ends on the program's end point"
        );
        // Every pulse went somewhere: per axis, pulses minus the net move is an even number
        // (every step away was matched by one back).
        for (axis, (pulses, end)) in summary["steps_per_axis"]
            .as_array()
            .unwrap()
            .iter()
            .zip(summary["end_steps"].as_array().unwrap())
            .enumerate()
        {
            let (pulses, end) = (pulses.as_u64().unwrap(), end.as_i64().unwrap());
            assert!(pulses >= end.unsigned_abs(), "axis {axis}");
            assert_eq!(
                (pulses - end.unsigned_abs()) % 2,
                0,
                "axis {axis}: odd pulse count"
            );
        }
        assert!(
            s.u("shorts") >= n / 100,
            "{} shorts for {n} blocks: fewer than one per 100",
            s.u("shorts")
        );
        assert_eq!(s.u("turn_backs"), s.u("shorts"), "every short turned back");
        assert_eq!(s.u("alarms"), 0);
        assert_eq!(s.u("starvations"), 0);
        assert!(
            s.f("virtual_time_s") > 10.0 * s.f("producer_busy_s"),
            "the producer is not 10x faster than real time"
        );
        peaks.push(s.u("peak_rss_kib"));
    }
    let (short, long) = (peaks[0], peaks[1]);
    assert!(long < 32 * 1024, "peak RSS {long} KiB: not under 32 MiB");
    assert!(
        long <= short + 2 * 1024,
        "peak RSS grows with the program: {short} KiB at a tenth of the length, {long} KiB"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
