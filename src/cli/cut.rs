//! What a job run from the command line cuts: its technology (`--technology`, or the
//! program's `(TECH …)` header), the passes of the technology table (`--passes N`, for `run`
//! and `plan`) and the line it starts from (`--from-line`).

use std::path::Path;
use std::process::ExitCode;

use super::{Config, EXIT_BAD_INPUT, RunArgs};
use crate::technology::{Request, Selection, Tables};

/// A command-line job: the configuration with its technology applied, and what it cuts.
pub(super) struct CliJob {
    pub cfg: Config,
    pub technology: Option<Selection>,
    pub cut: crate::path::CutPlan,
}

impl CliJob {
    /// `program`'s job under `cfg`: the technology `asked` (else the program's header's)
    /// applied, then the first `passes` of the table in force (a wire technology's: all of
    /// them by default).
    pub(super) fn new(
        mut cfg: Config,
        program: &Path,
        asked: Option<&str>,
        passes: Option<usize>,
    ) -> Result<CliJob, ExitCode> {
        let fail = |e: &dyn std::fmt::Display| {
            eprintln!("edmd: error: {e}");
            ExitCode::from(EXIT_BAD_INPUT)
        };
        let request = match asked {
            Some(text) => Some(Request::parse(text, "--technology", 1, 1).map_err(|e| fail(&e))?),
            None => crate::technology::header(program, &program.display().to_string())
                .map_err(|e| fail(&e))?,
        };
        let technology = match request {
            Some(r) => {
                let tables = Tables::of(&cfg).map_err(|e| fail(&format!("technology.dir: {e}")))?;
                let selected = tables.select(&r).map_err(|e| fail(&e))?;
                selected.apply(&mut cfg);
                Some(selected)
            }
            None => None,
        };
        let passes = match (&technology, passes) {
            (Some(t), Some(_)) if t.passes.is_empty() => {
                return Err(fail(
                    &"--passes: a sinker table has stages (the program's E \
                                  words), not passes",
                ));
            }
            (Some(t), None) if !t.passes.is_empty() => Some(t.passes.len()),
            (_, n) => n,
        };
        let cut = passes_plan(&cfg, passes)?;
        Ok(CliJob {
            cfg,
            technology,
            cut,
        })
    }

    /// `check`'s line for the technology in force: what it selects and its passes or stages.
    pub(super) fn technology_line(&self) -> Option<String> {
        self.technology.as_ref().map(|t| match t.passes.len() {
            0 => format!("{}: {} stages", t.summary(), t.stages.len()),
            n => format!("{}: {n} passes", t.summary()),
        })
    }

    /// Each pass's row, condition and machine time, from what was recorded.
    pub(super) fn pass_times(
        &self,
        recording: &crate::record::Recording,
        end_tick: u64,
    ) -> Vec<crate::report::PassTime> {
        let conditions: Vec<u32> = self.cut.passes.iter().map(|p| p.condition).collect();
        let rows = self
            .technology
            .as_ref()
            .map(Selection::pass_rows)
            .unwrap_or_default();
        let height = self.technology.as_ref().and_then(|t| t.part_height_mm());
        crate::report::pass_times(recording, end_tick, &conditions, &rows, height)
    }
}

/// The first `n` passes of the technology table (`--passes N`), with the table's tab.
fn passes_plan(cfg: &Config, passes: Option<usize>) -> Result<crate::path::CutPlan, ExitCode> {
    let passes = match passes {
        None => Vec::new(),
        Some(0) => {
            eprintln!("edmd: error: --passes counts from 1 (the first pass of [wire] pass)");
            return Err(ExitCode::from(EXIT_BAD_INPUT));
        }
        Some(n) => crate::path::passes::first(&cfg.wire.passes, n, &cfg.condition_numbers())
            .map_err(|e| {
                eprintln!("edmd: error: {e}");
                ExitCode::from(EXIT_BAD_INPUT)
            })?,
    };
    let tab_mm = if passes.is_empty() {
        0.0
    } else {
        cfg.wire.tab_mm
    };
    Ok(crate::path::CutPlan {
        from_line: None,
        passes,
        tab_mm,
        ..Default::default()
    })
}

impl RunArgs {
    /// The job: its technology, from `--from-line` (no passes then), in `--passes` of the
    /// table.
    pub(super) fn job(&self, cfg: Config) -> Result<CliJob, ExitCode> {
        let mut job = CliJob::new(cfg, &self.program, self.technology.as_deref(), self.passes)?;
        if self.from_line.is_some() {
            job.cut = crate::path::CutPlan {
                from_line: self.cut_from(&job.cfg),
                ..Default::default()
            };
        }
        Ok(job)
    }

    /// `--from-line` with its approach (the machine's usual one unless `--approach`).
    pub(super) fn cut_from(&self, cfg: &Config) -> Option<crate::path::FromLine> {
        self.from_line.map(|line| crate::path::FromLine {
            line,
            pass: None,
            // `edmd run` starts where the program starts: it knows no stopped job.
            wire_at: crate::path::WireAt::StartHole,
            approach: self
                .approach
                .unwrap_or(crate::path::Approach::default_for(cfg.machine.safe_z_mm)),
        })
    }
}
