//! The true chord error of a curve piece: the largest distance between the curve and the
//! straight segment that replaces it.
//!
//! The papers estimate it: seed 000 from the radius of curvature at the start (the circle
//! formula), seed 001 eq. 6 as the distance between the chord midpoint and the curve point at
//! the mid-parameter. Both are wrong where it matters: the mid-parameter is not the farthest
//! point when the parametrisation drifts tangentially, and near an inflection the curve crosses
//! its chord, so the midpoint can sit on the chord while the two bulges are out of tolerance.
//!
//! [`chord_error`] finds the maximum instead. The normal offset `r⊥(u)` of the curve from the
//! chord line vanishes at both ends and its derivative there is the tangent's normal component,
//! which the segmenter already has. A cubic Hermite model of `r⊥` on the piece therefore costs no
//! evaluation and shows where the bulges are (one bulge on a convex piece, two across an
//! inflection). Each bulge is then polished on the true curve by Newton's method on
//! `f(u) = |r⊥(u)|²`, whose first and second derivatives come from `C'` and `C''`:
//! `f'/2 = r⊥·C'` and `f''/2 = |C'⊥|² + r⊥·C''`. Near a maximum Newton converges quadratically,
//! so one or two evaluations per bulge usually give the maximum to many digits; the last Newton
//! step's quadratic model supplies the value at the maximum itself. When the model and the
//! curve disagree (near-cusps, pieces whose end tangents say little about their middle) the
//! bulges are found by sampling instead.

use crate::geometry::{CurveDerivs, NurbsCurve, Point, lanes, running_min};

mod model;

use model::{hermite_profile, model_untrusted};

/// A point of a curve with its derivatives: the unit of work the segmenter passes around.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    pub u: f64,
    pub d: CurveDerivs,
}

impl Sample {
    pub fn at(curve: &NurbsCurve, u: f64) -> Sample {
        Sample {
            u,
            d: curve.derivs(u),
        }
    }
}

/// The longest chord whose sagitta on a circle of radius `rho` is `tol`:
/// `2 sqrt(2 rho tol - tol²)` (errata), at most the diameter; infinite on a straight stretch.
pub fn chord_length_limit(rho: f64, tol: f64) -> f64 {
    if !rho.is_finite() {
        f64::INFINITY
    } else if tol >= rho {
        2.0 * rho
    } else {
        2.0 * (2.0 * rho * tol - tol * tol).sqrt()
    }
}

/// Result of [`chord_error`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChordError {
    /// Largest distance from the curve piece to its chord (mm).
    pub max: f64,
    /// The curve parameter where that distance was found (NaN when nothing was measured):
    /// where a certificate splits first ([`certify`](super::certify)).
    pub at: f64,
    /// Smallest radius of curvature seen at the interior points evaluated (mm).
    pub rho_min: f64,
    /// Curve evaluations spent.
    pub evals: u32,
}

impl ChordError {
    /// A distance found at parameter `u`: kept if it is the largest so far.
    #[inline]
    fn note(&mut self, distance: f64, u: f64) {
        if distance > self.max {
            self.max = distance;
            self.at = u;
        }
    }
}

/// Newton iterations per bulge before settling for the largest value seen.
const MAX_NEWTON: u32 = 4;
/// A Newton step smaller than this fraction of the piece means we are at the maximum.
const NEWTON_DONE: f64 = 2e-3;
/// Largest disagreement between the cubic and quintic models, as a fraction of the tolerance,
/// under which the cubic model steers the search.
const MODEL_TRUST: f64 = 0.25;
/// Golden-section steps refining the best sample of the fallback (each shrinks the bracket of
/// two sample spacings by 0.618: 16 leave 1/1000 of it).
const GOLDEN_STEPS: u32 = 16;
/// Samples when the Hermite model cannot be trusted.
const FALLBACK_SAMPLES: usize = 24;

/// The chord line of a piece and the helpers to measure against it, on the first `N`
/// coordinates ([`lanes`]).
struct Chord<const N: usize> {
    start: Point,
    end: Point,
    dir: Point,
    len: f64,
}

