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
pub mod fine_thread;
pub mod latency;
pub mod producer;
pub mod sys;

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::buffer::LoopBuffer;
use crate::config::{Config, GapKind, OutputKind};
use crate::fine::FineSettings;
use crate::gap::{AlwaysNormal, GapSensor, ScriptError, ScriptGap};
use crate::gcode::{self, GcodeError};
use crate::geometry::MAX_AXES;
use crate::output::{
    FaultInjector, NullOutput, OutputError, PulseLog, PulseLogHeader, PulseOutput,
};
use crate::parport::ParportError;
use crate::servo::{ServoEvent, ServoState};
use crate::trace::{TraceEvent, TraceRecord, TracedGap, TracedOutput, Tracer};

pub use consumer::{EventRecord, LoopReport, LoopSettings, Published, Snapshot};
pub use fine_thread::{FineDone, FineJob, FineThread, ResumePoint};
pub use latency::{LatencyHistogram, LatencySummary};
pub use producer::{BlockMaker, ProducerError, ProducerReport, to_steps};

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
    Output(#[from] OutputError),
    #[error(transparent)]
    Parport(#[from] ParportError),
    #[error("cannot start the fine interpolation thread: {0}")]
    Thread(std::io::Error),
    /// A combination of settings that cannot run (the validated configuration refuses it).
    #[error("{0}")]
    Config(String),
}

/// How a job ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Outcome {
    /// The whole program was executed.
    Done,
    /// Shorted after the whole reserved area: stopped, position kept.
    Alarm,
    /// The pulse output failed: stopped at once.
    OutputError,
    /// The gap input failed: stopped at once.
    GapError,
    /// The producer failed part-way (the program changed after the check, or a position out of
    /// range): the consumer executed what it had and stopped.
    ProducerError,
    /// Stopped on request.
    Stopped,
    /// A resumed job did not find its checkpoint on the program's path: nothing moved.
    ResumeRefused,
}

impl Outcome {
    pub fn name(self) -> &'static str {
        match self {
            Outcome::Done => "done",
            Outcome::Alarm => "alarm",
            Outcome::OutputError => "output error",
            Outcome::GapError => "gap input error",
            Outcome::ProducerError => "producer error",
            Outcome::Stopped => "stopped",
            Outcome::ResumeRefused => "resume refused",
        }
    }
}

/// The end-of-job summary (`edmd run` prints it; `--summary FILE` writes it as JSON).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JobSummary {
    pub program: String,
    pub outcome: Outcome,
    pub error: Option<String>,
    pub axes: Vec<String>,
    /// G-code blocks of the program.
    pub blocks: u64,
    /// Loop-buffer blocks (segments) produced.
    pub segments: u64,
    /// Pulses emitted per axis, both directions.
    pub steps_per_axis: Vec<u64>,
    /// The pulse ledger at the end, per axis (steps).
    pub end_steps: Vec<i64>,
    /// The program's end point, per axis (steps).
    pub program_end_steps: Vec<i64>,
    pub end_mm: Vec<f64>,
    pub events_forward: u64,
    pub events_backward: u64,
    pub shorts: u64,
    pub turn_backs: u64,
    pub deepest_turn_back_blocks: u64,
    pub alarms: u64,
    pub starvations: u64,
    pub overruns: u64,
    pub missed_deadlines: u64,
    /// Real time only.
    pub latency_us: Option<LatencySummary>,
    pub tick_us: u32,
    pub ticks: u64,
    pub virtual_time: bool,
    /// Machine time: ticks × tick period (s).
    pub virtual_time_s: f64,
    pub wall_time_s: f64,
    /// Wall time the producer spent working (not waiting for buffer space), s. Machine time
    /// over this is how many times faster than real time the producer can feed the loop.
    #[serde(default)]
    pub producer_busy_s: f64,
    /// Peak resident set size of the process at the end of the job, KiB.
    #[serde(default)]
    pub peak_rss_kib: u64,
    pub buffer_capacity: u64,
    pub buffer_high_water: u64,
    pub events_dropped: u64,
    /// Trace records dropped because the logger fell behind (real time only).
    pub trace_dropped: u64,
    /// Real-time features the system refused.
    pub rt_refused: Vec<String>,
}

