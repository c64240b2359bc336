//! Fine interpolation: the consumer's per-tick core, from loop-buffer blocks to step pulses.
//!
//! Every tick (`fine.tick_us`) the thread loop samples the gap, calls
//! [`Interpolator::tick`] and hands the returned steps to the pulse output. The tick core is
//! a pure function of its state, the gap state and the blocks its [`BlockSource`] hands out:
//! it reads no clock, does no I/O, allocates nothing and logs nothing (it returns a
//! [`ServoEvent`] instead). That is what makes a run in virtual time deterministic and fast,
//! and the real-time loop boring.
//!
//! One tick:
//!
//! 1. **Servo** ([`crate::servo`]): the gap state may start a turn-back, end one, or (at the
//!    end of the reserved area) raise the alarm. The servo gives a direction and a feed.
//! 2. **Speed**: the path speed `v` moves towards `min(servo feed, planned limit)` by at most
//!    `a_T · dt` per tick (so acceleration is honoured across block boundaries, since the
//!    planned limits of consecutive blocks meet at the junction speed). The planned limit at
//!    distance `s` into a block of length `L` is the planner's trapezoid,
//!    `min(v_cruise, sqrt(v_entry² + 2 a s), sqrt(v_exit² + 2 a (L − s)))`, mirrored when
//!    moving backwards, and never below a creep speed `sqrt(a · step)` so the last steps before
//!    a stop are always taken (nor above `v_cruise`: a slow programmed feed stays slow).
//!    The operator's override `k` scales the cruise aimed for on a forward move
//!    (`min(servo feed, planned limit, k · v_cruise)`), up to the block's limits without its
//!    programmed feed (`v_limit`); it never touches the braking, so a lower override brakes
//!    under `a_T`. The servo's own motion (a turn-back, the re-advance, braking for a short)
//!    goes by the path's limits instead of the feed's plan (`StepBlock::path`: a retract
//!    feed above F is honoured) under the reversal's acceleration; a re-advance brakes to
//!    meet the plan at the point of the short. Reversing first brakes to zero. A block's
//!    speed is capped at one event per tick: the pulse outputs take one step per axis a tick.
//! 3. **DDA**: a phase accumulator adds `v · dt / ds` per tick (`ds`: the lattice distance of
//!    one event); on reaching one it fires one Bresenham event ([`bresenham`]) forward or
//!    backward, moving every axis by at most one step.
//! 4. **Blocks**: forward past a block's end it asks the source for the next block (an empty
//!    buffer is a starvation: hold); backward past a block's start for the previous one (none
//!    left while shorted: alarm). Blocks of zero steps are passed over in either direction.
//!
//! The believed position (the pulse ledger) is updated with every step returned, so it always
//! equals the sum of everything emitted.
//!
//! **Programmed stops.** A block may carry a `G4` dwell or an `M0`/`M1` pause for the point
//! where it starts (the planner brings the path to a standstill there). The first time the
//! interpolator enters such a block going forward it honours them: a dwell holds the electrode
//! still for `round(dwell_s / dt)` ticks (the generator keeps sparking; the tick count is the
//! clock, so virtual time dwells too), a pause holds it like the operator's hold and reports
//! [`ServoEvent::Paused`], released by [`Interpolator::set_hold`]. Re-entering a block after a
//! turn-back, or walking over it to a checkpoint, does not repeat them.

mod blocks;
mod breakthrough;
pub mod bresenham;
mod excursion;
mod jerk;
mod motion;

pub use breakthrough::BreakthroughSettings;
pub use motion::Overrides;
mod settings;
mod stops;

use crate::buffer::BlockFlags;
use crate::buffer::{BlockSource, Fetch, StepBlock};
use crate::process::{ConditionTable, Process};
use crate::servo::{
    GapReading, LawInput, PathPoint, Servo, ServoCounters, ServoEvent, ServoState, Travel,
};
use crate::vocab::GapState;
use crate::vocab::{MAX_AXES, Steps};
use excursion::ExcursionState;
use motion::{Motion, Pace};
use stops::Stops;

