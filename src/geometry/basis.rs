//! B-spline basis functions and their derivatives (The NURBS Book, A2.1 and A2.3).
//!
//! Everything here works on caller-provided fixed-size arrays sized for [`MAX_DEGREE`], so an
//! evaluation never touches the heap. The knot vector is assumed validated (see
//! [`super::NurbsCurve::new`]): clamped, non-decreasing, interior multiplicity at most the degree.

use super::MAX_DEGREE;

/// Number of basis functions that are non-zero on one knot span, at the highest degree.
pub(crate) const MAX_ORDER: usize = MAX_DEGREE + 1;

/// Index `i` of the knot span `[knots[i], knots[i+1])` that holds `u` (A2.1, binary search).
///
/// `n` is the index of the last control point. `u` is clamped to the curve's parameter range;
/// at the upper end the last non-empty span is returned, so that `u = u_max` evaluates the end
/// point instead of falling off the knot vector.
#[inline]
pub(crate) fn find_span(n: usize, degree: usize, knots: &[f64], u: f64) -> usize {
    if u >= knots[n + 1] {
        // Last non-empty span: validation guarantees knots[n] < knots[n + 1].
        return n;
    }
    if u <= knots[degree] {
        return degree;
    }
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
/// span `span` at `u` (A2.3 specialised to two derivatives).
///
/// On return `ders[k][j]` is the k-th derivative of `N_{span-degree+j, degree}(u)`. Rows above
/// the degree (the second derivative of a degree-1 basis) are zero.
#[inline]
pub(crate) fn basis_derivs(
    span: usize,
    u: f64,
    degree: usize,
    knots: &[f64],
    ders: &mut [[f64; MAX_ORDER]; 3],
) {
    let p = degree;
    // ndu holds the basis functions (upper triangle) and the knot differences (lower triangle).
    let mut ndu = [[0.0f64; MAX_ORDER]; MAX_ORDER];
    let mut left = [0.0f64; MAX_ORDER];
    let mut right = [0.0f64; MAX_ORDER];
    ndu[0][0] = 1.0;
    for j in 1..=p {
        left[j] = u - knots[span + 1 - j];
        right[j] = knots[span + j] - u;
        let mut saved = 0.0;
        for r in 0..j {
            ndu[j][r] = right[r + 1] + left[j - r];
            let temp = ndu[r][j - 1] / ndu[j][r];
            ndu[r][j] = saved + right[r + 1] * temp;
            saved = left[j - r] * temp;
        }
        ndu[j][j] = saved;
    }
    for j in 0..=p {
        ders[0][j] = ndu[j][p];
    }
    let nd = p.min(2);
    for row in ders.iter_mut().skip(nd + 1) {
        row[..=p].fill(0.0);
    }
    if nd == 0 {
        return;
    }
    // Derivatives: a[s][j] are the coefficients of the k-th difference (two alternating rows).
    let mut a = [[0.0f64; MAX_ORDER]; 2];
    for r in 0..=p {
        let (mut s1, mut s2) = (0usize, 1usize);
        a[0][0] = 1.0;
        for k in 1..=nd {
            let mut d = 0.0;
            let rk = r as isize - k as isize;
            let pk = p - k;
            if r >= k {
                let rk = rk as usize;
                a[s2][0] = safe_div(a[s1][0], ndu[pk + 1][rk]);
                d = a[s2][0] * ndu[rk][pk];
            }
            let j1 = if rk >= -1 { 1 } else { (-rk) as usize };
            let j2 = if r as isize - 1 <= pk as isize {
                k - 1
            } else {
                p - r
            };
            for j in j1..=j2 {
                let idx = (rk + j as isize) as usize;
                a[s2][j] = safe_div(a[s1][j] - a[s1][j - 1], ndu[pk + 1][idx]);
                d += a[s2][j] * ndu[idx][pk];
            }
            if r <= pk {
                a[s2][k] = safe_div(-a[s1][k - 1], ndu[pk + 1][r]);
                d += a[s2][k] * ndu[r][pk];
            }
            ders[k][r] = d;
            std::mem::swap(&mut s1, &mut s2);
        }
    }
    // Multiply by p!/(p-k)!.
    let mut factor = p as f64;
    for row in ders.iter_mut().take(nd + 1).skip(1) {
        for v in row.iter_mut().take(p + 1) {
            *v *= factor;
        }
        factor *= (p - 1) as f64;
    }
}

/// Division with the Cox–de Boor convention `x / 0 := 0` (a zero-length knot interval
/// contributes nothing).
#[inline]
fn safe_div(num: f64, den: f64) -> f64 {
    if den == 0.0 { 0.0 } else { num / den }
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
