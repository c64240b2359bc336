//! Look-ahead feed planning under a tangential acceleration limit (seed 001 §2.3, in the form
//! Grbl's `planner.c` made familiar).
//!
//! Each segment arrives with a cruise limit (program feed, machine maximum, normal acceleration
//! over its tightest radius, and in period mode the chord-error speed) and its entry junction
//! limit (a corner's speed, infinite inside a smooth piece). The planner keeps the last
//! `lookahead_segments` segments in a window and knows, for each, the highest entry speed
//! from which the machine can still stop by the end of the window (`v_back`, the backward pass).
//! It never walks the window to find it: in squared speeds `v_back` is a suffix minimum over
//! the junctions ahead, which a monotonic queue answers at the window's front (see
//! [`Planner`]), so a push costs O(1) amortised whatever the window's length.
//!
//! When the window is full the oldest segment is released: its entry speed was fixed when its
//! predecessor left, its exit speed is the smaller of the successor's `v_back` and what the
//! acceleration limit allows from the entry (the forward pass, one segment at a time). Inside
//! the segment the speed follows a trapezoid (accelerate, cruise, decelerate at `a_T`), so
//! motion slows ahead of tight curvature, starts and ends at rest, and never needs more than the
//! window to stop. A window that is short against the braking distance costs speed, never safety.

use std::collections::VecDeque;

use super::GeoSegment;
use crate::geometry::{running_max, running_min};

// The minima and maxima of the speeds here, several a segment, are `running_min` and
// `running_max` from an operand that is a number: `f64::min` and `f64::max` bit for bit, in a
// fifth of the instructions. The numbers: cruise limits are minima started from the
// programmed feed, junctions and entry speeds minima of those, and `0.0` is one.

/// Speed profile over one segment: trapezoid (or triangle) at constant tangential acceleration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Profile {
    pub v_entry: f64,
    pub v_exit: f64,
    /// Highest speed reached inside the segment.
    pub v_peak: f64,
    pub accel: f64,
    pub length: f64,
    t_accel: f64,
    t_cruise: f64,
    t_decel: f64,
}

impl Profile {
    /// The fastest profile over `length` from `v_entry` to `v_exit` under `cruise` and `accel`.
    /// The end speeds must be reachable (the planner guarantees it); tiny rounding is absorbed.
    pub fn new(length: f64, v_entry: f64, v_exit: f64, cruise: f64, accel: f64) -> Profile {
        let peak_sq = (2.0 * accel * length + v_entry * v_entry + v_exit * v_exit) / 2.0;
        let v_peak = running_max(
            running_max(
                running_min(cruise, running_max(0.0, peak_sq).sqrt()),
                v_entry,
            ),
            v_exit,
        );
        let d_accel = (v_peak * v_peak - v_entry * v_entry) / (2.0 * accel);
        let d_decel = (v_peak * v_peak - v_exit * v_exit) / (2.0 * accel);
        let d_cruise = running_max(0.0, length - d_accel - d_decel);
        let t_cruise = if v_peak > 0.0 { d_cruise / v_peak } else { 0.0 };
        Profile {
            v_entry,
            v_exit,
            v_peak,
            accel,
            length,
            t_accel: (v_peak - v_entry) / accel,
            t_cruise,
            t_decel: (v_peak - v_exit) / accel,
        }
    }

    /// Planned time over the segment (s).
    pub fn duration(&self) -> f64 {
        self.t_accel + self.t_cruise + self.t_decel
    }

    /// Distance covered `t` seconds into the segment, clamped to the segment.
    pub fn distance_at(&self, t: f64) -> f64 {
        let a = self.accel;
        let s = if t <= 0.0 {
            0.0
        } else if t < self.t_accel {
            self.v_entry * t + 0.5 * a * t * t
        } else {
            let d_accel = self.v_entry * self.t_accel + 0.5 * a * self.t_accel * self.t_accel;
            let t2 = t - self.t_accel;
            if t2 < self.t_cruise {
                d_accel + self.v_peak * t2
            } else {
                let t3 = (t2 - self.t_cruise).min(self.t_decel);
                d_accel + self.v_peak * self.t_cruise + self.v_peak * t3 - 0.5 * a * t3 * t3
            }
        };
        s.min(self.length)
    }

