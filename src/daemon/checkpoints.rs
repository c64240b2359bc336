//! What the daemon keeps on disk about its jobs: the checkpoint (written ahead of motion,
//! at every standstill and end, removed when a job is done, put back when a resume is
//! refused before anything moved) and the private copies of the programs it names.

use super::launch::JobKind;
use std::path::{Path, PathBuf};

use super::refusal::{CheckpointWriteError, Refusal};
use super::status::mm;
use super::{Job, unix_now};
use crate::checkpoint::{self, Checkpoint, Reason};
use crate::runtime::{JobSummary, Outcome, Snapshot};

/// The copies of the daemon's job programs live beside its checkpoint.
pub(super) fn copy_dir(checkpoint: &Path) -> PathBuf {
    checkpoint.with_file_name("job-programs")
}

/// The checkpoint on disk and what went wrong with it: written through here only, so the
/// status always says whether the file is the one it shows.
#[derive(Debug, Default)]
pub(super) struct CheckpointKeeper {
    /// The checkpoint as last read or written.
    pub current: Option<Checkpoint>,
    /// A stopped job's checkpoint kept aside while another program job runs (beside the
    /// checkpoint, [`parked_path`]): it is the checkpoint again once no other is, until the
    /// operator discards it.
    pub parked: Option<Checkpoint>,
    /// Why the checkpoint on disk could not be read (the reply to `resume` says so).
    pub read_error: Option<String>,
    /// Why the last write failed (cleared by the next one that succeeds).
    pub write_error: Option<CheckpointWriteError>,
    /// Writes that failed since the daemon started.
    pub failures: u64,
}

/// Where a stopped job's checkpoint is kept while another program job runs.
pub(super) fn parked_path(checkpoint: &Path) -> PathBuf {
    checkpoint.with_extension("kept.json")
}

impl CheckpointKeeper {
    /// A new program job starts (not a resume): the stopped job's checkpoint is kept aside
    /// for a later resume, not replaced; refused while one is kept aside already. The same
    /// program (`sha256`) started again from its start replaces it, as a new run of it
    /// supersedes the old one. The program kept aside, if one was.
    pub(super) fn park(
        &mut self,
        checkpoint: &Path,
        sha256: &str,
    ) -> Result<Option<String>, Refusal> {
        let Some(current) = self.current.take() else {
            return Ok(None);
        };
        if current.program_sha256 == sha256 {
            tracing::warn!(
                "checkpoint of {} (line {}) replaced: the same program starts again",
                current.program.display(),
                current.line
            );
            self.current = Some(current);
            return Ok(None);
        }
        if let Some(kept) = &self.parked {
            let error = Refusal::BothKept {
                kept: kept.program.display().to_string(),
                stopped: current.program.display().to_string(),
                line: current.line,
            };
            self.current = Some(current);
            return Err(error);
        }
        let program = current.program.display().to_string();
        let parked = parked_path(checkpoint);
        if let Err(e) = std::fs::rename(checkpoint, &parked) {
            // Not moved aside: it stays the checkpoint, and the new job's write-ahead
            // replaces it, as before keeping existed.
            tracing::error!("{}: cannot keep it aside ({e})", checkpoint.display());
            self.current = Some(current);
            return Ok(None);
        }
        tracing::info!(
            edmd_event = "checkpoint_kept",
            "checkpoint of {program} (line {}) kept aside while another job runs: {}",
            current.line,
            parked.display()
        );
        self.parked = Some(current);
        Ok(Some(program))
    }

    /// The stopped job of `program` (as the operator names it), current or kept aside.
    pub(super) fn of_program(&self, program: &Path) -> Option<&Checkpoint> {
        [&self.current, &self.parked]
            .into_iter()
            .flatten()
            .find(|cp| cp.program == program)
    }

    /// No checkpoint is current (a job ended done, one was discarded): the one kept aside is
    /// the checkpoint again.
    pub(super) fn unpark(&mut self, checkpoint: &Path) {
        if self.current.is_some() {
            return;
        }
        let Some(kept) = self.parked.take() else {
            return;
        };
        match std::fs::rename(parked_path(checkpoint), checkpoint) {
            Ok(()) => {
                tracing::info!(
                    edmd_event = "checkpoint_kept",
                    "checkpoint of {} (line {}) is the checkpoint again: `resume` continues it",
                    kept.program.display(),
                    kept.line
                );
                self.current = Some(kept);
            }
            Err(e) => {
                tracing::error!("{}: cannot put it back ({e})", checkpoint.display());
                self.parked = Some(kept);
            }
        }
    }

