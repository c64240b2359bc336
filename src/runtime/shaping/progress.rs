//! How far a job has come and how long it has to go: the farthest fraction of the program's
//! path reached, and an ETA from the recent average forward feed.
//!
//! Progress is the farthest point reached, not the current one: a turn-back retraces executed
//! path, so it must not move progress back, and the re-advance over the same ground must not
//! count twice. The ETA divides the path left by the forward feed of the last
//! [`ETA_WINDOW`]: an EDM job's speed is the gap servo's, not the plan's, so the recent past is
//! the best guess at the near future. Time is passed in, so the tracker is testable.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// How far back the ETA's average feed looks.
pub const ETA_WINDOW: Duration = Duration::from_secs(20);

/// How much faster than the rapid feed an advance must look to be a replay, not motion.
const JUMP_MARGIN: f64 = 2.0;
/// An advance this small is never taken for a replay (mm).
const JUMP_SLACK_MM: f64 = 0.5;

/// A job's progress along its program's path.
#[derive(Debug, Clone)]
pub struct ProgressTracker {
    total_mm: f64,
    /// Rapids along the path (mm) and the speed they run at (mm/s): the ETA counts them so.
    rapid_spans: Vec<(f64, f64)>,
    rapid_feed: f64,
    fraction: f64,
    recent: VecDeque<(Instant, f64)>,
}

impl ProgressTracker {
    /// A job whose program is `total_mm` long (the precheck's path length).
    pub fn new(total_mm: f64) -> ProgressTracker {
        ProgressTracker::with_rapids(total_mm, Vec::new(), f64::INFINITY)
    }

    /// A tracker that knows where the rapids are (`Precheck::rapid_spans`) and their speed
    /// (`PlanSettings::rapid_feed`, mm/s): the ETA is the cutting still to do at the recent
    /// cutting feed plus the rapids still to do at rapid speed, the model `plan` uses.
    pub fn with_rapids(
        total_mm: f64,
        rapid_spans: Vec<(f64, f64)>,
        rapid_feed: f64,
    ) -> ProgressTracker {
        ProgressTracker {
            total_mm,
            rapid_spans,
            rapid_feed,
            fraction: 0.0,
            recent: VecDeque::new(),
        }
    }

