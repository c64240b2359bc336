//! Chord-bounded segmentation: a block's curve becomes the longest chords whose true chord
//! error stays within the tolerance.
//!
//! Per step, from the current point `a` (with `C'`, `C''`):
//! 1. target length: the circle formula `2 sqrt(2 rho h - h²)` at a slightly lower aim than the
//!    tolerance, capped by `max_segment_mm`;
//! 2. predicted parameter increment: Taylor (errata form) or Hamming from the last corrected
//!    parameters;
//! 3. evaluate the end `b`, measure the true chord error on `[a, b]` ([`chord_error`]);
//! 4. where the measurement is within the tolerance, certify it: the segment counts as within
//!    only when the certified bound ([`certify`](super::certify)) is, so a measurement the
//!    curve fooled cannot let a segment through;
//! 5. accept when the error is in the band just below the tolerance (or the piece, or the
//!    length cap, is reached); otherwise rescale the increment by `sqrt(aim / error)` (the
//!    sagitta grows with the square of the length, seed 001 eq. 5) inside a bracket of known good
//!    and known bad increments, falling back to halving (seed 000 Fig. 3).
//!
//! The measurement aims (it is close to the truth, so chords come out near the longest
//! possible); the bound decides. Every emitted segment carries its certified bound.
//!
//! Curves are cut at their corner knots (multiplicity ≥ degree) into C1 pieces; a piece end
//! takes the incoming derivatives, so a corner inside a NURBS is a junction like a corner
//! between blocks. Straight pieces (degree 1) skip the chord measurement: their error is zero.

use std::sync::Arc;

use super::certify::certify;
use super::chord::{ChordError, Sample, chord_error, chord_length_limit};
use super::predictor::{History, hamming_increments, taylor_increment};
use super::{GeoSegment, PlanSettings, corner_speed};
use crate::gcode::Block;
use crate::geometry::{NurbsCurve, Point};
use crate::vocab::{Predictor, Segmentation};

/// Fraction of the tolerance that predictions aim at, leaving room for the circle formula's
/// error on non-circular pieces.
const AIM: f64 = 0.985;
/// Accept without trying longer once the error is at least this fraction of the tolerance:
/// the chord is then within about 1.5 % of the longest possible (length grows as the square
/// root of the sagitta). Tighter costs more tries per segment; looser costs segments (0.95
/// left zigzags 3.4 % over the greedy count, `tests/chord_bound.rs`).
const BAND: f64 = 0.97;
/// Rescaling attempts before settling for the best accepted increment.
const MAX_TRIES: u32 = 12;
/// Halvings after that before giving up on a pathological piece.
const MAX_HALVINGS: u32 = 60;
/// Measurements up to this multiple of the tolerance are certified before a chord is refused:
/// the measurement's model can overshoot, the bound cannot be fooled.
const CERTIFY_ABOVE: f64 = 1.25;

/// Counters over everything segmented so far.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SegmenterStats {
    pub segments: u64,
    /// Curve evaluations, including chord-error measurement.
    pub evals: u64,
    /// Steps where the first prediction was outside the acceptance band and was rescaled.
    pub rescaled: u64,
    /// Steps that fell back to halving.
    pub halvings: u64,
    /// Segments still over tolerance after every halving (never seen on valid curves).
    pub over_tolerance: u64,
    /// Measurements within the tolerance that the certified bound refused (the measurement
    /// was fooled, or the error was within a hair of the tolerance).
    pub refused_by_bound: u64,
    /// Bézier pieces the certificates examined.
    pub certified_pieces: u64,
}

/// Turns blocks into chord-bounded segments, remembering the previous block's end tangent to
/// price the corner between them.
#[derive(Debug)]
pub struct Segmenter {
    settings: PlanSettings,
    prev_tangent: Option<Point>,
    history: History,
    /// Measured chord error over the circle formula's sagitta on the last segment: how far the
    /// curve is from its osculating circle here. Scales the next prediction.
    gain: f64,
    pub stats: SegmenterStats,
}

impl Segmenter {
    pub fn new(settings: PlanSettings) -> Segmenter {
        Segmenter {
            settings,
            prev_tangent: None,
            history: History::default(),
            gain: 1.0,
            stats: SegmenterStats::default(),
        }
    }

