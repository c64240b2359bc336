//! Jerk-limited speed for positioning moves: rapids, jumps and the rethread's return.
//!
//! A trapezoid changes the acceleration from 0 to `a_T` in one tick, which is an infinite jerk:
//! on a sinker's fast jump it shakes the machine. With `machine.max_jerk_mm_per_s3` set, the
//! tick core moves the speed of those moves so that the acceleration changes by at most
//! `J · dt` per tick (an S-curve), and cutting moves keep their trapezoid (the gap sets the
//! feed there, at speeds where the jerk is small).
//!
//! The profile is made online, one tick at a time, so that it answers a hold, an override or a
//! shorter way exactly as the trapezoid does. Each tick takes the largest acceleration within
//! `±J · dt` of the last one that (1) does not carry the speed past what it aims for once the
//! acceleration is ramped back to zero (`v + a·|a| / 2J`), and (2) still leaves room to stop:
//! [`stopping_distance`] from the state after the tick, the exact length of the fastest
//! jerk-limited braking, fits in the way left. Both tests are of the continuous profile, so
//! the speed follows the S-curve to within the tick's own rounding, and near the end, where
//! the stop's last fraction of an event would take forever, a creep speed
//! `(J · event²)^⅓` (the speed from which a jerk-limited stop takes one event) finishes it:
//! the pulse log can not tell a stop from that speed from a smooth one by more than a step.

/// The limits of a jerk-limited move: acceleration (mm/s²) and jerk (mm/s³), both > 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JerkLimits {
    pub accel: f64,
    pub jerk: f64,
}

/// The way left to a point the speed must be at most `v_end` at (mm, mm/s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Room {
    pub mm: f64,
    pub v_end: f64,
}

/// The length of the shortest jerk-limited braking from speed `v` and acceleration `a`
/// (along the motion; `a < 0` is already braking) to at most `v_end` with no acceleration
/// left, under `limits`. A state that can not avoid going below `v_end` (it brakes too hard
/// to ease off in time) needs only the way to `v_end`.
fn stopping_distance(v: f64, a: f64, v_end: f64, limits: JerkLimits) -> f64 {
    let JerkLimits { accel, jerk } = limits;
    let (mut v, mut d) = (v, 0.0);
    // Still speeding up: ease the acceleration off first.
    let mut b = -a;
    if a > 0.0 {
        let t = a / jerk;
        d += v * t + a * t * t / 2.0 - jerk * t * t * t / 6.0;
        v += a * a / (2.0 * jerk);
        b = 0.0;
    }
    let dv = v - v_end;
    if dv <= 0.0 {
        return d;
    }
    if dv <= b * b / (2.0 * jerk) {
        // Easing the braking off alone passes v_end: the way until it gets there.
        let t = (b - (b * b - 2.0 * jerk * dv).max(0.0).sqrt()) / jerk;
        return d + v * t - b * t * t / 2.0 + jerk * t * t * t / 6.0;
    }
    // Brake harder to the peak p (at most accel), hold it, ease off to v_end.
    let peak_free = ((2.0 * jerk * dv + b * b) / 2.0).sqrt();
    let (p, t2) = if peak_free <= accel {
        (peak_free, 0.0)
    } else {
        let p = accel.max(b);
        let lost = (2.0 * p * p - b * b) / (2.0 * jerk);
        (p, ((dv - lost) / p).max(0.0))
    };
    let t1 = ((p - b) / jerk).max(0.0);
    let d1 = v * t1 - b * t1 * t1 / 2.0 - jerk * t1 * t1 * t1 / 6.0;
    let v1 = v - b * t1 - jerk * t1 * t1 / 2.0;
    let d2 = v1 * t2 - p * t2 * t2 / 2.0;
    let v2 = v1 - p * t2;
    let t3 = p / jerk;
    let d3 = v2 * t3 - p * t3 * t3 / 2.0 + jerk * t3 * t3 * t3 / 6.0;
    d + d1 + d2 + d3
}

/// The speed from which a jerk-limited stop takes `event_mm`: below it the last fraction of
/// a move is finished at this speed rather than never.
#[inline]
pub fn creep(jerk: f64, event_mm: f64) -> f64 {
    (jerk * event_mm * event_mm).cbrt()
}

