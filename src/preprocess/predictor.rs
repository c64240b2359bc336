//! Parameter predictors: where on the curve does the next step of length `L` end?
//!
//! Both return a parameter *increment* from the current point and never evaluate the curve.
//!
//! - [`taylor_increment`]: the second-order Taylor update of seed 000 eq. 16 in its corrected
//!   form (errata): `Δu = L/|C'| - L² (C'·C'') / (2 |C'|⁴)`. It is the arc-length expansion of
//!   `u(s)`, so it is right for any feed profile as long as `L` is the distance the profile covers
//!   in the step (`v T + a T²/2` under acceleration), not `v T`.
//! - [`hamming_increment`]: seed 001 eqs. 12–13, extrapolating the last three *corrected*
//!   parameters of equally timed steps. Feeding raw predictions back would make it a pure
//!   extrapolator, which drifts off the curve's length scale within a few steps.

use super::chord::Sample;

/// `Δu` for a step of length `len` from `a` (corrected second-order Taylor update). Falls back to
/// the first-order term where the second-order one would turn the step backwards, and returns
/// `None` where the curve has no speed (a cusp in the parametrisation).
pub fn taylor_increment(a: &Sample, len: f64) -> Option<f64> {
    let d1 = &a.d.d1;
    let speed_sq = d1.norm_squared();
    if speed_sq <= 0.0 || !speed_sq.is_finite() {
        return None;
    }
    let speed = speed_sq.sqrt();
    let first = len / speed;
    let second = -len * len * d1.dot(&a.d.d2) / (2.0 * speed_sq * speed_sq);
    let du = first + second;
    // Far beyond the Taylor radius the correction can exceed the first-order term.
    Some(if du > 0.25 * first && du.is_finite() {
        du
    } else {
        first
    })
}

/// The two Hamming predictions (seed 001 eqs. 12 and 13, errata), as increments from `u[2]`,
/// given the last three corrected parameters `u = [u_{i-2}, u_{i-1}, u_i]` of equally timed steps.
pub fn hamming_increments(u: [f64; 3]) -> (f64, f64) {
    let [u2, u1, u0] = u;
    let first = 3.0 * u0 - 3.0 * u1 + u2;
    let second = (9.0 * u0 - 3.0 * u1 - u2) / 5.0;
    (first - u0, second - u0)
}

/// History of corrected parameters for the Hamming predictor, reset at every piece start.
#[derive(Debug, Clone, Copy, Default)]
pub struct History {
    u: [f64; 3],
    len: usize,
}

impl History {
    pub fn reset(&mut self) {
        self.len = 0;
    }

    /// Records a corrected parameter (never a raw prediction).
    pub fn push(&mut self, u: f64) {
        self.u = [self.u[1], self.u[2], u];
        self.len = (self.len + 1).min(3);
    }

    /// The last three parameters, once there are three.
    pub fn full(&self) -> Option<[f64; 3]> {
        (self.len == 3).then_some(self.u)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{NurbsCurve, circular_arc, point};

    #[test]
    fn taylor_is_second_order_accurate_on_a_non_arc_length_parametrisation() {
        // A parabola y = x² parametrised by x: the speed varies, so the second-order term matters.
        let c = NurbsCurve::new(
            2,
            2,
            &[point(&[-1.0, 1.0]), point(&[0.0, -1.0]), point(&[1.0, 1.0])],
            &[1.0; 3],
            vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0],
        )
        .unwrap();
        let a = Sample::at(&c, 0.3);
        let mut errors = vec![];
        for &len in &[0.02, 0.01] {
            let du = taylor_increment(&a, len).unwrap();
            let got = c.length_between(0.3, 0.3 + du);
            errors.push((got - len).abs());
        }
        // Third-order error: halving the step divides it by about 8.
        let ratio = errors[0] / errors[1];
        assert!(
            (6.0..10.0).contains(&ratio),
            "ratio {ratio}, errors {errors:?}"
        );
        // The printed form (|C''| / |C'|³, no 1/2) is much worse at the same step.
        let d = c.derivs(0.3);
        let s = d.d1.norm();
        let printed = 0.02 / s - 0.02 * 0.02 * d.d2.norm() / (s * s * s);
        let printed_err = (c.length_between(0.3, 0.3 + printed) - 0.02).abs();
        assert!(
            printed_err > 20.0 * errors[0],
            "{printed_err} vs {}",
            errors[0]
        );
    }

    #[test]
    fn taylor_is_exact_on_a_circle_to_first_order_and_refuses_zero_speed() {
        let arc = circular_arc(
            2,
            [0, 1],
            &point(&[0.0, 0.0]),
            &point(&[5.0, 0.0]),
            &point(&[0.0, 5.0]),
            std::f64::consts::FRAC_PI_2,
        )
        .unwrap();
        let a = Sample::at(&arc, 0.1);
        let du = taylor_increment(&a, 0.01).unwrap();
        let got = arc.length_between(0.1, 0.1 + du);
        assert!((got - 0.01).abs() < 1e-8, "{got}");
        let mut flat = a;
        flat.d.d1 = point(&[0.0, 0.0]);
        assert_eq!(taylor_increment(&flat, 0.01), None);
    }

    #[test]
    fn hamming_extrapolates_a_quadratic_exactly() {
        let u = |i: f64| 0.1 + 0.02 * i + 0.001 * i * i;
        let (d1, _) = hamming_increments([u(0.0), u(1.0), u(2.0)]);
        assert!((u(2.0) + d1 - u(3.0)).abs() < 1e-15);
        let mut h = History::default();
        h.push(1.0);
        h.push(2.0);
        assert_eq!(h.full(), None);
        h.push(3.0);
        h.push(4.0);
        assert_eq!(h.full(), Some([2.0, 3.0, 4.0]));
        h.reset();
        assert_eq!(h.full(), None);
    }
}
