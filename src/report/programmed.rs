//! The programmed path of a program as a drawing: two axes, thinned in the plane. The page
//! draws it under the executed path (`GET /api/path`), and so does a job's report
//! (`path.svg`).
//!
//! **A drawing's worth of points, whatever the program.** A backplot is a picture: past a
//! few thousand points nothing more can be seen, and a program that loops a million times
//! round the same circle draws the same circle. So the path is thinned in the plane, not
//! along the program: a point is kept when it enters a cell of a square grid that no kept
//! point has entered yet; a stretch that only retraces cells already drawn lifts the pen
//! (a new stroke starts where the path leaves them). When the kept points pass
//! [`MAX_POINTS`], the grid's cell doubles and the kept strokes are thinned again the same
//! way. Memory is bounded by the points kept, never by the program's length, and retracing
//! cannot alias (keeping every n-th point of a path that repeats every n points would keep
//! one spot of it).
//!
//! **A budget.** Reading a program runs its loops; [`programmed_path`] stops at a deadline
//! (its reader is cancelled through [`Budget::cancel`]) or at [`MAX_BLOCKS`] blocks and
//! returns what it drew so far, marked `partial`.

use std::collections::HashSet;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use serde::Serialize;

use crate::vocab::Axis;

/// Points of a drawn path at most.
pub const MAX_POINTS: usize = 20_000;
/// Blocks read at most for one drawing.
pub const MAX_BLOCKS: usize = 500_000;
/// The first grid cell (mm): finer than any screen shows a part.
const FIRST_CELL_MM: f64 = 1e-4;

/// Why a program could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum DrawError {
    #[error("{name}: {source}")]
    Open {
        name: String,
        source: std::io::Error,
    },
    #[error(transparent)]
    Program(crate::path::PathError),
}

#[derive(Debug, Serialize)]
pub struct PlannedPath {
    pub program: String,
    /// The two axes drawn (X and Y where the machine has them).
    pub axes: [String; 2],
    /// Polylines: each is a run of points `[a, b]` (mm); a rapid is its own polyline.
    pub strokes: Vec<Stroke>,
    /// Blocks read, and whether the drawing stops short of the program's end (the block or
    /// time budget ran out).
    pub blocks: usize,
    pub partial: bool,
    /// The grid cell the drawing was thinned to (mm).
    pub cell_mm: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct Stroke {
    pub rapid: bool,
    pub points: Vec<[f64; 2]>,
}

/// How long and how far one drawing may go: the reader is cancelled through `cancel` (a
/// timer sets it).
#[derive(Debug, Clone)]
pub struct Budget {
    pub cancel: Arc<AtomicBool>,
    pub max_blocks: usize,
}

/// A cell of the grid.
type Cell = (i64, i64);

/// The drawing being made: strokes thinned on a grid.
struct Drawing {
    cell: f64,
    strokes: Vec<Stroke>,
    /// The steps between two cells already drawn (either way round).
    edges: HashSet<(Cell, Cell)>,
    points: usize,
    /// The last point offered, its cell, and whether the current stroke ends in that cell
    /// (the pen is down).
    last: Option<([f64; 2], Cell, bool)>,
}

impl Drawing {
    fn new() -> Drawing {
        Drawing {
            cell: FIRST_CELL_MM,
            strokes: Vec::new(),
            edges: HashSet::new(),
            points: 0,
            last: None,
        }
    }

    fn cell_of(&self, p: [f64; 2]) -> Cell {
        (
            (p[0] / self.cell).floor() as i64,
            (p[1] / self.cell).floor() as i64,
        )
    }

    /// Offers the next point of the path (of a rapid move or not).
    fn offer(&mut self, p: [f64; 2], rapid: bool) {
        self.take(p, rapid);
        if self.points > MAX_POINTS {
            self.coarsen();
        }
    }

    /// Keeps `p` if the step to it from the last point is one not drawn yet.
    fn take(&mut self, p: [f64; 2], rapid: bool) {
        let c = self.cell_of(p);
        let Some((q, qc, down)) = self.last else {
            self.strokes.push(Stroke {
                rapid,
                points: vec![p],
            });
            self.points += 1;
            self.last = Some((p, c, true));
            return;
        };
        if qc == c {
            // Inside one cell nothing new can be seen.
            self.last = Some((p, c, down));
            return;
        }
        let fresh = self.edges.insert(if qc < c { (qc, c) } else { (c, qc) });
        if fresh {
            match self.strokes.last_mut() {
                Some(s) if down && s.rapid == rapid => {
                    s.points.push(p);
                    self.points += 1;
                }
                _ => {
                    // The pen comes down where the path leaves what is drawn.
                    self.strokes.push(Stroke {
                        rapid,
                        points: vec![q, p],
                    });
                    self.points += 2;
                }
            }
        }
        self.last = Some((p, c, fresh));
    }

