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

use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU64, Ordering};

use crossbeam::queue::ArrayQueue;
use crossbeam::utils::CachePadded;

use super::latency::LatencyHistogram;
use super::sys;
use crate::buffer::BlockSource;
use crate::fine::Interpolator;
use crate::gap::{GapError, GapSensor};
use crate::geometry::MAX_AXES;
use crate::output::{OutputError, PulseOutput};
use crate::servo::ServoEvent;

/// How the loop runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopSettings {
    pub tick_ns: u64,
    pub virtual_time: bool,
    /// SCHED_FIFO priority, 0 for none.
    pub rt_priority: u8,
    pub lock_memory: bool,
    pub cpu: Option<usize>,
}

impl LoopSettings {
    pub fn from_config(config: &crate::config::Config) -> LoopSettings {
        let f = &config.fine;
        LoopSettings {
            tick_ns: f.tick_us as u64 * 1000,
            virtual_time: f.virtual_time,
            rt_priority: f.rt_priority,
            lock_memory: f.lock_memory,
            cpu: f.cpu,
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

/// What the consumer publishes while it runs, for status reports and the event logger.
#[derive(Debug)]
pub struct Published {
    /// Servo events with their tick, drained by a normal-priority thread.
    pub events: ArrayQueue<EventRecord>,
    /// Events that found the queue full (the logger fell behind).
    pub events_dropped: CachePadded<AtomicU64>,
    pub ticks: CachePadded<AtomicU64>,
    pub overruns: CachePadded<AtomicU64>,
    pub position: [AtomicI64; MAX_AXES],
    /// Set by the supervisor: stop the loop where it is (the position is kept).
    pub stop: AtomicBool,
    /// Set by the consumer when its loop has ended.
    pub finished: AtomicBool,
}

impl Published {
    pub fn new(event_capacity: usize) -> Published {
        Published {
            events: ArrayQueue::new(event_capacity),
            events_dropped: CachePadded::new(AtomicU64::new(0)),
            ticks: CachePadded::new(AtomicU64::new(0)),
            overruns: CachePadded::new(AtomicU64::new(0)),
            position: std::array::from_fn(|_| AtomicI64::new(0)),
            stop: AtomicBool::new(false),
            finished: AtomicBool::new(false),
        }
    }

    pub fn position(&self) -> [i64; MAX_AXES] {
        std::array::from_fn(|i| self.position[i].load(Ordering::Relaxed))
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
    /// The gap input failed; the loop stopped before that tick moved anything.
    pub gap_error: Option<GapError>,
    /// The supervisor asked the loop to stop.
    pub stopped: bool,
    /// Real-time features the system refused, with the reason.
    pub rt_refused: Vec<String>,
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
/// request. Call from the consumer thread; applies the real-time settings to it.
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
    let realtime = apply_realtime(settings);
    let mut latency = (!settings.virtual_time).then(LatencyHistogram::default);
    let mut report = LoopReport {
        ticks: 0,
        latency: None,
        overruns: 0,
        missed_deadlines: 0,
        wall_ns: 0,
        output_error: None,
        untaken: None,
        gap_error: None,
        stopped: false,
        rt_refused: realtime.refused.clone(),
    };
    let started = sys::monotonic_ns();
    let period = settings.tick_ns;
    let mut deadline = started + period;
    let mut tick_no: u64 = 0;
    loop {
        if let Some(histogram) = latency.as_mut() {
            sys::sleep_until_ns(deadline);
            let woke = sys::monotonic_ns();
            histogram.record(woke.saturating_sub(deadline));
        }
        let gap = match sensor.sample(tick_no) {
            Ok(gap) => gap,
            Err(e) => {
                report.gap_error = Some(e);
                break;
            }
        };
        let tick = fine.tick(gap, source);
        if let Err(e) = output.write(tick_no, &tick.steps, gap) {
            if !e.step_taken() && tick.moved() {
                report.untaken = Some((tick.steps, tick.dir));
            }
            report.output_error = Some(e);
            tick_no += 1;
            break;
        }
        sensor.observe(&tick.steps, tick.dir);
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
        if tick.moved() {
            for (i, p) in fine.position().iter().enumerate() {
                published.position[i].store(*p, Ordering::Relaxed);
            }
        }
        tick_no += 1;
        if tick_no & 0x3ff == 0 {
            published.ticks.store(tick_no, Ordering::Relaxed);
        }
        if fine.state().is_final() {
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
    published.finished.store(true, Ordering::Release);
    report
}
