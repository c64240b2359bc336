//! The electrode's motion along the program: the block in hand, its Bresenham walk, the path
//! speed and direction, the DDA phase and the pulse ledger. It knows nothing of the gap: the
//! servo and the excursions decide where to go and how fast, [`Motion`] carries it out under
//! the planner's limits.

use super::bresenham::Bresenham;
use super::jerk::{self, JerkLimits, Room};
use crate::buffer::{BlockFlags, StepBlock};
use crate::servo::PathPoint;
use crate::vocab::{MAX_AXES, Steps};

/// Where the electrode is along the program and how it moves.
#[derive(Debug, Clone)]
pub(super) struct Motion {
    pub block: StepBlock,
    /// A block is in hand (false before the first block and while starved).
    pub has_block: bool,
    /// Where along the path (mm from the program's start) the electrode stands with no
    /// block in hand: the end of the last block it left forward (0 before the first).
    pub passed_mm: f64,
    pub walk: Bresenham,
    /// Lattice distance of one event of the block in hand (mm).
    pub event_mm: f64,
    /// Lattice length of the block in hand (mm).
    pub lattice_mm: f64,
    /// Believed position in steps: the pulse ledger.
    pub position: Steps,
    /// Path speed (mm/s), always >= 0; `dir` gives its sense.
    pub speed: f64,
    /// Rate of change of `speed` over the last tick (mm/s²): where a jerk-limited tick
    /// carries on from (its sign flips with `dir` on a reversal through a standstill).
    pub accel: f64,
    pub dir: i8,
    /// Fraction of the next event already covered.
    pub phase: f64,
    /// The operator's overrides of the planned feed ceiling.
    pub overrides: Overrides,
    /// The cruise a forward move of the block in hand aims for under the override (its
    /// `v_cruise` scaled), kept when the block or the override changes, not each tick.
    pub aim: f64,
}

/// The operator's feed and rapid overrides, as fractions (1.0 is 100 %): they scale the
/// planned cruise of a forward move (a rapid's by `rapid`, any other's by `feed`), never the
/// braking the plan needs, and never a turn-back or an excursion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Overrides {
    /// 0 to 2.
    pub feed: f64,
    /// 0 to 1.
    pub rapid: f64,
}

impl Default for Overrides {
    fn default() -> Self {
        Overrides {
            feed: 1.0,
            rapid: 1.0,
        }
    }
}

/// Whose limits a tick's speed goes by.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Pace {
    /// The feed's plan: braking under `accel` (`a_T`, what the plan was made with) to its
    /// junction speeds, towards `cruise`; `stop_at_end` ends the block at a standstill.
    Plan {
        accel: f64,
        cruise: f64,
        stop_at_end: bool,
    },
    /// The servo's own motion (a turn-back, a re-advance, a law backing off): the path's
    /// limits under the reversal's `accel`; re-advancing, `to_mark` is the way left to the
    /// point of the short, reached no faster than the plan (made under `plan_accel`) goes on.
    Servo {
        accel: f64,
        plan_accel: f64,
        to_mark: Option<f64>,
    },
}

impl Motion {
    /// Standing at `start` (steps) with no block in hand.
    pub fn new(start: Steps) -> Motion {
        Motion {
            block: StepBlock::EMPTY,
            has_block: false,
            passed_mm: 0.0,
            walk: Bresenham::new(&[0; MAX_AXES], false),
            event_mm: 0.0,
            lattice_mm: 0.0,
            position: start,
            speed: 0.0,
            accel: 0.0,
            dir: 1,
            phase: 0.0,
            overrides: Overrides::default(),
            aim: 0.0,
        }
    }

    /// The override changed.
    pub fn set_overrides(&mut self, overrides: Overrides) {
        self.overrides = overrides;
        self.aim = self.block.v_cruise * self.override_factor();
    }