impl<const N: usize> Chord<N> {
    fn new(start: Point, end: Point) -> Chord<N> {
        let v = lanes::sub::<N>(&end, &start);
        let len = lanes::norm::<N>(&v);
        Chord {
            start,
            end,
            dir: if len > 0.0 {
                lanes::div::<N>(&v, len)
            } else {
                Point::zeros()
            },
            len,
        }
    }

    fn perp(&self, v: &Point) -> Point {
        lanes::sub_scaled::<N>(v, &self.dir, lanes::dot::<N>(v, &self.dir))
    }

    fn dot(&self, a: &Point, b: &Point) -> f64 {
        lanes::dot::<N>(a, b)
    }

    /// Distance from `p` to the chord segment (not just its line).
    fn distance(&self, p: &Point) -> f64 {
        let r = lanes::sub::<N>(p, &self.start);
        let along = lanes::dot::<N>(&r, &self.dir);
        if along <= 0.0 {
            lanes::norm::<N>(&r)
        } else if along >= self.len {
            lanes::norm::<N>(&lanes::sub::<N>(p, &self.end))
        } else {
            lanes::norm::<N>(&self.perp(&r))
        }
    }
}

/// Up to two local maxima of a sampled profile, refined by a parabola through the neighbours.
/// Returns `(s, value)` pairs, largest first.
fn profile_peaks(g: &[f64]) -> [(f64, f64); 2] {
    let n = g.len() - 1;
    let h = 1.0 / n as f64;
    let mut peaks = [(0.5, -1.0), (0.5, -1.0)];
    for k in 1..n {
        if is_peak(g[k - 1], g[k], g[k + 1]) {
            let denom = g[k - 1] - 2.0 * g[k] + g[k + 1];
            let shift = if denom < 0.0 {
                (0.5 * (g[k - 1] - g[k + 1]) / denom).clamp(-0.5, 0.5)
            } else {
                0.0
            };
            let peak = ((k as f64 + shift) * h, g[k]);
            if peak.1 > peaks[0].1 {
                peaks[1] = peaks[0];
                peaks[0] = peak;
            } else if peak.1 > peaks[1].1 {
                peaks[1] = peak;
            }
        }
    }
    peaks
}

/// Whether `here` is a local maximum between its neighbours: at least both and above one of
/// them. (As `(≥ and >) or (> and ≥)` it took four comparisons where the rising side of a
/// bulge fails the first of these; a NaN fails both ways.)
#[inline(always)]
fn is_peak(prev: f64, here: f64, next: f64) -> bool {
    here >= next && here >= prev && (here > prev || here > next)
}

/// Model-only estimate of the chord error (no curve evaluation): the largest normal offset of
/// the cubic Hermite model built from the end tangents. Accurate to a few per cent on pieces
/// short against their radius of curvature; [`chord_error`] is the real measure.
///
/// `tol` is the tolerance the estimate will be compared with: where the model cannot be
/// trusted at that scale (see [`chord_error`]) the estimate is infinite, so the caller measures.
pub fn chord_error_estimate(a: &Sample, b: &Sample, tol: f64) -> f64 {
    // No curve to say how many axes it has: all of them.
    estimate::<{ crate::vocab::MAX_AXES }>(a, b, tol)
}

fn estimate<const N: usize>(a: &Sample, b: &Sample, tol: f64) -> f64 {
    let chord = Chord::<N>::new(a.d.point, b.d.point);
    let du = b.u - a.u;
    let ta = lanes::scale::<N>(&chord.perp(&a.d.d1), du);
    let tb = lanes::scale::<N>(&chord.perp(&b.d.d1), du);
    let peak = profile_peaks(&hermite_profile(&chord, &ta, &tb))[0]
        .1
        .max(0.0)
        .sqrt();
    if chord.len <= 1e-12 || model_untrusted(a, b, &chord, &ta, &tb, peak, tol) {
        return f64::INFINITY;
    }
    peak
}

