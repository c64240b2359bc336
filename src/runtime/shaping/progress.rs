//! How far a job has come and how long it has to go: the farthest fraction of the program's
//! path reached, and an ETA from the plan of what remains, corrected by how the job has kept
//! to its plan so far.
//!
//! Progress is the farthest point reached, not the current one: a turn-back retraces executed
//! path, so it must not move progress back, and the re-advance over the same ground must not
//! count twice.
//!
//! The ETA is [`PathPace`]'s time for the path left (every move at the feed the job will use:
//! a cut at its pass's feed, capped by its condition's sparking feed; a rapid at rapid speed),
//! times how much slower than that pace the job has run so far (an EDM cut goes at the gap's
//! speed, which the plan does not know). Only running time counts: while the job is held or
//! paused the clock the correction reads stands still, so a hold does not stretch the ETA.
//! Time is passed in, so the tracker is testable.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// How far back the recent feed (status `recent_feed_mm_per_min`) looks, in running time.
pub const ETA_WINDOW: Duration = Duration::from_secs(20);

/// How much faster than the rapid feed an advance must look to be a replay, not motion.
const JUMP_MARGIN: f64 = 2.0;
/// An advance this small is never taken for a replay (mm).
const JUMP_SLACK_MM: f64 = 0.5;
/// Planned seconds the job must have run before its own pace corrects the plan's.
const CORRECT_AFTER_S: f64 = 2.0;
/// The correction is kept within these factors: a job stuck in shorts for a while is slower,
/// not a hundred times slower.
const CORRECTION: (f64, f64) = (0.25, 8.0);

/// The plan's time along a job's path: pieces of path at one pace each (consecutive moves
/// at the same pace merged, so this grows with changes of feed, not with blocks). Path the
/// job skips (a direct approach's) takes no time.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PathPace {
    /// `(from_mm, to_mm, seconds at from_mm, mm/s)`, in path order.
    pieces: Vec<(f64, f64, f64, f64)>,
}

impl PathPace {
    /// `length` mm from `from_mm` along the path at `mm_per_s`.
    pub fn push(&mut self, from_mm: f64, length: f64, mm_per_s: f64) {
        if length <= 0.0 || mm_per_s.is_nan() || mm_per_s <= 0.0 {
            return;
        }
        let total = self.total_s();
        match self.pieces.last_mut() {
            Some((_, to, _, v)) if *to == from_mm && *v == mm_per_s => *to += length,
            _ => self
                .pieces
                .push((from_mm, from_mm + length, total, mm_per_s)),
        }
    }

    /// The plan's time for the whole path, s.
    fn total_s(&self) -> f64 {
        self.pieces
            .last()
            .map_or(0.0, |&(from, to, s, v)| s + (to - from) / v)
    }

    /// The plan's time from the start to `x` mm along the path, s.
    fn seconds_to(&self, x: f64) -> f64 {
        let i = self.pieces.partition_point(|&(_, to, _, _)| to <= x);
        match self.pieces.get(i) {
            Some(&(from, _, s, v)) => s + (x - from).max(0.0) / v,
            None => self.total_s(),
        }
    }

    /// How many pieces (0: the plan has no time for the path).
    pub fn pieces(&self) -> usize {
        self.pieces.len()
    }
}

/// A job's progress along its program's path.
#[derive(Debug, Clone)]
pub struct ProgressTracker {
    total_mm: f64,
    pace: PathPace,
    /// The rapid speed (mm/s): an advance much faster is a resume's replay.
    rapid_feed: f64,
    fraction: f64,
    /// Running time: wall time while the job was not held or paused.
    running: Duration,
    last: Option<Instant>,
    /// Where the correction counts from (running time, plan seconds): the start, or the
    /// end of a replay.
    base: (Duration, f64),
    /// `(running time, mm done)` over the last [`ETA_WINDOW`].
    recent: VecDeque<(Duration, f64)>,
}

