//! `edmd run --state FILE`: the machine state a single job starts from and leaves behind,
//! with the daemon's write-ahead rule (marked moving before the job, the stop point after).

use std::path::Path;
use std::process::ExitCode;

use super::{EXIT_BAD_INPUT, EXIT_RUNTIME};
use crate::config::Config;
use crate::gcode::{WorkOffsets, WorkStart, WorkSystem};
use crate::machine::{Admission, Found, Machine, OpenError};
use crate::runtime::{JobSummary, Outcome};

/// The state of one `edmd run`: the machine of the file (the daemon's write-ahead path,
/// [`Machine`]), or machine zero with no offsets and no file.
pub(super) struct RunState {
    machine: Machine,
}

impl RunState {
    /// Reads `path` (a missing file is machine zero) and marks it moving. `from_line`: the
    /// job cuts from a line, which is refused on a position an unclean stop left (the
    /// daemon's `--force` has no `edmd run` twin).
    pub fn open(path: Option<&Path>, cfg: &Config, from_line: bool) -> Result<RunState, ExitCode> {
        let shown = path.map_or(String::new(), |p| p.display().to_string());
        let (machine, found) = Machine::open(path, &cfg.machine).map_err(|e| {
            eprintln!("edmd: error: {e}");
            ExitCode::from(match e {
                OpenError::Read(_) => EXIT_BAD_INPUT,
                OpenError::Write(_) => EXIT_RUNTIME,
            })
        })?;
        let continued = machine.admit(Admission::Continue {
            homing_required: false,
        });
        if from_line && continued.is_err() {
            eprintln!(
                "edmd: error: {shown}: the position is not trusted (the machine was moving when \
                 the last run stopped): a run from a line would cut from a believed place; \
                 home the machine first (`edmd serve`, `edmd ctl home`)"
            );
            return Err(ExitCode::from(EXIT_RUNTIME));
        }
        if found == Found::Moving {
            tracing::warn!(
                "{shown}: the machine was moving when the last run stopped: its position is \
                 only believed, every axis is unhomed"
            );
        }
        let mut run = RunState { machine };
        run.save(true)?;
        Ok(run)
    }

    /// Where the job starts: the machine's work system and offsets.
    pub fn work_start(&self) -> WorkStart {
        self.machine.state.work_start()
    }

    /// Writes the state (nothing without a file).
    pub fn save(&mut self, moving: bool) -> Result<(), ExitCode> {
        self.machine.save(moving).map_err(|e| {
            eprintln!("edmd: error: {e}");
            ExitCode::from(EXIT_RUNTIME)
        })
    }

    /// The job stopped where `summary` says; a job that ran to its end leaves the work
    /// offsets and system its program set.
    pub fn stopped(
        &mut self,
        summary: &JobSummary,
        left: (WorkOffsets, WorkSystem),
    ) -> Result<(), ExitCode> {
        let mut at = self.machine.state.position;
        for (p, s) in at.iter_mut().zip(&summary.end_steps) {
            *p = *s;
        }
        let left = (summary.outcome == Outcome::Done).then_some(left);
        self.machine.stopped(&at, left).map_err(|e| {
            eprintln!("edmd: error: {e}");
            ExitCode::from(EXIT_RUNTIME)
        })
    }
}

/// The checkpoint of an `edmd run` job that stopped at `at` (a standstill: exact), in the
/// daemon's format, so that `edmd serve` resumes it.
pub(super) fn write_run_checkpoint(
    path: &Path,
    args: &super::RunArgs,
    job: &super::cut::CliJob,
    summary: &JobSummary,
    at: &crate::runtime::StopPoint,
    start: &crate::gcode::WorkStart,
) -> std::io::Result<()> {
    use crate::checkpoint::{self, Checkpoint, Reason};
    let cfg = &job.cfg;
    let keys = Config::load_with_keys(args.config.source().0.as_deref(), &args.config.set)
        .map(|(_, keys)| keys)
        .unwrap_or_default();
    // Only a job that did not finish leaves a checkpoint, so there is a reason.
    let reason = Reason::of_outcome(summary.outcome, None).unwrap_or(Reason::Error);
    let unix_now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let cp = Checkpoint {
        version: checkpoint::VERSION,
        program: std::fs::canonicalize(&args.program)?,
        program_sha256: at.program_sha256.clone(),
        motion_sha256: checkpoint::motion_hash(cfg),
        motion_settings: checkpoint::motion_settings(&keys),
        reason,
        still: true,
        line: at.line,
        segment: at.segment,
        step: at.step,
        segment_steps: at.segment_steps,
        parameter: at.parameter,
        dwell_s: at.dwell_s,
        axes: cfg.machine.axis_names(),
        position_steps: summary.end_steps.clone(),
        position_mm: summary.end_mm.clone(),
        written_unix_s: unix_now,
        start: Some(checkpoint::StartRecord::new(
            start,
            &cfg.machine.axes,
            &cfg.machine.step_mm,
        )),
        from_line: job.cut.from_line,
        passes: job.cut.passes.clone(),
        tab_mm: job.cut.tab_mm,
        kerf_end_mm: checkpoint::kerf_end_record(&job.cut, cfg.machine.axes.len()),
        technology: job.technology.as_ref().map(|t| t.request.text()),
    };
    cp.write_atomic(path)
}
