//! The rational Bézier pieces of a NURBS curve between two parameters, for bounds that hold.
//!
//! Inside one knot span a NURBS curve is a rational polynomial, so its piece between two
//! parameters `s < t` of that span is a rational Bézier curve of the same degree. Its
//! homogeneous control points are the blossom values `b(s,…,s, t,…,t)` (`p − j` times `s`,
//! `j` times `t`), which de Boor's algorithm evaluates when each level takes its own argument
//! (Ramshaw's blossoming; The NURBS Book §5.2 gets the same points by knot insertion). With
//! every argument inside the span, each de Boor step is a convex combination of homogeneous
//! points, so every Bézier control point is a convex combination of the curve's own: its
//! weight is positive when the curve's weights are (which `NurbsCurve::new` enforces).
//!
//! That is what makes bounds sound: a rational Bézier curve with positive weights is a convex
//! combination of its projected control points at every parameter
//! (`C(u) = Σ λ_j(u) P_j`, `λ_j = B_j w_j / Σ B_k w_k ≥ 0`, `Σ λ_j = 1`), so the curve lies in
//! their convex hull, and any convex function of the point (a distance to a segment, a
//! coordinate) is at most its largest value at a control point. Halving a piece by de
//! Casteljau ([`Bezier::split`]) gives control polygons that converge to the curve
//! quadratically, so such bounds tighten by about four at each halving.

use super::basis::{MAX_ORDER, find_span};
use super::nurbs::{HOMOGENEOUS_WIDTH, WEIGHT_SLOT};
use super::{MAX_AXES, NurbsCurve, Point};

/// A rational Bézier curve in homogeneous form `(w x, w)`: degree `p`, `p + 1` control points,
/// all weights positive, each a row of `W` numbers (the coordinates, zeros, the weight last),
/// in `R` rows.
///
/// Both sizes are parameters because pieces and their halves are copied on the stack, and the
/// certificate makes millions of them. `W = 4` holds curves of up to three axes in half the
/// room of `W = 8` (up to six). [`MAX_ORDER`] rows hold any degree (`p < R`, the rows past `p`
/// zero); every smaller `R` holds degree `R − 1` exactly (an arc, a quadratic, in three rows),
/// so that the degree is a constant and the loops over rows and coordinates unroll. The
/// arithmetic is the same at every size: only the unused zero rows and columns go, and the
/// loop bookkeeping. Fixed-size, so nothing allocates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bezier<const W: usize = HOMOGENEOUS_WIDTH, const R: usize = MAX_ORDER> {
    degree: usize,
    dim: usize,
    points: [[f64; W]; R],
}

#[inline]
fn lerp<const W: usize>(a: &[f64; W], b: &[f64; W], t: f64) -> [f64; W] {
    let mut out = [0.0; W];
    for c in 0..W {
        out[c] = (1.0 - t) * a[c] + t * b[c];
    }
    out
}

impl<const W: usize, const R: usize> Bezier<W, R> {
    const WEIGHT: usize = W - 1;
    /// Coordinates a row can hold (the rest of it is zero padding and the weight).
    const LANES: usize = if W - 1 < MAX_AXES { W - 1 } else { MAX_AXES };
    /// Whether the degree is `R − 1` exactly: every size but [`MAX_ORDER`] rows.
    const EXACT: bool = R < MAX_ORDER;

    pub fn degree(&self) -> usize {
        self.p()
    }

    /// The degree, as a constant where the size fixes it.
    #[inline(always)]
    fn p(&self) -> usize {
        Self::degree_of(self.degree)
    }

    /// The degree of a piece of a curve of degree `degree` at this size: `R − 1`, a constant,
    /// where the size fixes it (and `bezier_pieces` checks the curve agrees).
    #[inline(always)]
    fn degree_of(degree: usize) -> usize {
        if Self::EXACT { R - 1 } else { degree }
    }

    /// Weight of control point `j` (positive).
    pub fn weight(&self, j: usize) -> f64 {
        self.points[j][Self::WEIGHT]
    }

    /// Control point `j` in Cartesian coordinates (mm).
    pub fn control_point(&self, j: usize) -> Point {
        let h = &self.points[j];
        let w = h[Self::WEIGHT];
        let mut p = Point::zeros();
        for axis in 0..self.dim {
            p[axis] = h[axis] / w;
        }
        p
    }

