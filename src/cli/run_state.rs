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
    /// Reads `path` (a missing file is machine zero) and marks it moving.
    pub fn open(path: Option<&Path>, cfg: &Config) -> Result<RunState, ExitCode> {
        let state = match path.map(|p| MachineState::load(p, &cfg.machine)) {
            None | Some(Ok(None)) => MachineState::new(&cfg.machine),
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
