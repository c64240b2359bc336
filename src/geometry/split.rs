//! Cutting a curve in two at a parameter or an arc length: knot insertion (The NURBS Book
//! A5.1, one knot at a time) until the knot's multiplicity is the degree, where the curve
//! passes through a control point and falls apart into two clamped curves that trace it
//! exactly. Lines, arcs (rational) and NURBS alike; a wire contour's tab is cut this way.

use super::basis::find_span;
use super::nurbs::{HOMOGENEOUS_WIDTH, NurbsCurve};

type Homogeneous = [f64; HOMOGENEOUS_WIDTH];

impl NurbsCurve {
    /// The curve cut at `u`: the part before and the part after, in the same parameter units.
    /// `None` unless `u` lies strictly inside the parameter range.
    pub fn split_at(&self, u: f64) -> Option<(NurbsCurve, NurbsCurve)> {
        if !(u > self.u_min() && u < self.u_max()) {
            return None;
        }
        let p = self.degree();
        let mut knots = self.knots().to_vec();
        let mut points: Vec<Homogeneous> = self.homogeneous().to_vec();
        let have = knots.iter().filter(|&&k| k == u).count();
        for _ in have..p {
            insert(p, &mut knots, &mut points, u);
        }
        // The knot `u` now sits at `first .. first + p`; the point before `first` is on the
        // curve at `u`.
        let first = knots.iter().position(|&k| k == u)?;
        let mut left_knots = knots[..first + p].to_vec();
        left_knots.push(u);
        let mut right_knots = vec![u];
        right_knots.extend_from_slice(&knots[first..]);
        let left = points[..first].to_vec();
        let right = points[first - 1..].to_vec();
        Some((
            NurbsCurve::from_parts(p, self.dim(), left_knots, left),
            NurbsCurve::from_parts(p, self.dim(), right_knots, right),
        ))
    }

    /// The parameter at arc length `s` (mm) from the start, to `tolerance_mm` of length
    /// (bisection on the exact length; a few dozen length integrals).
    pub fn u_at_length(&self, s: f64, tolerance_mm: f64) -> f64 {
        let (mut lo, mut hi) = (self.u_min(), self.u_max());
        if s <= 0.0 {
            return lo;
        }
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            let at = self.length_between(self.u_min(), mid);
            if (at - s).abs() <= tolerance_mm {
                return mid;
            }
            if at < s {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }
}

/// Inserts the knot `u` once (A5.1 with r = 1) into a curve of degree `p`.
fn insert(p: usize, knots: &mut Vec<f64>, points: &mut Vec<Homogeneous>, u: f64) {
    let n = points.len() - 1;
    let k = find_span(n, p, knots, u);
    let mut out = Vec::with_capacity(points.len() + 1);
    for i in 0..=n + 1 {
        let q = if i + p <= k {
            points[i]
        } else if i > k {
            points[i - 1]
        } else {
            let a = (u - knots[i]) / (knots[i + p] - knots[i]);
            std::array::from_fn(|j| a * points[i][j] + (1.0 - a) * points[i - 1][j])
        };
        out.push(q);
    }
    knots.insert(k + 1, u);
    *points = out;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Point, circular_arc, point};

    fn close(a: &Point, b: &Point) -> bool {
        (a - b).norm() < 1e-9
    }

    /// Both parts trace the curve: dense samples of each agree with the whole at the same
    /// parameter, and their lengths add up.
    fn check_split(curve: &NurbsCurve, u: f64) {
        let (a, b) = curve.split_at(u).expect("inside");
        assert!(close(&a.end_point(), &curve.point(u)));
        assert!(close(&b.start_point(), &curve.point(u)));
        for i in 0..=50 {
            let t = f64::from(i) / 50.0;
            let ua = curve.u_min() + t * (u - curve.u_min());
            let ub = u + t * (curve.u_max() - u);
            assert!(close(&a.point(ua), &curve.point(ua)), "left at {ua}");
            assert!(close(&b.point(ub), &curve.point(ub)), "right at {ub}");
        }
        assert!((a.length() + b.length() - curve.length()).abs() < 1e-9);
    }

    #[test]
    fn a_split_line_arc_and_nurbs_trace_the_whole() {
        let line = NurbsCurve::line(2, &point(&[0.0, 0.0]), &point(&[3.0, 4.0])).unwrap();
        check_split(&line, 0.3);
        let end = point(&[0.0, -1.0]);
        let arc = circular_arc(
            2,
            [0, 1],
            &point(&[0.0, 0.0]),
            &point(&[1.0, 0.0]),
            &end,
            1.5 * std::f64::consts::PI,
        )
        .unwrap();
        for u in [0.1, 0.5, 0.77] {
            let u = arc.u_min() + u * (arc.u_max() - arc.u_min());
            check_split(&arc, u);
        }
        let pts: Vec<Point> = [[0.0, 0.0], [1.0, 2.0], [3.0, -1.0], [4.0, 1.0], [6.0, 0.0]]
            .iter()
            .map(|p| point(p))
            .collect();
        let nurbs = NurbsCurve::new(
            3,
            2,
            &pts,
            &[1.0, 0.5, 2.0, 1.0, 1.0],
            vec![0.0, 0.0, 0.0, 0.0, 0.4, 1.0, 1.0, 1.0, 1.0],
        )
        .unwrap();
        for u in [0.2, 0.4, 0.9] {
            check_split(&nurbs, u);
        }
        assert!(nurbs.split_at(0.0).is_none() && nurbs.split_at(1.0).is_none());
    }

    #[test]
    fn the_parameter_at_a_length() {
        let line = NurbsCurve::line(2, &point(&[0.0, 0.0]), &point(&[3.0, 4.0])).unwrap();
        assert!((line.u_at_length(2.5, 1e-9) - 0.5).abs() < 1e-9);
    }
}
