//! What the servo says and keeps: where along the path ([`PathPoint`]), its state
//! ([`ServoState`], with the excursion and rethread kinds), the events it reports
//! ([`ServoEvent`]), its feeds and its counters ([`ServoCounters`]), with their seqlock words.

use crate::words::{Packed, packed_struct};

/// Where the electrode is along the program: block sequence number and Bresenham event.
/// Ordered along the path (the end of block `s` and the start of block `s + 1` are the same
/// lattice point but compare as the order in which they are reached).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Default)]
pub struct PathPoint {
    pub seq: u64,
    pub event: i64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ServoState {
    Forward,
    Hold,
    TurnBack,
    ReAdvance,
    Alarm,
    Done,
    Retreat,
    Return,
    WireBroken,
    Threading,
}

/// Why the interpolator stopped before a move, to wait for the operator's resume.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PauseKind {
    /// The program's `M0`, or `M1` with the optional stop on.
    Program,
    /// The operator's single block: before every program block.
    SingleBlock,
    /// Before a wire contour's tab: the operator secures the slug the tab's cut frees.
    Slug,
}

impl PauseKind {
    pub fn name(self) -> &'static str {
        match self {
            PauseKind::Program => "program stop (M0/M1)",
            PauseKind::SingleBlock => "single block",
            PauseKind::Slug => "secure the slug",
        }
    }

    pub fn code(self) -> u8 {
        match self {
            PauseKind::Program => 1,
            PauseKind::SingleBlock => 2,
            PauseKind::Slug => 3,
        }
    }

    pub fn from_code(code: u8) -> Option<PauseKind> {
        match code {
            1 => Some(PauseKind::Program),
            2 => Some(PauseKind::SingleBlock),
            3 => Some(PauseKind::Slug),
            _ => None,
        }
    }
}

/// Where the wire is threaded again after a break.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Rethread {
    /// Back along the path to the start hole first.
    AtStart,
    /// Where the wire broke.
    Here,
}

/// Why the servo retreats along the path on purpose.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Excursion {
    /// A sinker's jump: up by the jump height, back down, sparking again.
    Jump,
    /// Back to the start hole to re-thread a broken wire.
    Rethread,
}

impl ServoState {
    pub fn name(self) -> &'static str {
        match self {
            ServoState::Forward => "forward",
            ServoState::Hold => "hold",
            ServoState::TurnBack => "turn-back",
            ServoState::ReAdvance => "re-advance",
            ServoState::Alarm => "alarm",
            ServoState::Done => "done",
            ServoState::Retreat => "retreat",
            ServoState::Return => "return",
            ServoState::WireBroken => "wire-break",
            ServoState::Threading => "threading",
        }
    }

    /// Every state.
    pub const ALL: [ServoState; 10] = [
        ServoState::Forward,
        ServoState::Hold,
        ServoState::TurnBack,
        ServoState::ReAdvance,
        ServoState::Alarm,
        ServoState::Done,
        ServoState::Retreat,
        ServoState::Return,
        ServoState::WireBroken,
        ServoState::Threading,
    ];

    /// The state a [`name`](Self::name) names.
    pub fn from_name(name: &str) -> Option<ServoState> {
        ServoState::ALL.into_iter().find(|s| s.name() == name)
    }

    /// The generator is off whatever the move: jumps, rethreading and the ways there and back.
    pub fn spark_off(self) -> bool {
        matches!(
            self,
            ServoState::Retreat
                | ServoState::Return
                | ServoState::WireBroken
                | ServoState::Threading
        )
    }

    /// Parked after a wire break, waiting for the operator.
    pub fn wire_parked(self) -> bool {
        matches!(self, ServoState::WireBroken | ServoState::Threading)
    }

    /// No more motion will happen.
    pub fn is_final(self) -> bool {
        matches!(self, ServoState::Alarm | ServoState::Done)
    }
}

/// In the status JSON a state is its [`name`](ServoState::name).
impl serde::Serialize for ServoState {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.name())
    }
}

impl<'de> serde::Deserialize<'de> for ServoState {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let name = String::deserialize(deserializer)?;
        ServoState::from_name(&name)
            .ok_or_else(|| serde::de::Error::custom(format!("no servo state {name:?}")))
    }
}

/// Servo feeds in mm/s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Feeds {
    pub normal: f64,
    pub open: f64,
    pub retract: f64,
}

/// How the servo takes a short (`[servo]`): a short is believed once the gap has read short
/// for `confirm_ticks` ticks in a row (until then the electrode only brakes: a single noisy
/// reading is no reason to reverse), and a turn-back, once begun, backs off at least
/// `min_retract_mm` along the path even if the gap clears sooner (a retraction of a step or
/// two does not break a bridge of debris; it only starts a chatter at the short's edge).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShortRules {
    pub confirm_ticks: u32,
    pub min_retract_mm: f64,
}

