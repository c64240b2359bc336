//! The runtime: one job through the two threads (seed 000 §III.B–D).
//!
//! ```text
//!  program ─► [precheck: parse it all, exit 2 on any error, before anything moves]
//!
//!  producer thread                loop buffer                 fine thread ("edmd-fine")
//!  parse ─► preprocess ─► round ─► push ──► reserved|unprocessed|unused ──► next/previous
//!  (sleeps while full)                                         tick core ─► output, gap
//!                                                                  │ events (lock-free queue)
//!                                                                  │ snapshot (seqlock)
//!  supervisor (the caller): logs events, hold/stop flags, joins, builds the summary ◄┘
//! ```
//!
//! [`run_job`] checks the whole program first: a CNC control must not start cutting a
//! program whose line 10,000 is bad. Then the producer ([`producer`]) streams it again into
//! the loop buffer while the fine thread ([`fine_thread`], looping in [`consumer`]) runs the
//! tick core in real or virtual time. The supervisor only logs, steers through [`Published`]
//! and waits. The summary ([`JobSummary`]) is what `edmd run` prints and writes as JSON; the
//! daemon runs its jobs through [`run_job_with`] on one long-lived [`FineThread`].

pub mod consumer;
mod devices;
mod events;
pub mod fine_thread;
mod histogram;
pub mod latency;
mod precheck;
pub mod probe;
pub mod producer;
pub mod program;
pub mod progress;
mod snapshot;
mod summary;

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::buffer::LoopBuffer;
use crate::config::Config;
use crate::fine::FineSettings;
use crate::gap::ScriptError;
use crate::gcode::GcodeError;
use crate::output::OutputError;
use crate::parport::ParportError;
use crate::record::{RecordedOutput, Recorder, Recording};
use crate::trace::{TraceEvent, TraceRecord, Tracer};
use crate::vocab::MAX_AXES;
use crate::vocab::TickPeriod;

pub use consumer::{EventRecord, LoopReport, LoopSettings, Published, Snapshot};
pub use devices::{BoxedGap, BoxedOutput, fine_speed_cap, open_gap, open_io, open_output, wrap_io};
pub use fine_thread::{FineDone, FineJob, FineThread, ResumePoint};
pub use histogram::{LatencyHistogram, LatencySummary};
pub use precheck::{Precheck, precheck};
pub use producer::{BlockMaker, ProducerError, ProducerReport, to_steps};
pub use program::{JobProgram, Progress, TempCopy};
pub use progress::ProgressTracker;
pub use summary::{JobSummary, LastProbe, Outcome, StopPoint, axis_list};

