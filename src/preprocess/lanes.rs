//! Vector arithmetic on the first `N` coordinates of a [`Point`], the rest being zero: a
//! three-axis curve's measurement works on three numbers where a `Point` holds six.
//!
//! Bit for bit nalgebra's on the whole point, which is what keeps every segment where it was:
//! nalgebra sums a six-wide dot product in order from `+0` (its unrolled loop starts at eight),
//! and the terms past `N` are `±0`, which leave such a sum as it is. The component-wise
//! operations leave `+0` past `N`, where nalgebra's may give `-0` (a zero times a negative
//! factor): the same number, and one no sum here can tell apart; with the positive factors
//! the measurement uses (a parameter step, a chord length) it is `+0` there too.
//!
//! Must never: hold state, or compute anything nalgebra would round differently.

use crate::geometry::Point;

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
        }
    }
}
