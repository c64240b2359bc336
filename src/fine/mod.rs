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
//!    Reversing first brakes to zero. A block's speed is capped at one
//!    event per tick: the pulse outputs take at most one step per axis per tick.
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

pub mod bresenham;
mod excursion;
mod laws;
mod skip;

use crate::buffer::BlockFlags;
use crate::buffer::{BlockSource, Fetch, StepBlock};
use crate::servo::{Feeds, Law, PathPoint, Servo, ServoCounters, ServoEvent, ServoState};
use crate::vocab::GapState;
use crate::vocab::{MAX_AXES, Steps};

pub use bresenham::Bresenham;
pub use excursion::ExcursionSettings;
pub use skip::SkipError;

/// The fine interpolator's fixed parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FineSettings {
    /// Tick period (s).
    pub dt: f64,
    /// Tangential acceleration limit (mm/s²).
    pub accel: f64,
    pub feeds: Feeds,
    /// Step size per axis (mm); unused axes 0.
    pub step_mm: [f64; MAX_AXES],
    /// A short lasting this many ticks raises the alarm (0: only the reserved history does).
    pub max_short_ticks: u64,
    /// The servo law (the voltage law reads [`Interpolator::tick_volts`]'s voltage).
    pub law: Law,
    /// Jumps, wire-break detection and rethreading.
    pub excursions: ExcursionSettings,
}

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

/// The consumer's per-tick core.
#[derive(Debug, Clone)]
pub struct Interpolator {
    settings: FineSettings,
    servo: Servo,
    block: StepBlock,
    /// A block is in hand (false before the first block and while starved).
    has_block: bool,
    walk: Bresenham,
    /// Lattice distance of one event of the block in hand (mm).
    event_mm: f64,
    /// Lattice length of the block in hand (mm).
    lattice_mm: f64,
    /// Believed position in steps: the pulse ledger.
    position: Steps,
    /// Path speed (mm/s), always >= 0; `dir` gives its sense.
    speed: f64,
    dir: i8,
    /// Fraction of the next event already covered.
    phase: f64,
    /// Held by the operator: brake to a standstill under `a_T` and stay there.
    hold: bool,
    /// Ticks of a `G4` dwell still to wait.
    dwell_left: u64,
    /// Blocks before this sequence number have had their stops honoured.
    stops_from: u64,
    /// A pause was met while fetching: reported by the tick that met it.
    paused: bool,
    /// Consecutive ticks the gap has read short while turning back.
    short_ticks: u64,
    /// The voltage law's filtered gap voltage (V); NaN before the first reading.
    volts: f64,
    /// Jumps of the block in hand: every so many ticks of cutting (0: none), how far (mm),
    /// how fast (mm/s).
    jump_every: u64,
    jump_height: f64,
    jump_feed: f64,
    /// Ticks cut forward since the last jump.
    cut_ticks: u64,
    /// Path gone back in the current retreat (mm).
    retreat_mm: f64,
    /// Cutting travel since the gap was last not open (mm).
    open_mm: f64,
    /// The wire-break input, as the thread loop last read it.
    wire_input: bool,
    /// The probing move in hand found its contact (or its end): the rest of it is dropped.
    probe_hit: bool,
    /// Travel left (mm) over which a short is still the last probe's contact.
    contact_grace_mm: f64,
    /// An event met outside a tick (a resume at the mark), reported by the next tick.
    pending: Option<ServoEvent>,
    counters: FineCounters,
}

impl Interpolator {
    /// A stopped interpolator at `start` (steps), waiting for its first block.
    pub fn new(settings: FineSettings, start: Steps) -> Interpolator {
        Interpolator {
            settings,
            servo: Servo::new(settings.feeds),
            block: StepBlock::EMPTY,
            has_block: false,
            walk: Bresenham::new(&[0; MAX_AXES], false),
            event_mm: 0.0,
            lattice_mm: 0.0,
            position: start,
            speed: 0.0,
            dir: 1,
            phase: 0.0,
            hold: false,
            dwell_left: 0,
            stops_from: 0,
            paused: false,
            short_ticks: 0,
            volts: f64::NAN,
            jump_every: 0,
            jump_height: 0.0,
            jump_feed: 0.0,
            cut_ticks: 0,
            retreat_mm: 0.0,
            open_mm: 0.0,
            wire_input: false,
            probe_hit: false,
            contact_grace_mm: 0.0,
            pending: None,
            counters: FineCounters::default(),
        }
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
        if self.hold && !hold {
            match self.servo.state() {
                ServoState::Alarm => {
                    self.servo.release_alarm();
                    self.short_ticks = 0;
                }
                ServoState::Threading => {
                    let event = self.servo.resume_threaded(self.here());
                    self.pending = self.pending.or(event);
                    self.open_mm = 0.0;
                }
                _ => {}
            }
        }
        self.hold = hold;
    }

