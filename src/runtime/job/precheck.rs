//! The check before a job: the whole program parsed, every end point rounded to steps once
//! to prove it fits a step counter, before anything moves. A CNC control must not start
//! cutting a program whose line 10,000 is bad.

use super::super::shaping::program::{CountingReader, JobProgram, Phase, Progress};
use super::super::shaping::progress::PathPace;
use super::error::JobError;
use super::producer::{ProducerError, to_steps};
use super::spec::start_steps;
use crate::config::{Config, GapKind, SparkingFeeds};
use crate::gcode::{self, WorkOffsets, WorkStart, WorkSystem};
use crate::geometry::Point;
use crate::path::{CutPlan, JobPath, PathItem, PathSpec, passes};
use crate::vocab::Steps;

/// What the check before the job found.
#[derive(Debug, Clone)]
pub struct Precheck {
    pub blocks: u64,
    /// The work offsets and the active system as the program leaves them (its `G10`s; `M2`
    /// returns to `G54`), for whoever keeps them after the job.
    pub work_offsets: WorkOffsets,
    pub work_system: WorkSystem,
    /// The work offsets and system in force at the program's first move: the ones it cuts
    /// in, in which the operator reads its positions while it runs (without a move: the
    /// ones it leaves).
    pub cuts_in: (WorkOffsets, WorkSystem),
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
    /// The plan's time along the path: every move at the feed the job will use (a cut at
    /// its pass's feed capped by its condition's sparking feed, a rapid at rapid speed): what
    /// the ETA counts the path left by.
    pub pace: PathPace,
    /// What the program tells the operator at each of its stops (`M0`, `M1`, a pause
    /// M-code): the line of the move it stops before, and the last message (`(MSG, …)` or
    /// the M-code's) given since the move before it. Sorted by line.
    pub pause_messages: Vec<(u64, String)>,
    /// Some move leans the wire (`G51`/`G52`): the job drives the upper guide itself.
    pub tapers: bool,
}

/// A programmed stop the check met: the line of the move it stops before, the line of the
/// move before that (its messages come after it), and the line that asked for the stop.
#[derive(Debug, Clone, Copy)]
struct StopMet {
    before_line: u64,
    after_line: u64,
    asked_at: u64,
}

/// What the check adds up block by block, over every pass.
struct Tally<'a> {
    config: &'a Config,
    /// Where the job starts: its work system says where the program's coordinates are.
    work: &'a WorkStart,
    program: &'a str,
    blocks: u64,
    end_steps: Steps,
    path_mm: f64,
    cutting_spans: Vec<(f64, f64)>,
    pace: PathPace,
    feeds: SparkingFeeds,
    /// Rapid speed and the highest feed, mm/s.
    rapid_feed: f64,
    max_feed: f64,
    /// Where the cutting moves lie is measured for the simulated gap's placed debris only.
    measure: bool,
    /// A dry run: nothing is cut.
    dry_run: bool,
    /// Some move leans the wire.
    tapers: bool,
    /// The line of the last move taken, and the stops met.
    last_line: u64,
    stops: Vec<StopMet>,
}

impl Tally<'_> {
    /// A run in passes ends where it started (the start hole). Said in the coordinates of
    /// the work system the job starts in, as the program is written.
    fn ends_at(&self, start: &Steps) -> Result<(), JobError> {
        if self.end_steps == *start {
            return Ok(());
        }
        let machine = &self.config.machine;
        let text = |s: &Steps| {
            let at = Point::from_fn(|i, _| {
                s.get(i)
                    .zip(machine.step_mm.get(i))
                    .map_or(0.0, |(&n, mm)| n as f64 * mm)
            });
            self.work.text_of(&at, &machine.axes)
        };
        Err(passes::PassError::NotClosed {
            program: self.program.to_string(),
            start: text(start),
            end: text(&self.end_steps),
        }
        .into())
    }

    fn take(&mut self, block: &gcode::Block) -> Result<(), JobError> {
        let machine = &self.config.machine;
        self.blocks += 1;
        if let Some((asked_at, _)) = block.pause {
            self.stops.push(StopMet {
                before_line: block.line,
                after_line: self.last_line,
                asked_at,
            });
        }
        self.last_line = block.line;
        self.tapers |= block.taper != 0.0;
        crate::machine::travel::hold_to_travel(
            block,
            &machine.axes,
            &machine.travel,
            self.program,
        )?;
        // Exact: the simulated gap places its debris along these lengths, so they are the
        // same to the last digit whatever reads them (lines and arcs in closed form).
        let length = block.curve.length();
        let path_mm = self.path_mm;
        // A spark-off move (an approach, a tabbed run's travel) cuts nothing.
        let cutting =
            block.kind != gcode::BlockKind::Rapid && block.spark_off.is_none() && !self.dry_run;
        if self.measure && cutting {
            match self.cutting_spans.last_mut() {
                Some((_, to)) if *to == path_mm => *to += length,
                _ => self.cutting_spans.push((path_mm, path_mm + length)),
            }
        }
        let feed = block
            .feed_mm_per_min
            .map_or(self.max_feed, |f| (f / 60.0).min(self.max_feed));
        let pace = match block.kind {
            gcode::BlockKind::Rapid => self.rapid_feed,
            _ if cutting => feed.min(self.feeds.mm_per_s(block.condition)),
            _ => feed,
        };
        self.pace.push(path_mm, length, pace);
        self.path_mm += length;
        self.end_steps =
            to_steps(&block.end(), &machine.step_mm).map_err(|(axis, mm, steps)| {
                ProducerError::OutOfRange {
                    program: self.program.to_string(),
                    line: block.line,
                    axis: machine.axes[axis].letter(),
                    mm,
                    steps,
                }
            })?;
        Ok(())
    }
}

