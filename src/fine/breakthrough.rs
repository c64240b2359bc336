//! Breakthrough on a drilling move (`[sinker] breakthrough`): a small-hole drill (or any
//! sinking move) that comes out of the far side of the work.
//!
//! While the electrode drills, the gap sparks (with the odd open or short tick). When the
//! material ends the gap opens and stays open while the servo keeps advancing. The detector
//! counts the move's forward cutting ticks in windows of `window_ticks` (time, as a
//! generator's pulse counters do: counting events instead would weigh the fast open advance
//! over the slow sparking one): a window with an open ratio under `open_ratio` is steady
//! cutting; one at or over it, after steady cutting was seen, is the breakthrough. The material ended where the last spark was (the last
//! event with the gap not open), so the electrode goes on `extra_mm` past that point (the
//! travel already made since counts) and stops there: the rest of the move is dropped, and
//! the producer, which waited as it waits for a probing move, plans the program on from
//! where it stopped (the retract that follows). A drilling move that ends without breaking
//! through says so, and the program goes on from its end as usual.
//!
//! Pure state, advanced once per forward cutting event by the tick core: no clock, no
//! allocation.

use crate::vocab::{GapState, Steps};

/// The detector's settings, in the tick core's units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BreakthroughSettings {
    /// Off: drilling moves are cut as any other.
    pub enabled: bool,
    /// Forward cutting ticks per window.
    pub window_ticks: u32,
    /// A window with this share of open events (0 to 1) or more is open.
    pub open_ratio: f64,
    /// How far past the last spark the electrode goes before it stops (mm).
    pub extra_mm: f64,
}

impl BreakthroughSettings {
    pub const OFF: BreakthroughSettings = BreakthroughSettings {
        enabled: false,
        window_ticks: 400,
        open_ratio: 0.95,
        extra_mm: 0.3,
    };
}

/// What the detector keeps over a drilling move.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Breakthrough {
    window_ticks: u32,
    window_open: u32,
    /// A window of steady cutting was seen in this move.
    sparked: bool,
    /// Travel since the last spark (mm).
    since_spark_mm: f64,
    /// Where the last spark was (steps).
    pub last_spark: Steps,
    /// Broken through: the travel left before the stop (mm).
    left_mm: Option<f64>,
}

impl Breakthrough {
    /// One forward cutting tick of a drilling move at `at`, the gap as read: a spark marks
    /// where material still was; a window closes, and may tell the breakthrough.
    pub(super) fn tick(&mut self, s: &BreakthroughSettings, gap: GapState, at: &Steps) {
        if gap != GapState::Open {
            self.since_spark_mm = 0.0;
            self.last_spark = *at;
        }
        self.window_ticks += 1;
        self.window_open += u32::from(gap == GapState::Open);
        if self.window_ticks >= s.window_ticks.max(1) {
            let ratio = f64::from(self.window_open) / f64::from(self.window_ticks);
            if ratio < s.open_ratio {
                self.sparked = true;
            } else if self.sparked && self.left_mm.is_none() {
                self.left_mm = Some(s.extra_mm - self.since_spark_mm);
            }
            self.window_ticks = 0;
            self.window_open = 0;
        }
    }

    /// One forward event of a drilling move, `mm` long: `true` when the electrode has gone
    /// far enough past the breakthrough to stop. (A sparking gap holds the three-state servo
    /// still: the electrode steps through the open between sparks, so the sparks are told
    /// by the ticks, the distance by the events.)
    pub(super) fn event(&mut self, mm: f64) -> bool {
        self.since_spark_mm += mm;
        if let Some(left) = &mut self.left_mm {
            *left -= mm;
        }
        self.left_mm.is_some_and(|left| left <= 1e-12)
    }

