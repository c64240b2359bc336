//! The control loop's job commands: `run` (confine, precheck, open the devices, start the job
//! thread), `hold`, `resume` (of a hold, or of the checkpoint), `abort`, and what happens
//! when a job ends: the checkpoint written at a standstill, or removed when the job is done.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use super::launch::{Checked, JobKind, Launch, Source, copy_and_check};
use super::protocol::{self, CheckStatus};
use super::refusal::{CheckRefusal, Refusal};
use super::{Core, CoreMsg, Job, JobReport, confine, unix_now};
use crate::checkpoint::{self, Reason};
use crate::config::{Config, GapKind, OutputKind};
use crate::record::{EventKind, Recording};
use crate::runtime::program::{self, JobProgram, Progress};
use crate::runtime::{
    self, BoxedGap, BoxedOutput, FineThread, JobEnd, JobError, JobIo, JobSummary, Outcome,
    ResumePoint,
};
use crate::servo::{Rethread, ServoState};

/// A resume waiting for its check: where to resume, and the bytes it must be.
pub(super) struct Resume {
    point: ResumePoint,
    sha256: String,
}

/// The check in progress.
pub(super) struct Check {
    pub(super) id: u64,
    /// The program as the operator named it.
    pub(super) name: String,
    pub(super) progress: Arc<Progress>,
    resume: Option<Resume>,
    /// Where the job starts (checked from there) and what it is.
    launch: Launch,
}

impl Job {
    /// An operator's event (a hold, its release) into the job's report, at the tick and
    /// line the job has reached.
    fn report_event(&self, kind: EventKind) {
        if let Some((_, recording)) = &self.report {
            let snap = self.published.snapshot();
            recording.lock().event(snap.tick, snap.line, kind, None);
        }
    }
}

impl Check {
    pub(super) fn is_resume(&self) -> bool {
        self.resume.is_some()
    }
}

/// The jobs: the fine thread that runs them and the port it lends them, the job running,
/// the check before the next one, and what the ended ones left (the last summary, the
/// counts).
pub(super) struct JobControl {
    pub fine: Arc<FineThread>,
    /// The parallel port, claimed at startup and lent to each job.
    pub port_output: Option<BoxedOutput>,
    pub port_gap: Option<BoxedGap>,
    pub job: Option<Job>,
    /// The program being copied and checked before its job starts.
    pub check: Option<Check>,
    /// The verdict of the last check.
    pub last_check: Option<protocol::CheckStatus>,
    /// The continuous jog in progress (being checked or moving) and its dead-man.
    pub continuous: Option<super::manual::ContinuousJog>,
    pub next_check_id: u64,
    pub last: Option<JobSummary>,
    /// Counts of the jobs that ended (the running one's are added when asked).
    pub finished: protocol::Counters,
    /// The operator's controls (overrides, single block): the running job's, and every
    /// job's from its start.
    pub controls: crate::runtime::controls::Controls,
}

/// The folder of a job's report and its recording, when the configuration asks for one. The
/// folder is made first: a job must not learn at its end that its report has nowhere to go.
fn job_report(config: &Config, program_name: &str) -> Result<Option<JobReport>, Refusal> {
    Ok(match &config.daemon.report_dir {
        Some(dir) => {
            let stem = Path::new(program_name)
                .file_stem()
                .map_or_else(|| "job".to_string(), |s| s.to_string_lossy().into_owned());
            let dir = dir.join(format!("{}-{stem}", unix_now()));
            if let Err(source) = std::fs::create_dir_all(&dir) {
                return Err(Refusal::ReportDir { dir, source });
            }
            let recording = Arc::new(parking_lot::Mutex::new(Recording::new(
                &config.machine.step_mm,
                config.fine.tick,
            )));
            Some((dir, recording))
        }
        None => None,
    })
}

