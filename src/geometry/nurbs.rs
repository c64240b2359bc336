//! The validated NURBS curve and its evaluation.

use super::basis::{MAX_ORDER, basis_derivs, basis_derivs_to, find_span};
use super::{MAX_AXES, MAX_DEGREE, Point};
use smallvec::SmallVec;

/// Why a set of NURBS data is not a curve edmd can run. One variant per rule, so that the
/// G-code layer can point at the word that broke it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NurbsError {
    #[error("degree {degree} is out of range (1 to {MAX_DEGREE})")]
    DegreeOutOfRange { degree: usize },
    #[error("{dim} axes is out of range (1 to {MAX_AXES})")]
    DimensionOutOfRange { dim: usize },
    #[error("degree {degree} needs at least {} control points, got {points}", degree + 1)]
    TooFewPoints { points: usize, degree: usize },
    #[error("{weights} weights for {points} control points")]
    WeightCount { points: usize, weights: usize },
    #[error(
        "wrong knot count: {points} control points of degree {degree} need {expected} knots, got {found}"
    )]
    KnotCount {
        points: usize,
        degree: usize,
        expected: usize,
        found: usize,
    },
    #[error("knot {index} is not a finite number")]
    NonFiniteKnot { index: usize },
    #[error("knots decrease: knot {index} ({value}) is less than the knot before it ({previous})")]
    KnotsDecreasing {
        index: usize,
        value: f64,
        previous: f64,
    },
    #[error("knot vector is not clamped at the {end}: the first/last {count} knots must be equal")]
    NotClamped { end: CurveEnd, count: usize },
    #[error("empty parameter range: the curve's knots start and end at {value}")]
    EmptyRange { value: f64 },
    #[error(
        "knot {value} is repeated {multiplicity} times; at most {max} allowed (the degree inside, degree + 1 at the ends)"
    )]
    KnotMultiplicity {
        value: f64,
        multiplicity: usize,
        max: usize,
    },
    #[error("weight {index} is {value}; weights must be finite and greater than 0")]
    BadWeight { index: usize, value: f64 },
    #[error("control point {index} has a coordinate that is not a finite number")]
    NonFiniteCoordinate { index: usize },
    #[error("all control points coincide: the curve has no length")]
    Degenerate,
}

/// Width of a stored homogeneous control point: up to [`MAX_AXES`] coordinates, the weight,
/// one slot of padding.
pub(super) const HOMOGENEOUS_WIDTH: usize = 8;
/// Where the weight sits in a stored homogeneous control point.
pub(super) const WEIGHT_SLOT: usize = MAX_AXES;

/// Which end of a knot vector a [`NurbsError::NotClamped`] refers to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CurveEnd {
    Start,
    End,
}

impl std::fmt::Display for CurveEnd {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            CurveEnd::Start => "start",
            CurveEnd::End => "end",
        })
    }
}

/// Point, first and second derivative of a curve with respect to its parameter `u`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurveDerivs {
    pub point: Point,
    pub d1: Point,
    pub d2: Point,
}

impl CurveDerivs {
    /// `|C'(u)|`: path length per unit of parameter.
    pub fn speed(&self) -> f64 {
        self.d1.norm()
    }

    /// Radius of curvature `rho = |C'|^3 / |C' x C''|` in any dimension; infinite where the
    /// curve is straight, zero where it has no speed (a cusp of the parametrisation, which the
    /// planner must treat like a corner).
    pub fn curvature_radius(&self) -> f64 {
        super::lanes::curvature_radius::<MAX_AXES>(self)
    }
}

/// A validated, clamped NURBS curve of degree 1 to [`MAX_DEGREE`] in 1 to [`MAX_AXES`] axes.
///
/// Control points are stored in homogeneous form `(w x, w)`, padded to a fixed width of eight
/// numbers (coordinates, zeros, the weight in slot [`WEIGHT_SLOT`]) so the evaluator's inner loop
/// has a fixed length the compiler vectorises, whatever the number of axes. Coordinates are
/// millimetres; the parameter is in the program's own knot units. Construction enforces every rule the evaluator relies on, so evaluation cannot fail.
#[derive(Debug, Clone, PartialEq)]
pub struct NurbsCurve {
    degree: usize,
    dim: usize,
    knots: Knots,
    homogeneous: Points,
}

