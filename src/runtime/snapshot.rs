//! The interpolator's state as the other threads see it: a [`Snapshot`] the consumer writes
//! through a single-writer sequence lock (it never waits) and anyone reads consistently.

use std::sync::atomic::{AtomicU64, Ordering, fence};

use crate::fine::Interpolator;
use crate::servo::{Excursion, PathPoint, ServoCounters, ServoState};
use crate::vocab::{MAX_AXES, Steps};

/// The interpolator's state as the other threads see it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Snapshot {
    pub tick: u64,
    pub state: ServoState,
    /// The hold is in force (the operator's, not a starvation).
    pub held: bool,
    /// Held (or finished) and at a standstill.
    pub still: bool,
    /// The pulse ledger (steps).
    pub position: Steps,
    /// Where along the program: segment and Bresenham step.
    pub here: PathPoint,
    /// Steps of the segment in hand.
    pub events: i64,
    /// Source line of the segment in hand.
    pub line: u64,
    /// Curve parameter at the end of the segment in hand (NaN outside NURBS).
    pub u_end: f64,
    /// Path speed (mm/s).
    pub speed: f64,
    pub servo: ServoCounters,
    /// Pulses emitted per axis.
    pub pulses: [u64; MAX_AXES],
    /// Path length from the program's start to the electrode (mm), along the segment in
    /// hand: goes back during a turn-back.
    pub path_mm: f64,
    /// What a retreat or return is for (in those states).
    pub excursion: Option<Excursion>,
    /// Ticks of a `G4` dwell still to wait here (a checkpoint keeps them).
    pub dwell_left: u64,
}

impl Default for Snapshot {
    fn default() -> Self {
        Snapshot {
            tick: 0,
            state: ServoState::Hold,
            held: false,
            still: true,
            position: [0; MAX_AXES],
            here: PathPoint::default(),
            events: 0,
            line: 0,
            u_end: f64::NAN,
            speed: 0.0,
            servo: ServoCounters::default(),
            pulses: [0; MAX_AXES],
            path_mm: 0.0,
            excursion: None,
            dwell_left: 0,
        }
    }
}

pub(super) const WORDS: usize = 2 + MAX_AXES + 6 + 6 + MAX_AXES + 5;
const STATES: [ServoState; 10] = [
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

impl Snapshot {
    pub fn of(tick: u64, fine: &Interpolator) -> Snapshot {
        let c = fine.counters();
        let (events, u_end) = fine
            .block()
            .map_or((0, f64::NAN), |b| (b.events() as i64, b.u_end));
        let here = fine.here();
        let path_mm = fine.block().map_or(0.0, |b| {
            let left = if events > 0 {
                (events - here.event).clamp(0, events) as f64 / events as f64
            } else {
                0.0
            };
            b.path_end_mm - b.length_mm * left
        });
        Snapshot {
            tick,
            state: fine.state(),
            held: fine.held(),
            still: fine.still(),
            position: fine.position(),
            here: fine.here(),
            events,
            line: fine.line(),
            u_end,
            speed: fine.speed(),
            servo: c.servo,
            pulses: c.pulses,
            path_mm,
            excursion: matches!(fine.state(), ServoState::Retreat | ServoState::Return)
                .then(|| fine.excursion()),
            dwell_left: fine.dwell_left(),
        }
    }

    pub(super) fn encode(&self) -> [u64; WORDS] {
        let mut w = [0u64; WORDS];
        let state = STATES.iter().position(|s| *s == self.state).unwrap_or(1) as u64;
        w[0] = self.tick;
        let excursion = match self.excursion {
            None => 0,
            Some(Excursion::Jump) => 1,
            Some(Excursion::Rethread) => 2,
        };
        w[1] = state | (self.held as u64) << 8 | (self.still as u64) << 9 | excursion << 10;
        for i in 0..MAX_AXES {
            w[2 + i] = self.position[i] as u64;
            w[2 + MAX_AXES + 12 + i] = self.pulses[i];
        }
        let m = 2 + MAX_AXES;
        w[m] = self.here.seq;
        w[m + 1] = self.here.event as u64;
        w[m + 2] = self.events as u64;
        w[m + 3] = self.line;
        w[m + 4] = self.u_end.to_bits();
        w[m + 5] = self.speed.to_bits();
        let c = &self.servo;
        w[m + 6..m + 12].copy_from_slice(&[
            c.shorts,
            c.turn_backs,
            c.deepest_turn_back_blocks,
            c.alarms,
            c.starvations,
            c.collisions,
        ]);
        w[WORDS - 5] = self.dwell_left;
        w[WORDS - 4] = c.jumps;
        w[WORDS - 3] = c.wire_breaks;
        w[WORDS - 2] = c.probes;
        w[WORDS - 1] = self.path_mm.to_bits();
        w
    }

    pub(super) fn decode(w: &[u64; WORDS]) -> Snapshot {
        let m = 2 + MAX_AXES;
        Snapshot {
            tick: w[0],
            state: STATES[(w[1] & 0xff) as usize % STATES.len()],
            held: w[1] & 1 << 8 != 0,
            still: w[1] & 1 << 9 != 0,
            excursion: match (w[1] >> 10) & 3 {
                1 => Some(Excursion::Jump),
                2 => Some(Excursion::Rethread),
                _ => None,
            },
            position: std::array::from_fn(|i| w[2 + i] as i64),
            here: PathPoint {
                seq: w[m],
                event: w[m + 1] as i64,
            },
            events: w[m + 2] as i64,
            line: w[m + 3],
            u_end: f64::from_bits(w[m + 4]),
            speed: f64::from_bits(w[m + 5]),
            servo: ServoCounters {
                shorts: w[m + 6],
                turn_backs: w[m + 7],
                deepest_turn_back_blocks: w[m + 8],
                alarms: w[m + 9],
                starvations: w[m + 10],
                collisions: w[m + 11],
                jumps: w[WORDS - 4],
                wire_breaks: w[WORDS - 3],
                probes: w[WORDS - 2],
            },
            pulses: std::array::from_fn(|i| w[m + 12 + i]),
            path_mm: f64::from_bits(w[WORDS - 1]),
            dwell_left: w[WORDS - 5],
        }
    }
}

/// A single-writer sequence lock over a few words: the writer never waits, a reader retries
/// while a write is in progress or happened under it.
#[derive(Debug)]
pub(super) struct SeqLock {
    version: AtomicU64,
    words: [AtomicU64; WORDS],
}

impl Default for SeqLock {
    fn default() -> Self {
        let lock = SeqLock {
            version: AtomicU64::new(0),
            words: std::array::from_fn(|_| AtomicU64::new(0)),
        };
        lock.write(&Snapshot::default().encode());
        lock
    }
}

impl SeqLock {
    #[inline]
    pub(super) fn write(&self, data: &[u64; WORDS]) {
        let v = self.version.load(Ordering::Relaxed);
        self.version.store(v.wrapping_add(1), Ordering::Relaxed);
        fence(Ordering::Release);
        for (slot, &d) in self.words.iter().zip(data) {
            slot.store(d, Ordering::Relaxed);
        }
        self.version.store(v.wrapping_add(2), Ordering::Release);
    }

    pub(super) fn read(&self) -> [u64; WORDS] {
        loop {
            let before = self.version.load(Ordering::Acquire);
            if before & 1 == 1 {
                std::hint::spin_loop();
                continue;
            }
            let data = std::array::from_fn(|i| self.words[i].load(Ordering::Relaxed));
            fence(Ordering::Acquire);
            if self.version.load(Ordering::Relaxed) == before {
                return data;
            }
        }
    }
}