    /// The curve's point at `t ∈ [0, 1]` (de Casteljau in homogeneous form).
    pub fn point(&self, t: f64) -> Point {
        let p = self.p();
        let mut work = self.points;
        for r in 1..=p {
            for j in 0..=p - r {
                work[j] = lerp(&work[j], &work[j + 1], t);
            }
        }
        let mut out = Point::zeros();
        for axis in 0..self.dim {
            out[axis] = work[0][axis] / work[0][Self::WEIGHT];
        }
        out
    }

    /// The two halves, on `[0, ½]` and `[½, 1]` (de Casteljau at `½`).
    pub fn split(&self) -> (Bezier<W, R>, Bezier<W, R>) {
        self.split_at(0.5)
    }

    /// The two parts on `[0, t]` and `[t, 1]`, `t ∈ [0, 1]` (de Casteljau at `t`). Their control
    /// points are convex combinations of this curve's, so they stay in its convex hull and
    /// keep positive weights.
    pub fn split_at(&self, t: f64) -> (Bezier<W, R>, Bezier<W, R>) {
        let p = self.p();
        // Copies, not zeroed arrays: the rows past `p` are zero already, and the rows up to
        // `p` are all overwritten below.
        let mut left = *self;
        let mut right = *self;
        let mut work = self.points;
        left.points[0] = work[0];
        right.points[p] = work[p];
        for r in 1..=p {
            for j in 0..=p - r {
                work[j] = lerp(&work[j], &work[j + 1], t);
            }
            left.points[r] = work[0];
            right.points[p - r] = work[p - r];
        }
        (left, right)
    }

    /// The largest of `f` over the control points (Cartesian), without building vectors:
    /// `f` gets each point's coordinates in every lane the row has (`min(W − 1, MAX_AXES)`),
    /// zero past the curve's axes, so that its loops have a constant length. Inlined into
    /// the certificate's walk, which calls it for every piece it looks at.
    #[inline]
    #[cfg(test)]
    fn max_over_control_points(&self, f: impl FnMut(&[f64]) -> f64) -> f64 {
        self.max_over_control_points_from::<0>(f)
    }

    /// `max_over_control_points` over the control points
    /// from `FIRST` on (0 when there are none). A constant, so that the loop keeps a
    /// constant length and unrolls.
    #[inline]
    pub fn max_over_control_points_from<const FIRST: usize>(
        &self,
        mut f: impl FnMut(&[f64]) -> f64,
    ) -> f64 {
        let mut best = 0.0f64;
        let mut c = [0.0; W];
        for h in self.points[..=self.p()].iter().skip(FIRST) {
            let inv = 1.0 / h[Self::WEIGHT];
            for axis in 0..Self::LANES {
                c[axis] = h[axis] * inv;
            }
            best = super::running_max(best, f(&c[..Self::LANES]));
        }
        best
    }
}

impl NurbsCurve {
    /// The curve between `u0` and `u1` (clamped to its range) as rational Bézier curves, one
    /// per non-empty knot span the interval crosses, in order along the curve; nothing when
    /// the interval is empty. Each comes with the parameter interval it covers. Allocation-free.
    ///
    /// `W` is the row width: 8 holds any curve; 4 holds curves of up to three axes. `R` is the
    /// row count: [`MAX_ORDER`] holds any degree; a smaller `R` holds degree `R − 1` only. Panics
    /// on a curve that does not fit: the caller picks the sizes from [`dim`](Self::dim) and
    /// [`degree`](Self::degree).
    pub fn bezier_pieces<const W: usize, const R: usize>(
        &self,
        u0: f64,
        u1: f64,
        mut each: impl FnMut(&Bezier<W, R>, f64, f64),
    ) {
        assert!(
            self.dim() < W,
            "a {W}-wide Bézier holds at most {} axes",
            W - 1
        );
        assert!(
            if Bezier::<W, R>::EXACT {
                self.degree() + 1 == R
            } else {
                self.degree() < R
            },
            "{R} rows do not hold Bézier pieces of degree {}",
            self.degree()
        );
        let (u0, u1) = (
            u0.clamp(self.u_min(), self.u_max()),
            u1.clamp(self.u_min(), self.u_max()),
        );
        if u0 >= u1 {
            return;
        }
        let p = self.degree();
        let knots = self.knots();
        let last = self.num_points() - 1;
        let mut span = find_span(last, p, knots, u0);
        loop {
            let (s, t) = (u0.max(knots[span]), u1.min(knots[span + 1]));
            if s < t {
                each(&self.span_bezier(span, s, t), s, t);
            }
            if knots[span + 1] >= u1 || span >= last {
                break;
            }
            span += 1;
        }
    }

