//! Period mode: one segment per interpolation period along the planned speed profile
//! (seed 001's direct interpolation).
//!
//! The planner's segments form a grid along the path with a trapezoidal speed profile on each.
//! At every period boundary `k T` the stepper asks the profile how far along the piece the
//! machine should be; the difference to where it is now is the step's planned length `ΔL`.
//! Under acceleration that is `v T + a T²/2`, not `v T`: this is how acceleration is accounted
//! for, and why the Taylor update (exact in arc length, not in time) is fed lengths, not speeds.
//!
//! The step's end parameter is predicted (Taylor, or Hamming once three equally timed steps
//! exist) and corrected (Lagrange/secant on the step length `L(u) = |C(u) - C(u_i)|`, seed 001
//! eq. 14, until the fluctuation `|L - ΔL| / ΔL` is within tolerance or the correction cap is
//! hit). With one node only, the secant's second node is the tangent line at the first
//! (`L'(u) = (C(u) - C(u_i))·C'(u) / L`, known from the same evaluation): Newton. The Hamming
//! predictor supplies a genuine second node (eq. 13) the first time a correction is needed.
//! The corrected parameter, never the prediction, is what later predictions extrapolate from.
//!
//! A piece (block, or curve part between corner knots) always ends exactly on its end point with
//! a partial period; the next piece starts on the same time grid.
//!
//! Every step obeys the certified chord bound ([`certify`](super::certify)): a step counts as
//! within the tolerance only when its bound holds, and one that is not is cut back until it
//! does. The measured error is reported beside the bound.

use super::certify::certify;
use super::chord::{Sample, chord_error, chord_error_estimate};
use super::planner::{PathLimits, PlannedSegment};
use super::predictor::{History, hamming_increments, taylor_increment};
use super::{PlanSettings, Segment};
use crate::gcode::Block;
use crate::geometry::NurbsCurve;
use crate::vocab::Predictor;
use std::sync::Arc;

/// Extra steps at most to close a piece whose profile ended short of the curve's end.
const MAX_CLOSING_STEPS: u32 = 256;

/// Below this fraction of the tolerance the Hermite model's chord error is trusted as is.
const CHORD_CHECK_FRACTION: f64 = 0.5;

/// A step's chord error as measured (or estimated, well below the tolerance) and its
/// certified bound; decisions use the bound.
#[derive(Debug, Clone, Copy)]
struct Chord {
    error: f64,
    bound: f64,
}

/// Samples the planned profile once per period.
#[derive(Debug)]
pub struct PeriodStepper {
    settings: PlanSettings,
    /// Planned time at the start of the next grid segment (s).
    clock: f64,
    /// Index of the next period boundary: it is at `tick * T`.
    tick: u64,
    /// Planned time of the current position.
    now: f64,
    /// Current position on the current piece.
    at: Option<Sample>,
    /// Distance along the current piece: where the stepper is, and where the next grid segment
    /// starts, by the profile.
    s_here: f64,
    s_grid: f64,
    /// Corrected parameters of equally timed steps, for the Hamming predictor.
    history: History,
    /// Speed of the last step (mm/s).
    prev_speed: f64,
    /// The path's corner not yet given to a step (infinite: none owed).
    corner_carry: f64,
    evals: u64,
    chord_checks: u64,
    certified_pieces: u64,
}

impl PeriodStepper {
    pub fn new(settings: PlanSettings) -> PeriodStepper {
        PeriodStepper {
            settings,
            clock: 0.0,
            tick: 1,
            now: 0.0,
            at: None,
            s_here: 0.0,
            s_grid: 0.0,
            history: History::default(),
            prev_speed: 0.0,
            corner_carry: f64::INFINITY,
            evals: 0,
            chord_checks: 0,
            certified_pieces: 0,
        }
    }

    pub fn evals(&self) -> u64 {
        self.evals
    }

    pub fn chord_checks(&self) -> u64 {
        self.chord_checks
    }