    pub fn settings(&self) -> &PlanSettings {
        &self.settings
    }

    /// Segments one block, handing each segment to `emit` in path order.
    pub fn segment_block<F: FnMut(GeoSegment)>(&mut self, block: &Arc<Block>, mut emit: F) {
        let curve = &block.curve;
        let (u_min, u_max) = (curve.u_min(), curve.u_max());
        let feed = self.block_feed(block);
        if block.dwell_s > 0.0 || block.pause.is_some() {
            // A dwell or a programmed stop first: the move before it ends at a standstill.
            self.prev_tangent = None;
        }
        let mut lo = u_min;
        let mut corners = curve.corner_knots().chain(std::iter::once(u_max));
        while let Some(hi) = corners.next().filter(|_| lo < u_max) {
            self.segment_piece(block, lo, hi, feed, hi >= u_max, &mut emit);
            lo = hi;
        }
    }

    /// Feed limit of a block in mm/s: the programmed feed clamped by the machine's maximum.
    fn block_feed(&self, block: &Block) -> f64 {
        if block.kind == crate::gcode::BlockKind::Rapid {
            return self.settings.rapid_feed;
        }
        let max = self.settings.max_feed;
        block.feed_mm_per_min.map_or(max, |f| (f / 60.0).min(max))
    }

    fn segment_piece<F: FnMut(GeoSegment)>(
        &mut self,
        block: &Arc<Block>,
        lo: f64,
        hi: f64,
        feed: f64,
        last_piece: bool,
        emit: &mut F,
    ) {
        let curve = &block.curve;
        let straight = curve.degree() == 1;
        let mut a = Sample::at(curve, lo);
        self.stats.evals += 1;
        let tangent = unit(&a.d.d1);
        let mut entry_limit = match self.prev_tangent {
            Some(prev) => corner_speed(&prev, &tangent, &self.settings),
            None => 0.0,
        };
        self.history.reset();
        self.history.push(lo);
        self.gain = 1.0;
        let (mut piece_end, mut piece_len) = (Point::zeros(), 0.0);
        if straight {
            // Equal pieces no longer than the cap.
            piece_end = curve.point(hi);
            self.stats.evals += 1;
            let len = (piece_end - a.d.point).norm();
            piece_len = len / (len / self.settings.max_segment).ceil().max(1.0);
        }
        let mut first_of_piece = true;
        let mut rho_start = a.d.curvature_radius();
        loop {
            let (b, err, bound, tried) = if straight {
                straight_step(curve, &a, hi, &piece_end, piece_len)
            } else {
                self.curved_step(curve, &a, hi)
            };
            let at_end = b.u >= hi;
            let rho_end = b.d.curvature_radius();
            let rho_min = rho_start.min(rho_end).min(err.rho_min);
            let chord = (b.d.point - a.d.point).norm();
            let seg = GeoSegment {
                block: Arc::clone(block),
                u_start: a.u,
                u_end: b.u,
                start: a.d.point,
                end: b.d.point,
                chord,
                arc: arc_length_estimate(chord, err.max),
                chord_error: err.max,
                chord_bound: bound,
                rho_min,
                rho_end,
                feed_limit: self.feed_limit(feed, rho_min, chord, err.max),
                entry_limit,
                evals: tried + err.evals,
                first_of_piece,
                last_of_piece: at_end,
                last_of_block: at_end && last_piece,
            };
            self.stats.segments += 1;
            self.stats.evals += u64::from(tried + err.evals);
            if bound > self.settings.tolerance {
                self.stats.over_tolerance += 1;
            }
            emit(seg);
            entry_limit = f64::INFINITY;
            first_of_piece = false;
            rho_start = rho_end;
            self.history.push(b.u);
            a = b;
            if at_end {
                break;
            }
        }
        self.prev_tangent = Some(unit(&a.d.d1));
    }