    /// The override that applies to the block in hand.
    #[inline]
    fn override_factor(&self) -> f64 {
        if self.block.flags.contains(BlockFlags::RAPID) {
            self.overrides.rapid
        } else {
            self.overrides.feed
        }
    }

    /// Where along the program the electrode is.
    #[inline]
    pub fn here(&self) -> PathPoint {
        PathPoint {
            seq: self.block.seq,
            event: self.walk.event(),
        }
    }

    /// A block is in hand and carries every flag of `flags`.
    #[inline]
    pub fn holds(&self, flags: BlockFlags) -> bool {
        self.has_block && self.block.flags.contains(flags)
    }

    /// Stops on the spot (no braking: a collision, a contact, a dwell, an alarm).
    #[inline]
    pub fn stop(&mut self) {
        self.speed = 0.0;
        self.accel = 0.0;
        self.phase = 0.0;
    }

    /// Takes the block just copied into `block` in hand, at its start or (walking back into
    /// it) at its end; `step_mm` converts its steps to the lattice length.
    pub fn enter(&mut self, at_end: bool, step_mm: &[f64; MAX_AXES]) {
        self.has_block = true;
        let delta = self.block.delta();
        self.walk = Bresenham::new(&delta, at_end);
        let mut len2 = 0.0;
        for (d, s) in delta.iter().zip(step_mm) {
            let mm = *d as f64 * s;
            len2 += mm * mm;
        }
        self.lattice_mm = len2.sqrt();
        self.event_mm = if self.walk.events() > 0 {
            self.lattice_mm / self.walk.events() as f64
        } else {
            0.0
        };
        self.aim = self.block.v_cruise * self.override_factor();
    }

    /// The planner's speed limit at the current point, in the current direction: its braking
    /// curves, never below the creep speed `sqrt(accel · event)`, nor above what the block
    /// allows whatever its feed (`v_limit`, for an override above 100 %; the cruise the
    /// speed aims for is the caller's business); capped at one event per tick of `dt`.
    /// `stop_at_end`: going forward, the block ends at a standstill whatever the plan said
    /// (single block).
    #[inline]
    fn planned_limit(&self, accel: f64, dt: f64, stop_at_end: bool) -> f64 {
        let b = &self.block;
        let v_exit = if stop_at_end { 0.0 } else { b.v_exit };
        self.limit_between(b.v_entry, v_exit, b.v_limit.max(b.v_cruise), accel, dt)
    }

    /// The acceleration, the cruise aimed for and the speed limit of this tick, by `pace`.
    #[inline]
    pub fn bounds(&self, pace: Pace, dt: f64) -> (f64, f64, f64) {
        match pace {
            Pace::Plan {
                accel,
                cruise,
                stop_at_end,
            } => (accel, cruise, self.planned_limit(accel, dt, stop_at_end)),
            Pace::Servo {
                accel,
                plan_accel,
                to_mark,
            } => {
                let mut limit = self.path_limit(accel, dt);
                if let Some(way) = to_mark {
                    let plan = self.planned_limit(plan_accel, dt, false).min(self.aim);
                    limit = limit.min((plan * plan + 2.0 * accel * way).sqrt());
                }
                (accel, self.block.path.cruise, limit)
            }
        }
    }

    /// The path's own limit at the current point, in the current direction, for the servo's
    /// own motion (a turn-back at the retract feed, the re-advance): its corners braked for at
    /// `accel` (the reversal's), its cruise whatever the programmed feed, never below the
    /// creep speed, capped at one event per tick.
    #[inline]
    fn path_limit(&self, accel: f64, dt: f64) -> f64 {
        let p = &self.block.path;
        self.limit_between(p.entry, p.exit, p.cruise, accel, dt)
    }

