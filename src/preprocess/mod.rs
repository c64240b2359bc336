//! The preprocessor: the producer thread's algorithm, from blocks to planned segments.
//!
//! ```text
//! Block ──► Segmenter ──► GeoSegment ──► Planner (look-ahead window) ──► PlannedSegment
//!           chord-bounded                 speeds under a_T, at rest          │
//!           pieces, cruise limits         at both ends                       ├─ chord mode: one Segment each
//!                                                                            └─ period mode: PeriodStepper,
//!                                                                               one Segment per period
//! ```
//!
//! **Segmenter** ([`segmenter`]): cuts each curve into the longest chords whose *true* chord
//! error ([`chord`]) is within `chord_tolerance_mm`, predicting each parameter step with the
//! Taylor or Hamming predictor ([`predictor`]) and correcting it on the measured error. Each
//! segment carries its cruise limit: the programmed feed clamped by the machine's maximum, the
//! normal-acceleration speed `sqrt(a_N rho)` over its tightest radius and, in period mode, the
//! chord-error speed. Corners between blocks (and at corner knots inside a curve) get a junction
//! speed from the junction-deviation rule with the chord tolerance as the deviation.
//!
//! **Planner** ([`planner`]): a bounded look-ahead window with a backward pass, so motion
//! decelerates at `a_T` ahead of tight curvature and corners, and starts and ends at rest.
//!
//! **Period stepper** ([`period`]): in period mode the planned speed profile is sampled once per
//! interpolation period (seed 001's direct interpolation): the distance the profile covers in
//! the period becomes a step length, the predictor proposes the parameter, and Lagrange
//! corrections bring the step length within the fluctuation tolerance.
//!
//! Memory is bounded: the segmenter holds one block, the planner its window, the stepper one
//! segment. Segments hold their block through an [`Arc`], so a block lives exactly as long as a
//! segment of it is in flight. Nothing here does I/O or reads a clock.

pub mod bound;
pub mod certify;
pub mod chord;
pub mod corners;
pub mod period;
pub mod planner;
pub mod predictor;
pub mod segmenter;

use std::sync::Arc;

use crate::gcode::Block;
use crate::geometry::{Point, running_min};
use crate::vocab::{Predictor, Segmentation};

pub use period::PeriodStepper;
pub use planner::{PathLimits, PlannedSegment, Planner, Profile};
pub use segmenter::{Segmenter, SegmenterStats};

/// Everything the preprocessor needs from the configuration, in SI-ish units (mm, s).
#[derive(Debug, Clone, PartialEq)]
pub struct PlanSettings {
    pub predictor: Predictor,
    pub segmentation: Segmentation,
    /// Chord tolerance (mm).
    pub tolerance_mm: f64,
    /// Longest segment (mm).
    pub max_segment_mm: f64,
    /// Interpolation period (s).
    pub period_s: f64,
    /// Machine maximum feed (mm/s).
    pub max_feed_mm_per_s: f64,
    /// Rapid (`G0`) speed (mm/s): the machine's maximum as far as the output can step it,
    /// so that planned rapid times are the executed ones.
    pub rapid_feed_mm_per_s: f64,
    /// mm/s².
    pub max_normal_accel_mm_per_s2: f64,
    /// mm/s².
    pub max_tangential_accel_mm_per_s2: f64,
    pub lookahead: usize,
    pub fluctuation_tolerance: f64,
    pub max_corrections: u32,
    /// Corner control, per condition ([`corners`]); empty: off.
    pub corners: Vec<corners::CornerRule>,
    /// Positioning moves (rapids, spark-off travel) start and end at a standstill: under a
    /// jerk limit the tick core's S-curve brings them to rest at their end.
    pub rapid_stops: bool,
    /// The fastest each axis can be stepped (mm/s): one step per tick (infinite for the axes
    /// the machine does not have). A segment is planned no faster than its direction allows.
    pub axis_cap_mm_per_s: [f64; crate::vocab::MAX_AXES],
}

/// A chord of a curve piece, before speed planning.
#[derive(Debug, Clone)]
pub struct GeoSegment {
    pub block: Arc<Block>,
    pub u_start: f64,
    pub u_end: f64,
    pub start: Point,
    pub end: Point,
    /// Chord length (mm).
    pub chord: f64,
    /// Arc length of the curve piece (mm), from chord and sagitta.
    pub arc: f64,
    /// True chord error (mm), as measured.
    pub chord_error: f64,
    /// Certified upper bound on the chord error (mm): the curve provably stays this close to
    /// the chord ([`certify`]).
    pub chord_bound: f64,
    /// Smallest radius of curvature seen on the piece (mm).
    pub rho_min: f64,
    /// Radius of curvature at the end (mm).
    pub rho_end: f64,
    /// Cruise limit on the segment (mm/s).
    pub feed_limit: f64,
    /// The same without the programmed feed (the machine's maximum in its place): how far a
    /// feed override above 100 % may raise the cruise (mm/s).
    pub speed_limit: f64,
    /// Speed limit at the segment's start junction (mm/s): a corner's speed on the first
    /// segment of a piece, infinite inside a smooth piece.
    pub entry_limit: f64,
    /// Curve evaluations spent on this segment.
    pub evals: u32,
    /// First segment of a C1 piece (a block, or the part of a curve after a corner knot).
    pub first_of_piece: bool,
    /// Last segment of a C1 piece.
    pub last_of_piece: bool,
    /// Last segment of its block.
    pub last_of_block: bool,
    /// Corner control's stop at the segment's start (s): the path stops there this long.
    pub corner_dwell_s: f64,
}

