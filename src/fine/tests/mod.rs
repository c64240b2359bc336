use proptest::prelude::*;

use super::*;
use crate::buffer::BlockFlags;
use crate::buffer::VecSource;
use crate::servo::{Feeds, ShortRules};
use crate::vocab::Steps;

pub(crate) const SETTINGS: FineSettings = FineSettings {
    dt: 50e-6,
    accel: 2400.0,
    reverse_accel: 2400.0,
    feeds: Feeds {
        normal: 1.0,
        open: 5.0,
        retract: 2.0,
    },
    shorts: ShortRules::IMMEDIATE,
    step_mm: [0.001; MAX_AXES],
    max_short_ticks: 0,
    law: crate::servo::Law::ThreeState,
    excursions: ExcursionSettings::OFF,
    dry_run: false,
    breakthrough: super::BreakthroughSettings::OFF,
    jerk: 0.0,
    lift_axis: Some(2),
};

/// The path's own cruise in [`chain`] (mm/s): above every feed the tests program.
pub(crate) const PATH_CRUISE: f64 = 100.0;

/// Blocks through lattice points (steps), planned as one long cruise at `v`, on a path that
/// allows [`PATH_CRUISE`] through every junction (at rest at both ends).
pub(crate) fn chain(points: &[Steps], v: f64) -> Vec<StepBlock> {
    let n = points.len() - 1;
    points
        .windows(2)
        .enumerate()
        .map(|(i, w)| {
            let length_mm = w[0]
                .iter()
                .zip(&w[1])
                .map(|(a, b)| ((b - a) as f64 * 0.001).powi(2))
                .sum::<f64>()
                .sqrt();
            StepBlock {
                seq: i as u64,
                start: w[0],
                end: w[1],
                length_mm,
                v_entry: if i == 0 { 0.0 } else { v },
                v_exit: if i + 1 == n { 0.0 } else { v },
                v_cruise: v,
                v_limit: v,
                path: crate::preprocess::PathLimits {
                    cruise: PATH_CRUISE,
                    entry: if i == 0 { 0.0 } else { PATH_CRUISE },
                    exit: if i + 1 == n { 0.0 } else { PATH_CRUISE },
                },
                line: i as u64 + 1,
                ..StepBlock::EMPTY
            }
        })
        .collect()
}

pub(crate) fn p2(x: i64, y: i64) -> Steps {
    [x, y, 0, 0, 0, 0]
}

/// Runs to completion (or alarm) under a gap schedule; returns the position after every
/// tick that moved (with whether it was a backward event) and the interpolator.
fn run(
    blocks: Vec<StepBlock>,
    reserved: usize,
    gap: impl Fn(u64) -> GapState,
    max_ticks: u64,
) -> (Vec<Move>, Interpolator) {
    let start = blocks[0].start;
    let mut source = VecSource::new(blocks, reserved);
    let mut fine = Interpolator::new(SETTINGS, start);
    let mut path = vec![(start, false)];
    for t in 0..max_ticks {
        let tick = fine.tick(gap(t), &mut source);
        if tick.moved() {
            assert!(tick.steps.iter().all(|s| (-1..=1).contains(s)));
            path.push((fine.position(), tick.dir < 0));
        }
        if fine.state().is_final() {
            break;
        }
    }
    (path, fine)
}

pub(crate) type Move = (Steps, bool);

/// Checks the retrace rule on a move sequence: every backward move goes back to the point
/// before on the forward path, and forward moves after a retrace revisit exactly the points
/// retraced, in reverse. Returns the number of backward moves.
pub(crate) fn assert_retraces(path: &[Move]) -> usize {
    let mut stack = vec![path[0].0];
    let mut undone: Vec<Steps> = Vec::new();
    let mut pops = 0;
    for &(q, backward) in &path[1..] {
        if backward {
            assert!(stack.len() >= 2, "turned back past the start");
            assert_eq!(q, stack[stack.len() - 2], "turn-back left the forward path");
            undone.push(stack.pop().unwrap());
            pops += 1;
        } else {
            if let Some(expected) = undone.pop() {
                assert_eq!(q, expected, "re-advance left the retraced path");
            }
            stack.push(q);
        }
    }
    pops
}