pub use blocks::SkipError;
pub use bresenham::Bresenham;
pub use excursion::ExcursionSettings;
pub use settings::FineSettings;

/// What one tick produced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tick {
    /// Signed step per axis (-1, 0, 1).
    pub steps: [i8; MAX_AXES],
    /// Direction of this tick's Bresenham event: 1 forward along the program, -1 backward
    /// (turn-back), 0 when no event (no step) happened.
    pub dir: i8,
    /// What the servo did this tick, if anything.
    pub event: Option<ServoEvent>,
}

/// Counters of the fine interpolator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FineCounters {
    pub ticks: u64,
    /// Bresenham events forward and backward.
    pub events_forward: u64,
    pub events_backward: u64,
    /// Pulses emitted per axis (both directions).
    pub pulses: [u64; MAX_AXES],
    /// Blocks taken from the source going forward (re-advances included).
    pub blocks_entered: u64,
    pub servo: ServoCounters,
}

/// The consumer's per-tick core: the servo (gap law, state machine, counters), the motion
/// along the program, the stops and the excursions, each a part of its own.
#[derive(Debug, Clone)]
pub struct Interpolator {
    settings: FineSettings,
    servo: Servo,
    motion: Motion,
    stops: Stops,
    excursions: ExcursionState,
    /// The machining condition in force and its set points.
    process: Process,
    /// An event met outside a tick (a resume at the mark), reported by the next tick.
    pending: Option<ServoEvent>,
    counters: FineCounters,
}

/// Where the decision of a tick leaves it: move this way at up to this feed, or stop here.
type Decision = Option<(i8, f64)>;

impl Interpolator {
    /// A stopped interpolator at `start` (steps), waiting for its first block.
    pub fn new(settings: FineSettings, start: Steps) -> Interpolator {
        Interpolator {
            settings,
            servo: Servo::with_law(
                settings.feeds,
                settings.law,
                settings.max_short_ticks,
                settings.dt,
                settings.shorts,
            ),
            motion: Motion::new(start),
            stops: Stops::default(),
            // Until a thread loop says otherwise, every reading is what it seems (a caller
            // that ticks with the contact directly, as the tests do).
            excursions: ExcursionState {
                contact_reading: true,
                ..ExcursionState::default()
            },
            process: Process::default(),
            pending: None,
            counters: FineCounters::default(),
        }
    }

    /// The job's machining conditions, before its first tick.
    pub fn set_conditions(&mut self, table: ConditionTable) {
        self.process = Process::new(table);
    }

    /// The machining condition in force and its set points.
    pub fn process(&self) -> &Process {
        &self.process
    }

    /// Single block, from the thread loop (the job's published controls): while on, every
    /// program block ends at a standstill and the next one waits for a release of the hold.
    pub fn set_single_block(&mut self, on: bool) {
        self.stops.single_block = on;
    }

    /// The operator's feed and rapid overrides, from the thread loop (the job's published
    /// controls): they take effect in this tick.
    pub fn set_overrides(&mut self, overrides: Overrides) {
        self.motion.set_overrides(overrides);
    }

    /// Holds (brakes to a standstill under `a_T`, then stays) or releases the hold. The servo
    /// keeps watching the gap while held; motion resumes from where it stopped.
    ///
    /// Releasing a hold after an alarm (a short that outlasted `max_short_ticks` or the
    /// reserved history) re-advances towards the point of the short: if the gap is still
    /// shorted there, the alarm comes straight back.
    ///
    /// Releasing it while parked for threading returns along the path to where the wire
    /// broke; while the wire is still broken (no rethread asked for) nothing moves.
    pub fn set_hold(&mut self, hold: bool) {
        if self.stops.hold && !hold {
            match self.servo.state() {
                ServoState::Alarm => self.servo.release_alarm(),
                ServoState::Threading => {
                    let event = self.servo.resume_threaded(self.here());
                    self.pending = self.pending.or(event);
                    self.excursions.open_mm = 0.0;
                }
                _ => {}
            }
        }
        self.stops.hold = hold;
    }

    pub fn held(&self) -> bool {
        self.stops.hold
    }

