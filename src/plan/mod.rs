//! `edmd plan`: the preprocessor alone, offline, with everything written down — the trace CSV
//! of `design.md`, a summary (text and JSON) and SVG plots.
//!
//! It streams: blocks are read, segmented, planned and written as they come, so the memory used
//! is the planner's window, the time-optimal bound's horizon of samples and the bounded plot
//! series, whatever the program's length.

use std::fs::File;
use std::io::{self, IsTerminal, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use serde::Serialize;

use crate::config::Config;
use crate::gcode::{Block, BlockKind, WorkStart};
use crate::geometry::running_max;
use crate::path::{CutPlan, JobPath, PathError, PathItem, PathSpec};
use crate::plot::Decimated;
use crate::preprocess::{PlanSettings, PreprocessStats, Preprocessor, Segment, bound};
use crate::vocab::{Axis, Predictor, Segmentation};

mod charts;
mod estimate;
mod row;
use charts::write_reports;

/// Points kept per plotted series.
const PLOT_POINTS: usize = 20_000;

#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    #[error("{0}")]
    Program(#[from] PathError),
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: io::Error },
    /// `--out` names something that is not a directory: bad input, like a bad program.
    #[error("{path}: not a directory (--out names the directory the plan is written into)")]
    NotADirectory { path: PathBuf },
}

fn io_err(path: &Path) -> impl FnOnce(io::Error) -> PlanError + '_ {
    move |source| PlanError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// A pass of a plan in passes: its condition, offset, feed ceiling and estimated time.
#[derive(Debug, Clone, Serialize)]
pub struct PassEstimate {
    pub condition: u32,
    pub offset_mm: f64,
    pub feed_mm_per_min: Option<f64>,
    pub estimated_time_s: f64,
}

/// The numbers of a plan, as written to `summary.json`.
#[derive(Debug, Clone, Serialize)]
pub struct PlanSummary {
    pub program: String,
    pub segmentation: String,
    pub predictor: String,
    /// `interpolation.chord_tolerance_mm`, as configured.
    pub chord_tolerance_mm: f64,
    /// The tolerance the segmenter holds in machine space where it differs from the
    /// configured one (four-axis wire machines: the configured one divided by √2, so that the
    /// upper guide's path keeps the configured one too).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub chord_tolerance_held_mm: Option<f64>,
    pub period_ms: f64,
    pub blocks: u64,
    pub segments: u64,
    pub length_mm: f64,
    pub planned_time_s: f64,
    /// The estimated machining time (s): cuts at the servo's nominal feed where that is
    /// slower than the plan ([`estimate`]).
    pub estimated_time_s: f64,
    /// A job in passes: each pass's estimate, first to last.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub passes: Vec<PassEstimate>,
    /// Dense forward/backward pass under the same limits; `None` when skipped (long programs).
    pub time_optimal_bound_s: Option<f64>,
    /// `planned / bound - 1`.
    pub time_over_bound: Option<f64>,
    /// Largest true chord error (mm), as measured.
    pub max_chord_error_mm: f64,
    /// Segments whose measured chord error is over the tolerance.
    pub segments_over_tolerance: u64,
    /// Largest certified bound on a segment's chord error (mm): no segment's curve leaves its
    /// chord by more. At most the tolerance.
    pub max_chord_bound_mm: f64,
    /// Segments whose certified bound is over the tolerance (none: the segmenter accepts a
    /// segment only when its bound holds).
    pub segments_bound_over_tolerance: u64,
    /// Measurements within the tolerance that the bound refused (the segment was shortened).
    pub refused_by_bound: u64,
    /// Bézier pieces examined by the certificates, per segment.
    pub certified_pieces_per_segment: f64,
    pub max_feed_mm_per_min: f64,
    /// Period mode: `|step - planned| / planned` (seed 001 eq. 16).
    pub max_fluctuation: Option<f64>,
    pub mean_fluctuation: Option<f64>,
    /// Largest tangential acceleration: between consecutive periods in period mode, over each
    /// segment in chord mode (mm/s²).
    pub max_tangential_accel_mm_per_s2: f64,
    /// Largest `v² / rho` at segment ends (mm/s²).
    pub max_normal_accel_mm_per_s2: f64,
    /// Curve evaluations per output segment, everything included (segmentation, chord-error
    /// measurement, period steps and their corrections).
    pub curve_evals_per_segment: f64,
    /// Period mode: evaluations of the period stepper alone per period step.
    pub step_evals_per_segment: Option<f64>,
    pub wall_time_s: f64,
    pub segments_per_second: f64,
    /// Peak resident memory of the process (KiB, from `/proc/self/status`).
    pub peak_rss_kib: Option<u64>,
    /// A die-sinker's orbital sinking moves, in program order (at most [`MAX_STAGES`]): the
    /// stages of a rough-to-finish sequence.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub stages: Vec<crate::path::StageRow>,
}

