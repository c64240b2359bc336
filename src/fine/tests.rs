use proptest::prelude::*;

use super::*;
use crate::buffer::VecSource;

const SETTINGS: FineSettings = FineSettings {
    dt: 50e-6,
    accel: 2400.0,
    feeds: Feeds {
        normal: 1.0,
        open: 5.0,
        retract: 2.0,
    },
    step_mm: [0.001; MAX_AXES],
};

/// Blocks through lattice points (steps), planned as one long cruise at `v`.
pub(crate) fn chain(points: &[[i64; MAX_AXES]], v: f64) -> Vec<StepBlock> {
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
                line: i as u64 + 1,
                flags: 0,
            }
        })
        .collect()
}

fn p2(x: i64, y: i64) -> [i64; MAX_AXES] {
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

type Move = ([i64; MAX_AXES], bool);

/// Checks the retrace rule on a move sequence: every backward move goes back to the point
/// before on the forward path, and forward moves after a retrace revisit exactly the points
/// retraced, in reverse. Returns the number of backward moves.
fn assert_retraces(path: &[Move]) -> usize {
    let mut stack = vec![path[0].0];
    let mut undone: Vec<[i64; MAX_AXES]> = Vec::new();
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