    /// Doubles the cell until the kept points fit in half the budget, thinning the kept
    /// strokes the same way.
    fn coarsen(&mut self) {
        let last = self.last;
        while self.points > MAX_POINTS / 2 {
            let strokes = std::mem::take(&mut self.strokes);
            self.cell *= 2.0;
            self.edges.clear();
            self.points = 0;
            for s in strokes {
                // Each kept stroke is redrawn on its own: the pen lifts between them.
                self.last = None;
                for p in s.points {
                    self.take(p, s.rapid);
                }
            }
        }
        // The path goes on from where it was, pen up.
        self.last = last.map(|(p, _, _)| (p, self.cell_of(p), false));
    }
}

/// The programmed path of `file` (named `name` in errors) as strokes in two axes, within
/// `budget`: in the program's own coordinates, or in machine coordinates from `start` (the
/// position and work offsets a job starts with), where the executed path is.
pub fn programmed_path(
    file: &Path,
    name: &str,
    axes: &[Axis],
    options: crate::gcode::ProgramOptions,
    start: Option<&crate::gcode::WorkStart>,
    budget: &Budget,
) -> Result<PlannedPath, DrawError> {
    let index = |a: Axis| axes.iter().position(|&x| x == a);
    let (ia, ib) = match (index(Axis::X), index(Axis::Y)) {
        (Some(x), Some(y)) => (x, y),
        _ => (0, 1.min(axes.len().saturating_sub(1))),
    };
    // Opened without blocking and only if still a regular file: a FIFO swapped in after the
    // name was confined would hold this drawing's thread for ever.
    let opened = crate::sys::open_regular(file).map_err(|source| DrawError::Open {
        name: name.to_string(),
        source,
    })?;
    let mut reader = crate::gcode::read_program(opened, name, axes, options);
    reader.cancel_on(budget.cancel.clone());
    if let Some(start) = start {
        reader.start_at(start);
    }
    // The program's own path: what its moves cut (wire offset, taper, orbit).
    let reader = crate::path::Pipeline::new(reader);
    let mut drawing = Drawing::new();
    let mut blocks = 0;
    let mut partial = false;
    for item in reader {
        let block = match item {
            Ok(block) => block,
            Err(e) if e.cancelled() => {
                partial = true;
                break;
            }
            Err(e) => return Err(DrawError::Program(e)),
        };
        blocks += 1;
        if blocks > budget.max_blocks || budget.cancel.load(Ordering::Relaxed) {
            partial = true;
            break;
        }
        let rapid = block.kind == crate::gcode::BlockKind::Rapid;
        let c = &block.curve;
        let (lo, hi) = (c.u_min(), c.u_max());
        let n = if c.degree() == 1 { 1 } else { 24 };
        let start = block.start();
        drawing.offer([start[ia], start[ib]], rapid);
        for k in 1..=n {
            let u = lo + (hi - lo) * k as f64 / n as f64;
            let p = c.point(u);
            drawing.offer([p[ia], p[ib]], rapid);
        }
    }
    let letter = |i: usize| {
        axes.get(i)
            .map_or("?".to_string(), |a| a.letter().to_string())
    };
    Ok(PlannedPath {
        program: name.to_string(),
        axes: [letter(ia), letter(ib)],
        cell_mm: drawing.cell,
        strokes: drawing.strokes,
        blocks,
        partial,
    })
}

impl PlannedPath {
    /// The cutting moves' strokes as one polyline for a chart, strokes apart at
    /// [`crate::plot::BREAK`]s (rapids are left out: the report draws the executed ones).
    pub fn cuts(&self) -> Vec<(f64, f64)> {
        let mut out = Vec::new();
        for stroke in self.strokes.iter().filter(|s| !s.rapid) {
            if !out.is_empty() {
                out.push(crate::plot::BREAK);
            }
            out.extend(stroke.points.iter().map(|p| (p[0], p[1])));
        }
        out
    }
}

/// The programmed cutting path of a job's program in machine coordinates, for its report:
/// what [`programmed_path`] draws from `start`, within [`MAX_BLOCKS`]; empty (with a
/// warning) when the program cannot be read again.
pub fn for_report(
    file: &Path,
    name: &str,
    axes: &[Axis],
    options: crate::gcode::ProgramOptions,
    start: &crate::gcode::WorkStart,
) -> Vec<(f64, f64)> {
    let budget = Budget {
        cancel: Arc::new(AtomicBool::new(false)),
        max_blocks: MAX_BLOCKS,
    };
    match programmed_path(file, name, axes, options, Some(start), &budget) {
        Ok(path) => path.cuts(),
        Err(e) => {
            tracing::warn!("report: the programmed path is not drawn: {e}");
            Vec::new()
        }
    }
}
