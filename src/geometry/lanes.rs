//! Vector arithmetic on the first `N` coordinates of a [`Point`], the rest being zero: a
//! three-axis curve's chord measurement, step ends and bound samples work on three numbers
//! where a `Point` holds six. The all-axis forms are the same functions at `N = MAX_AXES`.
//!
//! Bit for bit nalgebra's on the whole point, which is what keeps every segment where it was:
//! nalgebra sums a six-wide dot product in order from `+0` (its unrolled loop starts at eight),
//! and the terms past `N` are `±0`, which leave such a sum as it is. The component-wise
//! operations leave `+0` past `N`, where nalgebra's may give `-0` (a zero times a negative
//! factor): the same number, and one no sum here can tell apart; with the positive factors
//! the measurement uses (a parameter step, a chord length) it is `+0` there too.
//!
//! Must never: hold state, or compute anything nalgebra would round differently.

use super::{CurveDerivs, Point};

#[inline(always)]
pub fn dot<const N: usize>(a: &Point, b: &Point) -> f64 {
    let mut sum = 0.0;
    for i in 0..N {
        sum += a[i] * b[i];
    }
    sum
}

#[inline(always)]
pub fn norm<const N: usize>(a: &Point) -> f64 {
    dot::<N>(a, a).sqrt()
}

/// `a - b`.
#[inline(always)]
pub fn sub<const N: usize>(a: &Point, b: &Point) -> Point {
    let mut out = Point::zeros();
    for i in 0..N {
        out[i] = a[i] - b[i];
    }
    out
}

/// `a - b * k`.
#[inline(always)]
pub fn sub_scaled<const N: usize>(a: &Point, b: &Point, k: f64) -> Point {
    let mut out = Point::zeros();
    for i in 0..N {
        out[i] = a[i] - b[i] * k;
    }
    out
}

/// `a * k`.
#[inline(always)]
pub fn scale<const N: usize>(a: &Point, k: f64) -> Point {
    let mut out = Point::zeros();
    for i in 0..N {
        out[i] = a[i] * k;
    }
    out
}

/// `a / k`.
#[inline(always)]
pub fn div<const N: usize>(a: &Point, k: f64) -> Point {
    let mut out = Point::zeros();
    for i in 0..N {
        out[i] = a[i] / k;
    }
    out
}

/// `v / |v|`, zero staying zero.
#[inline(always)]
pub fn unit<const N: usize>(v: &Point) -> Point {
    let n = norm::<N>(v);
    if n > 0.0 { div::<N>(v, n) } else { *v }
}