impl JobSummary {
    /// The human-readable summary.
    pub fn text(&self) -> String {
        use std::fmt::Write;
        let mut t = String::new();
        let list = |v: &[i64]| axis_list(v, &self.axes, |s| s.to_string());
        let _ = writeln!(t, "{}: {}", self.program, self.outcome.name());
        if let Some(e) = &self.error {
            let _ = writeln!(t, "  error:            {e}");
        }
        let _ = writeln!(
            t,
            "  blocks:           {} G-code blocks, {} segments",
            self.blocks, self.segments
        );
        let pulses: Vec<i64> = self.steps_per_axis.iter().map(|&p| p as i64).collect();
        let _ = writeln!(t, "  steps per axis:   {}", list(&pulses));
        let _ = writeln!(
            t,
            "  end position:     {} steps (program end {})",
            list(&self.end_steps),
            list(&self.program_end_steps)
        );
        let _ = writeln!(
            t,
            "  servo:            {} shorts, {} turn-backs (deepest {} blocks), {} alarms, {} starvations",
            self.shorts,
            self.turn_backs,
            self.deepest_turn_back_blocks,
            self.alarms,
            self.starvations
        );
        let _ = writeln!(
            t,
            "  events:           {} forward, {} backward",
            self.events_forward, self.events_backward
        );
        match &self.latency_us {
            Some(l) => {
                let _ = writeln!(
                    t,
                    "  latency:          p50 {:.1} µs, p99 {:.1} µs, max {:.1} µs over {} ticks; {} overruns",
                    l.p50_us, l.p99_us, l.max_us, l.samples, self.overruns
                );
            }
            None => {
                let _ = writeln!(
                    t,
                    "  latency:          none measured (virtual time); {} overruns",
                    self.overruns
                );
            }
        }
        let _ = writeln!(
            t,
            "  time:             {:.3} s machine ({} ticks of {} µs), {:.3} s wall",
            self.virtual_time_s, self.ticks, self.tick_us, self.wall_time_s
        );
        let _ = writeln!(
            t,
            "  producer:         {:.3} s busy for {:.3} s of machine time ({:.0}x real time)",
            self.producer_busy_s,
            self.virtual_time_s,
            self.virtual_time_s / self.producer_busy_s.max(1e-9)
        );
        let _ = writeln!(
            t,
            "  loop buffer:      high water {} of {} blocks",
            self.buffer_high_water, self.buffer_capacity
        );
        let _ = writeln!(
            t,
            "  memory:           peak RSS {:.1} MiB",
            self.peak_rss_kib as f64 / 1024.0
        );
        for r in &self.rt_refused {
            let _ = writeln!(t, "  warning:          {r}");
        }
        t
    }
}

/// `X 1, Y 2`: one value per axis, each after its letter.
pub fn axis_list<T>(values: &[T], axes: &[String], format: impl Fn(&T) -> String) -> String {
    values
        .iter()
        .zip(axes)
        .map(|(v, a)| format!("{a} {}", format(v)))
        .collect::<Vec<_>>()
        .join(", ")
}

/// What the check before the job found.
#[derive(Debug, Clone)]
pub struct Precheck {
    pub blocks: u64,
    pub end_steps: [i64; MAX_AXES],
    /// Where the cutting (non-rapid) moves lie along the path: `(from, to)` in mm of path
    /// length from the program's start, consecutive cutting moves merged into one span (so
    /// this grows with the number of rapids, not of blocks). Measured only for the simulated
    /// gap's placed debris.
    pub cutting_spans: Vec<(f64, f64)>,
}

/// Parses the whole program and checks every end point fits a step counter.
pub fn precheck(program: &Path, config: &Config) -> Result<Precheck, JobError> {
    let mut reader = gcode::open_program(program, &config.machine.axes)?;
    let mut blocks = 0;
    let mut end_steps = [0; MAX_AXES];
    let mut path_mm = 0.0;
    let mut cutting_spans = Vec::new();
    let measure = config.gap.kind == GapKind::Sim && config.sim.debris_shorts > 0;
    for item in reader.by_ref() {
        let block = item?;
        blocks += 1;
        if measure {
            let length = block.curve.length();
            if block.kind != gcode::BlockKind::Rapid {
                match cutting_spans.last_mut() {
                    Some((_, to)) if *to == path_mm => *to += length,
                    _ => cutting_spans.push((path_mm, path_mm + length)),
                }
            }
            path_mm += length;
        }
        end_steps =
            to_steps(&block.end(), &config.machine.step_mm).map_err(|(axis, mm, steps)| {
                ProducerError::OutOfRange {
                    program: program.display().to_string(),
                    line: block.line,
                    axis: config.machine.axes[axis].letter(),
                    mm,
                    steps,
                }
            })?;
    }
    for w in reader.take_warnings() {
        if w.line == 0 {
            tracing::warn!("{}: {}", program.display(), w.message);
        } else {
            tracing::warn!("{}:{}:{}: {}", program.display(), w.line, w.col, w.message);
        }
    }
    Ok(Precheck {
        blocks,
        end_steps,
        cutting_spans,
    })
}