    /// Broken through (and going on, or stopped).
    pub(super) fn found(&self) -> bool {
        self.left_mm.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steady_cutting_then_open_stops_the_extra_past_the_last_spark() {
        let s = BreakthroughSettings {
            enabled: true,
            window_ticks: 10,
            open_ratio: 0.8,
            extra_mm: 0.05,
        };
        let mut b = Breakthrough::default();
        let step = 0.001;
        let mut at = [0i64; 6];
        // 100 ticks of cutting, an event each, the odd one open; then the material ends.
        // As the tick core calls it: the tick at where the electrode stands, then its event.
        for k in 0..100 {
            let gap = if k % 7 == 0 {
                GapState::Open
            } else {
                GapState::Normal
            };
            b.tick(&s, gap, &at);
            at[2] -= 1;
            assert!(!b.event(step));
        }
        assert!(!b.found());
        let mut stopped = None;
        for k in 0..200 {
            b.tick(&s, GapState::Open, &at);
            at[2] -= 1;
            if b.event(step) {
                stopped = Some(k + 1);
                break;
            }
        }
        // Detected at the end of the first open window, stopped 50 µm past the last spark
        // (the tick at −99, whose event went on to −100).
        assert!(b.found());
        assert_eq!(b.last_spark[2], -99);
        assert_eq!((stopped, at[2]), (Some(49), -149));
    }

    #[test]
    fn open_from_the_start_is_not_a_breakthrough() {
        // An approach through air: open windows before any steady cutting.
        let s = BreakthroughSettings {
            enabled: true,
            ..BreakthroughSettings::OFF
        };
        let mut b = Breakthrough::default();
        for _ in 0..500 {
            b.tick(&s, GapState::Open, &[0; 6]);
            assert!(!b.event(0.001));
        }
        assert!(!b.found());
    }

    /// The tick core with a drilling move in hand: it cuts while the gap sparks, and once
    /// the gap stays open stops `extra_mm` past the last spark and reports where.
    #[test]
    fn the_tick_core_stops_a_drill_past_its_last_spark_and_reports_where() {
        use crate::buffer::{BlockFlags, VecSource};
        use crate::fine::tests::{SETTINGS, chain, p2};
        use crate::fine::{FineSettings, Interpolator};
        use crate::servo::ServoEvent;
        // The tick core knows no tool axis: a 5 mm move along X flagged as drilling.
        let mut blocks = chain(&[p2(0, 0), p2(5000, 0)], 10.0);
        blocks[0].flags = BlockFlags::BREAKTHROUGH | BlockFlags::LAST_OF_BLOCK;
        let settings = FineSettings {
            breakthrough: BreakthroughSettings {
                enabled: true,
                window_ticks: 100,
                open_ratio: 0.95,
                extra_mm: 0.2,
            },
            ..SETTINGS
        };
        let mut fine = Interpolator::new(settings, p2(0, 0));
        let mut source = VecSource::new(blocks, 4);
        let mut report = None;
        for t in 0..2_000_000u64 {
            // Sparking (every other tick) until X2 mm, then the material has ended.
            let gap = if fine.position()[0] < 2000 && t % 2 == 0 {
                GapState::Normal
            } else {
                GapState::Open
            };
            if let Some(e @ ServoEvent::Breakthrough { .. }) = fine.tick(gap, &mut source).event {
                report = Some(e);
                break;
            }
        }
        let Some(ServoEvent::Breakthrough {
            steps,
            last_spark,
            found,
            ..
        }) = report
        else {
            panic!("no breakthrough report");
        };
        assert!(found);
        assert!((1998..=2000).contains(&last_spark[0]), "{last_spark:?}");
        assert_eq!(steps[0] - last_spark[0], 200, "0.2 mm past the last spark");
        assert_eq!(fine.position(), steps, "stopped there");
        // Without it the move runs to its end and says so.
        let mut blocks = chain(&[p2(0, 0), p2(500, 0)], 10.0);
        blocks[0].flags = BlockFlags::BREAKTHROUGH | BlockFlags::LAST_OF_BLOCK;
        let mut fine = Interpolator::new(settings, p2(0, 0));
        let mut source = VecSource::new(blocks, 4);
        let mut end = None;
        for t in 0..2_000_000u64 {
            let gap = if t % 2 == 0 {
                GapState::Normal
            } else {
                GapState::Open
            };
            if let Some(e @ ServoEvent::Breakthrough { .. }) = fine.tick(gap, &mut source).event {
                end = Some(e);
                break;
            }
        }
        assert!(
            matches!(end, Some(ServoEvent::Breakthrough { found: false, steps, .. }) if steps[0] == 500),
            "{end:?}"
        );
    }

    /// A resumed job may walk into a drilling move (the run decides its end again), never
    /// past one's end (where it ended was that run's).
    #[test]
    fn a_resume_walks_into_a_drilling_move_but_not_past_it() {
        use crate::buffer::{BlockFlags, VecSource};
        use crate::fine::Interpolator;
        use crate::fine::SkipError;
        use crate::fine::tests::{SETTINGS, chain, p2};
        use crate::servo::PathPoint;
        let mut blocks = chain(&[p2(0, 0), p2(300, 0), p2(300, 300)], 10.0);
        blocks[0].flags = BlockFlags::BREAKTHROUGH | BlockFlags::LAST_OF_BLOCK;
        let mut fine = Interpolator::new(SETTINGS, p2(0, 0));
        let into = PathPoint { seq: 0, event: 100 };
        fine.skip_to(into, &[100, 0], &mut VecSource::new(blocks.clone(), 4))
            .unwrap();
        let mut fine = Interpolator::new(SETTINGS, p2(0, 0));
        let past = PathPoint { seq: 1, event: 10 };
        let err = fine
            .skip_to(past, &[300, 10], &mut VecSource::new(blocks, 4))
            .unwrap_err();
        assert!(matches!(err, SkipError::Drilled { .. }), "{err}");
    }
}