/// A curve's knots: a line's four are kept in the curve itself, so a straight move (a
/// canned cycle makes five a hole) costs no allocation; longer ones go to the heap.
type Knots = SmallVec<[f64; 4]>;
/// A curve's homogeneous control points: a line's two kept in the curve, as its knots are.
type Points = SmallVec<[[f64; HOMOGENEOUS_WIDTH]; 2]>;

impl NurbsCurve {
    /// Builds and validates a curve. `points` gives the first `dim` coordinates of each control
    /// point (further coordinates of the [`Point`] are ignored).
    pub fn new(
        degree: usize,
        dim: usize,
        points: &[Point],
        weights: &[f64],
        knots: impl Into<Knots>,
    ) -> Result<Self, NurbsError> {
        let knots = knots.into();
        if !(1..=MAX_DEGREE).contains(&degree) {
            return Err(NurbsError::DegreeOutOfRange { degree });
        }
        if !(1..=MAX_AXES).contains(&dim) {
            return Err(NurbsError::DimensionOutOfRange { dim });
        }
        if points.len() < degree + 1 {
            return Err(NurbsError::TooFewPoints {
                points: points.len(),
                degree,
            });
        }
        if weights.len() != points.len() {
            return Err(NurbsError::WeightCount {
                points: points.len(),
                weights: weights.len(),
            });
        }
        validate_knots(degree, points.len(), &knots)?;
        for (index, &w) in weights.iter().enumerate() {
            if !(w.is_finite() && w > 0.0) {
                return Err(NurbsError::BadWeight { index, value: w });
            }
        }
        let mut homogeneous = Points::with_capacity(points.len());
        for (index, (p, &w)) in points.iter().zip(weights).enumerate() {
            if p.iter().take(dim).any(|c| !c.is_finite()) {
                return Err(NurbsError::NonFiniteCoordinate { index });
            }
            let mut h = [0.0; HOMOGENEOUS_WIDTH];
            for axis in 0..dim {
                h[axis] = p[axis] * w;
            }
            h[WEIGHT_SLOT] = w;
            homogeneous.push(h);
        }
        let first = points[0];
        if points
            .iter()
            .all(|p| (0..dim).all(|axis| p[axis] == first[axis]))
        {
            return Err(NurbsError::Degenerate);
        }
        Ok(Self {
            degree,
            dim,
            knots,
            homogeneous,
        })
    }

    /// A curve from parts already valid (a split of a valid curve keeps every rule).
    pub(super) fn from_parts(
        degree: usize,
        dim: usize,
        knots: impl Into<Knots>,
        homogeneous: impl Into<Points>,
    ) -> NurbsCurve {
        NurbsCurve {
            degree,
            dim,
            knots: knots.into(),
            homogeneous: homogeneous.into(),
        }
    }

    /// A straight line from `a` to `b` as a degree-1 curve on `[0, 1]`.
    pub fn line(dim: usize, a: &Point, b: &Point) -> Result<Self, NurbsError> {
        Self::new(1, dim, &[*a, *b], &[1.0, 1.0], [0.0, 0.0, 1.0, 1.0])
    }

    /// The same curve run the other way: `reversed().point(a + b - u) == point(u)` on the
    /// parameter range `[a, b]`.
    pub fn reversed(&self) -> NurbsCurve {
        let (a, b) = (self.u_min(), self.u_max());
        let mut homogeneous = self.homogeneous.clone();
        homogeneous.reverse();
        NurbsCurve {
            degree: self.degree,
            dim: self.dim,
            knots: self.knots.iter().rev().map(|u| a + b - u).collect(),
            homogeneous,
        }
    }

    pub fn degree(&self) -> usize {
        self.degree
    }

    /// Number of axes (coordinates per point).
    pub fn dim(&self) -> usize {
        self.dim
    }

    pub fn knots(&self) -> &[f64] {
        &self.knots
    }

    pub fn num_points(&self) -> usize {
        self.homogeneous.len()
    }

    /// Control point `i` in Cartesian coordinates (mm).
    pub fn control_point(&self, i: usize) -> Point {
        let h = &self.homogeneous[i];
        let w = h[WEIGHT_SLOT];
        let mut p = Point::zeros();
        for axis in 0..self.dim {
            p[axis] = h[axis] / w;
        }
        p
    }

    /// The homogeneous control points `(w x, w)`, weight in slot [`WEIGHT_SLOT`].
    pub(super) fn homogeneous(&self) -> &[[f64; HOMOGENEOUS_WIDTH]] {
        &self.homogeneous
    }