impl ShortRules {
    /// Every short believed at once, a turn-back as long as the short: the seeds' servo.
    pub const IMMEDIATE: ShortRules = ShortRules {
        confirm_ticks: 1,
        min_retract_mm: 0.0,
    };
}

/// What the fine interpolator met along the path, told to the servo as it happens: the one
/// way motion reaches the servo's state machine ([`Servo::observe`](super::Servo::observe)).
/// The interpolator moves and reports; the servo decides what a report means for its state.
/// A change to the turn-back is a change to the servo's answer to one of these, not to the
/// interpolator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Travel {
    /// This tick's gap at `at` while cutting: a short believed starts a turn-back, a cleared
    /// gap ends one, and a short that lasts too long while turning back is the alarm.
    Cutting {
        gap: crate::vocab::GapState,
        at: PathPoint,
    },
    /// This tick's gap at `at` on the way back to the mark after a jump or a rethread: a
    /// short turns back as in a re-advance (no short timer: the return is spark off).
    Returning {
        gap: crate::vocab::GapState,
        at: PathPoint,
    },
    /// A block is in hand (after a hold, a probing move's end, a resume at a checkpoint).
    BlockInHand,
    /// One step forward, or a block change going forward, now at `at`.
    Forward { at: PathPoint },
    /// One event backward along the path, `mm` long.
    Backward { mm: f64 },
    /// Going backward, the previous block came into hand from the reserved area.
    BlockBack,
    /// Going forward, the loop buffer had no block for the interpolator.
    Starved { at: PathPoint },
    /// Going forward, the program ended.
    ProgramEnd,
    /// Going backward, the way back ended at `at`: the start of the reserved area, or a
    /// barrier (a probing move, the rapid before the cut).
    WayBackEnds { at: PathPoint },
    /// A retreat (jump, rethread) ended at `at`, `mm` of path behind the mark; `exhausted`:
    /// at the oldest executed block kept, short of where it was going.
    RetreatEnds {
        at: PathPoint,
        mm: f64,
        exhausted: bool,
    },
    /// The gap shorted during a rapid at `at`: the electrode stopped there.
    Collision { at: PathPoint },
    /// A probing move ended at `at`; `missed`: it had to touch and did not.
    ProbeEnds { at: PathPoint, missed: bool },
    /// The wire broke at `at`: by the sensor, or (`open`) by an open gap over its distance.
    WireBreak { at: PathPoint, open: bool },
    /// The jump interval has passed while cutting at `at`.
    JumpDue { at: PathPoint },
}

/// Something the servo did that the outside world wants to hear about (logged by a normal
/// thread, never by the tick core).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ServoEvent {
    /// A short circuit began (or began again during re-advance).
    Short { at: PathPoint },
    /// The gap cleared after turning back over `depth` blocks.
    Cleared { depth: u64 },
    /// Back at the point of the short; machining goes on.
    Resumed { at: PathPoint },
    /// The buffer ran dry.
    Starved { at: PathPoint },
    /// Shorted after the whole reserved area, or for longer than `servo.max_short_s`
    /// (`timed_out`).
    Alarm {
        at: PathPoint,
        depth: u64,
        timed_out: bool,
    },
    /// The last block is done.
    Done,
    /// A stop before the move at `at` (see [`PauseKind`]): the interpolator holds there.
    Paused { at: PathPoint, kind: PauseKind },
    /// The gap shorted during a rapid (`G0`): the electrode touched something while
    /// positioning with the spark off. Motion stopped at `at`; the interpolator holds.
    Collision { at: PathPoint },
    /// The machining condition (`E<number>`) in force changed with the move in hand
    /// (reported by the consumer's thread loop).
    Condition { number: u16 },
    /// Flushing (`M7`/`M8`, `M9`) turned on or off with the move in hand (reported by the
    /// consumer's thread loop, which tells the output).
    Flushing { on: bool },
    /// Pass `number` (1-based) of the technology table starts with the move in hand
    /// (reported by the consumer's thread loop).
    PassStart { number: u8 },
    /// The operator's feed (or, `rapid`, rapid) override took effect at this tick (reported
    /// by the consumer's loop, like the flushing).
    Override { rapid: bool, percent: u16 },
    /// A jump began at `at` (the electrode lifts along the path, spark off).
    Jump { at: PathPoint },
    /// The retreat of a jump or a rethread ended at `at`, `mm` of path behind the mark.
    Retreated {
        why: Excursion,
        at: PathPoint,
        mm: f64,
        /// Stopped at the oldest executed block kept (`buffer.reserved`), short of the
        /// start of the cut.
        exhausted: bool,
    },
    /// Back at the mark after a jump or a rethread: sparking again.
    Returned { why: Excursion, at: PathPoint },
    /// The wire broke at `at`: by the sensor, or (`open`) by an open gap over
    /// `servo.max_open_mm` of cutting travel. Motion stopped; the interpolator holds.
    WireBreak { at: PathPoint, open: bool },
    /// A probing move touched (or, probing away, left) the work at `at`; `steps` is the
    /// pulse ledger there. `contact: false`: it reached its end point without.
    Probed {
        at: PathPoint,
        steps: [i64; crate::vocab::MAX_AXES],
        contact: bool,
        /// Probing away (`G38.4`/`G38.5`): the contact was lost rather than made.
        away: bool,
    },
    /// A `G38.2`/`G38.4` reached its end point without contact: the job cannot go on.
    ProbeMissed { at: PathPoint },
    /// A drilling move (`[sinker] breakthrough`) ended: `found`, it broke through (the last
    /// spark at `last_spark`) and stopped `breakthrough_extra_mm` past it at `steps`; else it
    /// reached its end point. The program goes on from `steps`.
    Breakthrough {
        at: PathPoint,
        steps: [i64; crate::vocab::MAX_AXES],
        last_spark: [i64; crate::vocab::MAX_AXES],
        found: bool,
    },
}

