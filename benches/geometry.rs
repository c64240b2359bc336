//! NURBS evaluation speed: point plus first and second derivative, the operation the segmenter
//! calls most. Run: `cargo bench --bench geometry`.

mod common;

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use edmd::geometry::{NurbsCurve, Point, circular_arc, point};

/// Seed 001's Table 1 cubic (weights 1, 10, 10, 1, 10, 10, 1), from its sample program.
fn jin_curve() -> NurbsCurve {
    common::program_curve("jin-table1-g06_2.nc").curve
}

/// A degree-5 curve in 3 axes with 40 control points (many spans: exercises the span search).
fn quintic_3d() -> NurbsCurve {
    let n = 40;
    let points: Vec<Point> = (0..n)
        .map(|i| {
            let t = i as f64 * 0.4;
            point(&[10.0 * t.cos(), 10.0 * t.sin(), i as f64])
        })
        .collect();
    let weights: Vec<f64> = (0..n).map(|i| 1.0 + 0.5 * ((i % 3) as f64)).collect();
    let mut knots = vec![0.0; 6];
    knots.extend((1..n - 5).map(|i| i as f64));
    knots.extend(std::iter::repeat_n((n - 5) as f64, 6));
    NurbsCurve::new(5, 3, &points, &weights, knots).unwrap()
}

fn bench_eval(c: &mut Criterion) {
    let arc = circular_arc(
        2,
        [0, 1],
        &point(&[0.0, 0.0]),
        &point(&[10.0, 0.0]),
        &point(&[10.0, 0.0]),
        std::f64::consts::TAU,
    )
    .unwrap();
    let curves = [
        ("cubic_2d_jin", jin_curve()),
        ("quintic_3d_40pts", quintic_3d()),
        ("full_circle", arc),
    ];
    let mut group = c.benchmark_group("nurbs_point_and_two_derivatives");
    const SAMPLES: usize = 1000;
    group.throughput(Throughput::Elements(SAMPLES as u64));
    for (name, curve) in &curves {
        let (lo, hi) = (curve.u_min(), curve.u_max());
        let us: Vec<f64> = (0..SAMPLES)
            .map(|i| lo + (hi - lo) * (i as f64 + 0.5) / SAMPLES as f64)
            .collect();
        group.bench_function(*name, |b| {
            b.iter(|| {
                let mut acc = 0.0;
                for &u in &us {
                    let d = curve.derivs(black_box(u));
                    acc += d.point[0] + d.d1[1] + d.d2[0];
                }
                acc
            })
        });
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .warm_up_time(std::time::Duration::from_millis(500))
        .measurement_time(std::time::Duration::from_secs(2));
    targets = bench_eval
}
criterion_main!(benches);