    /// Cruise speed limit on a segment (mm/s): programmed feed, normal acceleration over the
    /// tightest radius seen and, in period mode, the chord-error speed (one segment per period).
    fn feed_limit(&self, feed: f64, rho_min: f64, chord: f64, err: f64) -> f64 {
        let s = &self.settings;
        let a_n = s.max_normal_accel * (1.0 - super::PLANNING_MARGIN);
        let mut v = feed.min((a_n * rho_min).sqrt());
        if s.segmentation == Segmentation::Period {
            // The circle formula at the tightest radius, and the measured sagitta scaled to the
            // tolerance (sagitta ∝ length²: seed 001 eq. 5), whichever is smaller.
            let by_radius = chord_length_limit(rho_min, AIM * s.tolerance);
            let by_measure = if err > 0.0 {
                chord * (AIM * s.tolerance / err).sqrt()
            } else {
                f64::INFINITY
            };
            v = v.min(by_radius.min(by_measure) / s.period);
        }
        v
    }

    /// Whether the chord from `a` to `b` is within the tolerance: the certified bound holds.
    /// The measurement is certified when it is within the tolerance or just over it (the
    /// model's last Newton step can overshoot the true maximum; a bound that holds proves it
    /// did, and then caps the reported error). Returns the bound when it holds, and otherwise
    /// the error to rescale by (the measurement, or the bound that failed if it is larger).
    fn within(
        &mut self,
        curve: &NurbsCurve,
        a: &Sample,
        b: &Sample,
        err: &mut ChordError,
    ) -> Result<f64, f64> {
        let tol = self.settings.tolerance;
        if err.max > CERTIFY_ABOVE * tol {
            return Err(err.max);
        }
        let c = certify(curve, a.u, b.u, &a.d.point, &b.d.point, tol, err.at);
        self.stats.certified_pieces += u64::from(c.pieces);
        if c.holds(tol) {
            err.max = err.max.min(c.bound);
            Ok(c.bound)
        } else {
            if err.max <= tol {
                self.stats.refused_by_bound += 1;
            }
            Err(c.bound.max(err.max))
        }
    }

    /// One chord-bounded step on a curved piece. Returns the end sample, its measured chord
    /// error, its certified bound and the number of end-point evaluations spent.
    fn curved_step(
        &mut self,
        curve: &NurbsCurve,
        a: &Sample,
        hi: f64,
    ) -> (Sample, ChordError, f64, u32) {
        let s = &self.settings;
        let tol = s.tolerance;
        let remaining = hi - a.u;
        let rho = a.d.curvature_radius();
        let target = chord_length_limit(rho, AIM * tol / self.gain).min(s.max_segment);
        let predicted = match (s.predictor, self.history.full()) {
            (Predictor::Hamming, Some(hist)) => Some(hamming_increments(hist).0),
            _ => taylor_increment(a, target),
        };
        let mut du = match predicted {
            Some(du) if du > 0.0 && du.is_finite() => du,
            _ => remaining / 16.0,
        };
        // Avoid leaving a sliver at the end of the piece: split the rest evenly instead.
        if du < remaining && remaining - du < 0.3 * du {
            du = 0.5 * remaining;
        }
        let mut evals = 0;
        // The longest chord found within the measured tolerance, not yet certified.
        let mut good: Option<(Sample, ChordError, f64)> = None;
        let (mut lo, mut bad) = (0.0f64, f64::INFINITY);
        for attempt in 0..MAX_TRIES {
            let at_end = du >= remaining;
            let b = if at_end {
                Sample {
                    u: hi,
                    d: curve.derivs_from_left(hi),
                }
            } else {
                Sample::at(curve, a.u + du)
            };
            evals += 1;
            let mut err = chord_error(curve, a, &b, tol);
            let len = (b.d.point - a.d.point).norm();
            let max_segment = self.settings.max_segment;
            let capped = len >= max_segment * (1.0 - 1e-9);
            // Only a chord about to be accepted is certified: one that would only grow the
            // bracket is certified if it is ever taken (below). Over the tolerance, only the
            // piece's end is certified (a model overshoot there would leave a sliver).
            let accepting = at_end || capped || err.max >= BAND * tol;
            let verdict = if err.max <= tol && !accepting {
                Ok(f64::NAN)
            } else if err.max <= tol || at_end {
                self.within(curve, a, &b, &mut err)
            } else {
                Err(err.max)
            };
            let next;
            match verdict {
                Ok(bound) => {
                    if accepting {
                        self.learn(rho, len, err.max);
                        return (b, err, bound, evals);
                    }
                    lo = du;
                    good = Some((b, err, du));
                    let grow = (AIM * tol / err.max.max(1e-4 * tol)).sqrt().min(4.0);
                    let mut g = du * grow;
                    if len * grow > max_segment {
                        g = du * (max_segment / len).max(1.0 + 1e-6);
                    }
                    next = g;
                }
                Err(over) => {
                    bad = du;
                    next = du * (AIM * tol / over).sqrt().max(0.1);
                }
            }
            if attempt == 0 {
                self.stats.rescaled += 1;
            }
            let mut n = next;
            if n <= lo || n >= bad {
                n = if bad.is_finite() {
                    0.5 * (lo + bad)
                } else {
                    2.0 * du
                };
            }
            if bad.is_finite() && bad - lo <= 1e-12 * bad.max(1e-300) {
                break;
            }
            // Past the end of the piece: try exactly the end.
            du = n.min(remaining);
        }
        if let Some((b, mut err, good_du)) = good {
            match self.within(curve, a, &b, &mut err) {
                Ok(bound) => {
                    self.learn(rho, (b.d.point - a.d.point).norm(), err.max);
                    return (b, err, bound, evals);
                }
                Err(_) => bad = good_du,
            }
        }
        // Seed 000 Fig. 3: halve until it holds.
        self.stats.halvings += 1;
        let mut du = if bad.is_finite() { bad } else { du };
        let mut last = None;
        for _ in 0..MAX_HALVINGS {
            du *= 0.5;
            let b = Sample::at(curve, a.u + du);
            evals += 1;
            let mut err = chord_error(curve, a, &b, tol);
            let verdict = self.within(curve, a, &b, &mut err);
            let bound = match verdict {
                Ok(bound) | Err(bound) => bound,
            };
            last = Some((b, err, bound));
            if verdict.is_ok() {
                break;
            }
        }
        let (b, err, bound) = last.expect("at least one halving");
        (b, err, bound, evals)
    }
}

