//! What the daemon keeps on disk about its jobs: the checkpoint (written ahead of motion,
//! at every standstill and end, removed when a job is done, put back when a resume is
//! refused before anything moved) and the private copies of the programs it names.

use std::path::{Path, PathBuf};

use super::refusal::CheckpointWriteError;
use super::status::mm;
use super::{Core, Job, unix_now};
use crate::checkpoint::{self, Checkpoint, Reason};
use crate::runtime::{JobSummary, Outcome, Snapshot};

/// The copies of the daemon's job programs live beside its checkpoint.
pub(super) fn copy_dir(checkpoint: &Path) -> PathBuf {
    checkpoint.with_file_name("job-programs")
}

impl Core {
    /// Where the daemon keeps the private copies of its jobs' programs: beside the checkpoint.
    pub(super) fn copy_dir(&self) -> PathBuf {
        copy_dir(&self.config.daemon.checkpoint)
    }

    /// Removes the program copies no job or checkpoint needs (and half-written ones).
    pub(super) fn prune_copies(&self, running: Option<&str>) {
        let Ok(entries) = std::fs::read_dir(self.copy_dir()) else {
            return;
        };
        let keep: Vec<String> = running
            .into_iter()
            .map(str::to_string)
            .chain(self.checkpoint.as_ref().map(|c| c.program_sha256.clone()))
            .chain(self.job.as_ref().map(|j| j.program_sha256.clone()))
            .map(|sha| format!("{sha}.nc"))
            .collect();
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().to_string();
            let ours = name.ends_with(".nc");
            let busy = self.check.is_some() && name.starts_with(".incoming-");
            if ours && !busy && !keep.contains(&name) {
                let _ = std::fs::remove_file(entry.path());
            }
        }
    }

    /// The checkpoint when a job ends: exact where it stands for every end but "done",
    /// removed when done, and when a resume was refused before anything moved, put back as
    /// it was before the job's write-ahead.
    pub(super) fn settle_checkpoint(
        &mut self,
        job: &Job,
        stopped_at: Snapshot,
        summary: &JobSummary,
    ) {
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
                let _ = self.write_checkpoint(job, &at, reason, true);
            }
            None if summary.outcome == Outcome::Done => {
                if let Err(e) = Checkpoint::remove(&checkpoint_path) {
                    tracing::error!("{}: {e}", checkpoint_path.display());
                }
                self.checkpoint = None;
            }
            None => {
                // A refused resume moved nothing: the checkpoint it started from is true
                // again, as it was.
                if let Some(cp) = &job.resumed_from {
                    match cp.write_atomic(&checkpoint_path) {
                        Ok(()) => self.checkpoint = Some(cp.clone()),
                        Err(e) => {
                            let error = CheckpointWriteError {
                                path: checkpoint_path.clone(),
                                reason: cp.reason,
                                message: e.to_string(),
                            };
                            tracing::error!("{error} (putting it back)");
                            self.checkpoint_write_error = Some(error);
                        }
                    }
                }
            }
        }
    }

    /// Writes the checkpoint of `job` at `at`. A failure is logged (once per run of equal
    /// failures), shown in the status (`checkpoint_write_error`) and returned: the caller
    /// decides whether motion may go on.
    pub(super) fn write_checkpoint(
        &mut self,
        job: &Job,
        at: &Snapshot,
        reason: Reason,
        still: bool,
    ) -> Result<(), CheckpointWriteError> {
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
                self.checkpoint = Some(cp);
                self.checkpoint_error = None;
                self.checkpoint_write_error = None;
                Ok(())
            }
            Err(e) => {
                let error = CheckpointWriteError {
                    path: path.clone(),
                    reason,
                    message: e.to_string(),
                };
                let again = self
                    .checkpoint_write_error
                    .as_ref()
                    .is_some_and(|last| last.message == error.message);
                if again {
                    tracing::debug!("{error}");
                } else {
                    tracing::error!(edmd_event = "checkpoint_failed", "{error}");
                }
                self.finished.checkpoint_failures += 1;
                self.checkpoint_write_error = Some(error.clone());
                Err(error)
            }
        }
    }
}
