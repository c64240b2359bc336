//! What a job run from the command line cuts: the passes of the technology table
//! (`--passes N`, for `run` and `plan`) and the line it starts from (`--from-line`).

use std::process::ExitCode;

use super::{Config, EXIT_BAD_INPUT, RunArgs};

/// The first `n` passes of the technology table (`--passes N`), with the table's tab.
pub(super) fn passes_plan(
    cfg: &Config,
    passes: Option<usize>,
) -> Result<crate::path::CutPlan, ExitCode> {
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
    })
}

impl RunArgs {
    /// What the job cuts: from `--from-line`, in `--passes` of the table.
    pub(super) fn cut_plan(&self, cfg: &Config) -> Result<crate::path::CutPlan, ExitCode> {
        Ok(crate::path::CutPlan {
            from_line: self.cut_from(cfg),
            ..passes_plan(cfg, self.passes)?
        })
    }

    /// `--from-line` with its approach (the machine's usual one unless `--approach`).
    pub(super) fn cut_from(&self, cfg: &Config) -> Option<crate::path::FromLine> {
        self.from_line.map(|line| crate::path::FromLine {
            line,
            approach: self
                .approach
                .unwrap_or(crate::path::Approach::default_for(cfg.machine.safe_z_mm)),
        })
    }
}
