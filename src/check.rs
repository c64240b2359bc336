//! `edmd check`: what a program contains, block by block, and in total.

use std::fmt::Write as _;

use crate::gcode::{Block, BlockKind};
use crate::geometry::Point;
use crate::vocab::Axis;

/// Running totals over a program's blocks.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Totals {
    pub rapid: u64,
    pub line: u64,
    pub arc: u64,
    pub nurbs: u64,
    /// Probing moves (`G38.x`, `G31`).
    pub probe: u64,
    /// Control points over all NURBS blocks.
    pub nurbs_points: u64,
    /// Path length of feed moves, mm.
    pub feed_length_mm: f64,
    /// Path length of rapids, mm.
    pub rapid_length_mm: f64,
    /// Lowest and highest programmed feed, mm/min.
    pub feed_range_mm_per_min: Option<(f64, f64)>,
    /// Where the program ends, mm.
    pub end: Option<Point>,
}

impl Totals {
    pub fn blocks(&self) -> u64 {
        self.rapid + self.line + self.arc + self.nurbs + self.probe
    }

    /// Adds a block whose path length is `length_mm`.
    pub fn add(&mut self, block: &Block, length_mm: f64) {
        match &block.kind {
            BlockKind::Rapid => self.rapid += 1,
            BlockKind::Line => self.line += 1,
            BlockKind::Arc { .. } => self.arc += 1,
            BlockKind::Nurbs { .. } => {
                self.nurbs += 1;
                self.nurbs_points += block.curve.num_points() as u64;
            }
            BlockKind::Probe(_) => self.probe += 1,
        }
        if block.kind == BlockKind::Rapid {
            self.rapid_length_mm += length_mm;
        } else {
            self.feed_length_mm += length_mm;
        }
        if let Some(f) = block.feed_mm_per_min {
            self.feed_range_mm_per_min = Some(match self.feed_range_mm_per_min {
                None => (f, f),
                Some((lo, hi)) => (lo.min(f), hi.max(f)),
            });
        }
        self.end = Some(block.end());
    }
}

/// `X1.0000 Y2.0000` for the machine's axes.
pub fn format_point(p: &Point, axes: &[Axis]) -> String {
    let mut s = String::new();
    for (i, a) in axes.iter().enumerate() {
        if i > 0 {
            s.push(' ');
        }
        // Rounding can leave -0.0000; a machinist reads that as a sign error.
        let v = if p[i].abs() < 5e-5 { 0.0 } else { p[i] };
        let _ = write!(s, "{a}{v:.4}");
    }
    s
}

/// Header for [`describe_block`] rows.
pub const BLOCK_TABLE_HEADER: &str = "    line  kind      length_mm  details";

/// One row of the block table: line, kind, length and what the block is.
pub fn describe_block(block: &Block, length_mm: f64, axes: &[Axis]) -> String {
    let c = &block.curve;
    let details = match &block.kind {
        BlockKind::Rapid | BlockKind::Line => {
            format!(
                "{} -> {}",
                format_point(&block.start(), axes),
                format_point(&block.end(), axes)
            )
        }
        BlockKind::Probe(p) => {
            format!(
                "{} {} -> {} (or where contact {})",
                p.g_code(),
                format_point(&block.start(), axes),
                format_point(&block.end(), axes),
                if p.away { "is lost" } else { "happens" }
            )
        }
        BlockKind::Arc {
            center,
            radius,
            sweep,
            plane,
        } => format!(
            "{} {} radius {radius:.4} sweep {:+.3}° centre {} -> {}",
            plane.g_code(),
            if *sweep > 0.0 { "G3" } else { "G2" },
            sweep.to_degrees(),
            format_point(center, axes),
            format_point(&block.end(), axes)
        ),
        BlockKind::Nurbs { form } => format!(
            "{} degree {}, {} points, knots [{}, {}], {} -> {}",
            form.name(),
            c.degree(),
            c.num_points(),
            c.u_min(),
            c.u_max(),
            format_point(&block.start(), axes),
            format_point(&block.end(), axes)
        ),
    };
    let feed = match block.feed_mm_per_min {
        Some(f) => format!(" F{f}"),
        None => String::new(),
    };
    format!(
        "{:>8}  {:<6} {:>12.4}  {details}{feed}",
        block.line,
        block.kind.name(),
        length_mm
    )
}

/// The closing lines of `edmd check`.
pub fn describe_totals(t: &Totals, axes: &[Axis], max_feed_mm_per_min: f64) -> String {
    let mut s = format!(
        "blocks: {} (rapid {}, line {}, arc {}, nurbs {} with {} control points)\nlength: {:.4} mm at feed, {:.4} mm rapid",
        t.blocks(),
        t.rapid,
        t.line,
        t.arc,
        t.nurbs,
        t.nurbs_points,
        t.feed_length_mm,
        t.rapid_length_mm
    );
    if t.probe > 0 {
        let _ = write!(
            s,
            "\nprobing moves: {} (measured as far as their end points)",
            t.probe
        );
    }
    if let Some((lo, hi)) = t.feed_range_mm_per_min {
        let _ = write!(s, "\nfeed: {lo} to {hi} mm/min");
        if hi > max_feed_mm_per_min {
            let _ = write!(
                s,
                " (above machine.max_feed_mm_per_min = {max_feed_mm_per_min}: will be clamped)"
            );
        }
    }
    if let Some(end) = &t.end {
        let _ = write!(s, "\nend position: {}", format_point(end, axes));
    }
    s
}