/// Logs a job's start; what the command answers.
fn started(program: &str, blocks: u64, resumed: bool, kind: JobKind, message: &str) -> String {
    tracing::info!(
        edmd_event = "job_start",
        edmd_program = program,
        "job start: {program}{}",
        match (resumed, kind == JobKind::DryRun) {
            (true, _) => " (resumed)",
            (_, true) => " (dry run: spark off, the servo out of the loop)",
            _ => "",
        }
    );
    if resumed {
        format!("resuming {program}: {blocks} blocks")
    } else {
        format!("running {program}: {blocks} blocks{message}")
    }
}

impl JobControl {
    /// A job that ended, or did not start after all, hands the claimed parallel port back.
    pub(super) fn give_back_io(&mut self, config: &Config, output: BoxedOutput, gap: BoxedGap) {
        if config.output.kind == OutputKind::Parport {
            self.port_output = Some(output);
        }
        if config.gap.kind == GapKind::Parport {
            self.port_gap = Some(gap);
        }
    }

    /// The job's output and gap source: the claimed port when there is one, else opened now.
    pub(super) fn job_io(
        &mut self,
        config: &Config,
        check: &runtime::Precheck,
        start: &[i64],
    ) -> Result<JobIo, JobError> {
        let tracer = (config.output.trace || config.gap.trace).then(|| {
            crate::trace::Tracer::new(4096, config.fine.virtual_time, Some(std::thread::current()))
        });
        let (output, opened_gap) = match self.port_output.take() {
            Some(output) => (output, None),
            None => runtime::open_output(config, start)?,
        };
        let port_gap = if config.gap.kind == GapKind::Parport {
            self.port_gap.take().or(opened_gap)
        } else {
            None
        };
        let gap = match runtime::open_gap(config, check, port_gap) {
            Ok(gap) => gap,
            Err(e) => {
                if config.output.kind == OutputKind::Parport {
                    self.port_output = Some(output);
                }
                return Err(e);
            }
        };
        // The claimed port is lent as it is: wrappers would stay on it after the job.
        let (output, gap) = if config.output.kind == OutputKind::Parport {
            if config.output.trace || config.gap.trace || config.output.fault_at_tick.is_some() {
                tracing::warn!(
                    "output.trace, gap.trace and output.fault_at_tick are not applied to the \
                     daemon's claimed parallel port"
                );
            }
            (output, gap)
        } else {
            runtime::wrap_io(config, output, gap, tracer.as_ref())
        };
        Ok(JobIo {
            output,
            gap,
            tracer,
            recording: None,
            progress: None,
        })
    }
}

impl Core {
    pub(super) fn run_program(
        &mut self,
        requested: &str,
        dry_run: bool,
    ) -> Result<String, Refusal> {
        self.refuse_if_busy()?;
        self.refuse_if_tripped(None)?;
        self.refuse_if_unhomed()?;
        let program = confine(&self.config.daemon.program_dir, requested)?;
        let launch = Launch {
            start: self.machine.state.work_start(),
            kind: if dry_run {
                JobKind::DryRun
            } else {
                JobKind::Program
            },
        };
        let id = self.begin_check(Source::Original(program.clone()), None, launch);
        Ok(format!(
            "accepted: checking {} (check {id}); the job starts when the check passes",
            program.display()
        ))
    }

