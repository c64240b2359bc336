//! The consumer thread's loop: the clock around the tick core.
//!
//! ```text
//! real time:    deadline += period ─► clock_nanosleep(ABSTIME) ─► latency = now − deadline
//!               ─► gap = machine.sample_gap(tick) ─► fine.tick(gap) ─► machine.emit(steps)
//!               ─► late for the next deadline? count an overrun, skip the missed deadlines
//! virtual time: the same without the clock; waiting for the producer stops time
//! ```
//!
//! The loop is the only part of the consumer that reads the clock or touches the hardware.
//! Nothing in it allocates or logs once the loop has started: servo events go into a
//! lock-free bounded queue that a normal-priority thread drains and logs, counters are
//! published through atomics. Real-time scheduling (`SCHED_FIFO`, `mlockall`, CPU pinning)
//! is requested before the loop starts; each refusal is logged as a warning and the loop
//! runs without it.
//!
//! **Overruns.** When a tick's work ends after the next deadline, the missed deadlines are
//! skipped rather than caught up: catching up would fire several ticks back to back, a burst
//! of steps faster than the planned speed. Motion simply pauses for the missed periods.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering, fence};

use crossbeam::queue::ArrayQueue;
use crossbeam::utils::CachePadded;

use super::histogram::LatencyHistogram;
use crate::buffer::{BlockSource, StepBlock};
use crate::fine::Interpolator;
use crate::gap::{GapError, GapSensor};
use crate::geometry::MAX_AXES;
use crate::output::{Activity, OutputError, PulseOutput};
use crate::servo::{PathPoint, ServoCounters, ServoEvent, ServoState};
use crate::sys;

/// How the loop runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopSettings {
    pub tick_ns: u64,
    pub virtual_time: bool,
    /// SCHED_FIFO priority, 0 for none.
    pub rt_priority: u8,
    pub lock_memory: bool,
    pub cpu: Option<usize>,
    /// There is an operator (the daemon): a programmed stop (`M0`/`M1`) sets
    /// `Published::hold` (and `paused_line`), a collision or an alarm holds the job, all until
    /// released. Without one (`edmd run`) stops pass and collisions and alarms end the loop.
    pub program_pauses: bool,
}

impl LoopSettings {
    pub fn from_config(config: &crate::config::Config) -> LoopSettings {
        let f = &config.fine;
        LoopSettings {
            tick_ns: f.tick.ns(),
            virtual_time: f.virtual_time,
            rt_priority: f.rt_priority,
            lock_memory: f.lock_memory,
            cpu: f.cpu,
            program_pauses: false,
        }
    }
}

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
}

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
            snapshot: SeqLock::default(),
            buffer_unprocessed: AtomicU64::new(0),
            buffer_reserved: AtomicU64::new(0),
            hold: AtomicBool::new(false),
            stop: AtomicBool::new(false),
            finished: AtomicBool::new(false),
            output_synced: AtomicBool::new(false),
            paused_line: AtomicU64::new(0),
        }
    }

    /// The latest consistent snapshot of the interpolator (a few retries at most).
    pub fn snapshot(&self) -> Snapshot {
        Snapshot::decode(&self.snapshot.read())
    }

    pub fn position(&self) -> [i64; MAX_AXES] {
        self.snapshot().position
    }

    /// Publishes `fine`'s state (the consumer only).
    #[inline]
    pub fn publish(&self, tick: u64, fine: &Interpolator) {
        self.snapshot.write(&Snapshot::of(tick, fine).encode());
    }
}

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
    pub position: [i64; MAX_AXES],
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
        }
    }
}