    /// Ticks of a `G4` dwell still to wait where the electrode stands.
    pub fn dwell_left(&self) -> u64 {
        self.stops.dwell_left
    }

    /// A resumed job (after [`Interpolator::skip_to`]) owes the rest of the dwell its first
    /// run was in when it stopped: `ticks` more before it moves on.
    pub fn resume_dwell(&mut self, ticks: u64) {
        self.stops.dwell_left = ticks;
    }

    /// Held and at a standstill: nothing moves until the hold is released.
    pub fn still(&self) -> bool {
        self.motion.speed == 0.0 && (self.stops.hold || self.servo.state().is_final())
    }

    pub fn state(&self) -> ServoState {
        self.servo.state()
    }

    /// The pulse ledger: the believed position in steps.
    pub fn position(&self) -> Steps {
        self.motion.position
    }

    pub fn speed(&self) -> f64 {
        self.motion.speed
    }

    /// Source line of the block in hand (or of the last one).
    pub fn line(&self) -> u64 {
        self.motion.block.line
    }

    /// The block in hand, if any.
    pub fn block(&self) -> Option<&StepBlock> {
        self.motion.has_block.then_some(&self.motion.block)
    }

    /// Path length from the program's start to the electrode (mm), along the block in hand
    /// (it goes back during a turn-back); with none in hand, the end of the last one left.
    pub fn path_mm(&self) -> f64 {
        let Some(b) = self.block() else {
            return self.motion.passed_mm;
        };
        let events = b.events() as i64;
        let left = if events > 0 {
            (events - self.here().event).clamp(0, events) as f64 / events as f64
        } else {
            0.0
        };
        b.path_end_mm - b.length_mm * left
    }

    /// Where along the program the electrode is.
    pub fn here(&self) -> PathPoint {
        self.motion.here()
    }

    pub fn counters(&self) -> FineCounters {
        let mut c = self.counters;
        c.servo = self.servo.counters;
        c
    }

    /// The job is a dry run (spark off, the servo out of the loop).
    pub fn dry_run(&self) -> bool {
        self.settings.dry_run
    }

    /// What the servo law reads from the gap input beside its state.
    pub fn law_input(&self) -> LawInput {
        self.settings.law.input()
    }

    /// One tick with what the gap input read: the servo law classifies it (the voltage law
    /// filters the voltage, the ratio law reads the ratios, the three-state law takes the
    /// state), then [`Interpolator::tick`].
    #[inline]
    pub fn tick_measured<S: BlockSource + ?Sized>(
        &mut self,
        reading: GapReading,
        source: &mut S,
    ) -> Tick {
        let gap = self.servo.classify(&reading);
        let tick = self.tick(gap, source);
        let travel_mm = if tick.dir != 0 && self.motion.has_block {
            let b = &self.motion.block;
            tick.dir as f64 * b.length_mm / b.events().max(1) as f64
        } else {
            0.0
        };
        self.process
            .observe(reading.pulses.as_ref(), travel_mm, reading.flushing);
        tick
    }

    /// One tick with gap state `gap`, in named phases: acquire a block, honour what stops
    /// the electrode, decide where to go (the excursion's way, a rapid's, or the servo's),
    /// and drive there (speed, DDA, step, bookkeeping).
    #[inline]
    pub fn tick<S: BlockSource + ?Sized>(&mut self, gap: GapState, source: &mut S) -> Tick {
        let mut tick = Tick {
            steps: [0; MAX_AXES],
            dir: 0,
            event: None,
        };
        self.counters.ticks += 1;
        if self.servo.state().is_final() || !self.acquire(&mut tick, source) {
            return tick;
        }
        let Some((contact, gap)) = self.stopped_or_gap(gap, &mut tick, source) else {
            return tick;
        };
        if let Some((want_dir, feed)) = self.decide(contact, gap, &mut tick) {
            self.drive(want_dir, feed, gap, &mut tick, source);
        }
        tick
    }

