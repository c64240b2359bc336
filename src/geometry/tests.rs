//! Geometry checked against independent references: a published evaluation, a brute-force
//! Cox–de Boor summation, and closed-form circles.

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use super::*;

use crate::rng::SplitMix64 as Rng;

fn fanuc_cubic() -> NurbsCurve {
    let pts = [
        (0.0, 100.0),
        (10.0, 100.0),
        (10.0, 70.665),
        (27.928, 59.258),
        (34.093, 56.935),
        (41.136, 54.281),
        (63.112, 51.556),
        (79.999, 60.0),
        (99.998, 40.002),
        (100.0, 0.012),
    ];
    let points: Vec<Point> = pts.iter().map(|&(x, y)| point(&[x, y])).collect();
    let knots = vec![
        0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 7.0, 7.0, 7.0,
    ];
    NurbsCurve::new(3, 2, &points, &[1.0; 10], knots).unwrap()
}

#[test]
fn published_ten_point_cubic_vector() {
    let d = fanuc_cubic().derivs(3.5);
    assert!((d.point[0] - 37.943895833).abs() < 1e-8, "{}", d.point[0]);
    assert!((d.point[1] - 55.599625).abs() < 1e-8, "{}", d.point[1]);
    assert!((d.d1[0] - 8.799875).abs() < 1e-8, "{}", d.d1[0]);
    assert!((d.d1[1] - -2.6215).abs() < 1e-8, "{}", d.d1[1]);
}

// ---- brute-force reference ------------------------------------------------------------------

/// Cox–de Boor by the textbook recursion, `0/0 := 0`, the last span closed at `u_max`.
fn cox_de_boor(i: usize, p: usize, u: f64, knots: &[f64], u_max: f64) -> f64 {
    if p == 0 {
        let (a, b) = (knots[i], knots[i + 1]);
        let inside = a <= u && u < b;
        // The last non-empty span also takes u = u_max.
        let closes = u == u_max && b == u_max && a < b;
        return if inside || closes { 1.0 } else { 0.0 };
    }
    let mut v = 0.0;
    let d1 = knots[i + p] - knots[i];
    if d1 != 0.0 {
        v += (u - knots[i]) / d1 * cox_de_boor(i, p - 1, u, knots, u_max);
    }
    let d2 = knots[i + p + 1] - knots[i + 1];
    if d2 != 0.0 {
        v += (knots[i + p + 1] - u) / d2 * cox_de_boor(i + 1, p - 1, u, knots, u_max);
    }
    v
}

/// k-th derivative of N_{i,p} by the recursive derivative formula (NURBS Book eq. 2.9).
fn basis_deriv(k: usize, i: usize, p: usize, u: f64, knots: &[f64], u_max: f64) -> f64 {
    if k == 0 {
        return cox_de_boor(i, p, u, knots, u_max);
    }
    if p == 0 {
        return 0.0;
    }
    let mut v = 0.0;
    let d1 = knots[i + p] - knots[i];
    if d1 != 0.0 {
        v += p as f64 / d1 * basis_deriv(k - 1, i, p - 1, u, knots, u_max);
    }
    let d2 = knots[i + p + 1] - knots[i + 1];
    if d2 != 0.0 {
        v -= p as f64 / d2 * basis_deriv(k - 1, i + 1, p - 1, u, knots, u_max);
    }
    v
}

struct RawCurve {
    degree: usize,
    dim: usize,
    points: Vec<Point>,
    weights: Vec<f64>,
    knots: Vec<f64>,
}

/// Summation over all basis functions, then the quotient rule written out independently.
fn brute_force(c: &RawCurve, u: f64) -> [Point; 3] {
    let u_max = *c.knots.last().unwrap();
    let mut a = [Point::zeros(); 3];
    let mut w = [0.0; 3];
    for (i, (p, &wi)) in c.points.iter().zip(&c.weights).enumerate() {
        for k in 0..3 {
            let n = basis_deriv(k, i, c.degree, u, &c.knots, u_max);
            a[k] += p * (wi * n);
            w[k] += wi * n;
        }
    }
    let p0 = a[0] / w[0];
    let p1 = (a[1] - p0 * w[1]) / w[0];
    let p2 = (a[2] - p1 * (2.0 * w[1]) - p0 * w[2]) / w[0];
    [p0, p1, p2]
}

