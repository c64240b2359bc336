//! Preprocessor throughput: segments per second per core, chord guarantee included.
//! Run: `cargo bench --bench preprocess`.

mod common;

use std::fmt::Write as _;
use std::hint::black_box;
use std::sync::Arc;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use edmd::config::Config;
use edmd::gcode::{Block, BlockKind, NurbsForm};
use edmd::geometry::{NurbsCurve, Point, clamped_uniform_knots, point};
use edmd::preprocess::{PlanSettings, Preprocessor, Segmenter};
use edmd::vocab::{Predictor, Segmentation};

fn cubic(points: &[(f64, f64)], weights: &[f64]) -> Arc<Block> {
    let n = points.len();
    let pts: Vec<Point> = points.iter().map(|&(x, y)| point(&[x, y])).collect();
    let knots = clamped_uniform_knots(n, 3);
    Arc::new(Block::new(
        1,
        BlockKind::Nurbs {
            form: NurbsForm::Fanuc,
        },
        NurbsCurve::new(3, 2, &pts, weights, knots).unwrap(),
        Some(18000.0),
    ))
}

fn curves() -> Vec<(&'static str, Arc<Block>)> {
    let zigzag = [
        (0.0, 0.0),
        (10.0, 20.0),
        (20.0, -20.0),
        (30.0, 20.0),
        (40.0, -20.0),
        (50.0, 0.0),
    ];
    vec![
        (
            "jin",
            Arc::new(common::program_curve("jin-table1-g06_2.nc")),
        ),
        ("zigzag", cubic(&zigzag, &[1.0; 6])),
    ]
}

fn settings(segmentation: Segmentation, predictor: Predictor, max_segment: f64) -> PlanSettings {
    let mut cfg = Config::default();
    cfg.interpolation.segmentation = segmentation;
    cfg.interpolation.predictor = predictor;
    cfg.interpolation.max_segment_mm = max_segment;
    // The papers' machine (300 mm/s), not held to one step of 1 µm per 50 µs tick: the
    // figures stay comparable with the papers' and with earlier runs.
    PlanSettings {
        axis_cap_mm_per_s: [f64::INFINITY; edmd::vocab::MAX_AXES],
        ..PlanSettings::from_config(&cfg)
    }
}

fn count_segments(block: &Arc<Block>, s: &PlanSettings) -> u64 {
    let mut pre = Preprocessor::new(s.clone());
    let mut n = 0;
    pre.push_block(Arc::clone(block), |_| n += 1);
    pre.finish(|_| n += 1);
    n
}

fn bench_segmenter(c: &mut Criterion) {
    let mut group = c.benchmark_group("segmenter_chord_mode");
    for (name, block) in curves() {
        for predictor in [Predictor::Taylor, Predictor::Hamming] {
            let s = settings(Segmentation::Chord, predictor, 1e6);
            let n = count_segments(&block, &s);
            group.throughput(Throughput::Elements(n));
            group.bench_function(format!("{name}/{predictor:?}/uncapped"), |b| {
                b.iter(|| {
                    let mut seg = Segmenter::new(s.clone());
                    let mut count = 0u64;
                    seg.segment_block(black_box(&block), |_| count += 1);
                    count
                })
            });
        }
    }
    group.finish();
}

fn bench_pipeline(c: &mut Criterion) {
    let mut group = c.benchmark_group("preprocessor");
    for (name, block) in curves() {
        for (mode, cap) in [
            (Segmentation::Chord, 1.0),
            (Segmentation::Chord, 1e6),
            (Segmentation::Period, 1.0),
        ] {
            for predictor in [Predictor::Taylor, Predictor::Hamming] {
                let s = settings(mode, predictor, cap);
                let n = count_segments(&block, &s);
                group.throughput(Throughput::Elements(n));
                let label = format!("{name}/{mode:?}/{predictor:?}/cap{cap}");
                group.bench_function(label, |b| {
                    b.iter(|| {
                        let mut pre = Preprocessor::new(s.clone());
                        let mut length = 0.0;
                        pre.push_block(Arc::clone(black_box(&block)), |seg| length += seg.length);
                        pre.finish(|seg| length += seg.length);
                        length
                    })
                });
            }
        }
    }
    group.finish();
}

/// Numbers as text, `decimal`'s way against `core::fmt`'s (the same text), one comma after
/// each: a criterion group of the two.
fn bench_number_text(
    c: &mut Criterion,
    group: &str,
    numbers: &[f64],
    fast: (&str, fn(&mut Vec<u8>, f64)),
    fmt: fn(&mut String, f64),
) {
    let mut group = c.benchmark_group(group);
    group.throughput(Throughput::Elements(numbers.len() as u64));
    group.bench_function(fast.0, |b| {
        let mut out = Vec::with_capacity(32 * 1024);
        b.iter(|| {
            out.clear();
            for &x in numbers {
                (fast.1)(&mut out, x);
                out.push(b',');
            }
            std::hint::black_box(out.len())
        })
    });
    group.bench_function("format!", |b| {
        let mut out = String::with_capacity(32 * 1024);
        b.iter(|| {
            out.clear();
            for &x in numbers {
                fmt(&mut out, x);
                out.push(',');
            }
            std::hint::black_box(out.len())
        })
    });
    group.finish();
}

/// A trace row's numbers as text: `decimal::push_f64` against `format!("{x}")` (the same text),
/// on 1000 numbers of the sizes a trace holds (coordinates, times, feeds, micron errors).
fn bench_trace_numbers(c: &mut Criterion) {
    let mut rng = edmd::rng::SplitMix64::new(39);
    let numbers: Vec<f64> = (0..1000)
        .map(|i| match i % 4 {
            0 => rng.uniform(-200.0, 200.0),
            1 => rng.uniform(0.0, 10_000.0),
            2 => rng.uniform(0.0, 1200.0),
            _ => rng.uniform(0.0, 1e-3),
        })
        .collect();
    bench_number_text(
        c,
        "trace numbers",
        &numbers,
        ("decimal::push_f64", edmd::decimal::push_f64),
        |out, x| *out += &format!("{x}"),
    );
}

/// A chart path's coordinates as text: `decimal::push_fixed` against `format!("{x:.2}")` (the
/// same text), on 1000 pixel coordinates.
fn bench_chart_coordinates(c: &mut Criterion) {
    let mut rng = edmd::rng::SplitMix64::new(39);
    let numbers: Vec<f64> = (0..1000).map(|_| rng.uniform(0.0, 900.0)).collect();
    bench_number_text(
        c,
        "chart coordinates",
        &numbers,
        ("decimal::push_fixed", |out, x| {
            edmd::decimal::push_fixed(out, x, 2)
        }),
        |out, x| {
            let _ = write!(out, "{x:.2}");
        },
    );
}

criterion_group!(
    benches,
    bench_segmenter,
    bench_pipeline,
    bench_trace_numbers,
    bench_chart_coordinates
);
criterion_main!(benches);