    /// Phase 1: a block in hand. Before the first block, or held by a starvation, asks the
    /// source again; `false` when the program has ended.
    #[inline(always)]
    fn acquire<S: BlockSource + ?Sized>(&mut self, tick: &mut Tick, source: &mut S) -> bool {
        if self.motion.has_block || self.servo.state() == ServoState::TurnBack {
            return true;
        }
        match self.fetch_forward(source) {
            Fetch::Block => {
                self.servo.observe(Travel::BlockInHand);
            }
            Fetch::Empty => {}
            Fetch::End => {
                tick.event = self.servo.observe(Travel::ProgramEnd);
                return false;
            }
        }
        true
    }

    /// Phase 2: what keeps the electrode where it is this tick (a pause, the rest of a probing
    /// move, a broken wire, a dwell), and the events owed from outside the tick. Otherwise
    /// the gap as read (the probe's contact) and as the servo takes it.
    #[inline(always)]
    fn stopped_or_gap<S: BlockSource + ?Sized>(
        &mut self,
        gap: GapState,
        tick: &mut Tick,
        source: &mut S,
    ) -> Option<(GapState, GapState)> {
        if tick.event.is_none()
            && let Some(kind) = self.stops.take_pause()
        {
            tick.event = Some(ServoEvent::Paused {
                at: self.here(),
                kind,
            });
            self.motion.stop();
            return None;
        }
        if let Some(event) = self.pending.take() {
            tick.event = Some(event);
        }
        if self.excursions.probe_hit && !self.drop_probe_rest(tick, source) {
            return None;
        }
        if self.wire_break_input(tick) {
            return None;
        }
        let contact = gap;
        let gap = self.excursions.past_contact(gap);
        if self.servo.state() == ServoState::Forward && self.stops.dwell_tick() {
            // G4: the electrode stays where the dwell began while the gap sparks.
            self.motion.stop();
            return None;
        }
        Some((contact, gap))
    }

    /// Phase 3: direction and feed. A probing move or an excursion goes its own way with the
    /// spark off, a rapid at the planned speed, a cut as the servo law asks.
    #[inline(always)]
    fn decide(&mut self, contact: GapState, gap: GapState, tick: &mut Tick) -> Decision {
        let forward = self.servo.state() == ServoState::Forward;
        let probing = forward && self.motion.holds(BlockFlags::PROBE);
        if probing || self.servo.state().spark_off() {
            // A probe reads the contact as it is.
            let gap = if probing { contact } else { gap };
            return self.excursion_motion(gap, probing, tick);
        }
        // A dry run moves every move as a rapid moves (at its planned feed, the servo out of
        // the loop, a short a collision).
        if forward && (self.settings.dry_run || self.motion.holds(BlockFlags::RAPID)) {
            return self.rapid(gap, tick);
        }
        self.cut(gap, tick)
    }

    /// Positioning with the spark off: no gap servo, the planned speed. A short here is a
    /// collision: stop on the spot (no turn-back into a move that is not a cut) and hold
    /// until released.
    #[inline(always)]
    fn rapid(&mut self, gap: GapState, tick: &mut Tick) -> Decision {
        if gap != GapState::Short {
            return Some((1, f64::INFINITY));
        }
        self.motion.stop();
        if !self.stops.hold {
            self.stops.hold = true;
            tick.event = self.servo.observe(Travel::Collision { at: self.here() });
        }
        None
    }

    /// Cutting: the servo's state machine takes the gap, a short that lasts too long while
    /// turning back is the alarm, the law gives the feed (a machining condition may set the
    /// voltage law's reference or the three-state law's sparking feed), and a jump may be due.
    #[inline(always)]
    fn cut(&mut self, gap: GapState, tick: &mut Tick) -> Decision {
        let here = self.here();
        if self.servo.state() == ServoState::Forward && self.motion.holds(BlockFlags::BREAKTHROUGH)
        {
            let at = self.motion.position;
            self.excursions
                .drill
                .tick(&self.settings.breakthrough, gap, &at);
        }
        tick.event = self.servo.observe(Travel::Cutting { gap, at: here });
        if self.servo.state() == ServoState::Alarm {
            // The short outlasted `max_short_ticks` while turning back.
            self.motion.stop();
            return None;
        }
        let set = self.process.servo();
        let (dir, feed) = self.servo.law_motion(gap, set.v_ref);
        let sparking = gap == GapState::Normal
            && dir > 0
            && self.servo.three_state()
            && set.feed_mm_per_s > 0.0;
        let motion = if sparking {
            (dir, set.feed_mm_per_s as f64)
        } else {
            (dir, feed)
        };
        if gap != GapState::Open {
            self.excursions.open_mm = 0.0;
        }
        Some(self.jump_due(tick).unwrap_or(motion))
    }

