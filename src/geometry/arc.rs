//! Circular arcs as exact rational quadratic NURBS (The NURBS Book, A7.1).
//!
//! An arc of sweep `theta` is split into `ceil(|theta| / 90°)` equal pieces. Each piece is a
//! rational quadratic Bézier whose middle control point is the intersection of the end tangents,
//! `r / cos(d/2)` from the centre, with weight `cos(d/2)`. The result lies exactly on the circle,
//! so an arc goes through the same segmenter and chord-error guarantee as any other curve.

use std::f64::consts::FRAC_PI_2;

use super::nurbs::{HOMOGENEOUS_WIDTH, WEIGHT_SLOT};
use super::{NurbsCurve, NurbsError, Point};

/// Builds the arc from `start` around `center` by `sweep` radians in the plane of axes
/// `plane = [a, b]` (positive = counter-clockwise from `a` towards `b`), ending exactly at `end`.
///
/// The radius is taken from `start`. The last control point is `end` itself, so the curve ends
/// where the program says even when the programmed end is a hair off the circle (the G-code layer
/// rejects ends that are off by more than its tolerance). Axes outside the plane keep `start`'s
/// values on every control point but the last.
pub fn circular_arc(
    dim: usize,
    plane: [usize; 2],
    center: &Point,
    start: &Point,
    end: &Point,
    sweep: f64,
) -> Result<NurbsCurve, NurbsError> {
    let [a, b] = plane;
    let radius = (start[a] - center[a]).hypot(start[b] - center[b]);
    let angle0 = (start[b] - center[b]).atan2(start[a] - center[a]);
    // The small allowance keeps an exact quarter circle in one piece despite rounding of pi.
    let pieces = ((sweep.abs() / FRAC_PI_2) - 1e-9).ceil().max(1.0) as usize;
    let delta = sweep / pieces as f64;
    let mid_weight = (delta / 2.0).cos();

    let on_circle = |angle: f64, dist: f64| {
        let mut p = *start;
        p[a] = center[a] + dist * angle.cos();
        p[b] = center[b] + dist * angle.sin();
        p
    };
    let mut points = Vec::with_capacity(2 * pieces + 1);
    let mut weights = Vec::with_capacity(2 * pieces + 1);
    let mut knots = Vec::with_capacity(2 * pieces + 4);
    points.push(*start);
    weights.push(1.0);
    knots.extend([0.0; 3]);
    for k in 1..=pieces {
        let mid = angle0 + (k as f64 - 0.5) * delta;
        points.push(on_circle(mid, radius / mid_weight));
        weights.push(mid_weight);
        if k == pieces {
            points.push(*end);
        } else {
            points.push(on_circle(angle0 + k as f64 * delta, radius));
            let knot = k as f64 / pieces as f64;
            knots.extend([knot, knot]);
        }
        weights.push(1.0);
    }
    knots.extend([1.0; 3]);
    NurbsCurve::new(2, dim, &points, &weights, knots)
}

/// How far a [`spiral_arc`] may stray from the true spiral or helix, mm: a hundredth of a
/// micron, well inside any step.
pub const SPIRAL_FIT_TOLERANCE_MM: f64 = 1e-5;