    /// The operator discards the checkpoint (confirmed): removed, and the one kept aside, if
    /// any, is the checkpoint again. What was discarded.
    pub(super) fn discard(&mut self, checkpoint: &Path) -> std::io::Result<Option<Checkpoint>> {
        let Some(current) = self.current.take() else {
            return Ok(None);
        };
        if let Err(e) = Checkpoint::remove(checkpoint) {
            self.current = Some(current);
            return Err(e);
        }
        tracing::warn!(
            edmd_event = "checkpoint_discarded",
            "checkpoint of {} (line {}) discarded by the operator",
            current.program.display(),
            current.line
        );
        self.unpark(checkpoint);
        Ok(Some(current))
    }

    /// Removes the program copies beside `checkpoint` that no job, check or checkpoint
    /// needs (and half-written ones): `jobs` are the copies (SHA-256) of the running job and
    /// of one about to start; `checking`: a check is reading an incoming copy.
    pub(super) fn prune_copies(&self, checkpoint: &Path, jobs: &[&str], checking: bool) {
        let Ok(entries) = std::fs::read_dir(copy_dir(checkpoint)) else {
            return;
        };
        let keep: Vec<String> = jobs
            .iter()
            .map(|sha| sha.to_string())
            .chain(self.current.as_ref().map(|c| c.program_sha256.clone()))
            .chain(self.parked.as_ref().map(|c| c.program_sha256.clone()))
            .map(|sha| format!("{sha}.nc"))
            .collect();
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().to_string();
            let ours = name.ends_with(".nc");
            let busy = checking && name.starts_with(".incoming-");
            if ours && !busy && !keep.contains(&name) {
                let _ = std::fs::remove_file(entry.path());
            }
        }
    }

    /// The checkpoint at `path` as the daemon starts: a write that did not finish is
    /// cleaned up, one that cannot be read is reported and left in place.
    pub(super) fn open(path: &Path) -> CheckpointKeeper {
        if Checkpoint::remove_leftover(path) {
            tracing::warn!(
                "{}: removed the temporary file of a checkpoint write that did not finish",
                path.display()
            );
        }
        let mut keeper = CheckpointKeeper::default();
        match Checkpoint::load(path) {
            Ok(c) => keeper.current = c,
            Err(e) => {
                tracing::error!("{e}; ignoring it (it is left in place)");
                keeper.read_error = Some(e.to_string());
            }
        }
        if let Ok(Some(kept)) = Checkpoint::load(&parked_path(path)) {
            keeper.parked = Some(kept);
            keeper.unpark(path);
        }
        if let Some(c) = &keeper.current {
            tracing::info!(
                "checkpoint: {} stopped at line {} ({}); `edmd ctl resume{}` continues it",
                c.program.display(),
                c.line,
                c.reason.name(),
                if c.still { "" } else { " --force" }
            );
        }
        keeper
    }

    /// The checkpoint when a job ends: exact where it stands for every end but "done",
    /// removed when done, and when a resume was refused before anything moved, put back as
    /// it was before the job's write-ahead.
    pub(super) fn settle(&mut self, job: &Job, stopped_at: Snapshot, summary: &JobSummary) {
        if job.kind != JobKind::Program {
            return;
        }
        let reason = Reason::of_outcome(summary.outcome, job.stop_reason);
        let checkpoint_path = job.config.daemon.checkpoint.clone();
        match reason {
            Some(reason) => {
                let mut at = stopped_at;
                // The ledger the drives received (a failed write's steps taken back out).
                for (p, s) in at.position.iter_mut().zip(&summary.end_steps) {
                    *p = *s;
                }
                // A failure is logged and in the status; the file on disk stays the moving
                // one written when motion started, which a resume refuses without --force.
                let _ = self.write(job, &at, reason, true);
            }
            None if summary.outcome == Outcome::Done => {
                if let Err(e) = Checkpoint::remove(&checkpoint_path) {
                    tracing::error!("{}: {e}", checkpoint_path.display());
                }
                self.current = None;
                self.unpark(&checkpoint_path);
            }
            None => {
                // A refused resume moved nothing: the checkpoint it started from is true
                // again, as it was.
                if let Some(cp) = &job.resumed_from {
                    match cp.write_atomic(&checkpoint_path) {
                        Ok(()) => self.current = Some(cp.clone()),
                        Err(e) => {
                            let error = CheckpointWriteError {
                                path: checkpoint_path.clone(),
                                reason: cp.reason,
                                message: e.to_string(),
                            };
                            tracing::error!("{error} (putting it back)");
                            self.write_error = Some(error);
                        }
                    }
                }
            }
        }
    }

    /// Writes the checkpoint of `job` at `at`. A failure is logged (once per run of equal
    /// failures), shown in the status (`checkpoint_write_error`) and returned: the caller
    /// decides whether motion may go on.
    pub(super) fn write(
        &mut self,
        job: &Job,
        at: &Snapshot,
        reason: Reason,
        still: bool,
    ) -> Result<(), CheckpointWriteError> {
        // A jog or MDI has no program to resume: it leaves the program's checkpoint alone
        // (a resume then checks the machine stands where that checkpoint says).
        if job.kind != JobKind::Program {
            return Ok(());
        }
        let machine = &job.config.machine;
        let axes = machine.axes.len();
        let cp = Checkpoint {
            version: checkpoint::VERSION,
            program: job.program.clone(),
            program_sha256: job.program_sha256.clone(),
            motion_sha256: checkpoint::motion_hash(&job.config),
            motion_settings: job.motion_settings.clone(),
            reason,
            still,
            line: at.line,
            segment: at.here.seq,
            step: at.here.event,
            segment_steps: at.events,
            parameter: at.u_end.is_finite().then_some(at.u_end),
            dwell_s: job.config.fine.tick.ticks_to_secs(at.dwell_left),
            axes: machine.axis_names(),
            position_steps: at.position[..axes].to_vec(),
            position_mm: mm(&at.position[..axes], &machine.step_mm),
            written_unix_s: unix_now(),
            start: Some(checkpoint::StartRecord::new(
                &job.start,
                &machine.axes,
                &machine.step_mm,
            )),
            from_line: job.cut.from_line,
            passes: job.cut.passes.clone(),
            tab_mm: job.cut.tab_mm,
            kerf_end_mm: checkpoint::kerf_end_record(&job.cut, axes),
            technology: job.technology.as_ref().map(|t| t.request.text()),
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
                let program = cp.program.display().to_string();
                if reason == Reason::Periodic {
                    tracing::debug!(edmd_event = "checkpoint", edmd_program = program, "{log}");
                } else {
                    tracing::info!(edmd_event = "checkpoint", edmd_program = program, "{log}");
                }
                self.current = Some(cp);
                self.read_error = None;
                self.write_error = None;
                Ok(())
            }
            Err(e) => {
                let error = CheckpointWriteError {
                    path: path.clone(),
                    reason,
                    message: e.to_string(),
                };
                let again = self
                    .write_error
                    .as_ref()
                    .is_some_and(|last| last.message == error.message);
                if again {
                    tracing::debug!("{error}");
                } else {
                    tracing::error!(edmd_event = "checkpoint_failed", "{error}");
                }
                self.failures += 1;
                self.write_error = Some(error.clone());
                Err(error)
            }
        }
    }
}

/// Where the write-ahead checkpoint of a starting job puts it: moving, at the program's start
/// or at the resume point with the dwell it owes.
pub(super) fn write_ahead_point(
    resume: Option<&crate::runtime::ResumePoint>,
    spec: &crate::runtime::JobSpec,
    config: &crate::config::Config,
) -> Snapshot {
    let mut at = Snapshot {
        still: false,
        position: spec.start_steps(),
        ..Snapshot::default()
    };
    if let Some(r) = resume {
        at.here = r.here;
        at.line = r.line;
        at.dwell_left = (r.dwell_s / config.fine.tick.secs()).round() as u64;
        for (p, s) in at.position.iter_mut().zip(&r.position) {
            *p = *s;
        }
    }
    at
}
