//! The stepped part of issue [3/7] (Sato et al.'s reproduction) over twenty seeds:
//! `cargo bench -p edmd-benches --bench stepped_part [-- OUT_DIR]`.
//!
//! 1. The baseline: one fixed off time, the shortest of 12, 13, … µs that breaks no wire in
//!    any seed.
//! 2. The adaptive law (`[adaptive]`) on the same seeds.
//!
//! Prints the figures of BENCHMARKS.md (time, breaks, speed per stretch, the height
//! estimate's error) and writes `stepped-part.svg` (speed, off time and estimated height
//! along the cut, seed 1) and `stepped-part.csv` into OUT_DIR (default: target/).

#[path = "../tests/it/stepped.rs"]
mod stepped;

use edmd::plot::{Chart, Series, Style};
use stepped::{Cut, LENGTH_MM, OffTime, STRETCHES};

const SEEDS: u64 = 20;

fn main() {
    let out = std::env::args()
        .skip(1)
        .find(|a| !a.starts_with('-'))
        .map_or_else(
            || std::path::PathBuf::from("target"),
            std::path::PathBuf::from,
        );
    std::fs::create_dir_all(&out).unwrap();
    let run = |off: OffTime| -> Vec<Cut> { (1..=SEEDS).map(|s| stepped::cut(s, off)).collect() };

    let mut baseline = None;
    for us in 12..=40 {
        let cuts = run(OffTime::Fixed(us as f64));
        let breaks = cuts.iter().filter(|c| c.broke_at_mm.is_some()).count();
        println!("fixed off {us} µs: {breaks} of {SEEDS} seeds broke the wire");
        if breaks == 0 {
            baseline = Some((us, cuts));
            break;
        }
    }
    let (us, fixed) = baseline.expect("a fixed off time that breaks no wire");
    let adaptive = run(OffTime::Adaptive);
    let breaks = adaptive.iter().filter(|c| c.broke_at_mm.is_some()).count();
    println!("adaptive: {breaks} of {SEEDS} seeds broke the wire");

    let mean =
        |cuts: &[Cut], f: &dyn Fn(&Cut) -> f64| cuts.iter().map(f).sum::<f64>() / cuts.len() as f64;
    let whole = |c: &Cut| c.seconds;
    println!();
    println!("| | baseline, off {us} µs | adaptive | adaptive / baseline (speed) |");
    println!("|---|---|---|---|");
    let (tf, ta) = (mean(&fixed, &whole), mean(&adaptive, &whole));
    println!(
        "| the whole cut, s (mean of {SEEDS}) | {tf:.1} | {ta:.1} | {:.2}x |",
        tf / ta
    );
    for (name, a, b) in STRETCHES {
        let speed = |c: &Cut| {
            c.seconds_between(a, b)
                .map_or(f64::NAN, |s| (b - a) / s * 60.0)
        };
        let (sf, sa) = (mean(&fixed, &speed), mean(&adaptive, &speed));
        println!(
            "| {a}-{b} mm ({name}), mm/min | {sf:.2} | {sa:.2} | {:.2}x |",
            sa / sf
        );
    }
    let off = |c: &Cut, a: f64, b: f64| {
        let v: Vec<f64> = c
            .samples
            .iter()
            .filter(|s| s.mm > a && s.mm <= b)
            .map(|s| s.off_time_us)
            .collect();
        v.iter().sum::<f64>() / v.len().max(1) as f64
    };
    for (name, a, b) in STRETCHES {
        println!(
            "| off time {a}-{b} mm ({name}), µs | {us} | {:.1} | |",
            mean(&adaptive, &|c| off(c, a, b))
        );
    }
    let worst = adaptive
        .iter()
        .map(|c| c.worst_height_error(2.0))
        .fold(0.0, f64::max);
    println!(
        "| height estimate, worst error 2 mm or more after a step (all seeds) | | {:.1} % | |",
        worst * 100.0
    );
    let min_seconds = adaptive
        .iter()
        .map(|c| c.seconds)
        .fold(f64::INFINITY, f64::min);
    let max_seconds = adaptive.iter().map(|c| c.seconds).fold(0.0, f64::max);
    println!("adaptive cut times {min_seconds:.1} to {max_seconds:.1} s");

    chart(&out, &fixed[0], &adaptive[0], us);
}

/// Speed, off time and estimated height along the cut, one seed.
fn chart(out: &std::path::Path, fixed: &Cut, adaptive: &Cut, us: u32) {
    let speed = |c: &Cut| -> Vec<(f64, f64)> {
        c.samples
            .windows(5)
            .map(|w| {
                let (a, b) = (&w[0], &w[4]);
                (
                    (a.mm + b.mm) / 2.0,
                    (b.mm - a.mm) / (b.seconds - a.seconds) * 60.0,
                )
            })
            .collect()
    };
    let mut csv = String::from("mm,fixed_s,adaptive_s,adaptive_off_us,height_estimate_mm\n");
    for (f, a) in fixed.samples.iter().zip(&adaptive.samples) {
        csv.push_str(&format!(
            "{:.1},{:.3},{:.3},{:.2},{:.2}\n",
            a.mm, f.seconds, a.seconds, a.off_time_us, a.height_mm
        ));
    }
    std::fs::write(out.join("stepped-part.csv"), csv).unwrap();
    let svg = Chart {
        title: format!(
            "The stepped part (60 / 20 / 60 mm, poor flushing 6-9 mm), seed {}: speed ×10 mm/min, off time µs, estimated height mm",
            adaptive.seed
        ),
        x_label: "mm into the cut".into(),
        y_label: "".into(),
        series: vec![
            Series {
                name: format!("speed, fixed off {us} µs (×10 mm/min)"),
                color: "#888888",
                style: Style::Line,
                points: speed(fixed).into_iter().map(|(x, y)| (x, y * 10.0)).collect(),
            },
            Series {
                name: "speed, adaptive (×10 mm/min)".into(),
                color: "#1f77b4",
                style: Style::Line,
                points: speed(adaptive).into_iter().map(|(x, y)| (x, y * 10.0)).collect(),
            },
            Series {
                name: "off time, adaptive (µs)".into(),
                color: "#d62728",
                style: Style::Line,
                points: adaptive.samples.iter().map(|s| (s.mm, s.off_time_us)).collect(),
            },
            Series {
                name: "estimated height (mm)".into(),
                color: "#2ca02c",
                style: Style::Line,
                points: adaptive
                    .samples
                    .iter()
                    .filter(|s| s.height_mm.is_finite())
                    .map(|s| (s.mm, s.height_mm))
                    .collect(),
            },
            Series {
                name: "true height (mm)".into(),
                color: "#000000",
                style: Style::Dashed,
                points: (0..=(LENGTH_MM * 10.0) as usize)
                    .map(|i| {
                        let mm = i as f64 / 10.0;
                        (mm, stepped::true_height(mm))
                    })
                    .collect(),
            },
        ],
        ..Chart::default()
    }
    .render();
    std::fs::write(out.join("stepped-part.svg"), svg).unwrap();
    println!("wrote {}", out.join("stepped-part.svg").display());
}
