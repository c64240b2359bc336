//! What a check starts from and what it reads: the program's source (the operator's file,
//! a checkpoint's copy, text the daemon made for a jog or MDI), where the job starts and what
//! kind of job it is; and the check worker that copies and prechecks on its own thread.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::refusal::CheckRefusal;
use crate::checkpoint;
use crate::config::Config;
use crate::gcode::WorkStart;
use crate::runtime;
use crate::runtime::program::{self, JobProgram, Progress};

/// A program copied and checked: ready to run, as its launch says (with the technology
/// the check selected).
pub struct Checked {
    pub(super) program: JobProgram,
    pub(super) precheck: runtime::Precheck,
    pub(super) launch: Launch,
}

/// The technology a program job asks for: with the request, or else in the program's header
/// (`(TECH …)`), which the check reads from the private copy it made.
#[derive(Debug, Clone)]
pub(super) struct TechAsk {
    /// Given with the request (`--technology`); `None`: the header's, if it has one.
    pub asked: Option<crate::technology::Request>,
    /// `--passes N`: the first N of a wire table's passes (`None`: all of them).
    pub passes: Option<usize>,
    /// `--tab MM`: the tab this job leaves, in place of the configuration's.
    pub tab_mm: Option<f64>,
    /// A resume: the passes are the checkpoint's, which the table must still give.
    pub resume: bool,
    pub tables: Arc<crate::technology::Tables>,
}

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
    /// The technology it cuts with: asked for, then selected by the check.
    pub technology: JobTechnology,
    /// A run from a line along a stopped job's kerf: that job's program (SHA-256), which the
    /// program checked must still be.
    pub recovers: Option<String>,
}

/// A job's technology, before and after its check.
#[derive(Debug, Clone, Default)]
pub(super) enum JobTechnology {
    /// None (a jog, MDI, homing, a touch cycle; a program without one).
    #[default]
    None,
    /// To be selected by the check.
    Ask(TechAsk),
    /// What the check selected.
    Selected(Arc<crate::technology::Selection>),
}

impl JobTechnology {
    /// What was selected.
    pub fn selected(&self) -> Option<&crate::technology::Selection> {
        match self {
            JobTechnology::Selected(s) => Some(s),
            _ => None,
        }
    }
}

impl Launch {
    /// The job's configuration: the daemon's, with the selected technology's conditions and
    /// passes.
    pub fn job_config(&self, config: &Config) -> Config {
        let mut config = config.clone();
        if let Some(selected) = self.technology.selected() {
            selected.apply(&mut config);
        }
        config
    }

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
    mut launch: Launch,
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
    if let Some(expected) = &launch.recovers
        && program.sha256 != *expected
    {
        return Err(CheckRefusal::KerfOfAnother {
            program: program.name,
            expected: expected.clone(),
            found: program.sha256,
        });
    }
    let mut config = config.clone();
    if let JobTechnology::Ask(ask) = std::mem::take(&mut launch.technology) {
        select_technology(&program, &mut config, &mut launch, ask)?;
    }
    let check = runtime::precheck(&program, &config, &launch.start, &launch.cut, progress)?;
    Ok(Checked {
        program,
        precheck: check,
        launch,
    })
}

/// The technology a program job cuts with, applied to its configuration and its cut: the
/// one asked for, else its header's (a resume: the checkpoint's, never the header's); then
/// the passes (`--passes N`: the first N; a wire table's: all by default) of the table in
/// force, unless it runs from a line.
fn select_technology(
    program: &JobProgram,
    config: &mut Config,
    launch: &mut Launch,
    ask: TechAsk,
) -> Result<(), CheckRefusal> {
    let asked = match (ask.asked, ask.resume) {
        (Some(r), _) => Some(r),
        (None, true) => None,
        (None, false) => crate::technology::header(&program.path, &program.name)?,
    };
    let selection = asked.map(|r| ask.tables.select(&r)).transpose()?;
    if let Some(s) = &selection {
        s.apply(config);
    }
    let refused = |s: &crate::technology::Selection, why: &str| {
        CheckRefusal::from(crate::technology::TechError::Refused {
            message: format!("{}: {why} ({})", s.request.text(), s.table),
        })
    };
    let wire = selection.as_ref().filter(|s| !s.passes.is_empty());
    if ask.resume {
        if let Some(s) = wire
            && !same_passes(&s.wire_passes(), &launch.cut.passes)
        {
            return Err(refused(
                s,
                "the table's passes are no longer the checkpoint's (it changed since the job \
                 stopped): the job cannot be resumed as it was cut",
            ));
        }
    } else {
        let n = match (&selection, wire, ask.passes) {
            (Some(s), None, Some(_)) => {
                return Err(refused(
                    s,
                    "a sinker table has stages (the program's E words), not passes",
                ));
            }
            (_, Some(s), n) => Some(n.unwrap_or(s.passes.len())),
            (_, None, n) => n,
        };
        if let Some(n) = n {
            launch.cut.passes =
                crate::path::passes::first(&config.wire.passes, n, &config.condition_numbers())?;
            launch.cut.tab_mm = config.wire.tab_mm;
        }
        if let Some(tab_mm) = ask.tab_mm {
            if launch.cut.passes.is_empty() {
                return Err(crate::path::PassError::TabWithoutPasses { tab_mm }.into());
            }
            launch.cut.tab_mm = tab_mm;
        }
    }
    // A run from a line in passes is in pass 1 unless the operator said which.
    if let Some(from) = launch.cut.from_line.as_mut()
        && from.pass.is_none()
        && !launch.cut.passes.is_empty()
    {
        from.pass = Some(1);
    }
    crate::path::passes::from_line_fits(
        launch.cut.from_line.as_ref(),
        &launch.cut.passes,
        launch.cut.tab_mm,
    )?;
    let Some(selection) = selection else {
        return Ok(());
    };
    launch.technology = JobTechnology::Selected(Arc::new(selection));
    Ok(())
}

/// The checkpoint's passes are the first of the table's: to a nanometre (the checkpoint's
/// JSON gives its numbers back to the last bit or one off).
fn same_passes(table: &[crate::path::WirePass], checkpoint: &[crate::path::WirePass]) -> bool {
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9;
    checkpoint.len() <= table.len()
        && table.iter().zip(checkpoint).all(|(t, c)| {
            t.condition == c.condition
                && t.reverse == c.reverse
                && close(t.offset_mm, c.offset_mm)
                && match (t.feed_mm_per_min, c.feed_mm_per_min) {
                    (Some(a), Some(b)) => close(a, b),
                    (a, b) => a == b,
                }
        })
}