impl PlanSummary {
    /// The human-readable summary (`summary.txt`, and stdout).
    pub fn text(&self) -> String {
        let opt = |v: Option<f64>, unit: &str, scale: f64, digits: usize| match v {
            Some(v) => format!("{:.*}{unit}", digits, v * scale),
            None => "-".to_string(),
        };
        let mut s = String::new();
        s += &format!("program            {}\n", self.program);
        s += &format!(
            "mode               {} ({} predictor), tolerance {} mm{}, period {} ms\n",
            self.segmentation,
            self.predictor,
            self.chord_tolerance_mm,
            self.chord_tolerance_held_mm
                .map_or(String::new(), |held| format!(
                    " (held as {held:.6} mm in four axes)"
                )),
            self.period_ms
        );
        s += &format!("blocks             {}\n", self.blocks);
        s += &format!("segments           {}\n", self.segments);
        s += &format!("length             {:.4} mm\n", self.length_mm);
        s += &format!(
            "motion time        {:.4} s (the path at its planned feeds)\n",
            self.planned_time_s
        );
        s += &format!(
            "estimated time     {:.1} s (cuts at the servo's nominal feed)\n",
            self.estimated_time_s
        );
        for (i, p) in self.passes.iter().enumerate() {
            s += &format!(
                "  pass {:<2} E{:<4}  {:.1} s (offset {:.4} mm{})\n",
                i + 1,
                p.condition,
                p.estimated_time_s,
                p.offset_mm,
                p.feed_mm_per_min
                    .map_or(String::new(), |f| format!(", at most {f} mm/min"))
            );
        }
        s += &format!(
            "time-optimal bound {}{}\n",
            opt(self.time_optimal_bound_s, " s", 1.0, 4),
            match self.time_over_bound {
                Some(r) => format!(" (planned is {:+.3} % over)", 100.0 * r),
                None => " (no path)".into(),
            }
        );
        s += &format!(
            "max chord error    {:.6} mm ({} over tolerance)\n",
            self.max_chord_error_mm, self.segments_over_tolerance
        );
        s += &format!(
            "max chord bound    {:.6} mm certified ({} over tolerance, {} measurements refused)\n",
            self.max_chord_bound_mm, self.segments_bound_over_tolerance, self.refused_by_bound
        );
        s += &format!(
            "max feed           {:.1} mm/min\n",
            self.max_feed_mm_per_min
        );
        s += &format!(
            "fluctuation        max {}  mean {}\n",
            opt(self.max_fluctuation, "", 1.0, 9),
            opt(self.mean_fluctuation, "", 1.0, 9)
        );
        s += &format!(
            "max |a_T|          {:.1} mm/s²\n",
            self.max_tangential_accel_mm_per_s2
        );
        s += &format!(
            "max a_N            {:.1} mm/s²\n",
            self.max_normal_accel_mm_per_s2
        );
        s += &format!(
            "evals per segment  {:.3}{}\n",
            self.curve_evals_per_segment,
            match self.step_evals_per_segment {
                Some(v) => format!(" (period stepper alone {v:.3})"),
                None => String::new(),
            }
        );
        s += &format!(
            "wall time          {:.3} s ({:.0} segments/s)\n",
            self.wall_time_s, self.segments_per_second
        );
        if let Some(kib) = self.peak_rss_kib {
            s += &format!("peak RSS           {:.1} MiB\n", kib as f64 / 1024.0);
        }
        for st in &self.stages {
            s += &format!("orbit stage        {}\n", st.text());
        }
        s
    }
}