/// A state travels as its index in [`ServoState::ALL`].
impl Packed for ServoState {
    const WORDS: usize = 1;
    fn pack(&self, out: &mut [u64]) {
        out[0] = ServoState::ALL.iter().position(|s| s == self).unwrap_or(1) as u64;
    }
    fn unpack(words: &[u64]) -> Self {
        ServoState::ALL[words[0] as usize % ServoState::ALL.len()]
    }
}

impl Packed for Option<Excursion> {
    const WORDS: usize = 1;
    fn pack(&self, out: &mut [u64]) {
        out[0] = match self {
            None => 0,
            Some(Excursion::Jump) => 1,
            Some(Excursion::Rethread) => 2,
        };
    }
    fn unpack(words: &[u64]) -> Self {
        match words[0] {
            1 => Some(Excursion::Jump),
            2 => Some(Excursion::Rethread),
            _ => None,
        }
    }
}

impl Packed for PathPoint {
    const WORDS: usize = 2;
    fn pack(&self, out: &mut [u64]) {
        self.seq.pack(&mut out[..1]);
        self.event.pack(&mut out[1..]);
    }
    fn unpack(words: &[u64]) -> Self {
        PathPoint {
            seq: u64::unpack(&words[..1]),
            event: i64::unpack(&words[1..]),
        }
    }
}

packed_struct! {
/// Counters kept by the servo: one definition for the summary, the status, the metrics and
/// the snapshot (flattened into the JSON under these names).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub struct ServoCounters {
    pub shorts: u64,
    pub turn_backs: u64,
    /// The most blocks one turn-back went back over (a maximum, not a count).
    pub deepest_turn_back_blocks: u64,
    pub alarms: u64,
    pub starvations: u64,
    /// Shorts during rapids (collisions).
    #[serde(default)]
    pub collisions: u64,
    /// Jumps begun.
    #[serde(default)]
    pub jumps: u64,
    /// Wire breaks detected.
    #[serde(default)]
    pub wire_breaks: u64,
    /// Probing moves finished (with or without contact).
    #[serde(default)]
    pub probes: u64,
    /// Shorts that cleared before `servo.short_confirm_ticks`: braked for, not turned back.
    #[serde(default)]
    pub brief_shorts: u64,
}
}

impl ServoCounters {
    /// The counts (everything but the deepest turn-back) with their names and what they
    /// count, for the metrics: `edmd_<name>_total`.
    pub fn counts(&self) -> [(&'static str, &'static str, u64); 9] {
        [
            ("shorts", "Short circuits.", self.shorts),
            (
                "turn_backs",
                "Turn-backs along the executed path.",
                self.turn_backs,
            ),
            (
                "alarms",
                "Alarms (shorts the turn-back could not clear).",
                self.alarms,
            ),
            ("collisions", "Shorts during rapids.", self.collisions),
            (
                "starvations",
                "Times the loop buffer ran dry.",
                self.starvations,
            ),
            ("jumps", "Sinker jumps.", self.jumps),
            ("wire_breaks", "Wire breaks.", self.wire_breaks),
            ("probes", "Probing moves finished.", self.probes),
            (
                "brief_shorts",
                "Shorts that cleared before confirmation (no turn-back).",
                self.brief_shorts,
            ),
        ]
    }

    /// Two jobs' counters together: the counts summed, the deepest turn-back the deeper.
    pub fn plus(&self, other: &ServoCounters) -> ServoCounters {
        ServoCounters {
            shorts: self.shorts + other.shorts,
            turn_backs: self.turn_backs + other.turn_backs,
            deepest_turn_back_blocks: self
                .deepest_turn_back_blocks
                .max(other.deepest_turn_back_blocks),
            alarms: self.alarms + other.alarms,
            starvations: self.starvations + other.starvations,
            collisions: self.collisions + other.collisions,
            jumps: self.jumps + other.jumps,
            wire_breaks: self.wire_breaks + other.wire_breaks,
            probes: self.probes + other.probes,
            brief_shorts: self.brief_shorts + other.brief_shorts,
        }
    }
}