#[test]
fn a_chain_ends_exactly_at_rest() {
    let blocks = chain(&[p2(0, 0), p2(300, 120), p2(-50, 400), p2(-50, 399)], 5.0);
    let (path, fine) = run(blocks, 8, |_| GapState::Open, 10_000_000);
    assert_eq!(fine.state(), ServoState::Done);
    assert_eq!(fine.position(), p2(-50, 399));
    assert_eq!(assert_retraces(&path), 0);
    let c = fine.counters();
    assert_eq!(c.events_forward as usize, path.len() - 1);
    assert_eq!(c.pulses[0], 300 + 350);
}

#[test]
fn speed_changes_at_most_a_dt_per_tick_except_down_to_the_plan() {
    let blocks = chain(&[p2(0, 0), p2(2000, 0), p2(2000, 2000)], 20.0);
    let mut source = VecSource::new(blocks, 4);
    let settings = FineSettings {
        feeds: Feeds {
            normal: 20.0,
            open: 20.0,
            retract: 20.0,
        },
        ..SETTINGS
    };
    let mut fine = Interpolator::new(settings, [0; MAX_AXES]);
    let dv = settings.accel * settings.dt;
    let mut last = 0.0;
    let mut peak: f64 = 0.0;
    while !fine.state().is_final() {
        fine.tick(GapState::Normal, &mut source);
        let v = fine.speed();
        assert!(v - last <= dv * (1.0 + 1e-9), "accelerated by {}", v - last);
        peak = peak.max(v);
        last = v;
    }
    assert!((peak - 20.0).abs() < 1e-9, "peak {peak}");
    assert_eq!(fine.position(), p2(2000, 2000));
}

#[test]
fn a_short_mid_block_retraces_and_re_advances_to_the_end() {
    let blocks = chain(&[p2(0, 0), p2(100, 30), p2(180, 90), p2(260, 90)], 5.0);
    // At 1 mm/s (normal feed) a step takes about 20 ticks: the short comes in block 1, and
    // 600 ticks at the 2 mm/s retract feed back out about 60 µm, into block 0.
    let (path, fine) = run(
        blocks,
        8,
        |t| {
            if (3000..3600).contains(&t) {
                GapState::Short
            } else {
                GapState::Normal
            }
        },
        10_000_000,
    );
    assert_eq!(fine.state(), ServoState::Done);
    assert_eq!(fine.position(), p2(260, 90));
    let pops = assert_retraces(&path);
    assert!(pops > 10, "{pops} steps retraced");
    let c = fine.counters().servo;
    assert_eq!((c.shorts, c.turn_backs, c.alarms), (1, 1, 0));
    assert!(c.deepest_turn_back_blocks >= 1);
}

#[test]
fn exhausting_the_reserved_area_is_an_alarm_that_keeps_position() {
    let blocks = chain(
        &[p2(0, 0), p2(40, 0), p2(80, 0), p2(120, 0), p2(160, 0)],
        5.0,
    );
    let (path, fine) = run(
        blocks,
        1,
        |t| {
            if t >= 2000 {
                GapState::Short
            } else {
                GapState::Normal
            }
        },
        10_000_000,
    );
    assert_eq!(fine.state(), ServoState::Alarm);
    assert_eq!(fine.counters().servo.alarms, 1);
    // ~100 steps forward (block 2), back through block 2 and the one reserved block.
    assert_eq!(fine.position(), p2(40, 0));
    assert_eq!(path.last().unwrap().0, fine.position());
    assert_retraces(&path);
}

#[test]
fn zero_step_blocks_are_passed_over_both_ways() {
    let blocks = chain(&[p2(0, 0), p2(30, 0), p2(30, 0), p2(30, 0), p2(60, 0)], 5.0);
    let (path, fine) = run(
        blocks,
        8,
        |t| {
            if (700..900).contains(&t) {
                GapState::Short
            } else {
                GapState::Normal
            }
        },
        10_000_000,
    );
    assert_eq!(fine.state(), ServoState::Done);
    assert_eq!(fine.position(), p2(60, 0));
    assert!(assert_retraces(&path) > 0);
}

