//! Excursions from the cut: sinker jumps, probing moves, wire breaks and rethreading.
//!
//! All of them but a jump off an orbit move only over lattice points the program already has,
//! and that one only straight up the tool axis and back by whole steps, so the pulse ledger
//! stays exact whatever happens on the way:
//!
//! - A **jump** (`servo.jump_interval_s`, per machining condition where one sets it) lifts
//!   the electrode back along the executed path by the jump height at the jump feed with the
//!   spark off (on a plunge that is straight up the plunge), then comes back to the point it
//!   left and the servo takes over again. The retreat brakes so that it stops at the height;
//!   it stops early at the start of the cut (a rapid or a probing move behind it, or the end
//!   of the reserved area). Coming back down is a re-advance with the spark off, braking onto
//!   the point it left: a short on the way turns back as usual. On an orbit the jump lifts
//!   straight up the tool axis instead (the spiral behind it would rub the wall just cut)
//!   and comes straight back down.
//! - A **probing move** (`G38.2`…`G38.5`, `G31`) runs at its programmed feed with the servo
//!   out of the loop; contact is the gap reading `short` (the gap input may map a probe pin
//!   onto it). On contact (or, probing away, on losing it) the move stops within the tick and
//!   the rest of it is dropped: the producer plans the program on from the contact point.
//!   Reaching the end point without contact is an error for `G38.2`/`G38.4`.
//! - A **wire break** (the wire-break input, or an open gap over `servo.max_open_mm` of
//!   cutting travel) stops the motion on the spot and parks. The operator's rethread goes
//!   back along the path to the contour's start (the first move after a rapid or a probing
//!   move: the start hole) or threads in place; the resume returns along the path to the
//!   break point with the spark off and cutting carries on there.

use super::jerk::{JerkLimits, Room};
use super::motion::Motion;
use super::{Interpolator, Tick};
use crate::buffer::{BlockFlags, BlockSource, Fetch};

use crate::process::ServoSetPoints;
use crate::servo::{Excursion, Rethread, Servo, ServoEvent, ServoState, Travel};
use crate::vocab::GapState;

/// Jumps, wire-break detection and rethreading, in the interpolator's units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExcursionSettings {
    /// Ticks of cutting between two jumps; 0: no jumps.
    pub jump_interval_ticks: u64,
    /// How far a jump lifts, along the path (mm).
    pub jump_height_mm: f64,
    /// Feed of the jump, up and down (mm/s).
    pub jump_feed: f64,
    /// Cutting travel with the gap open that counts as a wire break (mm); 0: never.
    pub max_open_mm: f64,
    /// Feed of the way back to the start hole and of the return to the break point (mm/s).
    pub rethread_feed: f64,
}

impl ExcursionSettings {
    /// No jumps, no open-gap wire-break detection.
    pub const OFF: ExcursionSettings = ExcursionSettings {
        jump_interval_ticks: 0,
        jump_height_mm: 0.0,
        jump_feed: 1.0,
        max_open_mm: 0.0,
        rethread_feed: 5.0,
    };
}

/// After a probe touched, the gap reading `short` is the contact itself, not a collision or
/// a short to turn back from, until it reads otherwise or the electrode has moved this far
/// (mm): the move after a probe leaves the work (a program that drives on into it gets the
/// short, and its turn-back or collision, after this distance).
pub const PROBE_RELEASE_MM: f64 = 0.1;