fn random_curve(rng: &mut Rng) -> RawCurve {
    let degree = 1 + rng.below(MAX_DEGREE);
    let dim = 1 + rng.below(MAX_AXES);
    let count = degree + 1 + rng.below(10);
    let points = (0..count)
        .map(|_| {
            let mut p = Point::zeros();
            for axis in 0..dim {
                p[axis] = rng.uniform(-100.0, 100.0);
            }
            p
        })
        .collect();
    let weights = (0..count).map(|_| rng.uniform(0.2, 5.0)).collect();
    // Interior knots: random increasing values, some repeated up to the degree.
    let interior_count = count - degree - 1;
    let mut interior = Vec::new();
    while interior.len() < interior_count {
        let value = rng.uniform(0.05, 0.95);
        let repeat = (1 + rng.below(degree)).min(interior_count - interior.len());
        interior.extend(std::iter::repeat_n(value, repeat));
    }
    interior.sort_by(f64::total_cmp);
    let mut knots = vec![0.0; degree + 1];
    knots.extend(interior);
    knots.extend(std::iter::repeat_n(1.0, degree + 1));
    RawCurve {
        degree,
        dim,
        points,
        weights,
        knots,
    }
}

#[test]
fn matches_brute_force_cox_de_boor_on_random_curves() {
    let mut rng = Rng::new(0xED3D_2026);
    let mut checked = 0;
    for _ in 0..300 {
        let raw = random_curve(&mut rng);
        let curve = NurbsCurve::new(
            raw.degree,
            raw.dim,
            &raw.points,
            &raw.weights,
            raw.knots.clone(),
        )
        .unwrap();
        // Random parameters plus every knot value and both ends.
        let mut us: Vec<f64> = (0..20).map(|_| rng.uniform(0.0, 1.0)).collect();
        us.extend(raw.knots.iter().copied());
        for u in us {
            let got = curve.derivs(u);
            let want = brute_force(&raw, u);
            for (k, (g, w)) in [got.point, got.d1, got.d2].iter().zip(&want).enumerate() {
                let scale = 1.0 + w.norm();
                let err = (g - w).norm() / scale;
                assert!(
                    err < 1e-9,
                    "degree {} dim {} u {u} derivative {k}: got {g:?} want {w:?}",
                    raw.degree,
                    raw.dim
                );
            }
            checked += 1;
        }
    }
    assert!(checked > 6000);
}

#[test]
fn derivatives_agree_with_finite_differences_on_the_jin_curve() {
    let pts = [
        (0.0, 0.0),
        (-150.0, -150.0),
        (-150.0, 150.0),
        (0.0, 0.0),
        (150.0, -150.0),
        (150.0, 150.0),
        (0.0, 0.0),
    ];
    let points: Vec<Point> = pts.iter().map(|&(x, y)| point(&[x, y])).collect();
    let weights = [1.0, 10.0, 10.0, 1.0, 10.0, 10.0, 1.0];
    let knots = vec![0.0, 0.0, 0.0, 0.0, 0.25, 0.5, 0.75, 1.0, 1.0, 1.0, 1.0];
    let c = NurbsCurve::new(3, 2, &points, &weights, knots).unwrap();
    let h = 1e-6;
    for i in 1..100 {
        let u = i as f64 / 100.0;
        if [0.25, 0.5, 0.75].iter().any(|k| (u - k).abs() < 2.0 * h) {
            continue; // C2 holds at simple knots, but central differences straddle the span edge.
        }
        let d = c.derivs(u);
        let fd1 = (c.point(u + h) - c.point(u - h)) / (2.0 * h);
        let fd2 = (c.derivs(u + h).d1 - c.derivs(u - h).d1) / (2.0 * h);
        assert!((d.d1 - fd1).norm() < 1e-5 * (1.0 + d.d1.norm()), "u={u}");
        assert!((d.d2 - fd2).norm() < 1e-5 * (1.0 + d.d2.norm()), "u={u}");
    }
}

// ---- circles --------------------------------------------------------------------------------

fn assert_on_circle(c: &NurbsCurve, center: &Point, r: f64, plane: [usize; 2]) {
    for i in 0..=2000 {
        let u = i as f64 / 2000.0;
        let d = c.derivs(u);
        let dist = (d.point - center).norm();
        assert!(
            ((dist - r) / r).abs() < 1e-12,
            "u={u}: distance {dist} from centre, radius {r}"
        );
        // Tangent perpendicular to the radius, curvature radius equal to r.
        let radial = d.point - center;
        assert!(radial.dot(&d.d1).abs() < 1e-9 * r * d.d1.norm());
        assert!(((d.curvature_radius() - r) / r).abs() < 1e-9);
        // Out-of-plane axes stay where the arc started.
        for axis in (0..c.dim()).filter(|a| !plane.contains(a)) {
            let z = c.start_point()[axis];
            assert!((d.point[axis] - z).abs() <= 1e-14 * (1.0 + z.abs()));
        }
    }
}