    pub fn weight(&self, i: usize) -> f64 {
        self.homogeneous[i][WEIGHT_SLOT]
    }

    /// First parameter value of the curve.
    pub fn u_min(&self) -> f64 {
        self.knots[self.degree]
    }

    /// Last parameter value of the curve.
    pub fn u_max(&self) -> f64 {
        self.knots[self.num_points()]
    }

    /// The curve's start: its first control point (the knot vector is clamped).
    pub fn start_point(&self) -> Point {
        self.control_point(0)
    }

    /// The curve's end: its last control point.
    pub fn end_point(&self) -> Point {
        self.control_point(self.num_points() - 1)
    }

    /// `C(u)`, clamped to the parameter range. Allocation-free.
    pub fn point(&self, u: f64) -> Point {
        self.derivs(u).point
    }

    /// `C(u)`, `C'(u)`, `C''(u)` of the rational curve, clamped to the parameter range.
    ///
    /// Index loops on purpose: this is the numeric kernel, and the formulas read as written.
    /// Allocation-free: the basis and the homogeneous sums live on the stack.
    ///
    /// With `A(u) = sum N_i w_i P_i` and `w(u) = sum N_i w_i`:
    /// `C = A/w`, `C' = (A' - w' C)/w`, `C'' = (A'' - 2 w' C' - w'' C)/w` (errata, seed 000).
    #[allow(clippy::needless_range_loop)]
    pub fn derivs(&self, u: f64) -> CurveDerivs {
        self.derivs_inlined(u)
    }

    /// [`derivs`](Self::derivs) inlined where it is called, with the kernels of curves of up
    /// to three axes and degree 3 (the rest is a call). For a loop that only evaluates and
    /// reduces, as the bound's sampling does: there the call cost about fifty of an
    /// evaluation's three hundred instructions, in saved registers and in derivatives stored
    /// for the caller to load again. Where the caller keeps much else live (the chord
    /// measurement), inlined it spilled more than the call saved.
    #[inline(always)]
    pub fn derivs_inlined(&self, u: f64) -> CurveDerivs {
        let u = u.clamp(self.u_min(), self.u_max());
        let span = find_span(self.num_points() - 1, self.degree, &self.knots, u);
        self.derivs_on_span(span, u)
    }

    /// Like [`derivs`](Self::derivs), but at a knot takes the span that ends there: the
    /// derivatives of the piece arriving at `u`. They differ from the right-hand ones only at a
    /// knot where the curve is not C2 (a multiple knot); at a corner knot (multiplicity equal to
    /// the degree) this is the incoming tangent.
    pub fn derivs_from_left(&self, u: f64) -> CurveDerivs {
        let u = u.clamp(self.u_min(), self.u_max());
        let mut span = find_span(self.num_points() - 1, self.degree, &self.knots, u);
        while span > self.degree && self.knots[span] >= u {
            span -= 1;
        }
        self.derivs_on_span(span, u)
    }

    /// At the ends the point is the end control point itself, bit for bit: the sums of the
    /// basis can round a rational curve's end by an ulp, and a block's last segment must end
    /// exactly where the next block starts (both are rounded to steps independently).
    /// Applied inside the kernel, so the derivatives are built where the caller returns them:
    /// pinned after the call, they were copied through (70 M instructions of `memcpy` on a
    /// plan of 20,000 arcs).
    #[inline(always)]
    fn pin_ends(&self, u: f64, d: &mut CurveDerivs) {
        if u == self.u_max() {
            d.point = self.end_point();
        } else if u == self.u_min() {
            d.point = self.start_point();
        }
    }