/// What the excursions keep between ticks.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct ExcursionState {
    /// Jumps of the block in hand: every so many ticks of cutting (0: none), how far (mm),
    /// how fast (mm/s).
    pub jump_every: u64,
    pub jump_height: f64,
    pub jump_feed: f64,
    /// Ticks cut forward since the last jump.
    pub cut_ticks: u64,
    /// Path gone back in the current retreat (mm).
    pub retreat_mm: f64,
    /// Lattice path behind the farthest point cut (mm): how far a return has to go.
    pub behind_mm: f64,
    /// Cutting travel since the gap was last not open (mm).
    pub open_mm: f64,
    /// The wire-break input, as the thread loop last read it.
    pub wire_input: bool,
    /// The probing move in hand found its contact (or its end), or the drilling move in hand
    /// broke through (or ended): the rest of it is dropped.
    pub probe_hit: bool,
    /// The breakthrough detector of the drilling move in hand.
    pub drill: super::breakthrough::Breakthrough,
    /// Travel left (mm) over which a short is still the last probe's contact.
    pub contact_grace_mm: f64,
    /// A jump off an orbit: how far up the tool axis it is (`None`: jumps go along the path).
    pub lift: Option<Lift>,
    /// This tick's reading is of the probe's contact (the probe, a home switch): the gap
    /// input had been told a probing move is in hand when it read, as the thread loop knows.
    pub contact_reading: bool,
}

/// A jump lifted straight off the orbit: along `axis`, `sign` the way up, `steps` up so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Lift {
    pub axis: usize,
    pub sign: i8,
    pub steps: i64,
}

impl ExcursionState {
    /// Takes the jump settings of the block entered: its machining condition's (`set`) where
    /// it sets them, `settings`' otherwise (ticks of `dt`).
    pub fn on_enter(&mut self, set: &ServoSetPoints, settings: &ExcursionSettings, dt: f64) {
        let [interval, height, feed] = set.jump;
        self.jump_every = if interval.is_nan() {
            settings.jump_interval_ticks
        } else {
            (interval as f64 / dt).round() as u64
        };
        self.jump_height = if height.is_nan() {
            settings.jump_height_mm
        } else {
            height as f64
        };
        self.jump_feed = if feed.is_nan() {
            settings.jump_feed
        } else {
            feed as f64
        };
        if self.jump_height <= 0.0 {
            self.jump_every = 0;
        }
    }

    /// The gap as the servo should take it: a short just after a probe's contact is the
    /// contact (read as open) until the electrode has left it.
    pub fn past_contact(&mut self, gap: GapState) -> GapState {
        if self.contact_grace_mm <= 0.0 {
            return gap;
        }
        if gap == GapState::Short {
            GapState::Open
        } else {
            self.contact_grace_mm = 0.0;
            gap
        }
    }
}

impl Interpolator {
    /// The wire-break input as the thread loop read it this tick (a sensor, or the
    /// simulator's broken wire).
    pub fn set_wire_input(&mut self, broken: bool) {
        self.excursions.wire_input = broken;
    }

    /// Whether this tick's gap reading is of the probe's contact: the thread loop had told
    /// the input a probing move is in hand before it read.
    pub fn set_contact_reading(&mut self, of_contact: bool) {
        self.excursions.contact_reading = of_contact;
    }

    /// The operator's rethread after a wire break: back along the path to the start hole,
    /// or threading where the electrode stands. `false` unless the wire is broken. Moving
    /// back needs the hold released.
    pub fn rethread(&mut self, at: Rethread) -> bool {
        if !self.servo.rethread(at) {
            return false;
        }
        self.excursions.retreat_mm = 0.0;
        self.motion.phase = 0.0;
        true
    }

    /// What the current retreat or return is for.
    pub fn excursion(&self) -> Excursion {
        self.servo.excursion()
    }

    /// A retreat may not walk back into this block: a probing move (its steps are the
    /// programmed ones, not the ones taken) and, on purpose, a rapid (the start of the cut;
    /// not a spark-off travel along the kerf).
    pub(super) fn is_barrier(&self) -> bool {
        let purposeful = self.servo.state() == ServoState::Retreat;
        let flags = self.motion.block.flags;
        flags.contains(BlockFlags::PROBE)
            || (purposeful
                && flags.contains(BlockFlags::RAPID)
                && !flags.contains(BlockFlags::IN_KERF))
    }

    /// The way back ends here (start of the reserved area or a barrier): a short's turn-back
    /// raises the alarm, a jump or a rethread has gone as far as it can.
    /// `exhausted`: the reserved area ran out (not the start of the cut).
    pub(super) fn retreat_blocked(&mut self, tick: &mut Tick, exhausted: bool) {
        self.motion.stop();
        let here = self.motion.here();
        let travel = if self.servo.state() == ServoState::Retreat {
            Travel::RetreatEnds {
                at: here,
                mm: self.excursions.retreat_mm,
                exhausted,
            }
        } else {
            Travel::WayBackEnds { at: here }
        };
        let event = self.servo.observe(travel);
        if event.is_some() {
            tick.event = event;
        }
    }