impl ProgressTracker {
    /// A job whose path is `total_mm` long (the precheck's) and runs at `pace`; `rapid_feed`
    /// (mm/s) tells a resume's replay from motion.
    pub fn new(total_mm: f64, pace: PathPace, rapid_feed: f64) -> ProgressTracker {
        ProgressTracker {
            total_mm,
            pace,
            rapid_feed,
            fraction: 0.0,
            running: Duration::ZERO,
            last: None,
            base: (Duration::ZERO, 0.0),
            recent: VecDeque::new(),
        }
    }

    /// The electrode is `path_mm` along the program at `now`; `held`: the job is held or
    /// paused (the time since the last call does not count as running).
    pub fn track(&mut self, path_mm: f64, now: Instant, held: bool) {
        let dt = self
            .last
            .map_or(Duration::ZERO, |t| now.saturating_duration_since(t));
        self.last = Some(now);
        let before = self.done_mm();
        if self.total_mm > 0.0 && path_mm.is_finite() {
            self.fraction = self.fraction.max((path_mm / self.total_mm).clamp(0.0, 1.0));
        }
        // The clock starts with the motion: the check and the buffer's first fill before it
        // are not the job's pace.
        if !held && self.done_mm() > 0.0 {
            self.running += dt;
        }
        // Faster than the machine moves (a resume replaying its job up to where it stopped,
        // in no time): the correction and the window start again here.
        let possible = self.rapid_feed * JUMP_MARGIN * dt.as_secs_f64();
        if self.done_mm() - before > possible + JUMP_SLACK_MM {
            self.recent.clear();
            self.base = (self.running, self.pace.seconds_to(self.done_mm()));
        }
        self.recent.push_back((self.running, self.done_mm()));
        while self
            .recent
            .front()
            .is_some_and(|(t, _)| self.running.saturating_sub(*t) > ETA_WINDOW)
        {
            self.recent.pop_front();
        }
    }

    /// The job ended done: all of it.
    pub fn finish(&mut self) {
        self.fraction = 1.0;
    }

    /// Fraction of the path done (0 to 1).
    pub fn fraction(&self) -> f64 {
        self.fraction
    }

    pub fn done_mm(&self) -> f64 {
        self.fraction * self.total_mm
    }

    pub fn total_mm(&self) -> f64 {
        self.total_mm
    }

    /// Running time so far (held and paused time left out), s.
    #[cfg(test)]
    fn running_s(&self) -> f64 {
        self.running.as_secs_f64()
    }

    /// Average forward feed over the recent window of running time (mm/s), once a second of
    /// it is known.
    pub fn recent_feed(&self) -> Option<f64> {
        let (&(t0, p0), &(t1, p1)) = (self.recent.front()?, self.recent.back()?);
        let dt = (t1 - t0).as_secs_f64();
        (dt >= 1.0).then(|| (p1 - p0) / dt)
    }

    /// How much slower than the plan's pace the job has run (1: as planned).
    pub fn correction(&self) -> f64 {
        let planned = self.pace.seconds_to(self.done_mm()) - self.base.1;
        let ran = (self.running - self.base.0).as_secs_f64();
        if planned < CORRECT_AFTER_S {
            return 1.0;
        }
        (ran / planned).clamp(CORRECTION.0, CORRECTION.1)
    }

