//! The control loop's commands to a job: `hold`, `resume` (of a hold, or of the checkpoint,
//! whose check `start.rs` runs), `rethread`, `abort`, and what happens when a job ends: the
//! checkpoint written at a standstill, or removed when the job is done. A job's I/O is opened
//! here, or lent by the fine thread (the claimed parallel port or HAL component). What a job's
//! end means to the command that launched it (a homing sequence's next axis, a touch cycle's
//! next move) and the braking of a continuous jog are here too.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Instant;

use super::checkpoints::CheckpointKeeper;
use super::desk;
use super::launch::{JobKind, Launch, Source};
use super::names::confine;
use super::protocol;
use super::refusal::Refusal;
use super::{Core, Job};
use crate::checkpoint::Reason;
use crate::config::Config;
use crate::record::EventKind;
use crate::runtime::program::{self, JobProgram, Progress};
use crate::runtime::{self, FineThread, JobEnd, JobError, JobIo, JobSummary, Outcome, ResumePoint};
use crate::servo::{Rethread, ServoState};
use crate::vocab::HomeSwitch;

/// A resume waiting for its check: where to resume, and the bytes it must be.
pub(super) struct Resume {
    pub(super) point: ResumePoint,
    pub(super) sha256: String,
}

/// The check in progress.
pub(super) struct Check {
    pub(super) id: u64,
    /// The program as the operator named it.
    pub(super) name: String,
    pub(super) progress: Arc<Progress>,
    pub(super) resume: Option<Resume>,
}

impl Job {
    /// An operator's event (a hold, its release) into the job's report, at the tick and
    /// line the job has reached.
    fn report_event(&self, kind: EventKind) {
        let snap = self.published.snapshot();
        self.recording
            .lock()
            .event(snap.tick, snap.line, kind, None);
    }
}

impl Check {
    pub(super) fn is_resume(&self) -> bool {
        self.resume.is_some()
    }
}

/// The jobs: the fine thread that runs them (and keeps the claimed device), the job running,
/// the check before the next one, and what the ended ones left (the last summary, the
/// counts).
pub(super) struct JobControl {
    pub fine: Arc<FineThread>,
    pub job: Option<Job>,
    /// The program being copied and checked before its job starts.
    pub check: Option<Check>,
    /// The verdict of the last check.
    pub last_check: Option<protocol::CheckStatus>,
    /// The continuous jog in progress (being checked or moving), its dead-man and the
    /// latched one whose renewals are refused.
    pub pendant: desk::pendant::Pendant,
    pub next_check_id: u64,
    pub last: Option<JobSummary>,
    /// Counts of the jobs that ended (the running one's are added when asked).
    pub finished: protocol::Counters,
    /// The operator's controls (overrides, single block): the running job's, and every
    /// job's from its start.
    pub controls: crate::runtime::controls::Controls,
    /// The running or last job's recording, shared with the web page.
    pub executed: super::http::executed::ExecutedSlot,
}

impl JobControl {
    /// Removes the program copies no job, check or checkpoint needs; `starting` is the copy
    /// (SHA-256) of a job about to start.
    pub(super) fn prune_copies(
        &self,
        checkpoints: &CheckpointKeeper,
        checkpoint: &Path,
        starting: Option<&str>,
    ) {
        let jobs: Vec<&str> = starting
            .into_iter()
            .chain(self.job.as_ref().map(|j| j.program_sha256.as_str()))
            .collect();
        checkpoints.prune_copies(checkpoint, &jobs, self.check.is_some());
    }

    /// The job's output and gap source: the claimed device's (lent by the fine thread as
    /// it is: wrappers would stay on it after the job), or opened now.
    pub(super) fn job_io(
        &mut self,
        config: &Config,
        check: &runtime::Precheck,
        start: &[i64],
    ) -> Result<JobIo, JobError> {
        let tracer = (config.output.trace || config.gap.trace).then(|| {
            crate::trace::Tracer::new(4096, config.fine.virtual_time, Some(std::thread::current()))
        });
        let io = |output, gap: Option<runtime::OpenedGap>, inputs, tracer| {
            let (gap, gap_inputs) = gap.map_or((None, None), |g| (Some(g.gap), g.inputs));
            JobIo {
                output,
                gap,
                inputs,
                gap_inputs,
                probe_reads: Default::default(),
                tracer,
                recording: None,
                progress: None,
            }
        };
        if self.fine.has_claim() {
            if config.output.trace || config.gap.trace || config.output.fault_at_tick.is_some() {
                tracing::warn!(
                    "output.trace, gap.trace and output.fault_at_tick are not applied to the \
                     daemon's claimed device"
                );
            }
            let gap = if config.gap.kind.from_output_device() {
                None
            } else {
                Some(runtime::open_gap(config, check, None)?)
            };
            return Ok(io(None, gap, None, None));
        }
        let opened = runtime::open_output(config, start)?;
        let mut gap = runtime::open_gap(config, check, opened.port_gap)?;
        let output;
        (output, gap.gap) = runtime::wrap_io(config, opened.output, gap.gap, tracer.as_ref());
        Ok(io(Some(output), Some(gap), Some(opened.inputs), tracer))
    }
}