#[test]
fn arcs_lie_exactly_on_their_circle_in_every_plane_and_sweep() {
    let mut rng = Rng::new(7);
    for plane in [[0, 1], [2, 0], [1, 2]] {
        for sweep in [
            FRAC_PI_2,
            -FRAC_PI_2,
            0.3,
            -2.9,
            PI,
            3.0 * FRAC_PI_2 + 0.1,
            TAU,
            -TAU,
        ] {
            let center = point(&[rng.uniform(-50.0, 50.0), rng.uniform(-50.0, 50.0), 3.0]);
            let r = rng.uniform(0.01, 200.0);
            let a0 = rng.uniform(-PI, PI);
            let mut start = center;
            start[plane[0]] += r * a0.cos();
            start[plane[1]] += r * a0.sin();
            let mut end = center;
            end[plane[0]] += r * (a0 + sweep).cos();
            end[plane[1]] += r * (a0 + sweep).sin();
            let c = circular_arc(3, plane, &center, &start, &end, sweep).unwrap();
            assert_on_circle(&c, &center, r, plane);
            assert_eq!(c.start_point(), start);
            assert_eq!(c.end_point(), end);
            let want = r * sweep.abs();
            assert!(((c.length() - want) / want).abs() < 1e-11, "length");
            // Direction: positive sweep turns from plane[0] towards plane[1].
            let d = c.derivs(0.0);
            let radial = start - center;
            let turn = radial[plane[0]] * d.d1[plane[1]] - radial[plane[1]] * d.d1[plane[0]];
            assert_eq!(turn > 0.0, sweep > 0.0);
        }
    }
}

#[test]
fn quarter_circle_is_one_rational_quadratic_piece() {
    let c = circular_arc(
        2,
        [0, 1],
        &point(&[0.0, 0.0]),
        &point(&[1.0, 0.0]),
        &point(&[0.0, 1.0]),
        FRAC_PI_2,
    )
    .unwrap();
    assert_eq!(c.num_points(), 3);
    assert!((c.weight(1) - 0.5f64.sqrt()).abs() < 1e-15);
    let full = circular_arc(
        2,
        [0, 1],
        &point(&[0.0, 0.0]),
        &point(&[1.0, 0.0]),
        &point(&[1.0, 0.0]),
        TAU,
    )
    .unwrap();
    assert_eq!(full.num_points(), 9);
}

#[test]
fn line_length_and_ends_are_exact() {
    let a = point(&[1.0, 2.0, 3.0]);
    let b = point(&[4.0, 6.0, 3.0]);
    let l = NurbsCurve::line(3, &a, &b).unwrap();
    assert_eq!(l.point(0.0), a);
    assert_eq!(l.point(1.0), b);
    assert!((l.length() - 5.0).abs() < 1e-13);
    assert_eq!(l.derivs(0.3).curvature_radius(), f64::INFINITY);
}

#[test]
fn length_of_a_nontrivial_curve_matches_dense_polyline() {
    let c = fanuc_cubic();
    let n = 200_000;
    let mut poly = 0.0;
    let mut prev = c.point(0.0);
    for i in 1..=n {
        let p = c.point(7.0 * i as f64 / n as f64);
        poly += (p - prev).norm();
        prev = p;
    }
    // A dense inscribed polyline is shorter by O(h^2); 1e-7 relative is well above that here.
    assert!(
        ((c.length() - poly) / poly).abs() < 1e-7,
        "{} vs {poly}",
        c.length()
    );
}

/// Found by the soak: a 20 µm arc far from the origin made the length quadrature chase its
/// coordinates' rounding noise to the depth limit (seconds per arc, a job of them hung).
#[test]
fn length_of_a_tiny_arc_far_from_the_origin_is_exact_and_quick() {
    for x in [0.0, 200.0, 1500.0, 1.0e5] {
        let r = 0.02;
        let center = point(&[x, 0.0]);
        let sweep: f64 = -1.2;
        let start = point(&[x + r, 0.0]);
        let end = point(&[x + r * sweep.cos(), r * sweep.sin()]);
        let arc = circular_arc(2, [0, 1], &center, &start, &end, sweep).unwrap();
        let started = std::time::Instant::now();
        let length = arc.length();
        let took = started.elapsed();
        let exact = r * sweep.abs();
        assert!(
            (length - exact).abs() <= 1e-9 * exact.max(x * 1e-3),
            "x = {x}: {length} vs {exact}"
        );
        assert!(took.as_millis() < 100, "x = {x}: length took {took:?}");
    }
}

// ---- validation -----------------------------------------------------------------------------

fn pts(n: usize) -> Vec<Point> {
    (0..n).map(|i| point(&[i as f64, (i * i) as f64])).collect()
}