    /// The electrode is `path_mm` along the program at `now`.
    pub fn track(&mut self, path_mm: f64, now: Instant) {
        if self.total_mm > 0.0 && path_mm.is_finite() {
            self.fraction = self.fraction.max((path_mm / self.total_mm).clamp(0.0, 1.0));
        }
        if let Some(&(t, p)) = self.recent.back() {
            // Faster than the machine moves (a resume replaying its job up to where it
            // stopped, in no time): the window starts again here, or the ETA would take the
            // replay for the feed.
            let possible = self.rapid_feed * JUMP_MARGIN * now.duration_since(t).as_secs_f64();
            if self.done_mm() - p > possible + JUMP_SLACK_MM {
                self.recent.clear();
            }
        }
        self.recent.push_back((now, self.done_mm()));
        while self
            .recent
            .front()
            .is_some_and(|(t, _)| now.duration_since(*t) > ETA_WINDOW)
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

    /// Average forward feed over the recent window (mm/s), once a second of it is known.
    pub fn recent_feed(&self) -> Option<f64> {
        let (&(t0, p0), &(t1, p1)) = (self.recent.front()?, self.recent.back()?);
        let dt = t1.duration_since(t0).as_secs_f64();
        (dt >= 1.0).then(|| (p1 - p0) / dt)
    }

    /// Seconds to the end at the recent feed (none while nothing advances).
    pub fn eta_s(&self) -> Option<f64> {
        let (&(t0, p0), &(t1, p1)) = (self.recent.front()?, self.recent.back()?);
        let dt = t1.duration_since(t0).as_secs_f64();
        if dt < 1.0 {
            return None;
        }
        let done = self.done_mm();
        let rapid_left = self.rapid_mm_before(self.total_mm) - self.rapid_mm_before(done);
        let cut_left = ((self.total_mm - done) - rapid_left).max(0.0);
        let rapid_time = if self.rapid_feed.is_finite() && self.rapid_feed > 0.0 {
            rapid_left / self.rapid_feed
        } else {
            0.0
        };
        if cut_left <= 1e-9 {
            return Some(rapid_time);
        }
        let cut_feed = ((p1 - self.rapid_mm_before(p1)) - (p0 - self.rapid_mm_before(p0))) / dt;
        (cut_feed > 1e-9).then(|| cut_left / cut_feed + rapid_time)
    }

    /// Rapid path length between the start and path position `x` (mm).
    fn rapid_mm_before(&self, x: f64) -> f64 {
        self.rapid_spans
            .iter()
            .map(|&(from, to)| (to.min(x) - from).max(0.0))
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_resumes_replay_is_not_taken_for_the_feed() {
        // 100 mm at most 10 mm/s; a resume replays to 50 mm in 10 ms, then cuts at 1 mm/s.
        let t0 = Instant::now();
        let at = |s: f64| t0 + Duration::from_secs_f64(s);
        let mut p = ProgressTracker::with_rapids(100.0, Vec::new(), 10.0);
        p.track(0.0, at(0.0));
        p.track(50.0, at(0.01));
        for i in 1..=5 {
            p.track(50.0 + f64::from(i), at(0.01 + f64::from(i)));
        }
        let eta = p.eta_s().unwrap();
        assert!((eta - 45.0).abs() < 0.5, "{eta}");
        assert_eq!(p.fraction(), 0.55);
    }

    #[test]
    fn a_turn_back_is_not_progress_and_the_eta_follows_the_recent_feed() {
        let t0 = Instant::now();
        let at = |s: f64| t0 + Duration::from_secs_f64(s);
        let mut p = ProgressTracker::new(100.0);
        assert_eq!(p.eta_s(), None);
        p.track(10.0, at(0.0));
        p.track(20.0, at(1.0));
        p.track(30.0, at(2.0));
        assert_eq!(p.fraction(), 0.3);
        assert_eq!(p.recent_feed(), Some(10.0));
        assert_eq!(p.eta_s(), Some(7.0));
        // Turned back 5 mm, then re-advancing over the same ground: no progress, and the
        // recent feed drops accordingly.
        p.track(25.0, at(3.0));
        p.track(30.0, at(4.0));
        assert_eq!(p.fraction(), 0.3);
        assert_eq!(p.recent_feed(), Some(5.0));
        assert_eq!(p.eta_s(), Some(14.0));
        // Standing still for longer than the window: no ETA.
        p.track(30.0, at(30.0));
        p.track(30.0, at(40.0));
        assert_eq!(p.eta_s(), None);
        p.finish();
        assert_eq!(p.done_mm(), 100.0);
    }

    /// Rapids count at rapid speed: 40 mm of cutting at a recent 1 mm/s and 50 mm of rapids at
    /// 20 mm/s still to go is 40 + 2.5 s, and a window spent in a rapid does not make the
    /// cutting look fast.
    #[test]
    fn the_eta_counts_rapids_at_rapid_speed() {
        let t0 = Instant::now();
        let at = |s: f64| t0 + Duration::from_secs_f64(s);
        // Path: 10 mm cut, 50 mm rapid (10..60), 40 mm cut.
        let mut p = ProgressTracker::with_rapids(100.0, vec![(10.0, 60.0)], 20.0);
        p.track(0.0, at(0.0));
        p.track(5.0, at(5.0));
        assert_eq!(p.eta_s(), Some(5.0 + 40.0 + 2.5));
        // Through the rapid: 5 more mm of cut, then 50 mm of rapid in 2.5 s.
        p.track(10.0, at(10.0));
        p.track(60.0, at(12.5));
        p.track(62.0, at(14.5));
        let eta = p.eta_s().unwrap();
        // Over the window (0 to 14.5 s) 12 mm were cut: 12/14.5 mm/s for the 38 mm left.
        assert!((eta - 38.0 / (12.0 / 14.5)).abs() < 1e-9, "{eta}");
    }
}