const WORDS: usize = 2 + MAX_AXES + 6 + 6 + MAX_AXES + 1;
const STATES: [ServoState; 6] = [
    ServoState::Forward,
    ServoState::Hold,
    ServoState::TurnBack,
    ServoState::ReAdvance,
    ServoState::Alarm,
    ServoState::Done,
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
        }
    }

    fn encode(&self) -> [u64; WORDS] {
        let mut w = [0u64; WORDS];
        let state = STATES.iter().position(|s| *s == self.state).unwrap_or(1) as u64;
        w[0] = self.tick;
        w[1] = state | (self.held as u64) << 8 | (self.still as u64) << 9;
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
        w[WORDS - 1] = self.path_mm.to_bits();
        w
    }

    fn decode(w: &[u64; WORDS]) -> Snapshot {
        let m = 2 + MAX_AXES;
        Snapshot {
            tick: w[0],
            state: STATES[(w[1] & 0xff) as usize % STATES.len()],
            held: w[1] & 1 << 8 != 0,
            still: w[1] & 1 << 9 != 0,
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
            },
            pulses: std::array::from_fn(|i| w[m + 12 + i]),
            path_mm: f64::from_bits(w[WORDS - 1]),
        }
    }
}

/// A single-writer sequence lock over a few words: the writer never waits, a reader retries
/// while a write is in progress or happened under it.
#[derive(Debug)]
struct SeqLock {
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
    fn write(&self, data: &[u64; WORDS]) {
        let v = self.version.load(Ordering::Relaxed);
        self.version.store(v.wrapping_add(1), Ordering::Relaxed);
        fence(Ordering::Release);
        for (slot, &d) in self.words.iter().zip(data) {
            slot.store(d, Ordering::Relaxed);
        }
        self.version.store(v.wrapping_add(2), Ordering::Release);
    }