    /// Interior parameters where the curve may have a corner: knots of multiplicity at least
    /// the degree (every interior knot of a degree-1 polyline). Between two of them (and the
    /// ends) the curve is at least C1.
    pub fn corner_knots(&self) -> impl Iterator<Item = f64> + '_ {
        let p = self.degree;
        let interior = &self.knots[p + 1..self.num_points()];
        interior.iter().enumerate().filter_map(move |(i, &k)| {
            let first = i == 0 || interior[i - 1] != k;
            let multiplicity = interior[i..].iter().take_while(|&&x| x == k).count();
            (first && multiplicity >= p).then_some(k)
        })
    }

    /// Dispatches on the degree so that each common degree gets its own copy of the kernel with
    /// the loop bounds known at compile time (unrolled, no dead table work).
    ///
    /// Curves of up to three axes (lines, arcs, a plane's or a wire's cubics) also get copies
    /// that sum three coordinates and the weight rather than every slot: the slots past the
    /// curve's axes hold zeros, whose sums and quotients are `+0` (a `±0` term leaves a sum
    /// from `+0` unchanged, and the weight is positive), which is what `Point::zeros` leaves
    /// there. The same numbers, bit for bit, for half the multiplications. Inlined into its
    /// two callers: one call an evaluation, not two.
    #[inline(always)]
    fn derivs_on_span(&self, span: usize, u: f64) -> CurveDerivs {
        match (self.degree, self.dim <= 3) {
            (1, true) => self.kernel::<3>(span, u, 1),
            (2, true) => self.kernel::<3>(span, u, 2),
            (3, true) => self.kernel::<3>(span, u, 3),
            _ => self.derivs_on_span_wide(span, u),
        }
    }

    /// [`derivs_on_span`](Self::derivs_on_span) for more than three axes or a degree above 3:
    /// a call of its own, so that the inlined evaluation stays small.
    #[inline(never)]
    fn derivs_on_span_wide(&self, span: usize, u: f64) -> CurveDerivs {
        match (self.degree, self.dim <= 3) {
            (1, false) => self.kernel::<MAX_AXES>(span, u, 1),
            (2, false) => self.kernel::<MAX_AXES>(span, u, 2),
            (3, false) => self.kernel::<MAX_AXES>(span, u, 3),
            (4, _) => self.kernel::<MAX_AXES>(span, u, 4),
            (5, _) => self.kernel::<MAX_AXES>(span, u, 5),
            (p, _) => self.kernel::<MAX_AXES>(span, u, p),
        }
    }

    /// The point and two derivatives from the basis on `span`, in the first `LANES`
    /// coordinates (the rest left zero), the point [pinned](Self::pin_ends) at the ends.
    #[inline(always)]
    #[allow(clippy::needless_range_loop)]
    fn kernel<const LANES: usize>(&self, span: usize, u: f64, p: usize) -> CurveDerivs {
        let mut ders = [[0.0f64; MAX_ORDER]; 3];
        basis_derivs(span, u, p, &self.knots, &mut ders);

        let mut sums = [[0.0f64; HOMOGENEOUS_WIDTH]; 3];
        let points = &self.homogeneous[span - p..=span];
        for j in 0..=p {
            let hp = &points[j];
            for k in 0..3 {
                let b = ders[k][j];
                for c in 0..LANES {
                    sums[k][c] += b * hp[c];
                }
                sums[k][WEIGHT_SLOT] += b * hp[WEIGHT_SLOT];
            }
        }
        let (w, w1, w2) = (
            sums[0][WEIGHT_SLOT],
            sums[1][WEIGHT_SLOT],
            sums[2][WEIGHT_SLOT],
        );
        let inv_w = 1.0 / w;
        let mut out = CurveDerivs {
            point: Point::zeros(),
            d1: Point::zeros(),
            d2: Point::zeros(),
        };
        // Slots past `dim` hold zeros, so they produce zeros: no need to stop at `dim`.
        for axis in 0..LANES {
            let c = sums[0][axis] * inv_w;
            let c1 = (sums[1][axis] - w1 * c) * inv_w;
            let c2 = (sums[2][axis] - 2.0 * w1 * c1 - w2 * c) * inv_w;
            out.point[axis] = c;
            out.d1[axis] = c1;
            out.d2[axis] = c2;
        }
        self.pin_ends(u, &mut out);
        out
    }

    /// `|C'(u)|`, the speed alone: the kernel without the second derivative (an arc length's
    /// quadrature needs nothing else).
    pub fn speed_at(&self, u: f64) -> f64 {
        let u = u.clamp(self.u_min(), self.u_max());
        let span = find_span(self.num_points() - 1, self.degree, &self.knots, u);
        match self.degree {
            1 => self.speed_kernel(span, u, 1),
            2 => self.speed_kernel(span, u, 2),
            3 => self.speed_kernel(span, u, 3),
            p => self.speed_kernel(span, u, p),
        }
    }

    #[inline(always)]
    #[allow(clippy::needless_range_loop)]
    fn speed_kernel(&self, span: usize, u: f64, p: usize) -> f64 {
        let mut ders = [[0.0f64; MAX_ORDER]; 3];
        basis_derivs_to::<false>(span, u, p, &self.knots, &mut ders);
        let mut sums = [[0.0f64; HOMOGENEOUS_WIDTH]; 2];
        let first = span - p;
        for j in 0..=p {
            let hp = &self.homogeneous[first + j];
            for k in 0..2 {
                let b = ders[k][j];
                for c in 0..HOMOGENEOUS_WIDTH {
                    sums[k][c] += b * hp[c];
                }
            }
        }
        let (w, w1) = (sums[0][WEIGHT_SLOT], sums[1][WEIGHT_SLOT]);
        let inv_w = 1.0 / w;
        let mut speed_sq = 0.0;
        for axis in 0..MAX_AXES {
            let c = sums[0][axis] * inv_w;
            let c1 = (sums[1][axis] - w1 * c) * inv_w;
            speed_sq += c1 * c1;
        }
        speed_sq.sqrt()
    }
}