/// A job that could not start: bad program, gap script or output. Nothing has moved.
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    #[error(transparent)]
    Program(#[from] GcodeError),
    #[error(transparent)]
    Producer(#[from] ProducerError),
    #[error(transparent)]
    GapScript(#[from] ScriptError),
    #[error(transparent)]
    Iio(#[from] crate::gap::IioError),
    #[error(transparent)]
    Output(#[from] OutputError),
    #[error(transparent)]
    Parport(#[from] ParportError),
    #[error("cannot start the fine interpolation thread: {0}")]
    Thread(std::io::Error),
    /// A combination of settings that cannot run (the validated configuration refuses it).
    #[error("{0}")]
    Config(String),
    #[error(transparent)]
    Copy(#[from] program::CopyError),
    #[error("{program}: the check was cancelled")]
    Cancelled { program: String },
}

/// Logs one trace record (from the main thread).
fn log_trace(config: &Config, record: &TraceRecord, tick: TickPeriod) {
    let t = tick.ticks_to_secs(record.tick);
    let tick_no = record.tick;
    match record.event {
        TraceEvent::Gap { from, to } => tracing::info!(
            target: "edmd::trace",
            "t={t:.5} s (tick {tick_no}): gap {} -> {}",
            from.map_or("(first reading)", |f| f.name()),
            to.name()
        ),
        TraceEvent::Direction { axis, positive } => tracing::info!(
            target: "edmd::trace",
            "t={t:.5} s (tick {tick_no}): axis {} now steps {}",
            config.machine.axes[axis as usize].letter(),
            if positive { "+" } else { "-" }
        ),
        TraceEvent::WriteFailed => tracing::info!(
            target: "edmd::trace",
            "t={t:.5} s (tick {tick_no}): output write failed"
        ),
    }
}

/// A report's recorder samples the motion at most this often (and at every gap change).
const RECORD_EVERY_TICKS: u64 = 20;

/// How long a controlled stop lets a consumer that waits for the producer keep waiting.
const STOP_WAKE: Duration = Duration::from_millis(200);

/// Runs `program` through both threads with the output and gap source of `config`.
pub fn run_job(program: &Path, config: &Config) -> Result<JobSummary, JobError> {
    run_job_until(
        program,
        config,
        &AtomicBool::new(false),
        Observers::default(),
    )
}

/// Who watches a job besides its log: a progress callback, a recording for a report.
#[derive(Default)]
pub struct Observers {
    pub progress: Option<ProgressFn>,
    pub recording: Option<Arc<parking_lot::Mutex<Recording>>>,
}

/// [`run_job`], stopping where it is (position kept, outputs inactive) once `stop` is set,
/// e.g. by a signal handler; `observers.progress` hears how far the job has come every
/// [`PROGRESS_EVERY`], `observers.recording` gathers what ran.
pub fn run_job_until(
    program: &Path,
    config: &Config,
    stop: &AtomicBool,
    observers: Observers,
) -> Result<JobSummary, JobError> {
    let (copy, check) = copy_and_check(program, config, stop)?;
    let program = &copy.0;
    let tracer = (config.output.trace || config.gap.trace)
        .then(|| Tracer::new(4096, config.fine.virtual_time, Some(std::thread::current())));
    let (output, gap) = open_io(config, &check, tracer.as_ref())?;
    let io = JobIo {
        output,
        gap,
        tracer,
        recording: observers.recording,
        progress: observers.progress,
        program_pauses: false,
    };
    run_job_io(program, config, &check, io, Some(stop))
}

/// How often a job's supervisor reports progress.
pub const PROGRESS_EVERY: Duration = Duration::from_millis(250);

/// Hears a job's progress (on the supervising thread): the tracker and the latest snapshot.
pub type ProgressFn = Box<dyn FnMut(&ProgressTracker, &Snapshot) + Send>;

/// Copies `program` to a private temporary copy and checks the copy (on a thread of their
/// own, so `stop` cancels them within a poll period however large the file).
pub fn copy_and_check(
    program: &Path,
    config: &Config,
    stop: &AtomicBool,
) -> Result<(TempCopy, Precheck), JobError> {
    let progress = Progress::new();
    std::thread::scope(|s| {
        let work = std::thread::Builder::new()
            .name("edmd-check".to_string())
            .stack_size(crate::gcode::PARSER_STACK_BYTES)
            .spawn_scoped(s, || {
                let copy = TempCopy::new_with(program, &progress)?;
                let check = precheck(&copy.0, config, &progress)?;
                Ok((copy, check))
            })
            .map_err(JobError::Thread)?;
        while !work.is_finished() {
            if stop.load(Ordering::Relaxed) {
                progress.cancel();
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        work.join().expect("the program check panicked")
    })
}

/// Runs `program` (already checked: `check`) through both threads with the given output and
/// gap source; `tracer` is drained and logged while the job runs; once `stop` is set the job
/// brakes to a standstill and ends there (position kept).
pub fn run_job_on(
    program: &JobProgram,
    config: &Config,
    check: &Precheck,
    output: BoxedOutput,
    gap: BoxedGap,
    tracer: Option<Arc<Tracer>>,
    stop: Option<&AtomicBool>,
) -> Result<JobSummary, JobError> {
    let io = JobIo {
        output,
        gap,
        tracer,
        recording: None,
        progress: None,
        program_pauses: false,
    };
    run_job_io(program, config, check, io, stop)
}

fn run_job_io(
    program: &JobProgram,
    config: &Config,
    check: &Precheck,
    io: JobIo,
    stop: Option<&AtomicBool>,
) -> Result<JobSummary, JobError> {
    let fine_thread =
        FineThread::start(&LoopSettings::from_config(config)).map_err(JobError::Thread)?;
    let never = AtomicBool::new(false);
    let end = run_job_with(
        &fine_thread,
        program,
        config,
        check,
        io,
        Arc::new(Published::new(4096)),
        stop.unwrap_or(&never),
        None,
    );
    Ok(end.summary)
}

/// What a job runs on besides the program.
pub struct JobIo {
    pub output: BoxedOutput,
    pub gap: BoxedGap,
    pub tracer: Option<Arc<Tracer>>,
    /// What actually ran, for a report (`edmd run --report`): the output is wrapped in a
    /// [`RecordedOutput`] and the supervisor fills the recording.
    pub recording: Option<Arc<parking_lot::Mutex<Recording>>>,
    /// Hears the job's progress (`edmd run`'s bar or log line); the daemon reads `Published`.
    pub progress: Option<ProgressFn>,
    /// `M0`/`M1` hold the job until the operator resumes it (the daemon); otherwise (`edmd
    /// run`, which has no operator channel) they are logged and the job goes on.
    pub program_pauses: bool,
}

/// A finished job: the summary, where the electrode stands, and the output and gap source
/// handed back (a daemon keeps its parallel port claimed across jobs).
pub struct JobEnd {
    pub summary: JobSummary,
    /// The interpolator at the end: the checkpoint's point and ledger.
    pub stopped_at: Snapshot,
    pub output: BoxedOutput,
    pub gap: BoxedGap,
}

/// One job on a running [`FineThread`]: the producer on a new thread, the tick loop on the
/// fine thread, this thread supervising (logging events, turning `stop` into a controlled
/// stop). Other threads watch and steer the job through `published` (status, hold). With
/// `resume`, the job starts by walking, without emitting, to that point of the program.
#[allow(clippy::too_many_arguments)]
pub fn run_job_with(
    fine_thread: &FineThread,
    program: &JobProgram,
    config: &Config,
    check: &Precheck,
    io: JobIo,
    published: Arc<Published>,
    stop: &AtomicBool,
    resume: Option<ResumePoint>,
) -> JobEnd {
    let name = program.name.clone();
    let cap = fine_speed_cap(config);
    if config.machine.max_feed_mm_per_min / 60.0 > cap {
        tracing::info!(
            "fine.tick_us = {} allows at most one step per axis per tick: path speeds above \
             about {:.0} mm/min (machine.max_feed_mm_per_min = {}) are not reachable",
            config.fine.tick.us(),
            cap * 60.0,
            config.machine.max_feed_mm_per_min
        );
    }
    tracing::info!(
        "{name}: {} blocks; {} time, tick {}",
        check.blocks,
        if config.fine.virtual_time {
            "virtual"
        } else {
            "real"
        },
        config.fine.tick
    );
    let buffer = Arc::new(LoopBuffer::new(
        config.buffer.capacity,
        config.buffer.reserved,
    ));
    let mut loop_settings = LoopSettings::from_config(config);
    let tick = config.fine.tick;
    let JobIo {
        mut output,
        gap,
        tracer,
        recording,
        mut progress,
        program_pauses,
    } = io;
    loop_settings.program_pauses = program_pauses;
    let mut recorder = None;
    if recording.is_some() {
        let queue = Recorder::new(
            1 << 16,
            config.fine.virtual_time,
            Some(std::thread::current()),
        );
        let start = resume.as_ref().map_or([0; MAX_AXES], |r| {
            std::array::from_fn(|i| r.position.get(i).copied().unwrap_or(0))
        });
        output = Box::new(RecordedOutput::new(
            output,
            queue.clone(),
            RECORD_EVERY_TICKS,
            start,
        ));
        recorder = Some(queue);
    }
    let mut tracker = ProgressTracker::with_rapids(
        check.path_mm,
        check.rapid_spans.clone(),
        crate::preprocess::PlanSettings::from_config(config).rapid_feed,
    );
    let mut last_progress = Instant::now();

    let producer_cancel = Arc::new(AtomicBool::new(false));
    let (producer, done) = std::thread::scope(|s| {
        let producer = std::thread::Builder::new()
            .name("edmd-producer".to_string())
            .stack_size(crate::gcode::PARSER_STACK_BYTES)
            .spawn_scoped(s, || {
                let cancel = producer_cancel.clone();
                producer::produce(program, config, &buffer, &published.probe, cancel)
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
            settings: FineSettings::from_config(config),
            loop_settings,
            resume: resume.clone(),
            supervisor: std::thread::current(),
        });
        let drain = || {
            let mut events = Vec::new();
            while let Some(record) = published.events.pop() {
                events::log_event(&name, &record, config, program_pauses);
                if recording.is_some() {
                    events.push(record);
                }
            }
            if let (Some(recording), Some(recorder)) = (&recording, &recorder) {
                events::record_batch(&mut recording.lock(), recorder, &events);
            }
            if let Some(tracer) = &tracer {
                tracer.drain(|record| log_trace(config, record, tick));
            }
        };
        let mut stop_asked: Option<Instant> = None;
        let done = loop {
            // A controlled stop: hold, and end the loop once it stands still. A consumer
            // that waits for the producer (virtual time, the walk to a checkpoint) is told to
            // stop waiting if it has not come to a standstill within STOP_WAKE.
            if stop.load(Ordering::Relaxed) {
                published.hold.store(true, Ordering::Relaxed);
                let asked = *stop_asked.get_or_insert_with(Instant::now);
                if published.snapshot().still {
                    published.stop.store(true, Ordering::Relaxed);
                } else if asked.elapsed() >= STOP_WAKE {
                    buffer.interrupt();
                }
            }
            drain();
            if let Some(report) = progress.as_mut()
                && last_progress.elapsed() >= PROGRESS_EVERY
            {
                last_progress = Instant::now();
                let snap = published.snapshot();
                tracker.track(snap.path_mm, last_progress);
                report(&tracker, &snap);
            }
            let areas = buffer.areas();
            published
                .buffer_unprocessed
                .store(areas.unprocessed, Ordering::Relaxed);
            published
                .buffer_reserved
                .store(areas.reserved, Ordering::Relaxed);
            match result.try_recv() {
                Ok(done) => break Some(done),
                Err(crossbeam::channel::TryRecvError::Disconnected) => break None,
                Err(crossbeam::channel::TryRecvError::Empty) => {}
            }
            std::thread::park_timeout(Duration::from_millis(10));
        };
        drain();
        // The consumer is gone: a producer still reading has no one to read for.
        producer_cancel.store(true, Ordering::Relaxed);
        if done.is_none() {
            buffer.abort();
        }
        let producer = producer.and_then(|p| p.join().expect("the producer thread panicked"));
        (producer, done)
    });
    let Some(FineDone {
        fine,
        report,
        finished,
        skip,
        output,
        gap,
    }) = done
    else {
        panic!("the fine interpolation thread panicked");
    };

    let (counters, mut position) = summary::delivered(&fine, &report);
    if let (Err(_), Some(point)) = (&skip, &resume) {
        // Nothing moved: the walk towards the checkpoint emits nothing, so the machine
        // stands where the checkpoint says, whatever point the walk reached.
        for (p, s) in position.iter_mut().zip(&point.position) {
            *p = *s;
        }
    }
    let axes = config.machine.axes.len();
    let (outcome, error) = summary::outcome(&skip, &report, &finished, fine.state(), &producer);
    let producer = producer.unwrap_or_default();
    let mut stopped_at = Snapshot::of(report.ticks, &fine);
    if let Some((here, events)) = report.untaken_from {
        // The failed tick's step never reached the drives: the checkpoint's point is the
        // one before it (its ledger is taken back below, in `summary::delivered`).
        stopped_at.here = here;
        stopped_at.events = events;
    }
    let summary = JobSummary {
        program: name,
        outcome,
        error,
        axes: config.machine.axis_names(),
        blocks: check.blocks,
        segments: producer.pushed,
        steps_per_axis: counters.pulses[..axes].to_vec(),
        end_steps: position[..axes].to_vec(),
        program_end_steps: check.end_steps[..axes].to_vec(),
        end_mm: position[..axes]
            .iter()
            .zip(&config.machine.step_mm)
            .map(|(p, s)| *p as f64 * s)
            .collect(),
        events_forward: counters.events_forward,
        events_backward: counters.events_backward,
        servo: counters.servo,
        last_probe: summary::LastProbe::new(report.last_probe.as_ref(), &config.machine.step_mm),
        overruns: report.overruns,
        missed_deadlines: report.missed_deadlines,
        latency_us: report.latency.as_ref().map(|h| h.summary()),
        tick_us: tick.us(),
        ticks: report.ticks,
        virtual_time: loop_settings.virtual_time,
        virtual_time_s: tick.ticks_to_secs(report.ticks),
        wall_time_s: report.wall_ns as f64 * 1e-9,
        producer_busy_s: producer.busy_ns as f64 * 1e-9,
        peak_rss_kib: crate::sys::peak_rss_kib(),
        buffer_capacity: config.buffer.capacity as u64,
        buffer_high_water: buffer.areas().high_water,
        events_dropped: published.events_dropped.load(Ordering::Relaxed),
        trace_dropped: tracer.as_ref().map_or(0, |t| t.dropped()),
        rt_refused: report.rt_refused,
        stopped_at: (outcome != Outcome::Done && outcome != Outcome::ResumeRefused).then(|| {
            StopPoint {
                line: stopped_at.line,
                segment: stopped_at.here.seq,
                step: stopped_at.here.event,
                segment_steps: stopped_at.events,
                parameter: stopped_at.u_end.is_finite().then_some(stopped_at.u_end),
                dwell_s: tick.ticks_to_secs(stopped_at.dwell_left),
                program_sha256: program.sha256.clone(),
            }
        }),
    };
    JobEnd {
        summary,
        stopped_at,
        output,
        gap,
    }
}
