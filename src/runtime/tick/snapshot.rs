//! The interpolator's state as the other threads see it: a [`Snapshot`] the consumer writes
//! through a single-writer sequence lock (it never waits) and anyone reads consistently.

use std::sync::atomic::{AtomicU64, Ordering, fence};

use crate::fine::Interpolator;
use crate::servo::{Excursion, PathPoint, ServoCounters, ServoState};
use crate::vocab::{MAX_AXES, Steps};
use crate::words::{Packed, packed_struct};

packed_struct! {
/// The interpolator's state as the other threads see it. It travels through the seqlock
/// field by field, in this order: the one list of its fields ([`crate::words`]).
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
    /// hand: goes back during a turn-back; with none in hand, the end of the last one left.
    pub path_mm: f64,
    /// What a retreat or return is for (in those states).
    pub excursion: Option<Excursion>,
    /// Ticks of a `G4` dwell still to wait here (a checkpoint keeps them).
    pub dwell_left: u64,
    /// The segment in hand's condition (`E`; 0 none), pass of the technology table (0: not
    /// in passes) and wire offset (mm, + left, − right, 0 none).
    pub condition: u64,
    pub pass: u64,
    pub wire_offset_mm: f64,
    /// The gap's pulses so far by class (normal, arc, short, open; all 0 from an input that
    /// does not count them) and the sum of their ignition delays (µs).
    pub pulse_totals: [u64; 4],
    pub delay_sum_us: f64,
    /// The generator's off time in force (µs; 0 with no condition), and the adaptive law's
    /// estimate of the part height (mm; NaN while the law does not run).
    pub off_time_us: f64,
    pub height_mm: f64,
}
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
            condition: 0,
            pass: 0,
            wire_offset_mm: 0.0,
            pulse_totals: [0; 4],
            delay_sum_us: 0.0,
            off_time_us: 0.0,
            height_mm: f64::NAN,
        }
    }
}

/// Words of a snapshot in the seqlock.
pub(crate) const WORDS: usize = <Snapshot as Packed>::WORDS;

impl Snapshot {
    pub fn of(tick: u64, fine: &Interpolator) -> Snapshot {
        let c = fine.counters();
        let (events, u_end) = fine
            .block()
            .map_or((0, f64::NAN), |b| (b.events() as i64, b.u_end));
        let path_mm = fine.path_mm();
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
            condition: fine.block().map_or(0, |b| u64::from(b.condition)),
            pass: fine.block().map_or(0, |b| u64::from(b.pass)),
            wire_offset_mm: fine.block().map_or(0.0, |b| f64::from(b.wire_offset_mm)),
            pulse_totals: fine.process().pulse_totals().0,
            delay_sum_us: fine.process().pulse_totals().1,
            off_time_us: fine.process().generator().off_time_us,
            height_mm: fine.process().adaptive().map_or(f64::NAN, |a| a.height_mm),
        }
    }

    pub(crate) fn encode(&self) -> [u64; WORDS] {
        let mut words = [0u64; WORDS];
        self.pack(&mut words);
        words
    }

    pub(crate) fn decode(words: &[u64; WORDS]) -> Snapshot {
        Snapshot::unpack(words)
    }
}

/// A single-writer sequence lock over a few words: the writer never waits, a reader retries
/// while a write is in progress or happened under it.
#[derive(Debug)]
pub(crate) struct SeqLock {
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
    pub(crate) fn write(&self, data: &[u64; WORDS]) {
        let v = self.version.load(Ordering::Relaxed);
        self.version.store(v.wrapping_add(1), Ordering::Relaxed);
        fence(Ordering::Release);
        for (slot, &d) in self.words.iter().zip(data) {
            slot.store(d, Ordering::Relaxed);
        }
        self.version.store(v.wrapping_add(2), Ordering::Release);
    }

    pub(crate) fn read(&self) -> [u64; WORDS] {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// Every field survives the seqlock's words, whatever its value: random snapshots
    /// (seeded), each state and excursion, NaN and extreme numbers.
    #[test]
    fn a_snapshot_round_trips_through_the_seqlock() {
        let mut rng = SplitMix64::new(7);
        let lock = SeqLock::default();
        // The default's parameter is NaN (no NURBS yet), which compares unequal to itself.
        let first = Snapshot::decode(&lock.read());
        assert!(first.u_end.is_nan());
        assert_eq!(first.encode(), Snapshot::default().encode());
        for i in 0..1000u64 {
            let mut r = || rng.next_u64();
            let snap = Snapshot {
                tick: r(),
                state: ServoState::ALL[i as usize % ServoState::ALL.len()],
                held: i % 2 == 0,
                still: i % 3 == 0,
                position: std::array::from_fn(|_| r() as i64),
                here: PathPoint {
                    seq: r(),
                    event: r() as i64,
                },
                events: r() as i64,
                line: r(),
                u_end: f64::from_bits(r() & !(0x7ff << 52)),
                speed: (r() % 1000) as f64 / 7.0,
                servo: ServoCounters {
                    shorts: r(),
                    turn_backs: r(),
                    deepest_turn_back_blocks: r(),
                    alarms: r(),
                    starvations: r(),
                    collisions: r(),
                    jumps: r(),
                    wire_breaks: r(),
                    probes: r(),
                    brief_shorts: r(),
                },
                pulses: std::array::from_fn(|_| r()),
                path_mm: -(r() as f64),
                excursion: [None, Some(Excursion::Jump), Some(Excursion::Rethread)][i as usize % 3],
                dwell_left: r(),
                condition: r(),
                pass: r(),
                wire_offset_mm: (r() % 1000) as f64 / -3.0,
                pulse_totals: std::array::from_fn(|_| r()),
                delay_sum_us: (r() % 100_000) as f64 / 3.0,
                off_time_us: (r() % 1000) as f64 / 7.0,
                height_mm: (r() % 1000) as f64 / 9.0,
            };
            lock.write(&snap.encode());
            assert_eq!(Snapshot::decode(&lock.read()), snap);
        }
    }
}
