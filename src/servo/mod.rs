//! The gap servo and short-circuit turn-back (seed 000 §III.D) as an explicit state machine.
//!
//! ```text
//!                 short                         gap clears
//!   Forward ─────────────────► TurnBack ─────────────────► ReAdvance
//!     ▲  │ ▲                    │    ▲          short          │
//!     │  │ └── block arrives ─┐ │    └─────────────────────────┤
//!     │  └─ buffer empty ──► Hold│                              │
//!     │                (short ──┘ too)                          │
//!     └──────────────── back at the point of the short ────────┘
//!   Forward ── program end ──► Done          TurnBack ── reserved area exhausted ──► Alarm
//!
//!   Forward ── jump interval ──► Retreat ── height gone ──► Return ── at the mark ──► Forward
//!   Forward/ReAdvance ── wire break ──► WireBroken ── rethread ──► Retreat ── start hole ──►
//!       Threading ── resume ──► Return ── at the mark ──► Forward      (Return: short ──► TurnBack)
//! ```
//!
//! - **Forward**: along the program at min(planned feed, gap feed): the normal feed while
//!   sparking, the open feed while the gap is open.
//! - **TurnBack**: backwards along the executed path (the block in hand, then the reserved
//!   area) at the retract feed, for as long as the gap is shorted.
//! - **ReAdvance**: forwards again over the same lattice points at the gap feed, to the point
//!   where the short happened (the *mark*); a new short turns back again, the mark stays.
//! - **Hold**: forward motion but no block to execute (a starvation in real time).
//! - **Alarm**: shorted after the whole reserved area; motion stops and the position is kept.
//! - **Done**: the program's last block is executed.
//! - **Retreat**: backwards along the executed path on purpose, spark off: a sinker's jump
//!   (by `servo.jump_height_mm`, to flush the debris out) or the way back to the start hole
//!   after a wire break. The interpolator decides where it ends ([`Servo::on_retreat_done`]).
//! - **Return**: forwards again to the mark, spark off, at the jump or rethread feed; a short
//!   on the way turns back as in a re-advance.
//! - **WireBroken**: the wire broke (a sensor, or an open gap over `servo.max_open_mm` of
//!   cutting): motion stops at once and waits for the operator's rethread.
//! - **Threading**: parked for threading (at the start hole, or where the wire broke), until
//!   the operator resumes.
//!
//! The machine only decides; the fine interpolator moves, and reports back where it is
//! ([`PathPoint`]) and what it ran into (block boundaries, the end of the reserved area) as a
//! [`Travel`], through [`Servo::observe`] alone. Beside it the interpolator only asks (the
//! state, the law's direction and feed) and relays the operator's release, rethread and
//! resume.

mod law;
mod state;

pub use law::{GapReading, Law, LawInput};
pub use state::{
    Excursion, Feeds, PathPoint, PauseKind, Rethread, ServoCounters, ServoEvent, ServoState,
    ShortRules, Travel,
};

use crate::vocab::GapState;
use law::GapLaw;

/// The state machine, with the law that reads the gap and the timer of a long short.
#[derive(Debug, Clone, Copy)]
pub struct Servo {
    state: ServoState,
    feeds: Feeds,
    law: GapLaw,
    /// Consecutive ticks the gap has read short while turning back, and how many raise the
    /// alarm (0: only the reserved history does).
    short_ticks: u64,
    max_short_ticks: u64,
    /// The farthest point reached: where a re-advance hands over to forward motion.
    mark: PathPoint,
    /// Blocks entered backwards in the current turn-back episode.
    depth: u64,
    /// What the current retreat or return is for.
    excursion: Excursion,
    rules: ShortRules,
    /// Consecutive ticks of a short not yet confirmed (`rules.confirm_ticks`).
    short_seen: u32,
    /// The gap read short in the last tick the servo was told of.
    shorted: bool,
    /// How far the current turn-back has backed off along the path (mm).
    backed_mm: f64,
    pub counters: ServoCounters,
}

impl Servo {
    /// A servo with the three-state law, no short timeout and every short believed at once.
    pub fn new(feeds: Feeds) -> Servo {
        Servo::with_law(feeds, Law::ThreeState, 0, 1.0, ShortRules::IMMEDIATE)
    }