/// The radius of curvature `|C'|³ / |C' × C''|`, as `|C'|² / |C''⊥|` with `C''⊥` the part of
/// `C''` normal to `C'` (`|C' × C''| = |C'| |C''⊥|`): zero where the curve stops, infinite
/// where it runs straight. [`CurveDerivs::curvature_radius`] is this on every axis.
#[inline(always)]
pub fn curvature_radius<const N: usize>(d: &CurveDerivs) -> f64 {
    let (a, b) = (&d.d1, &d.d2);
    let speed_sq = dot::<N>(a, a);
    if speed_sq == 0.0 {
        return 0.0;
    }
    let normal_norm = norm::<N>(&sub_scaled::<N>(b, a, dot::<N>(a, b) / speed_sq));
    if normal_norm == 0.0 {
        f64::INFINITY
    } else {
        speed_sq / normal_norm
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// A point of three axes in a six-wide `Point`, some coordinates negative zero or zero.
    fn three_axes(rng: &mut SplitMix64) -> Point {
        let mut p = Point::zeros();
        for slot in p.iter_mut().take(3) {
            *slot = match rng.next_u64() % 8 {
                0 => -0.0,
                1 => 0.0,
                _ => rng.uniform(-100.0, 100.0),
            };
        }
        p
    }

    /// The radius of curvature in nalgebra's whole-point arithmetic.
    fn nalgebra_radius(a: &Point, b: &Point) -> f64 {
        let speed_sq = a.norm_squared();
        if speed_sq == 0.0 {
            return 0.0;
        }
        let normal_norm = (b - a * (a.dot(b) / speed_sq)).norm();
        if normal_norm == 0.0 {
            f64::INFINITY
        } else {
            speed_sq / normal_norm
        }
    }

    #[test]
    fn three_lanes_are_nalgebras_six_bit_for_bit() {
        let mut rng = SplitMix64::new(3);
        for _ in 0..100_000 {
            let (a, b) = (three_axes(&mut rng), three_axes(&mut rng));
            let k = rng.uniform(-10.0, 10.0);
            assert_eq!(dot::<3>(&a, &b).to_bits(), a.dot(&b).to_bits());
            assert_eq!(norm::<3>(&a).to_bits(), a.norm().to_bits());
            let mut pairs = vec![
                (sub::<3>(&a, &b), a - b),
                (sub_scaled::<3>(&a, &b, k), a - b * k),
                (scale::<3>(&a, k), a * k),
            ];
            if k != 0.0 {
                pairs.push((div::<3>(&a, k), a / k));
            }
            for (mine, theirs) in pairs {
                // The lanes bit for bit, zeros past them (nalgebra's may be -0 there).
                for i in 0..3 {
                    assert_eq!(mine[i].to_bits(), theirs[i].to_bits());
                }
                for i in 3..6 {
                    assert_eq!((mine[i].to_bits(), theirs[i]), (0, 0.0));
                }
                // And any dot product they enter is the same to the bit.
                assert_eq!(dot::<3>(&mine, &b).to_bits(), theirs.dot(&b).to_bits());
            }
            // The vector helpers on three lanes against nalgebra's formulas on all six.
            let d = assert_helpers_are_nalgebras::<3>(&a, &b);
            assert_eq!(
                curvature_radius::<3>(&d).to_bits(),
                d.curvature_radius().to_bits()
            );
        }
        // A straight piece: no curvature, an infinite radius either way.
        let d = CurveDerivs {
            point: Point::zeros(),
            d1: three_axes(&mut rng),
            d2: Point::zeros(),
        };
        assert_eq!(curvature_radius::<3>(&d), d.curvature_radius());
    }

    /// On all six lanes the helpers are nalgebra's own formulas, bit for bit: what the
    /// all-axis callers (`unit`, `CurveDerivs::curvature_radius`) used before they came here.
    #[test]
    fn six_lanes_are_nalgebras_formulas_bit_for_bit() {
        let mut rng = SplitMix64::new(6);
        let six = |rng: &mut SplitMix64| {
            let mut p = Point::zeros();
            for slot in p.iter_mut() {
                *slot = match rng.next_u64() % 8 {
                    0 => -0.0,
                    1 => 0.0,
                    _ => rng.uniform(-100.0, 100.0),
                };
            }
            p
        };
        for _ in 0..100_000 {
            let (a, b) = (six(&mut rng), six(&mut rng));
            assert_helpers_are_nalgebras::<6>(&a, &b);
        }
    }

    /// `unit` of `a` and the radius of curvature of `C' = a`, `C'' = b` on `N` lanes, bit for
    /// bit nalgebra's formulas on the whole `Point`; returns those derivatives.
    fn assert_helpers_are_nalgebras<const N: usize>(a: &Point, b: &Point) -> CurveDerivs {
        let n = a.norm();
        let theirs = if n > 0.0 { a / n } else { *a };
        assert_eq!(unit::<N>(a).map(f64::to_bits), theirs.map(f64::to_bits));
        let d = CurveDerivs {
            point: Point::zeros(),
            d1: *a,
            d2: *b,
        };
        assert_eq!(
            curvature_radius::<N>(&d).to_bits(),
            nalgebra_radius(a, b).to_bits()
        );
        d
    }
}
