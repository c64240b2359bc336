//! A certified upper bound on a segment's chord error: a number the curve cannot exceed, not
//! an estimate of it.
//!
//! [`chord_error`](super::chord::chord_error) *measures* the largest distance between a curve
//! piece and its chord: a Hermite model steers Newton's method to the bulges, with sampling
//! where the model is distrusted. It is fast and usually exact, but a model can be fooled (a
//! quadratic with repeated knots, a wiggle its end tangents do not show). The segmenter
//! therefore aims with the measurement and accepts a segment only when this bound holds.
//!
//! **Why the bound is sound.** Between two parameters `u0 < u1` the curve is a chain of
//! rational Bézier curves, one per knot span, whose control points are convex combinations of
//! the curve's own ([`Bezier`], `geometry/bezier.rs`); with the curve's weights positive
//! (validated), theirs are too. A rational Bézier curve with positive weights lies in the convex
//! hull of its control points. The distance from a point to the chord *segment* `[A, B]` is a
//! convex function of the point (the distance to a convex set), and a convex function on a
//! polytope is largest at a vertex. So the largest control-point distance over all the pieces
//! bounds the distance of every point of the curve between `u0` and `u1`: the true chord error.
//!
//! **Tightening.** The first bound of a short piece is loose by about a third of the chord
//! error (a cubic's inner control points stand 4/3 as far out as the curve). A piece whose bound
//! exceeds the tolerance is halved by de Casteljau; the halves' control points lie in the
//! parent's hull, so the bound never grows, and their excess over the curve shrinks about
//! fourfold per halving. Only pieces over the tolerance are halved, up to [`MAX_DEPTH`] times;
//! a piece still over it then is reported as over (the segmenter shortens the segment).
//!
//! **Rounding.** The bound is computed in floating point; [`allowance_on`] adds the
//! worst the lerps and distances can lose (a few hundred ulps of the coordinates' magnitude
//! at the deepest halving: about 5e-11 mm at 500 mm), far below any tolerance, so rounding
//! cannot turn a bound into an underestimate. Distances are computed from the offset's
//! components, never as a difference of squares, which would cancel far along a long chord.
//!
//! Cost: no curve evaluations, and no allocation: one blossom per knot span crossed (`O(p³)`
//! lerps of eight numbers) and a fixed-size stack for the halving.

use crate::geometry::{Bezier, MAX_ORDER, NurbsCurve, Point, lanes, running_max};
use crate::vocab::MAX_AXES;

/// Halvings of one Bézier piece before its bound is reported as it stands.
pub const MAX_DEPTH: u32 = 24;

/// A certified bound and what it cost.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Certificate {
    /// When the certificate [holds](Self::holds): an upper bound on the distance from the
    /// curve between the two parameters to the chord segment (mm), rounding allowance
    /// included. When it does not: the control-point distance (above the tolerance) of the
    /// first piece that stayed over it at the depth limit, where the walk stopped.
    pub bound: f64,
    /// Bézier pieces examined (spans crossed plus halves made).
    pub pieces: u32,
}

impl Certificate {
    pub fn holds(&self, tol: f64) -> bool {
        self.bound <= tol
    }
}

/// Distance from a point to the segment `[a, b]`.
struct Segment {
    a: Point,
    dir: Point,
    len: f64,
}

impl Segment {
    #[cfg(test)]
    fn new(a: &Point, b: &Point) -> Segment {
        Segment::on::<MAX_AXES>(a, b)
    }

    /// The segment from `a` to `b`, on their first `N` coordinates ([`lanes`]): the rest are
    /// zero in both ends of a curve of up to `N` axes, and then the same numbers as on all.
    fn on<const N: usize>(a: &Point, b: &Point) -> Segment {
        let v = lanes::sub::<N>(b, a);
        let len = lanes::norm::<N>(&v);
        Segment {
            a: *a,
            dir: if len > 0.0 {
                lanes::div::<N>(&v, len)
            } else {
                Point::zeros()
            },
            len,
        }
    }

    #[cfg(test)]
    fn distance(&self, p: &Point) -> f64 {
        let r = p - self.a;
        let along = r.dot(&self.dir).clamp(0.0, self.len);
        (r - self.dir * along).norm()
    }