    /// Seconds to the end: the plan's time for the path left, corrected by the job's pace so
    /// far (none for a path the plan has no time for).
    pub fn eta_s(&self) -> Option<f64> {
        if self.pace.pieces() == 0 {
            return None;
        }
        let left = self.pace.total_s() - self.pace.seconds_to(self.done_mm());
        Some(left.max(0.0) * self.correction())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pace(pieces: &[(f64, f64)]) -> PathPace {
        let mut p = PathPace::default();
        let mut at = 0.0;
        for &(len, v) in pieces {
            p.push(at, len, v);
            at += len;
        }
        p
    }

    #[test]
    fn the_pace_merges_equal_feeds_and_times_any_point() {
        // 10 mm at 1 mm/s, 50 mm of rapid at 20 mm/s, 40 mm at 0.5 mm/s (two moves).
        let p = pace(&[(10.0, 1.0), (50.0, 20.0), (20.0, 0.5), (20.0, 0.5)]);
        assert_eq!(p.pieces(), 3);
        assert_eq!(p.total_s(), 10.0 + 2.5 + 80.0);
        assert_eq!(p.seconds_to(5.0), 5.0);
        assert_eq!(p.seconds_to(60.0), 12.5);
        assert_eq!(p.seconds_to(70.0), 32.5);
        assert_eq!(p.seconds_to(1000.0), p.total_s());
        // Skipped path (a gap between pieces) takes no time.
        let mut q = PathPace::default();
        q.push(0.0, 10.0, 1.0);
        q.push(20.0, 10.0, 1.0);
        assert_eq!(q.seconds_to(15.0), 10.0);
        assert_eq!(q.total_s(), 20.0);
    }

    #[test]
    fn the_eta_is_the_plans_time_left_corrected_by_the_pace_so_far() {
        let t0 = Instant::now();
        let at = |s: f64| t0 + Duration::from_secs_f64(s);
        // 100 mm at 1 mm/s planned; the job runs at half that.
        let mut p = ProgressTracker::new(100.0, pace(&[(100.0, 1.0)]), 10.0);
        p.track(0.0, at(0.0), false);
        assert_eq!(p.eta_s(), Some(100.0), "the plan alone at the start");
        p.track(5.0, at(10.0), false);
        assert_eq!(p.eta_s(), Some(95.0 * 2.0));
        // A 20 s hold: nothing runs, the ETA stays.
        p.track(5.0, at(20.0), true);
        p.track(5.0, at(30.0), true);
        assert_eq!(p.eta_s(), Some(95.0 * 2.0));
        assert_eq!(p.running_s(), 10.0);
        // A turn-back is no progress.
        p.track(3.0, at(32.0), false);
        assert_eq!(p.fraction(), 0.05);
        p.finish();
        assert_eq!(p.done_mm(), 100.0);
        assert_eq!(p.eta_s(), Some(0.0));
    }

    #[test]
    fn a_pass_at_a_finer_feed_is_timed_at_its_own_feed() {
        let t0 = Instant::now();
        let at = |s: f64| t0 + Duration::from_secs_f64(s);
        // Three passes of 10 mm: 1, 0.5 and 0.25 mm/s; the first as planned.
        let mut p =
            ProgressTracker::new(30.0, pace(&[(10.0, 1.0), (10.0, 0.5), (10.0, 0.25)]), 10.0);
        p.track(0.0, at(0.0), false);
        p.track(5.0, at(5.0), false);
        assert_eq!(p.eta_s(), Some(5.0 + 20.0 + 40.0));
    }

    #[test]
    fn a_resumes_replay_is_not_taken_for_the_pace() {
        // 100 mm at 1 mm/s; a resume replays to 50 mm in 10 ms, then cuts at 0.5 mm/s.
        let t0 = Instant::now();
        let at = |s: f64| t0 + Duration::from_secs_f64(s);
        let mut p = ProgressTracker::new(100.0, pace(&[(100.0, 1.0)]), 10.0);
        p.track(0.0, at(0.0), false);
        p.track(50.0, at(0.01), false);
        assert_eq!(p.eta_s(), Some(50.0));
        for i in 1..=10 {
            p.track(50.0 + 0.5 * f64::from(i), at(0.01 + f64::from(i)), false);
        }
        let eta = p.eta_s().unwrap();
        assert!((eta - 45.0 * 2.0).abs() < 0.1, "{eta}");
        assert_eq!(p.fraction(), 0.55);
        assert!((p.recent_feed().unwrap() - 0.5).abs() < 1e-9);
    }
}