/// Peak resident set size of this process, KiB (Linux).
pub fn peak_rss_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// A reader that counts the bytes it hands out (for the progress bar).
struct Counting<R> {
    inner: R,
    count: Arc<AtomicU64>,
    /// Bytes the runs before this one read (a job in passes reads the file once a pass).
    base: u64,
}

impl<R: Read> Read for Counting<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.count.fetch_add(n as u64, Ordering::Relaxed);
        Ok(n)
    }
}

/// Loops and calls seek back: the count follows the position.
impl<R: io::Seek> io::Seek for Counting<R> {
    fn seek(&mut self, pos: io::SeekFrom) -> io::Result<u64> {
        let at = self.inner.seek(pos)?;
        self.count.store(self.base + at, Ordering::Relaxed);
        Ok(at)
    }
}

/// The progress bar on stderr (`term`), shown only after planning has run for a second
/// (short plans print nothing), updated at most every 200 ms.
struct Progress {
    bar: Option<indicatif::ProgressBar>,
    enabled: bool,
    total: u64,
    started: Instant,
    last: Instant,
}

impl Progress {
    fn new(enabled: bool, total: u64) -> Progress {
        let now = Instant::now();
        Progress {
            bar: None,
            enabled,
            total: total.max(1),
            started: now,
            last: now,
        }
    }

    fn tick(&mut self, done: u64, blocks: u64) {
        let now = Instant::now();
        if !self.enabled
            || now.duration_since(self.started) < Duration::from_secs(1)
            || now.duration_since(self.last) < Duration::from_millis(200)
        {
            return;
        }
        self.last = now;
        let total = self.total;
        let bar = self
            .bar
            .get_or_insert_with(|| crate::term::bar(total, true));
        bar.set_position(done.min(total));
        bar.set_message(format!(
            "{blocks} blocks  {:.1} s",
            now.duration_since(self.started).as_secs_f64()
        ));
    }

    fn finish(&mut self) {
        if self.bar.take().is_some() {
            crate::term::clear();
        }
    }
}

/// Running figures over the emitted segments, and the plot series.
struct Collector {
    trace_path: PathBuf,
    /// The trace file's writer.
    rows: row::RowWriter<File>,
    t: f64,
    s: f64,
    segments: u64,
    length: f64,
    max_err: f64,
    over: u64,
    max_bound: f64,
    bound_over: u64,
    max_feed: f64,
    fl_max: f64,
    fl_sum: f64,
    fl_count: u64,
    max_at: f64,
    max_an: f64,
    prev: Option<(f64, f64, bool)>,
    tolerance: f64,
    period: f64,
    period_mode: bool,
    path: Decimated,
    chord: Decimated,
    feed: Decimated,
    accel: Decimated,
    fluct: Decimated,
    /// Z against path length, when the machine has a Z axis (a path plot shows X and Y).
    z: Option<Decimated>,
    /// On a four-axis wire machine: the upper guide's path and the wire's angle.
    wire: Option<charts::WireView>,
    /// Rapid moves, each G0 block one stroke, [`MAX_RAPID_STROKES`] at most.
    rapids: Vec<(f64, f64)>,
    rapid_strokes: usize,
    /// The first point, and the direction the path leaves it in.
    start: Option<(f64, f64)>,
    direction: Option<(f64, f64)>,
    error: Option<io::Error>,
    /// The estimated machining time.
    cut: estimate::CutTime,
}

/// Rapid strokes kept for the path plot (a program with more draws the first ones).
const MAX_RAPID_STROKES: usize = 10_000;