    /// Turning back at the start of the block in hand (or with none in hand): takes the
    /// previous block from the reserved area, passing over blocks of zero steps. `false` when
    /// the reserved area is exhausted: the alarm while shorted (a turn-back backing off its
    /// least retraction after the gap cleared re-advances instead).
    pub(super) fn retreat<S: BlockSource + ?Sized>(
        &mut self,
        tick: &mut Tick,
        source: &mut S,
    ) -> bool {
        // The way back to the start hole walks on past the reserved area, along the trail.
        let rethread = self.servo.state() == ServoState::Retreat
            && self.servo.excursion() == Excursion::Rethread;
        loop {
            if rethread && self.motion.holds(BlockFlags::START_HOLE) {
                // A pass that starts at the start hole: the way back ends where it began.
                self.retreat_blocked(tick, false);
                return false;
            }
            let back = if rethread {
                source.previous_on_trail(&mut self.motion.block)
            } else {
                source.previous(&mut self.motion.block)
            };
            if !back {
                self.retreat_blocked(tick, true);
                return false;
            }
            if self.is_barrier() {
                // Back out of it: the block this retreat came from is handed out again, and
                // the electrode stands at its start, where it was.
                if source.next(&mut self.motion.block) == Fetch::Block {
                    self.enter_block(false);
                } else {
                    self.motion.has_block = false;
                }
                self.retreat_blocked(tick, false);
                return false;
            }
            self.servo.observe(Travel::BlockBack);
            self.enter_block(true);
            if self.motion.walk.events() > 0 {
                return true;
            }
        }
    }

    /// One backward event of a retreat: a jump ends at its height.
    pub(super) fn retreated(&mut self, tick: &mut Tick) {
        self.excursions.retreat_mm += self.motion.event_mm;
        // The height to the nearest lattice point (a condition's height is an f32).
        let reached =
            self.excursions.retreat_mm >= self.excursions.jump_height - 0.5 * self.motion.event_mm;
        if self.servo.excursion() == Excursion::Jump && reached {
            // The retreat braked on its way here and arrives at creep speed: it stops on this
            // point, so every jump lifts exactly its height.
            self.motion.stop();
            tick.event = self.servo.observe(Travel::RetreatEnds {
                at: self.motion.here(),
                mm: self.excursions.retreat_mm,
                exhausted: false,
            });
        }
    }

    /// The wire-break input fired while cutting: stop on the spot and park.
    pub(super) fn wire_break_input(&mut self, tick: &mut Tick) -> bool {
        if !self.excursions.wire_input || self.servo.state().wire_parked() {
            return false;
        }
        self.wire_break(tick, false)
    }

    fn wire_break(&mut self, tick: &mut Tick, open: bool) -> bool {
        let at = self.motion.here();
        match self.servo.observe(Travel::WireBreak { at, open }) {
            Some(event) => {
                self.motion.stop();
                self.excursions.open_mm = 0.0;
                self.stops.hold = true;
                tick.event = Some(event);
                true
            }
            None => false,
        }
    }

    /// A forward event cut through an open gap: over `servo.max_open_mm` of it, the wire
    /// has broken.
    pub(super) fn open_travel(&mut self, tick: &mut Tick) {
        let max = self.settings.excursions.max_open_mm;
        if max <= 0.0 {
            return;
        }
        self.excursions.open_mm += self.motion.event_mm;
        if self.excursions.open_mm >= max && tick.event.is_none() {
            self.wire_break(tick, true);
        }
    }

