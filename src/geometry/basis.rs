//! B-spline basis functions and their derivatives (The NURBS Book, A2.1 and A2.3).
//!
//! Everything here works on caller-provided fixed-size arrays sized for [`MAX_DEGREE`], so an
//! evaluation never touches the heap. The knot vector is assumed validated (see
//! [`super::NurbsCurve::new`]): clamped, non-decreasing, interior multiplicity at most the degree.

use super::MAX_DEGREE;

/// Number of basis functions that are non-zero on one knot span, at the highest degree.
pub const MAX_ORDER: usize = MAX_DEGREE + 1;

/// Index `i` of the knot span `[knots[i], knots[i+1])` that holds `u` (A2.1, binary search).
///
/// `n` is the index of the last control point. `u` is clamped to the curve's parameter range;
/// at the upper end the last non-empty span is returned, so that `u = u_max` evaluates the end
/// point instead of falling off the knot vector.
///
/// Inside the range only one non-empty span holds `u`, so a walk up the knots and the binary
/// search find the same one. The walk is taken on curves of at most [`WALK_SPANS`] spans (an
/// arc has one to four): it computes no midpoints, and on so few spans it reads about as
/// many knots as the search.
#[inline(always)]
pub(crate) fn find_span(n: usize, degree: usize, knots: &[f64], u: f64) -> usize {
    if u >= knots[n + 1] {
        // Last non-empty span: validation guarantees knots[n] < knots[n + 1].
        return n;
    }
    if u <= knots[degree] {
        return degree;
    }
    if n - degree < WALK_SPANS {
        // knots[degree] < u < knots[n + 1]: the first span whose end lies beyond `u` holds it.
        let mut span = degree;
        while u >= knots[span + 1] {
            span += 1;
        }
        return span;
    }
    search_span(n, degree, knots, u)
}

/// Curves of at most this many knot spans find theirs by walking up the knots.
const WALK_SPANS: usize = 8;

/// [`find_span`]'s binary search, for `knots[degree] < u < knots[n + 1]`. A call of its own,
/// so that the walk stays small enough to inline into every evaluation.
#[inline(never)]
fn search_span(n: usize, degree: usize, knots: &[f64], u: f64) -> usize {
    let (mut low, mut high) = (degree, n + 1);
    let mut mid = (low + high) / 2;
    while u < knots[mid] || u >= knots[mid + 1] {
        if u < knots[mid] {
            high = mid;
        } else {
            low = mid;
        }
        mid = (low + high) / 2;
    }
    mid
}

/// Values and first two derivatives of the `degree + 1` basis functions that are non-zero on
/// span `span` at `u`.
///
/// On return `ders[k][j]` is the k-th derivative of `N_{span-degree+j, degree}(u)`. Rows above
/// the degree (the second derivative of a degree-1 basis) are zero.
///
/// The values come from the triangular recurrence of A2.2. The derivatives use the degree-lowering
/// identity `N'_{i,p} = p (N_{i,p-1} / (u_{i+p} - u_i) - N_{i+1,p-1} / (u_{i+p+1} - u_{i+1}))`
/// applied once on the degree `p - 1` values and twice on the degree `p - 2` values, which are
/// byproducts of the same recurrence. This is A2.3 specialised to two derivatives without its
/// general coefficient table: same numbers, a fraction of the work. Every denominator spans the
/// non-empty span `[u_span, u_{span+1})`, so none is zero.
#[inline(always)]
pub(crate) fn basis_derivs(
    span: usize,
    u: f64,
    degree: usize,
    knots: &[f64],
    ders: &mut [[f64; MAX_ORDER]; 3],
) {
    basis_derivs_to::<true>(span, u, degree, knots, ders);
}