    /// The largest distance from a control point of `bz` from the `FIRST` on. The
    /// coordinates past the curve's axes are zero in the control points and in the segment,
    /// so they add nothing to either sum (a `±0` term leaves a sum from `+0` unchanged):
    /// every lane the row has is summed, a loop of constant length.
    fn largest_control_distance<const FIRST: usize, const W: usize, const R: usize>(
        &self,
        bz: &Bezier<W, R>,
    ) -> f64 {
        bz.max_over_control_points_from::<FIRST>(|c| {
            let mut along = 0.0;
            for (axis, &x) in c.iter().enumerate() {
                along += (x - self.a[axis]) * self.dir[axis];
            }
            let along = along.clamp(0.0, self.len);
            // The offset from the nearest point of the segment, component by component: the
            // shortcut |r|² − 2 along·along' + along'² cancels catastrophically far along a
            // long chord (a 1e-4 mm offset at 60 mm loses about 1e-6 mm), which would make
            // the bound unsound; this loses a few ulps of the coordinates, which the rounding
            // allowance covers.
            let mut d2 = 0.0;
            for (axis, &x) in c.iter().enumerate() {
                let e = x - self.a[axis] - self.dir[axis] * along;
                d2 += e * e;
            }
            d2.sqrt()
        })
    }
}

/// How far the control points of a short Bézier piece stand out from the chord compared with
/// the curve itself, at a parabola-like bulge: `p / (p - 1)` for even degree `p`, `(p + 1) / p`
/// for odd (the Bernstein coefficients of `s (1 - s)` peak at `i (p - i) / (p (p - 1))` against
/// the curve's `1/4`): 2 for a quadratic, 4/3 for a cubic. The segmenter uses it to decide
/// whether a cut at the farthest point is worth making before the first bound; it has no part
/// in soundness.
pub fn hull_excess(degree: usize) -> f64 {
    let p = degree.max(2) as f64;
    if degree.is_multiple_of(2) {
        p / (p - 1.0)
    } else {
        (p + 1.0) / p
    }
}

/// What floating point may have lost in the distances, for a piece of degree `degree` whose
/// chord runs from `a` to `b`, measured against `tol`.
///
/// Each lerp of a blossom or a split rounds by at most an ulp of the magnitudes involved;
/// a control point goes through `degree` levels of the blossom and `degree` more per halving,
/// and the distance adds a few more. With the coordinates bounded by `scale` (the chord's
/// ends, plus `tol` since a bound that holds keeps the control points within it of the
/// chord), the computed distances are within `(16 + 2 degree (MAX_DEPTH + 2))` ulps of `scale`
/// of the exact ones: about 5e-11 mm at 500 mm for degree 9, 1e-11 mm for a cubic.
#[cfg(test)]
fn rounding_allowance(a: &Point, b: &Point, degree: usize, tol: f64) -> f64 {
    allowance_on::<MAX_AXES>(a, b, degree, tol)
}

/// `rounding_allowance` on the first `N` coordinates: the rest, zero, change no maximum.
fn allowance_on<const N: usize>(a: &Point, b: &Point, degree: usize, tol: f64) -> f64 {
    // The largest magnitude of a coordinate, as nalgebra's `amax` gives it, in a plain loop
    // (`amax` goes through simba's generic comparisons: 3 % of the certificate's cost).
    let largest = |p: &Point| {
        p.iter()
            .take(N)
            .fold(0.0f64, |m, x| running_max(m, x.abs()))
    };
    let scale = largest(a).max(largest(b)).max(1.0) + tol;
    let ulps = 16.0 + 2.0 * degree as f64 * f64::from(MAX_DEPTH + 2);
    ulps * f64::EPSILON * scale
}

