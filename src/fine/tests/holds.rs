//! Holds of the tick core: dwell and pause, rapids and collisions, a long short's alarm, the
//! creep floor, probing, and the overrides.

use super::*;

/// A dwell holds the electrode at its block's start for `dwell_s / dt` ticks; a pause holds it
/// until released; neither repeats when a turn-back brings the block back.
#[test]
fn dwell_and_pause_hold_at_the_block_start_once() {
    let mut blocks = chain(&[p2(0, 0), p2(40, 0), p2(80, 0), p2(120, 0)], 2.0);
    blocks[1].dwell_s = 0.01; // 200 ticks at 50 µs
    blocks[1].v_entry = 0.0;
    blocks[0].v_exit = 0.0;
    blocks[2].flags |= BlockFlags::PAUSE;
    blocks[2].v_entry = 0.0;
    blocks[1].v_exit = 0.0;
    let mut source = VecSource::new(blocks, 4);
    let mut fine = Interpolator::new(SETTINGS, [0; MAX_AXES]);
    let mut still_at_40 = 0u64;
    let mut still_at_40_again = 0u64;
    let mut paused_at = None;
    let mut released = false;
    let mut short_ticks = 0u64;
    let mut min_x_after_short = i64::MAX;
    let mut hold = false;
    for t in 0..2_000_000u64 {
        fine.set_hold(hold);
        // A short just after the dwell takes the electrode back into block 0; the re-advance
        // enters block 1 again.
        if fine.position()[0] == 41 && short_ticks == 0 {
            short_ticks = 1;
        }
        let gap = if (1..400).contains(&short_ticks) {
            short_ticks += 1;
            GapState::Short
        } else {
            GapState::Normal
        };
        let shorted = short_ticks > 0;
        let tick = fine.tick(gap, &mut source);
        if fine.position()[0] == 40 && !tick.moved() {
            if shorted {
                still_at_40_again += 1;
            } else {
                still_at_40 += 1;
            }
        }
        if shorted {
            min_x_after_short = min_x_after_short.min(fine.position()[0]);
        }
        if let Some(ServoEvent::Paused { at, .. }) = tick.event {
            assert!(paused_at.is_none(), "the pause is reported once");
            assert_eq!(fine.position()[0], 80);
            assert_eq!(at.seq, 2);
            paused_at = Some(t);
            hold = true;
        }
        if let Some(p) = paused_at
            && !released
        {
            assert_eq!(fine.position()[0], 80, "held at the pause");
            if t == p + 1000 {
                assert!(fine.still());
                hold = false;
                released = true;
            }
        }
        if fine.state().is_final() {
            break;
        }
    }
    assert_eq!(fine.state(), ServoState::Done);
    assert_eq!(fine.position()[0], 120);
    assert!(released);
    // Passing 40 twice (back and forth) at servo speeds takes some 30 ticks; a dwell, 200.
    assert!(
        min_x_after_short < 40,
        "the turn-back left block 1 ({min_x_after_short})"
    );
    assert!(
        still_at_40_again < 100,
        "the dwell was repeated: {still_at_40_again} ticks"
    );
    // 200 dwell ticks, plus the few ticks the arrival and departure take at creep speed.
    assert!(
        (200..230).contains(&still_at_40),
        "still at the dwell point for {still_at_40} ticks"
    );
}

/// A rapid runs at its planned speed whatever the servo feeds say; a short during it is a
/// collision: motion stops on the spot, no turn-back, the interpolator holds until released.
#[test]
fn rapids_ignore_the_servo_and_a_short_in_one_is_a_collision() {
    let mut blocks = chain(&[p2(0, 0), p2(2000, 0), p2(2100, 0)], 15.0);
    blocks[0].flags |= BlockFlags::RAPID;
    blocks[1].v_cruise = 0.5;
    blocks[1].v_entry = 0.0;
    blocks[0].v_exit = 0.0;
    let mut source = VecSource::new(blocks, 4);
    let mut fine = Interpolator::new(SETTINGS, [0; MAX_AXES]);
    let mut top_speed: f64 = 0.0;
    let mut collided_at = None;
    let mut hold = false;
    for t in 0..4_000_000u64 {
        fine.set_hold(hold);
        // Contact at 1.5 mm into the rapid, for 100 ticks.
        let x = fine.position()[0];
        let gap = match collided_at {
            None if x == 1500 => GapState::Short,
            Some(at) if t < at + 100 => GapState::Short,
            _ => GapState::Normal,
        };
        let tick = fine.tick(gap, &mut source);
        assert!(tick.dir >= 0, "no turn-back in a rapid");
        if fine
            .block()
            .is_some_and(|b| b.flags.contains(BlockFlags::RAPID))
        {
            top_speed = top_speed.max(fine.speed());
        }
        if let Some(ServoEvent::Collision { at }) = tick.event {
            assert!(collided_at.is_none(), "reported once while held");
            assert_eq!((at.seq, fine.position()[0]), (0, 1500));
            assert_eq!(fine.speed(), 0.0);
            collided_at = Some(t);
            hold = true;
        }
        if let Some(at) = collided_at
            && hold
        {
            assert_eq!(fine.position()[0], 1500, "stopped on the spot");
            if t == at + 200 {
                hold = false; // the operator clears the contact and resumes
            }
        }
        if fine.state().is_final() {
            break;
        }
    }
    assert_eq!(fine.state(), ServoState::Done);
    assert_eq!(fine.position()[0], 2100);
    assert!(collided_at.is_some());
    // Far above the servo's normal feed of 1 mm/s: the planned rapid speed (one step per tick
    // caps it at 20 mm/s here; the plan says 15).
    assert!(top_speed > 14.0, "rapid top speed {top_speed} mm/s");
    assert_eq!(fine.counters().servo.collisions, 1);
    assert_eq!(fine.counters().servo.shorts, 0);
}

