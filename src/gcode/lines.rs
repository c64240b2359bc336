//! Bounded line reading: a program is streamed line by line and never loaded whole.
//!
//! A line longer than [`MAX_LINE_BYTES`] is consumed to its end without being stored (so a
//! 10 MB line costs no memory) and reported; invalid UTF-8 is reported at its column.
//!
//! The source keeps the byte offset of the next line, so the interpreter can come back to a
//! line it read before (a loop, a subroutine) by seeking rather than by keeping the lines.

use std::io::{self, BufRead, Seek, SeekFrom};

/// Where a line starts: byte offset and 1-based line number.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Pos {
    pub offset: u64,
    /// Number of the line that starts at `offset`.
    pub line: u64,
}

/// Longest line accepted, in bytes (without the line break).
pub const MAX_LINE_BYTES: usize = 64 * 1024;

/// What one physical line turned out to be.
pub(crate) enum Line<'a> {
    Text(&'a str),
    TooLong,
    /// Not UTF-8: the bytes up to the first invalid sequence, as text, for the error's column
    /// and excerpt, and the whole line's bytes (a comment saved by an older editor may be
    /// Latin-1).
    BadUtf8 {
        valid_prefix: &'a str,
        bytes: &'a [u8],
    },
}

pub(crate) struct LineSource<R> {
    reader: R,
    buf: Vec<u8>,
    line_no: u64,
    /// Byte offset of the next line.
    offset: u64,
}

impl<R: BufRead + Seek> LineSource<R> {
    pub(crate) fn new(reader: R) -> Self {
        Self {
            reader,
            buf: Vec::with_capacity(256),
            line_no: 0,
            offset: 0,
        }
    }

    /// Where the next line starts.
    pub(crate) fn position(&self) -> Pos {
        Pos {
            offset: self.offset,
            line: self.line_no + 1,
        }
    }

    /// Makes the line at `pos` the next one.
    pub(crate) fn seek(&mut self, pos: Pos) -> io::Result<()> {
        if pos.offset != self.offset {
            self.reader.seek(SeekFrom::Start(pos.offset))?;
            self.offset = pos.offset;
        }
        self.line_no = pos.line - 1;
        Ok(())
    }

    /// The next line and its 1-based number, or `None` at the end of input.
    pub(crate) fn next_line(&mut self) -> io::Result<Option<(u64, Line<'_>)>> {
        self.buf.clear();
        let mut too_long = false;
        let mut read_any = false;
        loop {
            let available = match self.reader.fill_buf() {
                Ok(b) => b,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(e),
            };
            if available.is_empty() {
                break;
            }
            read_any = true;
            let (chunk, found_newline) = match available.iter().position(|&b| b == b'\n') {
                Some(i) => (&available[..i], true),
                None => (available, false),
            };
            if !too_long {
                if self.buf.len() + chunk.len() > MAX_LINE_BYTES {
                    too_long = true;
                    self.buf.clear();
                } else {
                    self.buf.extend_from_slice(chunk);
                }
            }
            let consumed = chunk.len() + usize::from(found_newline);
            self.reader.consume(consumed);
            self.offset += consumed as u64;
            if found_newline {
                break;
            }
        }
        if !read_any {
            return Ok(None);
        }
        self.line_no += 1;
        if too_long {
            return Ok(Some((self.line_no, Line::TooLong)));
        }
        if self.buf.last() == Some(&b'\r') {
            self.buf.pop();
        }
        if self.line_no == 1 && self.buf.starts_with(crate::vocab::BOM.as_bytes()) {
            self.buf.drain(..crate::vocab::BOM.len());
        }
        let line = match std::str::from_utf8(&self.buf) {
            Ok(text) => Line::Text(text),
            Err(e) => Line::BadUtf8 {
                // Safe: the prefix up to valid_up_to is valid UTF-8 by definition.
                valid_prefix: std::str::from_utf8(&self.buf[..e.valid_up_to()]).unwrap_or(""),
                bytes: &self.buf,
            },
        };
        Ok(Some((self.line_no, line)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn collect(input: &[u8]) -> Vec<String> {
        let mut src = LineSource::new(io::BufReader::with_capacity(7, io::Cursor::new(input)));
        let mut out = Vec::new();
        while let Some((n, line)) = src.next_line().unwrap() {
            out.push(match line {
                Line::Text(t) => format!("{n}:{t}"),
                Line::TooLong => format!("{n}:<too long>"),
                Line::BadUtf8 { valid_prefix, .. } => format!("{n}:<utf8 after {valid_prefix:?}>"),
            });
        }
        out
    }

    #[test]
    fn splits_lines_across_small_buffers_and_strips_crlf() {
        assert_eq!(
            collect(b"G1 X1\r\nG1 X2\n\nlast"),
            ["1:G1 X1", "2:G1 X2", "3:", "4:last"]
        );
        assert_eq!(collect(b""), Vec::<String>::new());
        assert_eq!(collect(b"\n"), ["1:"]);
    }

    #[test]
    fn seeks_back_to_a_line() {
        let mut src = LineSource::new(io::BufReader::with_capacity(
            5,
            io::Cursor::new(&b"a1\r\nbb2\nccc3\n"[..]),
        ));
        src.next_line().unwrap();
        let at = src.position();
        assert_eq!(at, Pos { offset: 4, line: 2 });
        src.next_line().unwrap();
        src.next_line().unwrap();
        src.seek(at).unwrap();
        match src.next_line().unwrap() {
            Some((2, Line::Text(t))) => assert_eq!(t, "bb2"),
            _ => panic!("line 2 expected"),
        }
        assert_eq!(src.position(), Pos { offset: 8, line: 3 });
    }

    #[test]
    fn long_lines_are_skipped_not_stored() {
        let mut input = vec![b'X'; MAX_LINE_BYTES + 10];
        input.extend_from_slice(b"\nG1\n");
        assert_eq!(collect(&input), ["1:<too long>", "2:G1"]);
    }

    #[test]
    fn invalid_utf8_reports_the_valid_prefix() {
        assert_eq!(
            collect(b"G1 \xff X\nok"),
            ["1:<utf8 after \"G1 \">", "2:ok"]
        );
    }
}