impl Core {
    pub(super) fn hold(&mut self) -> Result<String, Refusal> {
        if self.hold_ends_jog() {
            return Ok("holding: the continuous jog brakes to a standstill and ends".to_string());
        }
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
        self.desk().refuse_if_tripped(None)?;
        self.desk().refuse_if_untrusted("resume", force)?;
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
        let copy = program::copy_path(
            &super::checkpoints::copy_dir(&self.config.daemon.checkpoint),
            &cp.program_sha256,
        );
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
        let start = self.desk().resume_start(&cp, force)?;
        let resume = Resume {
            point,
            sha256: cp.program_sha256.clone(),
        };
        let launch = Launch {
            // The checkpoint's technology selected again (never the program's header: a
            // job cut without one resumes without one).
            technology: super::launch::JobTechnology::Ask(super::launch::TechAsk {
                asked: cp
                    .technology
                    .as_deref()
                    .map(|t| crate::technology::Request::parse(t, "checkpoint technology", 1, 1))
                    .transpose()
                    .map_err(|e| Refusal::BadArgument(e.to_string()))?,
                passes: None,
                tab_mm: None,
                resume: true,
                tables: self.technology.clone(),
            }),
            start,
            kind: JobKind::Program,
            recovers: None,
            cut: crate::path::CutPlan {
                from_line: cp.from_line,
                passes: cp.passes.clone(),
                tab_mm: cp.tab_mm,
                // A dry run keeps no checkpoint.
                dry_run_feed_mm_per_min: None,
                kerf_end: cp.kerf_end(),
            },
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
        self.machine.save(true).map_err(desk::unwritten)?;
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
            self.machine.save(true).map_err(desk::unwritten)?;
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
        // An abort ends a homing sequence whole: no later axis starts, whatever the one in
        // hand ends with (its latch, its final move, or the stop).
        if !self.machine.homing_queue.is_empty() {
            tracing::info!(
                "abort: the homing sequence is cancelled ({} axis(es) not started)",
                self.machine.homing_queue.len()
            );
            self.machine.homing_queue.clear();
        }
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
        let counted = super::status::job_counters(&job.published, &job.published.snapshot());
        self.jobs.finished = self.jobs.finished.plus(&counted);
        // A continuous jog that ended by itself (an E-stop, a limit switch, its end of
        // travel, an alarm): the renewals of its client, still pressing, are refused until it
        // lets go. One that `jog-stop` or the dead-man ended was taken already.
        self.jobs.pendant.stop(true, crate::sys::monotonic_ns());
        let mut summary = end.summary;
        if let JobKind::Home { switch, .. } = job.kind {
            desk::homing::say_why_it_failed(&self.config, &switch, &mut summary);
        }
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
        // A failed write is logged and shown in the status; the next one may succeed.
        let _ = self
            .machine
            .stopped(&at, ran_to_the_end.then(|| job.leaves.clone()))
            .map_err(desk::unwritten);
        if ran_to_the_end && job.kind == JobKind::Mdi {
            self.machine.mdi_modes = job.modes;
        }
        desk::trips::after_job(&self.config, &mut self.machine, &summary);
        // Before a homing sequence or a touch cycle starts its next check: that check's copy
        // is not this job's and must not be pruned.
        self.jobs
            .prune_copies(&self.checkpoints, &self.config.daemon.checkpoint, None);
        match job.kind {
            JobKind::Home { switch, .. } => self.homing_done(&switch, &summary),
            JobKind::Touch { .. } => self.find_moved(&summary),
            _ => {}
        }
        let part_height_mm = job.technology.as_ref().and_then(|t| t.part_height_mm());
        let passes = {
            let conditions: Vec<u32> = job.cut.passes.iter().map(|p| p.condition).collect();
            let rows = job
                .technology
                .as_ref()
                .map(|t| t.pass_rows())
                .unwrap_or_default();
            crate::report::pass_times(
                &job.recording.lock(),
                summary.ticks,
                &conditions,
                &rows,
                part_height_mm,
            )
        };
        if let Some(dir) = &job.report {
            match crate::report::write_report(dir, &mut job.recording.lock(), &summary, &passes) {
                Ok(()) => tracing::info!("job report: {}", dir.display()),
                Err(e) => tracing::error!("{e}"),
            }
        }
        // Sparking: the gap read normal or short (index 0 and 2 of the gap's tallies).
        let tick = job.config.fine.tick;
        let spark_s = tick.ticks_to_secs(counted.gap_ticks[0] + counted.gap_ticks[2]);
        let record = matches!(job.kind, JobKind::Program | JobKind::DryRun).then(|| {
            let mut record = super::history::record_of(
                &summary,
                &job.recording.lock(),
                job.started_at.clone(),
                job.kind == JobKind::DryRun,
                job.cut.from_line,
                (passes, job.technology.as_ref().map(|t| t.summary())),
                job.report.as_deref(),
            );
            record.spark_s = Some(spark_s);
            record.mean_rate_mm2_per_min = job
                .recording
                .lock()
                .cut_between(0, summary.ticks)
                .and_then(|s| crate::report::mean_rate(&s, summary.virtual_time_s, part_height_mm));
            // The program as the operator names it: below the program directory.
            if let Ok(name) = job.program.strip_prefix(&self.config.daemon.program_dir) {
                record.program = name.display().to_string();
            }
            record
        });
        self.history
            .add(record.as_ref(), summary.virtual_time_s, spark_s);
        self.jobs.last = Some(summary);
        self.notify_status();
    }
}

/// What a job's end or a hold means to the commands that launched it: the next axis of a
/// homing sequence, the next move of a touch cycle, a continuous jog braked.
impl Core {
    /// A homing job ended: the next axis starts, if the latch says so.
    pub(super) fn homing_done(&mut self, switch: &HomeSwitch, summary: &JobSummary) {
        if let Some(next) =
            desk::homing::latched(&self.config, &mut self.machine, switch, summary.into())
        {
            let job = desk::homing::axis_job(self.desk(), next);
            self.begin_check(job.source, None, job.launch);
        }
    }