    pub fn held(&self) -> bool {
        self.hold
    }

    /// Ticks of a `G4` dwell still to wait where the electrode stands.
    pub fn dwell_left(&self) -> u64 {
        self.dwell_left
    }

    /// A resumed job (after [`Interpolator::skip_to`]) owes the rest of the dwell its first
    /// run was in when it stopped: `ticks` more before it moves on.
    pub fn resume_dwell(&mut self, ticks: u64) {
        self.dwell_left = ticks;
    }

    /// Held and at a standstill: nothing moves until the hold is released.
    pub fn still(&self) -> bool {
        self.speed == 0.0 && (self.hold || self.servo.state().is_final())
    }

    fn add_steps(&mut self, steps: &[i8; MAX_AXES]) {
        for (p, &s) in self.position.iter_mut().zip(steps) {
            *p += s as i64;
        }
    }

    pub fn state(&self) -> ServoState {
        self.servo.state()
    }

    /// The pulse ledger: the believed position in steps.
    pub fn position(&self) -> Steps {
        self.position
    }

    pub fn speed(&self) -> f64 {
        self.speed
    }

    /// Source line of the block in hand (or of the last one).
    pub fn line(&self) -> u64 {
        self.block.line
    }

    /// The block in hand, if any.
    pub fn block(&self) -> Option<&StepBlock> {
        self.has_block.then_some(&self.block)
    }

    /// Where along the program the electrode is.
    pub fn here(&self) -> PathPoint {
        PathPoint {
            seq: self.block.seq,
            event: self.walk.event(),
        }
    }

    pub fn counters(&self) -> FineCounters {
        let mut c = self.counters;
        c.servo = self.servo.counters;
        c
    }

    /// The voltage law's filtered gap voltage (V), if it has one.
    pub fn filtered_volts(&self) -> Option<f64> {
        self.volts.is_finite().then_some(self.volts)
    }