impl Collector {
    fn first_row(&mut self, block: &Block) {
        let p = block.start();
        let u = match block.kind {
            BlockKind::Nurbs { .. } => Some(block.curve.u_min()),
            _ => None,
        };
        self.write_row(&row::Row {
            block,
            u,
            point: &p,
            t: 0.0,
            feed_mm_per_min: 0.0,
            chord_err: 0.0,
            chord_bound: 0.0,
            fluctuation: None,
            rho: f64::INFINITY,
            evals: 0,
        });
        self.path.push(p[0], p[1]);
        self.start.get_or_insert((p[0], p[1]));
    }

    fn write_row(&mut self, row: &row::Row) {
        if self.error.is_none()
            && let Err(e) = self.rows.push(row)
        {
            self.error = Some(e);
        }
    }

    fn add(&mut self, seg: &Segment) {
        self.t += seg.duration;
        self.s += seg.length;
        self.segments += 1;
        self.length += seg.length;
        self.max_err = running_max(self.max_err, seg.chord_error);
        if seg.chord_error > self.tolerance {
            self.over += 1;
        }
        self.max_bound = running_max(self.max_bound, seg.chord_bound);
        if seg.chord_bound > self.tolerance {
            self.bound_over += 1;
        }
        let v = seg.v_exit;
        self.max_feed = running_max(self.max_feed, seg.v_peak);
        self.cut.add(seg);
        if let Some(f) = seg.fluctuation {
            self.fl_max = self.fl_max.max(f);
            self.fl_sum += f;
            self.fl_count += 1;
            self.fluct.push(self.t, f);
        }
        let full = (seg.duration - self.period).abs() < 1e-9 && seg.fluctuation.is_some();
        let at = if self.period_mode {
            match self.prev {
                Some((_, v_prev, prev_full)) if prev_full && full => {
                    Some((v - v_prev) / self.period)
                }
                _ => None,
            }
        } else if seg.length > 0.0 {
            Some((seg.v_exit * seg.v_exit - seg.v_entry * seg.v_entry) / (2.0 * seg.length))
        } else {
            None
        };
        if let Some(a) = at {
            self.max_at = running_max(self.max_at, a.abs());
            self.accel.push(self.t, a);
        }
        if seg.rho_end > 0.0 {
            self.max_an = running_max(self.max_an, v * v / seg.rho_end);
        }
        self.prev = Some((self.t, v, full));
        self.path.push(seg.end[0], seg.end[1]);
        if self.direction.is_none() && seg.length > 0.0 {
            let d = (seg.end[0] - seg.start[0], seg.end[1] - seg.start[1]);
            if d.0 != 0.0 || d.1 != 0.0 {
                self.direction = Some(d);
            }
        }
        if seg.block.kind == BlockKind::Rapid && self.rapid_strokes < MAX_RAPID_STROKES {
            let start = (seg.start[0], seg.start[1]);
            if self.rapids.last() != Some(&start) {
                self.rapids.extend([crate::plot::BREAK, start]);
                self.rapid_strokes += 1;
            }
            self.rapids.push((seg.end[0], seg.end[1]));
        }
        if let (Some(z), Some(axis)) = (self.z.as_mut(), self.rows.z()) {
            z.push(self.s, seg.end[axis]);
        }
        if let Some(wire) = self.wire.as_mut() {
            wire.push(self.s, &seg.end);
        }
        self.chord.push(self.s, seg.chord_error);
        self.feed.push(self.t, v * 60.0);
        let u = match seg.block.kind {
            BlockKind::Nurbs { .. } => Some(seg.u_end),
            _ => None,
        };
        self.write_row(&row::Row {
            block: &seg.block,
            u,
            point: &seg.end,
            t: self.t,
            feed_mm_per_min: v * 60.0,
            chord_err: seg.chord_error,
            chord_bound: seg.chord_bound,
            fluctuation: seg.fluctuation,
            rho: seg.rho_end,
            evals: seg.evals,
        });
    }
}

