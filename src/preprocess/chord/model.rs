//! The chord measurement's models: the cubic Hermite profile of a piece's normal offset, which
//! steers the search for its bulges, and the checks that say when that model cannot be
//! trusted (the quintic that also matches the end curvatures departs from it, or the piece may
//! run past an end of its chord). Arithmetic on the ends' derivatives only: no curve
//! evaluation happens here.

use super::{Chord, MODEL_TRUST, Sample};
use crate::geometry::{Point, lanes, running_max};

/// The cubic Hermite model of the normal offset, `H(s) = s (1-s)² ta - s² (1-s) tb` on
/// `s ∈ [0, 1]`, sampled at eighths. Returns `|H|²` at `s = k/8`, `k = 0..=8`, from three dot
/// products: `|H|² = s²(1-s)² ((1-s)² |ta|² - 2 s (1-s) ta·tb + s² |tb|²)`.
pub(super) fn hermite_profile<const N: usize>(
    chord: &Chord<N>,
    ta: &Point,
    tb: &Point,
) -> [f64; 9] {
    let (aa, ab, bb) = (chord.dot(ta, ta), chord.dot(ta, tb), chord.dot(tb, tb));
    let mut g = [0.0; 9];
    // An index loop: the iterator form (`enumerate().take(8).skip(1)`) did not unroll and cost
    // more than the arithmetic.
    #[allow(clippy::needless_range_loop)]
    for k in 1..8 {
        let s = k as f64 / 8.0;
        let t = 1.0 - s;
        let st = s * t;
        g[k] = st * st * (t * t * aa - 2.0 * st * ab + s * s * bb);
    }
    g
}

/// Whether the cubic Hermite model of the normal offset may misplace the chord error at the
/// scale of `tol`. The end curvatures it ignores: where a quintic through them departs from the
/// cubic by a fair part of the tolerance, the piece has more going on inside than its end
/// tangents tell (a sharp turn or a wiggle between the ends). And the along-chord motion it
/// does not model at all: a piece that runs past an end of its chord and comes back.
pub(super) fn model_untrusted<const N: usize>(
    a: &Sample,
    b: &Sample,
    chord: &Chord<N>,
    ta: &Point,
    tb: &Point,
    peak: f64,
    tol: f64,
) -> bool {
    let du = b.u - a.u;
    // On a piece far over the tolerance (a segmenter's probe) the model only has to be right
    // to a fraction of its own size to say "too long".
    let scale = MODEL_TRUST * running_max(tol, peak);
    overshoots_the_chord(a, b, chord, du, MODEL_TRUST * tol)
        || model_disagreement(a, b, chord, du, ta, tb) > scale
}

/// The quintic Hermite basis at `s = k/8`, `k = 1..=7`: for the start value (unused, zero),
/// start tangent, start second derivative, end second derivative, end tangent, end value;
/// then the cubic Hermite basis for the start and end tangents.
const HERMITE_AT_EIGHTHS: [[f64; 8]; 7] = {
    let mut table = [[0.0; 8]; 7];
    let mut k = 0;
    while k < 7 {
        let s = (k + 1) as f64 / 8.0;
        let (s2, s3) = (s * s, s * s * s);
        let (s4, s5) = (s3 * s, s3 * s2);
        table[k] = [
            1.0 - 10.0 * s3 + 15.0 * s4 - 6.0 * s5,
            s - 6.0 * s3 + 8.0 * s4 - 3.0 * s5,
            0.5 * s2 - 1.5 * s3 + 1.5 * s4 - 0.5 * s5,
            0.5 * s3 - s4 + 0.5 * s5,
            -4.0 * s3 + 7.0 * s4 - 3.0 * s5,
            10.0 * s3 - 15.0 * s4 + 6.0 * s5,
            s3 - 2.0 * s2 + s,
            s3 - s2,
        ];
        k += 1;
    }
    table
};

/// The coefficients of `|D|²` at `s = k/8`, `k = 1..=7`, on the ten dot products of the four
/// vectors of [`model_disagreement`] (in the order `(0,0), (0,1), … (3,3)`): with
/// `D = Σ c_i v_i`, `|D|² = Σ_i c_i² v_i·v_i + Σ_{i<j} 2 c_i c_j v_i·v_j`. Taken once, so
/// each eighth costs ten products instead of a 4×4 quadratic form.
const DISAGREEMENT_AT_EIGHTHS: [[f64; 10]; 7] = {
    let mut table = [[0.0; 10]; 7];
    let mut k = 0;
    while k < 7 {
        let q = HERMITE_AT_EIGHTHS[k];
        let c = [q[1] - q[6], q[4] - q[7], q[2], q[3]];
        let mut n = 0;
        let mut i = 0;
        while i < 4 {
            let mut j = i;
            while j < 4 {
                table[k][n] = if i == j {
                    c[i] * c[j]
                } else {
                    2.0 * c[i] * c[j]
                };
                n += 1;
                j += 1;
            }
            i += 1;
        }
        k += 1;
    }
    table
};