    /// Counts a tick of cutting; when the jump interval is up, starts a jump.
    pub(super) fn jump_due(&mut self, tick: &mut Tick) -> Option<(i8, f64)> {
        let cutting = self.servo.state() == ServoState::Forward
            && self.motion.has_block
            && !self
                .motion
                .block
                .flags
                .intersects(BlockFlags::RAPID | BlockFlags::PROBE)
            && !self.stops.hold
            && self.stops.dwell_left == 0;
        if self.excursions.jump_every == 0 || !cutting {
            return None;
        }
        self.excursions.cut_ticks += 1;
        if self.excursions.cut_ticks < self.excursions.jump_every || tick.event.is_some() {
            return None;
        }
        self.excursions.cut_ticks = 0;
        self.excursions.retreat_mm = 0.0;
        tick.event = self.servo.observe(Travel::JumpDue {
            at: self.motion.here(),
        });
        if let Some(axis) = self.settings.lift_axis
            && self.motion.holds(BlockFlags::ORBIT)
        {
            // Up is away from where the orbit sinks (+ on the flat bottom's return).
            let sinks = self.motion.block.end[axis] - self.motion.block.start[axis];
            let sign = if sinks > 0 { -1 } else { 1 };
            self.excursions.lift = Some(Lift {
                axis,
                sign,
                steps: 0,
            });
        }
        Some((-1, self.excursions.jump_feed))
    }

    /// Direction and feed of a probing move or an excursion (spark off); `None`: the tick
    /// ends here (contact made).
    pub(super) fn excursion_motion(
        &mut self,
        gap: GapState,
        probing: bool,
        tick: &mut Tick,
    ) -> Option<(i8, f64)> {
        let here = self.motion.here();
        if probing && !self.excursions.contact_reading {
            // The reading was taken before the input learnt of the probing move (it is told
            // at the end of the tick the move comes in hand): judging contact on a gap
            // reading could end the move where it starts. Stand until a contact reading.
            return Some((0, 0.0));
        }
        if probing {
            let away = self.motion.block.flags.contains(BlockFlags::PROBE_AWAY);
            let contact = (gap == GapState::Short) != away;
            let end = self.motion.walk.at_end()
                && self.motion.block.flags.contains(BlockFlags::LAST_OF_BLOCK);
            if contact || end {
                self.probe_found(tick, contact);
                return None;
            }
            // The programmed probing feed (the planned limit alone is lifted to the creep
            // speed near a standstill, faster than a slow probing feed).
            return Some((1, self.motion.block.v_cruise));
        }
        let feed = match self.servo.excursion() {
            Excursion::Jump => self.excursions.jump_feed,
            Excursion::Rethread => self.settings.excursions.rethread_feed,
        };
        match self.servo.state() {
            ServoState::Retreat if self.servo.excursion() == Excursion::Jump => {
                // Brake so as to stop at the height, never below the creep speed.
                let left = (self.excursions.jump_height - self.excursions.retreat_mm).max(0.0);
                let braking = (2.0 * self.settings.accel * left).sqrt();
                Some((-1, feed.min(braking)))
            }
            ServoState::Retreat => Some((-1, feed)),
            ServoState::Return => {
                if self.excursions.lift.is_some() {
                    // Off the path: a short on the way down goes back up until it clears.
                    let dir = if gap == GapState::Short { -1 } else { 1 };
                    return Some((dir, feed));
                }
                if let Some(event) = self.servo.observe(Travel::Returning { gap, at: here }) {
                    tick.event = Some(event);
                    return Some(self.servo.motion(gap));
                }
                if gap == GapState::Short {
                    // Not believed yet: no further in.
                    return Some((1, 0.0));
                }
                // Brake so as to arrive at the mark slowly: the gap is there.
                let accel = self.settings.accel;
                let left = self.excursions.behind_mm;
                let braking = (2.0 * accel * left)
                    .sqrt()
                    .max((accel * self.motion.event_mm).sqrt());
                Some((1, feed.min(braking)))
            }
            _ => Some((0, 0.0)),
        }
    }