#[test]
fn every_validation_rule_has_its_own_error() {
    let k4 = || vec![0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0];
    let cases: Vec<(Result<NurbsCurve, NurbsError>, &str)> = vec![
        (
            NurbsCurve::new(0, 2, &pts(2), &[1.0; 2], vec![0.0, 1.0]),
            "DegreeOutOfRange",
        ),
        (
            NurbsCurve::new(10, 2, &pts(11), &[1.0; 11], vec![0.0; 22]),
            "DegreeOutOfRange",
        ),
        (
            NurbsCurve::new(3, 7, &pts(4), &[1.0; 4], k4()),
            "DimensionOutOfRange",
        ),
        (
            NurbsCurve::new(3, 2, &pts(3), &[1.0; 3], vec![0.0; 7]),
            "TooFewPoints",
        ),
        (
            NurbsCurve::new(3, 2, &pts(4), &[1.0; 3], k4()),
            "WeightCount",
        ),
        (
            NurbsCurve::new(3, 2, &pts(4), &[1.0; 4], vec![0.0; 7]),
            "KnotCount",
        ),
        (
            NurbsCurve::new(
                3,
                2,
                &pts(4),
                &[1.0; 4],
                vec![0.0, 0.0, 0.0, 0.0, f64::NAN, 1.0, 1.0, 1.0],
            ),
            "NonFiniteKnot",
        ),
        (
            NurbsCurve::new(
                3,
                2,
                &pts(5),
                &[1.0; 5],
                vec![0.0, 0.0, 0.0, 0.0, 2.0, 1.0, 1.0, 1.0, 1.0],
            ),
            "KnotsDecreasing",
        ),
        (
            NurbsCurve::new(
                3,
                2,
                &pts(4),
                &[1.0; 4],
                vec![0.0, 0.0, 0.0, 0.5, 1.0, 1.0, 1.0, 1.0],
            ),
            "NotClamped",
        ),
        (
            NurbsCurve::new(3, 2, &pts(4), &[1.0; 4], vec![1.0; 8]),
            "EmptyRange",
        ),
        (
            NurbsCurve::new(
                2,
                2,
                &pts(6),
                &[1.0; 6],
                vec![0.0, 0.0, 0.0, 0.5, 0.5, 0.5, 1.0, 1.0, 1.0],
            ),
            "KnotMultiplicity",
        ),
        (
            NurbsCurve::new(3, 2, &pts(4), &[1.0, 0.0, 1.0, 1.0], k4()),
            "BadWeight",
        ),
        (
            NurbsCurve::new(3, 2, &pts(4), &[1.0, -2.0, 1.0, 1.0], k4()),
            "BadWeight",
        ),
        (
            NurbsCurve::new(3, 2, &pts(4), &[1.0, f64::INFINITY, 1.0, 1.0], k4()),
            "BadWeight",
        ),
        (
            NurbsCurve::new(
                3,
                2,
                &[
                    point(&[0.0, 0.0]),
                    point(&[f64::NAN, 0.0]),
                    point(&[1.0, 1.0]),
                    point(&[2.0, 0.0]),
                ],
                &[1.0; 4],
                k4(),
            ),
            "NonFiniteCoordinate",
        ),
        (
            NurbsCurve::new(3, 2, &[point(&[1.0, 1.0]); 4], &[1.0; 4], k4()),
            "Degenerate",
        ),
    ];
    for (result, want) in cases {
        let err = result.expect_err(want);
        assert!(
            format!("{err:?}").starts_with(want),
            "{err:?} is not {want}"
        );
        assert!(!err.to_string().is_empty());
    }
}

#[test]
fn a_reversed_curve_runs_the_same_points_backwards() {
    let c = fanuc_cubic();
    let r = c.reversed();
    let (a, b) = (c.u_min(), c.u_max());
    assert_eq!((r.u_min(), r.u_max()), (a, b));
    for k in 0..=50 {
        let u = a + (b - a) * f64::from(k) / 50.0;
        assert!((r.point(a + b - u) - c.point(u)).norm() < 1e-9, "u = {u}");
    }
    assert_eq!(
        r.reversed().point(a + 0.3 * (b - a)),
        c.point(a + 0.3 * (b - a))
    );
}

#[test]
fn running_extremes_are_std_max_and_min_bit_for_bit() {
    // Numbers of both signs, infinities, a NaN to pass over, and zeros of one sign: the
    // cases a running maximum of magnitudes or distances meets.
    let mut rng = Rng::new(3);
    let special = [
        0.0,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NAN,
        f64::MIN_POSITIVE,
        1.0,
    ];
    for _ in 0..50_000 {
        let mut pick = || match rng.below(3) {
            0 => special[rng.below(special.len())],
            _ => rng.uniform(-1e3, 1e3),
        };
        let best = pick();
        let x = pick();
        if best.is_nan() {
            continue;
        }
        assert_eq!(
            running_max(best, x).to_bits(),
            best.max(x).to_bits(),
            "{best} {x}"
        );
        assert_eq!(
            running_min(best, x).to_bits(),
            best.min(x).to_bits(),
            "{best} {x}"
        );
    }
}
