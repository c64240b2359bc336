//! The producer thread: program text to loop-buffer blocks.
//!
//! It streams the job's path ([`JobPath`]: the program through the reader and every stage)
//! through the [`Preprocessor`], turns every planned
//! segment into a [`StepBlock`] and pushes it into the loop buffer, sleeping whenever the
//! buffer is full. Step positions are rounded once per segment end point, absolutely, from mm
//! (never accumulated), so a block's start is bit-for-bit the previous block's end.

use crate::buffer::BlockFlags;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use super::super::shaping::program::JobProgram;
use super::super::tick::probe::ProbeLink;
use super::spec::JobSpec;
use crate::buffer::{LoopBuffer, StepBlock};
use crate::gcode::{self, BlockKind};
use crate::geometry::Point;
use crate::path::{JobPath, MAX_STAGES, PathError, PathItem, StageRow};
use crate::preprocess::{PreprocessStats, Preprocessor, Segment};
use crate::vocab::{MAX_AXES, Steps};

/// Largest step position accepted: beyond 2^53 an `f64` no longer holds every integer.
const MAX_STEPS: f64 = 9.0e15;

/// Why the producer stopped early.
#[derive(Debug, thiserror::Error)]
pub enum ProducerError {
    #[error(transparent)]
    Path(#[from] PathError),
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
    pub stages: Vec<StageRow>,
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
    fn start_pass(&mut self, number: u8, at_start_hole: bool) {
        self.pass = number;
        self.pass_starts = BlockFlags::PASS_START;
        if at_start_hole {
            self.pass_starts |= BlockFlags::START_HOLE;
        }
    }

    /// The path length (mm) the next block starts at: a direct approach counts the program
    /// it skips, so progress and placed debris stay where a full run has them.
    fn set_path_mm(&mut self, mm: f64) {
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
        if segment.block.spark_off.is_some() {
            flags |= BlockFlags::APPROACH;
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
            path: segment.path,
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
            pass: self.pass,
            wire_offset_mm: segment.block.wire_offset.map_or(0.0, |w| {
                if w.left {
                    w.d_mm as f32
                } else {
                    -w.d_mm as f32
                }
            }),
        };
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
    let open =
        |options| gcode::open_program_as(&program.path, &program.name, &spec.axes, options, |f| f);
    // The job's end (a stop, an alarm) reaches a reader busy in a loop that moves nothing.
    let mut path = JobPath::new(&spec.path, &program.name, open, Some(cancel));
    let buffer = out.buffer;
    let mut probes = 0;
    loop {
        let item = match path.next_item() {
            Ok(Some(item)) => item,
            Ok(None) => break,
            Err(e) if e.cancelled() => {
                out.report.aborted = true;
                break;
            }
            Err(e) => return Err(e.into()),
        };
        let block = match item {
            PathItem::PassStart {
                pass,
                at_start_hole,
            } => {
                // Segments leave the preprocessor up to a look-ahead later: the pass's
                // first block is marked when the last pass is out, so plan its end as a
                // standstill.
                if pass > 1 {
                    pre.finish(|s| out.push(s));
                }
                out.maker.start_pass(pass, at_start_hole);
                continue;
            }
            PathItem::Skipped { mm } => {
                out.maker.set_path_mm(out.maker.path_mm() + mm);
                continue;
            }
            PathItem::Block(block) => block,
        };
        if out.report.stages.len() < MAX_STAGES
            && let Some(stage) = StageRow::of(&block)
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
            probes += 1;
            let waiting = Instant::now();
            let result = probe.wait(probes, || buffer.aborted());
            out.waited += waiting.elapsed();
            match result {
                Some(result) => {
                    let step_mm = &spec.step_mm;
                    let mm = Point::from_fn(|i, _| {
                        step_mm.get(i).map_or(0.0, |s| result.steps[i] as f64 * s)
                    });
                    path.probed(&mm, result.contact);
                    out.maker.probed(&result.steps);
                }
                None => out.report.aborted = true,
            }
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