    /// Starts copying and checking a program on a worker thread; the verdict comes back as
    /// [`CoreMsg::Checked`]. Returns the check's id.
    pub(super) fn begin_check(
        &mut self,
        source: Source,
        resume: Option<Resume>,
        launch: Launch,
    ) -> u64 {
        self.jobs.next_check_id += 1;
        let id = self.jobs.next_check_id;
        let progress = Arc::new(Progress::new());
        let name = match &source {
            Source::Original(path) => path.display().to_string(),
            Source::Copy(program) => program.name.clone(),
            Source::Generated { name, .. } => name.clone(),
        };
        let (mut config, dir, tx) = (
            self.config.clone(),
            self.copy_dir(),
            self.clients.to_core.clone(),
        );
        if matches!(launch.kind, JobKind::Home { .. }) {
            // Homing finds where the machine is: the soft limits mean nothing yet.
            config.machine.travel.iter_mut().for_each(|t| *t = None);
        }
        let expect = resume.as_ref().map(|r| r.sha256.clone());
        let worker_progress = progress.clone();
        let worker_start = launch.start.clone();
        let spawned = std::thread::Builder::new()
            .name("edmd-check".to_string())
            .stack_size(crate::gcode::PARSER_STACK_BYTES)
            .spawn(move || {
                let result = copy_and_check(
                    source,
                    &dir,
                    &config,
                    &worker_start,
                    expect.as_deref(),
                    &worker_progress,
                );
                let result = Box::new(result);
                let _ = tx.send(CoreMsg::Checked { id, result });
            });
        if let Err(e) = spawned {
            let result = Err(CheckRefusal::Thread(e));
            let result = Box::new(result);
            let _ = self.clients.to_core.send(CoreMsg::Checked { id, result });
        }
        tracing::info!("check {id}: {name}: copying and checking");
        self.jobs.check = Some(Check {
            id,
            name,
            progress,
            resume,
            launch,
        });
        id
    }

    /// The verdict of a check: start the job, or record why not.
    pub(super) fn on_checked(&mut self, id: u64, result: Result<Checked, CheckRefusal>) {
        let Some(check) = self.jobs.check.take_if(|c| c.id == id) else {
            return;
        };
        let outcome = if self.shutting_down {
            Err(Refusal::ShuttingDown)
        } else {
            result
                .map_err(Refusal::from)
                .and_then(|(program, precheck)| {
                    let resume = check.resume.as_ref().map(|r| r.point.clone());
                    self.start_job(program, precheck, resume, check.launch.clone())
                })
        };
        let (bytes_done, bytes_total) = {
            let (_, done, total) = check.progress.get();
            (done, total)
        };
        let mut status = CheckStatus {
            id,
            program: check.name.clone(),
            phase: String::new(),
            bytes_done,
            bytes_total,
            error: None,
            message: None,
            resume: check.resume.is_some(),
        };
        match outcome {
            Ok(message) => {
                tracing::info!("check {id}: {message}");
                status.phase = "started".to_string();
                status.message = Some(message);
            }
            Err(error) => {
                // A homing sequence stops at its first refusal.
                self.machine.homing_queue.clear();
                tracing::error!(
                    edmd_event = "refusal",
                    edmd_program = check.name,
                    "check {id}: refused: {error}"
                );
                status.phase = "refused".to_string();
                status.error = Some(error.to_string());
            }
        }
        self.jobs.last_check = Some(status);
        self.notify_status();
    }

