//! `edmd check`: the program read as a job would cut it (its technology applied, the wire
//! offset, the taper and the orbits), a table of its moves and their totals, or the first
//! error at its line.

use std::process::ExitCode;

use super::{CheckArgs, EXIT_BAD_INPUT, cut, init_logging, load_config, write_stdout};
use crate::{check, gcode};

pub(super) fn run_check(args: &CheckArgs) -> ExitCode {
    let cfg = match load_config(&args.config) {
        Ok(c) => c,
        Err(code) => return code,
    };
    let _ = init_logging(&cfg.log);
    if args.verbose {
        eprintln!("{}", args.config.describe());
    }
    // The program's technology applied first, as `plan` and `run` apply it: a sinker
    // header's table defines the program's E words.
    let job = match cut::CliJob::new(cfg, &args.program, None, None) {
        Ok(job) => job,
        Err(code) => return code,
    };
    let cfg = &job.cfg;
    let axes = &cfg.machine.axes;
    let name = args.program.display().to_string();
    let options = gcode::ProgramOptions::from_config(cfg);
    let mut reader = match gcode::open_program_as(&args.program, &name, axes, options, |f| f) {
        // What the program's moves cut: the wire offset, the taper and the orbits applied.
        Ok(r) => crate::path::Pipeline::new(r),
        Err(e) => {
            eprintln!("edmd: error: {e}");
            return ExitCode::from(EXIT_BAD_INPUT);
        }
    };
    let mut totals = check::Totals::default();
    if !args.quiet {
        outln!("{name}");
        outln!("{}", check::BLOCK_TABLE_HEADER);
    }
    let mut failed = None;
    for item in reader.by_ref() {
        match item {
            Ok(block) => {
                // A measure for the table and totals: exact for lines, arcs and helices.
                let length = block.length_mm(axes);
                if !args.quiet {
                    outln!("{}", check::describe_block(&block, length, axes));
                }
                totals.add(&block, length);
            }
            Err(e) => {
                failed = Some(e);
                break;
            }
        }
    }
    for w in reader.reader().take_warnings() {
        if w.line == 0 {
            eprintln!("{name}: warning: {}", w.message);
        } else {
            eprintln!("{name}:{}:{}: warning: {}", w.line, w.col, w.message);
        }
    }
    if let Some(e) = failed {
        eprintln!("edmd: error: {e}");
        return ExitCode::from(EXIT_BAD_INPUT);
    }
    outln!(
        "{}",
        check::describe_totals(&totals, axes, cfg.machine.max_feed_mm_per_min)
    );
    if let Some(line) = reader.reader().program_end_line() {
        outln!("program end: line {line}");
    }
    if let Some(technology) = job.technology_line() {
        outln!("technology: {technology}");
    }
    ExitCode::SUCCESS
}