    /// Bézier pieces the steps' certificates examined.
    pub fn certified_pieces(&self) -> u64 {
        self.certified_pieces
    }

    /// Takes one planned grid segment and emits the period steps that end inside it.
    pub fn push(&mut self, planned: &PlannedSegment, sink: &mut dyn FnMut(Segment)) {
        let geo = &planned.geo;
        // Corner control's stop goes with the first period step of the segment, and so does
        // the path's corner; the steps inside a C1 piece meet without one, and the piece's
        // closing steps take the corner it ends in.
        let mut dwell = geo.corner_dwell_s;
        // A segment shorter than a period step leaves its corner to the next step.
        let mut corner = self.corner_carry.min(planned.path.entry);
        let exit = if geo.last_of_piece {
            planned.path.exit
        } else {
            f64::INFINITY
        };
        let emit = &mut |mut s: Segment| {
            s.corner_dwell_s = std::mem::take(&mut dwell);
            s.path = PathLimits {
                cruise: planned.path.cruise,
                entry: std::mem::replace(&mut corner, f64::INFINITY),
                exit: f64::INFINITY,
            };
            sink(s)
        };
        let curve = &geo.block.curve;
        if geo.first_of_piece || self.at.is_none() {
            self.at = Some(Sample::at(curve, geo.u_start));
            self.evals += 1;
            self.s_here = 0.0;
            self.s_grid = 0.0;
            self.history.reset();
        }
        let period = self.settings.period_s;
        let duration = planned.profile.duration();
        let end_time = self.clock + duration;
        loop {
            let t = self.tick as f64 * period;
            // The piece's last tick is taken by the closing step below.
            let inside = if geo.last_of_piece {
                t < end_time - 1e-12
            } else {
                t <= end_time
            };
            if !inside {
                break;
            }
            let target = self.s_grid + planned.profile.distance_at(t - self.clock);
            let full_period = (t - self.now - period).abs() < 1e-9;
            if target > self.s_here + 1e-12 {
                self.step(&geo.block, geo.u_end, target, t, full_period, emit);
            } else if !full_period {
                self.history.reset();
            }
            self.tick += 1;
        }
        self.clock = end_time;
        self.s_grid += geo.arc;
        if geo.last_of_piece {
            self.close_piece(&geo.block, geo.u_end, geo.last_of_block, &mut |mut s| {
                s.path.exit = exit;
                emit(s)
            });
        }
        self.corner_carry = corner;
    }