    /// Phase 4: turn the decision into motion. Reversing brakes to zero first; going back
    /// past a block's start takes the previous block; the speed follows
    /// `min(feed, planned limit)` under `a_T`; the DDA decides whether an event is due.
    #[inline(always)]
    fn drive<S: BlockSource + ?Sized>(
        &mut self,
        want_dir: i8,
        feed: f64,
        gap: GapState,
        tick: &mut Tick,
        source: &mut S,
    ) {
        if want_dir == 0 {
            self.motion.stop();
            return;
        }
        if want_dir != self.motion.dir && self.motion.speed == 0.0 {
            self.motion.dir = want_dir;
            self.motion.phase = 0.0;
            self.motion.accel = -self.motion.accel;
        }
        if self.lifting() {
            self.drive_lift(want_dir, feed, tick);
            return;
        }
        if self.motion.dir < 0
            && (!self.motion.has_block || self.motion.walk.at_start())
            && !self.retreat(tick, source)
        {
            return;
        }
        if !self.motion.has_block {
            return;
        }
        let dt = self.settings.dt;
        let pace = if self.servo_way(want_dir) {
            let readvance = self.servo.state() == ServoState::ReAdvance && self.motion.dir > 0;
            Pace::Servo {
                accel: self.settings.reverse_accel,
                plan_accel: self.settings.accel,
                to_mark: readvance.then_some(self.excursions.behind_mm),
            }
        } else {
            Pace::Plan {
                accel: self.settings.accel,
                // The operator's override scales a forward move's cruise; a retreat and a
                // return go at their own feed up to the path's limits.
                cruise: match self.servo.state() {
                    ServoState::Forward if self.motion.dir > 0 => self.motion.aim,
                    ServoState::Retreat | ServoState::Return => self.motion.block.v_limit,
                    _ => self.motion.block.v_cruise,
                },
                // Single block: the end of a program block is a standstill.
                stop_at_end: self.stops.single_block
                    && self.motion.block.flags.contains(BlockFlags::LAST_OF_BLOCK),
            }
        };
        let (accel, cruise, limit) = self.motion.bounds(pace, dt);
        // The plan's cruise, scaled: lowering it lowers the speed aimed for, which brakes
        // down under a_T (the limit is the plan's braking, not the cruise).
        let target = if want_dir != self.motion.dir || self.stops.hold {
            0.0
        } else {
            feed.min(limit).min(cruise)
        };
        // Most machines set no jerk limit: the trapezoid, without a call.
        let room = if self.settings.jerk > 0.0 {
            excursion::room_ahead(
                &self.motion,
                &self.servo,
                &self.excursions,
                self.settings.jerk,
                want_dir,
            )
        } else {
            None
        };
        match room {
            Some(room) => {
                let limits = jerk::JerkLimits {
                    accel,
                    jerk: self.settings.jerk,
                };
                let event_mm = self.motion.event_mm;
                self.motion
                    .follow_jerk(target, limit, room, limits, dt, event_mm);
            }
            None => self.motion.follow(target, limit, accel, dt),
        }
        if self.motion.speed <= 0.0 || !self.motion.event_due(dt) {
            return;
        }
        if self.motion.dir > 0 {
            self.event_forward(gap, tick, source);
        } else {
            self.motion.walk.backward(&mut tick.steps);
            self.apply(tick);
            self.counters.events_backward += 1;
            self.excursions.behind_mm += self.motion.event_mm;
            self.servo.observe(Travel::Backward {
                mm: self.motion.event_mm,
            });
            if self.servo.state() == ServoState::Retreat {
                self.retreated(tick);
            }
        }
    }

