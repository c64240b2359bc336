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
//! A job is checked whole first ([`precheck`]): a CNC control must not start cutting a
//! program whose line 10,000 is bad. Its settings are read from the configuration once
//! ([`JobSpec`]); then [`run`], the one way into a job, has the producer ([`producer`])
//! stream the program again into the loop buffer while the fine thread ([`fine_thread`],
//! looping in [`consumer`]) runs the tick core in real or virtual time. The supervisor only
//! logs, steers through [`Published`] and waits. The summary ([`JobSummary`]) is what `edmd
//! run` prints and writes as JSON; the daemon runs its jobs on one long-lived [`FineThread`].
//! [`run_file`] is `edmd run`'s path: copy, check, open the devices, run.

mod job;
mod run;
mod shaping;
mod tick;

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::config::Config;
use crate::gcode::{WorkOffsets, WorkStart, WorkSystem};
use crate::path::CutPlan;
use crate::record::Recording;
use crate::trace::{TraceEvent, TraceRecord, Tracer};

use job::{devices, error, precheck, spec, summary};
pub use job::{fine_thread, producer};
pub use shaping::{program, progress};
pub use tick::{consumer, controls, idle, latency, probe};
use tick::{histogram, realtime};

pub use consumer::{EventRecord, LoopReport, LoopSettings, Published, Snapshot};
pub use devices::{
    BoxedGap, BoxedInputs, BoxedOutput, OpenedGap, OpenedIo, OpenedOutput, open_gap, open_io,
    open_output, wrap_io,
};
pub use error::JobError;
pub use fine_thread::{Claimed, FineDone, FineJob, FineThread, JobRecorder, ResumePoint};
pub use histogram::{LatencyHistogram, LatencySummary};
pub use precheck::{Precheck, precheck};
pub use producer::{BlockMaker, ProducerError, ProducerReport, to_steps};
pub use program::{JobProgram, Progress, TempCopy};
pub use progress::ProgressTracker;
pub use realtime::{RealtimeGuard, apply_realtime};
pub use run::{JobRun, run};
pub use spec::{JobSpec, fine_speed_cap, start_steps};
pub use summary::{JobSummary, LastProbe, Outcome, StopPoint, axis_list};

/// Logs one trace record (from the main thread).
fn log_trace(spec: &JobSpec, record: &TraceRecord) {
    let t = spec.tick.ticks_to_secs(record.tick);
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
            spec.axes[axis as usize].letter(),
            if positive { "+" } else { "-" }
        ),
        TraceEvent::WriteFailed => tracing::info!(
            target: "edmd::trace",
            "t={t:.5} s (tick {tick_no}): output write failed"
        ),
    }
}

/// Who watches a job besides its log: a progress callback, a recording for a report.
#[derive(Default)]
pub struct Observers {
    pub progress: Option<ProgressFn>,
    pub recording: Option<Arc<parking_lot::Mutex<Recording>>>,
}

/// How often a job's supervisor reports progress.
pub const PROGRESS_EVERY: Duration = Duration::from_millis(250);

/// Hears a job's progress (on the supervising thread): the tracker and the latest snapshot.
pub type ProgressFn = Box<dyn FnMut(&ProgressTracker, &Snapshot) + Send>;

/// `edmd run`'s job: copies and checks `program`, opens the devices of `config` and runs it
/// on a fine thread of its own, stopping where it is (position kept, outputs inactive) once
/// `stop` is set; `observers.progress` hears how far the job has come every
/// [`PROGRESS_EVERY`], `observers.recording` gathers what ran. `M0`/`M1` pass (there is no
/// operator to resume them).
pub fn run_file(
    program: &Path,
    config: &Config,
    stop: &AtomicBool,
    observers: Observers,
) -> Result<JobSummary, JobError> {
    run_file_from(
        program,
        config,
        &WorkStart::default(),
        &CutPlan::default(),
        stop,
        observers,
    )
    .map(|(s, _)| s)
}