    /// Opens the I/O and starts the job thread on a checked program.
    fn start_job(
        &mut self,
        program: JobProgram,
        check: runtime::Precheck,
        resume: Option<ResumePoint>,
        launch: Launch,
    ) -> Result<String, Refusal> {
        let config = self.config.clone();
        let spec = launch.spec(&config);
        let switch = launch.home_switch();
        let Launch { start, kind } = launch;
        let blocks = check.blocks;
        let path_total_mm = check.path_mm;
        let rapid_spans = check.rapid_spans.clone();
        let ledger = resume
            .as_ref()
            .map_or_else(|| spec.start_steps().to_vec(), |r| r.position.clone());
        // A report of what this job runs, when the configuration asks for one. Its folder is
        // made first: a job must not learn at its end that its report has nowhere to go.
        let report = job_report(&config, &program.name)?;
        let mut io = self.jobs.job_io(&config, &check, &ledger)?;
        // A homing job's probing moves read its switch; any other job's the probe (the
        // claimed port's gap input is lent to every job).
        io.gap.home_switch(switch);
        io.recording = report.as_ref().map(|(_, recording)| recording.clone());
        let resumed = resume.is_some();
        let published = Arc::new(self.jobs.published());
        let stop = Arc::new(AtomicBool::new(false));
        let job = Job {
            program: PathBuf::from(&program.name),
            program_sha256: program.sha256.clone(),
            published: published.clone(),
            stop: stop.clone(),
            stop_reason: None,
            started: Instant::now(),
            resumed,
            hold_checkpointed: false,
            last_checkpoint: Instant::now(),
            overruns_seen: 0,
            last_overrun_report: Instant::now(),
            config: config.clone(),
            report,
            motion_settings: checkpoint::motion_settings(&self.keys),
            progress: runtime::ProgressTracker::with_rapids(
                path_total_mm,
                rapid_spans,
                spec.plan.rapid_feed,
            ),
            resumed_from: if resumed {
                self.checkpoints.current.clone()
            } else {
                None
            },
            start,
            leaves: (check.work_offsets.clone(), check.work_system),
            modes: check.modes,
            kind,
        };
        // Write-ahead: before the first step the checkpoint on disk says this job is moving,
        // from where it starts; a job that cannot record that does not start.
        let old = self.checkpoints.current.clone();
        let at = super::checkpoints::write_ahead_point(resume.as_ref(), &spec, &config);
        self.homing_started(switch.as_ref());
        if let Err(refusal) = self.machine.save(true) {
            self.jobs.give_back_io(&config, io.output, io.gap);
            return Err(refusal);
        }
        if let Err(error) = self.checkpoints.write(&job, &at, Reason::Moving, false) {
            self.jobs.give_back_io(&config, io.output, io.gap);
            return Err(Refusal::WriteAhead {
                error,
                consequence: "the job does not start without its checkpoint",
            });
        }
        // A new program replaces the checkpoint of an old one, and only now that it really
        // starts (a jog, MDI, homing or a dry run leave it alone).
        let mut message = String::new();
        if !resumed
            && kind == JobKind::Program
            && let Some(old) = old
        {
            tracing::warn!(
                "checkpoint of {} (line {}) replaced: a new job starts",
                old.program.display(),
                old.line
            );
            message = format!(
                "; the checkpoint of {} was discarded",
                old.program.display()
            );
        }
        self.prune_copies(Some(&program.sha256));
        let (fine, tx) = (self.jobs.fine.clone(), self.clients.to_core.clone());
        let (job_published, job_stop, job_program) =
            (published.clone(), stop.clone(), program.clone());
        std::thread::Builder::new()
            .name("edmd-job".to_string())
            .spawn(move || {
                let job = runtime::JobRun {
                    program: &job_program,
                    check: &check,
                    spec: &spec,
                    resume,
                };
                let end = runtime::run(&fine, job, io, job_published, &job_stop);
                let _ = tx.send(CoreMsg::JobDone(Box::new(end)));
            })
            .map_err(Refusal::JobThread)?;
        self.jobs.job = Some(job);
        Ok(started(&program.name, blocks, resumed, kind, &message))
    }

    pub(super) fn hold(&mut self) -> Result<String, Refusal> {
        let Some(job) = &mut self.jobs.job else {
            return Err(Refusal::NoJob);
        };
        if job.stop.load(Ordering::Relaxed) {
            return Err(Refusal::Stopping);
        }
        if job.published.hold.swap(true, Ordering::Relaxed) {
            return Ok("already held".to_string());
        }
        job.published.holds.fetch_add(1, Ordering::Relaxed);
        job.hold_checkpointed = false;
        job.report_event(EventKind::Hold);
        tracing::info!(
            edmd_event = "hold",
            edmd_program = job.program.display().to_string(),
            "hold: {} braking to a standstill",
            job.program.display()
        );
        Ok("holding: braking to a standstill".to_string())
    }

