//! The control loop's job commands: `run` (confine, precheck, open the devices, start the job
//! thread), `hold`, `resume` (of a hold, or of the checkpoint), `abort`, and what happens
//! when a job ends: the checkpoint written at a standstill, or removed when the job is done.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use super::status::mm;
use super::{Core, CoreMsg, Job, confine, unix_now};
use crate::checkpoint::{self, Checkpoint, Reason};
use crate::config::{Config, GapKind, OutputKind};
use crate::runtime::{self, JobEnd, JobError, JobIo, Outcome, Published, ResumePoint, Snapshot};

impl Core {
    pub(super) fn run_program(&mut self, requested: &str) -> Result<String, String> {
        self.refuse_if_busy()?;
        let program = confine(&self.config.daemon.program_dir, requested)?;
        let mut message = String::new();
        if let Some(old) = self.checkpoint.take() {
            tracing::warn!(
                "checkpoint of {} (line {}) discarded: a new job starts",
                old.program.display(),
                old.line
            );
            if let Err(e) = Checkpoint::remove(&self.config.daemon.checkpoint) {
                tracing::error!("{}: {e}", self.config.daemon.checkpoint.display());
            }
            message = format!(
                "; the checkpoint of {} was discarded",
                old.program.display()
            );
        }
        let blocks = self.start_job(program.clone(), None)?;
        Ok(format!(
            "running {}: {blocks} blocks{message}",
            program.display()
        ))
    }

