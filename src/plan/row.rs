//! `trace.csv`'s rows: one per segment end (and one for the path's first point), every number
//! at full precision, the shortest decimal that reads back as the same double, so a 0.1 µm
//! tolerance is not drowned by the printing.
//!
//! Rows are built through [`crate::decimal`], not `format!`: a plan of 20,000 arcs writes
//! 840,000 rows, and `core::fmt` spent more on them than segmenting and planning did. The text
//! is the one `format!("{}")` (and `{:e}` for the fluctuation) gives. They are appended to one
//! buffer that goes to the file in [`FLUSH_AT`] pieces: built in place there, a row is never
//! copied on its way out (through a `BufWriter` each row was copied once more). What is left
//! is written when the writer is [finished](RowWriter::finish) or dropped, so a plan that
//! stops at a bad block leaves the rows before it, as a `BufWriter` did.

use crate::decimal::{push_f64, push_f64_exp, push_u64};
use crate::gcode::Block;
use crate::geometry::Point;
use crate::vocab::Axis;
use std::io::{self, Write};

/// How many bytes of rows the writer gathers before it hands them to the file.
const FLUSH_AT: usize = 64 * 1024;

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

/// The trace file: its columns for one machine, and the buffer rows are built in until they
/// are written to `file`.
pub(super) struct RowWriter<W: Write> {
    file: W,
    /// Where X, Y and Z are among the machine's axes.
    xyz: [Option<usize>; 3],
    /// The axes beyond X, Y and Z: their index and column name.
    extra: Vec<(usize, char)>,
    text: Vec<u8>,
    /// The last row's `line,kind,` text and what it was made from (the line, and the kind's
    /// name by address): a block's rows, forty-odd on an arc, repeat it, and it is copied
    /// rather than written again.
    prefix: Vec<u8>,
    prefix_of: Option<(u64, usize)>,
}

impl<W: Write> RowWriter<W> {
    /// A writer of `file`, its header line gathered.
    pub fn new(axes: &[Axis], file: W) -> RowWriter<W> {
        let index_of = |a: Axis| axes.iter().position(|&x| x == a);
        let extra = axes
            .iter()
            .enumerate()
            .filter(|(_, a)| !matches!(a, Axis::X | Axis::Y | Axis::Z))
            // Upper case: `u` is the curve parameter's column.
            .map(|(i, a)| (i, a.letter()))
            .collect();
        let mut writer = RowWriter {
            file,
            xyz: [index_of(Axis::X), index_of(Axis::Y), index_of(Axis::Z)],
            extra,
            text: Vec::with_capacity(FLUSH_AT + 1024),
            prefix: Vec::new(),
            prefix_of: None,
        };
        writer.header();
        writer
    }

    /// The index of Z among the machine's axes, if it has one.
    pub fn z(&self) -> Option<usize> {
        self.xyz[2]
    }

    fn header(&mut self) {
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
    }

    /// Writes what has gathered to the file and empties the buffer, once there is at least
    /// `at_least` bytes of it. After an error the buffer is emptied too: how much of it
    /// reached the file is unknown, and writing it again could repeat rows.
    fn write_out(&mut self, at_least: usize) -> io::Result<()> {
        if self.text.len() < at_least.max(1) {
            return Ok(());
        }
        let written = self.file.write_all(&self.text);
        self.text.clear();
        written
    }

    /// Writes every row gathered so far.
    pub fn finish(&mut self) -> io::Result<()> {
        self.write_out(0)
    }

    /// Appends the text of `row`, newline included, and writes the buffer out once it holds
    /// [`FLUSH_AT`] bytes.
    pub fn push(&mut self, row: &Row) -> io::Result<()> {
        self.append(row);
        self.write_out(FLUSH_AT)
    }

    fn append(&mut self, row: &Row) {
        let kind = row.block.kind.name();
        // Equal addresses mean equal names; a name at another address is only written anew.
        let key = (row.block.line, kind.as_ptr() as usize);
        if self.prefix_of != Some(key) {
            self.prefix.clear();
            push_u64(&mut self.prefix, row.block.line);
            self.prefix.push(b',');
            self.prefix.extend_from_slice(kind.as_bytes());
            self.prefix.push(b',');
            self.prefix_of = Some(key);
        }
        let out = &mut self.text;
        out.extend_from_slice(&self.prefix);
        if let Some(u) = row.u {
            push_f64(out, u);
        }
        // Cell by cell, not in loops over the columns: each number's conversion is inlined,
        // and a loop around it stayed a loop, its counting and the array it walked costing
        // about forty instructions a row.
        let coordinate = |out: &mut Vec<u8>, axis: Option<usize>| {
            out.push(b',');
            if let Some(i) = axis {
                push_f64(out, row.point[i]);
            }
        };
        coordinate(out, self.xyz[0]);
        coordinate(out, self.xyz[1]);
        coordinate(out, self.xyz[2]);
        let number = |out: &mut Vec<u8>, x: f64| {
            out.push(b',');
            push_f64(out, x);
        };
        number(out, row.t);
        number(out, row.feed_mm_per_min);
        number(out, row.chord_err);
        number(out, row.chord_bound);
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
    }
}

