//! Look-ahead feed planning under a tangential acceleration limit (seed 001 §2.3, in the form
//! Grbl's `planner.c` made familiar).
//!
//! Each segment arrives with a cruise limit (program feed, machine maximum, normal acceleration
//! over its tightest radius, and in period mode the chord-error speed) and its entry junction
//! limit (a corner's speed, infinite inside a smooth piece). The planner keeps the last
//! `lookahead_segments` segments in a window and maintains, for each, the highest entry speed
//! from which the machine can still stop by the end of the window (`v_back`, the backward pass).
//! A new segment can only raise those speeds, and the pass stops at the first one it does not
//! change, so a push costs O(1) amortised rather than O(window).
//!
//! When the window is full the oldest segment is released: its entry speed was fixed when its
//! predecessor left, its exit speed is the smaller of the successor's `v_back` and what the
//! acceleration limit allows from the entry (the forward pass, one segment at a time). Inside
//! the segment the speed follows a trapezoid (accelerate, cruise, decelerate at `a_T`), so
//! motion slows ahead of tight curvature, starts and ends at rest, and never needs more than the
//! window to stop. A window that is short against the braking distance costs speed, never safety.

use std::collections::VecDeque;

use super::GeoSegment;

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
        let v_peak = peak_sq.max(0.0).sqrt().min(cruise).max(v_entry).max(v_exit);
        let d_accel = (v_peak * v_peak - v_entry * v_entry) / (2.0 * accel);
        let d_decel = (v_peak * v_peak - v_exit * v_exit) / (2.0 * accel);
        let d_cruise = (length - d_accel - d_decel).max(0.0);
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

/// A segment with its planned speeds.
#[derive(Debug, Clone)]
pub struct PlannedSegment {
    pub geo: GeoSegment,
    pub profile: Profile,
}

#[derive(Debug)]
struct Entry {
    geo: GeoSegment,
    /// Entry junction limit: corner speed and both neighbours' cruise limits.
    junction: f64,
    /// Highest entry speed that can still stop by the end of the window.
    v_back: f64,
}

/// The look-ahead planner. Holds at most `lookahead` segments.
#[derive(Debug)]
pub struct Planner {
    accel: f64,
    lookahead: usize,
    window: VecDeque<Entry>,
    /// Entry speed of the window's first segment (fixed when its predecessor left).
    v_start: f64,
    prev_cruise: f64,
}

impl Planner {
    pub fn new(accel: f64, lookahead: usize) -> Planner {
        Planner {
            accel,
            lookahead: lookahead.max(1),
            window: VecDeque::with_capacity(lookahead.max(1) + 1),
            v_start: 0.0,
            prev_cruise: 0.0,
        }
    }

    /// Adds a segment; releases the oldest to `emit` when the window is full.
    pub fn push<F: FnMut(PlannedSegment)>(&mut self, geo: GeoSegment, mut emit: F) {
        // `prev_cruise` starts at 0: the first segment of a job starts at rest.
        let junction = geo.entry_limit.min(geo.feed_limit).min(self.prev_cruise);
        self.prev_cruise = geo.feed_limit;
        let v_back = junction.min((2.0 * self.accel * geo.arc).sqrt());
        self.window.push_back(Entry {
            geo,
            junction,
            v_back,
        });
        // Backward pass: raise entry speeds now that the window ends one segment later.
        let mut next = v_back;
        for j in (0..self.window.len() - 1).rev() {
            let e = &mut self.window[j];
            let v = e
                .junction
                .min((next * next + 2.0 * self.accel * e.geo.arc).sqrt());
            if v == e.v_back {
                break;
            }
            e.v_back = v;
            next = v;
        }
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
    }

    fn release<F: FnMut(PlannedSegment)>(&mut self, emit: &mut F) {
        let Some(e) = self.window.pop_front() else {
            return;
        };
        let v0 = self.v_start.min(e.v_back);
        let next_max = self.window.front().map_or(0.0, |n| n.v_back);
        let v1 = next_max.min((v0 * v0 + 2.0 * self.accel * e.geo.arc).sqrt());
        let profile = Profile::new(e.geo.arc, v0, v1, e.geo.feed_limit, self.accel);
        self.v_start = v1;
        emit(PlannedSegment {
            geo: e.geo,
            profile,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