    pub(super) fn resume(&mut self, force: bool) -> Result<String, Refusal> {
        if let Some(mut job) = self.jobs.job.take() {
            let released = self.release(&mut job);
            self.jobs.job = Some(job);
            return released;
        }
        self.refuse_if_busy()?;
        self.refuse_if_tripped(None)?;
        let Some(cp) = self.checkpoints.current.clone() else {
            return Err(Refusal::NothingToResume {
                why: match &self.checkpoints.read_error {
                    Some(e) => e.clone(),
                    None => format!(
                        "no job and no checkpoint ({})",
                        self.config.daemon.checkpoint.display()
                    ),
                },
            });
        };
        cp.check_resumable(&self.config, &self.keys, force)?;
        let axes = self.config.machine.axes.len();
        if cp.position_steps.len() != axes {
            return Err(Refusal::AxisCount {
                found: cp.position_steps.len(),
                machine: axes,
            });
        }
        let point = ResumePoint {
            here: crate::servo::PathPoint {
                seq: cp.segment,
                event: cp.step,
            },
            position: cp.position_steps.clone(),
            dwell_s: cp.dwell_s,
            line: cp.line,
        };
        // The private copy the checkpoint's job ran, if it is still there: the very bytes,
        // whatever became of the original. Otherwise the original, copied again and held to
        // the checkpoint's hash.
        let copy = program::copy_path(&self.copy_dir(), &cp.program_sha256);
        let source = match std::fs::metadata(&copy) {
            Ok(meta) if meta.is_file() => Source::Copy(JobProgram {
                path: copy,
                name: cp.program.display().to_string(),
                sha256: cp.program_sha256.clone(),
                bytes: meta.len(),
            }),
            _ => Source::Original(confine(
                &self.config.daemon.program_dir,
                &cp.program.display().to_string(),
            )?),
        };
        let start = self.resume_start(&cp, force)?;
        let resume = Resume {
            point,
            sha256: cp.program_sha256.clone(),
        };
        let launch = Launch {
            start,
            kind: JobKind::Program,
        };
        let id = self.begin_check(source, Some(resume), launch);
        Ok(format!(
            "accepted: checking {} (check {id}) to resume it from line {} (segment {}, step {})",
            cp.program.display(),
            cp.line,
            cp.segment,
            cp.step
        ))
    }

    /// `resume` of a held job: the checkpoint becomes a moving one first (write-ahead), then
    /// the hold is released.
    fn release(&mut self, job: &mut Job) -> Result<String, Refusal> {
        if job.stop.load(Ordering::Relaxed) {
            return Err(Refusal::Stopping);
        }
        let snap = job.published.snapshot();
        if snap.state == ServoState::WireBroken {
            return Err(Refusal::WireBroken);
        }
        if !job.published.hold.load(Ordering::Acquire) {
            return Err(Refusal::NotHeld);
        }
        self.checkpoints
            .write(job, &snap, Reason::Moving, false)
            .map_err(|error| Refusal::WriteAhead {
                error,
                consequence: "the job stays held",
            })?;
        self.machine.save(true)?;
        job.published.hold.store(false, Ordering::Release);
        job.hold_checkpointed = false;
        job.last_checkpoint = Instant::now();
        job.published.paused_line.store(0, Ordering::Relaxed);
        job.report_event(EventKind::Released);
        tracing::info!("resume: {} released", job.program.display());
        Ok("resumed".to_string())
    }

    /// After a wire break: back to the start hole along the path (or threading in place);
    /// `resume` then returns to the break point.
    pub(super) fn rethread(&mut self, here: bool) -> Result<String, Refusal> {
        let Some(mut job) = self.jobs.job.take() else {
            return Err(Refusal::NoJob);
        };
        let result = self.rethread_job(&mut job, here);
        self.jobs.job = Some(job);
        result
    }

