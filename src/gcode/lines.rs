//! Bounded line reading: a program is streamed line by line and never loaded whole.
//!
//! A line longer than [`MAX_LINE_BYTES`] is consumed to its end without being stored (so a
//! 10 MB line costs no memory) and reported; invalid UTF-8 is reported at its column.
//!
//! The source keeps the byte offset of the next line, so the interpreter can come back to a
//! line it read before (a loop, a subroutine). The last [`WINDOW_BYTES`] read are kept: a
//! jump back inside them (a loop body, a subroutine called again) is served from memory,
//! without a system call per iteration; a jump further back seeks the file. Memory stays
//! bounded whatever the program.

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

/// Bytes of the program kept behind the reading point for jumps back (loops, subroutines):
/// a loop body up to about half of it is always replayed from memory.
pub const WINDOW_BYTES: usize = 1024 * 1024;

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
    /// The bytes from `window_start` to `reader_at`, the reader's position; the next line
    /// comes from here while `offset < reader_at` (after a jump back into it).
    window: Vec<u8>,
    window_start: u64,
    reader_at: u64,
}

impl<R: BufRead + Seek> LineSource<R> {
    pub(crate) fn new(reader: R) -> Self {
        Self {
            reader,
            buf: Vec::with_capacity(256),
            line_no: 0,
            offset: 0,
            window: Vec::new(),
            window_start: 0,
            reader_at: 0,
        }
    }

    /// Where the next line starts.
    pub(crate) fn position(&self) -> Pos {
        Pos {
            offset: self.offset,
            line: self.line_no + 1,
        }
    }

    /// Makes the line at `pos` the next one: from memory if the window holds it, else by
    /// seeking the file.
    pub(crate) fn seek(&mut self, pos: Pos) -> io::Result<()> {
        if pos.offset != self.offset {
            if (self.window_start..=self.reader_at).contains(&pos.offset) {
                self.offset = pos.offset;
            } else {
                self.reader.seek(SeekFrom::Start(pos.offset))?;
                self.offset = pos.offset;
                self.reader_at = pos.offset;
                self.window_start = pos.offset;
                self.window.clear();
            }
        }
        self.line_no = pos.line - 1;
        Ok(())
    }

    /// Whether the last seek came from memory (for tests).
    #[cfg(test)]
    fn replaying(&self) -> bool {
        self.offset < self.reader_at
    }

    /// The next line of the window into `buf` (the reading point is behind the reader).
    fn replay_line(&mut self) {
        let from = (self.offset - self.window_start) as usize;
        let rest = &self.window[from..];
        let (line, consumed) = match rest.iter().position(|&b| b == b'\n') {
            Some(i) => (&rest[..i], i + 1),
            None => (rest, rest.len()),
        };
        self.buf.extend_from_slice(line);
        self.offset += consumed as u64;
    }

    /// Keeps `bytes`, just read, in the window, dropping its older half when it is full.
    fn remember(&mut self, bytes: &[u8]) {
        if self.window.len() + bytes.len() > WINDOW_BYTES {
            let drop = self
                .window
                .len()
                .min(self.window.len() + bytes.len() - WINDOW_BYTES / 2);
            self.window.drain(..drop);
            self.window_start += drop as u64;
        }
        self.window.extend_from_slice(bytes);
    }

    /// The next line and its 1-based number, or `None` at the end of input.
    pub(crate) fn next_line(&mut self) -> io::Result<Option<(u64, Line<'_>)>> {
        self.buf.clear();
        if self.offset < self.reader_at {
            self.replay_line();
            self.line_no += 1;
            return Ok(Some((self.line_no, self.finish_line())));
        }
        let start = self.offset;
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
        self.reader_at = self.offset;
        if !read_any {
            return Ok(None);
        }
        self.line_no += 1;
        if too_long {
            // Not kept: the window restarts after it (a jump back past it seeks).
            self.window.clear();
            self.window_start = self.offset;
            return Ok(Some((self.line_no, Line::TooLong)));
        }
        let line = std::mem::take(&mut self.buf);
        self.remember(&line);
        if (self.offset - start) as usize > line.len() {
            // Its line break.
            self.remember(b"\n");
        }
        self.buf = line;
        Ok(Some((self.line_no, self.finish_line())))
    }

    /// `buf` as a line: its `\r` and a first line's byte-order mark taken off, checked as
    /// UTF-8.
    fn finish_line(&mut self) -> Line<'_> {
        if self.buf.last() == Some(&b'\r') {
            self.buf.pop();
        }
        if self.line_no == 1 && self.buf.starts_with(crate::vocab::BOM.as_bytes()) {
            self.buf.drain(..crate::vocab::BOM.len());
        }
        match std::str::from_utf8(&self.buf) {
            Ok(text) => Line::Text(text),
            Err(e) => Line::BadUtf8 {
                // Safe: the prefix up to valid_up_to is valid UTF-8 by definition.
                valid_prefix: std::str::from_utf8(&self.buf[..e.valid_up_to()]).unwrap_or(""),
                bytes: &self.buf,
            },
        }
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
    fn jumps_back_inside_the_window_are_served_from_memory() {
        let text = b"o1 while\r\nG1 X1\nG1 X2\no1 endwhile\nlast";
        let mut src = LineSource::new(io::BufReader::with_capacity(4, io::Cursor::new(&text[..])));
        src.next_line().unwrap();
        let body = src.position();
        let mut seen = Vec::new();
        for _ in 0..3 {
            src.seek(body).unwrap();
            assert!(src.replaying() || seen.is_empty());
            while let Some((n, Line::Text(t))) = src.next_line().unwrap() {
                seen.push(format!("{n}:{t}"));
                if t.ends_with("endwhile") {
                    break;
                }
            }
        }
        assert_eq!(seen.len(), 9);
        assert_eq!(&seen[..3], ["2:G1 X1", "3:G1 X2", "4:o1 endwhile"]);
        assert_eq!(seen[3..6], seen[..3]);
        assert_eq!(seen[6..], seen[..3]);
        // Past the window's end the reader goes on: the last line, without a line break.
        match src.next_line().unwrap() {
            Some((5, Line::Text(t))) => assert_eq!(t, "last"),
            _ => panic!("line 5"),
        }
        assert!(src.next_line().unwrap().is_none());
        // And back to the first line, CR and all, from memory.
        src.seek(Pos { offset: 0, line: 1 }).unwrap();
        assert!(src.replaying());
        match src.next_line().unwrap() {
            Some((1, Line::Text(t))) => assert_eq!(t, "o1 while"),
            _ => panic!("line 1"),
        }
    }

    #[test]
    fn a_jump_further_back_than_the_window_seeks() {
        // Lines of 1 KiB: the window keeps the last WINDOW_BYTES, the first line falls out.
        let line = format!("({})\n", "x".repeat(1021));
        let text = line.repeat(2 * WINDOW_BYTES / line.len());
        let mut src = LineSource::new(io::BufReader::new(io::Cursor::new(text.as_bytes())));
        while src.next_line().unwrap().is_some() {}
        src.seek(Pos { offset: 0, line: 1 }).unwrap();
        assert!(!src.replaying(), "sought, not replayed");
        match src.next_line().unwrap() {
            Some((1, Line::Text(t))) => assert_eq!(t.len(), 1023),
            _ => panic!("line 1"),
        }
        // The window never held more than its bound.
        assert!(src.window.len() <= WINDOW_BYTES);
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
