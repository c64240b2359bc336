//! The producer thread: program text to loop-buffer blocks.
//!
//! It streams the program through the parser and the [`Preprocessor`], turns every planned
//! segment into a [`StepBlock`] and pushes it into the loop buffer, sleeping whenever the
//! buffer is full. Step positions are rounded once per segment end point, absolutely, from mm
//! (never accumulated), so a block's start is bit-for-bit the previous block's end.

use crate::buffer::BlockFlags;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use super::super::shaping::from_line::{self, Approach, Gate, Route};
use super::super::shaping::passes;
use super::super::shaping::program::JobProgram;
use super::super::shaping::tabs::{self, PassProgram};
use super::super::tick::probe::ProbeLink;
use super::spec::{JobSpec, StepCondition};
use crate::buffer::{LoopBuffer, StepBlock};
use crate::config::WirePass;
use crate::gcode::{self, BlockKind, GcodeError};
use crate::geometry::Point;
use crate::preprocess::{PreprocessStats, Preprocessor, Segment};
use crate::vocab::{MAX_AXES, Steps};

/// Largest step position accepted: beyond 2^53 an `f64` no longer holds every integer.
const MAX_STEPS: f64 = 9.0e15;

/// Why the producer stopped early.
#[derive(Debug, thiserror::Error)]
pub enum ProducerError {
    #[error(transparent)]
    Program(#[from] GcodeError),
    #[error(
        "{program}:{line}: position {mm} mm on axis {axis} is {steps:e} steps from zero, beyond \
         what a step counter holds"
    )]
    OutOfRange {
        program: String,
        line: u64,
        axis: char,
        mm: f64,
        steps: f64,
    },
    #[error("cannot start the producer thread: {0}")]
    Thread(std::io::Error),
    #[error(transparent)]
    FromLine(#[from] super::super::shaping::from_line::FromLineError),
    #[error(transparent)]
    Passes(#[from] passes::PassError),
    #[error(transparent)]
    Tabs(#[from] super::super::shaping::tabs::TabError),
}

/// What the producer did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ProducerReport {
    pub stats: PreprocessStats,
    /// Blocks pushed into the loop buffer.
    pub pushed: u64,
    /// The consumer had gone (alarm, stop): the rest of the program was not produced.
    pub aborted: bool,
    /// Wall time spent reading, preprocessing and converting, not waiting for buffer space
    /// (ns): what the producer's real-time margin is measured against.
    pub busy_ns: u64,
    /// The orbital sinking moves read, in order (the stages the summary lists).
    pub stages: Vec<super::super::shaping::stages::StageRow>,
}

/// Rounds a point in mm to absolute step positions.
pub fn to_steps(point: &Point, step_mm: &[f64]) -> Result<Steps, (usize, f64, f64)> {
    let mut steps = [0i64; MAX_AXES];
    for (i, &step) in step_mm.iter().enumerate() {
        let exact = point[i] / step;
        if !exact.is_finite() || exact.abs() > MAX_STEPS {
            return Err((i, point[i], exact));
        }
        steps[i] = exact.round() as i64;
    }
    Ok(steps)
}

/// Converts planned segments to step blocks with one rounding per end point.
#[derive(Debug)]
pub struct BlockMaker {
    step_mm: Vec<f64>,
    axes: Vec<char>,
    program: String,
    seq: u64,
    last_end: Steps,
    path_mm: f64,
    /// The next segment is the first of its G-code block (it carries the block's stops).
    first_of_block: bool,
    /// `[generator] condition`s as the blocks carry them.
    conditions: Vec<StepCondition>,
    /// The pass the next blocks belong to (0: none), and the flags of the next block if it
    /// starts it (`PASS_START`, and `START_HOLE` where it starts at the start hole).
    pass: u8,
    pass_starts: BlockFlags,
    /// The tool axis (Z) whose sinking moves are watched for breakthrough, when
    /// `[sinker] breakthrough` is on.
    drills_along: Option<usize>,
    /// Path left of the curved spark-off move being made (mm): its length less its chords.
    curve_left_mm: f64,
    /// Lattice path since the start of the contour (mm).
    contour_path_mm: f64,
}

impl BlockMaker {
    pub fn new(spec: &JobSpec, program: &str) -> BlockMaker {
        BlockMaker {
            step_mm: spec.step_mm.clone(),
            axes: spec.axes.iter().map(|a| a.letter()).collect(),
            program: program.to_string(),
            seq: 0,
            last_end: spec.start_steps(),
            path_mm: 0.0,
            first_of_block: true,
            conditions: spec.conditions.clone(),
            pass: 0,
            pass_starts: BlockFlags::NONE,
            drills_along: spec
                .fine
                .breakthrough
                .enabled
                .then(|| spec.axes.iter().position(|&a| a == crate::vocab::Axis::Z))
                .flatten(),
            curve_left_mm: 0.0,
            contour_path_mm: 0.0,
        }
    }

    /// The lattice path from the start of the contour to `end` (mm), the move's flags saying
    /// where a contour starts: at the start hole, and after a rapid through the open or a
    /// probing move (where a rethread's way back stops).
    fn contour_mm(&mut self, end: &Steps, flags: BlockFlags) -> f64 {
        if flags.contains(BlockFlags::START_HOLE) {
            self.contour_path_mm = 0.0;
        }
        let mut len2 = 0.0;
        for ((e, s), mm) in end.iter().zip(&self.last_end).zip(&self.step_mm) {
            len2 += ((e - s) as f64 * mm).powi(2);
        }
        self.contour_path_mm += len2.sqrt();
        let at = self.contour_path_mm;
        let barrier = flags.contains(BlockFlags::PROBE)
            || (flags.contains(BlockFlags::RAPID) && !flags.contains(BlockFlags::IN_KERF));
        if barrier {
            self.contour_path_mm = 0.0;
        }
        at
    }

    /// Path from `segment`'s end to the end of its G-code block (mm), on a spark-off move:
    /// a straight one to its end point, a curved one (a pass's travel along the kerf) by its
    /// length less the chords made so far.
    fn rest_mm(&mut self, segment: &Segment, first: bool, flags: BlockFlags) -> f64 {
        if !flags.contains(BlockFlags::RAPID) || segment.last_of_block {
            return 0.0;
        }
        let curve = &segment.block.curve;
        if curve.degree() == 1 {
            return (curve.end_point() - segment.end).norm();
        }
        if first {
            self.curve_left_mm = curve.length();
        }
        self.curve_left_mm -= segment.length;
        self.curve_left_mm.max(0.0)
    }

    /// `block` is a drilling move watched for breakthrough: a sinking move (or its orbit).
    pub fn drills(&self, block: &gcode::Block) -> bool {
        self.drills_along
            .is_some_and(|z| block.orbit.is_some() || block.sinks(z))
    }

    /// The next blocks are pass `number` (1-based) of the technology table; `at_start_hole`:
    /// it starts there (not at a tab).
    pub fn start_pass(&mut self, number: u8, at_start_hole: bool) {
        self.pass = number;
        self.pass_starts = BlockFlags::PASS_START;
        if at_start_hole {
            self.pass_starts |= BlockFlags::START_HOLE;
        }
    }

    /// The path length (mm) the next block starts at: a direct approach counts the program
    /// it skips, so progress and placed debris stay where a full run has them.
    pub fn set_path_mm(&mut self, mm: f64) {
        self.path_mm = mm;
    }

    pub fn path_mm(&self) -> f64 {
        self.path_mm
    }

    /// A probing move ended at `steps`: the next block starts there.
    pub fn probed(&mut self, steps: &Steps) {
        self.last_end = *steps;
    }

    pub fn make(&mut self, segment: &Segment) -> Result<StepBlock, ProducerError> {
        let end = to_steps(&segment.end, &self.step_mm).map_err(|(axis, mm, steps)| {
            ProducerError::OutOfRange {
                program: self.program.clone(),
                line: segment.block.line,
                axis: self.axes[axis],
                mm,
                steps,
            }
        })?;
        let mut flags = BlockFlags::NONE;
        if segment.last_of_block {
            flags |= BlockFlags::LAST_OF_BLOCK;
        }
        if segment.block.spark_off == Some(gcode::Travel::Kerf) {
            flags |= BlockFlags::IN_KERF;
        }
        if segment.block.kind == BlockKind::Rapid || segment.block.spark_off.is_some() {
            flags |= BlockFlags::RAPID;
        }
        if segment.block.flushing {
            flags |= BlockFlags::FLUSH;
        }
        if segment.block.orbit.is_some() {
            flags |= BlockFlags::ORBIT;
        }
        if self.drills(&segment.block) {
            flags |= BlockFlags::BREAKTHROUGH;
        }
        if let BlockKind::Probe(p) = segment.block.kind {
            flags |= BlockFlags::PROBE;
            if p.away {
                flags |= BlockFlags::PROBE_AWAY;
            }
            if p.must_touch {
                flags |= BlockFlags::PROBE_MUST;
            }
        }
        let first = std::mem::replace(&mut self.first_of_block, segment.last_of_block);
        if first && segment.block.pause.is_some() {
            flags |= BlockFlags::PAUSE;
        }
        flags |= std::mem::take(&mut self.pass_starts);
        if first && matches!(segment.block.pause, Some((_, gcode::Pause::Slug))) {
            flags |= BlockFlags::TAB;
        }
        let rest_mm = self.rest_mm(segment, first, flags);
        let contour_mm = self.contour_mm(&end, flags);
        let block = StepBlock {
            seq: self.seq,
            start: self.last_end,
            end,
            length_mm: segment.length,
            v_entry: segment.v_entry,
            v_exit: segment.v_exit,
            v_cruise: segment.v_peak,
            v_limit: segment.speed_limit.max(segment.v_peak),
            line: segment.block.line,
            u_end: match segment.block.kind {
                BlockKind::Nurbs { .. } => segment.u_end,
                _ => f64::NAN,
            },
            flags,
            path_end_mm: self.path_mm + segment.length,
            rest_mm,
            contour_mm,
            dwell_s: if first { segment.block.dwell_s } else { 0.0 } + segment.corner_dwell_s,
            condition: segment.block.condition as u16,
            condition_feed: 0.0,
            condition_v_ref: 0.0,
            condition_jump: [f32::NAN; 3],
            pass: self.pass,
        };
        let mut block = block;
        if let Some(c) = self
            .conditions
            .iter()
            .find(|c| c.number == segment.block.condition)
        {
            block.condition_feed = c.feed;
            block.condition_v_ref = c.v_ref;
            block.condition_jump = c.jump;
        }
        self.path_mm += segment.length;
        self.seq += 1;
        self.last_end = end;
        Ok(block)
    }
}

/// Streams `program` into `buffer`; closes the buffer at the end (also after an error, so the
/// consumer finishes what it has and stops).
///
/// After a probing move it plans the path to a standstill at the move's end, pushes it and
/// waits for `probe` to say where the move really ended, then reads on from there.
pub fn produce(
    program: &JobProgram,
    spec: &JobSpec,
    buffer: &LoopBuffer,
    probe: &ProbeLink,
    cancel: Arc<AtomicBool>,
) -> Result<ProducerReport, ProducerError> {
    let result = produce_inner(program, spec, buffer, probe, cancel);
    buffer.close();
    result
}

fn produce_inner(
    program: &JobProgram,
    spec: &JobSpec,
    buffer: &LoopBuffer,
    probe: &ProbeLink,
    cancel: Arc<AtomicBool>,
) -> Result<ProducerReport, ProducerError> {
    let mut pre = Preprocessor::new(spec.plan.clone());
    let started = Instant::now();
    let mut out = Pusher {
        maker: BlockMaker::new(spec, &program.name),
        buffer,
        report: ProducerReport::default(),
        failed: None,
        waited: Duration::ZERO,
    };
    let runs: Vec<Option<&WirePass>> = if spec.cut.passes.is_empty() {
        vec![None]
    } else {
        spec.cut.passes.iter().map(Some).collect()
    };
    let mut probes = 0;
    let runs = if spec.cut.tabbed() {
        tabbed(program, spec, &cancel, &mut pre, &mut out)?;
        Vec::new()
    } else {
        runs
    };
    for (k, pass) in runs.into_iter().enumerate() {
        if pass.is_some() {
            // Segments leave the preprocessor up to a look-ahead later: the pass's first
            // block is marked when the last pass is out, so plan its end as a standstill.
            if k > 0 {
                pre.finish(|s| out.push(s));
            }
            out.maker
                .start_pass(u8::try_from(k + 1).unwrap_or(u8::MAX), true);
        }
        let mut reader = gcode::open_program_as(
            &program.path,
            &program.name,
            &spec.axes,
            passes::options(&spec.program, pass),
            |f| f,
        )?;
        // The job's end (a stop, an alarm) reaches a reader busy in a loop that moves nothing.
        reader.cancel_on(cancel.clone());
        reader.start_at(&spec.work);
        if pass.is_some_and(|p| p.reverse) {
            reversed_pass(reader, pass, &program.name, &mut pre, &mut out)?;
        } else {
            stream(
                reader,
                spec,
                program,
                pass,
                probe,
                &mut probes,
                &mut pre,
                &mut out,
            )?;
        }
        if out.report.aborted {
            break;
        }
    }
    if !out.report.aborted {
        pre.finish(|s| out.push(s));
    }
    if let Some(e) = out.failed {
        return Err(e);
    }
    let mut report = out.report;
    report.stats = pre.stats();
    report.busy_ns = started.elapsed().saturating_sub(out.waited).as_nanos() as u64;
    Ok(report)
}

/// Passes with a tab ([`tabs`]): every pass read whole, the chain planned, then pushed with
/// each pass's start marked (only the first starts at the start hole).
fn tabbed(
    program: &JobProgram,
    spec: &JobSpec,
    cancel: &Arc<AtomicBool>,
    pre: &mut Preprocessor,
    out: &mut Pusher<'_>,
) -> Result<(), ProducerError> {
    let mut read = Vec::new();
    for pass in &spec.cut.passes {
        let mut reader = gcode::open_program_as(
            &program.path,
            &program.name,
            &spec.axes,
            passes::options(&spec.program, Some(pass)),
            |f| f,
        )?;
        reader.cancel_on(cancel.clone());
        reader.start_at(&spec.work);
        match PassProgram::read(&mut reader, pass, &program.name) {
            Ok(p) => read.push(p),
            Err(tabs::TabError::Program(e))
                if matches!(e.kind, gcode::GcodeErrorKind::Cancelled) =>
            {
                out.report.aborted = true;
                return Ok(());
            }
            Err(e) => return Err(e.into()),
        }
    }
    let blocks = tabs::plan(
        read,
        &spec.cut.passes,
        spec.cut.tab_mm,
        spec.approach_feed_mm_per_min,
        &program.name,
    )?;
    for b in blocks {
        if b.starts_pass {
            // Plan the last pass's end as a standstill: its blocks are all out.
            pre.finish(|s| out.push(s));
            out.maker.start_pass(b.pass, b.pass == 1);
        }
        pre.push_block(Arc::new(b.block), |s| out.push(s));
        if out.report.aborted {
            break;
        }
    }
    Ok(())
}

/// A reversed pass: its blocks read whole, then pushed last first, each run backwards.
fn reversed_pass<R: std::io::BufRead + std::io::Seek>(
    reader: gcode::BlockReader<R>,
    pass: Option<&WirePass>,
    name: &str,
    pre: &mut Preprocessor,
    out: &mut Pusher<'_>,
) -> Result<(), ProducerError> {
    let mut blocks = Vec::new();
    for item in reader {
        match item {
            Ok(block) => blocks.push(passes::block(block, pass, name)?),
            Err(e) if matches!(e.kind, gcode::GcodeErrorKind::Cancelled) => {
                out.report.aborted = true;
                return Ok(());
            }
            Err(e) => return Err(e.into()),
        }
    }
    for block in blocks.iter().rev() {
        pre.push_block(Arc::new(block.reversed()), |s| out.push(s));
        if out.report.aborted {
            break;
        }
    }
    Ok(())
}

/// One run of the program through the preprocessor, as it reads: a run from a line's
/// approach, and probing moves (planned to a standstill, then read on from where they stop).
#[allow(clippy::too_many_arguments)]
fn stream<R: std::io::BufRead + std::io::Seek>(
    mut reader: gcode::BlockReader<R>,
    spec: &JobSpec,
    program: &JobProgram,
    pass: Option<&WirePass>,
    probe: &ProbeLink,
    probes: &mut u64,
    pre: &mut Preprocessor,
    out: &mut Pusher<'_>,
) -> Result<(), ProducerError> {
    let buffer = out.buffer;
    let mut gate = spec.cut.from_line.map(|f| Gate::new(f, &program.name));
    while let Some(item) = reader.next() {
        let block = match item {
            Ok(block) => block,
            Err(e) if matches!(e.kind, gcode::GcodeErrorKind::Cancelled) => {
                out.report.aborted = true;
                break;
            }
            Err(e) => return Err(e.into()),
        };
        let block = passes::block(block, pass, &program.name)?;
        let block = match &mut gate {
            None => block,
            Some(gate) => match approach(gate, block, reader.comp_entry_line(), spec, out, pre)? {
                Some(block) => block,
                None => continue,
            },
        };
        if out.report.stages.len() < super::super::shaping::stages::MAX_STAGES
            && let Some(stage) = super::super::shaping::stages::StageRow::of(&block)
        {
            out.report.stages.push(stage);
        }
        // A probing move, and a drilling move watched for breakthrough, end where the
        // consumer says.
        let probing = matches!(block.kind, BlockKind::Probe(_)) || out.maker.drills(&block);
        pre.push_block(Arc::new(block), |s| out.push(s));
        if probing && !out.report.aborted && out.failed.is_none() {
            // The rest of the program starts where the move stops: plan to a standstill at
            // its end, hand everything over, and wait for the consumer to say where.
            pre.finish(|s| out.push(s));
            *probes += 1;
            let waiting = Instant::now();
            let result = probe.wait(*probes, || buffer.aborted());
            out.waited += waiting.elapsed();
            match result {
                Some(result) => {
                    let step_mm = &spec.step_mm;
                    let mm = Point::from_fn(|i, _| {
                        step_mm.get(i).map_or(0.0, |s| result.steps[i] as f64 * s)
                    });
                    reader.probed(&mm, result.contact);
                    out.maker.probed(&result.steps);
                }
                None => out.report.aborted = true,
            }
        }
        if out.report.aborted {
            break;
        }
    }
    if !out.report.aborted
        && let Some(gate) = &gate
    {
        gate.finish()?;
    }
    Ok(())
}

/// A block of a job run from a line, routed: the block to push, or `None` where the approach
/// drops it. The direct approach's moves are pushed before the first block of the cut.
fn approach(
    gate: &mut Gate,
    block: gcode::Block,
    comp_entry: Option<u64>,
    spec: &JobSpec,
    out: &mut Pusher<'_>,
    pre: &mut Preprocessor,
) -> Result<Option<gcode::Block>, ProducerError> {
    let direct = gate.from().approach == Approach::Direct;
    Ok(match gate.admit(&block, comp_entry)? {
        Route::Cut => Some(block),
        Route::Before if direct => {
            out.maker
                .set_path_mm(out.maker.path_mm() + block.curve.length());
            None
        }
        Route::Before => Some(from_line::path_approach(
            block,
            spec.approach_feed_mm_per_min,
        )),
        Route::First if direct => {
            let origin = Point::from_fn(|i, _| spec.work.position_mm[i]);
            let moves = from_line::direct_approach(
                &origin,
                &block,
                &spec.axes,
                spec.safe_z_mm,
                spec.approach_feed_mm_per_min,
            );
            let length: f64 = moves.iter().map(|b| b.curve.length()).sum();
            out.maker.set_path_mm(out.maker.path_mm() - length);
            for m in moves {
                pre.push_block(Arc::new(m), |s| out.push(s));
            }
            Some(block)
        }
        Route::First => Some(block),
    })
}

/// Turns segments into step blocks and pushes them, timing only the waits.
struct Pusher<'b> {
    maker: BlockMaker,
    buffer: &'b LoopBuffer,
    report: ProducerReport,
    failed: Option<ProducerError>,
    /// Time spent waiting for buffer space or a probe result.
    waited: Duration,
}

impl Pusher<'_> {
    fn push(&mut self, segment: Segment) {
        if self.failed.is_some() || self.report.aborted {
            return;
        }
        match self.maker.make(&segment) {
            Ok(block) => {
                // Only a push that finds the ring full is timed: the clock stays off the
                // common path.
                let pushed = self.buffer.try_push(&block) || {
                    let waiting = Instant::now();
                    let pushed = self.buffer.push(&block).is_ok();
                    self.waited += waiting.elapsed();
                    pushed
                };
                if pushed {
                    self.report.pushed += 1;
                } else {
                    self.report.aborted = true;
                }
            }
            Err(e) => self.failed = Some(e),
        }
    }
}