/// The eighths side by side: a table's columns as rows, one lane per eighth `k = 1..=7` and
/// an eighth lane of zeros. Summed lane-wise, every eighth goes through the same operations in
/// the same order as it would alone, so the lanes are the eighths' own numbers bit for bit;
/// laid out so, the checks compile to fewer instructions than eighth by eighth (BENCHMARKS.md,
/// "`plan`'s trace rows", seventh session).
const fn by_eighth<const C: usize>(table: &[[f64; C]; 7]) -> [[f64; EIGHTHS]; C] {
    let mut out = [[0.0; EIGHTHS]; C];
    let mut k = 0;
    while k < 7 {
        let mut n = 0;
        while n < C {
            out[n][k] = table[k][n];
            n += 1;
        }
        k += 1;
    }
    out
}

/// Lanes of the eighths' rows: seven eighths and one of zeros, a whole number of vectors.
const EIGHTHS: usize = 8;

/// [`DISAGREEMENT_AT_EIGHTHS`], one row per dot product.
const DISAGREEMENT_BY_PRODUCT: [[f64; EIGHTHS]; 10] = by_eighth(&DISAGREEMENT_AT_EIGHTHS);

/// [`HERMITE_AT_EIGHTHS`], one row per basis function.
const HERMITE_BY_FUNCTION: [[f64; EIGHTHS]; 8] = by_eighth(&HERMITE_AT_EIGHTHS);

/// Largest distance, over `s = k/8`, between the cubic Hermite model of the normal offset
/// (end tangents `ta`, `tb`) and the quintic one that also matches the end second derivatives
/// (all scaled to `s ∈ [0, 1]`). Arithmetic only: no curve evaluation. The difference is
/// `D = ta·va + tb·vb + na·aa + nb·ab`, so `|D|²` comes from the ten dot products of the four
/// vectors, taken once.
fn model_disagreement<const N: usize>(
    a: &Sample,
    b: &Sample,
    chord: &Chord<N>,
    du: f64,
    ta: &Point,
    tb: &Point,
) -> f64 {
    let na = lanes::scale::<N>(&chord.perp(&a.d.d2), du * du);
    let nb = lanes::scale::<N>(&chord.perp(&b.d.d2), du * du);
    let v = [ta, tb, &na, &nb];
    let mut gram = [0.0; 10];
    let mut n = 0;
    for i in 0..4 {
        for j in i..4 {
            gram[n] = chord.dot(v[i], v[j]);
            n += 1;
        }
    }
    largest_squared_gap(&gram).max(0.0).sqrt()
}

/// The largest `|D|²` over the eighths from the ten dot products: at each eighth the products
/// times their coefficients, summed in order from `-0` as `Iterator::sum` sums them, lane by
/// lane over the eighths. A call of its own: inlined, the measurement around it compiled to
/// more instructions than the whole cost as a call.
#[inline(never)]
fn largest_squared_gap(gram: &[f64; 10]) -> f64 {
    let mut d2 = [-0.0f64; EIGHTHS];
    for (coefficients, g) in DISAGREEMENT_BY_PRODUCT.iter().zip(gram) {
        for (d, c) in d2.iter_mut().zip(coefficients) {
            *d += c * g;
        }
    }
    let mut worst: f64 = 0.0;
    for &d in &d2[..7] {
        worst = running_max(worst, d);
    }
    worst
}

/// Whether the piece may run past either end of its chord along the chord's direction (a
/// hairpin at an end: the curve overshoots the end point and comes back to it), which the
/// normal-offset models cannot see: an end tangent pointing backwards along the chord, or the
/// quintic Hermite model of the along-chord coordinate leaving `[-slack, len + slack]`.
fn overshoots_the_chord<const N: usize>(
    a: &Sample,
    b: &Sample,
    chord: &Chord<N>,
    du: f64,
    slack: f64,
) -> bool {
    let (v0, v1) = (
        chord.dot(&a.d.d1, &chord.dir) * du,
        chord.dot(&b.d.d1, &chord.dir) * du,
    );
    if v0 < 0.0 || v1 < 0.0 {
        return true;
    }
    let (a0, a1) = (
        chord.dot(&a.d.d2, &chord.dir) * du * du,
        chord.dot(&b.d.d2, &chord.dir) * du * du,
    );
    // Every lane, the eighth of zeros too (a zero is inside the range; a NaN fails both
    // comparisons, as in the seven), tested with `|`: a short-circuiting test of the seven
    // cost a branch a comparison, twice what the comparisons cost.
    let high = chord.len + slack;
    along_at_eighths(chord.len, [v0, a0, a1, v1])
        .iter()
        .fold(false, |out, &x| out | (x < -slack) | (x > high))
}