/// Parses the whole program and checks every end point fits a step counter (and, for a job
/// run from a line, that it can start there; in passes, every pass with its offset, and that
/// the program ends where it starts). Reads the job's path as the producer will
/// ([`JobPath`]). Reports the bytes read to `progress` and gives up with
/// [`JobError::Cancelled`] when it is cancelled.
pub fn precheck(
    program: &JobProgram,
    config: &Config,
    start: &WorkStart,
    cut: &CutPlan,
    progress: &Progress,
) -> Result<Precheck, JobError> {
    progress.start(Phase::Checking, program.bytes);
    let spec = PathSpec::from_config(config, start, cut);
    let plan = crate::preprocess::PlanSettings::from_config(config);
    let start_at = start_steps(&spec.machine_start(), &config.machine.step_mm);
    let mut tally = Tally {
        config,
        work: start,
        program: &program.name,
        blocks: 0,
        end_steps: start_at,
        path_mm: 0.0,
        cutting_spans: Vec::new(),
        pace: PathPace::default(),
        feeds: SparkingFeeds::new(config),
        rapid_feed: plan.rapid_feed_mm_per_s,
        max_feed: plan.max_feed_mm_per_s,
        measure: config.gap.kind == GapKind::Sim && config.sim.debris_per_mm > 0.0,
        dry_run: cut.dry_run_feed_mm_per_min.is_some(),
        tapers: false,
        last_line: 0,
        stops: Vec::new(),
    };
    let cancelled = || JobError::Cancelled {
        program: program.name.clone(),
    };
    let open = |options| {
        gcode::open_program_as(
            &program.path,
            &program.name,
            &config.machine.axes,
            options,
            |f| CountingReader::new(f, progress),
        )
    };
    let mut cuts_in = None;
    let mut path = JobPath::new(&spec, &program.name, open, Some(progress.cancel_flag()));
    // Where the pass in hand started: a whole pass ends there (the start hole). A pass cut
    // from a line started where the wire stood: it is not held to it.
    let mut pass_start: Option<Steps> = None;
    let mut first_pass = true;
    loop {
        let item = match path.next_item() {
            Ok(Some(item)) => item,
            Ok(None) => break,
            Err(e) if e.cancelled() => return Err(cancelled()),
            Err(e) => return Err(e.into()),
        };
        match item {
            // A run in passes ends where it started (the start hole) before the next.
            PathItem::PassStart {
                at_start_hole: true,
                ..
            } => {
                if let Some(start) = pass_start {
                    tally.ends_at(&start)?;
                }
                let from_line = first_pass && cut.from_line.is_some();
                pass_start = (!from_line).then_some(tally.end_steps);
                first_pass = false;
            }
            PathItem::PassStart { .. } => {}
            PathItem::Skipped { mm } => tally.path_mm += mm,
            PathItem::Block(block) => {
                // The reader looks at the flag on every line; a block's own work (the
                // length of a curve of 100,000 points) is looked at here.
                if progress.cancelled() {
                    return Err(cancelled());
                }
                if cuts_in.is_none() {
                    cuts_in = path.in_force();
                }
                tally.take(&block)?;
            }
        }
    }
    if let Some(start) = pass_start {
        tally.ends_at(&start)?;
    }
    let warnings = path.take_warnings();
    let pause_messages = pause_messages(&tally.stops, &warnings);
    for w in warnings {
        if w.line == 0 {
            tracing::warn!("{}: {}", program.name, w.message);
        } else {
            tracing::warn!("{}:{}:{}: {}", program.name, w.line, w.col, w.message);
        }
    }
    let (work_offsets, work_system, modes) = path.left().cloned().expect("one run at least");
    Ok(Precheck {
        cuts_in: cuts_in.unwrap_or_else(|| (work_offsets.clone(), work_system)),
        work_offsets,
        work_system,
        modes,
        blocks: tally.blocks,
        end_steps: tally.end_steps,
        cutting_spans: tally.cutting_spans,
        path_mm: tally.path_mm,
        pace: tally.pace,
        pause_messages,
        tapers: tally.tapers,
    })
}

/// Each stop's message: the last operator message (the reader's `message: …` warnings) on a
/// line after the move before the stop and up to the line that asked for it.
fn pause_messages(stops: &[StopMet], warnings: &[gcode::Warning]) -> Vec<(u64, String)> {
    let mut said: Vec<(u64, String)> = stops
        .iter()
        .filter_map(|stop| {
            let message = warnings
                .iter()
                .filter(|w| w.line > stop.after_line && w.line <= stop.asked_at)
                .filter_map(|w| w.message.strip_prefix(gcode::OPERATOR_MESSAGE))
                .next_back()?;
            Some((stop.before_line, message.to_string()))
        })
        .collect();
    // A program in passes meets its stops once per pass.
    said.sort();
    said.dedup_by_key(|(line, _)| *line);
    said
}