pub type BoxedOutput = Box<dyn PulseOutput + Send>;
pub type BoxedGap = Box<dyn GapSensor + Send>;

/// Opens the output and the gap source of `config`, with the fault injector and the tracer
/// when configured: everything that can fail at startup fails here, before anything moves.
pub fn open_io(
    config: &Config,
    check: &Precheck,
    tracer: Option<&Arc<Tracer>>,
) -> Result<(BoxedOutput, BoxedGap), JobError> {
    let (output, port_gap) = open_output(config, &[])?;
    let gap = open_gap(config, check, port_gap)?;
    Ok(wrap_io(config, output, gap, tracer))
}

/// Opens the pulse output of `config`; a parallel port comes with its status pins (the gap
/// input), opened together under one claim. `start`: the ledger the job starts from (steps
/// per axis; empty for zero), for the pulse log's header.
pub fn open_output(
    config: &Config,
    start: &[i64],
) -> Result<(BoxedOutput, Option<BoxedGap>), JobError> {
    let axes = config.machine.axes.len();
    Ok(match config.output.kind {
        // The simulated drives take every step and report nothing: the ledger is their position.
        OutputKind::Null | OutputKind::Sim => (Box::new(NullOutput), None),
        OutputKind::File => (
            Box::new(PulseLog::create(
                &config.output.path,
                &PulseLogHeader {
                    axes: config.machine.axes.clone(),
                    step_mm: config.machine.step_mm.clone(),
                    tick_us: config.fine.tick_us,
                    start: (0..axes)
                        .map(|i| start.get(i).copied().unwrap_or(0))
                        .collect(),
                },
            )?),
            None,
        ),
        OutputKind::Parport => {
            let (output, gap) = crate::parport::open(config)?;
            (Box::new(output), Some(Box::new(gap)))
        }
    })
}

/// Opens the gap source of `config`; `port_gap` is the parallel port's status pins when the
/// port is open.
pub fn open_gap(
    config: &Config,
    check: &Precheck,
    port_gap: Option<BoxedGap>,
) -> Result<BoxedGap, JobError> {
    Ok(match (config.gap.kind, port_gap) {
        (GapKind::Parport, Some(gap)) => gap,
        // Validation refuses this combination; a hand-built `Config` gets an error, not a panic.
        (GapKind::Parport, None) => {
            return Err(JobError::Config(
                "gap.kind = \"parport\" reads the output port's status pins and needs \
                 output.kind = \"parport\""
                    .to_string(),
            ));
        }
        (GapKind::None, _) => Box::new(AlwaysNormal),
        (GapKind::Script, _) => Box::new(ScriptGap::load(&config.gap.script)?),
        (GapKind::Sim, _) => Box::new(crate::sim::SimGap::from_config(
            config,
            &check.cutting_spans,
        )?),
    })
}

/// Wraps the output and the gap source in the fault injector and the tracer, as configured.
pub fn wrap_io(
    config: &Config,
    mut output: BoxedOutput,
    mut gap: BoxedGap,
    tracer: Option<&Arc<Tracer>>,
) -> (BoxedOutput, BoxedGap) {
    if let Some(tick) = config.output.fault_at_tick {
        tracing::warn!("output.fault_at_tick = {tick}: the output will fail at that tick");
        output = Box::new(FaultInjector::new(output, tick));
    }
    if let Some(tracer) = tracer {
        if config.output.trace {
            output = Box::new(TracedOutput::new(output, tracer.clone()));
        }
        if config.gap.trace {
            gap = Box::new(TracedGap::new(gap, tracer.clone()));
        }
    }
    (output, gap)
}

