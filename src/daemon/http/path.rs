//! What the page draws besides the live state: the programs it can run, and the programmed
//! path of one of them (X and Y, decimated) under the executed one.

use std::path::Path;

use serde::Serialize;

use crate::vocab::Axis;

/// Points of a programmed path sent at most (every n-th is kept beyond it).
const MAX_POINTS: usize = 20_000;
/// Blocks read at most for a backplot (a larger program is drawn in part).
const MAX_BLOCKS: usize = 500_000;

#[derive(Debug, Serialize)]
pub struct ProgramEntry {
    pub name: String,
    pub bytes: u64,
}

/// Regular files under `dir`, four levels deep at most, at most 2000, sorted by name.
pub fn list_programs(dir: &Path) -> Result<Vec<ProgramEntry>, String> {
    let mut out = Vec::new();
    walk(dir, dir, 0, &mut out).map_err(|e| format!("{}: {e}", dir.display()))?;
    out.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(out)
}

fn walk(root: &Path, dir: &Path, depth: usize, out: &mut Vec<ProgramEntry>) -> std::io::Result<()> {
    for entry in std::fs::read_dir(dir)? {
        if out.len() >= 2000 {
            return Ok(());
        }
        let entry = entry?;
        let path = entry.path();
        let meta = std::fs::metadata(&path)?;
        let hidden = entry.file_name().to_string_lossy().starts_with('.');
        if hidden {
            continue;
        }
        if meta.is_dir() && depth < 3 {
            walk(root, &path, depth + 1, out)?;
        } else if meta.is_file() {
            let name = path.strip_prefix(root).unwrap_or(&path);
            out.push(ProgramEntry {
                name: name.display().to_string(),
                bytes: meta.len(),
            });
        }
    }
    Ok(())
}

#[derive(Debug, Serialize)]
pub struct PlannedPath {
    pub program: String,
    /// The two axes drawn (X and Y where the machine has them).
    pub axes: [String; 2],
    /// Polylines: each is a run of points `[a, b]` (mm); a rapid is its own polyline.
    pub strokes: Vec<Stroke>,
    /// Blocks read, and whether the path was cut short or thinned.
    pub blocks: usize,
    pub partial: bool,
}

#[derive(Debug, Serialize)]
pub struct Stroke {
    pub rapid: bool,
    pub points: Vec<[f64; 2]>,
}

/// The programmed path of `file` (named `name` in errors) as strokes in two axes.
pub fn programmed_path(
    file: &Path,
    name: &str,
    axes: &[Axis],
    options: crate::gcode::ProgramOptions,
) -> Result<PlannedPath, String> {
    let index = |a: Axis| axes.iter().position(|&x| x == a);
    let (ia, ib) = match (index(Axis::X), index(Axis::Y)) {
        (Some(x), Some(y)) => (x, y),
        _ => (0, 1.min(axes.len().saturating_sub(1))),
    };
    let reader = crate::gcode::open_program_as(file, name, axes, options, |f| f)
        .map_err(|e| e.to_string())?;
    let mut strokes: Vec<Stroke> = Vec::new();
    let mut blocks = 0;
    let mut points = 0;
    let mut partial = false;
    for item in reader {
        let block = item.map_err(|e| e.to_string())?;
        blocks += 1;
        if blocks > MAX_BLOCKS {
            partial = true;
            break;
        }
        let rapid = block.kind == crate::gcode::BlockKind::Rapid;
        let c = &block.curve;
        let (lo, hi) = (c.u_min(), c.u_max());
        let n = if c.degree() == 1 { 1 } else { 24 };
        let start = block.start();
        let same_kind = strokes.last().is_some_and(|s| s.rapid == rapid);
        if !same_kind {
            strokes.push(Stroke {
                rapid,
                points: vec![[start[ia], start[ib]]],
            });
            points += 1;
        }
        let stroke = strokes.last_mut().expect("pushed above");
        for k in 1..=n {
            let u = lo + (hi - lo) * k as f64 / n as f64;
            let p = c.point(u);
            stroke.points.push([p[ia], p[ib]]);
            points += 1;
        }
    }
    if points > MAX_POINTS {
        partial = true;
        let keep = points.div_ceil(MAX_POINTS);
        for s in &mut strokes {
            let last = *s.points.last().expect("a stroke has points");
            let mut thinned: Vec<[f64; 2]> = s.points.iter().step_by(keep).copied().collect();
            if thinned.last() != Some(&last) {
                thinned.push(last);
            }
            s.points = thinned;
        }
    }
    let letter = |i: usize| {
        axes.get(i)
            .map_or("?".to_string(), |a| a.letter().to_string())
    };
    Ok(PlannedPath {
        program: name.to_string(),
        axes: [letter(ia), letter(ib)],
        strokes,
        blocks,
        partial,
    })
}