/// A short that outlasts `max_short_ticks` raises the alarm (timed out) and holds; when the
/// operator releases the hold with the gap flushed, the re-advance goes back to the point of
/// the short and the job ends exactly on the last point.
#[test]
fn a_long_short_alarms_and_a_release_re_advances_to_the_end() {
    let blocks = chain(&[p2(0, 0), p2(300, 0), p2(600, 0), p2(900, 0)], 1.0);
    let settings = FineSettings {
        max_short_ticks: 2_000,
        ..SETTINGS
    };
    let mut source = VecSource::new(blocks, 4);
    let mut fine = Interpolator::new(settings, [0; MAX_AXES]);
    let mut alarm_at = None;
    let mut short_from = None;
    let mut hold = false;
    for t in 0..10_000_000u64 {
        fine.set_hold(hold);
        if fine.position()[0] == 450 && short_from.is_none() {
            short_from = Some(t);
        }
        // Shorted for 50,000 ticks (2.5 s) from the point 450: the turn-back alone cannot clear it.
        let gap = match short_from {
            Some(from) if t < from + 50_000 => GapState::Short,
            _ => GapState::Normal,
        };
        let tick = fine.tick(gap, &mut source);
        if let Some(ServoEvent::Alarm { timed_out, .. }) = tick.event {
            assert!(timed_out, "the reserved history was not used up");
            assert!(alarm_at.is_none());
            alarm_at = Some(t);
            hold = true; // the daemon holds the job
        }
        if let (Some(at), true) = (alarm_at, hold) {
            assert!(!tick.moved(), "moved while alarm-held");
            if t >= short_from.unwrap() + 60_000 {
                assert!(t > at);
                hold = false; // flushed; the operator resumes
            }
        }
        if fine.state() == ServoState::Done {
            break;
        }
    }
    let at = alarm_at.expect("an alarm");
    let from = short_from.unwrap();
    assert!(
        (at - from).abs_diff(2_000) < 10,
        "alarm {} ticks into the short",
        at - from
    );
    assert_eq!(fine.state(), ServoState::Done);
    assert_eq!(fine.position()[0], 900);
    assert_eq!(fine.counters().servo.alarms, 1);
}

/// A programmed feed below the creep speed (`sqrt(a · step)`, 1.55 mm/s here) is kept: the
/// creep floor only lifts the braking tail, never the cruise (F30 ran at 93 mm/min before).
#[test]
fn a_slow_programmed_feed_is_not_lifted_to_the_creep_speed() {
    let blocks = chain(&[p2(0, 0), p2(400, 0)], 0.5);
    let mut source = VecSource::new(blocks, 4);
    let mut fine = Interpolator::new(SETTINGS, p2(0, 0));
    let mut max = 0.0f64;
    for _ in 0..40_000 {
        fine.tick(GapState::Normal, &mut source);
        max = max.max(fine.speed());
        if fine.state().is_final() {
            break;
        }
    }
    assert_eq!(fine.position(), p2(400, 0));
    assert!(max <= 0.5 + 1e-9, "ran at {max} mm/s, programmed 0.5");
}

#[test]
fn a_probe_judges_contact_only_on_a_reading_of_the_contact() {
    // One probing move towards the switch (G38.4-like: probing away, it ends when contact
    // is lost). A reading taken before the input knew of the probe reads the gap (open
    // here), which is "contact lost" to a probe away: the move must stand, not end.
    let mut blocks = chain(&[p2(0, 0), p2(5000, 0)], 10.0);
    blocks[0].flags = BlockFlags::PROBE | BlockFlags::PROBE_AWAY | BlockFlags::LAST_OF_BLOCK;
    let mut source = VecSource::new(blocks, 4);
    let mut fine = Interpolator::new(SETTINGS, p2(0, 0));
    fine.set_contact_reading(false);
    for _ in 0..20 {
        let tick = fine.tick(GapState::Open, &mut source);
        assert!(!tick.moved() && tick.event.is_none(), "{:?}", tick.event);
    }
    // Contact readings now: still in contact (short), it backs off; open ends it.
    fine.set_contact_reading(true);
    let mut moved = 0;
    for _ in 0..400 {
        moved += i32::from(fine.tick(GapState::Short, &mut source).moved());
    }
    assert!(moved > 0, "backs off while the contact holds");
    let tick = fine.tick(GapState::Open, &mut source);
    assert!(
        matches!(
            tick.event,
            Some(ServoEvent::Probed {
                contact: true,
                away: true,
                ..
            })
        ),
        "{:?}",
        tick.event
    );
}