/// One tick of `dt` from speed `v` and acceleration `a`: the new speed and acceleration,
/// aiming for `target` (>= 0) and able to stop within `room`. The speed never goes below 0;
/// reaching 0 keeps the acceleration so a reversal carries on from it.
#[inline]
pub fn step(
    v: f64,
    a: f64,
    target: f64,
    room: Option<Room>,
    creep: f64,
    limits: JerkLimits,
    dt: f64,
) -> (f64, f64) {
    let JerkLimits { accel, jerk } = limits;
    let lo = (a - jerk * dt).max(-accel);
    let hi = (a + jerk * dt).min(accel);
    // (1) Aim: the acceleration whose easing-off lands on the target.
    // v1 + a1·|a1| / 2J = target, with v1 = v + (a + a1)·dt / 2 the speed after the tick.
    let e = target - v - a * dt / 2.0;
    let half = dt / 2.0;
    let aim = e.signum() * jerk * ((half * half + 2.0 * e.abs() / jerk).sqrt() - half);
    let mut next = aim.clamp(lo, hi);
    // (2) Room: the largest acceleration not above that from which the stop still fits.
    if let Some(mut room) = room {
        if target > 0.0 {
            // A move that wants on brakes to the creep speed, not to a standstill it would
            // reach only in the limit: it arrives at creep speed with no acceleration left.
            room.v_end = room.v_end.max(creep);
        }
        let fits = |a1: f64| {
            let v1 = v + (a + a1) / 2.0 * dt;
            let left = room.mm - (v + v1) / 2.0 * dt;
            stopping_distance(v1, a1, room.v_end, limits) <= left
        };
        if !fits(next) {
            let (mut bad, mut good) = (next, lo);
            if fits(good) {
                for _ in 0..40 {
                    let mid = (bad + good) / 2.0;
                    if fits(mid) {
                        good = mid;
                    } else {
                        bad = mid;
                    }
                }
            }
            next = good;
        }
    }
    let v1 = v + (a + next) / 2.0 * dt;
    if target == 0.0 && v1 <= jerk * dt * dt {
        // Stopped: what is left is below what a tick of jerk can tell.
        return (0.0, 0.0);
    }
    // Below the creep speed a move that wants on does not slow down further before its end:
    // the last fraction of an event is finished at the speed it has.
    let floor = v.min(creep);
    if target > 0.0 && room.is_some_and(|r| r.mm > 0.0) && v1 < floor {
        return (floor, 0.0);
    }
    (v1.max(0.0), next)
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: JerkLimits = JerkLimits {
        accel: 2400.0,
        jerk: 1e5,
    };

    /// The stop from (v, a) integrated finely with the same phases' jerks, as a reference.
    fn simulated_stop(v: f64, a: f64, limits: JerkLimits) -> f64 {
        // Greedy in tiny steps: brake as hard as the jerk allows until the ease-off from the
        // current state just reaches zero speed, then ease off.
        let dt = 1e-7;
        let (mut v, mut a, mut s) = (v, a, 0.0);
        while v > 0.0 {
            let ease = a * a / (2.0 * limits.jerk);
            let j = if a >= 0.0 || v > ease {
                -limits.jerk
            } else {
                limits.jerk
            };
            a = (a + j * dt).clamp(-limits.accel, limits.accel);
            let v1 = v + a * dt;
            s += (v + v1.max(0.0)) / 2.0 * dt;
            v = v1;
        }
        s
    }

    #[test]
    fn the_stopping_distance_matches_a_fine_integration() {
        for (v, a) in [
            (20.0, 0.0),
            (100.0, 0.0),
            (20.0, 1000.0),
            (20.0, -1000.0),
            (100.0, -2400.0),
            (1.0, 0.0),
        ] {
            let d = stopping_distance(v, a, 0.0, LIMITS);
            let sim = simulated_stop(v, a, LIMITS);
            assert!(
                (d - sim).abs() < 1e-4 * sim.max(1e-3),
                "v {v} a {a}: {d} against {sim}"
            );
        }
        // The textbook forms from rest: below A²/J no hold, above it a hold at A.
        let (a, j) = (LIMITS.accel, LIMITS.jerk);
        let v = 20.0;
        assert!((stopping_distance(v, 0.0, 0.0, LIMITS) - v * (v / j).sqrt()).abs() < 1e-12);
        let v = 100.0;
        let d = v / 2.0 * (v / a + a / j);
        assert!((stopping_distance(v, 0.0, 0.0, LIMITS) - d).abs() < 1e-9);
    }

    /// Runs a move of `length` mm from rest aiming at `cruise`: ticks, peak |jerk| seen per
    /// tick, and the speed left when the way is gone.
    fn run(length: f64, cruise: f64, dt: f64) -> (usize, f64, f64, f64) {
        let (mut v, mut a, mut s, mut worst) = (0.0, 0.0, 0.0, 0.0f64);
        let mut ticks = 0;
        let creep = creep(LIMITS.jerk, 1e-4);
        while s < length && ticks < 10_000_000 {
            let room = Room {
                mm: length - s,
                v_end: 0.0,
            };
            let (v1, a1) = step(v, a, cruise, Some(room), creep, LIMITS, dt);
            worst = worst.max((a1 - a).abs() / dt);
            s += (v + v1) / 2.0 * dt;
            v = v1;
            a = a1;
            ticks += 1;
        }
        (ticks, worst, v, a)
    }

    #[test]
    fn a_move_ramps_within_the_jerk_and_arrives_slowly() {
        let dt = 50e-6;
        for (length, cruise) in [(50.0, 20.0), (0.1, 20.0), (5.0, 100.0)] {
            let (ticks, worst, v, a) = run(length, cruise, dt);
            assert!(
                worst <= LIMITS.jerk * (1.0 + 1e-9),
                "{length}: jerk {worst}"
            );
            assert!(
                v <= creep(LIMITS.jerk, 1e-4) + 1e-9,
                "{length}: arrives at {v}"
            );
            assert!(
                a.abs() <= LIMITS.jerk * dt * 4.0,
                "{length}: arrives accelerating {a}"
            );
            // Not much slower than the continuous S-curve's time.
            let ideal = ideal_time(length, cruise);
            let t = ticks as f64 * dt;
            assert!(
                t < ideal * 1.05 + 0.005,
                "{length}: {t} s against {ideal} s"
            );
        }
    }

    /// The time of the continuous rest-to-rest S-curve over `length` at up to `cruise`.
    fn ideal_time(length: f64, cruise: f64) -> f64 {
        let (a, j) = (LIMITS.accel, LIMITS.jerk);
        let ramp = |v: f64| {
            if v >= a * a / j {
                v / a + a / j
            } else {
                2.0 * (v / j).sqrt()
            }
        };
        let d = |v: f64| v * ramp(v);
        if d(cruise) <= length {
            return 2.0 * ramp(cruise) + (length - d(cruise)) / cruise;
        }
        let (mut lo, mut hi) = (0.0, cruise);
        for _ in 0..60 {
            let mid = (lo + hi) / 2.0;
            if d(mid) <= length {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        2.0 * ramp(lo)
    }

    #[test]
    fn a_lower_aim_brakes_down_to_it_without_overshoot() {
        let dt = 50e-6;
        let (mut v, mut a) = (20.0, 0.0);
        let mut lowest = f64::MAX;
        for _ in 0..20_000 {
            let (v1, a1) = step(v, a, 5.0, None, 0.0, LIMITS, dt);
            assert!((a1 - a).abs() <= LIMITS.jerk * dt * (1.0 + 1e-9));
            v = v1;
            a = a1;
            lowest = lowest.min(v);
        }
        assert!((v - 5.0).abs() < 1e-3, "{v}");
        assert!(lowest > 5.0 - 0.01, "undershot to {lowest}");
    }
}

#[cfg(test)]
mod tick_core {
    use crate::buffer::{BlockFlags, VecSource};
    use crate::fine::Interpolator;
    use crate::fine::tests::{SETTINGS, chain, p2};
    use crate::vocab::GapState;

    /// A rapid of ten 1 mm blocks at 20 mm/s, held halfway and released: in every tick the
    /// acceleration changes by at most `J · dt` (but where the creep speed finishes the
    /// move), and the rapid ends on its end point.
    #[test]
    fn a_held_rapid_brakes_and_restarts_within_the_jerk() {
        let jerk = 1e5;
        let settings = crate::fine::FineSettings { jerk, ..SETTINGS };
        let points: Vec<_> = (0..=10).map(|i| p2(1000 * i, 0)).collect();
        let mut blocks = chain(&points, 20.0);
        let n = blocks.len();
        for (i, b) in blocks.iter_mut().enumerate() {
            b.flags = BlockFlags::RAPID;
            b.rest_mm = (n - 1 - i) as f64;
            if i + 1 == n {
                b.flags |= BlockFlags::LAST_OF_BLOCK;
            }
        }
        let mut source = VecSource::new(blocks, 4);
        let mut fine = Interpolator::new(settings, p2(0, 0));
        let dt = settings.dt;
        let creep = super::creep(jerk, 0.001);
        let (mut v0, mut a0, mut worst) = (0.0, 0.0, 0.0f64);
        let mut stood = 0;
        for tick in 0..400_000u64 {
            if tick == 8_000 {
                fine.set_hold(true);
            }
            if fine.still() && fine.held() {
                stood += 1;
                if stood == 100 {
                    fine.set_hold(false);
                }
            }
            fine.tick(GapState::Open, &mut source);
            if fine.position() == p2(10_000, 0) {
                break;
            }
            let v = fine.speed();
            let a = (v - v0) / dt;
            if v0 > creep * 1.01 || v > creep * 1.01 {
                worst = worst.max((a - a0).abs() / dt);
            }
            v0 = v;
            a0 = a;
        }
        assert_eq!(fine.position(), p2(10_000, 0));
        assert!(stood >= 100, "never stood still while held");
        assert!(worst <= jerk * 1.001, "{worst:.4e} mm/s³");
    }

    /// A rethread's way back to the start hole and its return to the break, under a jerk
    /// limit: within it every tick, slowing to the creep speed before the start hole (the
    /// contour's lattice length tells the tick core how far that is).
    #[test]
    fn a_rethread_goes_back_and_returns_within_the_jerk() {
        use crate::servo::{Excursion, Rethread, ServoEvent, ServoState};
        let jerk = 1e5;
        let settings = crate::fine::FineSettings { jerk, ..SETTINGS };
        let mut blocks = chain(&[p2(0, 0), p2(300, 0), p2(800, 0), p2(800, 600)], 5.0);
        blocks[0].flags |= BlockFlags::RAPID;
        blocks[1].contour_mm = 0.5;
        blocks[2].contour_mm = 1.1;
        let mut source = VecSource::new(blocks, 64);
        let mut fine = Interpolator::new(settings, p2(0, 0));
        while fine.position()[1] < 200 {
            fine.tick(GapState::Normal, &mut source);
        }
        fine.set_wire_input(true);
        fine.tick(GapState::Normal, &mut source);
        assert_eq!(fine.state(), ServoState::WireBroken);
        assert!(fine.rethread(Rethread::AtStart));
        fine.set_wire_input(false);
        fine.set_hold(false);
        let dt = settings.dt;
        let creep = super::creep(jerk, 0.001);
        let (mut v0, mut a0, mut worst, mut arrival) = (0.0, 0.0, 0.0f64, 0.0);
        let mut fastest = 0.0f64;
        let mut back = false;
        for _ in 0..100_000 {
            let tick = fine.tick(GapState::Open, &mut source);
            let v = fine.speed();
            let a = (v - v0) / dt;
            if v0 > creep * 1.01 || v > creep * 1.01 {
                worst = worst.max((a - a0).abs() / dt);
            }
            fastest = fastest.max(v);
            if let Some(ServoEvent::Retreated {
                why: Excursion::Rethread,
                ..
            }) = tick.event
            {
                arrival = v0;
                assert_eq!(fine.position(), p2(300, 0), "at the start hole");
                fine.set_hold(true);
                fine.set_hold(false);
            }
            if let Some(ServoEvent::Returned { .. }) = tick.event {
                back = true;
                break;
            }
            v0 = v;
            a0 = a;
        }
        assert!(back, "never returned to the break");
        assert!(fastest > 4.9, "the rethread feed never reached: {fastest}");
        assert!(arrival <= creep * 1.01, "arrived at {arrival} mm/s");
        assert!(worst <= jerk * 1.001, "{worst:.4e} mm/s³");
    }
}