/// [`basis_derivs`] with the second derivatives only if `SECOND` (row 2 is left as it was
/// otherwise): an arc length needs the speed alone.
#[inline(always)]
pub(crate) fn basis_derivs_to<const SECOND: bool>(
    span: usize,
    u: f64,
    degree: usize,
    knots: &[f64],
    ders: &mut [[f64; MAX_ORDER]; 3],
) {
    let p = degree;
    // The 2p knots the basis on `span` reads, `k[i] = knots[span + 1 - p + i]`, taken once:
    // with the degree a constant, every index below is then known to be in range.
    let k = &knots[span + 1 - p..=span + p];
    let mut left = [0.0f64; MAX_ORDER];
    let mut right = [0.0f64; MAX_ORDER];
    // `values[r]` = N_{span-j+r, j} after step j; `lower1`/`lower2` keep degrees p-1 and p-2.
    let mut values = [0.0f64; MAX_ORDER];
    let mut lower1 = [0.0f64; MAX_ORDER];
    let mut lower2 = [0.0f64; MAX_ORDER];
    values[0] = 1.0;
    for j in 1..=p {
        if j + 1 == p {
            lower2 = values;
        }
        if j == p {
            lower1 = values;
        }
        left[j] = u - k[p - j];
        right[j] = k[p - 1 + j] - u;
        let mut saved = 0.0;
        for r in 0..j {
            let temp = values[r] / (right[r + 1] + left[j - r]);
            values[r] = saved + right[r + 1] * temp;
            saved = left[j - r] * temp;
        }
        values[j] = saved;
    }
    ders[0][..=p].copy_from_slice(&values[..=p]);

    // Degree p-1 basis over its knot span length: c[r] = N_{span-p+1+r, p-1} / D[r],
    // D[r] = u_{span+r+1} - u_{span-p+1+r}.
    let pf = p as f64;
    let mut inv_d = [0.0f64; MAX_ORDER];
    let mut c = [0.0f64; MAX_ORDER + 1];
    for r in 0..p {
        inv_d[r] = 1.0 / (k[p + r] - k[r]);
        c[r + 1] = lower1[r] * inv_d[r];
    }
    // c[0] and c[p + 1] stand for the zero neighbours outside the support.
    for j in 0..=p {
        ders[1][j] = pf * (c[j] - c[j + 1]);
    }
    if !SECOND {
        return;
    }
    if p < 2 {
        ders[2][..=p].fill(0.0);
        return;
    }
    // First derivatives of the degree p-1 basis, from the degree p-2 values.
    let mut c2 = [0.0f64; MAX_ORDER + 1];
    for q in 0..p - 1 {
        c2[q + 1] = lower2[q] / (k[p + q] - k[q + 1]);
    }
    // e[r + 1] = N'_{span-p+1+r, p-1} / D[r], with zero neighbours at e[0] and e[p + 1].
    let mut e = [0.0f64; MAX_ORDER + 1];
    let pm1 = (p - 1) as f64;
    for r in 0..p {
        e[r + 1] = pm1 * (c2[r] - c2[r + 1]) * inv_d[r];
    }
    for j in 0..=p {
        ders[2][j] = pf * (e[j] - e[j + 1]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn span_search_handles_ends_and_multiple_knots() {
        // Cubic, 7 points, knots with a double interior knot at 0.5.
        let knots = [0.0, 0.0, 0.0, 0.0, 0.25, 0.5, 0.5, 1.0, 1.0, 1.0, 1.0];
        let n = 6;
        assert_eq!(find_span(n, 3, &knots, 0.0), 3);
        assert_eq!(find_span(n, 3, &knots, 0.1), 3);
        assert_eq!(find_span(n, 3, &knots, 0.25), 4);
        assert_eq!(find_span(n, 3, &knots, 0.49), 4);
        assert_eq!(find_span(n, 3, &knots, 0.5), 6);
        assert_eq!(find_span(n, 3, &knots, 0.9), 6);
        assert_eq!(find_span(n, 3, &knots, 1.0), 6);
        assert_eq!(find_span(n, 3, &knots, 7.0), 6);
        assert_eq!(find_span(n, 3, &knots, -1.0), 3);
    }

    #[test]
    fn the_walk_finds_the_span_the_search_finds() {
        // Knot vectors of one to eight spans, with double knots, and parameters on and between
        // their knots: the walk (taken up to WALK_SPANS spans) against the binary search.
        let mut rng = crate::rng::SplitMix64::new(7);
        for case in 0..2000 {
            let degree = 1 + case % 3;
            let mut knots = vec![0.0; degree + 1];
            let mut k = 0.0;
            // Interior knots, a double one now and then: fewer than WALK_SPANS, so at most
            // WALK_SPANS spans.
            let interior = rng.below(WALK_SPANS);
            while knots.len() < degree + 1 + interior {
                k += 0.25 * (1 + rng.below(4)) as f64;
                knots.push(k);
                if rng.below(3) == 0 && degree > 1 && knots.len() < degree + 1 + interior {
                    knots.push(k);
                }
            }
            k += 1.0;
            knots.extend(std::iter::repeat_n(k, degree + 1));
            let n = knots.len() - degree - 2;
            assert!(n - degree < WALK_SPANS);
            for step in 0..=(8.0 * k) as usize {
                let u = step as f64 / 8.0;
                let walked = find_span(n, degree, &knots, u);
                if u > knots[degree] && u < knots[n + 1] {
                    assert_eq!(
                        walked,
                        search_span(n, degree, &knots, u),
                        "{knots:?} at {u}"
                    );
                }
                assert!(
                    knots[walked] <= u.max(0.0) && walked <= n,
                    "{knots:?} at {u}"
                );
            }
        }
    }

    #[test]
    fn basis_is_a_partition_of_unity_with_zero_derivative_sums() {
        let knots = [0.0, 0.0, 0.0, 0.0, 0.3, 0.5, 0.5, 0.8, 1.0, 1.0, 1.0, 1.0];
        let n = 7;
        let mut ders = [[0.0; MAX_ORDER]; 3];
        for step in 0..=100 {
            let u = step as f64 / 100.0;
            let span = find_span(n, 3, &knots, u);
            basis_derivs(span, u, 3, &knots, &mut ders);
            let sums: Vec<f64> = ders.iter().map(|r| r[..4].iter().sum()).collect();
            assert!((sums[0] - 1.0).abs() < 1e-14, "u={u} sum={}", sums[0]);
            assert!(sums[1].abs() < 1e-11, "u={u} d1 sum={}", sums[1]);
            assert!(sums[2].abs() < 1e-9, "u={u} d2 sum={}", sums[2]);
        }
    }

    #[test]
    fn degree_one_has_no_second_derivative() {
        let knots = [0.0, 0.0, 1.0, 1.0];
        let mut ders = [[7.0; MAX_ORDER]; 3];
        basis_derivs(1, 0.25, 1, &knots, &mut ders);
        assert_eq!(&ders[0][..2], &[0.75, 0.25]);
        assert_eq!(&ders[1][..2], &[-1.0, 1.0]);
        assert_eq!(&ders[2][..2], &[0.0, 0.0]);
    }
}
