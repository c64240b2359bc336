//! `trace.csv`'s rows: one per segment end (and one for the path's first point), every number
//! at full precision, the shortest decimal that reads back as the same double, so a 0.1 µm
//! tolerance is not drowned by the printing.
//!
//! A row is built in one reused buffer through [`crate::decimal`], not `format!`: a plan of
//! 20,000 arcs writes 840,000 rows, and `core::fmt` spent more on them than segmenting and
//! planning did. The text is the one `format!("{}")` (and `{:e}` for the fluctuation) gives.

use crate::decimal::{push_f64, push_f64_exp, push_u64};
use crate::gcode::Block;
use crate::geometry::Point;
use crate::vocab::Axis;

/// What one row says about a point of the path.
pub(super) struct Row<'a> {
    pub block: &'a Block,
    /// The curve parameter, for a NURBS block.
    pub u: Option<f64>,
    pub point: &'a Point,
    pub t: f64,
    pub feed_mm_per_min: f64,
    pub chord_err: f64,
    pub chord_bound: f64,
    pub fluctuation: Option<f64>,
    /// The curvature radius (mm), empty when infinite.
    pub rho: f64,
    pub evals: u32,
}

/// The trace's columns for one machine, and the buffer rows are built in.
pub(super) struct RowWriter {
    /// Where X, Y and Z are among the machine's axes.
    xyz: [Option<usize>; 3],
    /// The axes beyond X, Y and Z: their index and column name.
    extra: Vec<(usize, char)>,
    text: Vec<u8>,
}

impl RowWriter {
    pub fn new(axes: &[Axis]) -> RowWriter {
        let index_of = |a: Axis| axes.iter().position(|&x| x == a);
        let extra = axes
            .iter()
            .enumerate()
            .filter(|(_, a)| !matches!(a, Axis::X | Axis::Y | Axis::Z))
            // Upper case: `u` is the curve parameter's column.
            .map(|(i, a)| (i, a.letter()))
            .collect();
        RowWriter {
            xyz: [index_of(Axis::X), index_of(Axis::Y), index_of(Axis::Z)],
            extra,
            text: Vec::with_capacity(256),
        }
    }

    /// The index of Z among the machine's axes, if it has one.
    pub fn z(&self) -> Option<usize> {
        self.xyz[2]
    }

    /// The header line.
    pub fn header(&mut self) -> &[u8] {
        self.text.clear();
        self.text.extend_from_slice(
            b"line,kind,u,x,y,z,t,feed_mm_per_min,chord_err,chord_bound,fluctuation,rho,evals",
        );
        for &(_, letter) in &self.extra {
            self.text.push(b',');
            let mut utf8 = [0; 4];
            self.text
                .extend_from_slice(letter.encode_utf8(&mut utf8).as_bytes());
        }
        self.text.push(b'\n');
        &self.text
    }

    /// The text of `row`, newline included; valid until the next call.
    pub fn format(&mut self, row: &Row) -> &[u8] {
        let out = &mut self.text;
        out.clear();
        push_u64(out, row.block.line);
        out.push(b',');
        out.extend_from_slice(row.block.kind.name().as_bytes());
        out.push(b',');
        if let Some(u) = row.u {
            push_f64(out, u);
        }
        for axis in self.xyz {
            out.push(b',');
            if let Some(i) = axis {
                push_f64(out, row.point[i]);
            }
        }
        for x in [row.t, row.feed_mm_per_min, row.chord_err, row.chord_bound] {
            out.push(b',');
            push_f64(out, x);
        }
        out.push(b',');
        if let Some(f) = row.fluctuation {
            push_f64_exp(out, f);
        }
        out.push(b',');
        if row.rho.is_finite() {
            push_f64(out, row.rho);
        }
        out.push(b',');
        push_u64(out, u64::from(row.evals));
        for &(i, _) in &self.extra {
            out.push(b',');
            push_f64(out, row.point[i]);
        }
        out.push(b'\n');
        &self.text
    }
}