    fn rethread_job(&mut self, job: &mut Job, here: bool) -> Result<String, Refusal> {
        if job.stop.load(Ordering::Relaxed) {
            return Err(Refusal::Stopping);
        }
        let snap = job.published.snapshot();
        if snap.state != ServoState::WireBroken {
            return Err(Refusal::WireNotBroken { state: snap.state });
        }
        if !here {
            // The way back to the start hole leaves the standstill: write-ahead.
            self.checkpoints
                .write(job, &snap, Reason::Moving, false)
                .map_err(|error| Refusal::WriteAhead {
                    error,
                    consequence: "the wire stays where it broke",
                })?;
            self.machine.save(true)?;
            job.last_checkpoint = Instant::now();
        }
        let (request, message) = if here {
            (
                Rethread::Here,
                "thread the wire where it broke, then `edmd ctl resume`",
            )
        } else {
            (
                Rethread::AtStart,
                "going back along the path to the start hole (spark off); thread the wire \
                 there, then `edmd ctl resume`",
            )
        };
        // The request first, then the hold's release: the consumer takes them in that order.
        job.published.rethread.ask(request);
        if !here {
            job.published.hold.store(false, Ordering::Release);
        }
        job.hold_checkpointed = false;
        job.report_event(EventKind::Rethread);
        tracing::info!(
            edmd_event = "rethread",
            edmd_program = job.program.display().to_string(),
            "rethread: {}: {message}",
            job.program.display()
        );
        Ok(format!("rethread: {message}"))
    }

    pub(super) fn abort(&mut self) -> Result<String, Refusal> {
        if let Some(check) = &self.jobs.check {
            check.progress.cancel();
            tracing::info!("abort: check {} of {} cancelled", check.id, check.name);
            return Ok(format!("cancelling the check of {}", check.name));
        }
        let Some(job) = &mut self.jobs.job else {
            return Err(Refusal::NoJob);
        };
        job.stop_reason.get_or_insert(Reason::Abort);
        job.stop.store(true, Ordering::Relaxed);
        job.report_event(EventKind::Abort);
        tracing::info!("abort: {} braking to a standstill", job.program.display());
        Ok("aborting: braking to a standstill, then the job ends".to_string())
    }

    // ---- signals --------------------------------------------------------------------------

    pub(super) fn on_job_done(&mut self, end: JobEnd) {
        let Some(job) = self.jobs.job.take() else {
            return;
        };
        self.jobs.finished = self.jobs.finished.plus(&super::status::job_counters(
            &job.published,
            &job.published.snapshot(),
        ));
        self.jobs.give_back_io(&job.config, end.output, end.gap);
        if job.kind != JobKind::Program {
            self.jobs.continuous = None;
        }
        let summary = end.summary;
        let text = summary.text();
        let mut lines = text.lines();
        let head = lines.next().unwrap_or_default();
        match summary.outcome {
            Outcome::Done => tracing::info!(
                edmd_event = "job_end",
                edmd_program = summary.program,
                "job end: {head}"
            ),
            // An operator's abort or stop, or a signal's: asked for, not a fault.
            Outcome::Stopped => tracing::warn!(
                edmd_event = "job_end",
                edmd_program = summary.program,
                "job end: {head}"
            ),
            _ => tracing::error!(
                edmd_event = "job_end",
                edmd_program = summary.program,
                "job end: {head}{}",
                summary
                    .error
                    .as_ref()
                    .map(|e| format!(": {e}"))
                    .unwrap_or_default()
            ),
        }
        for line in lines {
            tracing::info!("job end: {line}");
        }
        self.checkpoints.settle(&job, end.stopped_at, &summary);
        let ran_to_the_end = summary.outcome == Outcome::Done;
        // The ledger the drives received (a failed write's steps taken back out).
        let mut at = end.stopped_at.position;
        for (p, s) in at.iter_mut().zip(&summary.end_steps) {
            *p = *s;
        }
        self.machine
            .stopped(&at, ran_to_the_end.then(|| job.leaves.clone()));
        if ran_to_the_end && job.kind == JobKind::Mdi {
            self.machine.mdi_modes = job.modes;
        }
        self.note_trip(&job, &summary);
        if let JobKind::Home { switch, .. } = job.kind {
            self.homing_done(&switch, &summary);
        }
        if let Some((dir, recording)) = &job.report {
            match crate::report::write_report(dir, &mut recording.lock(), &summary) {
                Ok(()) => tracing::info!("job report: {}", dir.display()),
                Err(e) => tracing::error!("{e}"),
            }
        }
        self.jobs.last = Some(summary);
        self.prune_copies(None);
        self.notify_status();
    }
}