    /// One period step to the profile distance `target`, ending at time `t`.
    fn step(
        &mut self,
        block: &Arc<Block>,
        piece_end: f64,
        target: f64,
        t: f64,
        full_period: bool,
        emit: &mut dyn FnMut(Segment),
    ) {
        let curve = &block.curve;
        let a = self.at.expect("a piece is open");
        let ds = target - self.s_here;
        let rho = a.d.curvature_radius();
        // Chord of an arc of length ds on the local circle.
        let want = if rho.is_finite() {
            ds - ds * ds * ds / (24.0 * rho * rho)
        } else {
            ds
        };
        let mut evals = 0u32;
        let taylor = taylor_increment(&a, want).unwrap_or((piece_end - a.u) * 0.5);
        let (first_du, second_du) = match (self.settings.predictor, self.history.full()) {
            (Predictor::Hamming, Some(h)) if full_period => {
                let (d1, d2) = hamming_increments(h);
                (d1, Some(d2))
            }
            _ => (taylor, None),
        };
        let clamp = |u: f64| u.clamp(a.u + 1e-15 * (piece_end - a.u), piece_end);
        let eval = |u: f64, evals: &mut u32| -> (Sample, f64) {
            *evals += 1;
            let d = if u >= piece_end {
                curve.derivs_from_left(piece_end)
            } else {
                curve.derivs(u)
            };
            let s = Sample { u, d };
            let len = (s.d.point - a.d.point).norm();
            (s, len)
        };
        let mut best = eval(clamp(a.u + first_du), &mut evals);
        let mut other: Option<(Sample, f64)> = None;
        let tol = self.settings.fluctuation_tolerance;
        let fluct = |len: f64| (len - want).abs() / want;
        let mut corrections = 0;
        while fluct(best.1) > tol && corrections < self.settings.max_corrections {
            if other.is_none()
                && let Some(d2) = second_du
            {
                // Hamming: eq. 13 is the second node of the Lagrange correction.
                let node = eval(clamp(a.u + d2), &mut evals);
                other = Some(node);
            }
            let next_u = match other {
                Some(o) if o.1 != best.1 => {
                    best.0.u + (o.0.u - best.0.u) * (want - best.1) / (o.1 - best.1)
                }
                _ => {
                    let slope = (best.0.d.point - a.d.point).dot(&best.0.d.d1) / best.1;
                    best.0.u + (want - best.1) / slope
                }
            };
            if !next_u.is_finite() {
                break;
            }
            let node = eval(clamp(next_u), &mut evals);
            corrections += 1;
            // Keep the two nodes closest to the target.
            if fluct(node.1) <= fluct(best.1) {
                other = Some(best);
                best = node;
            } else if other.is_none_or(|o| fluct(node.1) < fluct(o.1)) {
                other = Some(node);
            }
        }
        let (mut b, mut len) = best;
        let mut chord_err = self.chord_error(curve, &a, &b, &mut evals);
        let shortened = chord_err.bound > self.settings.tolerance_mm;
        if shortened {
            // The chord-length correction can land past a hairpin (|C(u) - C(u_i)| is not
            // monotone there) or the profile can ask for more than the curve allows: the step is
            // cut back until its chord is within tolerance. The profile is followed by distance,
            // so the next steps make up the lag.
            (b, chord_err) = self.shorten_to_tolerance(curve, &a, b, &mut evals);
            len = (b.d.point - a.d.point).norm();
        }
        if full_period && !shortened {
            self.history.push(b.u);
        } else {
            self.history.reset();
            self.history.push(b.u);
        }
        let fluctuation = Some(fluct(len));
        self.emit_step(
            block,
            a,
            b,
            len,
            t,
            fluctuation,
            chord_err,
            evals,
            false,
            emit,
        );
    }

    /// Bisects the end of a step from `a` to `b` back towards `a` to the longest step whose
    /// chord error is within the tolerance.
    fn shorten_to_tolerance(
        &mut self,
        curve: &NurbsCurve,
        a: &Sample,
        b: Sample,
        evals: &mut u32,
    ) -> (Sample, Chord) {
        let tol = self.settings.tolerance_mm;
        let (mut lo, mut hi) = (a.u, b.u);
        let mut best: Option<(Sample, Chord)> = None;
        for _ in 0..48 {
            let mid = 0.5 * (lo + hi);
            if mid <= lo || mid >= hi {
                break;
            }
            let sample = Sample::at(curve, mid);
            *evals += 1;
            let err = self.chord_error(curve, a, &sample, evals);
            if err.bound <= tol {
                lo = mid;
                best = Some((sample, err));
            } else {
                hi = mid;
            }
            if best.is_some() && hi - lo <= 1e-3 * (hi - a.u) {
                break;
            }
        }
        best.unwrap_or_else(|| {
            let sample = Sample::at(curve, hi);
            *evals += 1;
            let err = self.chord_error(curve, a, &sample, evals);
            (sample, err)
        })
    }