/// The highest path speed the fine interpolator can reach (mm/s): one step of the coarsest
/// axis per tick.
pub fn fine_speed_cap(config: &Config) -> f64 {
    let coarsest = config.machine.step_mm.iter().cloned().fold(0.0, f64::max);
    coarsest / (config.fine.tick_us as f64 * 1e-6)
}

/// Logs one servo event (from the main thread, never the consumer).
fn log_event(program: &str, record: &EventRecord, tick_s: f64) {
    let t = record.tick as f64 * tick_s;
    let line = record.line;
    match record.event {
        ServoEvent::Short { at } => tracing::info!(
            "{program}:{line}: short circuit at t={t:.4} s (segment {}, step {}): turning back",
            at.seq,
            at.event
        ),
        ServoEvent::Cleared { depth } => tracing::info!(
            "{program}:{line}: gap cleared at t={t:.4} s after turning back over {depth} blocks: re-advancing"
        ),
        ServoEvent::Resumed { .. } => {
            tracing::debug!("{program}:{line}: back at the short at t={t:.4} s: machining on")
        }
        ServoEvent::Starved { at } => tracing::warn!(
            "{program}:{line}: loop buffer empty at t={t:.4} s (segment {}): holding",
            at.seq
        ),
        ServoEvent::Alarm { at, depth } => tracing::error!(
            "{program}:{line}: ALARM at t={t:.4} s: still shorted after turning back over the whole \
             reserved area ({depth} blocks, segment {}); motion stopped, position kept",
            at.seq
        ),
        ServoEvent::Done => tracing::info!("{program}: program end at t={t:.4} s"),
    }
}

/// Logs one trace record (from the main thread).
fn log_trace(config: &Config, record: &TraceRecord, tick_s: f64) {
    let t = record.tick as f64 * tick_s;
    let tick = record.tick;
    match record.event {
        TraceEvent::Gap { from, to } => tracing::info!(
            target: "edmd::trace",
            "t={t:.5} s (tick {tick}): gap {} -> {}",
            from.map_or("(first reading)", |f| f.name()),
            to.name()
        ),
        TraceEvent::Direction { axis, positive } => tracing::info!(
            target: "edmd::trace",
            "t={t:.5} s (tick {tick}): axis {} now steps {}",
            config.machine.axes[axis as usize].letter(),
            if positive { "+" } else { "-" }
        ),
        TraceEvent::WriteFailed => tracing::info!(
            target: "edmd::trace",
            "t={t:.5} s (tick {tick}): output write failed"
        ),
    }
}

/// Runs `program` through both threads with the output and gap source of `config`.
pub fn run_job(program: &Path, config: &Config) -> Result<JobSummary, JobError> {
    run_job_until(program, config, &AtomicBool::new(false))
}

/// [`run_job`], stopping where it is (position kept, outputs inactive) once `stop` is set,
/// e.g. by a signal handler.
pub fn run_job_until(
    program: &Path,
    config: &Config,
    stop: &AtomicBool,
) -> Result<JobSummary, JobError> {
    let check = precheck(program, config)?;
    let tracer = (config.output.trace || config.gap.trace)
        .then(|| Tracer::new(4096, config.fine.virtual_time, Some(std::thread::current())));
    let (output, gap) = open_io(config, &check, tracer.as_ref())?;
    run_job_on(program, config, &check, output, gap, tracer, Some(stop))
}

