//! What the consumer publishes while a job runs, and the flags other threads steer it by:
//! [`Published`], shared between the fine thread (which only stores into it), the job's
//! supervisor and the daemon's control loop (which read it, and set hold, stop, the controls
//! and a continuous jog's dead-man).

use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, Ordering};

use std::sync::OnceLock;

use crossbeam::queue::ArrayQueue;
use crossbeam::utils::CachePadded;

use super::controls::{ControlWord, RethreadRequest};
use super::probe::ProbeLink;
use super::snapshot::{SeqLock, Snapshot};
use crate::fine::Interpolator;
use crate::gap::GapState;
use crate::record::{ProcessPoint, ProcessTap};
use crate::servo::ServoEvent;
use crate::vocab::Steps;

/// A servo event with the tick it happened in and the source line of the block in hand.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EventRecord {
    pub tick: u64,
    pub line: u64,
    pub event: ServoEvent,
}

/// What the consumer publishes while it runs, for status reports, checkpoints, the
/// watchdog and the event logger, and the flags other threads use to steer it. The consumer
/// only stores into it (relaxed atomics, a seqlock for the [`Snapshot`]); it never waits on it.
#[derive(Debug)]
pub struct Published {
    /// Servo events with their tick, drained by a normal-priority thread.
    pub events: ArrayQueue<EventRecord>,
    /// Events that found the queue full (the logger fell behind).
    pub events_dropped: CachePadded<AtomicU64>,
    /// Ticks executed so far: the watchdog's proof of progress.
    pub ticks: CachePadded<AtomicU64>,
    pub overruns: CachePadded<AtomicU64>,
    /// Real time only: wake-up latency so far (ns): sum, samples and maximum.
    pub latency_sum_ns: AtomicU64,
    pub latency_samples: AtomicU64,
    pub latency_max_ns: AtomicU64,
    /// Real time only: wake-up latency per bucket of [`LATENCY_BUCKETS_US`] (the last:
    /// above them all), for a Prometheus histogram.
    pub latency_buckets: [AtomicU64; LATENCY_BUCKETS_US.len() + 1],
    /// Ticks by the gap state the input read (normal, open, short).
    pub gap_ticks: [AtomicU64; 3],
    /// The gap state read in the last tick: 1 + its [`GapState::index`], 0 before the first.
    pub gap: AtomicU8,
    /// The gap voltage the input measured in the last tick (f64 bits; NaN: the input
    /// measures none), for the console's live trace.
    pub gap_volts: AtomicU64,
    /// Times the job was held: by the operator, a programmed stop, a collision, an alarm
    /// or a wire break.
    pub holds: AtomicU64,
    snapshot: SeqLock,
    /// Loop-buffer fill, refreshed by the job's supervisor (not the consumer).
    pub buffer_unprocessed: AtomicU64,
    pub buffer_reserved: AtomicU64,
    /// Set by the supervisor: hold (brake to a standstill and stay) while set.
    pub hold: AtomicBool,
    /// Set by the supervisor: end the loop where it is (the position is kept). A controlled
    /// stop sets `hold` first and this once the snapshot says `still`.
    pub stop: AtomicBool,
    /// Set by the consumer when its loop has ended.
    pub finished: AtomicBool,
    /// Set by the consumer's loop once the output was synced at the current standstill
    /// (cleared when motion resumes): a checkpoint written now agrees with the pulse record.
    pub output_synced: AtomicBool,
    /// Source line of the move a programmed stop (`M0`/`M1`) holds before; 0 for none.
    /// Set by the consumer's loop, cleared by whoever releases the hold.
    pub paused_line: AtomicU64,
    /// Why it holds there ([`PauseKind::code`]); set and cleared with `paused_line`.
    pub paused_kind: AtomicU8,
    /// Set by the supervisor after a wire break; the consumer's loop takes it (and clears
    /// it) before the hold.
    pub rethread: RethreadRequest,
    /// Where probing moves ended, for the producer.
    pub probe: ProbeLink,
    /// A report's process trace: where the loop queues a process point every so many ticks
    /// (set before the loop starts, by a job with a recording).
    pub process: OnceLock<ProcessTap>,
    /// Set by the supervisor: the operator's feed and rapid overrides and single block.
    pub controls: ControlWord,
    /// A continuous jog's dead-man: the monotonic time (ns) by which its next renewal must
    /// come, 0 for none. The consumer's loop holds the job once it passes, whatever the
    /// control loop is doing; a renewal moves it on.
    pub dead_man_ns: AtomicU64,
    /// Set by the consumer's loop when it held the job because `dead_man_ns` passed.
    pub dead_man_tripped: AtomicBool,
}

