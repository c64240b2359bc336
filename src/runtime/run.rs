//! The runner: one job through both threads, supervised from the calling thread. Every way
//! into a job ends here ([`run`]): the daemon's jobs, `edmd run`'s, the tests'.
//!
//! ```text
//!  announce ─► buffer, recorder around the output
//!  ─► producer thread (edmd-producer) ─► fine thread (FineThread::submit)
//!  ─► supervise until the fine job is done: steer a stop, drain and log events, report
//!     progress, publish the buffer's fill
//!  ─► cancel and join the producer ─► the summary and the stop point (JobEnd)
//! ```

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crossbeam::channel::{Receiver, TryRecvError};

use super::job::events;
use super::job::fine_thread::{FineDone, FineJob, FineThread, JobRecorder, ResumePoint};
use super::job::precheck::Precheck;
use super::job::producer::{self, ProducerError, ProducerReport};
use super::job::spec::JobSpec;
use super::job::summary::{self, JobSummary};
use super::shaping::program::JobProgram;
use super::shaping::progress::ProgressTracker;
use super::tick::consumer::{EventRecord, Published};
use super::{JobEnd, JobIo, PROGRESS_EVERY, ProgressFn, log_trace};
use crate::buffer::LoopBuffer;
use crate::record::{ProcessPoint, ProcessTap, Recorder, Recording, process_every_ticks};
use crate::trace::Handoff;
use crate::trace::Tracer;

/// A report's recorder samples the motion at most this often (and at every gap change).
const RECORD_EVERY_TICKS: u64 = 20;

/// How long a controlled stop lets a consumer that waits for the producer keep waiting.
const STOP_WAKE: Duration = Duration::from_millis(200);

/// One job to run: the program (a private copy), what its check found, the settings, and
/// where to start (a checkpoint's point, for a resumed job).
pub struct JobRun<'a> {
    pub program: &'a JobProgram,
    pub check: &'a Precheck,
    pub spec: &'a JobSpec,
    pub resume: Option<ResumePoint>,
}

/// Runs one job on a running [`FineThread`]: the producer on a new thread, the tick loop on
/// the fine thread, this thread supervising (logging events, turning `stop` into a
/// controlled stop). Other threads watch and steer the job through `published` (status,
/// hold). With a resume point the job starts by walking, without emitting, to it.
pub fn run(
    fine_thread: &FineThread,
    job: JobRun<'_>,
    io: JobIo,
    published: Arc<Published>,
    stop: &AtomicBool,
) -> JobEnd {
    let spec = job.spec;
    announce(&job);
    let buffer = Arc::new(
        LoopBuffer::new(spec.buffer_capacity, spec.buffer_reserved).with_trail(spec.buffer_trail),
    );
    let JobIo {
        output,
        gap,
        inputs,
        gap_inputs,
        probe_reads,
        tracer,
        recording,
        progress,
    } = io;
    let recorder = recording.is_some().then(|| recorder(&job));
    let queue = recorder
        .as_ref()
        .map(|r| (r.queue.clone(), r.process.queue.clone()));
    let mut supervisor = Supervisor {
        name: job.program.name.clone(),
        spec,
        published: &published,
        buffer: &buffer,
        stop,
        tracer: tracer.as_deref(),
        recording: recording.as_ref().zip(queue.as_ref()),
        progress,
        tracker: ProgressTracker::new(
            job.check.path_mm,
            job.check.pace.clone(),
            spec.plan.rapid_feed_mm_per_s,
        ),
        last_progress: Instant::now(),
        stop_asked: None,
    };
    let producer_cancel = Arc::new(AtomicBool::new(false));
    let (producer, done) = std::thread::scope(|s| {
        let producer = std::thread::Builder::new()
            .name("edmd-producer".to_string())
            .stack_size(crate::gcode::PARSER_STACK_BYTES)
            .spawn_scoped(s, || {
                let cancel = producer_cancel.clone();
                producer::produce(job.program, spec, &buffer, &published.probe, cancel)
            })
            .map_err(|e| {
                // No producer: the fine thread finds an empty, closed buffer and ends.
                buffer.close();
                ProducerError::Thread(e)
            });
        let result = fine_thread.submit(FineJob {
            buffer: buffer.clone(),
            published: published.clone(),
            output,
            gap,
            inputs,
            gap_inputs,
            recorder,
            probe_reads,
            conditions: spec.conditions.clone(),
            settings: spec.fine,
            loop_settings: spec.run_loop,
            resume: job.resume.clone(),
            start: spec.start_steps(),
            supervisor: std::thread::current(),
        });
        let done = supervisor.watch(&result);
        // The consumer is gone: a producer still reading has no one to read for.
        producer_cancel.store(true, Ordering::Relaxed);
        if done.is_none() {
            buffer.abort();
        }
        let producer = producer.and_then(|p| p.join().expect("the producer thread panicked"));
        (producer, done)
    });
    let Some(done) = done else {
        panic!("the fine interpolation thread panicked");
    };
    finish(&job, done, producer, &buffer, &published, tracer.as_deref())
}

