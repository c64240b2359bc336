//! Geometry: every motion block is a NURBS curve.
//!
//! A line is a degree-1 curve and a circular arc an exact rational quadratic ([`circular_arc`]),
//! so the rest of edmd knows one kind of path: [`NurbsCurve`], validated once on construction and
//! then evaluated (point, first and second derivative, curvature radius, length) without
//! allocating. Coordinates are millimetres in the machine's axis order; a curve has `dim` axes
//! and the unused tail of a [`Point`] stays zero.
//!
//! The formulas follow The NURBS Book (Piegl & Tiller) with the corrections in
//! `shared/notes/seed-errata.md`: the Cox–de Boor recursion with the right denominators, and the
//! quotient rule for the rational derivatives.

mod arc;
mod basis;
mod bezier;
pub mod lanes;
mod length;
mod nurbs;

#[cfg(test)]
pub use arc::semicircle;
pub use arc::{SPIRAL_FIT_TOLERANCE_MM, circular_arc, spiral_arc};
pub use basis::MAX_ORDER;
pub use bezier::Bezier;
pub use length::ESTIMATE_TOLERANCE;
pub use nurbs::{CurveDerivs, CurveEnd, NurbsCurve, NurbsError};

/// Highest curve degree accepted (order 10).
pub const MAX_DEGREE: usize = 9;

pub use crate::vocab::MAX_AXES;

/// A point or vector in machine space (mm); components past the curve's `dim` are zero.
pub type Point = nalgebra::SVector<f64, MAX_AXES>;

/// A clamped uniform knot vector on `[0, 1]` for `points` control points of degree `degree`:
/// `degree + 1` zeros, the interior knots evenly spaced, `degree + 1` ones.
pub fn clamped_uniform_knots(points: usize, degree: usize) -> Vec<f64> {
    let interior = points.saturating_sub(degree + 1);
    let spans = (interior + 1) as f64;
    let mut knots = vec![0.0; degree + 1];
    knots.extend((1..=interior).map(|j| j as f64 / spans));
    knots.extend(std::iter::repeat_n(1.0, degree + 1));
    knots
}

/// A running maximum `best` moved up to `x` where `x` is larger: `best.max(x)` bit for bit
/// while `best` is a number and the two are not zeros of opposite signs, a NaN `x` passed
/// over as `max` passes over it. One instruction where `max` spends five, the rest on passing
/// over a NaN `best`, which a maximum started from a number never is. For the maxima of
/// magnitudes and distances (never `-0`) on the certificate's and the plan's hot paths.
#[inline(always)]
pub fn running_max(best: f64, x: f64) -> f64 {
    if x > best { x } else { best }
}

/// [`running_max`]'s minimum: `best.min(x)` bit for bit under the same conditions.
#[inline(always)]
pub fn running_min(best: f64, x: f64) -> f64 {
    if x < best { x } else { best }
}

/// Builds a [`Point`] from up to [`MAX_AXES`] coordinates.
pub fn point(coords: &[f64]) -> Point {
    let mut p = Point::zeros();
    for (slot, c) in p.iter_mut().zip(coords) {
        *slot = *c;
    }
    p
}

/// A random curve for tests: `n` control points of `dim` axes (within ±50 mm, the third
/// within ±5), weights 0.2 to 5, clamped uniform knots, with `repeat` one interior knot
/// repeated up to the degree.
#[cfg(test)]
pub fn random_curve(
    rng: &mut crate::rng::SplitMix64,
    degree: usize,
    dim: usize,
    n: usize,
    repeat: bool,
) -> NurbsCurve {
    let points: Vec<Point> = (0..n)
        .map(|_| {
            let mut p = Point::zeros();
            for axis in 0..dim {
                let reach = if axis == 2 { 5.0 } else { 50.0 };
                p[axis] = rng.uniform(-reach, reach);
            }
            p
        })
        .collect();
    let weights: Vec<f64> = (0..n).map(|_| rng.uniform(0.2, 5.0)).collect();
    let mut knots = clamped_uniform_knots(n, degree);
    if repeat && n > degree + 2 {
        // Repeat one interior knot up to the degree (replacing its neighbours).
        let i = degree + 1;
        for k in 1..degree.min(n - degree - 1) {
            knots[i + k] = knots[i];
        }
    }
    NurbsCurve::new(degree, dim, &points, &weights, knots).unwrap()
}

#[cfg(test)]
mod tests;