#[test]
fn a_short_that_clears_just_after_turning_into_the_previous_block_re_advances_from_its_end() {
    // The short's start sweeps over the block boundary (about tick 210 at 1 mm/s) and its
    // length over the braking time, so that some clear after the turn-back has entered the
    // previous block but before it stepped back in it: the re-advance then starts at that
    // block's very end.
    let lattice = [p2(0, 0), p2(10, 0), p2(20, 0)];
    for start in 150..300 {
        for len in [5, 10, 15, 20, 25, 30, 40] {
            let blocks = chain(&lattice, 5.0);
            let short = |t: u64| (start..start + len).contains(&t);
            let gap = |t| {
                if short(t) {
                    GapState::Short
                } else {
                    GapState::Normal
                }
            };
            let (path, fine) = run(blocks, 4, gap, 1_000_000);
            assert_eq!(fine.state(), ServoState::Done, "short {start}+{len}");
            assert_eq!(fine.position(), p2(20, 0), "short {start}+{len}");
            assert_retraces(&path);
        }
    }
}

fn gap_schedule() -> impl Strategy<Value = Vec<(u64, u64, GapState)>> {
    proptest::collection::vec(
        (
            0u64..60_000,
            // Brief shorts (about a braking time) as often as long ones: they clear at every
            // stage of a turn-back.
            prop_oneof![1u64..40, 1u64..4_000],
            prop_oneof![3 => Just(GapState::Short), 1 => Just(GapState::Open)],
        ),
        0..6,
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Random chains under random gap schedules: the ledger ends exactly on the last point
    /// unless an alarm stopped it, every turn-back retraces forward points in reverse and
    /// every re-advance revisits them, and no tick moves an axis by more than one step.
    #[test]
    fn turn_back_retraces_and_the_end_is_exact(
        points in proptest::collection::vec((-60i64..60, -60i64..60, -20i64..20), 2..12),
        reserved in 0usize..6,
        schedule in gap_schedule(),
    ) {
        let lattice: Vec<_> = points.iter().map(|&(x, y, z)| [x, y, z, 0, 0, 0]).collect();
        let blocks = chain(&lattice, 5.0);
        let gap = |t: u64| {
            schedule
                .iter()
                .rev()
                .find(|(from, len, _)| (*from..from + len).contains(&t))
                .map_or(GapState::Normal, |s| s.2)
        };
        let (path, fine) = run(blocks, reserved, gap, 5_000_000);
        assert_retraces(&path);
        match fine.state() {
            ServoState::Done => prop_assert_eq!(fine.position(), *lattice.last().unwrap()),
            ServoState::Alarm => prop_assert_eq!(fine.position(), path.last().unwrap().0),
            other => prop_assert!(false, "stuck in {:?}", other),
        }
    }
}

/// Positions of every moving tick of a run that is held over `hold` ticks, and the run.
fn run_with_hold(blocks: Vec<StepBlock>, hold: std::ops::Range<u64>) -> (Vec<Steps>, Interpolator) {
    let mut source = VecSource::new(blocks, 4);
    let mut fine = Interpolator::new(SETTINGS, [0; MAX_AXES]);
    let mut path = Vec::new();
    let dv = SETTINGS.accel * SETTINGS.dt;
    let mut last_speed = 0.0;
    for t in 0..10_000_000 {
        fine.set_hold(hold.contains(&t));
        let tick = fine.tick(GapState::Normal, &mut source);
        if fine.held() {
            assert!(
                fine.speed() <= last_speed || fine.speed() == 0.0,
                "speeding up while held"
            );
            assert!(
                last_speed - fine.speed() <= dv + 1e-12,
                "braked harder than a_T"
            );
            if fine.still() {
                assert!(!tick.moved(), "moved while still");
            }
        }
        last_speed = fine.speed();
        if tick.moved() {
            path.push(fine.position());
        }
        if fine.state().is_final() {
            break;
        }
    }
    (path, fine)
}

#[test]
fn a_hold_brakes_to_a_standstill_and_the_release_carries_on_along_the_same_points() {
    // The normal feed, 1 mm/s, brakes to a standstill in 9 ticks at 2400 mm/s².
    let points = [p2(0, 0), p2(3000, 1200), p2(2500, 4000)];
    let (free, _) = run_with_hold(chain(&points, 4.0), 0..0);
    let (held, fine) = run_with_hold(chain(&points, 4.0), 20_000..300_000);
    assert_eq!(fine.state(), ServoState::Done);
    assert_eq!(held, free, "a hold changes when, never where");
    // And it really stood still: no step during most of the hold.
    let (part, _) = run_with_hold(chain(&points, 4.0), 20_000..u64::MAX);
    assert!(
        part.len() < free.len() / 2,
        "{} of {}",
        part.len(),
        free.len()
    );
    assert!(part.len() > 100, "it moved before the hold");
}

#[test]
fn skip_to_refuses_a_point_off_the_program() {
    let blocks = chain(&[p2(0, 0), p2(30, 12), p2(25, 40)], 5.0);
    let mut fine = Interpolator::new(SETTINGS, [0; MAX_AXES]);
    let at = PathPoint { seq: 1, event: 4 };
    let err = fine
        .skip_to(at, &[30, 13], &mut VecSource::new(blocks.clone(), 4))
        .unwrap_err();
    assert!(matches!(err, SkipError::Position { .. }), "{err}");
    let mut fine = Interpolator::new(SETTINGS, [0; MAX_AXES]);
    let at = PathPoint { seq: 5, event: 0 };
    let err = fine
        .skip_to(at, &[25, 40], &mut VecSource::new(blocks.clone(), 4))
        .unwrap_err();
    assert!(matches!(err, SkipError::PastEnd { .. }), "{err}");
    let mut fine = Interpolator::new(SETTINGS, [0; MAX_AXES]);
    let at = PathPoint { seq: 1, event: 99 };
    let err = fine
        .skip_to(at, &[25, 40], &mut VecSource::new(blocks, 4))
        .unwrap_err();
    assert!(matches!(err, SkipError::NoSuchPoint { .. }), "{err}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Stop anywhere (even mid-turn-back), note where the electrode is, start a fresh
    /// interpolator, skip to that point and run on: the moves before the stop plus the moves
    /// after the resume are the moves of the uninterrupted run from that point, and the end
    /// is exact. No step lost, none doubled.
    #[test]
    fn stop_anywhere_then_skip_and_resume_loses_and_doubles_nothing(
        points in proptest::collection::vec((-60i64..60, -60i64..60), 2..10),
        stop_at in 1u64..40_000,
        short_from in 0u64..40_000,
    ) {
        let lattice: Vec<_> = points.iter().map(|&(x, y)| p2(x, y)).collect();
        let mut lattice_from_zero = vec![p2(0, 0)];
        lattice_from_zero.extend(lattice);
        let blocks = chain(&lattice_from_zero, 5.0);
        let gap = |t: u64| if (short_from..short_from + 300).contains(&t) {
            GapState::Short
        } else {
            GapState::Normal
        };
        // First run: up to the stop.
        let mut source = VecSource::new(blocks.clone(), 8);
        let mut first = Interpolator::new(SETTINGS, [0; MAX_AXES]);
        for t in 0..stop_at {
            first.tick(gap(t), &mut source);
            if first.state().is_final() {
                break;
            }
        }
        prop_assume!(!first.state().is_final());
        let here = first.here();
        let ledger = first.position();
        // Resume: skip, then run to the end with the gap normal.
        let mut second = Interpolator::new(SETTINGS, [0; MAX_AXES]);
        let mut source = VecSource::new(blocks.clone(), 8);
        second.skip_to(here, &ledger[..2], &mut source).unwrap();
        prop_assert_eq!(second.counters().pulses, [0; MAX_AXES]);
        for _ in 0..10_000_000 {
            second.tick(GapState::Normal, &mut source);
            if second.state().is_final() {
                break;
            }
        }
        prop_assert_eq!(second.state(), ServoState::Done);
        prop_assert_eq!(second.position(), *lattice_from_zero.last().unwrap());
        // The resumed run's pulses are exactly those from the stop point to the end: the
        // lattice path from `ledger` onwards, which (no turn-back after the resume) is the
        // Manhattan length of the rest of the path along the blocks.
        let mut rest = [0u64; MAX_AXES];
        for b in &blocks {
            let from = if b.seq < here.seq {
                continue;
            } else if b.seq == here.seq {
                Bresenham::offset_at(&b.delta(), here.event)
            } else {
                [0; MAX_AXES]
            };
            for i in 0..MAX_AXES {
                rest[i] += (b.delta()[i] - from[i]).unsigned_abs();
            }
        }
        prop_assert_eq!(second.counters().pulses, rest);
    }
}

mod holds;