    /// One tick with gap state `gap`.
    #[inline]
    pub fn tick<S: BlockSource + ?Sized>(&mut self, gap: GapState, source: &mut S) -> Tick {
        let mut tick = Tick {
            steps: [0; MAX_AXES],
            dir: 0,
            event: None,
        };
        self.counters.ticks += 1;
        let state = self.servo.state();
        if state.is_final() {
            return tick;
        }
        if !self.has_block && state != ServoState::TurnBack {
            // Before the first block, or held by a starvation: try again.
            match self.fetch_forward(source) {
                Fetch::Block => self.servo.on_block(),
                Fetch::Empty => {}
                Fetch::End => {
                    tick.event = self.servo.on_end();
                    return tick;
                }
            }
        }
        if self.take_pause(&mut tick) {
            return tick;
        }
        if let Some(event) = self.pending.take() {
            tick.event = Some(event);
        }
        if self.probe_hit && !self.drop_probe_rest(&mut tick, source) {
            return tick;
        }
        if self.wire_break_input(&mut tick) {
            return tick;
        }
        let (contact, gap) = (gap, self.past_contact(gap));
        if self.dwell_left > 0 && self.servo.state() == ServoState::Forward {
            // G4: the electrode stays where the dwell began while the gap sparks.
            self.dwell_left -= 1;
            self.speed = 0.0;
            self.phase = 0.0;
            return tick;
        }
        let here = self.here();
        let rapid = self.has_block
            && self.block.flags.contains(BlockFlags::RAPID)
            && self.servo.state() == ServoState::Forward;
        let probing = self.has_block
            && self.block.flags.contains(BlockFlags::PROBE)
            && self.servo.state() == ServoState::Forward;
        let excursion = self.servo.state().spark_off();
        let (want_dir, feed) = if probing || excursion {
            // A probe reads the contact as it is.
            let gap = if probing { contact } else { gap };
            match self.excursion_motion(gap, probing, &mut tick) {
                Some(motion) => motion,
                None => return tick,
            }
        } else if rapid {
            // Positioning with the spark off: no gap servo, the planned speed. A short here is
            // a collision: stop on the spot (no turn-back into a move that is not a cut) and
            // hold until released.
            if gap == GapState::Short {
                self.speed = 0.0;
                self.phase = 0.0;
                if !self.hold {
                    self.hold = true;
                    self.servo.counters.collisions += 1;
                    tick.event = Some(ServoEvent::Collision { at: here });
                }
                return tick;
            }
            (1, f64::INFINITY)
        } else {
            tick.event = self.servo.on_gap(gap, here);
            if gap == GapState::Short && self.servo.state() == ServoState::TurnBack {
                self.short_ticks += 1;
                let max = self.settings.max_short_ticks;
                if max > 0 && self.short_ticks >= max {
                    self.speed = 0.0;
                    self.phase = 0.0;
                    tick.event = self.servo.on_short_timeout(here).or(tick.event);
                    return tick;
                }
            } else {
                self.short_ticks = 0;
            }
            let (dir, feed) = if self.volts.is_finite() {
                let mut law = self.settings.law;
                if let Law::Voltage { v_ref, .. } = &mut law
                    && self.block.condition_v_ref > 0.0
                {
                    *v_ref = self.block.condition_v_ref as f64;
                }
                self.servo.voltage_motion(gap, self.volts, &law)
            } else {
                self.servo.motion(gap)
            };
            // A machining condition sets the sparking feed of the three-state law.
            let sparking = gap == GapState::Normal
                && dir > 0
                && self.settings.law == Law::ThreeState
                && self.block.condition_feed > 0.0;
            let motion = if sparking {
                (dir, self.block.condition_feed as f64)
            } else {
                (dir, feed)
            };
            if gap != GapState::Open {
                self.open_mm = 0.0;
            }
            match self.jump_due(&mut tick) {
                Some(jump) => jump,
                None => motion,
            }
        };
        if want_dir == 0 {
            self.speed = 0.0;
            self.phase = 0.0;
            return tick;
        }
        if want_dir != self.dir && self.speed == 0.0 {
            self.dir = want_dir;
            self.phase = 0.0;
        }
        if self.dir < 0
            && (!self.has_block || self.walk.at_start())
            && !self.retreat(&mut tick, source)
        {
            return tick;
        }
        if !self.has_block {
            return tick;
        }

        // Speed: brake before reversing, then follow min(feed, planned limit) under a_T.
        let dv = self.settings.accel * self.settings.dt;
        let limit = self.planned_limit();
        let target = if want_dir != self.dir || self.hold {
            0.0
        } else {
            feed.min(limit)
        };
        self.speed = if self.speed > target {
            (self.speed - dv).max(target).min(limit)
        } else {
            (self.speed + dv).min(target)
        };
        if self.speed <= 0.0 {
            return tick;
        }

        // DDA: at most one event per tick (the speed is capped at one event per tick).
        self.phase += self.speed * self.settings.dt / self.event_mm;
        if self.phase < 1.0 {
            return tick;
        }
        self.phase = (self.phase - 1.0).min(0.999_999);
        if self.dir > 0 {
            let cutting_open = gap == GapState::Open
                && self.servo.state() == ServoState::Forward
                && !self
                    .block
                    .flags
                    .intersects(BlockFlags::RAPID | BlockFlags::PROBE);
            self.step_forward(&mut tick, source);
            if cutting_open {
                self.open_travel(&mut tick);
            }
            self.contact_grace_mm = (self.contact_grace_mm - self.event_mm).max(0.0);
        } else {
            self.walk.backward(&mut tick.steps);
            self.apply(&mut tick);
            self.counters.events_backward += 1;
            if self.servo.state() == ServoState::Retreat {
                self.retreated(&mut tick);
            }
        }
        tick
    }

    /// The planner's speed limit at the current point, in the current direction, never below
    /// the creep speed; capped at one event per tick.
    #[inline]
    fn planned_limit(&self) -> f64 {
        if !self.has_block || self.walk.events() == 0 {
            return 0.0;
        }
        let b = &self.block;
        let a2 = 2.0 * self.settings.accel;
        let done = (self.walk.event() as f64 + self.phase.min(1.0) * self.dir as f64)
            / self.walk.events() as f64;
        let s = (done.clamp(0.0, 1.0)) * self.lattice_mm;
        let (v_behind, v_ahead, to_go, gone) = if self.dir > 0 {
            (b.v_entry, b.v_exit, self.lattice_mm - s, s)
        } else {
            (b.v_exit, b.v_entry, s, self.lattice_mm - s)
        };
        let v2 = (v_ahead * v_ahead + a2 * to_go).min(v_behind * v_behind + a2 * gone);
        let creep = (self.settings.accel * self.event_mm).sqrt();
        let cap = self.event_mm / self.settings.dt;
        v2.sqrt().max(creep).min(b.v_cruise).min(cap)
    }