    /// A servo reading the gap through `law` in ticks of `dt` seconds; a short that lasts
    /// `max_short_ticks` while turning back raises the alarm (0: never); `rules` say when a
    /// short is believed and how far a turn-back goes at least.
    pub fn with_law(
        feeds: Feeds,
        law: Law,
        max_short_ticks: u64,
        dt: f64,
        rules: ShortRules,
    ) -> Servo {
        Servo {
            state: ServoState::Hold,
            feeds,
            law: GapLaw::new(law, dt),
            short_ticks: 0,
            max_short_ticks,
            mark: PathPoint::default(),
            depth: 0,
            excursion: Excursion::Jump,
            rules,
            short_seen: 0,
            shorted: false,
            backed_mm: 0.0,
            counters: ServoCounters::default(),
        }
    }

    pub fn state(&self) -> ServoState {
        self.state
    }

    pub fn mark(&self) -> PathPoint {
        self.mark
    }

    /// What the interpolator met along the path, as it happens: the one door through which
    /// motion reaches the state machine. Returns the event when the state changed.
    ///
    /// Always inlined: each call site names its variant, so the match folds away and the
    /// tick pays what it paid for calling the handler directly (not inlined, the door cost
    /// 68 instructions a tick, +6.7 % of a job's; BENCHMARKS.md).
    #[inline(always)]
    pub fn observe(&mut self, travel: Travel) -> Option<ServoEvent> {
        match travel {
            Travel::Cutting { gap, at } => {
                let event = self.on_gap(gap, at);
                self.count_short(gap, at).or(event)
            }
            Travel::Returning { gap, at } => self.on_gap(gap, at),
            Travel::BlockInHand => {
                self.on_block();
                None
            }
            Travel::Forward { at } => self.on_forward(at),
            Travel::Backward { mm } => {
                self.on_backward(mm);
                None
            }
            Travel::BlockBack => {
                self.on_block_back();
                None
            }
            Travel::Starved { at } => self.on_starved(at),
            Travel::ProgramEnd => self.on_end(),
            Travel::WayBackEnds { at } => self.on_reserved_exhausted(at),
            Travel::RetreatEnds { at, mm, exhausted } => self.on_retreat_done(at, mm, exhausted),
            Travel::Collision { at } => Some(self.on_collision(at)),
            Travel::ProbeEnds { at, missed } => self.on_probe_end(at, missed),
            Travel::WireBreak { at, open } => self.on_wire_break(at, open),
            Travel::JumpDue { at } => self.start_jump(at),
        }
    }

    /// This tick's gap state, as the law reads what the input measured.
    #[inline]
    pub fn classify(&mut self, reading: &GapReading) -> GapState {
        self.law.classify(reading)
    }

    /// The three-state law is in force (a machining condition's feed applies to it).
    #[inline]
    pub fn three_state(&self) -> bool {
        self.law.is_three_state()
    }

    /// Direction and feed while cutting: the proportional law's once it has a signal (with
    /// a machining condition's reference voltage `v_ref`, 0 for the law's own), the gap
    /// state's otherwise.
    #[inline]
    pub fn law_motion(&self, gap: GapState, v_ref: f32) -> (i8, f64) {
        match self.law.proportional(v_ref) {
            Some((signal, reference, gain)) => {
                self.proportional_motion(gap, signal, reference, gain)
            }
            None => self.motion(gap),
        }
    }

    /// Counts a tick of the gap at `here`: while turning back on a short, a short that has
    /// lasted `max_short_ticks` raises the alarm (returned); anything else resets the count.
    #[inline]
    fn count_short(&mut self, gap: GapState, here: PathPoint) -> Option<ServoEvent> {
        if gap == GapState::Short && self.state == ServoState::TurnBack {
            self.short_ticks += 1;
            if self.max_short_ticks > 0 && self.short_ticks >= self.max_short_ticks {
                return self.on_short_timeout(here);
            }
        } else {
            self.short_ticks = 0;
        }
        None
    }

    /// The gap shorted during a rapid at `here`: a collision (the interpolator stops and
    /// holds there).
    fn on_collision(&mut self, here: PathPoint) -> ServoEvent {
        self.counters.collisions += 1;
        ServoEvent::Collision { at: here }
    }

    /// A probing move ended at `here`: counted, or (`missed`, it had to touch and did not)
    /// the job cannot go on (final, like an alarm).
    fn on_probe_end(&mut self, here: PathPoint, missed: bool) -> Option<ServoEvent> {
        if missed {
            self.state = ServoState::Alarm;
            return Some(ServoEvent::ProbeMissed { at: here });
        }
        self.counters.probes += 1;
        None
    }