/// Plans `program` under `config`, writing `trace.csv`, `summary.json`, `summary.txt` and the
/// plots into `out_dir` (created if needed).
pub fn plan_program(
    program: &Path,
    config: &Config,
    cut: &CutPlan,
    out_dir: &Path,
    progress: bool,
) -> Result<PlanSummary, PlanError> {
    let started = Instant::now();
    if out_dir.exists() && !out_dir.is_dir() {
        return Err(PlanError::NotADirectory {
            path: out_dir.to_path_buf(),
        });
    }
    let file = File::open(program).map_err(io_err(program))?;
    let runs = cut.passes.len().max(1) as u64;
    let total = file.metadata().map(|m| m.len()).unwrap_or(0) * runs;
    drop(file);
    let count = Arc::new(AtomicU64::new(0));
    let name = program.display().to_string();
    let axes = &config.machine.axes;
    // The job's path as the job cuts it: one run of the program, or one per pass (each pass
    // reads the file again, as a job does).
    let spec = PathSpec::from_config(config, &WorkStart::default(), cut);
    let open = |options| {
        let done = count.load(Ordering::Relaxed);
        crate::gcode::open_program_as(program, &name, axes, options, |inner| {
            // A pass's run counts on from where the last one ended.
            Counting {
                inner,
                count: Arc::clone(&count),
                base: done,
            }
        })
    };
    let mut path = JobPath::new(&spec, &name, open, None);
    std::fs::create_dir_all(out_dir).map_err(io_err(out_dir))?;
    let trace_path = out_dir.join("trace.csv");
    let trace = File::create(&trace_path).map_err(io_err(&trace_path))?;

    let settings = PlanSettings::from_config(config);
    let mut c = Collector::new(trace, trace_path.clone(), axes, &settings);
    c.wire = charts::WireView::new(axes, config.wire.guides);
    c.cut = estimate::CutTime::new(config);

    let mut pre = Preprocessor::new(settings.clone());
    let mut bound = bound::TimeOptimalBound::new(&settings, bound::MAX_SPACING_MM);
    let mut bar = Progress::new(progress && io::stderr().is_terminal(), total);
    let mut first = true;
    let mut stages = Vec::new();
    let mut blocks_read = 0u64;
    while let Some(item) = path.next_item()? {
        let block = match item {
            PathItem::Block(block) => Arc::new(block),
            PathItem::PassStart { .. } => {
                c.cut.pass_starts(blocks_read);
                continue;
            }
            PathItem::Skipped { .. } => continue,
        };
        blocks_read += 1;
        if stages.len() < crate::path::MAX_STAGES
            && let Some(stage) = crate::path::StageRow::of(&block)
        {
            stages.push(stage);
        }
        if first {
            c.first_row(&block);
            first = false;
        }
        bound.push_block(&block);
        pre.push_block(block, |seg| c.add(&seg));
        bar.tick(count.load(Ordering::Relaxed), pre.stats().blocks);
    }
    pre.finish(|seg| c.add(&seg));
    bar.finish();
    for w in path.take_warnings() {
        tracing::warn!("{name}:{}:{}: {}", w.line, w.col, w.message);
    }
    if let Some(e) = c.error.take() {
        return Err(PlanError::Io {
            path: c.trace_path.clone(),
            source: e,
        });
    }
    c.rows.finish().map_err(io_err(&trace_path))?;
    let wall = started.elapsed().as_secs_f64();

    let bound = bound.finish();
    let mut summary = summary_of(name, &settings, &c, &pre.stats(), bound, wall);
    summary.stages = stages;
    summary.passes = (cut.passes.iter().zip(&c.cut.pass_seconds))
        .map(|(p, s)| PassEstimate {
            condition: p.condition,
            offset_mm: p.offset_mm,
            feed_mm_per_min: p.feed_mm_per_min,
            estimated_time_s: *s,
        })
        .collect();
    // The tolerance as configured; on a four-axis wire machine the segmenter holds a tighter
    // one in machine space (`config::settings`), shown beside it.
    summary.chord_tolerance_mm = config.interpolation.chord_tolerance_mm;
    summary.chord_tolerance_held_mm =
        (settings.tolerance_mm != summary.chord_tolerance_mm).then_some(settings.tolerance_mm);
    write_reports(out_dir, &summary, &c, &settings)?;
    Ok(summary)
}