/// What the preprocessor produces: one straight move of the path with its planned timing.
#[derive(Debug, Clone)]
pub struct Segment {
    pub block: Arc<Block>,
    /// Curve parameter at the end (the program's knot units for NURBS blocks).
    pub u_end: f64,
    pub start: Point,
    pub end: Point,
    /// Chord length (mm).
    pub length: f64,
    /// True chord error (mm); in period mode a model estimate unless it came near the tolerance.
    pub chord_error: f64,
    /// Certified upper bound on the chord error (mm), never above the tolerance
    /// ([`certify`]).
    pub chord_bound: f64,
    /// Speeds at the start and end of the segment and the highest inside it (mm/s).
    pub v_entry: f64,
    pub v_exit: f64,
    pub v_peak: f64,
    /// The highest cruise a feed override may ask for (mm/s): the segment's limits without
    /// the programmed feed ([`GeoSegment::speed_limit`]); `v_peak` where there is no such
    /// freedom (period mode).
    pub speed_limit: f64,
    /// The path's own limits, without the programmed feed: what the servo's own motion (a
    /// turn-back, a re-advance) may go at.
    pub path: PathLimits,
    /// Planned time over the segment (s).
    pub duration: f64,
    /// Radius of curvature at the end (mm; infinite on straight stretches).
    pub rho_end: f64,
    /// Curve evaluations spent on this segment.
    pub evals: u32,
    /// Period mode: `|step - planned| / planned` (seed 001 eq. 16); `None` in chord mode and
    /// on the step that closes a piece.
    pub fluctuation: Option<f64>,
    pub last_of_block: bool,
    /// Corner control's stop at the segment's start (s): the electrode holds there this long.
    pub corner_dwell_s: f64,
}

/// The fastest the outputs can step a move `d` of length `chord` along it (mm/s): one step
/// per tick (`axis_cap`, mm/s per axis) on the axis that moves most for its step size.
///
/// On the first `N` coordinates of `d` (the rest zero): a three-axis curve's step costs half.
pub fn step_cap<const N: usize>(
    axis_cap: &[f64; crate::vocab::MAX_AXES],
    d: &Point,
    chord: f64,
) -> f64 {
    let mut cap = f64::INFINITY;
    for i in 0..N {
        let x = d[i].abs();
        if x > 0.0 {
            // `f64::min`'s result (an infinite cap on a zero chord is a NaN, passed over),
            // in fewer instructions, on every segment and every sample of the bound.
            cap = running_min(cap, axis_cap[i] * chord / x);
        }
    }
    cap
}

/// The junction-deviation corner speed between two unit tangents (Grbl's rule): the speed at
/// which a circle of normal acceleration `a_N` tangent to both directions stays within
/// `tolerance` of the corner. Zero for a reversal, infinite for a straight continuation.
pub fn corner_speed(incoming: &Point, outgoing: &Point, settings: &PlanSettings) -> f64 {
    let cos_theta = -incoming.dot(outgoing);
    if cos_theta > 0.999_999 {
        0.0
    } else if cos_theta < -0.999_999_999 {
        f64::INFINITY
    } else {
        let sin_half = (0.5 * (1.0 - cos_theta)).sqrt();
        (settings.max_normal_accel_mm_per_s2 * settings.tolerance_mm * sin_half / (1.0 - sin_half))
            .sqrt()
    }
}

/// Fraction of the acceleration limits the planner leaves unused: headroom for what the plan
/// cannot see exactly (step lengths within the fluctuation tolerance, arc against chord, the
/// curvature between the points where it was sampled), so measured figures stay within limits.
pub const PLANNING_MARGIN: f64 = 1e-3;

/// Counters of a preprocessing run.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PreprocessStats {
    pub blocks: u64,
    pub segmenter: SegmenterStats,
    /// Output segments (equal to the segmenter's in chord mode; periods in period mode).
    pub segments: u64,
    /// Curve evaluations of the period stepper (period mode).
    pub step_evals: u64,
    /// Period-mode steps whose chord error needed the full measurement.
    pub chord_checks: u64,
    /// Bézier pieces the period steps' certificates examined (the segmenter counts its own).
    pub certified_pieces: u64,
}

/// Segmenter, planner and (in period mode) period stepper, wired together.
#[derive(Debug)]
pub struct Preprocessor {
    segmenter: Segmenter,
    corners: corners::CornerControl,
    planner: Planner,
    stepper: Option<PeriodStepper>,
    blocks: u64,
    segments: u64,
}