/// The job's first log line: what it runs. (A feed the outputs cannot reach is the
/// configuration's warning, said once by the command: `config::max_feed_warning`.)
fn announce(job: &JobRun<'_>) {
    let spec = job.spec;
    tracing::info!(
        "{}: {} blocks; {} time, tick {}",
        job.program.name,
        job.check.blocks,
        if spec.run_loop.virtual_time {
            "virtual"
        } else {
            "real"
        },
        spec.tick
    );
}

/// A recorder for the job's output (a report, the page's executed path), sampling from where
/// the job starts.
fn recorder(job: &JobRun<'_>) -> JobRecorder {
    let start = job.resume.as_ref().map_or(job.spec.start_steps(), |r| {
        std::array::from_fn(|i| r.position.get(i).copied().unwrap_or(0))
    });
    JobRecorder {
        queue: Recorder::new(
            1 << 16,
            job.spec.run_loop.virtual_time,
            Some(std::thread::current()),
        ),
        every_ticks: RECORD_EVERY_TICKS,
        start,
        process: ProcessTap {
            queue: Handoff::new(
                256,
                job.spec.run_loop.virtual_time,
                Some(std::thread::current()),
            ),
            every_ticks: process_every_ticks(job.spec.tick),
        },
    }
}

/// The queues a report's recording is fed from: the recorder's, the process trace's.
type RecordingQueues = (Arc<Recorder>, Arc<Handoff<ProcessPoint>>);

/// The calling thread while a job runs: it logs, steers and reports, never touching the
/// real-time thread but through `Published`.
struct Supervisor<'a> {
    name: String,
    spec: &'a JobSpec,
    published: &'a Published,
    buffer: &'a LoopBuffer,
    stop: &'a AtomicBool,
    tracer: Option<&'a Tracer>,
    /// The report's recording and the queues that feed it: the recorder's and the process
    /// trace's.
    recording: Option<(&'a Arc<parking_lot::Mutex<Recording>>, &'a RecordingQueues)>,
    progress: Option<ProgressFn>,
    tracker: ProgressTracker,
    last_progress: Instant,
    /// When a stop was first seen.
    stop_asked: Option<Instant>,
}