/// An upper bound on the chord error of `curve` between `u0` and `u1` against the chord from
/// `start` to `end` (the curve's points there), refined until it is within `tol` or the
/// halving depth runs out. See the module docs for why it holds.
///
/// `farthest` is where a measurement found the largest distance (NaN for none). The piece
/// holding it is first cut there: at a bulge's farthest point the tangent is parallel to the
/// chord, so the control points next to the cut lie on that tangent line, and one cut often
/// leaves a bound equal to the measured maximum where blind halving needs two or three
/// levels. Where the cut falls does not affect soundness, only speed.
pub fn certify(
    curve: &NurbsCurve,
    u0: f64,
    u1: f64,
    start: &Point,
    end: &Point,
    tol: f64,
    farthest: f64,
) -> Certificate {
    // Narrow rows for up to three axes, and the chord on three coordinates; exactly as many
    // rows as an arc (a quadratic), a line or a cubic has: the same arithmetic, with less
    // copying and loops that unroll.
    if curve.dim() < 4 {
        certify_on::<3, 4>(curve, u0, u1, start, end, tol, farthest)
    } else {
        certify_on::<MAX_AXES, 8>(curve, u0, u1, start, end, tol, farthest)
    }
}

/// [`certify`] with the chord on `N` coordinates and the Bézier rows `W` wide.
fn certify_on<const N: usize, const W: usize>(
    curve: &NurbsCurve,
    u0: f64,
    u1: f64,
    start: &Point,
    end: &Point,
    tol: f64,
    farthest: f64,
) -> Certificate {
    let chord = Segment::on::<N>(start, end);
    let allowance = allowance_on::<N>(start, end, curve.degree(), tol);
    // Below this a piece needs no halving; above it after MAX_DEPTH halvings, it is over.
    let mut walk = Walk {
        chord: &chord,
        target: tol - allowance,
        bound: 0.0,
        pieces: 0,
        over: false,
    };
    walk.curve_of_degree::<W>(curve, u0, u1, farthest);
    Certificate {
        bound: walk.bound + allowance,
        pieces: walk.pieces,
    }
}

/// The halving walk over one segment's pieces (depth-first; recursion depth at most
/// [`MAX_DEPTH`], so the stack holds at most that many pieces and nothing is allocated).
struct Walk<'a> {
    chord: &'a Segment,
    target: f64,
    bound: f64,
    pieces: u32,
    /// A piece stayed above the target at the depth limit: the bound is over; stop.
    over: bool,
}