    /// Speed `t` seconds into the segment.
    pub fn speed_at(&self, t: f64) -> f64 {
        if t < self.t_accel {
            self.v_entry + self.accel * t.max(0.0)
        } else if t < self.t_accel + self.t_cruise {
            self.v_peak
        } else {
            let t3 = (t - self.t_accel - self.t_cruise).min(self.t_decel);
            self.v_peak - self.accel * t3
        }
    }
}

/// A segment with its planned speeds, lent to the caller as the segment leaves the window: a
/// `GeoSegment` is over 200 bytes, and handing it over by value cost one more copy of it a
/// segment.
#[derive(Debug, Clone, Copy)]
pub struct PlannedSegment<'a> {
    pub geo: &'a GeoSegment,
    pub profile: Profile,
    /// What the path allows whatever the programmed feed: what a turn-back along it may go at.
    pub path: PathLimits,
}

/// A segment's speed limits from the path alone, without the programmed feed (mm/s): its
/// cruise ([`GeoSegment::speed_limit`]) and its two junctions (the corner's speed and both
/// neighbours' cruise; 0 where the path starts or stops). The servo's own motion (a turn-back
/// at the retract feed, the re-advance after it) goes by these, not by the feed's plan. Unlike
/// the plan's entry and exit speeds they are not braked over a window: going backwards the
/// interpolator only sees the block in hand, which at a retract feed is ample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathLimits {
    pub cruise: f64,
    pub entry: f64,
    pub exit: f64,
}

impl PathLimits {
    /// No freedom at all (a placeholder block).
    pub const ZERO: PathLimits = PathLimits {
        cruise: 0.0,
        entry: 0.0,
        exit: 0.0,
    };
}

#[derive(Debug)]
struct Entry {
    geo: GeoSegment,
    /// Position in the job's sequence of segments.
    seq: u64,
    /// Arc length from the planner's origin to the segment's start (mm).
    before: f64,
    /// Entry junction limit (mm/s): corner speed and both neighbours' cruise limits.
    junction: f64,
    /// The same without the programmed feed ([`PathLimits::entry`]).
    corner: f64,
}

/// A junction that caps the entry speed of segment `seq`, as a key of the suffix minimum:
/// `J² + 2a·before`, the squared speed it allows, shifted by the arc length before it.
#[derive(Debug, Clone, Copy)]
struct Cap {
    seq: u64,
    key: f64,
}

/// Prefix arc length (mm) past which the planner subtracts its origin from every stored
/// position, so keys stay small and their rounding far below any speed that matters.
const REBASE_AFTER_MM: f64 = 1e6;

/// The look-ahead planner. Holds at most `lookahead` segments.
///
/// The backward pass is kept implicitly. In squared speeds, with `s_j` the arc length before
/// segment `j`, `S` the arc length at the end of the window and `J_k` the entry junction limit
/// of segment `k`, the highest entry speed from which segment `j` can still stop in time is
///
/// ```text
/// v_back(j)² = min( min over k ≥ j of (J_k² + 2a·s_k),  2a·S ) − 2a·s_j
/// ```
///
/// (stop at `k`'s junction, or at the window's end, whichever binds first). The inner minimum is
/// a suffix minimum over a window that only grows at the back and shrinks at the front, so a
/// monotonic queue of caps (`caps`, keys increasing front to back) answers it at the front in
/// O(1), and a push costs O(1) amortised however long the stretch without a binding junction.
/// Grbl walks its backward pass over the whole buffer; with a 1024-segment window on a smooth
/// curve that walk was most of the planner's time.
#[derive(Debug)]
pub struct Planner {
    /// Tangential acceleration (mm/s²).
    accel: f64,
    lookahead: usize,
    window: VecDeque<Entry>,
    caps: VecDeque<Cap>,
    /// Entry speed of the window's first segment (fixed when its predecessor left).
    v_start: f64,
    prev_cruise: f64,
    /// The previous segment's cruise without the programmed feed (0 at rest).
    prev_speed_limit: f64,
    /// Arc length from the origin to the end of the window (mm).
    travelled: f64,
    next_seq: u64,
}