/// An arc whose radius changes from `start`'s to `end`'s linearly with the angle (LinuxCNC's
/// spiral, for centre arcs whose end radius differs from the start's), whose axes outside
/// the plane move linearly with it (a helix: a circular move with Z), or both; `sweep` may
/// be more than a turn. Neither is a rational quadratic, so the curve is a C1 cubic that
/// interpolates the true one's points and tangents at equal angles, with as many pieces as
/// keep it within [`SPIRAL_FIT_TOLERANCE_MM`] of it (checked at the quarter points of every
/// piece). It starts at `start` and ends at `end` exactly. A plain arc (equal radii, no move
/// outside the plane) is [`circular_arc`]'s exact curve.
pub fn spiral_arc(
    dim: usize,
    plane: [usize; 2],
    center: &Point,
    start: &Point,
    end: &Point,
    sweep: f64,
) -> Result<NurbsCurve, NurbsError> {
    let [a, b] = plane;
    let r0 = (start[a] - center[a]).hypot(start[b] - center[b]);
    let r1 = (end[a] - center[a]).hypot(end[b] - center[b]);
    let leaves_plane = (0..dim).any(|i| i != a && i != b && start[i] != end[i]);
    if (r1 - r0).abs() <= 1e-9 && !leaves_plane {
        return circular_arc(dim, plane, center, start, end, sweep);
    }
    let angle0 = (start[b] - center[b]).atan2(start[a] - center[a]);
    // The true curve and its derivative by t in [0, 1], given the sine and cosine of its
    // angle there.
    let at_trig = |t: f64, (sin, cos): (f64, f64)| -> (Point, Point) {
        let r = r0 + t * (r1 - r0);
        let mut p = *start;
        let mut d = Point::zeros();
        for i in 0..dim {
            p[i] = start[i] + t * (end[i] - start[i]);
            d[i] = end[i] - start[i];
        }
        p[a] = center[a] + r * cos;
        p[b] = center[b] + r * sin;
        d[a] = (r1 - r0) * cos - r * sweep * sin;
        d[b] = (r1 - r0) * sin + r * sweep * cos;
        (p, d)
    };
    let at = |t: f64| at_trig(t, (angle0 + t * sweep).sin_cos());
    let hermite = |(p0, d0): (Point, Point), (p1, d1): (Point, Point), h: f64, s: f64| {
        let (s2, s3) = (s * s, s * s * s);
        let (h00, h10) = (2.0 * s3 - 3.0 * s2 + 1.0, s3 - 2.0 * s2 + s);
        let (h01, h11) = (-2.0 * s3 + 3.0 * s2, s3 - s2);
        p0 * h00 + d0 * (h10 * h) + p1 * h01 + d1 * (h11 * h)
    };
    // As many pieces as the error of cubic Hermite interpolation allows, (Δt)⁴/384 times
    // the curve's fourth derivative, at most r·sweep⁴ + 4·|r1 - r0|·|sweep|³: a bound, so
    // the check below rarely doubles it (a radius 10 mm turn: 45 pieces, where doubling from
    // one an eighth of a half turn gave 64).
    let fourth = r0.max(r1) * sweep.powi(4) + 4.0 * (r1 - r0).abs() * sweep.abs().powi(3);
    let mut pieces = ((fourth / (384.0 * SPIRAL_FIT_TOLERANCE_MM))
        .powf(0.25)
        .ceil() as usize)
        .max(((sweep.abs() / (std::f64::consts::PI / 8.0)).ceil() as usize).max(2))
        .min(1 << 16);
    // A helix's pieces are all the same piece turned and raised (its radius is constant and
    // its rise linear in the angle), so the first one's error is every one's: checking one
    // instead of all made the fit of a helix a fraction of its cost. A spiral's radius
    // changes along it, so each piece is checked.
    let congruent = (r1 - r0).abs() <= 1e-9;
    loop {
        let h = 1.0 / pieces as f64;
        let checked = if congruent { 1 } else { pieces };
        let fits = (0..checked).all(|k| {
            let (t0, t1) = (k as f64 * h, (k + 1) as f64 * h);
            let (e0, e1) = (at(t0), at(t1));
            [0.25, 0.5, 0.75].iter().all(|&s| {
                let error = (hermite(e0, e1, h, s) - at(t0 + s * h).0)
                    .iter()
                    .take(dim)
                    .fold(0.0f64, |m, x| m.hypot(*x));
                error <= SPIRAL_FIT_TOLERANCE_MM
            })
        });
        if fits || pieces >= 1 << 16 {
            break;
        }
        pieces *= 2;
    }
    Ok(hermite_pieces(
        dim,
        plane,
        center,
        (start, end),
        (r0, r1, angle0, sweep),
        pieces,
    ))
}