/// The quintic Hermite model of the along-chord coordinate at every eighth, from the chord's
/// length and the end derivatives along it `[v0, a0, a1, v1]`: each lane the sum
/// `len q5 + v0 q1 + a0 q2 + a1 q3 + v1 q4`, in that order.
#[inline]
fn along_at_eighths(len: f64, [v0, a0, a1, v1]: [f64; 4]) -> [f64; EIGHTHS] {
    let q = &HERMITE_BY_FUNCTION;
    let mut x = [0.0f64; EIGHTHS];
    for (k, x) in x.iter_mut().enumerate() {
        *x = len * q[5][k] + v0 * q[1][k] + a0 * q[2][k] + a1 * q[3][k] + v1 * q[4][k];
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eighths_side_by_side_are_each_eighths_own_numbers() {
        // Eighth by eighth, as the checks were first written: the lanes must be these numbers
        // bit for bit (a different order of the sums would round differently).
        let mut rng = crate::rng::SplitMix64::new(23);
        let mut value = || {
            let magnitude = 10f64.powf(rng.uniform(-9.0, 3.0));
            if rng.below(2) == 0 {
                magnitude
            } else {
                -magnitude
            }
        };
        for _ in 0..20_000 {
            let gram: [f64; 10] = std::array::from_fn(|_| value());
            let mut worst: f64 = 0.0;
            for coefficients in &DISAGREEMENT_AT_EIGHTHS {
                let d2: f64 = coefficients.iter().zip(&gram).map(|(c, g)| c * g).sum();
                worst = worst.max(d2);
            }
            assert_eq!(
                largest_squared_gap(&gram).to_bits(),
                worst.to_bits(),
                "{gram:?}"
            );

            let (len, ends) = (value().abs(), [value(), value(), value(), value()]);
            let [v0, a0, a1, v1] = ends;
            let lanes = along_at_eighths(len, ends);
            for (k, q) in HERMITE_AT_EIGHTHS.iter().enumerate() {
                let x = len * q[5] + v0 * q[1] + a0 * q[2] + a1 * q[3] + v1 * q[4];
                assert_eq!(
                    lanes[k].to_bits(),
                    x.to_bits(),
                    "eighth {k}: {len} {ends:?}"
                );
            }
        }
    }

    #[test]
    fn disagreement_is_the_largest_gap_between_the_two_models() {
        // Straight from the definition: at each eighth, the quintic Hermite model of the
        // normal offset minus the cubic one, as a vector, and its length. On an arc: a
        // polynomial cubic's normal offset is a cubic, where the two models agree exactly.
        let c = crate::geometry::semicircle();
        let mut rng = crate::rng::SplitMix64::new(11);
        let mut measurable = 0;
        for _ in 0..200 {
            let a = rng.uniform(0.0, 0.9);
            let b = (a + rng.uniform(0.001, 0.5)).min(1.0);
            let (sa, sb) = (Sample::at(&c, a), Sample::at(&c, b));
            let chord = Chord::<3>::new(sa.d.point, sb.d.point);
            let du = b - a;
            let ta = chord.perp(&sa.d.d1) * du;
            let tb = chord.perp(&sb.d.d1) * du;
            let na = chord.perp(&sa.d.d2) * (du * du);
            let nb = chord.perp(&sb.d.d2) * (du * du);
            let direct = HERMITE_AT_EIGHTHS
                .iter()
                .map(|q| {
                    let quintic = ta * q[1] + na * q[2] + nb * q[3] + tb * q[4];
                    let cubic = ta * q[6] + tb * q[7];
                    (quintic - cubic).norm()
                })
                .fold(0.0, f64::max);
            let table = model_disagreement(&sa, &sb, &chord, du, &ta, &tb);
            // Squares from dot products cancel where the gap is small against the vectors:
            // compare at the vectors' scale.
            let scale = ta.norm() + tb.norm() + na.norm() + nb.norm();
            assert!(
                (table * table - direct * direct).abs() <= 1e-12 * scale * scale,
                "[{a},{b}]: {table} vs {direct}"
            );
            if direct > 1e-6 * scale {
                measurable += 1;
            }
        }
        // Most pieces are long enough for the models to part (not a test of zeros).
        assert!(measurable > 100, "{measurable} of 200");
    }
}