    /// The Bézier control points of knot span `span` restricted to `[s, t]` (both inside it):
    /// blossom values `b(s^{p−j}, t^j)` by de Boor's algorithm with one argument per level.
    ///
    /// The blossom is symmetric, so control point `j` may take `t` at the first `j` levels and
    /// `s` after: the `t` levels are a prefix shared by every `j`, computed once (`p(p+1)/2`
    /// lerps), and each point finishes with its own `s` levels (`(p−j)(p−j+1)/2`).
    fn span_bezier<const W: usize, const R: usize>(
        &self,
        span: usize,
        s: f64,
        t: f64,
    ) -> Bezier<W, R> {
        let p = Bezier::<W, R>::degree_of(self.degree());
        let dim = self.dim();
        // The 2p knots the span's levels read, `k[i] = knots[span + 1 - p + i]`, taken once so
        // that, the degree a constant, their indices need no checks.
        let k = &self.knots()[span + 1 - p..=span + p];
        // Every loop below runs over all `R` rows and skips the rows a level or a point does
        // not touch, rather than starting where the level does: with the row count a constant
        // the loops then have constant lengths and unroll whole, and the lerps happen in the
        // same order as before, so the points are the same numbers (a third of the
        // certificate's instructions went on the loops' counting).
        let level = |d: &mut [[f64; W]; R], r: usize, x: f64| {
            for i in (1..R).rev() {
                if i >= r && i <= p {
                    let alpha = (x - k[i - 1]) / (k[p + i - r] - k[i - 1]);
                    d[i] = lerp(&d[i - 1], &d[i], alpha);
                }
            }
        };
        let mut out = Bezier {
            degree: p,
            dim,
            points: [[0.0; W]; R],
        };
        // `prefix` after j levels at t; `d` finishes each point. Both are copied whole, in
        // constant lengths (every lane a row has: the slots past the curve's axes are zero in
        // the curve's points too; every row, though point `j` reads only rows `j..=p`):
        // copies of a length known only at run time went through `memcpy` calls, four a piece.
        let mut prefix = [[0.0; W]; R];
        for (row, h) in prefix.iter_mut().zip(&self.homogeneous()[span - p..=span]) {
            row[..Bezier::<W, R>::LANES].copy_from_slice(&h[..Bezier::<W, R>::LANES]);
            row[W - 1] = h[WEIGHT_SLOT];
        }
        for j in (0..R).take_while(|&j| j <= p) {
            if j > 0 {
                level(&mut prefix, j, t);
            }
            let mut d = prefix;
            for r in 1..R {
                if r > j && r <= p {
                    level(&mut d, r, s);
                }
            }
            out.points[j] = d[p];
        }
        out
    }
}