#[test]
fn the_feed_override_scales_the_cruise_and_brakes_under_the_acceleration() {
    // A long cut planned at 2 mm/s whose limits without the programmed feed allow 3 mm/s;
    // the gap is open, so the servo asks for its open feed (5 mm/s), above both.
    let mut blocks = chain(&[p2(0, 0), p2(200_000, 0)], 2.0);
    blocks[0].v_limit = 3.0;
    let mut source = VecSource::new(blocks, 4);
    let mut fine = Interpolator::new(SETTINGS, p2(0, 0));
    let dv = SETTINGS.accel * SETTINGS.dt;
    let mut settle = |fine: &mut Interpolator, feed: f64| {
        fine.set_overrides(Overrides { feed, rapid: 1.0 });
        let mut last = fine.speed();
        for _ in 0..4000 {
            fine.tick(GapState::Open, &mut source);
            let speed = fine.speed();
            assert!(
                (speed - last).abs() <= dv + 1e-9,
                "speed jumped {last} -> {speed}"
            );
            last = speed;
        }
        last
    };
    assert!(
        (settle(&mut fine, 1.0) - 2.0).abs() < 1e-9,
        "100 %: the plan's cruise"
    );
    assert!((settle(&mut fine, 0.5) - 1.0).abs() < 1e-9, "50 %");
    assert!((settle(&mut fine, 1.25) - 2.5).abs() < 1e-9, "125 %");
    assert!(
        (settle(&mut fine, 2.0) - 3.0).abs() < 1e-9,
        "200 %: held to v_limit"
    );
    assert_eq!(settle(&mut fine, 0.0), 0.0, "0 %: braked to a standstill");
    let at = fine.position();
    settle(&mut fine, 0.0);
    assert_eq!(fine.position(), at, "and stays");
}

#[test]
fn the_rapid_override_scales_rapids_and_not_cuts() {
    let mut blocks = chain(&[p2(0, 0), p2(200_000, 0)], 4.0);
    blocks[0].flags = BlockFlags::RAPID | BlockFlags::LAST_OF_BLOCK;
    let mut source = VecSource::new(blocks, 4);
    let mut fine = Interpolator::new(SETTINGS, p2(0, 0));
    fine.set_overrides(Overrides {
        feed: 0.1,
        rapid: 0.5,
    });
    for _ in 0..4000 {
        fine.tick(GapState::Open, &mut source);
    }
    assert!((fine.speed() - 2.0).abs() < 1e-9, "{}", fine.speed());
}

/// A turn-back at a retract feed 40 times the programmed one (F3 against 120 mm/min) goes at
/// the retract feed, slows for the path's stop corner behind it to the creep speed, and the
/// re-advance retraces the same points back to the end.
#[test]
fn a_turn_back_goes_at_the_retract_feed_and_slows_for_the_path_s_corners() {
    let mut blocks = super::chain(&[p2(0, 0), p2(100, 0), p2(100, 200)], 0.05);
    blocks[0].path.exit = 0.0;
    blocks[1].path.entry = 0.0;
    let mut source = VecSource::new(blocks, 4);
    let mut fine = Interpolator::new(SETTINGS, [0; MAX_AXES]);
    let creep = (SETTINGS.reverse_accel * 0.001).sqrt();
    let (mut fastest_back, mut at_corner) = (0.0f64, None);
    let mut seq = 0;
    let mut path = vec![([0; MAX_AXES], false)];
    let mut short_from = None;
    for t in 0..20_000_000u64 {
        // Short from 150 steps in (block 1, 50 µm past the corner) for 60 ms: about 120 µm
        // back at 2 mm/s, over the corner.
        if fine.position()[1] >= 50 && short_from.is_none() {
            short_from = Some(t);
        }
        let gap = match short_from {
            Some(from) if t < from + 1_200 => GapState::Short,
            _ => GapState::Normal,
        };
        let tick = fine.tick(gap, &mut source);
        if tick.dir < 0 {
            fastest_back = fastest_back.max(fine.speed());
        }
        if tick.moved() {
            path.push((fine.position(), tick.dir < 0));
        }
        if fine.here().seq != seq {
            if fine.state() == ServoState::TurnBack {
                at_corner = Some(fine.speed());
            }
            seq = fine.here().seq;
        }
        if fine.state().is_final() {
            break;
        }
    }
    assert_eq!(fine.state(), ServoState::Done);
    assert_eq!(fine.position(), p2(100, 200));
    assert!((fastest_back - 2.0).abs() < 1e-9, "{fastest_back}");
    let corner = at_corner.expect("turned back over the corner");
    assert!(
        corner <= creep + SETTINGS.reverse_accel * SETTINGS.dt,
        "{corner} mm/s at a stop corner"
    );
    assert!(super::assert_retraces(&path) > 100);
}