fn validate_knots(degree: usize, points: usize, knots: &[f64]) -> Result<(), NurbsError> {
    let expected = points + degree + 1;
    if knots.len() != expected {
        return Err(NurbsError::KnotCount {
            points,
            degree,
            expected,
            found: knots.len(),
        });
    }
    if let Some(index) = knots.iter().position(|k| !k.is_finite()) {
        return Err(NurbsError::NonFiniteKnot { index });
    }
    if let Some(index) = (1..knots.len()).find(|&i| knots[i] < knots[i - 1]) {
        return Err(NurbsError::KnotsDecreasing {
            index,
            value: knots[index],
            previous: knots[index - 1],
        });
    }
    let count = degree + 1;
    if knots[..count].iter().any(|&k| k != knots[0]) {
        return Err(NurbsError::NotClamped {
            end: CurveEnd::Start,
            count,
        });
    }
    let last = knots[knots.len() - 1];
    if knots[knots.len() - count..].iter().any(|&k| k != last) {
        return Err(NurbsError::NotClamped {
            end: CurveEnd::End,
            count,
        });
    }
    if knots[0] == last {
        return Err(NurbsError::EmptyRange { value: last });
    }
    // Runs of equal knots: at most degree inside, exactly degree + 1 at either end.
    let mut i = 0;
    while i < knots.len() {
        let mut j = i;
        while j + 1 < knots.len() && knots[j + 1] == knots[i] {
            j += 1;
        }
        let multiplicity = j - i + 1;
        let at_end = i == 0 || j == knots.len() - 1;
        let max = if at_end { degree + 1 } else { degree };
        if multiplicity > max {
            return Err(NurbsError::KnotMultiplicity {
                value: knots[i],
                multiplicity,
                max,
            });
        }
        i = j + 1;
    }
    Ok(())
}

// Cutting a curve in two (`NurbsCurve::split_at`).
// Cutting a curve in two at a parameter or an arc length: knot insertion (The NURBS Book
// A5.1, one knot at a time) until the knot's multiplicity is the degree, where the curve
// passes through a control point and falls apart into two clamped curves that trace it
// exactly. Lines, arcs (rational) and NURBS alike; a wire contour's tab is cut this way.
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
    use crate::rng::SplitMix64;

    /// The three-coordinate kernel gives every bit the all-slot kernel gives, signs of zero
    /// included, on curves of one to three axes, degrees one to three, repeated knots too.
    #[test]
    fn three_coordinate_evaluation_is_the_all_slot_one_bit_for_bit() {
        let mut rng = SplitMix64::new(0x3_1a9e5);
        for case in 0..300 {
            let degree = 1 + case % 3;
            let dim = 1 + (case / 3) % 3;
            let count = degree + 1 + rng.below(6);
            let curve = crate::geometry::random_curve(&mut rng, degree, dim, count, case % 4 == 0);
            for k in 0..=40 {
                let u = if k == 40 { 1.0 } else { rng.uniform(0.0, 1.0) };
                let span = find_span(count - 1, degree, curve.knots(), u);
                let narrow = curve.kernel::<3>(span, u, degree);
                let wide = curve.kernel::<MAX_AXES>(span, u, degree);
                for (n, w) in [narrow.point, narrow.d1, narrow.d2]
                    .iter()
                    .zip(&[wide.point, wide.d1, wide.d2])
                {
                    let bits = |v: &Point| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(n), bits(w), "case {case} at {u}");
                }
            }
        }
    }
}

#[cfg(test)]
mod split_tests {
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