    /// The gap state of this tick at `here`. Returns an event when the state changed.
    ///
    /// A short is believed after `rules.confirm_ticks` ticks in a row (one that clears
    /// sooner is counted as brief); a turn-back ends when the gap has cleared and it has
    /// backed off at least `rules.min_retract_mm`.
    fn on_gap(&mut self, gap: GapState, here: PathPoint) -> Option<ServoEvent> {
        self.shorted = gap == GapState::Short;
        match (self.state, gap) {
            (
                ServoState::Forward | ServoState::Hold | ServoState::ReAdvance | ServoState::Return,
                GapState::Short,
            ) => {
                self.short_seen += 1;
                if self.short_seen < self.rules.confirm_ticks {
                    return None;
                }
                self.short_seen = 0;
                if matches!(self.state, ServoState::Forward | ServoState::Hold) {
                    self.mark = here;
                }
                self.start_turn_back(here)
            }
            (ServoState::TurnBack, GapState::Normal | GapState::Open) => {
                (self.backed_mm >= self.rules.min_retract_mm).then(|| self.end_turn_back())
            }
            (_, GapState::Normal | GapState::Open) => {
                if self.short_seen > 0 {
                    self.short_seen = 0;
                    self.counters.brief_shorts += 1;
                }
                None
            }
            _ => None,
        }
    }

    /// A short is being confirmed: the gap reads short but the servo does not believe it
    /// yet, so motion only brakes.
    #[inline]
    pub fn confirming(&self) -> bool {
        self.short_seen > 0
    }

    fn start_turn_back(&mut self, here: PathPoint) -> Option<ServoEvent> {
        self.state = ServoState::TurnBack;
        self.depth = 0;
        self.backed_mm = 0.0;
        self.counters.shorts += 1;
        self.counters.turn_backs += 1;
        Some(ServoEvent::Short { at: here })
    }

    fn end_turn_back(&mut self) -> ServoEvent {
        self.state = ServoState::ReAdvance;
        ServoEvent::Cleared { depth: self.depth }
    }

    /// The interpolator stepped `mm` backwards along the path.
    #[inline]
    fn on_backward(&mut self, mm: f64) {
        if self.state == ServoState::TurnBack {
            self.backed_mm += mm;
        }
    }

    /// The interpolator moved forward to `here` (after an event or a block change).
    fn on_forward(&mut self, here: PathPoint) -> Option<ServoEvent> {
        match self.state {
            ServoState::ReAdvance if here >= self.mark => {
                self.state = ServoState::Forward;
                Some(ServoEvent::Resumed { at: here })
            }
            ServoState::Return if here >= self.mark => {
                self.state = ServoState::Forward;
                Some(ServoEvent::Returned {
                    why: self.excursion,
                    at: here,
                })
            }
            ServoState::Forward => {
                self.mark = here;
                None
            }
            _ => None,
        }
    }

    /// The turn-back entered the previous block (from the reserved area).
    fn on_block_back(&mut self) {
        self.depth += 1;
        let c = &mut self.counters;
        c.deepest_turn_back_blocks = c.deepest_turn_back_blocks.max(self.depth);
    }

    /// The turn-back reached the start of the reserved area: the alarm with the gap still
    /// shorted; with the gap clear (backing off its least retraction) the re-advance.
    fn on_reserved_exhausted(&mut self, here: PathPoint) -> Option<ServoEvent> {
        if self.state == ServoState::TurnBack && !self.shorted {
            return Some(self.end_turn_back());
        }
        self.alarm(here, false)
    }

    /// The short has lasted `servo.max_short_s` while turning back.
    fn on_short_timeout(&mut self, here: PathPoint) -> Option<ServoEvent> {
        self.alarm(here, true)
    }

    fn alarm(&mut self, here: PathPoint, timed_out: bool) -> Option<ServoEvent> {
        (self.state == ServoState::TurnBack).then(|| {
            self.state = ServoState::Alarm;
            self.counters.alarms += 1;
            ServoEvent::Alarm {
                at: here,
                depth: self.depth,
                timed_out,
            }
        })
    }