/// [`run_file`] from `start` (the machine position, work offsets and active system, as a
/// state file keeps them), cutting from `from_line` if given; returns the summary and the
/// work offsets and system the program left (`G10`, `M2`).
pub fn run_file_from(
    program: &Path,
    config: &Config,
    start: &WorkStart,
    cut: &CutPlan,
    stop: &AtomicBool,
    observers: Observers,
) -> Result<(JobSummary, (WorkOffsets, WorkSystem)), JobError> {
    let (copy, check) = copy_and_check(program, config, start, cut, stop)?;
    let tracer = (config.output.trace || config.gap.trace)
        .then(|| Tracer::new(4096, config.fine.virtual_time, Some(std::thread::current())));
    let mut spec = JobSpec::from_config(config, false);
    spec.path.work = start.clone();
    spec.path.cut = cut.clone();
    let opened = open_io(config, &check, &spec.start_steps(), tracer.as_ref())?;
    let io = JobIo {
        output: Some(opened.output),
        gap: Some(opened.gap),
        inputs: Some(opened.inputs),
        gap_inputs: opened.gap_inputs,
        probe_reads: Default::default(),
        tracer,
        recording: observers.recording,
        progress: observers.progress,
    };
    let fine_thread = FineThread::start(&spec.run_loop, None).map_err(JobError::Thread)?;
    let job = JobRun {
        program: &copy.0,
        check: &check,
        spec: &spec,
        resume: None,
    };
    let end = run(&fine_thread, job, io, Arc::new(Published::new(4096)), stop);
    Ok((end.summary, (check.work_offsets, check.work_system)))
}

/// Copies `program` to a private temporary copy and checks the copy (on a thread of their
/// own, so `stop` cancels them within a poll period however large the file).
pub fn copy_and_check(
    program: &Path,
    config: &Config,
    start: &WorkStart,
    cut: &CutPlan,
    stop: &AtomicBool,
) -> Result<(TempCopy, Precheck), JobError> {
    let progress = Progress::new();
    std::thread::scope(|s| {
        let work = std::thread::Builder::new()
            .name("edmd-check".to_string())
            .stack_size(crate::gcode::PARSER_STACK_BYTES)
            .spawn_scoped(s, || {
                let copy = TempCopy::new_with(program, &progress)?;
                let check = precheck(&copy.0, config, start, cut, &progress)?;
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

/// What a job runs on besides the program.
pub struct JobIo {
    /// The job's own devices; `None`: the fine thread's claimed device's
    /// ([`FineThread::start`]).
    pub output: Option<BoxedOutput>,
    pub gap: Option<BoxedGap>,
    pub inputs: Option<BoxedInputs>,
    /// The inputs side of the job's simulated gap ([`OpenedGap::inputs`]), read beside
    /// the machine's.
    pub gap_inputs: Option<BoxedInputs>,
    /// What the job's probing moves read as their contact (a homing job's switch, a touch
    /// cycle's part; the probe otherwise), told to the gap and the inputs it runs on.
    pub probe_reads: crate::vocab::ProbeReads,
    pub tracer: Option<Arc<Tracer>>,
    /// What actually ran, for a report (`edmd run --report`): the output is wrapped in a
    /// recorder and the supervisor fills the recording.
    pub recording: Option<Arc<parking_lot::Mutex<Recording>>>,
    /// Hears the job's progress (`edmd run`'s bar or log line); the daemon reads `Published`.
    pub progress: Option<ProgressFn>,
}

/// A finished job: the summary, where the electrode stands, and the job's own devices
/// handed back (a claimed device stays with the fine thread).
pub struct JobEnd {
    pub summary: JobSummary,
    /// The interpolator at the end: the checkpoint's point and ledger.
    pub stopped_at: Snapshot,
    pub output: Option<BoxedOutput>,
    pub gap: Option<BoxedGap>,
    pub inputs: Option<BoxedInputs>,
}
