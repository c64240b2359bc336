//! The tracer (`output.trace`, `gap.trace`): every change of an output's or a gap input's
//! state, logged, around any output or gap source.
//!
//! ```text
//!  consumer thread loop                              normal-priority thread
//!  TracedGap(sensor) ── gap normal → short ──┐
//!                                            ├─► Tracer queue (lock-free, bounded) ─► log
//!  TracedOutput(out) ── X direction − ───────┘
//! ```
//!
//! The wrappers sit in the real-time loop, so they never log themselves: they push a small
//! record into a bounded lock-free queue that the supervisor drains and logs (target
//! `edmd::trace`). In real time a full queue drops the record and counts it: the tick must
//! not wait for a logger. In virtual time nothing is lost: the loop yields until the logger
//! has made room, which only slows a simulation.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::thread::Thread;

use crossbeam::queue::ArrayQueue;

use crate::gap::{GapError, GapSensor, GapState};
use crate::output::{OutputError, PulseOutput};
use crate::vocab::MAX_AXES;

/// A change of state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TraceEvent {
    /// The gap input changed state (`from` is `None` for the first reading).
    Gap {
        from: Option<GapState>,
        to: GapState,
    },
    /// An axis stepped in a new direction (its first step included).
    Direction { axis: u8, positive: bool },
    /// The output refused a write.
    WriteFailed,
}

/// A change with the tick it happened in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TraceRecord {
    pub tick: u64,
    pub event: TraceEvent,
}

/// A bounded lock-free hand-off from the real-time loop to a normal-priority thread: the
/// tracer's queue, and the recorder's (`crate::record`).
#[derive(Debug)]
pub struct Handoff<T> {
    queue: ArrayQueue<T>,
    dropped: AtomicU64,
    lossless: bool,
    /// The draining thread, woken when a lossless queue is full.
    drainer: Option<Thread>,
}

/// The queue between the traced wrappers and the thread that logs.
pub type Tracer = Handoff<TraceRecord>;

impl<T> Handoff<T> {
    /// `lossless`: wait for room instead of dropping (virtual time only). `drainer` is the
    /// thread that calls [`drain`](Self::drain).
    pub fn new(capacity: usize, lossless: bool, drainer: Option<Thread>) -> Arc<Handoff<T>> {
        Arc::new(Handoff {
            queue: ArrayQueue::new(capacity.max(1)),
            dropped: AtomicU64::new(0),
            lossless,
            drainer,
        })
    }

    /// Queues `record`; never allocates. Lossless: yields until there is room; otherwise a
    /// full queue drops it and counts it.
    pub fn push(&self, mut record: T) {
        loop {
            match self.queue.push(record) {
                Ok(()) => return,
                Err(back) if self.lossless => {
                    if let Some(thread) = &self.drainer {
                        thread.unpark();
                    }
                    std::thread::yield_now();
                    record = back;
                }
                Err(_) => {
                    self.dropped.fetch_add(1, Ordering::Relaxed);
                    return;
                }
            }
        }
    }

    /// Hands every queued record to `f`, oldest first.
    pub fn drain(&self, mut f: impl FnMut(&T)) {
        while let Some(record) = self.queue.pop() {
            f(&record);
        }
    }

    /// Records dropped because the queue was full (real time only).
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

impl Tracer {
    pub fn record(&self, tick: u64, event: TraceEvent) {
        self.push(TraceRecord { tick, event });
    }
}

/// Traces an output: direction changes per axis and failed writes.
#[derive(Debug)]
pub struct TracedOutput<O> {
    inner: O,
    tracer: Arc<Tracer>,
    dir: [i8; MAX_AXES],
}

impl<O> TracedOutput<O> {
    pub fn new(inner: O, tracer: Arc<Tracer>) -> TracedOutput<O> {
        TracedOutput {
            inner,
            tracer,
            dir: [0; MAX_AXES],
        }
    }
}

impl<O: PulseOutput> PulseOutput for TracedOutput<O> {
    fn write(
        &mut self,
        tick: u64,
        steps: &[i8; MAX_AXES],
        gap: GapState,
    ) -> Result<(), OutputError> {
        let result = self.inner.write(tick, steps, gap);
        if result.is_err() {
            self.tracer.record(tick, TraceEvent::WriteFailed);
            return result;
        }
        for (axis, (&s, dir)) in steps.iter().zip(self.dir.iter_mut()).enumerate() {
            if s != 0 && s != *dir {
                *dir = s;
                self.tracer.record(
                    tick,
                    TraceEvent::Direction {
                        axis: axis as u8,
                        positive: s > 0,
                    },
                );
            }
        }
        result
    }

    fn finish(&mut self, why: crate::output::StopReason) -> Result<(), OutputError> {
        self.inner.finish(why)
    }

    fn idle(&mut self, elapsed_ns: u64) -> Result<(), OutputError> {
        self.inner.idle(elapsed_ns)
    }

    fn prepare(&mut self) {
        self.inner.prepare()
    }

    fn sync(&mut self) -> Result<(), OutputError> {
        self.inner.sync()
    }

    fn moving_in(&mut self, now: crate::output::Activity) {
        self.inner.moving_in(now)
    }