    /// The probing move ends at this point: stop, report, drop the rest of the move.
    fn probe_found(&mut self, tick: &mut Tick, contact: bool) {
        self.motion.stop();
        self.excursions.probe_hit = true;
        if contact && !self.motion.block.flags.contains(BlockFlags::PROBE_AWAY) {
            // The electrode rests on the work: the move after the probe starts shorted.
            self.excursions.contact_grace_mm = PROBE_RELEASE_MM;
        }
        let at = self.motion.here();
        let missed = !contact && self.motion.block.flags.contains(BlockFlags::PROBE_MUST);
        if let Some(event) = self.servo.observe(Travel::ProbeEnds { at, missed }) {
            tick.event = Some(event);
            return;
        }
        tick.event = Some(ServoEvent::Probed {
            at,
            steps: self.motion.position,
            contact,
            away: self.motion.block.flags.contains(BlockFlags::PROBE_AWAY),
        });
    }

    /// One forward cutting event of a drilling move: far enough past a breakthrough, or at
    /// the move's end, it stops and reports where (the producer waits for it).
    pub(super) fn drilled(&mut self, tick: &mut Tick) {
        let at = self.motion.position;
        let stop = self.excursions.drill.event(self.motion.event_mm);
        let end = self.motion.walk.at_end()
            && self.motion.block.flags.contains(BlockFlags::LAST_OF_BLOCK);
        if !(stop || end) {
            return;
        }
        self.motion.stop();
        self.excursions.probe_hit = true;
        let event = ServoEvent::Breakthrough {
            at: self.motion.here(),
            steps: at,
            last_spark: self.excursions.drill.last_spark,
            found: self.excursions.drill.found(),
        };
        self.excursions.drill = Default::default();
        // The report must not be lost to another event of this tick: the producer waits for
        // it. It goes out next tick then.
        match tick.event {
            None => tick.event = Some(event),
            Some(_) => self.pending = Some(event),
        }
    }

    /// After a probing move ended: the next move starts where it ended (the producer planned
    /// it from there). `false`: none yet, the tick ends.
    pub(super) fn drop_probe_rest<S: crate::buffer::BlockSource + ?Sized>(
        &mut self,
        tick: &mut Tick,
        source: &mut S,
    ) -> bool {
        use crate::buffer::Fetch;
        self.excursions.probe_hit = false;
        // The probing move's other segments are already in the buffer: pass over them (they
        // stay in the reserved area as barriers) to the first move planned from here.
        while self.motion.has_block
            && self
                .motion
                .block
                .flags
                .intersects(BlockFlags::PROBE | BlockFlags::BREAKTHROUGH)
            && !self.motion.block.flags.contains(BlockFlags::LAST_OF_BLOCK)
        {
            if source.next(&mut self.motion.block) != Fetch::Block {
                // The producer closed the buffer or the job was torn down.
                self.motion.has_block = false;
                return false;
            }
            self.counters.blocks_entered += 1;
        }
        match self.fetch_forward(source) {
            Fetch::Block => {
                self.servo.observe(Travel::BlockInHand);
                true
            }
            Fetch::Empty => false,
            Fetch::End => {
                tick.event = self.servo.observe(Travel::ProgramEnd);
                false
            }
        }
    }
}

impl Interpolator {
    /// A jump off an orbit is under way, up or down the tool axis (the braking of the cut
    /// before it goes along the path as usual).
    pub(super) fn lifting(&self) -> bool {
        self.excursions.lift.is_some()
            && match self.servo.state() {
                ServoState::Retreat => self.motion.dir < 0,
                ServoState::Return => true,
                _ => false,
            }
    }