impl Walk<'_> {
    /// [`curve`](Self::curve) with as many rows as the curve's degree needs, up to cubics.
    fn curve_of_degree<const W: usize>(
        &mut self,
        curve: &NurbsCurve,
        u0: f64,
        u1: f64,
        farthest: f64,
    ) {
        match curve.degree() {
            1 => self.curve::<W, 2>(curve, u0, u1, farthest),
            2 => self.curve::<W, 3>(curve, u0, u1, farthest),
            3 => self.curve::<W, 4>(curve, u0, u1, farthest),
            _ => self.curve::<W, MAX_ORDER>(curve, u0, u1, farthest),
        }
    }

    /// Every Bézier piece of `curve` between `u0` and `u1`, in `R` rows `W` wide; the piece
    /// holding `farthest` is cut there first.
    fn curve<const W: usize, const R: usize>(
        &mut self,
        curve: &NurbsCurve,
        u0: f64,
        u1: f64,
        farthest: f64,
    ) {
        curve.bezier_pieces::<W, R>(u0, u1, |piece, s, t| {
            if self.over {
                return;
            }
            let cut = (farthest - s) / (t - s);
            // Only a cut well inside the piece helps; near an end one half is a sliver. The
            // cut is made without first measuring the whole piece: with a measured maximum
            // near the tolerance, the whole piece's control points are over it anyway.
            if cut > 0.02 && cut < 0.98 {
                self.pieces += 1;
                let (left, right) = piece.split_at(cut);
                self.visit::<0, W, R>(&left, 1);
                if !self.over {
                    self.visit::<1, W, R>(&right, 1);
                }
            } else {
                self.visit::<0, W, R>(piece, 0);
            }
        });
    }

    /// Looks at `bz` and, while it stands over the target, its halves.
    ///
    /// `SKIP` is 1 when the first control point of `bz` is the last of the piece looked at
    /// just before, bit for bit (a split copies the point where it cuts into both parts);
    /// that point is left out. The piece before was accepted, or the walk would have halved
    /// it or stopped over: so the point's distance is within the target and already in
    /// `bound`, and leaving it out changes neither whether `bz` is accepted nor the bound.
    /// Pieces of different knot spans are blossomed separately and share no point bit for
    /// bit: they start with `SKIP` 0. A constant, so that the distances' loop keeps a
    /// constant length.
    fn visit<const SKIP: usize, const W: usize, const R: usize>(
        &mut self,
        bz: &Bezier<W, R>,
        depth: u32,
    ) {
        self.pieces += 1;
        let b = self.chord.largest_control_distance::<SKIP, W, R>(bz);
        if b <= self.target {
            self.bound = running_max(self.bound, b);
        } else if depth >= MAX_DEPTH {
            self.bound = running_max(self.bound, b);
            self.over = true;
        } else {
            let (left, right) = bz.split();
            self.visit::<SKIP, W, R>(&left, depth + 1);
            if !self.over {
                self.visit::<1, W, R>(&right, depth + 1);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{point, semicircle};

    #[test]
    fn the_bound_of_an_arc_tightens_to_the_sagitta() {
        // Radius 10, a 0.2 rad piece: sagitta r (1 - cos 0.1).
        let arc = semicircle();
        let (u0, u1) = (0.1, 0.1 + 0.2 / std::f64::consts::PI);
        let (a, b) = (arc.point(u0), arc.point(u1));
        let truth = {
            let mid = arc.point(0.5 * (u0 + u1));
            Segment::new(&a, &b).distance(&mid)
        };
        // With the tolerance well above the error, no halving: a loose but valid bound.
        let loose = certify(&arc, u0, u1, &a, &b, 10.0 * truth, f64::NAN);
        assert!(loose.bound >= truth);
        assert_eq!(loose.pieces, 1);
        // A tolerance 0.1 % above the error is met after halving.
        let tight = certify(&arc, u0, u1, &a, &b, 1.001 * truth, f64::NAN);
        assert!(tight.holds(1.001 * truth), "{} vs {truth}", tight.bound);
        assert!(tight.bound >= truth);
        // Below the error it cannot hold.
        let under = certify(&arc, u0, u1, &a, &b, 0.999 * truth, f64::NAN);
        assert!(!under.holds(0.999 * truth));
    }

    #[test]
    fn a_cut_at_the_farthest_point_certifies_with_fewer_pieces() {
        let arc = semicircle();
        let (u0, u1) = (0.1, 0.1 + 0.2 / std::f64::consts::PI);
        let (a, b) = (arc.point(u0), arc.point(u1));
        // The farthest point, by golden section (a rational arc's parameter is not its
        // angle, so it is not the parameter midpoint).
        let chord = Segment::new(&a, &b);
        let (mut lo, mut hi) = (u0, u1);
        for _ in 0..100 {
            let (m1, m2) = (lo + 0.382 * (hi - lo), lo + 0.618 * (hi - lo));
            if chord.distance(&arc.point(m1)) < chord.distance(&arc.point(m2)) {
                lo = m1;
            } else {
                hi = m2;
            }
        }
        let mid = 0.5 * (lo + hi);
        let truth = chord.distance(&arc.point(mid));
        let tol = 1.002 * truth;
        let blind = certify(&arc, u0, u1, &a, &b, tol, f64::NAN);
        let guided = certify(&arc, u0, u1, &a, &b, tol, mid);
        assert!(blind.holds(tol) && guided.holds(tol));
        assert!(guided.bound >= truth);
        assert!(guided.pieces < blind.pieces, "{guided:?} vs {blind:?}");
        // A wrong hint costs pieces, never soundness.
        let wrong = certify(&arc, u0, u1, &a, &b, tol, u0 + 0.9 * (u1 - u0));
        assert!(wrong.holds(tol) && wrong.bound >= truth);
    }

    #[test]
    fn an_uncut_bound_stands_out_from_a_parabola_by_the_hull_excess() {
        // y = x (1 - x) on [0, 1] as a quadratic, and degree-elevated to a cubic and a quartic:
        // the curve peaks at 1/4 over its chord, the control points stand higher.
        let elevated = [
            vec![(0.0, 0.0), (0.5, 0.5), (1.0, 0.0)],
            vec![
                (0.0, 0.0),
                (1.0 / 3.0, 1.0 / 3.0),
                (2.0 / 3.0, 1.0 / 3.0),
                (1.0, 0.0),
            ],
            vec![
                (0.0, 0.0),
                (0.25, 0.25),
                (0.5, 1.0 / 3.0),
                (0.75, 0.25),
                (1.0, 0.0),
            ],
        ];
        for pts in elevated {
            let degree = pts.len() - 1;
            let points: Vec<Point> = pts.iter().map(|&(x, y)| point(&[x, y])).collect();
            let knots = crate::geometry::clamped_uniform_knots(points.len(), degree);
            let curve =
                NurbsCurve::new(degree, 2, &points, &vec![1.0; points.len()], knots).unwrap();
            let (a, b) = (curve.point(0.0), curve.point(1.0));
            assert!((Segment::new(&a, &b).distance(&curve.point(0.5)) - 0.25).abs() < 1e-12);
            let c = certify(&curve, 0.0, 1.0, &a, &b, 10.0, f64::NAN);
            assert_eq!(c.pieces, 1);
            let excess = c.bound / 0.25;
            assert!(
                (excess - hull_excess(degree)).abs() < 1e-9,
                "degree {degree}: {excess} against {}",
                hull_excess(degree)
            );
        }
    }

    /// The walk as it was before pieces shared points: every control point of every piece
    /// measured. The reference for `leaving_out_shared_points_changes_nothing`.
    fn walk_measuring_every_point<const W: usize, const R: usize>(
        curve: &NurbsCurve,
        (u0, u1): (f64, f64),
        chord: &Segment,
        target: f64,
        farthest: f64,
    ) -> (f64, u32) {
        fn visit<const W: usize, const R: usize>(
            chord: &Segment,
            target: f64,
            bz: &Bezier<W, R>,
            depth: u32,
            out: &mut (f64, u32, bool),
        ) {
            out.1 += 1;
            let b = chord.largest_control_distance::<0, W, R>(bz);
            if b <= target || depth >= MAX_DEPTH {
                out.0 = out.0.max(b);
                out.2 = b > target;
            } else {
                let (left, right) = bz.split();
                visit(chord, target, &left, depth + 1, out);
                if !out.2 {
                    visit(chord, target, &right, depth + 1, out);
                }
            }
        }
        let mut out = (0.0, 0, false);
        curve.bezier_pieces::<W, R>(u0, u1, |piece, s, t| {
            if out.2 {
                return;
            }
            let cut = (farthest - s) / (t - s);
            if cut > 0.02 && cut < 0.98 {
                out.1 += 1;
                let (left, right) = piece.split_at(cut);
                visit(chord, target, &left, 1, &mut out);
                if !out.2 {
                    visit(chord, target, &right, 1, &mut out);
                }
            } else {
                visit(chord, target, piece, 0, &mut out);
            }
        });
        (out.0, out.1)
    }

    #[test]
    fn leaving_out_shared_points_changes_nothing() {
        // Random curves at the sizes the certificate picks for them (narrow rows of exact
        // degree, wide rows of any), random pieces, tolerances from loose to under the
        // error (deep halvings, and walks that stop over), with and without a cut.
        let mut rng = crate::rng::SplitMix64::new(23);
        let mut halved = 0;
        let mut over = 0;
        for case in 0..3000 {
            let degree = 1 + case % 5;
            let dim = if case % 2 == 0 { 3 } else { 5 };
            let curve =
                crate::geometry::random_curve(&mut rng, degree, dim, degree + 4, case % 3 == 0);
            let u0 = rng.uniform(0.0, 0.9);
            let u1 = u0 + rng.uniform(1e-4, 1.0 - u0);
            let (a, b) = (curve.point(u0), curve.point(u1));
            let tol = 10f64.powf(rng.uniform(-6.0, 1.0));
            let farthest = if case % 4 == 0 {
                f64::NAN
            } else {
                rng.uniform(u0, u1)
            };
            let chord = Segment::new(&a, &b);
            let target = tol - rounding_allowance(&a, &b, degree, tol);
            let piece = (u0, u1);
            let (bound, pieces) = match (dim < 4, degree) {
                (true, 1) => {
                    walk_measuring_every_point::<4, 2>(&curve, piece, &chord, target, farthest)
                }
                (true, 2) => {
                    walk_measuring_every_point::<4, 3>(&curve, piece, &chord, target, farthest)
                }
                (true, 3) => {
                    walk_measuring_every_point::<4, 4>(&curve, piece, &chord, target, farthest)
                }
                (true, _) => walk_measuring_every_point::<4, MAX_ORDER>(
                    &curve, piece, &chord, target, farthest,
                ),
                (false, _) => walk_measuring_every_point::<8, MAX_ORDER>(
                    &curve, piece, &chord, target, farthest,
                ),
            };
            let c = certify(&curve, u0, u1, &a, &b, tol, farthest);
            let expected = bound + rounding_allowance(&a, &b, degree, tol);
            assert_eq!(c.bound.to_bits(), expected.to_bits(), "case {case}");
            assert_eq!(c.pieces, pieces, "case {case}");
            halved += usize::from(pieces > 3);
            over += usize::from(!c.holds(tol));
        }
        // Both kinds of walk were exercised.
        assert!(halved > 300 && over > 100, "{halved} halved, {over} over");
    }

    #[test]
    fn the_rounding_allowance_scales_with_nalgebras_largest_magnitude() {
        let mut rng = crate::rng::SplitMix64::new(11);
        for _ in 0..10_000 {
            let mut a = Point::zeros();
            let mut b = Point::zeros();
            for axis in 0..crate::vocab::MAX_AXES {
                a[axis] = rng.uniform(-600.0, 600.0);
                b[axis] = rng.uniform(-2.0, 2.0);
            }
            let tol = 0.001;
            let ulps = 16.0 + 2.0 * 3.0 * f64::from(MAX_DEPTH + 2);
            for (p, q) in [(&a, &b), (&b, &a), (&b, &b)] {
                let scale = p.amax().max(q.amax()).max(1.0) + tol;
                assert_eq!(
                    rounding_allowance(p, q, 3, tol),
                    ulps * f64::EPSILON * scale
                );
            }
        }
    }

    #[test]
    fn three_coordinates_certify_as_all_of_them() {
        // Curves of up to three axes take the narrow chord and rows; the wide ones must give
        // the same bound and pieces, bit for bit, on their points (zero past the axes).
        let mut rng = crate::rng::SplitMix64::new(0xce27);
        for case in 0..3_000 {
            let degree = 1 + case % 3;
            let dim = 2 + case % 2;
            let curve = crate::geometry::random_curve(&mut rng, degree, dim, degree + 3, false);
            let u0 = rng.uniform(0.0, 0.9);
            let u1 = (u0 + rng.uniform(1e-3, 0.3)).min(1.0);
            let (a, b) = (curve.point(u0), curve.point(u1));
            let tol = [1e-4, 1e-3, 1e-1][case % 3];
            let farthest = if case % 4 == 0 {
                f64::NAN
            } else {
                0.5 * (u0 + u1)
            };
            let narrow = certify(&curve, u0, u1, &a, &b, tol, farthest);
            let wide = certify_on::<MAX_AXES, 8>(&curve, u0, u1, &a, &b, tol, farthest);
            assert_eq!(narrow.bound.to_bits(), wide.bound.to_bits(), "case {case}");
            assert_eq!(narrow.pieces, wide.pieces, "case {case}");
        }
    }

    #[test]
    fn a_line_has_no_chord_error() {
        let line =
            NurbsCurve::line(3, &point(&[1.0, 2.0, 3.0]), &point(&[4.0, -2.0, 5.0])).unwrap();
        let (a, b) = (line.point(0.2), line.point(0.7));
        let c = certify(&line, 0.2, 0.7, &a, &b, 1e-6, f64::NAN);
        assert!(c.holds(1e-6) && c.bound < 1e-12, "{}", c.bound);
    }
}