/// The largest distance between the curve on `[a.u, b.u]` and the chord from `a` to `b`.
///
/// `tol` only steers effort: disagreements between model and curve far below it are not
/// chased. Evaluations are counted in the result.
pub fn chord_error(curve: &NurbsCurve, a: &Sample, b: &Sample, tol: f64) -> ChordError {
    // Three coordinates for up to three axes, all of a `Point` beyond.
    if curve.dim() <= 3 {
        measure::<3>(curve, a, b, tol)
    } else {
        measure::<{ crate::vocab::MAX_AXES }>(curve, a, b, tol)
    }
}

fn measure<const N: usize>(curve: &NurbsCurve, a: &Sample, b: &Sample, tol: f64) -> ChordError {
    let mut out = ChordError {
        max: 0.0,
        at: f64::NAN,
        rho_min: f64::INFINITY,
        evals: 0,
    };
    let du = b.u - a.u;
    if du <= 0.0 {
        return out;
    }
    let chord = Chord::<N>::new(a.d.point, b.d.point);
    if chord.len <= 1e-12 {
        // A closed piece (the curve leaves and comes back): no chord direction to model.
        sampled_maximum(curve, a.u, du, &chord, &mut out);
        return out;
    }
    let ta = lanes::scale::<N>(&chord.perp(&a.d.d1), du);
    let tb = lanes::scale::<N>(&chord.perp(&b.d.d1), du);
    let g = hermite_profile(&chord, &ta, &tb);
    let peaks = profile_peaks(&g);
    if model_untrusted(a, b, &chord, &ta, &tb, peaks[0].1.max(0.0).sqrt(), tol) {
        sampled_maximum(curve, a.u, du, &chord, &mut out);
        return out;
    }
    let noise = (0.05 * tol) * (0.05 * tol);
    for (i, &(s, model)) in peaks.iter().enumerate() {
        if model < 0.0 || (i == 1 && model < 0.01 * peaks[0].1) {
            continue;
        }
        let first = polish(curve, a.u, du, &chord, s, &mut out);
        let trusted = first <= 4.0 * model + noise && model <= 4.0 * first + noise;
        if !trusted {
            sampled_maximum(curve, a.u, du, &chord, &mut out);
            return out;
        }
    }
    if peaks[0].1 < 0.0 {
        // The model is flat (end tangents along the chord): look at the middle anyway.
        let first = polish(curve, a.u, du, &chord, 0.5, &mut out);
        if first > noise {
            sampled_maximum(curve, a.u, du, &chord, &mut out);
        }
    }
    out
}

/// Newton's method for a local maximum of the squared normal offset, from `s0` (fraction of the
/// piece). Records every evaluated point's distance to the chord segment and, once converged, the
/// quadratic model's maximum. Returns the squared normal offset at the first evaluated point,
/// for the caller's model check.
fn polish<const N: usize>(
    curve: &NurbsCurve,
    u0: f64,
    du: f64,
    chord: &Chord<N>,
    s0: f64,
    out: &mut ChordError,
) -> f64 {
    let mut s = s0;
    let mut first = -1.0;
    for _ in 0..MAX_NEWTON {
        let d = curve.derivs(u0 + s * du);
        out.evals += 1;
        out.rho_min = running_min(out.rho_min, lanes::curvature_radius::<N>(&d));
        out.note(chord.distance(&d.point), u0 + s * du);
        let r = chord.perp(&lanes::sub::<N>(&d.point, &chord.start));
        let f = chord.dot(&r, &r);
        if first < 0.0 {
            first = f;
        }
        let slope = chord.dot(&r, &d.d1);
        let across = chord.perp(&d.d1);
        let curv = chord.dot(&across, &across) + chord.dot(&r, &d.d2);
        if curv >= 0.0 {
            // Not in the concave neighbourhood of a maximum: Newton would walk away.
            break;
        }
        let step = -slope / curv;
        if (step / du).abs() <= NEWTON_DONE {
            let peak = (s + step / du).clamp(0.0, 1.0);
            out.note((f - slope * slope / curv).max(0.0).sqrt(), u0 + peak * du);
            break;
        }
        s = (s + step / du).clamp(0.0, 1.0);
    }
    first
}

