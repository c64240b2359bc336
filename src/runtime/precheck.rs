//! The check before a job: the whole program parsed, every end point rounded to steps once
//! to prove it fits a step counter, before anything moves. A CNC control must not start
//! cutting a program whose line 10,000 is bad.

use super::JobError;
use super::from_line::{FromLine, Gate};
use super::producer::{ProducerError, to_steps};
use super::program::{CountingReader, JobProgram, Phase, Progress};
use super::spec::start_steps;
use crate::config::{Config, GapKind};
use crate::gcode::{self, WorkOffsets, WorkStart, WorkSystem};
use crate::vocab::Steps;

/// What the check before the job found.
#[derive(Debug, Clone)]
pub struct Precheck {
    pub blocks: u64,
    /// The work offsets and the active system as the program leaves them (its `G10`s; `M2`
    /// returns to `G54`), for whoever keeps them after the job.
    pub work_offsets: WorkOffsets,
    pub work_system: WorkSystem,
    /// The units and distance mode at the end (MDI keeps them for its next lines).
    pub modes: gcode::StartModes,
    pub end_steps: Steps,
    /// Where the cutting (non-rapid) moves lie along the path: `(from, to)` in mm of path
    /// length from the program's start, consecutive cutting moves merged into one span (so
    /// this grows with the number of rapids, not of blocks). Measured only for the simulated
    /// gap's placed debris.
    pub cutting_spans: Vec<(f64, f64)>,
    /// Path length of the whole program (mm): the denominator of a job's progress.
    pub path_mm: f64,
    /// Where the rapids lie along the path (`(from, to)`, mm; consecutive rapids merged): the
    /// ETA counts them at rapid speed, not at the cutting feed.
    pub rapid_spans: Vec<(f64, f64)>,
}

/// Parses the whole program and checks every end point fits a step counter (and, for a job
/// run from a line, that it can start there). Reports the bytes read to `progress` and gives
/// up with [`JobError::Cancelled`] when it is cancelled.
pub fn precheck(
    program: &JobProgram,
    config: &Config,
    start: &WorkStart,
    from_line: Option<FromLine>,
    progress: &Progress,
) -> Result<Precheck, JobError> {
    progress.start(Phase::Checking, program.bytes);
    let mut reader = gcode::open_program_as(
        &program.path,
        &program.name,
        &config.machine.axes,
        gcode::ProgramOptions::from_config(config),
        |f| CountingReader::new(f, progress),
    )?;
    reader.cancel_on(progress.cancel_flag());
    reader.start_at(start);
    let machine = &config.machine;
    let mut blocks = 0;
    let mut end_steps = start_steps(start, &machine.step_mm);
    let mut path_mm = 0.0;
    let mut cutting_spans = Vec::new();
    let mut rapid_spans: Vec<(f64, f64)> = Vec::new();
    let measure = config.gap.kind == GapKind::Sim && config.sim.debris_shorts > 0;
    let cancelled = || JobError::Cancelled {
        program: program.name.clone(),
    };
    let mut gate = from_line.map(|f| Gate::new(f, &program.name));
    while let Some(item) = reader.next() {
        let block = match item {
            Ok(block) => block,
            Err(e) if matches!(e.kind, gcode::GcodeErrorKind::Cancelled) => return Err(cancelled()),
            Err(e) => return Err(e.into()),
        };
        if let Some(gate) = &mut gate {
            gate.admit(&block, reader.comp_entry_line())?;
        }
        blocks += 1;
        // The reader looks at the flag on every line; a block's own work (the length of a
        // curve of 100,000 points) is looked at here.
        if progress.cancelled() {
            return Err(cancelled());
        }
        crate::check::hold_to_travel(&block, &machine.axes, &machine.travel, &program.name)?;
        let length = block.curve.length();
        if measure && block.kind != gcode::BlockKind::Rapid {
            match cutting_spans.last_mut() {
                Some((_, to)) if *to == path_mm => *to += length,
                _ => cutting_spans.push((path_mm, path_mm + length)),
            }
        }
        if block.kind == gcode::BlockKind::Rapid {
            match rapid_spans.last_mut() {
                Some((_, to)) if *to == path_mm => *to += length,
                _ => rapid_spans.push((path_mm, path_mm + length)),
            }
        }
        path_mm += length;
        end_steps =
            to_steps(&block.end(), &config.machine.step_mm).map_err(|(axis, mm, steps)| {
                ProducerError::OutOfRange {
                    program: program.name.clone(),
                    line: block.line,
                    axis: config.machine.axes[axis].letter(),
                    mm,
                    steps,
                }
            })?;
    }
    if let Some(gate) = &gate {
        gate.finish()?;
    }
    for w in reader.take_warnings() {
        if w.line == 0 {
            tracing::warn!("{}: {}", program.name, w.message);
        } else {
            tracing::warn!("{}:{}:{}: {}", program.name, w.line, w.col, w.message);
        }
    }
    Ok(Precheck {
        work_offsets: reader.work_offsets(),
        work_system: reader.work_system(),
        modes: reader.modes(),
        blocks,
        end_steps,
        cutting_spans,
        path_mm,
        rapid_spans,
    })
}