/// The curve of [`spiral_arc`] in `pieces` cubic pieces: each junction on the true curve
/// (radius `r0` to `r1` from `angle0` through `sweep`, rising linearly outside the plane)
/// with its true tangent, from exactly `start` to exactly `end`.
fn hermite_pieces(
    dim: usize,
    [a, b]: [usize; 2],
    center: &Point,
    (start, end): (&Point, &Point),
    (r0, r1, angle0, sweep): (f64, f64, f64, f64),
    pieces: usize,
) -> NurbsCurve {
    // Piecewise Bézier with double interior knots: the junction point is the middle of
    // the two inner points beside it, so only those are stored.
    let h = 1.0 / pieces as f64;
    // The angle steps by h·sweep from piece to piece: its sine and cosine by the addition
    // formulas, not a sin_cos at each (a drift of a few ulps over the curve, far inside the
    // fit's tolerance; the ends are the exact start and end).
    let (step_sin, step_cos) = (h * sweep).sin_cos();
    let mut trig = angle0.sin_cos();
    // Valid by construction (clamped knots, unit weights, finite points that move), so the
    // control points are written straight into the curve's homogeneous form, without
    // `NurbsCurve::new`'s checks and copies: those were a quarter of a helix's cost. The
    // point and its tangent are built in that form too, the axes outside the plane as a
    // start and a rise over the fixed width (the weight's slot: 1 and no rise).
    type Row = [f64; HOMOGENEOUS_WIDTH];
    let row = |q: &Point| -> Row {
        let mut w = [0.0; HOMOGENEOUS_WIDTH];
        w[..dim].copy_from_slice(&q.as_slice()[..dim]);
        w[WEIGHT_SLOT] = 1.0;
        w
    };
    let (first, last) = (row(start), row(end));
    let mut rise: Row = [0.0; HOMOGENEOUS_WIDTH];
    for i in (0..dim).filter(|&i| i != a && i != b) {
        rise[i] = end[i] - start[i];
    }
    let (dr, third) = (r1 - r0, h / 3.0);
    let mut homogeneous: Vec<Row> = Vec::with_capacity(2 * pieces + 2);
    let mut knots = Vec::with_capacity(2 * pieces + 6);
    knots.extend([0.0; 4]);
    for k in 0..=pieces {
        let t = k as f64 * h;
        let (sin, cos) = trig;
        trig = (
            sin * step_cos + cos * step_sin,
            cos * step_cos - sin * step_sin,
        );
        let r = r0 + t * dr;
        let mut d = rise;
        d[a] = dr * cos - r * sweep * sin;
        d[b] = dr * sin + r * sweep * cos;
        let p = if k == 0 {
            first
        } else if k == pieces {
            last
        } else {
            let mut p = first;
            for (p, rise) in p.iter_mut().zip(&rise) {
                *p += t * rise;
            }
            p[a] = center[a] + r * cos;
            p[b] = center[b] + r * sin;
            p
        };
        let along = |by: f64| -> Row { std::array::from_fn(|i| p[i] + d[i] * by) };
        if k > 0 {
            homogeneous.push(along(-third));
        }
        if k == 0 || k == pieces {
            homogeneous.push(p);
        }
        if k < pieces {
            homogeneous.push(along(third));
        }
        if k > 0 && k < pieces {
            knots.extend([t, t]);
        }
    }
    knots.extend([1.0; 4]);
    NurbsCurve::from_parts(3, dim, knots, homogeneous)
}

/// The test curves' semicircle: radius 10 about the origin in X/Y, counter-clockwise from
/// (10, 0) to (−10, 0).
#[cfg(test)]
pub fn semicircle() -> NurbsCurve {
    use super::point;
    circular_arc(
        2,
        [0, 1],
        &point(&[0.0, 0.0]),
        &point(&[10.0, 0.0]),
        &point(&[-10.0, 0.0]),
        std::f64::consts::PI,
    )
    .unwrap()
}

#[cfg(test)]
mod spiral_tests {
    use super::*;
    use crate::geometry::point;

    /// The true spiral/helix point at `t` (radius and the third axis linear in the angle).
    fn truth(c: &Point, s: &Point, e: &Point, sweep: f64, t: f64) -> Point {
        let (r0, r1) = ((s - c).xy_norm(), (e - c).xy_norm());
        let a0 = (s[1] - c[1]).atan2(s[0] - c[0]);
        let (r, a) = (r0 + t * (r1 - r0), a0 + t * sweep);
        point(&[
            c[0] + r * a.cos(),
            c[1] + r * a.sin(),
            s[2] + t * (e[2] - s[2]),
        ])
    }

    trait XyNorm {
        fn xy_norm(&self) -> f64;
    }
    impl XyNorm for Point {
        fn xy_norm(&self) -> f64 {
            self[0].hypot(self[1])
        }
    }

    #[test]
    fn a_spiral_helix_of_two_turns_stays_within_the_fit_tolerance_and_ends_exactly() {
        let c = point(&[0.0, 0.0, 0.0]);
        let s = point(&[10.0, 0.0, 0.0]);
        let e = point(&[0.0, 10.003, -4.0]);
        let sweep = std::f64::consts::FRAC_PI_2 + std::f64::consts::TAU;
        let curve = spiral_arc(3, [0, 1], &c, &s, &e, sweep).unwrap();
        assert_eq!(curve.start_point(), s);
        assert_eq!(curve.end_point(), e);
        assert_eq!(curve.corner_knots().count(), 0, "C1: no corners inside");
        let mut worst: f64 = 0.0;
        for k in 0..=4000 {
            let t = k as f64 / 4000.0;
            let d = (curve.point(t) - truth(&c, &s, &e, sweep, t)).norm();
            worst = worst.max(d);
        }
        assert!(worst <= SPIRAL_FIT_TOLERANCE_MM * 1.01, "{worst}");
    }

    #[test]
    fn equal_radii_in_the_plane_are_the_exact_circular_arc() {
        let c = point(&[0.0, 0.0]);
        let (s, e) = (point(&[10.0, 0.0]), point(&[0.0, 10.0]));
        let sweep = std::f64::consts::FRAC_PI_2;
        assert_eq!(
            spiral_arc(2, [0, 1], &c, &s, &e, sweep).unwrap(),
            circular_arc(2, [0, 1], &c, &s, &e, sweep).unwrap()
        );
    }
}