    /// The braking curves to `v_start` at the block's start and `v_end` at its end, under
    /// `top`, from the current point in the current direction.
    #[inline]
    fn limit_between(&self, v_start: f64, v_end: f64, top: f64, accel: f64, dt: f64) -> f64 {
        if !self.has_block || self.walk.events() == 0 {
            return 0.0;
        }
        let a2 = 2.0 * accel;
        let done = (self.walk.event() as f64 + self.phase.min(1.0) * self.dir as f64)
            / self.walk.events() as f64;
        let s = (done.clamp(0.0, 1.0)) * self.lattice_mm;
        let (v_behind, v_ahead, to_go, gone) = if self.dir > 0 {
            (v_start, v_end, self.lattice_mm - s, s)
        } else {
            (v_end, v_start, s, self.lattice_mm - s)
        };
        let v2 = (v_ahead * v_ahead + a2 * to_go).min(v_behind * v_behind + a2 * gone);
        let creep = (accel * self.event_mm).sqrt();
        let cap = self.event_mm / dt;
        v2.sqrt().max(creep).min(top).min(cap)
    }

    /// The lattice distance to the end of the block in hand in the current direction (mm).
    #[inline]
    pub fn way_left(&self) -> f64 {
        if self.walk.events() == 0 {
            return 0.0;
        }
        let done = (self.walk.event() as f64 + self.phase.min(1.0) * self.dir as f64)
            / self.walk.events() as f64;
        let s = done.clamp(0.0, 1.0) * self.lattice_mm;
        if self.dir > 0 { self.lattice_mm - s } else { s }
    }

    /// Moves the speed towards `target` by at most `a_T · dt`, never above `limit` while
    /// braking (the trapezoid).
    #[inline]
    pub fn follow(&mut self, target: f64, limit: f64, accel: f64, dt: f64) {
        let (before, dv) = (self.speed, accel * dt);
        self.speed = if self.speed > target {
            (self.speed - dv).max(target).min(limit)
        } else {
            (self.speed + dv).min(target)
        };
        self.accel = (self.speed - before) / dt;
    }

    /// Moves the speed towards `target` with the acceleration changing by at most `J · dt`
    /// ([`super::jerk::step`]), able to stop within `room`, never above `limit` (the plan's
    /// hard ceiling: a corner of the path on an excursion), finishing the last `event_mm` at
    /// the creep speed.
    #[inline]
    pub fn follow_jerk(
        &mut self,
        target: f64,
        limit: f64,
        room: Option<Room>,
        limits: JerkLimits,
        dt: f64,
        event_mm: f64,
    ) {
        let creep = jerk::creep(limits.jerk, event_mm);
        let (v, a) = jerk::step(
            self.speed,
            self.accel,
            target.min(limit),
            room,
            creep,
            limits,
            dt,
        );
        if v > limit {
            self.accel = (limit - self.speed) / dt;
            self.speed = limit;
        } else {
            self.speed = v;
            self.accel = a;
        }
    }

    /// The DDA: covers one tick of `dt` at the current speed; `true` when that completes an
    /// event (at most one per tick: the speed is capped at one event per tick).
    #[inline]
    pub fn event_due(&mut self, dt: f64) -> bool {
        self.phase += self.speed * dt / self.event_mm;
        if self.phase < 1.0 {
            return false;
        }
        self.phase = (self.phase - 1.0).min(0.999_999);
        true
    }

    /// Adds one event's steps to the ledger.
    #[inline]
    fn add_steps(&mut self, steps: &[i8; MAX_AXES]) {
        for (p, &s) in self.position.iter_mut().zip(steps) {
            *p += s as i64;
        }
    }

    /// Walks forward, emitting nothing, to event `event` of the block in hand (its end if
    /// `None`), keeping the ledger.
    pub fn walk_silently_to(&mut self, event: Option<i64>) {
        let mut scratch = [0i8; MAX_AXES];
        let end = event.unwrap_or(self.walk.events());
        while self.walk.event() < end {
            self.walk.forward(&mut scratch);
            self.add_steps(&scratch);
        }
    }
}