    /// The operator released the hold an alarm caused (the gap was flushed): re-advance to
    /// the point of the short; a short there turns back again, or alarms again.
    pub fn release_alarm(&mut self) {
        if self.state == ServoState::Alarm {
            self.state = ServoState::ReAdvance;
            self.depth = 0;
            self.short_ticks = 0;
            self.short_seen = 0;
        }
    }

    /// Forward motion found no block to execute.
    fn on_starved(&mut self, here: PathPoint) -> Option<ServoEvent> {
        (self.state == ServoState::Forward).then(|| {
            self.state = ServoState::Hold;
            self.counters.starvations += 1;
            ServoEvent::Starved { at: here }
        })
    }

    /// A block is in hand again after a hold.
    fn on_block(&mut self) {
        if self.state == ServoState::Hold {
            self.state = ServoState::Forward;
        }
    }

    /// Forward motion found the end of the program.
    fn on_end(&mut self) -> Option<ServoEvent> {
        (!self.state.is_final()).then(|| {
            self.state = ServoState::Done;
            ServoEvent::Done
        })
    }

    /// The jump interval has passed while cutting forward at `here`: lift along the path.
    fn start_jump(&mut self, here: PathPoint) -> Option<ServoEvent> {
        (self.state == ServoState::Forward).then(|| {
            self.mark = here;
            self.state = ServoState::Retreat;
            self.excursion = Excursion::Jump;
            self.counters.jumps += 1;
            ServoEvent::Jump { at: here }
        })
    }

    /// What the current retreat or return is for.
    pub fn excursion(&self) -> Excursion {
        self.excursion
    }

    /// The retreat ended at `here`, `mm` of path behind the mark: a jump comes back down, a
    /// rethread parks for threading.
    /// `exhausted`: it stopped at the oldest executed block the loop buffer keeps, short of
    /// where it was going.
    fn on_retreat_done(&mut self, here: PathPoint, mm: f64, exhausted: bool) -> Option<ServoEvent> {
        (self.state == ServoState::Retreat).then(|| {
            self.state = match self.excursion {
                Excursion::Jump => ServoState::Return,
                Excursion::Rethread => ServoState::Threading,
            };
            ServoEvent::Retreated {
                why: self.excursion,
                at: here,
                mm,
                exhausted,
            }
        })
    }

    /// The wire broke at `here` while it was cutting (or closing in). The mark stays the
    /// farthest point cut, where the return after threading ends.
    fn on_wire_break(&mut self, here: PathPoint, open: bool) -> Option<ServoEvent> {
        let cutting = matches!(
            self.state,
            ServoState::Forward | ServoState::ReAdvance | ServoState::TurnBack | ServoState::Hold
        );
        cutting.then(|| {
            if self.state == ServoState::Forward || here > self.mark {
                self.mark = here;
            }
            self.state = ServoState::WireBroken;
            self.counters.wire_breaks += 1;
            ServoEvent::WireBreak { at: here, open }
        })
    }

    /// The operator asked for a rethread: back along the path to the start hole, or
    /// threading where the wire broke.
    pub fn rethread(&mut self, at: Rethread) -> bool {
        if self.state != ServoState::WireBroken {
            return false;
        }
        self.excursion = Excursion::Rethread;
        self.state = match at {
            Rethread::AtStart => ServoState::Retreat,
            Rethread::Here => ServoState::Threading,
        };
        true
    }

    /// The operator resumed after threading: return along the path to the mark (at `here`
    /// already: cutting again at once).
    pub fn resume_threaded(&mut self, here: PathPoint) -> Option<ServoEvent> {
        if self.state != ServoState::Threading {
            return None;
        }
        self.state = ServoState::Return;
        self.on_forward(here)
    }

    /// Direction and feed under a proportional law for a sparking gap whose `signal` is the
    /// filtered voltage, or the ratio law's `open − short`: `gain · (signal − reference)`,
    /// backing off (negative) at up to the retract feed.
    #[inline]
    fn proportional_motion(
        &self,
        gap: GapState,
        signal: f64,
        reference: f64,
        gain: f64,
    ) -> (i8, f64) {
        match (self.state, gap) {
            (ServoState::Forward | ServoState::ReAdvance, GapState::Normal) => {
                let feed = gain * (signal - reference);
                if feed >= 0.0 {
                    (1, feed)
                } else {
                    (-1, (-feed).min(self.feeds.retract))
                }
            }
            _ => self.motion(gap),
        }
    }