impl Segmenter {
    /// Updates the prediction gain from an accepted segment of chord `len` and error `err`
    /// that started where the radius of curvature was `rho`.
    fn learn(&mut self, rho: f64, len: f64, err: f64) {
        if rho.is_finite() && len > 0.0 && len < 2.0 * rho && err > 0.0 {
            let circle = rho - (rho * rho - 0.25 * len * len).sqrt();
            if circle > 0.0 {
                self.gain = (err / circle).clamp(0.25, 4.0);
            }
        }
    }
}

/// One step along a straight piece: the next of its equal parts (lengths need only be roughly
/// equal; a rational line is not uniform in `u`, the Taylor step absorbs most of that).
///
/// Its certified bound is zero: a degree-1 piece between corner knots is one knot span, a
/// rational line whose points between two parameters lie on the segment joining them.
fn straight_step(
    curve: &NurbsCurve,
    a: &Sample,
    hi: f64,
    end: &Point,
    len: f64,
) -> (Sample, ChordError, f64, u32) {
    let remaining = (end - a.d.point).norm();
    let b = if remaining <= len * (1.0 + 1e-6) {
        Sample {
            u: hi,
            d: curve.derivs_from_left(hi),
        }
    } else {
        let du = taylor_increment(a, len).unwrap_or((hi - a.u) / 2.0);
        Sample::at(curve, (a.u + du).min(hi))
    };
    let straight = ChordError {
        max: 0.0,
        at: f64::NAN,
        rho_min: f64::INFINITY,
        evals: 0,
    };
    (b, straight, 0.0, 1)
}

/// Unit vector along `v` (zero stays zero).
pub(crate) fn unit(v: &Point) -> Point {
    let n = v.norm();
    if n > 0.0 { v / n } else { *v }
}

/// Arc length of a gently curved piece from its chord and sagitta (`L + 8h²/(3L)`, the
/// circular-arc expansion); exact to far below a micron for chord-bounded pieces.
pub fn arc_length_estimate(chord: f64, sagitta: f64) -> f64 {
    if chord > 0.0 {
        chord + 8.0 * sagitta * sagitta / (3.0 * chord)
    } else {
        0.0
    }
}
