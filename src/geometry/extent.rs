//! How far a curve reaches along one axis: the bounds a soft-limit check holds a path to.
//!
//! A curve lies in the convex hull of its Bézier pieces' control points (see [`super::bezier`]),
//! so the largest control coordinate of a piece is an upper bound of the curve's coordinate
//! there, and the piece's end points (and any point evaluated on it) are lower bounds of its
//! maximum. Halving the pieces whose bound still lies more than `tolerance` above the best
//! point found closes the gap; what is returned is an outer bound (never inside the true
//! extent) at most `tolerance` beyond it. A line is settled at once (its control points are its
//! end points); an arc in a few halvings.

use super::basis::MAX_ORDER;
use super::nurbs::HOMOGENEOUS_WIDTH;
use super::{Bezier, NurbsCurve};

/// Deepest halving of one piece: a bound of 2⁻⁴⁰ of the piece is far below any tolerance.
const MAX_DEPTH: usize = 40;

impl NurbsCurve {
    /// The lowest and highest value of coordinate `axis` along the curve, mm: outer bounds,
    /// each within `tolerance` of the true extreme.
    pub fn axis_extent(&self, axis: usize, tolerance: f64) -> (f64, f64) {
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        self.bezier_pieces::<HOMOGENEOUS_WIDTH, MAX_ORDER>(
            self.u_min(),
            self.u_max(),
            |piece, _, _| {
                hi = hi.max(piece_max(piece, |c| c[axis], tolerance));
                lo = lo.min(-piece_max(piece, |c| -c[axis], tolerance));
            },
        );
        (lo, hi)
    }
}

/// An outer bound of the largest `f` (a linear function of the point) along `piece`, within
/// `tolerance` of the true largest value.
fn piece_max<const W: usize>(
    piece: &Bezier<W>,
    f: impl Fn(&[f64]) -> f64 + Copy,
    tolerance: f64,
) -> f64 {
    let at = |b: &Bezier<W>, t: f64| {
        let p = b.point(t);
        f(p.as_slice())
    };
    // The best point found so far (a lower bound of the maximum) and the largest bound of the
    // pieces settled (an upper bound of it).
    let mut found = at(piece, 0.0).max(at(piece, 1.0));
    let mut bound = found;
    let mut stack = [(*piece, 0usize); MAX_DEPTH + 2];
    let mut top = 1;
    while top > 0 {
        top -= 1;
        let (b, depth) = stack[top];
        // Not `max_over_control_points`: that one starts from 0 (it bounds distances).
        let hull = (0..=b.degree())
            .map(|j| f(b.control_point(j).as_slice()))
            .fold(f64::NEG_INFINITY, f64::max);
        if hull <= found + tolerance || depth >= MAX_DEPTH {
            bound = bound.max(hull);
            continue;
        }
        found = found.max(at(&b, 0.5));
        let (left, right) = b.split();
        stack[top] = (right, depth + 1);
        stack[top + 1] = (left, depth + 1);
        top += 2;
    }
    bound.max(found)
}

#[cfg(test)]
mod tests {
    use crate::geometry::{NurbsCurve, circular_arc, clamped_uniform_knots, point};
    use crate::rng::SplitMix64;

    #[test]
    fn random_curves_stay_inside_their_extent_and_reach_it_within_the_tolerance() {
        let mut rng = SplitMix64::new(33);
        let tolerance = 1e-4;
        for case in 0..100 {
            let degree = 1 + case % 5;
            let n = degree + 1 + case % 7;
            let points: Vec<_> = (0..n)
                .map(|_| point(&[rng.uniform(-80.0, 20.0), rng.uniform(5.0, 60.0)]))
                .collect();
            let weights: Vec<f64> = (0..n).map(|_| rng.uniform(0.2, 5.0)).collect();
            let knots = clamped_uniform_knots(n, degree);
            let curve = NurbsCurve::new(degree, 2, &points, &weights, knots).unwrap();
            for axis in 0..2 {
                let (lo, hi) = curve.axis_extent(axis, tolerance);
                // Dense sampling: an independent inner estimate of the extent.
                let (mut slo, mut shi) = (f64::INFINITY, f64::NEG_INFINITY);
                // (The knots too: a degree-1 curve's extremes are there.)
                let span = curve.u_max() - curve.u_min();
                let samples = (0..=20_000).map(|k| curve.u_min() + span * k as f64 / 20_000.0);
                for u in samples.chain(curve.knots().iter().copied()) {
                    let v = curve.point(u)[axis];
                    slo = slo.min(v);
                    shi = shi.max(v);
                }
                assert!(
                    hi >= shi - 1e-9 && lo <= slo + 1e-9,
                    "case {case}: not outer"
                );
                assert!(
                    hi - shi <= tolerance + 1e-6 && slo - lo <= tolerance + 1e-6,
                    "case {case} axis {axis}: [{lo}, {hi}] against sampled [{slo}, {shi}]"
                );
            }
        }
    }

    #[test]
    fn a_line_reaches_its_end_points_exactly() {
        let line = NurbsCurve::line(2, &point(&[1.0, -2.0]), &point(&[-3.5, 4.0])).unwrap();
        assert_eq!(line.axis_extent(0, 1e-6), (-3.5, 1.0));
        assert_eq!(line.axis_extent(1, 1e-6), (-2.0, 4.0));
    }

    #[test]
    fn a_half_circle_reaches_its_radius_within_the_tolerance() {
        // Centre (10, 0), radius 5, from (15, 0) counter-clockwise to (5, 0): top at y = 5.
        let arc = circular_arc(
            2,
            [0, 1],
            &point(&[10.0, 0.0]),
            &point(&[15.0, 0.0]),
            &point(&[5.0, 0.0]),
            std::f64::consts::PI,
        )
        .unwrap();
        for tolerance in [1e-3, 1e-6] {
            let (lo, hi) = arc.axis_extent(1, tolerance);
            assert!((-1e-12..=tolerance).contains(&(hi - 5.0)), "{hi}");
            assert!(lo.abs() <= 1e-12, "{lo}");
            let (lo, hi) = arc.axis_extent(0, tolerance);
            assert!((lo - 5.0).abs() <= 1e-12 && (hi - 15.0).abs() <= 1e-12);
        }
    }
}