impl<W: Write> Drop for RowWriter<W> {
    /// Writes what is left, errors ignored (as `BufWriter` does): a plan that failed reports
    /// its own error, and the rows before it are worth having.
    fn drop(&mut self) {
        let _ = self.write_out(0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gcode::BlockReader;

    /// A block of a one-line program under `axes`.
    fn block(line: &str, axes: &[Axis]) -> Block {
        let text = format!("G21 G90 F100\n{line}\n");
        let mut reader = BlockReader::new(std::io::Cursor::new(text), "t", axes);
        reader.next().expect("a block").expect("valid")
    }

    fn row<'a>(block: &'a Block, point: &'a Point, t: f64) -> Row<'a> {
        Row {
            block,
            u: None,
            point,
            t,
            feed_mm_per_min: 600.0,
            chord_err: 1e-4,
            chord_bound: 0.000125,
            fluctuation: Some(1.5e-7),
            rho: f64::INFINITY,
            evals: 12,
        }
    }

    #[test]
    fn rows_are_std_text_gathered_then_written_on_finish_and_on_drop() {
        let axes = [Axis::X, Axis::Y, Axis::Z, Axis::U];
        let line = block("G1 X1.5 Y-2 U0.25", &axes);
        let arc = block("G2 X2 Y0 I1 J0", &axes);
        let p = line.end();
        let mut file = Vec::new();
        {
            let mut writer = RowWriter::new(&axes, &mut file);
            writer.push(&row(&line, &p, 0.1)).unwrap();
            writer.push(&row(&line, &p, 0.2)).unwrap();
            // The line's `2,line,` is kept; the arc on the same line number is not the line.
            writer.push(&row(&arc, &p, 0.3)).unwrap();
            writer.finish().unwrap();
            writer.push(&row(&line, &p, 0.4)).unwrap();
        }
        let expected = [
            "line,kind,u,x,y,z,t,feed_mm_per_min,chord_err,chord_bound,fluctuation,rho,evals,U",
            "2,line,,1.5,-2,0,0.1,600,0.0001,0.000125,1.5e-7,,12,0.25",
            "2,line,,1.5,-2,0,0.2,600,0.0001,0.000125,1.5e-7,,12,0.25",
            "2,arc,,1.5,-2,0,0.3,600,0.0001,0.000125,1.5e-7,,12,0.25",
            // After `finish`, written when the writer is dropped.
            "2,line,,1.5,-2,0,0.4,600,0.0001,0.000125,1.5e-7,,12,0.25",
        ];
        assert_eq!(String::from_utf8(file).unwrap(), expected.join("\n") + "\n");
    }

    #[test]
    fn rows_reach_the_file_in_pieces_of_flush_at() {
        let axes = [Axis::X, Axis::Y];
        let line = block("G1 X1 Y1", &axes);
        let p = line.end();
        let mut file = Vec::new();
        let mut writer = RowWriter::new(&axes, &mut file);
        let mut pushed = 0;
        while writer.text.len() + 100 < FLUSH_AT {
            writer.push(&row(&line, &p, 0.5)).unwrap();
            pushed += 1;
        }
        assert!(writer.file.is_empty(), "nothing written before FLUSH_AT");
        let gathered = writer.text.len();
        while writer.text.len() >= gathered {
            writer.push(&row(&line, &p, 0.5)).unwrap();
            pushed += 1;
        }
        // The row that brought the buffer to FLUSH_AT went out with it, in one piece.
        assert!(writer.text.is_empty());
        assert!(writer.file.len() >= FLUSH_AT);
        assert!(writer.file.ends_with(b"\n"));
        writer.push(&row(&line, &p, 0.5)).unwrap();
        drop(writer);
        assert_eq!(file.iter().filter(|&&b| b == b'\n').count(), pushed + 2);
    }

    /// A file that takes `room` bytes, fails once, then takes everything again.
    struct Flaky {
        taken: Vec<u8>,
        room: usize,
        failed: bool,
    }

    impl Write for Flaky {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            let n = if self.failed {
                buf.len()
            } else {
                buf.len().min(self.room - self.taken.len())
            };
            if n == 0 {
                self.failed = true;
                return Err(io::Error::other("disk full"));
            }
            self.taken.extend_from_slice(&buf[..n]);
            Ok(n)
        }

        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn a_failed_write_is_reported_and_nothing_is_written_twice() {
        let axes = [Axis::X, Axis::Y];
        let line = block("G1 X1 Y1", &axes);
        let p = line.end();
        let mut flaky = Flaky {
            taken: Vec::new(),
            room: FLUSH_AT / 2,
            failed: false,
        };
        let mut writer = RowWriter::new(&axes, &mut flaky);
        let mut failed = None;
        for _ in 0..FLUSH_AT {
            if let Err(e) = writer.push(&row(&line, &p, 0.5)) {
                failed = Some(e.to_string());
                break;
            }
        }
        assert_eq!(failed.as_deref(), Some("disk full"));
        // Dropped after the error (as a failed plan drops it): the rows the file did not take
        // are not offered again, so nothing before them is repeated.
        drop(writer);
        assert_eq!(flaky.taken.len(), FLUSH_AT / 2);
    }
}