    /// A touch cycle's move ended: its next move starts, if the cycle orders one.
    pub(super) fn find_moved(&mut self, summary: &JobSummary) {
        if let Some(order) = self.touch.moved(&self.config, &mut self.machine, summary) {
            self.launch(order);
        }
    }

    /// A continuous jog not renewed in time stops (from the control loop's period; the
    /// job's own thread has held it at the same deadline already).
    pub(super) fn dead_man(&mut self) {
        let held_by_job = self
            .jobs
            .job
            .as_ref()
            .is_some_and(|job| job.published.dead_man_tripped.load(Ordering::Relaxed));
        if self
            .jobs
            .pendant
            .dead_man_due(crate::sys::monotonic_ns(), held_by_job)
        {
            self.stop_continuous("not renewed for 250 ms: stopping (dead-man)", true);
        }
    }

    /// An E-stop or a limit switch ends the continuous jog (being checked or moving) for
    /// good: its client's renewals are refused until it lets go.
    pub(super) fn latch_stopped_jog(&mut self) {
        if self.jobs.pendant.is_moving() {
            self.stop_continuous("a trip ends the continuous jog", true);
        }
    }

    /// A hold ends a continuous jog: it brakes and ends, and its renewals are refused.
    fn hold_ends_jog(&mut self) -> bool {
        if !self.jobs.pendant.is_moving() {
            return false;
        }
        self.stop_continuous("held: stopping the continuous jog", true);
        true
    }

    /// Ends the continuous jog: its check is cancelled, its job braked; `latch`: its client's
    /// renewals that follow are refused.
    pub(super) fn stop_continuous(&mut self, why: &str, latch: bool) {
        self.jobs.pendant.stop(latch, crate::sys::monotonic_ns());
        if let Some(check) = &self.jobs.check {
            check.progress.cancel();
        }
        if let Some(job) = &self.jobs.job
            && matches!(job.kind, JobKind::Jog { .. })
        {
            job.stop.store(true, Ordering::Relaxed);
        }
        tracing::info!("jog: {why}");
    }
}
