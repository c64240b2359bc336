//! Chord-bounded segmentation: a block's curve becomes the longest chords whose true chord
//! error stays within the tolerance.
//!
//! Per step, from the current point `a` (with `C'`, `C''`):
//! 1. target length: the circle formula `2 sqrt(2 rho h - h²)` at a slightly lower aim than the
//!    tolerance, or just under `max_segment_mm` where that is shorter;
//! 2. predicted parameter increment: Taylor (errata form) or Hamming from the last corrected
//!    parameters; where the length cap binds, Taylor to the cap (an extrapolation of
//!    parameters knows nothing of lengths);
//! 3. evaluate the end `b`, measure the true chord error on `[a, b]` ([`chord_error`]);
//! 4. where the measurement is within the tolerance, certify it: the segment counts as within
//!    only when the certified bound ([`certify`](super::certify)) is, so a measurement the
//!    curve fooled cannot let a segment through;
//! 5. accept when the error is in the band just below the tolerance (or the piece's end, or
//!    the last 0.1 % below the length cap, is reached); otherwise rescale the increment by
//!    `sqrt(aim / error)` (the sagitta grows with the square of the length, seed 001 eq. 5), or
//!    by `aim / length` for a chord over the cap, inside a bracket of known good and known bad
//!    increments, falling back to halving (seed 000 Fig. 3).
//!
//! The length cap is as hard as the tolerance: no chord is ever longer than `max_segment_mm`
//! (it bounds what one loop-buffer block reaches, and so how finely a turn-back retraces).
//!
//! The measurement aims (it is close to the truth, so chords come out near the longest
//! possible); the bound decides. Every emitted segment carries its certified bound.
//!
//! Curves are cut at their corner knots (multiplicity ≥ degree) into C1 pieces; a piece end
//! takes the incoming derivatives, so a corner inside a NURBS is a junction like a corner
//! between blocks. Straight pieces (degree 1) skip the chord measurement: their error is zero.

use std::sync::Arc;

use super::certify::{certify, hull_excess};
use super::chord::{ChordError, Sample, chord_error, chord_length_limit};
use super::predictor::{History, hamming_increments, taylor_increment};
use super::{GeoSegment, PlanSettings, corner_speed, step_cap};
use crate::gcode::Block;
use crate::geometry::{CurveDerivs, NurbsCurve, Point, lanes, running_min};
use crate::vocab::{Predictor, Segmentation};