impl Supervisor<'_> {
    /// Supervises until the fine job is done (`None`: its thread died).
    fn watch(&mut self, result: &Receiver<FineDone>) -> Option<FineDone> {
        let done = loop {
            self.steer_stop();
            self.drain();
            self.record_process(false);
            self.report_progress();
            self.publish_fill();
            match result.try_recv() {
                Ok(done) => break Some(done),
                Err(TryRecvError::Disconnected) => break None,
                Err(TryRecvError::Empty) => {}
            }
            std::thread::park_timeout(Duration::from_millis(10));
        };
        self.drain();
        self.record_process(true);
        done
    }

    /// Hands the process points the consumer's loop queued to the report's recording, and
    /// when `closing` the job's last reading (its final snapshot).
    fn record_process(&self, closing: bool) {
        if let Some((recording, (_, process))) = self.recording {
            let mut recording = recording.lock();
            process.drain(|point| recording.process_point(*point, false));
            if closing {
                let snap = self.published.snapshot();
                let point = ProcessPoint {
                    tick: snap.tick,
                    path_mm: snap.path_mm,
                    pulses: snap.pulse_totals,
                    off_time_us: snap.off_time_us,
                    height_mm: snap.height_mm,
                };
                recording.process_point(point, true);
            }
        }
    }

    /// A controlled stop: hold, and end the loop once it stands still. A consumer that
    /// waits for the producer (virtual time, the walk to a checkpoint) is told to stop
    /// waiting if it has not come to a standstill within [`STOP_WAKE`].
    fn steer_stop(&mut self) {
        if !self.stop.load(Ordering::Relaxed) {
            return;
        }
        self.published.hold.store(true, Ordering::Relaxed);
        let asked = *self.stop_asked.get_or_insert_with(Instant::now);
        if self.published.snapshot().still {
            self.published.stop.store(true, Ordering::Relaxed);
        } else if asked.elapsed() >= STOP_WAKE {
            self.buffer.interrupt();
        }
    }

    /// Logs the servo events and trace records queued so far, and hands the events to the
    /// report's recording.
    fn drain(&self) {
        let mut events: Vec<EventRecord> = Vec::new();
        while let Some(record) = self.published.events.pop() {
            events::log_event(&self.name, &record, self.spec);
            if self.recording.is_some() {
                events.push(record);
            }
        }
        if let Some((recording, (recorder, _))) = self.recording {
            events::record_batch(&mut recording.lock(), recorder, &events);
        }
        if let Some(tracer) = self.tracer {
            tracer.drain(|record| log_trace(self.spec, record));
        }
    }

    fn report_progress(&mut self) {
        if let Some(report) = self.progress.as_mut()
            && self.last_progress.elapsed() >= PROGRESS_EVERY
        {
            self.last_progress = Instant::now();
            let snap = self.published.snapshot();
            let held = self
                .published
                .hold
                .load(std::sync::atomic::Ordering::Relaxed);
            self.tracker.track(snap.path_mm, self.last_progress, held);
            report(&self.tracker, &snap);
        }
    }

    /// The buffer's fill, for the status (the consumer does not count it).
    fn publish_fill(&self) {
        let areas = self.buffer.areas();
        self.published
            .buffer_unprocessed
            .store(areas.unprocessed, Ordering::Relaxed);
        self.published
            .buffer_reserved
            .store(areas.reserved, Ordering::Relaxed);
    }
}

/// The end of a job: its summary and the point where it stands, with the devices handed
/// back.
fn finish(
    job: &JobRun<'_>,
    done: FineDone,
    producer: Result<ProducerReport, ProducerError>,
    buffer: &LoopBuffer,
    published: &Published,
    tracer: Option<&Tracer>,
) -> JobEnd {
    let FineDone {
        fine,
        report,
        finished,
        skip,
        output,
        gap,
        inputs,
    } = done;
    let (summary, stopped_at) = JobSummary::of(summary::JobFacts {
        program: job.program,
        check: job.check,
        spec: job.spec,
        resume: job.resume.as_ref(),
        fine: &fine,
        report,
        finished: &finished,
        skip: &skip,
        producer,
        buffer_high_water: buffer.areas().high_water,
        events_dropped: published.events_dropped.load(Ordering::Relaxed),
        trace_dropped: tracer.map_or(0, |t| t.dropped()),
    });
    JobEnd {
        summary,
        stopped_at,
        output,
        gap,
        inputs,
    }
}