    /// One tick of a jump off an orbit: straight up the tool axis by the jump height from
    /// where the orbit is, and straight back down to it (retracing the spiral would rub the
    /// wall just cut). Up counts as a backward event and down as a forward one, so the
    /// ledger, the simulator's gap and the counters see an excursion as usual; the path
    /// point stays the mark, where the orbit carries on.
    pub(super) fn drive_lift(&mut self, want_dir: i8, feed: f64, tick: &mut Tick) {
        let Some(lift) = self.excursions.lift else {
            return;
        };
        let step = self.settings.step_mm[lift.axis];
        let (accel, dt) = (self.settings.accel, self.settings.dt);
        let up_mm = lift.steps as f64 * step;
        let left = if self.motion.dir < 0 {
            (self.excursions.jump_height - up_mm).max(0.0)
        } else {
            up_mm
        };
        let cap = step / dt;
        let toward = want_dir == self.motion.dir && !self.stops.hold;
        let target = if toward { feed.min(cap) } else { 0.0 };
        if self.settings.jerk > 0.0 {
            let room = toward.then_some(Room {
                mm: left,
                v_end: 0.0,
            });
            let limits = JerkLimits {
                accel,
                jerk: self.settings.jerk,
            };
            self.motion.follow_jerk(target, cap, room, limits, dt, step);
        } else {
            let braking = (2.0 * accel * left).sqrt().max((accel * step).sqrt());
            self.motion.follow(target.min(braking), cap, accel, dt);
        }
        if self.motion.speed <= 0.0 {
            return;
        }
        self.motion.phase += self.motion.speed * dt / step;
        if self.motion.phase < 1.0 {
            return;
        }
        self.motion.phase = (self.motion.phase - 1.0).min(0.999_999);
        let up = self.motion.dir < 0;
        tick.steps[lift.axis] = if up { lift.sign } else { -lift.sign };
        self.apply(tick);
        let steps = lift.steps + if up { 1 } else { -1 };
        self.excursions.lift = Some(Lift { steps, ..lift });
        if up {
            self.counters.events_backward += 1;
            self.excursions.retreat_mm = steps as f64 * step;
            if self.excursions.retreat_mm >= self.excursions.jump_height - 0.5 * step {
                self.motion.stop();
                tick.event = self.servo.observe(Travel::RetreatEnds {
                    at: self.motion.here(),
                    mm: self.excursions.retreat_mm,
                    exhausted: false,
                });
            }
        } else {
            self.counters.events_forward += 1;
            if steps == 0 {
                // Back on the orbit: it carries on from here.
                self.motion.stop();
                self.excursions.lift = None;
                tick.event = self.servo.observe(Travel::Forward {
                    at: self.motion.here(),
                });
            }
        }
    }
}

/// Whether this tick's speed is jerk-limited, and the way to the stop it must make: `None`
/// for the trapezoid (no jerk limit, or a cut, a probing move); `Some(None)` for a
/// jerk-limited move with no stop ahead in its direction (braking to reverse, a turn-back). A function of
/// the block in hand, the servo's state and the excursion's distances, with `jerk` the limit.
pub(super) fn room_ahead(
    motion: &Motion,
    servo: &Servo,
    excursions: &ExcursionState,
    jerk: f64,
    want_dir: i8,
) -> Option<Option<Room>> {
    if jerk <= 0.0 || !motion.has_block {
        return None;
    }
    let toward = want_dir == motion.dir;
    let stop = |mm: f64| toward.then_some(Room { mm, v_end: 0.0 });
    match servo.state() {
        ServoState::Forward
            if motion.holds(BlockFlags::RAPID) && !motion.holds(BlockFlags::PROBE) =>
        {
            // A rapid ends at a standstill (the planner stops there under a jerk limit).
            Some(stop(motion.way_left() + motion.block.rest_mm))
        }
        ServoState::Retreat => Some(match servo.excursion() {
            Excursion::Jump => stop((excursions.jump_height - excursions.retreat_mm).max(0.0)),
            // Back to the start of the contour: the lattice path there from the point of the
            // block in hand.
            Excursion::Rethread => {
                stop((motion.block.contour_mm - motion.lattice_mm + motion.way_left()).max(0.0))
            }
        }),
        ServoState::Return => Some(stop(excursions.behind_mm)),
        // The servo's own motion: a turn-back goes on while the short lasts; a re-advance
        // reaches the point of the short at the plan's cruise, where cutting goes on.
        ServoState::TurnBack => Some(None),
        ServoState::ReAdvance => Some(toward.then_some(Room {
            mm: excursions.behind_mm,
            v_end: motion.aim,
        })),
        ServoState::Forward if servo.confirming() => Some(None),
        _ => None,
    }
}

#[cfg(test)]
mod tests;