    /// Direction (+1 forward, -1 backward, 0 still) and feed (mm/s) for this tick's gap state.
    #[inline]
    pub fn motion(&self, gap: GapState) -> (i8, f64) {
        let gap_feed = match gap {
            GapState::Open => self.feeds.open,
            _ => self.feeds.normal,
        };
        match self.state {
            // A short not yet believed: no further in, no reversal yet.
            ServoState::Forward | ServoState::ReAdvance if gap == GapState::Short => (1, 0.0),
            ServoState::Forward | ServoState::ReAdvance => (1, gap_feed),
            ServoState::TurnBack => (-1, self.feeds.retract),
            // The interpolator sets the feed of an excursion.
            ServoState::Retreat => (-1, self.feeds.retract),
            ServoState::Return => (1, self.feeds.open),
            ServoState::Hold
            | ServoState::Alarm
            | ServoState::Done
            | ServoState::WireBroken
            | ServoState::Threading => (0, 0.0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FEEDS: Feeds = Feeds {
        normal: 1.0,
        open: 5.0,
        retract: 2.0,
    };

    fn at(seq: u64, event: i64) -> PathPoint {
        PathPoint { seq, event }
    }

    /// The interpolator's side of the seam: a turn-back told only through `observe`, from the
    /// short to the resume, then a short that outlasts its ticks while turning back.
    #[test]
    fn a_turn_back_through_the_one_door() {
        let mut servo = Servo::with_law(FEEDS, Law::ThreeState, 3, 1.0, ShortRules::IMMEDIATE);
        assert_eq!(servo.observe(Travel::BlockInHand), None);
        assert_eq!(servo.observe(Travel::Forward { at: at(1, 4) }), None);
        let short = Travel::Cutting {
            gap: GapState::Short,
            at: at(1, 5),
        };
        assert_eq!(
            servo.observe(short),
            Some(ServoEvent::Short { at: at(1, 5) })
        );
        assert_eq!(servo.state(), ServoState::TurnBack);
        assert_eq!(servo.observe(Travel::Backward { mm: 0.001 }), None);
        assert_eq!(servo.observe(Travel::BlockBack), None);
        let clear = Travel::Cutting {
            gap: GapState::Normal,
            at: at(0, 9),
        };
        assert_eq!(servo.observe(clear), Some(ServoEvent::Cleared { depth: 1 }));
        assert_eq!(servo.observe(Travel::Forward { at: at(1, 4) }), None);
        assert_eq!(
            servo.observe(Travel::Forward { at: at(1, 5) }),
            Some(ServoEvent::Resumed { at: at(1, 5) })
        );
        assert_eq!(servo.state(), ServoState::Forward);
        // Shorted for 3 ticks in a turn-back: the alarm on the third (the first also turned
        // back), reported over the tick's other event.
        let short = Travel::Cutting {
            gap: GapState::Short,
            at: at(1, 6),
        };
        assert!(matches!(
            servo.observe(short),
            Some(ServoEvent::Short { .. })
        ));
        assert_eq!(servo.observe(short), None);
        assert_eq!(
            servo.observe(short),
            Some(ServoEvent::Alarm {
                at: at(1, 6),
                depth: 0,
                timed_out: true
            })
        );
        assert_eq!(servo.state(), ServoState::Alarm);
        assert_eq!(servo.counters.turn_backs, 2);
    }

    #[test]
    fn short_turn_back_clear_re_advance_resume() {
        let mut servo = Servo::new(FEEDS);
        servo.on_block();
        assert_eq!(servo.state(), ServoState::Forward);
        assert_eq!(servo.motion(GapState::Open), (1, 5.0));
        servo.on_forward(at(3, 7));
        assert_eq!(
            servo.on_gap(GapState::Short, at(3, 7)),
            Some(ServoEvent::Short { at: at(3, 7) })
        );
        assert_eq!(servo.motion(GapState::Short), (-1, 2.0));
        servo.on_block_back();
        servo.on_block_back();
        assert_eq!(
            servo.on_gap(GapState::Normal, at(1, 2)),
            Some(ServoEvent::Cleared { depth: 2 })
        );
        assert_eq!(servo.state(), ServoState::ReAdvance);
        // A second short while re-advancing keeps the original mark.
        servo.on_forward(at(2, 0));
        assert!(servo.on_gap(GapState::Short, at(2, 0)).is_some());
        servo.on_gap(GapState::Normal, at(1, 9));
        assert_eq!(servo.on_forward(at(3, 6)), None);
        assert_eq!(
            servo.on_forward(at(3, 7)),
            Some(ServoEvent::Resumed { at: at(3, 7) })
        );
        assert_eq!(servo.state(), ServoState::Forward);
        let c = servo.counters;
        assert_eq!(
            (c.shorts, c.turn_backs, c.deepest_turn_back_blocks),
            (2, 2, 2)
        );
    }

    #[test]
    fn exhausted_reserve_is_an_alarm_and_final() {
        let mut servo = Servo::new(FEEDS);
        servo.on_block();
        servo.on_gap(GapState::Short, at(0, 5));
        assert!(matches!(
            servo.on_reserved_exhausted(at(0, 0)),
            Some(ServoEvent::Alarm { .. })
        ));
        assert_eq!(servo.motion(GapState::Normal), (0, 0.0));
        assert_eq!(servo.on_gap(GapState::Normal, at(0, 0)), None);
        assert_eq!(servo.state(), ServoState::Alarm);
        assert_eq!(servo.on_end(), None);
    }

    #[test]
    fn a_short_is_believed_after_its_confirmation_and_a_brief_one_is_counted() {
        let rules = ShortRules {
            confirm_ticks: 3,
            min_retract_mm: 0.0,
        };
        let mut servo = Servo::with_law(FEEDS, Law::ThreeState, 0, 1.0, rules);
        servo.on_block();
        assert_eq!(servo.on_gap(GapState::Short, at(0, 5)), None);
        assert!(servo.confirming());
        assert_eq!(
            servo.motion(GapState::Short),
            (1, 0.0),
            "brakes, no reversal"
        );
        assert_eq!(servo.on_gap(GapState::Short, at(0, 5)), None);
        assert_eq!(servo.on_gap(GapState::Normal, at(0, 5)), None);
        assert_eq!(servo.counters.brief_shorts, 1);
        assert_eq!(servo.state(), ServoState::Forward);
        for _ in 0..2 {
            assert_eq!(servo.on_gap(GapState::Short, at(0, 6)), None);
        }
        assert_eq!(
            servo.on_gap(GapState::Short, at(0, 6)),
            Some(ServoEvent::Short { at: at(0, 6) })
        );
        assert_eq!(servo.counters.shorts, 1);
        assert_eq!(servo.counters.brief_shorts, 1);
    }

    #[test]
    fn a_turn_back_backs_off_its_least_retraction_after_the_gap_clears() {
        let rules = ShortRules {
            confirm_ticks: 1,
            min_retract_mm: 0.005,
        };
        let mut servo = Servo::with_law(FEEDS, Law::ThreeState, 0, 1.0, rules);
        servo.on_block();
        servo.on_gap(GapState::Short, at(0, 10));
        servo.on_backward(0.001);
        assert_eq!(servo.on_gap(GapState::Normal, at(0, 9)), None);
        assert_eq!(servo.motion(GapState::Normal), (-1, 2.0));
        for _ in 0..4 {
            servo.on_backward(0.001);
        }
        assert_eq!(
            servo.on_gap(GapState::Normal, at(0, 5)),
            Some(ServoEvent::Cleared { depth: 0 })
        );
        // The reserved area ends before the least retraction, the gap clear: no alarm.
        servo.on_gap(GapState::Short, at(0, 6));
        servo.on_gap(GapState::Normal, at(0, 6));
        assert_eq!(
            servo.on_reserved_exhausted(at(0, 0)),
            Some(ServoEvent::Cleared { depth: 0 })
        );
        assert_eq!(servo.state(), ServoState::ReAdvance);
        // Still shorted there: the alarm.
        servo.on_gap(GapState::Short, at(0, 3));
        assert!(matches!(
            servo.on_reserved_exhausted(at(0, 0)),
            Some(ServoEvent::Alarm { .. })
        ));
    }

    #[test]
    fn starvation_holds_until_a_block_arrives() {
        let mut servo = Servo::new(FEEDS);
        servo.on_block();
        assert!(servo.on_starved(at(0, 9)).is_some());
        assert_eq!(servo.on_starved(at(0, 9)), None, "counted once per episode");
        assert_eq!(servo.motion(GapState::Normal).0, 0);
        servo.on_block();
        assert_eq!(servo.state(), ServoState::Forward);
        assert_eq!(servo.counters.starvations, 1);
    }
}