// How far a curve reaches along one axis (`NurbsCurve::axis_extent`).
// How far a curve reaches along one axis: the bounds a soft-limit check holds a path to.
//
// A curve lies in the convex hull of its Bézier pieces' control points (above),
// so the largest control coordinate of a piece is an upper bound of the curve's coordinate
// there, and the piece's end points (and any point evaluated on it) are lower bounds of its
// maximum. Halving the pieces whose bound still lies more than `tolerance` above the best
// point found closes the gap; what is returned is an outer bound (never inside the true
// extent) at most `tolerance` beyond it. A line is settled at once (its control points are its
// end points); an arc in a few halvings.

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
    use super::*;
    use crate::geometry::{random_curve, semicircle};
    use crate::rng::SplitMix64;

    /// Each piece's control points, then those of its two parts split at 0.3, then the
    /// largest control-point distance from the origin.
    type Rows = Vec<(Vec<Point>, Vec<Point>, Vec<Point>, f64)>;

    fn rows_of<const W: usize, const R: usize>(
        bz: &Bezier<W, R>,
    ) -> (Vec<Point>, Vec<Point>, Vec<Point>, f64) {
        let points = |b: &Bezier<W, R>| (0..=b.degree()).map(|j| b.control_point(j)).collect();
        let (l, r) = bz.split_at(0.3);
        let far = bz.max_over_control_points(|c| c.iter().map(|x| x * x).sum::<f64>().sqrt());
        (points(bz), points(&l), points(&r), far)
    }

    fn exact_rows<const R: usize>(curve: &NurbsCurve, a: f64, b: f64) -> Rows {
        let mut out = Vec::new();
        curve.bezier_pieces::<4, R>(a, b, |bz, _, _| out.push(rows_of(bz)));
        out
    }

    fn general_rows(pieces: &[Bezier<4, MAX_ORDER>]) -> Rows {
        pieces.iter().map(rows_of).collect()
    }

    #[test]
    fn pieces_reproduce_the_curve_between_the_parameters() {
        let mut rng = SplitMix64::new(7);
        for case in 0..200 {
            let degree = 1 + case % 7;
            let curve = random_curve(&mut rng, degree, 3, degree + 1 + case % 6, case % 3 == 0);
            let (lo, hi) = (curve.u_min(), curve.u_max());
            let a = rng.uniform(lo, hi);
            let b = rng.uniform(a, hi);
            let mut pieces = Vec::new();
            curve.bezier_pieces::<8, MAX_ORDER>(a, b, |bz, _, _| pieces.push(*bz));
            // The narrow rows give the same points, and the exact rows of a low degree the
            // same points, parts and distances bit for bit, since the arithmetic is the same.
            let mut narrow = Vec::new();
            curve.bezier_pieces::<4, MAX_ORDER>(a, b, |bz, _, _| narrow.push(*bz));
            for (w, n) in pieces.iter().zip(&narrow) {
                for j in 0..=degree {
                    assert!((w.control_point(j) - n.control_point(j)).norm() < 1e-12);
                }
            }
            let exact = match degree {
                1 => exact_rows::<2>(&curve, a, b),
                2 => exact_rows::<3>(&curve, a, b),
                3 => exact_rows::<4>(&curve, a, b),
                _ => Vec::new(),
            };
            if degree < 4 {
                assert_eq!(exact, general_rows(&narrow), "case {case}");
            }
            assert!(!pieces.is_empty());
            // The pieces chain and end on the curve's points at a and b.
            let scale = 1e-9 * 100.0;
            assert!((pieces[0].control_point(0) - curve.point(a)).norm() < scale);
            let last = pieces.last().unwrap();
            assert!((last.control_point(degree) - curve.point(b)).norm() < scale);
            for w in pieces.windows(2) {
                assert!((w[0].control_point(degree) - w[1].control_point(0)).norm() < scale);
            }
            // Every piece matches the curve in between, and its weights are positive.
            let knots = curve.knots();
            let mut starts = vec![a];
            starts.extend(knots.iter().copied().filter(|&k| k > a && k < b));
            starts.dedup();
            starts.push(b);
            let spans: Vec<(f64, f64)> = starts
                .windows(2)
                .map(|w| (w[0], w[1]))
                .filter(|(s, t)| t > s)
                .collect();
            assert_eq!(spans.len(), pieces.len(), "case {case}");
            for ((s, t), bz) in spans.iter().zip(&pieces) {
                for j in 0..=degree {
                    assert!(bz.weight(j) > 0.0);
                }
                for k in 0..=8 {
                    let f = k as f64 / 8.0;
                    let u = s + f * (t - s);
                    assert!(
                        (bz.point(f) - curve.point(u)).norm() < scale,
                        "case {case} at {u}"
                    );
                }
            }
        }
    }

    #[test]
    fn halves_are_the_two_halves_and_stay_in_the_hull() {
        let arc = semicircle();
        let mut piece: Option<Bezier<4, 3>> = None;
        arc.bezier_pieces(
            arc.u_min(),
            arc.u_min() + 0.3 * (arc.u_max() - arc.u_min()),
            |b, _, _| {
                piece.get_or_insert(*b);
            },
        );
        let piece = piece.unwrap();
        let (l, r) = piece.split();
        for k in 0..=10 {
            let t = k as f64 / 10.0;
            assert!((l.point(t) - piece.point(0.5 * t)).norm() < 1e-12);
            assert!((r.point(t) - piece.point(0.5 + 0.5 * t)).norm() < 1e-12);
            // On the circle of radius 10.
            assert!((piece.point(t).norm() - 10.0).abs() < 1e-12);
        }
        for j in 0..=2 {
            assert!(l.weight(j) > 0.0 && r.weight(j) > 0.0);
        }
    }
}

#[cfg(test)]
mod extent_tests {
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