impl Planner {
    pub fn new(accel: f64, lookahead: usize) -> Planner {
        let lookahead = lookahead.max(1);
        Planner {
            accel,
            lookahead,
            window: VecDeque::with_capacity(lookahead + 1),
            caps: VecDeque::with_capacity(lookahead + 1),
            v_start: 0.0,
            prev_cruise: 0.0,
            prev_speed_limit: 0.0,
            travelled: 0.0,
            next_seq: 0,
        }
    }

    /// Adds a segment; releases the oldest to `emit` when the window is full.
    pub fn push<F: FnMut(PlannedSegment)>(&mut self, geo: GeoSegment, mut emit: F) {
        if self.travelled > REBASE_AFTER_MM {
            self.rebase();
        }
        // `prev_cruise` starts at 0: the first segment of a job starts at rest.
        let junction = running_min(
            self.prev_cruise,
            running_min(geo.feed_limit, geo.entry_limit),
        );
        self.prev_cruise = geo.feed_limit;
        let corner = running_min(
            self.prev_speed_limit,
            running_min(geo.speed_limit, geo.entry_limit),
        );
        self.prev_speed_limit = geo.speed_limit;
        let seq = self.next_seq;
        self.next_seq += 1;
        let before = self.travelled;
        self.travelled += geo.arc;
        if junction.is_finite() {
            let key = junction * junction + 2.0 * self.accel * before;
            while self.caps.back().is_some_and(|c| c.key >= key) {
                self.caps.pop_back();
            }
            self.caps.push_back(Cap { seq, key });
        }
        self.window.push_back(Entry {
            geo,
            seq,
            before,
            junction,
            corner,
        });
        while self.window.len() > self.lookahead {
            self.release(&mut emit);
        }
    }

    /// Releases everything, ending at rest.
    pub fn finish<F: FnMut(PlannedSegment)>(&mut self, mut emit: F) {
        while !self.window.is_empty() {
            self.release(&mut emit);
        }
        self.prev_cruise = 0.0;
        self.prev_speed_limit = 0.0;
        self.travelled = 0.0;
    }

    /// Highest entry speed of the window's `i`-th segment that can still stop in time (the
    /// caps before it already dropped).
    fn v_back_at(&self, i: usize) -> f64 {
        let Some(entry) = self.window.get(i) else {
            return 0.0;
        };
        let two_a = 2.0 * self.accel;
        let end = two_a * self.travelled;
        // Caps before the segment were dropped when their segment left.
        let bound = self.caps.front().map_or(end, |c| running_min(end, c.key));
        // The segment's own junction, applied directly: the key's rounding must not lift a
        // speed above its limit.
        running_min(
            entry.junction,
            running_max(0.0, bound - two_a * entry.before).sqrt(),
        )
    }

    /// Plans the window's first segment, lends it to `emit`, then drops it from the window:
    /// lent in place, not moved out and handed over.
    fn release<F: FnMut(PlannedSegment)>(&mut self, emit: &mut F) {
        if self.window.is_empty() {
            return;
        }
        let v_back = self.v_back_at(0);
        // The leaving segment's caps go; the next one's bound starts at its own junction.
        if let Some(next) = self.window.get(1).map(|e| e.seq) {
            while self.caps.front().is_some_and(|c| c.seq < next) {
                self.caps.pop_front();
            }
        } else {
            self.caps.clear();
        }
        let v0 = running_min(v_back, self.v_start);
        let next_max = self.v_back_at(1);
        let path = PathLimits {
            cruise: self.window[0].geo.speed_limit,
            entry: self.window[0].corner,
            exit: self.window.get(1).map_or(0.0, |e| e.corner),
        };
        let geo = &self.window[0].geo;
        let v1 = running_min(next_max, (v0 * v0 + 2.0 * self.accel * geo.arc).sqrt());
        let profile = Profile::new(geo.arc, v0, v1, geo.feed_limit, self.accel);
        self.v_start = v1;
        emit(PlannedSegment { geo, profile, path });
        self.window.pop_front();
    }