    /// The servo's own motion is under way: a turn-back, the re-advance after it, braking
    /// for a short not yet confirmed, or a law backing off while cutting. It goes by the
    /// path's limits and the reversal's acceleration, not by the feed's plan.
    #[inline(always)]
    fn servo_way(&self, want_dir: i8) -> bool {
        match self.servo.state() {
            ServoState::TurnBack | ServoState::ReAdvance => true,
            ServoState::Forward => {
                !self.settings.dry_run
                    && !self
                        .motion
                        .block
                        .flags
                        .intersects(BlockFlags::RAPID | BlockFlags::PROBE)
                    && (want_dir < 0 || self.motion.dir < 0 || self.servo.confirming())
            }
            _ => false,
        }
    }

    /// One event forward, and what cutting through an open gap or leaving a probe's contact
    /// behind makes of it.
    #[inline]
    fn event_forward<S: BlockSource + ?Sized>(
        &mut self,
        gap: GapState,
        tick: &mut Tick,
        source: &mut S,
    ) {
        let cutting_open = gap == GapState::Open
            && self.servo.state() == ServoState::Forward
            && !self
                .motion
                .block
                .flags
                .intersects(BlockFlags::RAPID | BlockFlags::PROBE);
        let drilling = self.servo.state() == ServoState::Forward
            && self.motion.block.flags.contains(BlockFlags::BREAKTHROUGH)
            && !self
                .motion
                .block
                .flags
                .intersects(BlockFlags::RAPID | BlockFlags::PROBE);
        self.excursions.behind_mm = (self.excursions.behind_mm - self.motion.event_mm).max(0.0);
        self.step_forward(tick, source);
        if cutting_open {
            self.open_travel(tick);
        }
        if drilling {
            self.drilled(tick);
        }
        self.excursions.contact_grace_mm =
            (self.excursions.contact_grace_mm - self.motion.event_mm).max(0.0);
    }

    fn step_forward<S: BlockSource + ?Sized>(&mut self, tick: &mut Tick, source: &mut S) {
        if self.motion.walk.at_end() {
            // A turn-back entered this block at its end and the gap cleared before it stepped
            // back in it: the re-advance starts from the block after it (the one it came from,
            // which the source hands out again). Same point, so no step is owed here.
            match self.fetch_forward(source) {
                Fetch::Block => {}
                Fetch::Empty => {
                    tick.event = self.servo.observe(Travel::Starved { at: self.here() });
                    self.motion.stop();
                    return;
                }
                Fetch::End => {
                    tick.event = self.servo.observe(Travel::ProgramEnd);
                    return;
                }
            }
        }
        self.motion.walk.forward(&mut tick.steps);
        self.apply(tick);
        self.counters.events_forward += 1;
        let mut event = self.servo.observe(Travel::Forward { at: self.here() });
        if event.is_none()
            && let Some(kind) = self.stops.take_pause()
        {
            // The step that finished the block before a programmed stop.
            event = Some(ServoEvent::Paused {
                at: self.here(),
                kind,
            });
        }
        // A probing move waits at its end point for the next tick's contact check, a drilling
        // move for its breakthrough report.
        let flags = self.motion.block.flags;
        let waits = flags.contains(BlockFlags::LAST_OF_BLOCK)
            && flags.intersects(BlockFlags::PROBE | BlockFlags::BREAKTHROUGH);
        if self.motion.walk.at_end() && !waits {
            match self.fetch_forward(source) {
                Fetch::Block => {
                    if let Some(e) = self.servo.observe(Travel::Forward { at: self.here() }) {
                        event = Some(e);
                    }
                }
                Fetch::Empty => {
                    let at = self.here();
                    event = self.servo.observe(Travel::Starved { at }).or(event);
                    self.motion.stop();
                }
                Fetch::End => event = self.servo.observe(Travel::ProgramEnd).or(event),
            }
        }
        if event.is_some() {
            tick.event = event;
        }
    }
}

impl Tick {
    /// Some axis stepped.
    pub fn moved(&self) -> bool {
        self.dir != 0
    }
}

#[cfg(test)]
mod tests;