impl Preprocessor {
    pub fn new(settings: PlanSettings) -> Preprocessor {
        let accel = settings.max_tangential_accel_mm_per_s2 * (1.0 - PLANNING_MARGIN);
        let planner = Planner::new(accel, settings.lookahead);
        let period_mode = settings.segmentation == Segmentation::Period;
        let stepper = period_mode.then(|| PeriodStepper::new(settings.clone()));
        let mut grid = settings;
        if period_mode {
            // The output segments are the periods; the segmenter only lays the planning grid,
            // which needs no length cap (the cap bounds loop-buffer blocks in chord mode).
            grid.max_segment_mm = f64::INFINITY;
        }
        Preprocessor {
            corners: corners::CornerControl::new(grid.corners.clone()),
            segmenter: Segmenter::new(grid),
            planner,
            stepper,
            blocks: 0,
            segments: 0,
        }
    }

    pub fn settings(&self) -> &PlanSettings {
        self.segmenter.settings()
    }

    /// Feeds one block; finished segments go to `emit` (with a delay of up to the look-ahead).
    pub fn push_block<F: FnMut(Segment)>(&mut self, block: Arc<Block>, mut emit: F) {
        self.blocks += 1;
        let planner = &mut self.planner;
        let stepper = &mut self.stepper;
        let segments = &mut self.segments;
        let corners = &mut self.corners;
        let mut plan = |geo| {
            planner.push(geo, |planned| {
                forward(stepper, planned, &mut |s| {
                    *segments += 1;
                    emit(s)
                })
            })
        };
        if corners.is_off() {
            self.segmenter.segment_block(&block, plan);
        } else {
            self.segmenter
                .segment_block(&block, |geo| corners.push(geo, &mut plan));
        }
    }

    /// End of the program: flushes the window; the last segment ends at rest.
    pub fn finish<F: FnMut(Segment)>(&mut self, mut emit: F) {
        let stepper = &mut self.stepper;
        let segments = &mut self.segments;
        let planner = &mut self.planner;
        self.corners.finish(|geo| {
            planner.push(geo, |planned| {
                forward(stepper, planned, &mut |s| {
                    *segments += 1;
                    emit(s)
                })
            })
        });
        self.planner.finish(|planned| {
            forward(stepper, planned, &mut |s| {
                *segments += 1;
                emit(s)
            })
        });
    }

    pub fn stats(&self) -> PreprocessStats {
        let (step_evals, chord_checks, certified_pieces) =
            self.stepper.as_ref().map_or((0, 0, 0), |s| {
                (s.evals(), s.chord_checks(), s.certified_pieces())
            });
        PreprocessStats {
            blocks: self.blocks,
            segmenter: self.segmenter.stats,
            segments: self.segments,
            step_evals,
            chord_checks,
            certified_pieces,
        }
    }
}

fn forward(
    stepper: &mut Option<PeriodStepper>,
    planned: PlannedSegment,
    emit: &mut dyn FnMut(Segment),
) {
    match stepper {
        Some(stepper) => stepper.push(&planned, emit),
        None => emit(chord_segment(planned)),
    }
}

fn chord_segment(p: PlannedSegment) -> Segment {
    let g = p.geo;
    Segment {
        u_end: g.u_end,
        start: g.start,
        end: g.end,
        length: g.chord,
        chord_error: g.chord_error,
        chord_bound: g.chord_bound,
        v_entry: p.profile.v_entry,
        v_exit: p.profile.v_exit,
        v_peak: p.profile.v_peak,
        speed_limit: g.speed_limit,
        path: p.path,
        duration: p.profile.duration(),
        rho_end: g.rho_end,
        evals: g.evals,
        fluctuation: None,
        last_of_block: g.last_of_block,
        corner_dwell_s: g.corner_dwell_s,
        block: Arc::clone(&g.block),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vocab::MAX_AXES;

    #[test]
    fn the_step_cap_is_the_least_axis_cap_bit_for_bit() {
        // Against `f64::min` over the moving axes, with zero components, infinite caps (no
        // step size) and zero chords, whose NaN quotients both pass over.
        let mut rng = crate::rng::SplitMix64::new(5);
        for case in 0..20_000 {
            let mut axis_cap = [0.0; MAX_AXES];
            let mut d = Point::zeros();
            for i in 0..MAX_AXES {
                axis_cap[i] = match rng.below(4) {
                    0 => f64::INFINITY,
                    _ => rng.uniform(0.1, 100.0),
                };
                d[i] = match rng.below(3) {
                    0 => 0.0,
                    _ => rng.uniform(-2.0, 2.0),
                };
            }
            let chord = if case % 5 == 0 {
                0.0
            } else {
                rng.uniform(0.0, 1.0)
            };
            let expected = (0..3)
                .filter(|&i| d[i] != 0.0)
                .fold(f64::INFINITY, |cap, i| {
                    cap.min(axis_cap[i] * chord / d[i].abs())
                });
            assert_eq!(
                step_cap::<3>(&axis_cap, &d, chord).to_bits(),
                expected.to_bits()
            );
        }
    }
}