/// Upper bounds (µs) of the wake-up latency buckets ([`Published::latency_buckets`]).
pub const LATENCY_BUCKETS_US: [u64; 13] =
    [1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000, 10000];

/// The snapshot is published every so many ticks (a power of two), besides every servo event
/// and every held tick: status and periodic checkpoints lag by that much at most.
pub const PUBLISH_EVERY_TICKS: u64 = 64;

impl Published {
    pub fn new(event_capacity: usize) -> Published {
        Published {
            events: ArrayQueue::new(event_capacity),
            events_dropped: CachePadded::new(AtomicU64::new(0)),
            ticks: CachePadded::new(AtomicU64::new(0)),
            overruns: CachePadded::new(AtomicU64::new(0)),
            latency_sum_ns: AtomicU64::new(0),
            latency_samples: AtomicU64::new(0),
            latency_max_ns: AtomicU64::new(0),
            latency_buckets: std::array::from_fn(|_| AtomicU64::new(0)),
            gap_ticks: std::array::from_fn(|_| AtomicU64::new(0)),
            gap: AtomicU8::new(0),
            gap_volts: AtomicU64::new(f64::NAN.to_bits()),
            holds: AtomicU64::new(0),
            snapshot: SeqLock::default(),
            buffer_unprocessed: AtomicU64::new(0),
            buffer_reserved: AtomicU64::new(0),
            hold: AtomicBool::new(false),
            stop: AtomicBool::new(false),
            finished: AtomicBool::new(false),
            output_synced: AtomicBool::new(false),
            paused_line: AtomicU64::new(0),
            paused_kind: AtomicU8::new(0),
            rethread: RethreadRequest::default(),
            probe: ProbeLink::default(),
            process: OnceLock::new(),
            controls: ControlWord::default(),
            dead_man_ns: AtomicU64::new(0),
            dead_man_tripped: AtomicBool::new(false),
        }
    }

    /// The latest consistent snapshot of the interpolator (a few retries at most).
    pub fn snapshot(&self) -> Snapshot {
        Snapshot::decode(&self.snapshot.read())
    }

    /// The gap state read in the last tick (none before the first).
    /// The gap voltage of the last tick, where the input measures one.
    pub fn gap_volts(&self) -> Option<f64> {
        Some(f64::from_bits(self.gap_volts.load(Ordering::Relaxed))).filter(|v| v.is_finite())
    }

    pub fn gap(&self) -> Option<GapState> {
        match self.gap.load(Ordering::Relaxed) {
            0 => None,
            code => GapState::ALL.get(usize::from(code) - 1).copied(),
        }
    }

    pub fn position(&self) -> Steps {
        self.snapshot().position
    }

    /// Publishes `fine`'s state (the consumer only).
    #[inline]
    pub fn publish(&self, tick: u64, fine: &Interpolator) {
        self.snapshot.write(&Snapshot::of(tick, fine).encode());
    }
}

/// The loop's side of a report's process trace: a point every `every_ticks` of machine time.
pub(super) struct ProcessTapper<'a> {
    tap: Option<&'a ProcessTap>,
    next: u64,
}

impl<'a> ProcessTapper<'a> {
    pub(super) fn new(published: &'a Published) -> ProcessTapper<'a> {
        ProcessTapper {
            tap: published.process.get(),
            next: 0,
        }
    }

    /// Queues the process as it stands after `tick`, when a point is due: running totals,
    /// so a point the supervisor thins away loses nothing.
    #[inline]
    pub(super) fn offer(&mut self, tick: u64, fine: &Interpolator) {
        let Some(tap) = self.tap.filter(|_| tick >= self.next) else {
            return;
        };
        let process = fine.process();
        tap.queue.push(ProcessPoint {
            tick,
            path_mm: fine.path_mm(),
            pulses: process.pulse_totals().0,
            off_time_us: process.generator().off_time_us,
            height_mm: process.adaptive().map_or(f64::NAN, |a| a.height_mm),
        });
        self.next = tick + tap.every_ticks;
    }
}