    fn step_forward<S: BlockSource + ?Sized>(&mut self, tick: &mut Tick, source: &mut S) {
        if self.walk.at_end() {
            // A turn-back entered this block at its end and the gap cleared before it stepped
            // back in it: the re-advance starts from the block after it (the one it came from,
            // which the source hands out again). Same point, so no step is owed here.
            match self.fetch_forward(source) {
                Fetch::Block => {}
                Fetch::Empty => {
                    tick.event = self.servo.on_starved(self.here());
                    self.speed = 0.0;
                    self.phase = 0.0;
                    return;
                }
                Fetch::End => {
                    tick.event = self.servo.on_end();
                    return;
                }
            }
        }
        self.walk.forward(&mut tick.steps);
        self.apply(tick);
        self.counters.events_forward += 1;
        let mut event = self.servo.on_forward(self.here());
        if self.paused && event.is_none() {
            // The step that finished the block before a programmed stop.
            self.paused = false;
            event = Some(ServoEvent::Paused { at: self.here() });
        }
        // A probing move waits at its end point for the next tick's contact check.
        let probe_end = BlockFlags::PROBE | BlockFlags::LAST_OF_BLOCK;
        if self.walk.at_end() && !self.block.flags.contains(probe_end) {
            match self.fetch_forward(source) {
                Fetch::Block => {
                    if let Some(e) = self.servo.on_forward(self.here()) {
                        event = Some(e);
                    }
                }
                Fetch::Empty => {
                    event = self.servo.on_starved(self.here()).or(event);
                    self.speed = 0.0;
                    self.phase = 0.0;
                }
                Fetch::End => event = self.servo.on_end().or(event),
            }
        }
        if event.is_some() {
            tick.event = event;
        }
    }

    /// Turning back at the start of the block in hand (or with none in hand): takes the
    /// previous block from the reserved area, passing over blocks of zero steps. `false` when
    /// the reserved area is exhausted, which (turn-back only happens while shorted) is the alarm.
    fn retreat<S: BlockSource + ?Sized>(&mut self, tick: &mut Tick, source: &mut S) -> bool {
        loop {
            if !source.previous(&mut self.block) {
                self.retreat_blocked(tick, true);
                return false;
            }
            if self.is_barrier() {
                // Back out of it: the block this retreat came from is handed out again, and
                // the electrode stands at its start, where it was.
                if source.next(&mut self.block) == Fetch::Block {
                    self.enter_block(false);
                } else {
                    self.has_block = false;
                }
                self.retreat_blocked(tick, false);
                return false;
            }
            self.servo.on_block_back();
            self.enter_block(true);
            if self.walk.events() > 0 {
                return true;
            }
        }
    }

    /// Copies the next block with steps into hand, passing over blocks of zero steps.
    fn fetch_forward<S: BlockSource + ?Sized>(&mut self, source: &mut S) -> Fetch {
        loop {
            let fetch = source.next(&mut self.block);
            if fetch != Fetch::Block {
                self.has_block = false;
                return fetch;
            }
            self.counters.blocks_entered += 1;
            self.enter_block(false);
            if self.block.seq >= self.stops_from {
                self.stops_from = self.block.seq + 1;
                if self.block.dwell_s > 0.0 {
                    self.dwell_left += (self.block.dwell_s / self.settings.dt).round() as u64;
                }
                if self.block.flags.contains(BlockFlags::PAUSE) {
                    self.hold = true;
                    self.paused = true;
                }
            }
            if self.walk.events() > 0 {
                return Fetch::Block;
            }
        }
    }

    fn enter_block(&mut self, at_end: bool) {
        self.has_block = true;
        self.block_jumps();
        let delta = self.block.delta();
        self.walk = Bresenham::new(&delta, at_end);
        let mut len2 = 0.0;
        for (d, s) in delta.iter().zip(&self.settings.step_mm) {
            let mm = *d as f64 * s;
            len2 += mm * mm;
        }
        self.lattice_mm = len2.sqrt();
        self.event_mm = if self.walk.events() > 0 {
            self.lattice_mm / self.walk.events() as f64
        } else {
            0.0
        };
    }

    /// Reports a pause met while fetching, if the tick has no other event to report.
    fn take_pause(&mut self, tick: &mut Tick) -> bool {
        if self.paused && tick.event.is_none() {
            self.paused = false;
            tick.event = Some(ServoEvent::Paused { at: self.here() });
            self.speed = 0.0;
            self.phase = 0.0;
            return true;
        }
        false
    }

    #[inline]
    fn apply(&mut self, tick: &mut Tick) {
        for i in 0..MAX_AXES {
            let s = tick.steps[i];
            self.position[i] += s as i64;
            self.counters.pulses[i] += s.unsigned_abs() as u64;
        }
        tick.dir = self.dir;
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
