//! What a check starts from and what it reads: the program's source (the operator's file,
//! a checkpoint's copy, text the daemon made for a jog or MDI), where the job starts and what
//! kind of job it is; and the check worker that copies and prechecks on its own thread.

use std::path::{Path, PathBuf};

use super::refusal::CheckRefusal;
use crate::checkpoint;
use crate::config::Config;
use crate::gcode::WorkStart;
use crate::runtime;
use crate::runtime::program::{self, JobProgram, Progress};

/// A program copied and checked: ready to run.
pub(super) type Checked = (JobProgram, runtime::Precheck);

/// What a check reads.
pub(super) enum Source {
    /// The operator's file: copied first.
    Original(PathBuf),
    /// A private copy already made (a checkpoint's).
    Copy(JobProgram),
    /// Program text the daemon made (a jog, MDI lines), named `name` in errors.
    Generated { text: String, name: String },
}

/// What a job is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum JobKind {
    /// A program the operator named (or a checkpoint's).
    Program,
    /// A program proved without cutting: spark off, the servo out of the loop, the planned
    /// feed. It keeps no checkpoint (a resume must never cut what a dry run left).
    DryRun,
    /// A jog: one positioning move (spark off) at this feed, mm/min.
    Jog { feed_mm_per_min: f64 },
    /// MDI lines.
    Mdi,
    /// Homing one axis: its probing moves read `switch`; the search feed, mm/min, is also
    /// the final move's.
    Home {
        switch: crate::vocab::HomeSwitch,
        feed_mm_per_min: f64,
    },
    /// One move of a wire-touch cycle (`find`), at its touch feed (mm/min, its back-offs'
    /// too); `first`: the cycle's first approach.
    Touch { feed_mm_per_min: f64, first: bool },
}

/// Where a job starts and what it is: decided when its check begins.
#[derive(Debug, Clone)]
pub(super) struct Launch {
    pub start: WorkStart,
    pub kind: JobKind,
    /// A program run from a line or in passes (a checkpoint of one resumes it as one).
    pub cut: crate::path::CutPlan,
}

impl Launch {
    /// The job's settings: the daemon's jobs have an operator (programmed stops, collisions
    /// and alarms hold), start where the launch says, and a jog's or homing job's rapids go
    /// at its own feed, not the machine's rapid.
    pub fn spec(&self, config: &Config) -> runtime::JobSpec {
        let mut spec = runtime::JobSpec::from_config(config, true);
        spec.path.work = self.start.clone();
        spec.fine.dry_run = self.kind == JobKind::DryRun;
        spec.path.cut = self.cut.clone();
        if let JobKind::Jog { feed_mm_per_min }
        | JobKind::Home {
            feed_mm_per_min, ..
        }
        | JobKind::Touch {
            feed_mm_per_min, ..
        } = self.kind
        {
            spec.plan.rapid_feed_mm_per_s =
                spec.plan.rapid_feed_mm_per_s.min(feed_mm_per_min / 60.0);
        }
        spec
    }

    /// The switch a homing job's probing moves read.
    pub fn home_switch(&self) -> Option<crate::vocab::HomeSwitch> {
        match self.kind {
            JobKind::Home { switch, .. } => Some(switch),
            _ => None,
        }
    }

    /// What the job's probing moves read (`start`: the job's first ledger, in steps).
    pub fn probe_reads(&self, start: &crate::vocab::Steps) -> crate::vocab::ProbeReads {
        use crate::vocab::ProbeReads;
        match self.kind {
            JobKind::Home { switch, .. } => ProbeReads::Switch(switch),
            JobKind::Touch { first, .. } => ProbeReads::Touch {
                start: *start,
                bounce: first,
            },
            _ => ProbeReads::Probe,
        }
    }
}

/// The check worker: copy (unless already a copy), hold to the expected hash, then check.
pub(super) fn copy_and_check(
    source: Source,
    dir: &Path,
    config: &Config,
    start: &WorkStart,
    cut: &crate::path::CutPlan,
    expect: Option<&str>,
    progress: &Progress,
) -> Result<Checked, CheckRefusal> {
    let program = match source {
        Source::Original(path) => program::copy_program(&path, dir, progress)?,
        Source::Copy(program) => program,
        Source::Generated { text, name } => {
            let tmp = dir.join(format!(".{name}-{}.ngc", std::process::id()));
            std::fs::create_dir_all(dir)
                .and_then(|()| std::fs::write(&tmp, text))
                .map_err(|source| program::CopyError::Write {
                    dir: dir.to_path_buf(),
                    source,
                })?;
            let copied = program::copy_program(&tmp, dir, progress);
            let _ = std::fs::remove_file(&tmp);
            JobProgram { name, ..copied? }
        }
    };
    if let Some(expect) = expect
        && program.sha256 != expect
    {
        return Err(checkpoint::CheckpointError::ProgramChanged {
            program: PathBuf::from(&program.name),
            expected: expect.to_string(),
            found: program.sha256,
        }
        .into());
    }
    let check = runtime::precheck(&program, config, start, cut, progress)?;
    Ok((program, check))
}
