//! `edmd run --state FILE`: the machine state a single job starts from and leaves behind,
//! with the daemon's write-ahead rule (marked moving before the job, the stop point after).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use super::{EXIT_BAD_INPUT, EXIT_RUNTIME};
use crate::config::Config;
use crate::gcode::{WorkOffsets, WorkSystem};
use crate::machine::MachineState;
use crate::runtime::{JobSummary, Outcome};

/// The state of one `edmd run`: from the file, or machine zero with no offsets and no file.
pub(super) struct RunState {
    pub state: MachineState,
    path: Option<PathBuf>,
}

impl RunState {
    /// Reads `path` (a missing file is machine zero) and marks it moving. `from_line`: the
    /// job cuts from a line, which is refused on a position an unclean stop left (the
    /// daemon's `--force` has no `edmd run` twin).
    pub fn open(path: Option<&Path>, cfg: &Config, from_line: bool) -> Result<RunState, ExitCode> {
        let state = match path.map(|p| MachineState::load(p, &cfg.machine)) {
            None | Some(Ok(None)) => MachineState::new(&cfg.machine),
            Some(Ok(Some(loaded)))
                if from_line && (loaded.was_moving || !loaded.state.position_trusted) =>
            {
                eprintln!(
                    "edmd: error: {}: the position is not trusted (the machine was moving when \
                     the last run stopped): a run from a line would cut from a believed place; \
                     home the machine first (`edmd serve`, `edmd ctl home`)",
                    path.map_or(String::new(), |p| p.display().to_string())
                );
                return Err(ExitCode::from(EXIT_RUNTIME));
            }
            Some(Ok(Some(loaded))) if loaded.was_moving => {
                tracing::warn!(
                    "{}: the machine was moving when the last run stopped: its position is \
                     only believed, every axis is unhomed",
                    path.map_or(String::new(), |p| p.display().to_string())
                );
                loaded.state.distrusted()
            }
            Some(Ok(Some(loaded))) => loaded.state,
            Some(Err(e)) => {
                eprintln!("edmd: error: {e}");
                return Err(ExitCode::from(EXIT_BAD_INPUT));
            }
        };
        let run = RunState {
            state,
            path: path.map(Path::to_path_buf),
        };
        run.save(true)?;
        Ok(run)
    }

    /// Writes the state (nothing without a file).
    pub fn save(&self, moving: bool) -> Result<(), ExitCode> {
        let Some(path) = &self.path else {
            return Ok(());
        };
        self.state.write(path, moving).map_err(|e| {
            eprintln!(
                "edmd: error: {}: cannot write the machine state: {e}",
                path.display()
            );
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
        for (p, s) in self.state.position.iter_mut().zip(&summary.end_steps) {
            *p = *s;
        }
        if summary.outcome == Outcome::Done {
            (self.state.offsets, self.state.system) = left;
        }
        self.save(false)
    }
}

/// The checkpoint of an `edmd run` job that stopped at `at` (a standstill: exact), in the
/// daemon's format, so that `edmd serve` resumes it.
pub(super) fn write_run_checkpoint(
    path: &Path,
    args: &super::RunArgs,
    cfg: &Config,
    summary: &JobSummary,
    at: &crate::runtime::StopPoint,
    start: &crate::gcode::WorkStart,
) -> std::io::Result<()> {
    use crate::checkpoint::{self, Checkpoint, Reason};
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
        from_line: args.cut_from(cfg),
        passes: args.cut_plan(cfg).map(|c| c.passes).unwrap_or_default(),
        tab_mm: args.cut_plan(cfg).map_or(0.0, |c| c.tab_mm),
    };
    cp.write_atomic(path)
}