    /// Checks, opens the I/O and starts the job thread. Returns the program's block count.
    pub(super) fn start_job(
        &mut self,
        program: PathBuf,
        resume: Option<ResumePoint>,
    ) -> Result<u64, String> {
        let config = self.config.clone();
        let program_sha256 =
            checkpoint::sha256_file(&program).map_err(|e| format!("{}: {e}", program.display()))?;
        let check = runtime::precheck(&program, &config).map_err(|e| e.to_string())?;
        let blocks = check.blocks;
        let start = resume
            .as_ref()
            .map(|r| r.position.clone())
            .unwrap_or_default();
        let io = self
            .job_io(&config, &check, &start)
            .map_err(|e| e.to_string())?;
        let published = Arc::new(Published::new(4096));
        let stop = Arc::new(AtomicBool::new(false));
        let resumed = resume.is_some();
        let (fine, tx) = (self.fine.clone(), self.to_core.clone());
        let (job_published, job_stop, job_config, job_program) = (
            published.clone(),
            stop.clone(),
            config.clone(),
            program.clone(),
        );
        std::thread::Builder::new()
            .name("edmd-job".to_string())
            .spawn(move || {
                let end = runtime::run_job_with(
                    &fine,
                    &job_program,
                    &job_config,
                    &check,
                    io,
                    job_published,
                    &job_stop,
                    resume,
                );
                let _ = tx.send(CoreMsg::JobDone(Box::new(end)));
            })
            .map_err(|e| format!("cannot start the job thread: {e}"))?;
        tracing::info!(
            "job start: {}{}",
            program.display(),
            if resumed { " (resumed)" } else { "" }
        );
        self.job = Some(Job {
            program,
            program_sha256,
            published,
            stop,
            stop_reason: None,
            started: Instant::now(),
            resumed,
            hold_checkpointed: false,
            last_checkpoint: Instant::now(),
            overruns_seen: 0,
            last_overrun_report: Instant::now(),
            config,
        });
        Ok(blocks)
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
        })
    }

    pub(super) fn hold(&mut self) -> Result<String, String> {
        let Some(job) = &mut self.job else {
            return Err("no job is running".to_string());
        };
        if job.stop.load(Ordering::Relaxed) {
            return Err("the job is stopping".to_string());
        }
        if job.published.hold.swap(true, Ordering::Relaxed) {
            return Ok("already held".to_string());
        }
        job.hold_checkpointed = false;
        tracing::info!("hold: {} braking to a standstill", job.program.display());
        Ok("holding: braking to a standstill".to_string())
    }

    pub(super) fn resume(&mut self, force: bool) -> Result<String, String> {
        if let Some(job) = &mut self.job {
            if job.stop.load(Ordering::Relaxed) {
                return Err("the job is stopping".to_string());
            }
            if !job.published.hold.swap(false, Ordering::Relaxed) {
                return Err("the job is not held".to_string());
            }
            job.hold_checkpointed = false;
            tracing::info!("resume: {} released", job.program.display());
            return Ok("resumed".to_string());
        }
        self.refuse_if_busy()?;
        let Some(cp) = self.checkpoint.clone() else {
            return Err(format!(
                "nothing to resume: no job and no checkpoint ({})",
                self.config.daemon.checkpoint.display()
            ));
        };
        let program = confine(
            &self.config.daemon.program_dir,
            &cp.program.display().to_string(),
        )?;
        cp.check_resumable(&self.config, force)
            .map_err(|e| e.to_string())?;
        let axes = self.config.machine.axes.len();
        if cp.position_steps.len() != axes {
            return Err(format!(
                "the checkpoint has {} axes, the machine {axes}",
                cp.position_steps.len()
            ));
        }
        let point = ResumePoint {
            here: crate::servo::PathPoint {
                seq: cp.segment,
                event: cp.step,
            },
            position: cp.position_steps.clone(),
        };
        self.start_job(program.clone(), Some(point))?;
        Ok(format!(
            "resuming {} from line {} (segment {}, step {})",
            program.display(),
            cp.line,
            cp.segment,
            cp.step
        ))
    }

    pub(super) fn abort(&mut self) -> Result<String, String> {
        let Some(job) = &mut self.job else {
            return Err("no job is running".to_string());
        };
        job.stop_reason.get_or_insert(Reason::Abort);
        job.stop.store(true, Ordering::Relaxed);
        tracing::info!("abort: {} braking to a standstill", job.program.display());
        Ok("aborting: braking to a standstill, then the job ends".to_string())
    }

    // ---- signals --------------------------------------------------------------------------

    pub(super) fn on_job_done(&mut self, end: JobEnd) {
        let Some(job) = self.job.take() else {
            return;
        };
        if job.config.output.kind == OutputKind::Parport {
            self.port_output = Some(end.output);
        }
        if job.config.gap.kind == GapKind::Parport {
            self.port_gap = Some(end.gap);
        }
        let summary = end.summary;
        let reason = match summary.outcome {
            Outcome::Done => None,
            Outcome::ResumeRefused => None,
            Outcome::Alarm => Some(Reason::Alarm),
            Outcome::Stopped => Some(job.stop_reason.unwrap_or(Reason::Stop)),
            Outcome::OutputError | Outcome::GapError | Outcome::ProducerError => {
                Some(Reason::Error)
            }
        };
        let text = summary.text();
        let mut lines = text.lines();
        let head = lines.next().unwrap_or_default();
        match summary.outcome {
            Outcome::Done => tracing::info!("job end: {head}"),
            _ => tracing::error!(
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
        let checkpoint_path = job.config.daemon.checkpoint.clone();
        match reason {
            Some(reason) => {
                let mut at = end.stopped_at;
                // The ledger the drives received (a failed write's steps taken back out).
                for (p, s) in at.position.iter_mut().zip(&summary.end_steps) {
                    *p = *s;
                }
                self.write_checkpoint(&job, &at, reason, true);
            }
            None if summary.outcome == Outcome::Done => {
                if let Err(e) = Checkpoint::remove(&checkpoint_path) {
                    tracing::error!("{}: {e}", checkpoint_path.display());
                }
                self.checkpoint = None;
            }
            None => {}
        }
        self.last = Some(summary);
        self.notify_status();
    }

    pub(super) fn write_checkpoint(
        &mut self,
        job: &Job,
        at: &Snapshot,
        reason: Reason,
        still: bool,
    ) {
        let machine = &job.config.machine;
        let axes = machine.axes.len();
        let cp = Checkpoint {
            version: checkpoint::VERSION,
            program: job.program.clone(),
            program_sha256: job.program_sha256.clone(),
            motion_sha256: checkpoint::motion_hash(&job.config),
            reason,
            still,
            line: at.line,
            segment: at.here.seq,
            step: at.here.event,
            segment_steps: at.events,
            parameter: at.u_end.is_finite().then_some(at.u_end),
            axes: machine.axis_names(),
            position_steps: at.position[..axes].to_vec(),
            position_mm: mm(&at.position[..axes], &machine.step_mm),
            written_unix_s: unix_now(),
        };
        let path = &job.config.daemon.checkpoint;
        match cp.write_atomic(path) {
            Ok(()) => {
                let log = format!(
                    "checkpoint ({}): {} line {}, segment {} step {}, at {:?} steps -> {}",
                    reason.name(),
                    cp.program.display(),
                    cp.line,
                    cp.segment,
                    cp.step,
                    cp.position_steps,
                    path.display()
                );
                if reason == Reason::Periodic {
                    tracing::debug!("{log}");
                } else {
                    tracing::info!("{log}");
                }
                self.checkpoint = Some(cp);
            }
            Err(e) => tracing::error!("{}: cannot write the checkpoint: {e}", path.display()),
        }
    }
}