    /// Moves the origin to the window's first segment (rarely: every [`REBASE_AFTER_MM`]).
    fn rebase(&mut self) {
        let origin = self.window.front().map_or(self.travelled, |e| e.before);
        let shift = 2.0 * self.accel * origin;
        for e in &mut self.window {
            e.before -= origin;
        }
        for c in &mut self.caps {
            c.key -= shift;
        }
        self.travelled -= origin;
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use proptest::prelude::*;

    use super::*;
    use crate::gcode::{Block, BlockKind};
    use crate::geometry::{NurbsCurve, point};

    fn segment(block: &Arc<Block>, arc: f64, feed_limit: f64, entry_limit: f64) -> GeoSegment {
        GeoSegment {
            block: Arc::clone(block),
            u_start: 0.0,
            u_end: 1.0,
            start: point(&[0.0, 0.0]),
            end: point(&[arc, 0.0]),
            chord: arc,
            arc,
            chord_error: 0.0,
            chord_bound: 0.0,
            rho_min: f64::INFINITY,
            rho_end: f64::INFINITY,
            feed_limit,
            speed_limit: feed_limit,
            entry_limit,
            evals: 0,
            first_of_piece: false,
            last_of_piece: false,
            last_of_block: false,
            corner_dwell_s: 0.0,
        }
    }

    /// The backward pass written out: every push walks the whole window (Grbl's way). The
    /// planner's implicit pass must agree with it.
    fn walked_plan(accel: f64, lookahead: usize, segs: &[(f64, f64, f64)]) -> Vec<(f64, f64)> {
        let mut window: VecDeque<(f64, f64, f64, f64)> = VecDeque::new(); // arc, feed, junction, v_back
        let (mut v_start, mut prev_cruise) = (0.0, 0.0);
        let mut out = Vec::new();
        let mut release = |window: &mut VecDeque<(f64, f64, f64, f64)>, v_start: &mut f64| {
            let (arc, _, _, vb) = window.pop_front().unwrap();
            let v0 = v_start.min(vb);
            let next = window.front().map_or(0.0, |n| n.3);
            let v1 = next.min((v0 * v0 + 2.0 * accel * arc).sqrt());
            *v_start = v1;
            out.push((v0, v1));
        };
        for &(arc, feed, entry) in segs {
            let junction = entry.min(feed).min(prev_cruise);
            prev_cruise = feed;
            window.push_back((
                arc,
                feed,
                junction,
                junction.min((2.0 * accel * arc).sqrt()),
            ));
            for j in (0..window.len() - 1).rev() {
                let next = window[j + 1].3;
                let e = &mut window[j];
                e.3 = e.2.min((next * next + 2.0 * accel * e.0).sqrt());
            }
            while window.len() > lookahead {
                release(&mut window, &mut v_start);
            }
        }
        while !window.is_empty() {
            release(&mut window, &mut v_start);
        }
        out
    }

    fn planned(accel: f64, lookahead: usize, segs: &[(f64, f64, f64)]) -> Vec<(f64, f64)> {
        let curve = NurbsCurve::line(2, &point(&[0.0, 0.0]), &point(&[1.0, 0.0])).unwrap();
        let block = Arc::new(Block::new(1, BlockKind::Line, curve, None));
        let mut planner = Planner::new(accel, lookahead);
        let mut out = Vec::new();
        for &(arc, feed, entry) in segs {
            planner.push(segment(&block, arc, feed, entry), |p| {
                out.push((p.profile.v_entry, p.profile.v_exit))
            });
        }
        planner.finish(|p| out.push((p.profile.v_entry, p.profile.v_exit)));
        out
    }

    fn segments() -> impl Strategy<Value = Vec<(f64, f64, f64)>> {
        let entry = prop_oneof![
            3 => Just(f64::INFINITY),
            1 => Just(0.0),
            2 => 0.0..400.0f64,
        ];
        prop::collection::vec((1e-4..20.0f64, 1.0..400.0f64, entry), 1..300)
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

        /// Same entry and exit speeds as the walked backward pass, to rounding, for any
        /// window length, corners (stops included) and feed changes.
        #[test]
        fn implicit_backward_pass_equals_the_walked_one(
            segs in segments(),
            lookahead in 1usize..64,
            accel in 10.0..5000.0f64,
        ) {
            let want = walked_plan(accel, lookahead, &segs);
            let got = planned(accel, lookahead, &segs);
            prop_assert_eq!(want.len(), got.len());
            // The keys carry `2a·s`, so their rounding is a few ulps of `2a` times the path
            // length, in squared speed: compare squares against that.
            let path: f64 = segs.iter().map(|s| s.0).sum();
            let tol = 1e-13 * 2.0 * accel * path + 1e-12;
            for (i, (w, g)) in want.iter().zip(&got).enumerate() {
                let close = |a: f64, b: f64| (a * a - b * b).abs() <= tol + 1e-12 * a * a;
                prop_assert!(close(w.0, g.0) && close(w.1, g.1),
                    "segment {}: walked {:?}, planned {:?}", i, w, g);
                // A stop is a stop, not a rounding of one.
                prop_assert_eq!(w.0 == 0.0, g.0 == 0.0, "segment {} entry", i);
            }
        }
    }

    #[test]
    fn long_paths_rebase_without_changing_the_plan() {
        // 3000 segments of 1 km: the origin moves many times; speeds match the walked pass.
        let segs: Vec<_> = (0..3000)
            .map(|i| (1000.0, 300.0, if i % 7 == 0 { 0.0 } else { f64::INFINITY }))
            .collect();
        let want = walked_plan(2400.0, 16, &segs);
        let got = planned(2400.0, 16, &segs);
        for (w, g) in want.iter().zip(&got) {
            assert!(
                (w.0 - g.0).abs() < 1e-9 && (w.1 - g.1).abs() < 1e-9,
                "{w:?} {g:?}"
            );
        }
    }

    #[test]
    fn trapezoid_and_triangle() {
        // 10 mm from rest to rest at 100 mm/s cruise and 1000 mm/s²: accel 5 mm, no... 5 mm to
        // reach 100 mm/s takes 0.1 s and 5 mm, so it is a triangle peaking at 100 exactly.
        let p = Profile::new(10.0, 0.0, 0.0, 100.0, 1000.0);
        assert!((p.v_peak - 100.0).abs() < 1e-9);
        assert!((p.duration() - 0.2).abs() < 1e-9);
        assert!((p.distance_at(0.1) - 5.0).abs() < 1e-9);
        assert!((p.distance_at(0.2) - 10.0).abs() < 1e-9);
        // Longer: cruise phase.
        let p = Profile::new(20.0, 0.0, 0.0, 100.0, 1000.0);
        assert!((p.duration() - 0.3).abs() < 1e-9);
        assert!((p.distance_at(0.15) - 10.0).abs() < 1e-9);
        assert!((p.speed_at(0.15) - 100.0).abs() < 1e-9);
        // Short: triangle below cruise.
        let p = Profile::new(1.0, 0.0, 0.0, 100.0, 1000.0);
        assert!((p.v_peak - 1000f64.sqrt()).abs() < 1e-9);
    }
}
