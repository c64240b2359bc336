//! The excursions' state machine driven tick by tick: every move checked against the
//! retrace rule (back only over points already cut, forward again over the same points),
//! the ledger against the blocks' end.

use super::*;
use crate::buffer::{BlockFlags, StepBlock, VecSource};
use crate::fine::tests::{Move, SETTINGS, assert_retraces, chain, p2};
use crate::fine::{FineSettings, Tick};
use crate::servo::PathPoint;

/// Jumps every 2000 ticks (0.1 s, 0.1 mm of cut at the normal feed), 50 steps high, at 5 mm/s.
fn jumping() -> FineSettings {
    FineSettings {
        excursions: ExcursionSettings {
            jump_interval_ticks: 2000,
            jump_height_mm: 0.05,
            jump_feed: 5.0,
            ..ExcursionSettings::OFF
        },
        ..SETTINGS
    }
}

/// A straight 2 mm cut along X in 0.5 mm blocks, planned at 5 mm/s.
fn cut() -> Vec<StepBlock> {
    chain(
        &[p2(0, 0), p2(500, 0), p2(1000, 0), p2(1500, 0), p2(2000, 0)],
        5.0,
    )
}

struct Driver {
    fine: Interpolator,
    source: VecSource,
    path: Vec<Move>,
    events: Vec<ServoEvent>,
}

impl Driver {
    fn new(settings: FineSettings, blocks: Vec<StepBlock>) -> Driver {
        let start = blocks[0].start;
        Driver {
            fine: Interpolator::new(settings, start),
            source: VecSource::new(blocks, 64),
            path: vec![(start, false)],
            events: Vec::new(),
        }
    }

    fn tick(&mut self, gap: GapState) -> Tick {
        let tick = self.fine.tick(gap, &mut self.source);
        if tick.moved() {
            self.path.push((self.fine.position(), tick.dir < 0));
        }
        if let Some(e) = tick.event {
            self.events.push(e);
        }
        tick
    }

    /// Ticks with `gap` until `until` holds of an event (at most `max` ticks).
    fn until(&mut self, gap: GapState, max: u64, until: impl Fn(&ServoEvent) -> bool) {
        for _ in 0..max {
            if let Some(e) = self.tick(gap).event
                && until(&e)
            {
                return;
            }
        }
        panic!("no such event within {max} ticks: {:?}", self.events);
    }

    fn run_to_the_end(&mut self) {
        self.until(GapState::Normal, 200_000, |e| *e == ServoEvent::Done);
    }
}

#[test]
fn jumps_lift_the_height_and_come_back_to_the_point_they_left() {
    let mut d = Driver::new(jumping(), cut());
    d.until(GapState::Normal, 10_000, |e| {
        matches!(e, ServoEvent::Jump { .. })
    });
    let ServoEvent::Jump { at } = *d.events.last().unwrap() else {
        unreachable!()
    };
    let left = d.fine.position();
    assert_eq!(d.fine.state(), ServoState::Retreat);
    d.until(GapState::Normal, 10_000, |e| {
        matches!(e, ServoEvent::Retreated { .. })
    });
    assert_eq!(d.fine.position()[0], left[0] - 50, "up by the height");
    d.until(GapState::Normal, 10_000, |e| {
        matches!(e, ServoEvent::Returned { .. })
    });
    assert_eq!(d.fine.position(), left, "back where it left");
    assert_eq!(d.fine.here(), at);
    d.run_to_the_end();
    assert_eq!(d.fine.position(), p2(2000, 0));
    let jumps = d.fine.counters().servo.jumps;
    assert!(jumps >= 3, "{jumps} jumps");
    assert_eq!(assert_retraces(&d.path) as u64, 50 * jumps);
}

/// A short on the way back down turns back as in a re-advance; the gap clears, the
/// re-advance reaches the point the jump left, and cutting goes on to the exact end.
#[test]
fn a_short_on_the_way_down_from_a_jump_turns_back_and_the_cut_ends_exactly() {
    let mut d = Driver::new(jumping(), cut());
    d.until(GapState::Normal, 10_000, |e| {
        matches!(e, ServoEvent::Jump { .. })
    });
    let left = d.fine.position();
    d.until(GapState::Normal, 10_000, |e| {
        matches!(e, ServoEvent::Retreated { .. })
    });
    // Down 20 steps, then the gap shorts (debris in the flushed gap).
    while d.fine.position()[0] < left[0] - 30 {
        d.tick(GapState::Normal);
    }
    assert_eq!(d.fine.state(), ServoState::Return);
    d.tick(GapState::Short);
    assert_eq!(d.fine.state(), ServoState::TurnBack);
    assert!(matches!(d.events.last(), Some(ServoEvent::Short { .. })));
    for _ in 0..400 {
        d.tick(GapState::Short);
    }
    d.until(GapState::Normal, 10, |e| {
        matches!(e, ServoEvent::Cleared { .. })
    });
    assert_eq!(d.fine.state(), ServoState::ReAdvance);
    d.until(GapState::Normal, 20_000, |e| {
        matches!(e, ServoEvent::Resumed { .. })
    });
    assert_eq!(
        d.fine.position(),
        left,
        "the re-advance ends where the jump left"
    );
    d.run_to_the_end();
    assert_eq!(d.fine.position(), p2(2000, 0));
    assert_eq!(d.fine.counters().servo.shorts, 1);
    assert_retraces(&d.path);
}

