//! `edmd tech`: the technology tables (`technology.dir`), listed, and what a request
//! selects, explained.

use std::process::ExitCode;

use clap::{Args, Subcommand};

use super::{ConfigArgs, EXIT_BAD_INPUT, load_config, write_stdout};
use crate::technology::{Request, Tables};

#[derive(Args, Debug)]
pub(super) struct TechArgs {
    #[command(subcommand)]
    command: TechCommand,
    #[command(flatten)]
    config: ConfigArgs,
}

#[derive(Subcommand, Debug)]
enum TechCommand {
    /// One line per table: what it is for, its rows, its file (every table is checked)
    List,
    /// What a request selects: the table, the rows and why, the passes (or stages) and the
    /// conditions with their generator set points
    Explain {
        /// material=steel,height=32,wire=0.25 (a wire cut) or
        /// electrode=copper,material=steel,area=4 (a sinker)
        request: String,
    },
}

pub(super) fn run_tech(args: &TechArgs) -> ExitCode {
    let cfg = match load_config(&args.config) {
        Ok(c) => c,
        Err(code) => return code,
    };
    let fail = |e: &dyn std::fmt::Display| {
        eprintln!("edmd: error: {e}");
        ExitCode::from(EXIT_BAD_INPUT)
    };
    let tables = match Tables::of(&cfg) {
        Ok(t) => t,
        Err(e) => return fail(&format!("technology.dir: {e}")),
    };
    match &args.command {
        TechCommand::List => {
            if tables.tables().is_empty() {
                outln!("no technology tables in {}", tables.dir().display());
            }
            for line in tables.list() {
                outln!("{line}");
            }
            ExitCode::SUCCESS
        }
        TechCommand::Explain { request } => {
            let selected = Request::parse(request, "request", 1, 1).and_then(|r| tables.select(&r));
            match selected {
                Ok(s) => {
                    out!("{}", s.explain());
                    ExitCode::SUCCESS
                }
                Err(e) => fail(&e),
            }
        }
    }
}