    fn read(&self) -> [u64; WORDS] {
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

/// What the loop measured.
#[derive(Debug)]
pub struct LoopReport {
    /// Ticks executed.
    pub ticks: u64,
    /// Real time only: wake-up latency of every tick.
    pub latency: Option<LatencyHistogram>,
    /// Ticks whose work ended after the next deadline.
    pub overruns: u64,
    /// Deadlines skipped to resynchronise after overruns.
    pub missed_deadlines: u64,
    pub wall_ns: u64,
    /// The output failed; the loop stopped at once.
    pub output_error: Option<OutputError>,
    /// The failed write's tick did not reach the drives: its steps and event direction, to
    /// take back out of the interpolator's ledger.
    pub untaken: Option<([i8; MAX_AXES], i8)>,
    /// With `untaken`: where along the program the electrode was before that tick (segment
    /// and step, and the segment's step count), the checkpoint's point to go with the ledger.
    pub untaken_from: Option<(PathPoint, i64)>,
    /// The gap input failed; the loop stopped before that tick moved anything.
    pub gap_error: Option<GapError>,
    /// The supervisor asked the loop to stop.
    pub stopped: bool,
    /// A collision during a rapid ended a job without an operator: where, and the line.
    pub collision: Option<(PathPoint, u64)>,
    /// Real-time features the system refused, with the reason.
    pub rt_refused: Vec<String>,
}

impl LoopReport {
    /// The report of a loop that never ran.
    pub fn empty() -> LoopReport {
        LoopReport {
            ticks: 0,
            latency: None,
            overruns: 0,
            missed_deadlines: 0,
            wall_ns: 0,
            output_error: None,
            untaken: None,
            untaken_from: None,
            gap_error: None,
            stopped: false,
            collision: None,
            rt_refused: Vec::new(),
        }
    }
}

/// Real-time features in force for the loop; dropping it releases them.
#[derive(Debug, Default)]
pub struct RealtimeGuard {
    /// Holds the zero wake-up latency request while open.
    _cpu_latency: Option<std::fs::File>,
    /// What the system refused, as operator-facing reasons.
    pub refused: Vec<String>,
}

/// Applies the configured real-time features to the calling thread; refusals come back as
/// human-readable reasons (and are logged as warnings), never as errors. In real time the
/// timer slack is always minimised and, with `lock_memory`, CPUs are kept out of deep idle
/// states (`/dev/cpu_dma_latency`, as cyclictest does).
pub fn apply_realtime(settings: &LoopSettings) -> RealtimeGuard {
    let mut guard = RealtimeGuard::default();
    if settings.virtual_time {
        return guard;
    }
    let refused = &mut guard.refused;
    if let Err(e) = sys::minimise_timer_slack() {
        refused.push(format!(
            "timer slack: cannot minimise it ({e}); wake-ups may come up to 50 µs late"
        ));
    }
    if settings.lock_memory {
        if let Err(e) = sys::lock_all_memory() {
            refused.push(format!(
                "fine.lock_memory: mlockall refused ({e}); running with pageable memory \
                 (raise RLIMIT_MEMLOCK, e.g. systemd LimitMEMLOCK=infinity)"
            ));
        }
        match sys::hold_zero_cpu_wakeup_latency() {
            Ok(file) => guard._cpu_latency = Some(file),
            Err(e) => refused.push(format!(
                "fine.lock_memory: cannot hold /dev/cpu_dma_latency at 0 ({e}); CPUs may sleep \
                 in deep idle states between ticks"
            )),
        }
    }
    if let Some(cpu) = settings.cpu
        && let Err(e) = sys::pin_to_cpu(cpu)
    {
        refused.push(format!(
            "fine.cpu: cannot pin to CPU {cpu} ({e}); running on any CPU"
        ));
    }
    if settings.rt_priority > 0
        && let Err(e) = sys::set_fifo_priority(settings.rt_priority)
    {
        refused.push(format!(
            "fine.rt_priority: SCHED_FIFO {} refused ({e}); running at normal priority \
             (needs CAP_SYS_NICE or RLIMIT_RTPRIO, e.g. systemd LimitRTPRIO={})",
            settings.rt_priority, settings.rt_priority
        ));
    }
    for reason in &guard.refused {
        tracing::warn!("{reason}");
    }
    guard
}

/// Runs the tick core until the program is done, an alarm, an output error or a stop
/// request. Call from the consumer thread after [`apply_realtime`].
pub fn run_loop<S, O, G>(
    fine: &mut Interpolator,
    source: &mut S,
    output: &mut O,
    sensor: &mut G,
    settings: &LoopSettings,
    published: &Published,
) -> LoopReport
where
    S: BlockSource + ?Sized,
    O: PulseOutput + ?Sized,
    G: GapSensor + ?Sized,
{
    let mut latency = (!settings.virtual_time).then(LatencyHistogram::default);
    let mut report = LoopReport::empty();
    let started = sys::monotonic_ns();
    let period = settings.tick_ns;
    let mut deadline = started + period;
    let mut tick_no: u64 = 0;
    // What the machine is doing, as the output was last told.
    let mut activity = Activity::default();
    loop {
        if let Some(histogram) = latency.as_mut() {
            sys::sleep_until_ns(deadline);
            let woke = sys::monotonic_ns();
            let late = woke.saturating_sub(deadline);
            histogram.record(late);
            published.latency_sum_ns.fetch_add(late, Ordering::Relaxed);
            published.latency_samples.fetch_add(1, Ordering::Relaxed);
            published.latency_max_ns.fetch_max(late, Ordering::Relaxed);
        } else if fine.held() && fine.still() {
            // Held in virtual time: nothing can change but the operator's mind, so let the
            // CPU go rather than spin through ticks.
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        fine.set_hold(published.hold.load(Ordering::Relaxed));
        let gap = match sensor.sample(tick_no) {
            Ok(gap) => gap,
            Err(e) => {
                report.gap_error = Some(e);
                break;
            }
        };
        // Where the electrode stands before this tick (two words): if the output refuses the
        // tick's step, this is the point that goes with the ledger the drives received.
        let before = fine.here();
        let tick = fine.tick_measured(gap, sensor.volts(), sensor.ratios(), source);
        let block = fine.block();
        let flags = block.map_or(0, |b| b.flags);
        let now = Activity {
            flags,
            spark: block.is_some_and(|b| b.flags & StepBlock::RAPID == 0)
                && !fine.held()
                && !fine.state().is_final(),
            condition: block.map_or(activity.condition, |b| b.condition),
        };
        if now != activity {
            let tell = |event| {
                let record = EventRecord {
                    tick: tick_no,
                    line: fine.line(),
                    event,
                };
                if published.events.push(record).is_err() {
                    published.events_dropped.fetch_add(1, Ordering::Relaxed);
                }
            };
            if (flags ^ activity.flags) & StepBlock::FLUSH != 0 {
                tell(ServoEvent::Flushing {
                    on: flags & StepBlock::FLUSH != 0,
                });
            }
            if now.condition != activity.condition {
                tell(ServoEvent::Condition {
                    number: now.condition,
                });
            }
            if flags != activity.flags {
                sensor.moving_in(flags);
            }
            activity = now;
            output.moving_in(now);
        }
        if let Err(e) = output.write(tick_no, &tick.steps, gap) {
            if !e.step_taken() && tick.moved() {
                report.untaken = Some((tick.steps, tick.dir));
                // A tick takes at most one step event: if it finished the segment, that
                // segment had one event more than the point before it.
                let events = match fine.block() {
                    Some(b) if b.seq == before.seq => b.events() as i64,
                    _ => before.event + 1,
                };
                report.untaken_from = Some((before, events));
            }
            report.output_error = Some(e);
            tick_no += 1;
            break;
        }
        sensor.observe(&tick.steps, tick.dir);
        match tick.event {
            Some(ServoEvent::Paused { .. }) if settings.program_pauses => {
                published.paused_line.store(fine.line(), Ordering::Relaxed);
                published.hold.store(true, Ordering::Relaxed);
            }
            // A collision or an alarm holds a job that has an operator; otherwise it ends it.
            Some(ServoEvent::Collision { .. } | ServoEvent::Alarm { .. })
                if settings.program_pauses =>
            {
                published.hold.store(true, Ordering::Relaxed);
            }
            Some(ServoEvent::Collision { at }) => report.collision = Some((at, fine.line())),
            _ => {}
        }
        if let Some(event) = tick.event
            && published
                .events
                .push(EventRecord {
                    tick: tick_no,
                    line: fine.line(),
                    event,
                })
                .is_err()
        {
            published.events_dropped.fetch_add(1, Ordering::Relaxed);
        }
        tick_no += 1;
        // Every servo event and every held tick (a controlled stop waits for `still`);
        // otherwise every 64 ticks (3.2 ms at 50 µs): status and periodic checkpoints lag by
        // that much at most, and the ticks that publish nothing stay as cheap as before.
        if tick.event.is_some() || fine.held() || tick_no & 0x3f == 0 {
            published.publish(tick_no, fine);
            published.ticks.store(tick_no, Ordering::Relaxed);
        }
        // At a held standstill the output's record is made durable once, before the
        // supervisor writes its checkpoint (it waits for `output_synced`). Nothing moves
        // here, so the time a disk takes costs no step; the next deadline starts afresh.
        let standstill = fine.held() && fine.still();
        if standstill && !published.output_synced.load(Ordering::Relaxed) {
            if let Err(e) = output.sync() {
                report.output_error = Some(e);
                break;
            }
            published.output_synced.store(true, Ordering::Release);
            deadline = sys::monotonic_ns();
        } else if !standstill && published.output_synced.load(Ordering::Relaxed) {
            published.output_synced.store(false, Ordering::Relaxed);
        }
        let state = fine.state();
        let alarm_held = state == ServoState::Alarm && settings.program_pauses;
        if (state.is_final() && !alarm_held) || report.collision.is_some() {
            break;
        }
        if published.stop.load(Ordering::Relaxed) {
            report.stopped = true;
            break;
        }
        if latency.is_some() {
            deadline += period;
            let now = sys::monotonic_ns();
            if now > deadline {
                report.overruns += 1;
                published.overruns.fetch_add(1, Ordering::Relaxed);
                let missed = (now - deadline) / period + 1;
                report.missed_deadlines += missed;
                deadline += missed * period;
            }
        }
    }
    report.ticks = tick_no;
    report.wall_ns = sys::monotonic_ns() - started;
    report.latency = latency;
    published.ticks.store(tick_no, Ordering::Relaxed);
    published.publish(tick_no, fine);
    published.finished.store(true, Ordering::Release);
    report
}