/// Runs `program` (already checked: `check`) through both threads with the given output and
/// gap source; `tracer` is drained and logged while the job runs; once `stop` is set the job
/// brakes to a standstill and ends there (position kept).
pub fn run_job_on(
    program: &Path,
    config: &Config,
    check: &Precheck,
    output: BoxedOutput,
    gap: BoxedGap,
    tracer: Option<Arc<Tracer>>,
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
        JobIo {
            output,
            gap,
            tracer,
        },
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
    program: &Path,
    config: &Config,
    check: &Precheck,
    io: JobIo,
    published: Arc<Published>,
    stop: &AtomicBool,
    resume: Option<ResumePoint>,
) -> JobEnd {
    let name = program.display().to_string();
    let cap = fine_speed_cap(config);
    if config.machine.max_feed_mm_per_min / 60.0 > cap {
        tracing::info!(
            "fine.tick_us = {} allows at most one step per axis per tick: path speeds above \
             about {:.0} mm/min (machine.max_feed_mm_per_min = {}) are not reachable",
            config.fine.tick_us,
            cap * 60.0,
            config.machine.max_feed_mm_per_min
        );
    }
    tracing::info!(
        "{name}: {} blocks; {} time, tick {} µs",
        check.blocks,
        if config.fine.virtual_time {
            "virtual"
        } else {
            "real"
        },
        config.fine.tick_us
    );
    let buffer = Arc::new(LoopBuffer::new(
        config.buffer.capacity,
        config.buffer.reserved,
    ));
    let loop_settings = LoopSettings::from_config(config);
    let tick_s = config.fine.tick_us as f64 * 1e-6;
    let JobIo {
        output,
        gap,
        tracer,
    } = io;

    let (producer, done) = std::thread::scope(|s| {
        let producer = s.spawn(|| producer::produce(program, config, &buffer));
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
            while let Some(record) = published.events.pop() {
                log_event(&name, &record, tick_s);
            }
            if let Some(tracer) = &tracer {
                tracer.drain(|record| log_trace(config, record, tick_s));
            }
        };
        let done = loop {
            // A controlled stop: hold, and end the loop once it stands still.
            if stop.load(Ordering::Relaxed) {
                published.hold.store(true, Ordering::Relaxed);
                if published.snapshot().still {
                    published.stop.store(true, Ordering::Relaxed);
                }
            }
            drain();
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
        if done.is_none() {
            buffer.abort();
        }
        let producer = producer.join().expect("the producer thread panicked");
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

    let mut counters = fine.counters();
    let mut position = fine.position();
    // A tick whose write failed before its step edge never reached the drives: the ledger
    // is what they received.
    if let Some((steps, dir)) = report.untaken {
        for (axis, &s) in steps.iter().enumerate() {
            position[axis] -= s as i64;
            counters.pulses[axis] -= s.unsigned_abs() as u64;
        }
        if dir > 0 {
            counters.events_forward -= 1;
        } else {
            counters.events_backward -= 1;
        }
    }
    let axes = config.machine.axes.len();
    let (outcome, error) = if let Err(e) = &skip {
        (Outcome::ResumeRefused, Some(e.to_string()))
    } else if let Some(e) = report.gap_error.as_ref() {
        (Outcome::GapError, Some(e.to_string()))
    } else if let Some(e) = report.output_error.as_ref() {
        (Outcome::OutputError, Some(e.to_string()))
    } else if let Err(e) = finished {
        (Outcome::OutputError, Some(e.to_string()))
    } else if fine.state() == ServoState::Alarm {
        (
            Outcome::Alarm,
            Some("shorted after turning back over the whole reserved area".to_string()),
        )
    } else if let Err(e) = &producer {
        (Outcome::ProducerError, Some(e.to_string()))
    } else if report.stopped {
        (
            Outcome::Stopped,
            Some("a stop was requested: motion stopped where it was, position kept".to_string()),
        )
    } else if fine.state() != ServoState::Done {
        (Outcome::Stopped, None)
    } else {
        (Outcome::Done, None)
    };
    let producer = producer.unwrap_or_default();
    let stopped_at = Snapshot::of(report.ticks, &fine);
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
        shorts: counters.servo.shorts,
        turn_backs: counters.servo.turn_backs,
        deepest_turn_back_blocks: counters.servo.deepest_turn_back_blocks,
        alarms: counters.servo.alarms,
        starvations: counters.servo.starvations,
        overruns: report.overruns,
        missed_deadlines: report.missed_deadlines,
        latency_us: report.latency.as_ref().map(|h| h.summary()),
        tick_us: config.fine.tick_us,
        ticks: report.ticks,
        virtual_time: loop_settings.virtual_time,
        virtual_time_s: report.ticks as f64 * tick_s,
        wall_time_s: report.wall_ns as f64 * 1e-9,
        producer_busy_s: producer.busy_ns as f64 * 1e-9,
        peak_rss_kib: sys::peak_rss_kib(),
        buffer_capacity: config.buffer.capacity as u64,
        buffer_high_water: buffer.areas().high_water,
        events_dropped: published.events_dropped.load(Ordering::Relaxed),
        trace_dropped: tracer.as_ref().map_or(0, |t| t.dropped()),
        rt_refused: report.rt_refused,
    };
    JobEnd {
        summary,
        stopped_at,
        output,
        gap,
    }
}
