//! Circular arcs as exact rational quadratic NURBS (The NURBS Book, A7.1).
//!
//! An arc of sweep `theta` is split into `ceil(|theta| / 90°)` equal pieces. Each piece is a
//! rational quadratic Bézier whose middle control point is the intersection of the end tangents,
//! `r / cos(d/2)` from the centre, with weight `cos(d/2)`. The result lies exactly on the circle,
//! so an arc goes through the same segmenter and chord-error guarantee as any other curve.

use std::f64::consts::FRAC_PI_2;

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