/// The wire breaks during a re-advance, short of the point the short happened: motion stops
/// at once; threading in place and resuming returns (spark off) to the farthest point cut,
/// which is where cutting goes on.
#[test]
fn a_break_during_a_re_advance_returns_to_the_farthest_point_cut() {
    let mut d = Driver::new(SETTINGS, cut());
    while d.fine.position()[0] < 700 {
        d.tick(GapState::Normal);
    }
    let mark = d.fine.position();
    d.tick(GapState::Short);
    for _ in 0..2000 {
        d.tick(GapState::Short);
    }
    d.until(GapState::Normal, 10, |e| {
        matches!(e, ServoEvent::Cleared { .. })
    });
    while d.fine.position()[0] < mark[0] - 100 {
        d.tick(GapState::Normal);
    }
    assert_eq!(d.fine.state(), ServoState::ReAdvance);
    d.fine.set_wire_input(true);
    let tick = d.tick(GapState::Open);
    assert!(
        matches!(tick.event, Some(ServoEvent::WireBreak { open: false, .. })),
        "{tick:?}"
    );
    let broke_at = d.fine.position();
    assert!(broke_at[0] < mark[0]);
    for _ in 0..1000 {
        assert!(!d.tick(GapState::Open).moved(), "moved with a broken wire");
    }
    // Releasing the hold does nothing while the wire is broken.
    d.fine.set_hold(false);
    assert!(!d.tick(GapState::Open).moved());
    assert_eq!(d.fine.state(), ServoState::WireBroken);
    assert!(d.fine.rethread(Rethread::Here));
    d.fine.set_wire_input(false);
    assert_eq!(d.fine.state(), ServoState::Threading);
    d.fine.set_hold(true);
    d.fine.set_hold(false);
    d.until(GapState::Open, 20_000, |e| {
        matches!(
            e,
            ServoEvent::Returned {
                why: Excursion::Rethread,
                ..
            }
        )
    });
    assert_eq!(d.fine.position(), mark, "back at the farthest point cut");
    assert_eq!(d.fine.state(), ServoState::Forward);
    d.run_to_the_end();
    assert_eq!(d.fine.position(), p2(2000, 0));
    assert_retraces(&d.path);
}

/// A rethread to the start hole goes back along the cut to where the rapid ended, not
/// into the rapid; the return then retraces the same points to the break.
#[test]
fn a_rethread_goes_back_to_the_end_of_the_rapid() {
    let mut blocks = chain(&[p2(0, 0), p2(300, 0), p2(800, 0), p2(800, 600)], 5.0);
    blocks[0].flags |= BlockFlags::RAPID;
    let mut d = Driver::new(SETTINGS, blocks);
    while d.fine.position()[1] < 200 {
        d.tick(GapState::Normal);
    }
    d.fine.set_wire_input(true);
    d.tick(GapState::Normal);
    let broke_at = d.fine.position();
    assert_eq!(d.fine.state(), ServoState::WireBroken);
    assert!(d.fine.rethread(Rethread::AtStart));
    d.fine.set_wire_input(false);
    d.fine.set_hold(false);
    d.until(GapState::Open, 20_000, |e| {
        matches!(
            e,
            ServoEvent::Retreated {
                why: Excursion::Rethread,
                ..
            }
        )
    });
    assert_eq!(d.fine.position(), p2(300, 0), "at the start hole");
    assert_eq!(d.fine.state(), ServoState::Threading);
    for _ in 0..100 {
        assert!(!d.tick(GapState::Open).moved(), "moved while threading");
    }
    d.fine.set_hold(true);
    d.fine.set_hold(false);
    d.until(GapState::Open, 20_000, |e| {
        matches!(e, ServoEvent::Returned { .. })
    });
    assert_eq!(d.fine.position(), broke_at);
    d.run_to_the_end();
    assert_eq!(d.fine.position(), p2(800, 600));
    assert_eq!(assert_retraces(&d.path), 500 + broke_at[1] as usize);
    assert_eq!(d.fine.here(), PathPoint { seq: 2, event: 600 });
}

/// A pass starts at the start hole: a rethread in a later pass goes back to where that pass
/// began, not on into the pass before it.
#[test]
fn a_rethread_goes_back_to_the_start_of_its_pass() {
    let mut blocks = chain(
        &[p2(0, 0), p2(300, 0), p2(0, 0), p2(300, 0), p2(300, 400)],
        5.0,
    );
    blocks[2].flags |= BlockFlags::PASS_START | BlockFlags::START_HOLE;
    let mut d = Driver::new(SETTINGS, blocks);
    while d.fine.position()[1] < 200 {
        d.tick(GapState::Normal);
    }
    d.fine.set_wire_input(true);
    d.tick(GapState::Normal);
    assert!(d.fine.rethread(Rethread::AtStart));
    d.fine.set_wire_input(false);
    d.fine.set_hold(false);
    d.until(GapState::Open, 20_000, |e| {
        matches!(
            e,
            ServoEvent::Retreated {
                why: Excursion::Rethread,
                exhausted: false,
                ..
            }
        )
    });
    assert_eq!(d.fine.position(), p2(0, 0), "at the start of the pass");
    assert_eq!(d.fine.here().seq, 2, "in the pass's first block");
    assert_eq!(d.fine.state(), ServoState::Threading);
}