impl Collector {
    /// A collector writing the trace to `trace` (at `trace_path`), its header gathered, with a
    /// column per axis beyond X, Y and Z.
    fn new(trace: File, trace_path: PathBuf, axes: &[Axis], settings: &PlanSettings) -> Collector {
        let has_z = axes.contains(&Axis::Z);
        Collector {
            trace_path,
            rows: row::RowWriter::new(axes, trace),
            t: 0.0,
            s: 0.0,
            segments: 0,
            length: 0.0,
            max_err: 0.0,
            over: 0,
            max_bound: 0.0,
            bound_over: 0,
            max_feed: 0.0,
            fl_max: 0.0,
            fl_sum: 0.0,
            fl_count: 0,
            max_at: 0.0,
            max_an: 0.0,
            prev: None,
            tolerance: settings.tolerance_mm,
            period: settings.period_s,
            period_mode: settings.segmentation == Segmentation::Period,
            path: Decimated::new(PLOT_POINTS),
            chord: Decimated::new(PLOT_POINTS),
            feed: Decimated::new(PLOT_POINTS),
            accel: Decimated::new(PLOT_POINTS),
            fluct: Decimated::new(PLOT_POINTS),
            z: has_z.then(|| Decimated::new(PLOT_POINTS)),
            wire: None,
            rapids: Vec::new(),
            rapid_strokes: 0,
            start: None,
            direction: None,
            error: None,
            cut: estimate::CutTime::default(),
        }
    }
}

/// The summary of a plan from what the collector saw and the preprocessor counted.
fn summary_of(
    name: String,
    settings: &PlanSettings,
    c: &Collector,
    stats: &PreprocessStats,
    bound: Option<f64>,
    wall: f64,
) -> PlanSummary {
    let segments = c.segments.max(1) as f64;
    let period_mode = c.period_mode;
    PlanSummary {
        program: name,
        segmentation: match settings.segmentation {
            Segmentation::Chord => "chord",
            Segmentation::Period => "period",
        }
        .into(),
        predictor: match settings.predictor {
            Predictor::Taylor => "taylor",
            Predictor::Hamming => "hamming",
        }
        .into(),
        chord_tolerance_mm: settings.tolerance_mm,
        chord_tolerance_held_mm: None,
        period_ms: settings.period_s * 1000.0,
        blocks: stats.blocks,
        segments: c.segments,
        length_mm: c.length,
        planned_time_s: c.t,
        estimated_time_s: c.cut.seconds,
        passes: Vec::new(),
        time_optimal_bound_s: bound,
        time_over_bound: bound.map(|b| c.t / b - 1.0),
        max_chord_error_mm: c.max_err,
        segments_over_tolerance: c.over,
        max_chord_bound_mm: c.max_bound,
        segments_bound_over_tolerance: c.bound_over,
        refused_by_bound: stats.segmenter.refused_by_bound,
        certified_pieces_per_segment: (stats.segmenter.certified_pieces + stats.certified_pieces)
            as f64
            / segments,
        max_feed_mm_per_min: c.max_feed * 60.0,
        max_fluctuation: (c.fl_count > 0).then_some(c.fl_max),
        mean_fluctuation: (c.fl_count > 0).then(|| c.fl_sum / c.fl_count as f64),
        max_tangential_accel_mm_per_s2: c.max_at,
        max_normal_accel_mm_per_s2: c.max_an,
        curve_evals_per_segment: (stats.segmenter.evals + stats.step_evals) as f64 / segments,
        step_evals_per_segment: period_mode.then(|| stats.step_evals as f64 / segments),
        wall_time_s: wall,
        segments_per_second: c.segments as f64 / wall.max(1e-9),
        peak_rss_kib: peak_rss_kib(),
        stages: Vec::new(),
    }
}