/// Fraction of the tolerance that predictions aim at, leaving room for the circle formula's
/// error on non-circular pieces.
const AIM: f64 = 0.985;
/// Accept without trying longer once the error is at least this fraction of the tolerance:
/// the chord is then within about 1.5 % of the longest possible (length grows as the square
/// root of the sagitta). Tighter costs more tries per segment; looser costs segments (0.95
/// left zigzags 3.4 % over the greedy count, `tests/it/chord_bound.rs`).
const BAND: f64 = 0.97;
/// Rescaling attempts before settling for the best accepted increment.
const MAX_TRIES: u32 = 12;
/// Halvings after that before giving up on a pathological piece.
const MAX_HALVINGS: u32 = 60;
/// A length-capped chord is accepted anywhere in `[1 - CAP_WINDOW, 1] × max_segment_mm`, and
/// predictions aim at the middle of that window: a second-order prediction lands inside it
/// first time (its length is off by about 1e-5 relative on a 1 mm step), where aiming at the
/// cap itself left half the steps a hair short of it and cost a second try. The cap is a hard
/// limit: a chord over it is refused.
const CAP_WINDOW: f64 = 1e-3;
/// A certificate cuts at the measured farthest point first when the uncut piece's bound
/// (the measurement times [`hull_excess`]) would exceed this fraction of the tolerance.
const HINT_ABOVE: f64 = 0.95;
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
    /// The last block was a positioning move (for `rapid_stops`).
    after_positioning: bool,
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
            after_positioning: false,
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
        let positioning = block.kind == crate::gcode::BlockKind::Rapid || block.spark_off.is_some();
        if self.settings.rapid_stops && (positioning || self.after_positioning) {
            self.prev_tangent = None;
        }
        self.after_positioning = positioning;
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
            return self.settings.rapid_feed_mm_per_s;
        }
        let max = self.settings.max_feed_mm_per_s;
        block.feed_mm_per_min.map_or(max, |f| (f / 60.0).min(max))
    }

    /// The fastest a block may go whatever its programmed feed (mm/s): the rapid feed for a
    /// rapid, the machine's maximum for the rest.
    fn ceiling(&self, block: &Block) -> f64 {
        if block.kind == crate::gcode::BlockKind::Rapid {
            self.settings.rapid_feed_mm_per_s
        } else {
            self.settings.max_feed_mm_per_s
        }
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
        // A step's start and end samples, in two buffers that trade places by reference: a
        // step writes its end into the other buffer, which then starts the next step. Moved
        // by value, a 152-byte sample was copied twice more a segment (out of the step, then
        // to the next start).
        let mut buffers = [Sample::at(curve, lo); 2];
        let [mut a, mut b] = buffers.each_mut();
        self.stats.evals += 1;
        let tangent = unit(&a.d.d1);
        let mut entry_limit = match self.prev_tangent {
            Some(prev) => corner_speed(&prev, &tangent, &self.settings),
            None => 0.0,
        };
        self.history.reset();
        self.history.push(lo);
        self.gain = 1.0;
        let mut line = (curve.degree() == 1).then(|| {
            self.stats.evals += 1;
            let end = curve.point(hi);
            StraightPiece::new(
                curve,
                lo,
                hi,
                &a.d.point,
                &end,
                self.settings.max_segment_mm,
            )
        });
        let mut first_of_piece = true;
        let mut rho_start = a.d.curvature_radius();
        loop {
            let (err, bound, tried) = if let Some(line) = &mut line {
                line.step(curve, b)
            } else {
                self.curved_step(curve, a, rho_start, hi, b)
            };
            let at_end = b.u >= hi;
            // On three coordinates for up to three axes: the same numbers ([`lanes`]).
            let (rho_end, chord, stepped) = if curve.dim() <= 3 {
                self.end_of_step::<3>(&a.d.point, &b.d)
            } else {
                self.end_of_step::<{ crate::vocab::MAX_AXES }>(&a.d.point, &b.d)
            };
            // Running minima (`f64::min`'s results in fewer instructions, on every segment):
            // radii of a finite curve are numbers.
            let rho_min = running_min(running_min(rho_start, rho_end), err.rho_min);
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
                feed_limit: running_min(self.feed_limit(feed, rho_min, chord, err.max), stepped),
                speed_limit: running_min(
                    self.feed_limit(self.ceiling(block), rho_min, chord, err.max),
                    stepped,
                ),
                entry_limit,
                evals: tried + err.evals,
                first_of_piece,
                last_of_piece: at_end,
                last_of_block: at_end && last_piece,
                corner_dwell_s: 0.0,
            };
            self.stats.segments += 1;
            self.stats.evals += u64::from(tried + err.evals);
            if bound > self.settings.tolerance_mm {
                self.stats.over_tolerance += 1;
            }
            emit(seg);
            entry_limit = f64::INFINITY;
            first_of_piece = false;
            rho_start = rho_end;
            self.history.push(b.u);
            std::mem::swap(&mut a, &mut b);
            if at_end {
                break;
            }
        }
        self.prev_tangent = Some(unit(&a.d.d1));
    }

    /// A step's radius of curvature at its end, its chord and the outputs' speed cap along it.
    fn end_of_step<const N: usize>(&self, start: &Point, end: &CurveDerivs) -> (f64, f64, f64) {
        let d = lanes::sub::<N>(&end.point, start);
        let chord = lanes::norm::<N>(&d);
        let cap = step_cap::<N>(&self.settings.axis_cap_mm_per_s, &d, chord);
        (lanes::curvature_radius::<N>(end), chord, cap)
    }

    /// Cruise speed limit on a segment (mm/s): programmed feed, normal acceleration over the
    /// tightest radius seen and, in period mode, the chord-error speed (one segment per period).
    fn feed_limit(&self, feed: f64, rho_min: f64, chord: f64, err: f64) -> f64 {
        let s = &self.settings;
        let a_n = s.max_normal_accel_mm_per_s2 * (1.0 - super::PLANNING_MARGIN);
        let mut v = running_min(feed, (a_n * rho_min).sqrt());
        if s.segmentation == Segmentation::Period {
            // The circle formula at the tightest radius, and the measured sagitta scaled to the
            // tolerance (sagitta ∝ length²: seed 001 eq. 5), whichever is smaller.
            let by_radius = chord_length_limit(rho_min, AIM * s.tolerance_mm);
            let by_measure = if err > 0.0 {
                chord * (AIM * s.tolerance_mm / err).sqrt()
            } else {
                f64::INFINITY
            };
            v = running_min(v, by_radius.min(by_measure) / s.period_s);
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
        let tol = self.settings.tolerance_mm;
        if err.max > CERTIFY_ABOVE * tol {
            return Err(err.max);
        }
        // A cut at the farthest point pays only where the whole piece's control points would
        // stand over the tolerance; far below it the uncut piece certifies alone.
        let farthest = if err.max * hull_excess(curve.degree()) > HINT_ABOVE * tol {
            err.at
        } else {
            f64::NAN
        };
        let c = certify(curve, a.u, b.u, &a.d.point, &b.d.point, tol, farthest);
        self.stats.certified_pieces += u64::from(c.pieces);
        if c.holds(tol) {
            err.max = running_min(err.max, c.bound);
            Ok(c.bound)
        } else {
            if err.max <= tol {
                self.stats.refused_by_bound += 1;
            }
            Err(c.bound.max(err.max))
        }
    }

    /// One chord-bounded step on a curved piece from `a`, whose radius of curvature is `rho`.
    /// Writes the end sample into `b`; returns its measured chord error, its certified bound
    /// and the number of end-point evaluations spent.
    fn curved_step(
        &mut self,
        curve: &NurbsCurve,
        a: &Sample,
        rho: f64,
        hi: f64,
        b: &mut Sample,
    ) -> (ChordError, f64, u32) {
        let s = &self.settings;
        let tol = s.tolerance_mm;
        let cap = s.max_segment_mm;
        let cap_aim = cap * (1.0 - 0.5 * CAP_WINDOW);
        let cap_floor = cap * (1.0 - CAP_WINDOW);
        let remaining = hi - a.u;
        let mut du = self.first_increment(a, rho, remaining, cap_aim);
        let mut evals = 0;
        // The longest chord found within the measured tolerance, not yet certified.
        let mut good: Option<(Sample, ChordError, f64)> = None;
        let (mut lo, mut bad) = (0.0f64, f64::INFINITY);
        for attempt in 0..MAX_TRIES {
            let at_end = du >= remaining;
            end_sample(curve, a, du, hi, b);
            evals += 1;
            let len = (b.d.point - a.d.point).norm();
            let next = if len > cap {
                // Over the length cap whatever its error: shorten in proportion.
                bad = du;
                du * (cap_aim / len).max(0.1)
            } else {
                let mut err = chord_error(curve, a, b, tol);
                let capped = len >= cap_floor;
                // Only a chord about to be accepted is certified: one that would only grow
                // the bracket is certified if it is ever taken (below). Over the tolerance,
                // only the piece's end is certified (a model overshoot there would leave a
                // sliver).
                let accepting = at_end || capped || err.max >= BAND * tol;
                let verdict = if err.max <= tol && !accepting {
                    Ok(f64::NAN)
                } else if err.max <= tol || at_end {
                    self.within(curve, a, b, &mut err)
                } else {
                    Err(err.max)
                };
                match verdict {
                    Ok(bound) if accepting => {
                        self.learn(rho, len, err.max);
                        return (err, bound, evals);
                    }
                    Ok(_) => {
                        lo = du;
                        good = Some((*b, err, du));
                        let grow = (AIM * tol / err.max.max(1e-4 * tol)).sqrt().min(4.0);
                        if len * grow > cap_aim {
                            du * (cap_aim / len).max(1.0 + 1e-6)
                        } else {
                            du * grow
                        }
                    }
                    Err(over) => {
                        bad = du;
                        du * (AIM * tol / over).sqrt().max(0.1)
                    }
                }
            };
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
        if let Some((good_b, mut err, good_du)) = good {
            match self.within(curve, a, &good_b, &mut err) {
                Ok(bound) => {
                    self.learn(rho, (good_b.d.point - a.d.point).norm(), err.max);
                    *b = good_b;
                    return (err, bound, evals);
                }
                Err(_) => bad = good_du,
            }
        }
        let du = if bad.is_finite() { bad } else { du };
        self.halve_until_within(curve, a, du, evals, b)
    }

    /// The first increment of a step: the Hamming or Taylor prediction towards the aimed
    /// chord error (Taylor where the length cap binds), a sixteenth of the piece where there
    /// is none, and half of what is left rather than a sliver at the end.
    #[inline]
    fn first_increment(&self, a: &Sample, rho: f64, remaining: f64, cap_aim: f64) -> f64 {
        let s = &self.settings;
        let tol = s.tolerance_mm;
        let by_chord = chord_length_limit(rho, AIM * tol / self.gain);
        let taylor = taylor_increment(a, running_min(cap_aim, by_chord));
        let predicted = match (s.predictor, self.history.full()) {
            // The extrapolation knows nothing of the length cap: where the cap binds, the step
            // is a length, which is what the Taylor update predicts.
            (Predictor::Hamming, Some(hist)) if by_chord <= cap_aim => {
                Some(hamming_increments(hist).0)
            }
            _ => taylor,
        };
        let mut du = match predicted {
            Some(du) if du > 0.0 && du.is_finite() => du,
            _ => remaining / 16.0,
        };
        // Avoid leaving a sliver at the end of the piece: split the rest evenly instead.
        if du < remaining && remaining - du < 0.3 * du {
            du = 0.5 * remaining;
        }
        du
    }

    /// Seed 000 Fig. 3: halves `du` until the chord holds (and is within the length cap).
    /// The end sample is left in `b`: the last one measured, since every halving but the
    /// last that is not measured is followed by another.
    fn halve_until_within(
        &mut self,
        curve: &NurbsCurve,
        a: &Sample,
        mut du: f64,
        mut evals: u32,
        b: &mut Sample,
    ) -> (ChordError, f64, u32) {
        let tol = self.settings.tolerance_mm;
        let cap = self.settings.max_segment_mm;
        self.stats.halvings += 1;
        let mut last = None;
        for halving in 1..=MAX_HALVINGS {
            du *= 0.5;
            *b = Sample::at(curve, a.u + du);
            evals += 1;
            if (b.d.point - a.d.point).norm() > cap && halving < MAX_HALVINGS {
                continue;
            }
            let mut err = chord_error(curve, a, b, tol);
            let verdict = self.within(curve, a, b, &mut err);
            let bound = match verdict {
                Ok(bound) | Err(bound) => bound,
            };
            last = Some((err, bound));
            if verdict.is_ok() {
                break;
            }
        }
        let (err, bound) = last.expect("the last halving is always measured");
        (err, bound, evals)
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

/// A straight piece (degree 1 between corner knots: one knot span) cut into the fewest equal
/// parts the length cap allows.
///
/// A rational line runs unevenly in `u`, but in closed form: with end weights `w0`, `w1` the
/// point at local parameter `t` lies the fraction `f = t w1 / ((1 - t) w0 + t w1)` along the
/// segment, so the part ends are `t = f w0 / (w1 (1 - f) + f w0)` at `f = k / n`, exact to
/// rounding whatever the weights (a polynomial line has `w0 = w1` and `t = f`).
///
/// Its certified bound is zero: the points of a rational line between two parameters lie on
/// the segment joining them.
#[derive(Debug)]
struct StraightPiece {
    lo: f64,
    hi: f64,
    w0: f64,
    w1: f64,
    parts: usize,
    done: usize,
}

impl StraightPiece {
    fn new(curve: &NurbsCurve, lo: f64, hi: f64, start: &Point, end: &Point, cap: f64) -> Self {
        let len = (end - start).norm();
        let parts = (len / cap).ceil().max(1.0);
        // Rounding in len / cap may leave a part a hair over the cap: one more part then.
        let parts = if len / parts > cap {
            parts + 1.0
        } else {
            parts
        } as usize;
        // The piece's end weights: its one Bézier piece's (any knot of a degree-1 curve is a
        // corner knot, so the piece is one span).
        let (mut w0, mut w1, mut spans) = (1.0, 1.0, 0);
        curve.bezier_pieces::<8, 2>(lo, hi, |bz, _, _| {
            (w0, w1) = (bz.weight(0), bz.weight(1));
            spans += 1;
        });
        debug_assert_eq!(spans, 1, "a straight piece is one knot span");
        StraightPiece {
            lo,
            hi,
            w0,
            w1,
            parts,
            done: 0,
        }
    }

    /// The next part's end, written into `b`, and what a step returns.
    fn step(&mut self, curve: &NurbsCurve, b: &mut Sample) -> (ChordError, f64, u32) {
        self.done += 1;
        *b = if self.done >= self.parts {
            Sample {
                u: self.hi,
                d: curve.derivs_from_left(self.hi),
            }
        } else {
            let f = self.done as f64 / self.parts as f64;
            let t = f * self.w0 / (self.w1 * (1.0 - f) + f * self.w0);
            Sample::at(curve, self.lo + t * (self.hi - self.lo))
        };
        let straight = ChordError {
            max: 0.0,
            at: f64::NAN,
            rho_min: f64::INFINITY,
            evals: 0,
        };
        (straight, 0.0, 1)
    }
}

/// Writes into `b` the sample `du` past `a`, or the piece's end (its derivatives from the
/// left) when that reaches or passes `hi`. Field by field: each evaluation then writes its
/// derivatives straight into `b`, where a `Sample` built and assigned was copied into it.
fn end_sample(curve: &NurbsCurve, a: &Sample, du: f64, hi: f64, b: &mut Sample) {
    if du >= hi - a.u {
        b.u = hi;
        b.d = curve.derivs_from_left(hi);
    } else {
        b.u = a.u + du;
        b.d = curve.derivs(b.u);
    }
}

/// Unit vector along `v` (zero stays zero).
pub(crate) fn unit(v: &Point) -> Point {
    lanes::unit::<{ crate::vocab::MAX_AXES }>(v)
}

/// Arc length of a gently curved piece from its chord and sagitta (`L + 8h²/(3L)`, the
/// circular-arc expansion); exact to far below a micron for chord-bounded pieces.
fn arc_length_estimate(chord: f64, sagitta: f64) -> f64 {
    if chord > 0.0 {
        chord + 8.0 * sagitta * sagitta / (3.0 * chord)
    } else {
        0.0
    }
}