    /// The last step of a piece: exactly onto its end point.
    fn close_piece(
        &mut self,
        block: &Arc<Block>,
        piece_end: f64,
        last_of_block: bool,
        emit: &mut dyn FnMut(Segment),
    ) {
        let mut a = self.at.expect("a piece is open");
        if piece_end > a.u {
            let curve = &block.curve;
            let b = Sample {
                u: piece_end,
                d: curve.derivs_from_left(piece_end),
            };
            let mut evals = 1;
            let mut chord_err = self.chord_error(curve, &a, &b, &mut evals);
            // The profile's length of the piece comes from chord-based arc estimates; around a
            // hairpin they fall short, and the profile ends before the curve does. Rather than
            // cut across, the rest is covered in steps within tolerance, each taking half of
            // the remaining time (the speed they imply is reported as it is).
            let mut extra = 0;
            while chord_err.bound > self.settings.tolerance_mm && extra < MAX_CLOSING_STEPS {
                let (mid, err) = self.shorten_to_tolerance(curve, &a, b, &mut evals);
                let len = (mid.d.point - a.d.point).norm();
                let t = self.now + 0.5 * (self.clock - self.now);
                self.emit_step(block, a, mid, len, t, None, err, evals, false, emit);
                a = mid;
                evals = 0;
                chord_err = self.chord_error(curve, &a, &b, &mut evals);
                extra += 1;
            }
            let len = (b.d.point - a.d.point).norm();
            let t = self.clock;
            self.emit_step(
                block,
                a,
                b,
                len,
                t,
                None,
                chord_err,
                evals,
                last_of_block,
                emit,
            );
        }
        self.at = None;
    }

    #[allow(clippy::too_many_arguments)]
    fn emit_step(
        &mut self,
        block: &Arc<Block>,
        a: Sample,
        b: Sample,
        len: f64,
        t: f64,
        fluctuation: Option<f64>,
        chord_err: Chord,
        evals: u32,
        last_of_block: bool,
        emit: &mut dyn FnMut(Segment),
    ) {
        self.evals += u64::from(evals);
        let rho_end = b.d.curvature_radius();
        let arc = if rho_end.is_finite() && rho_end > 0.0 {
            len + len * len * len / (24.0 * rho_end * rho_end)
        } else {
            len
        };
        let duration = t - self.now;
        let v = if duration > 0.0 { arc / duration } else { 0.0 };
        let v_prev = self.prev_speed;
        self.s_here += arc;
        self.now = t;
        self.at = Some(b);
        emit(Segment {
            block: Arc::clone(block),
            u_end: b.u,
            start: a.d.point,
            end: b.d.point,
            length: len,
            chord_error: chord_err.error,
            chord_bound: chord_err.bound,
            v_entry: v_prev,
            v_exit: v,
            v_peak: v,
            speed_limit: v,
            // Set by the caller ([`PeriodStepper::push`]).
            path: PathLimits::ZERO,
            duration,
            rho_end,
            evals,
            fluctuation,
            last_of_block,
            corner_dwell_s: 0.0,
        });
        self.prev_speed = v;
    }

    /// The chord error of a step (the Hermite model when it is well below the tolerance, the
    /// full measurement otherwise) and its certified bound. A degree-1 curve's bound is zero:
    /// a piece between corner knots is one span of a rational line, on its chord.
    fn chord_error(
        &mut self,
        curve: &NurbsCurve,
        a: &Sample,
        b: &Sample,
        evals: &mut u32,
    ) -> Chord {
        if curve.degree() == 1 {
            return Chord {
                error: 0.0,
                bound: 0.0,
            };
        }
        let tol = self.settings.tolerance_mm;
        let estimate = chord_error_estimate(a, b, tol);
        let (error, at) = if estimate < CHORD_CHECK_FRACTION * tol {
            (estimate, f64::NAN)
        } else {
            self.chord_checks += 1;
            let measured = chord_error(curve, a, b, tol);
            *evals += measured.evals;
            (measured.max, measured.at)
        };
        let certificate = certify(curve, a.u, b.u, &a.d.point, &b.d.point, tol, at);
        self.certified_pieces += u64::from(certificate.pieces);
        Chord {
            error,
            bound: certificate.bound,
        }
    }
}