/// Dense sampling of the piece, then Newton from the best samples.
fn sampled_maximum<const N: usize>(
    curve: &NurbsCurve,
    u0: f64,
    du: f64,
    chord: &Chord<N>,
    out: &mut ChordError,
) {
    let mut g = [0.0; FALLBACK_SAMPLES + 1];
    for (k, slot) in g.iter_mut().enumerate().take(FALLBACK_SAMPLES).skip(1) {
        let u = u0 + du * k as f64 / FALLBACK_SAMPLES as f64;
        let d = curve.derivs(u);
        out.evals += 1;
        out.rho_min = running_min(out.rho_min, lanes::curvature_radius::<N>(&d));
        let dist = chord.distance(&d.point);
        out.note(dist, u);
        *slot = dist * dist;
    }
    if chord.len > 1e-12 {
        for &(s, value) in &profile_peaks(&g) {
            if value > 0.0 {
                polish(curve, u0, du, chord, s, out);
            }
        }
    }
    // Newton polishes normal offsets; where the largest distance is past an end of the chord
    // (a hairpin overshooting the end point) it is a distance to that point instead. A
    // golden-section search on the distance itself around the best sample finds either.
    let best = (1..FALLBACK_SAMPLES)
        .max_by(|&i, &j| g[i].total_cmp(&g[j]))
        .unwrap_or(1);
    let h = 1.0 / FALLBACK_SAMPLES as f64;
    let distance_at = |s: f64, out: &mut ChordError| {
        let d = curve.derivs(u0 + du * s);
        out.evals += 1;
        out.rho_min = running_min(out.rho_min, lanes::curvature_radius::<N>(&d));
        let dist = chord.distance(&d.point);
        out.note(dist, u0 + du * s);
        dist
    };
    const INV_PHI: f64 = 0.618_033_988_749_895;
    let (mut lo, mut hi) = ((best as f64 - 1.0) * h, (best as f64 + 1.0) * h);
    let mut x1 = hi - INV_PHI * (hi - lo);
    let mut x2 = lo + INV_PHI * (hi - lo);
    let (mut f1, mut f2) = (distance_at(x1, out), distance_at(x2, out));
    for _ in 0..GOLDEN_STEPS {
        if f1 < f2 {
            lo = x1;
            (x1, f1) = (x2, f2);
            x2 = lo + INV_PHI * (hi - lo);
            f2 = distance_at(x2, out);
        } else {
            hi = x2;
            (x2, f2) = (x1, f1);
            x1 = hi - INV_PHI * (hi - lo);
            f1 = distance_at(x1, out);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{circular_arc, point};

    /// Brute force: the largest distance over 20,001 points of the piece.
    fn dense(curve: &NurbsCurve, a: f64, b: f64) -> f64 {
        let chord = Chord::<{ crate::vocab::MAX_AXES }>::new(curve.point(a), curve.point(b));
        (0..=20_000)
            .map(|k| chord.distance(&curve.point(a + (b - a) * k as f64 / 20_000.0)))
            .fold(0.0, f64::max)
    }

    fn s_curve() -> NurbsCurve {
        // A cubic with an inflection in the middle.
        let pts: Vec<Point> = [(0.0, 0.0), (10.0, 10.0), (20.0, -10.0), (30.0, 0.0)]
            .iter()
            .map(|&(x, y)| point(&[x, y]))
            .collect();
        NurbsCurve::new(
            3,
            2,
            &pts,
            &[1.0; 4],
            vec![0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0],
        )
        .unwrap()
    }

    #[test]
    fn peaks_are_the_local_maxima_as_first_defined() {
        // The peak test as first written, `(≥ and >) or (> and ≥)`, against the one that
        // fails early, on every triple of these values: ties, both orders, zeros of both
        // signs, infinities and NaN.
        let values = [
            f64::NAN,
            f64::NEG_INFINITY,
            -1.0,
            -0.0,
            0.0,
            0.5,
            1.0,
            f64::INFINITY,
        ];
        let mut peaks = 0;
        for prev in values {
            for here in values {
                for next in values {
                    let first = here >= prev && here > next || here > prev && here >= next;
                    assert_eq!(is_peak(prev, here, next), first, "{prev} {here} {next}");
                    peaks += usize::from(first);
                }
            }
        }
        assert!(peaks > 100, "{peaks} peaks");
    }

    #[test]
    fn circle_limit_matches_the_sagitta() {
        let (rho, tol) = (10.0, 0.001);
        let l = chord_length_limit(rho, tol);
        let sagitta = rho - (rho * rho - l * l / 4.0).sqrt();
        assert!((sagitta - tol).abs() < 1e-12);
        assert_eq!(chord_length_limit(0.5, 1.0), 1.0);
        assert_eq!(chord_length_limit(f64::INFINITY, 1.0), f64::INFINITY);
    }

    #[test]
    fn exact_on_an_arc() {
        let arc = circular_arc(
            2,
            [0, 1],
            &point(&[0.0, 0.0]),
            &point(&[10.0, 0.0]),
            &point(&[0.0, 10.0]),
            std::f64::consts::FRAC_PI_2,
        )
        .unwrap();
        for &(a, b) in &[(0.0, 0.1), (0.2, 0.21), (0.0, 1.0), (0.5, 0.9)] {
            let (sa, sb) = (Sample::at(&arc, a), Sample::at(&arc, b));
            let measured = chord_error(&arc, &sa, &sb, 1e-3);
            let chord = (sb.d.point - sa.d.point).norm();
            let sagitta = 10.0 - (100.0 - chord * chord / 4.0).sqrt();
            assert!(
                (measured.max - sagitta).abs() <= 1e-9 * sagitta.max(1e-9),
                "[{a},{b}]: {} vs sagitta {sagitta}",
                measured.max
            );
            assert!(measured.evals <= 3, "{} evals", measured.evals);
        }
    }

    #[test]
    fn finds_both_bulges_across_an_inflection() {
        let c = s_curve();
        // Symmetric around the inflection at u = 0.5: the mid-parameter point is on the chord.
        for &(a, b) in &[(0.3, 0.7), (0.45, 0.55), (0.4, 0.65), (0.0, 1.0)] {
            let (sa, sb) = (Sample::at(&c, a), Sample::at(&c, b));
            let mid = c.point(0.5 * (a + b));
            let midpoint_estimate = (mid - (sa.d.point + sb.d.point) * 0.5).norm();
            let measured = chord_error(&c, &sa, &sb, 1e-3).max;
            let truth = dense(&c, a, b);
            assert!(
                measured >= truth * (1.0 - 1e-7),
                "[{a},{b}]: {measured} < dense {truth}"
            );
            assert!(measured <= truth * (1.0 + 1e-6) + 1e-12);
            if (a + b - 1.0_f64).abs() < 1e-12 {
                assert!(midpoint_estimate < 1e-9 && truth > 1e-3);
            }
        }
    }

    #[test]
    fn matches_dense_sampling_on_random_pieces() {
        let c = s_curve();
        let mut state = 0x1234_5678_u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..300 {
            let a = next();
            let b = (a + 0.002 + 0.3 * next()).min(1.0);
            let (sa, sb) = (Sample::at(&c, a), Sample::at(&c, b));
            let measured = chord_error(&c, &sa, &sb, 1e-3).max;
            let truth = dense(&c, a, b);
            assert!(
                measured >= truth * (1.0 - 1e-6) && measured <= truth * (1.0 + 1e-6) + 1e-12,
                "[{a},{b}]: {measured} vs {truth}"
            );
        }
    }

    #[test]
    fn estimate_is_close_on_short_pieces() {
        let c = s_curve();
        let (sa, sb) = (Sample::at(&c, 0.1), Sample::at(&c, 0.12));
        let truth = dense(&c, 0.1, 0.12);
        let est = chord_error_estimate(&sa, &sb, truth);
        assert!((est / truth - 1.0).abs() < 0.02, "{est} vs {truth}");
    }
}
