//! NURBS evaluation speed: point plus first and second derivative, the operation the segmenter
//! calls most, against the `curvo` crate on the same curves in the same run.
//! Run: `cargo bench --bench geometry`.
//!
//! Three functions per curve, each over the same 1000 increasing parameters:
//! - `edmd`: [`NurbsCurve::derivs`] (span search every call);
//! - `curvo`: `NurbsCurve::rational_derivatives(u, 2)` (span search every call), the like-for-like
//!   call;
//! - `curvo_evaluator`: curvo's `CurveEvaluator`, which remembers the last knot span: curvo's
//!   fastest way to walk a curve, the fairest peer for a segmenter that walks forward.
//!
//! Before timing, every curve is checked to agree between the two libraries at every parameter
//! (relative 1e-9), so the comparison is of the same curves.

mod common;

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use edmd::geometry::{NurbsCurve, Point, circular_arc, point};
use nalgebra::allocator::Allocator;
use nalgebra::{DefaultAllocator, DimName, DimNameDiff, DimNameSub, OPoint, OVector, U1, U3, U4};

/// Seed 001's Table 1 cubic (weights 1, 10, 10, 1, 10, 10, 1), from its sample program.
fn jin_curve() -> NurbsCurve {
    common::program_curve("jin-table1-g06_2.nc").curve
}

/// Seed 000's Table I cubic (7 control points), from its sample program.
fn huang_curve() -> NurbsCurve {
    common::program_curve("huang-table1-g38.nc").curve
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

fn full_circle() -> NurbsCurve {
    circular_arc(
        2,
        [0, 1],
        &point(&[0.0, 0.0]),
        &point(&[10.0, 0.0]),
        &point(&[10.0, 0.0]),
        std::f64::consts::TAU,
    )
    .unwrap()
}

/// The same curve as curvo builds it: homogeneous control points `(w·x, w·y[, w·z], w)`.
/// `D` is the curve's dimension plus one.
fn to_curvo<D: DimName>(curve: &NurbsCurve) -> curvo::prelude::NurbsCurve<f64, D>
where
    DefaultAllocator: Allocator<D>,
{
    assert_eq!(curve.dim() + 1, D::dim());
    let points = (0..curve.num_points())
        .map(|i| {
            let (p, w) = (curve.control_point(i), curve.weight(i));
            let h = (0..D::dim()).map(|k| if k < curve.dim() { p[k] * w } else { w });
            OPoint::from(OVector::<f64, D>::from_iterator(h))
        })
        .collect();
    curvo::prelude::NurbsCurve::try_new(curve.degree(), points, curve.knots().to_vec())
        .expect("curvo accepts the curve")
}

const SAMPLES: usize = 1000;

fn parameters(curve: &NurbsCurve) -> Vec<f64> {
    let (lo, hi) = (curve.u_min(), curve.u_max());
    (0..SAMPLES)
        .map(|i| lo + (hi - lo) * (i as f64 + 0.5) / SAMPLES as f64)
        .collect()
}

/// Benches one curve in the three ways; `D` is its dimension plus one.
fn bench_curve<D>(c: &mut Criterion, name: &str, curve: &NurbsCurve)
where
    D: DimName + DimNameSub<U1>,
    DefaultAllocator: Allocator<D> + Allocator<DimNameDiff<D, U1>>,
{
    let peer = to_curvo::<D>(curve);
    let us = parameters(curve);
    let dim = curve.dim();
    for &u in &us {
        let ours = curve.derivs(u);
        let theirs = peer.rational_derivatives(u, 2);
        for (order, ours) in [ours.point, ours.d1, ours.d2].iter().enumerate() {
            let scale = ours.norm().max(1.0);
            for k in 0..dim {
                let diff = (ours[k] - theirs[order][k]).abs();
                assert!(
                    diff <= 1e-9 * scale,
                    "{name}: derivative {order} differs at u = {u}: {ours:?} vs {:?}",
                    theirs[order]
                );
            }
        }
    }

    let mut group = c.benchmark_group(format!("nurbs_point_and_two_derivatives/{name}"));
    group.throughput(Throughput::Elements(SAMPLES as u64));
    group.bench_function("edmd", |b| {
        b.iter(|| {
            let mut acc = 0.0;
            for &u in &us {
                let d = curve.derivs(black_box(u));
                acc += d.point[0] + d.d1[1] + d.d2[0];
            }
            acc
        })
    });
    group.bench_function("curvo", |b| {
        b.iter(|| {
            let mut acc = 0.0;
            for &u in &us {
                let d = peer.rational_derivatives(black_box(u), 2);
                acc += d[0][0] + d[1][1] + d[2][0];
            }
            acc
        })
    });
    group.bench_function("curvo_evaluator", |b| {
        b.iter(|| {
            let mut evaluator = peer.evaluator();
            let mut acc = 0.0;
            for &u in &us {
                let d = evaluator.rational_derivatives(black_box(u), 2);
                acc += d[0][0] + d[1][1] + d[2][0];
            }
            acc
        })
    });
    group.finish();
}

fn bench_eval(c: &mut Criterion) {
    bench_curve::<U3>(c, "cubic_2d_jin", &jin_curve());
    bench_curve::<U3>(c, "cubic_2d_huang", &huang_curve());
    bench_curve::<U4>(c, "quintic_3d_40pts", &quintic_3d());
    bench_curve::<U3>(c, "full_circle", &full_circle());
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .warm_up_time(std::time::Duration::from_millis(500))
        .measurement_time(std::time::Duration::from_secs(2));
    targets = bench_eval
}
criterion_main!(benches);