    fn set_points(&mut self, condition: u16, set: &crate::vocab::GeneratorSetPoints) {
        self.inner.set_points(condition, set)
    }
}

/// Traces a gap input: every change of state.
#[derive(Debug)]
pub struct TracedGap<G> {
    inner: G,
    tracer: Arc<Tracer>,
    last: Option<GapState>,
}

impl<G> TracedGap<G> {
    pub fn new(inner: G, tracer: Arc<Tracer>) -> TracedGap<G> {
        TracedGap {
            inner,
            tracer,
            last: None,
        }
    }
}

impl<G: GapSensor> GapSensor for TracedGap<G> {
    fn sample(&mut self, tick: u64) -> Result<GapState, GapError> {
        let state = self.inner.sample(tick)?;
        if self.last != Some(state) {
            self.tracer.record(
                tick,
                TraceEvent::Gap {
                    from: self.last,
                    to: state,
                },
            );
            self.last = Some(state);
        }
        Ok(state)
    }

    fn observe(&mut self, steps: &[i8; MAX_AXES], dir: i8) {
        self.inner.observe(steps, dir)
    }

    fn moving_in(&mut self, now: crate::buffer::Activity) {
        self.inner.moving_in(now)
    }

    fn probe_reads(&mut self, what: crate::vocab::ProbeReads) {
        self.inner.probe_reads(what)
    }

    fn volts(&self) -> Option<f64> {
        self.inner.volts()
    }

    fn ratios(&self) -> Option<(f64, f64)> {
        self.inner.ratios()
    }

    fn pulses(&self) -> Option<crate::vocab::PulseCounts> {
        self.inner.pulses()
    }

    fn generator(&mut self, set: &crate::vocab::GeneratorSetPoints) {
        self.inner.generator(set)
    }

    fn flushing(&self) -> Option<f64> {
        self.inner.flushing()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::ScriptGap;
    use crate::output::NullOutput;

    fn records(tracer: &Tracer) -> Vec<TraceRecord> {
        let mut out = Vec::new();
        tracer.drain(|r| out.push(*r));
        out
    }

    #[test]
    fn gap_changes_are_traced_once_each() {
        let tracer = Tracer::new(16, false, None);
        let script = ScriptGap::from_changes(vec![(2, GapState::Short), (4, GapState::Normal)]);
        let mut gap = TracedGap::new(script, tracer.clone());
        for t in 0..6 {
            gap.sample(t).unwrap();
        }
        use GapState::*;
        let events: Vec<(u64, TraceEvent)> =
            records(&tracer).iter().map(|r| (r.tick, r.event)).collect();
        assert_eq!(
            events,
            vec![
                (
                    0,
                    TraceEvent::Gap {
                        from: None,
                        to: Normal
                    }
                ),
                (
                    2,
                    TraceEvent::Gap {
                        from: Some(Normal),
                        to: Short
                    }
                ),
                (
                    4,
                    TraceEvent::Gap {
                        from: Some(Short),
                        to: Normal
                    }
                ),
            ]
        );
    }

    #[test]
    fn direction_changes_and_failures_are_traced() {
        let tracer = Tracer::new(16, false, None);
        let inner = crate::output::FaultInjector::new(NullOutput, 4);
        let mut out = TracedOutput::new(inner, tracer.clone());
        let g = GapState::Normal;
        out.write(0, &[1, 0, 0, 0, 0, 0], g).unwrap();
        out.write(1, &[1, -1, 0, 0, 0, 0], g).unwrap();
        out.write(2, &[0, -1, 0, 0, 0, 0], g).unwrap();
        out.write(3, &[-1, 0, 0, 0, 0, 0], g).unwrap();
        assert!(out.write(4, &[-1, 0, 0, 0, 0, 0], g).is_err());
        let events: Vec<(u64, TraceEvent)> =
            records(&tracer).iter().map(|r| (r.tick, r.event)).collect();
        let dir = |axis, positive| TraceEvent::Direction { axis, positive };
        assert_eq!(
            events,
            vec![
                (0, dir(0, true)),
                (1, dir(1, false)),
                (3, dir(0, false)),
                (4, TraceEvent::WriteFailed),
            ]
        );
    }

    #[test]
    fn a_full_queue_drops_in_real_time_and_waits_in_virtual_time() {
        let lossy = Tracer::new(2, false, None);
        for t in 0..5 {
            lossy.record(t, TraceEvent::WriteFailed);
        }
        assert_eq!((records(&lossy).len(), lossy.dropped()), (2, 3));

        let lossless = Tracer::new(2, true, Some(std::thread::current()));
        let writer = {
            let tracer = lossless.clone();
            std::thread::spawn(move || {
                for t in 0..1000 {
                    tracer.record(t, TraceEvent::WriteFailed);
                }
            })
        };
        let mut got = Vec::new();
        while got.len() < 1000 {
            lossless.drain(|r| got.push(r.tick));
            std::thread::park_timeout(std::time::Duration::from_millis(1));
        }
        writer.join().unwrap();
        assert_eq!(got, (0..1000).collect::<Vec<_>>());
        assert_eq!(lossless.dropped(), 0);
    }
}
