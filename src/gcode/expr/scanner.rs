//! The cursor an expression and a line are read with: position, column, and the nesting it
//! counts against [`MAX_NESTING`].

use super::{ExprError, MAX_NESTING};
use crate::gcode::error::GcodeErrorKind;

/// A cursor over one line: byte position and the 1-based column of the next character.
#[derive(Debug, Clone)]
pub(crate) struct Scanner<'a> {
    pub(crate) s: &'a str,
    pub(crate) pos: usize,
    /// Column of the last character taken (0 before the first).
    pub(crate) col: usize,
    /// Brackets, functions and indirections open around the position ([`MAX_NESTING`]).
    depth: usize,
}

impl<'a> Scanner<'a> {
    pub(crate) fn new(s: &'a str) -> Self {
        Self::at(s, 0, 0)
    }

    /// A scanner over `s` whose next character is at byte `pos`, column `col + 1`.
    pub(crate) fn at(s: &'a str, pos: usize, col: usize) -> Self {
        Self {
            s,
            pos,
            col,
            depth: 0,
        }
    }

    /// Opens one level of nesting at `col`, refused past [`MAX_NESTING`].
    pub(super) fn enter(&mut self, col: usize) -> Result<(), ExprError> {
        if self.depth >= MAX_NESTING {
            return Err((col, GcodeErrorKind::NestedTooDeep { limit: MAX_NESTING }));
        }
        self.depth += 1;
        Ok(())
    }

    pub(super) fn leave(&mut self) {
        self.depth -= 1;
    }

    // The four below are inlined: a lexed line calls them once or twice a character, and the
    // calls cost more than the look at a byte. An ASCII byte is its own character: read as
    // one, without slicing the line (a check that `pos` is on a character's boundary) and
    // decoding UTF-8; anything else is decoded.
    #[inline]
    pub(crate) fn peek(&self) -> Option<char> {
        match self.s.as_bytes().get(self.pos) {
            Some(&b) if b.is_ascii() => Some(char::from(b)),
            Some(_) => self.s[self.pos..].chars().next(),
            None => None,
        }
    }

    #[inline]
    pub(crate) fn peek2(&self) -> Option<char> {
        let bytes = self.s.as_bytes();
        match (bytes.get(self.pos), bytes.get(self.pos + 1)) {
            (Some(a), Some(&b)) if a.is_ascii() && b.is_ascii() => Some(char::from(b)),
            (None, _) => None,
            _ => {
                let mut it = self.s[self.pos..].chars();
                it.next();
                it.next()
            }
        }
    }

    #[inline]
    pub(crate) fn bump(&mut self) -> Option<char> {
        let c = self.peek()?;
        self.pos += c.len_utf8();
        self.col += 1;
        Some(c)
    }

    #[inline]
    pub(crate) fn skip_ws(&mut self) {
        while matches!(self.peek(), Some(' ' | '\t')) {
            self.bump();
        }
    }

    /// Column of the next character.
    pub(crate) fn next_col(&self) -> usize {
        self.col + 1
    }

    /// Takes `word` (ASCII letters, any case, spaces between them allowed as LinuxCNC strips
    /// spaces) if it comes next.
    pub(crate) fn eat_word(&mut self, word: &str) -> bool {
        let save = self.clone();
        for w in word.chars() {
            self.skip_ws();
            match self.peek() {
                Some(c) if c.eq_ignore_ascii_case(&w) => {
                    self.bump();
                }
                _ => {
                    *self = save;
                    return false;
                }
            }
        }
        true
    }

    /// The name inside `< >` (the `<` taken), lower case, spaces dropped, as LinuxCNC reads
    /// names. `strict`: only letters, digits, `_`, `.` and `-` (parameter names).
    pub(crate) fn angle_name(
        &mut self,
        open_col: usize,
        unclosed: &'static str,
        strict: bool,
    ) -> Result<String, ExprError> {
        let mut name = String::new();
        loop {
            match self.bump() {
                None => return Err((open_col, GcodeErrorKind::Expression { what: unclosed })),
                Some('>') => return Ok(name),
                Some(' ' | '\t') => {}
                Some(c) if !strict || c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '-') => {
                    name.push(c.to_ascii_lowercase())
                }
                Some(c) => {
                    return Err((
                        self.col,
                        GcodeErrorKind::UnexpectedChar {
                            ch: c,
                            hint: " (in a parameter name)",
                        },
                    ));
                }
            }
        }
    }

    /// Takes `ch` (after spaces) or fails with `what` at the column where it was expected.
    pub(crate) fn expect(&mut self, ch: char, what: &'static str) -> Result<(), ExprError> {
        self.skip_ws();
        if self.peek() == Some(ch) {
            self.bump();
            Ok(())
        } else {
            Err((self.next_col(), GcodeErrorKind::Expression { what }))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scanner_reads_ascii_and_wider_characters_alike() {
        // ASCII is read byte by byte, the rest decoded: the same characters either way, next
        // to each other in every order, and columns counted in characters.
        let text = "G1 Xé#µ(°)Y2.5 ü";
        let chars: Vec<char> = text.chars().collect();
        let mut sc = Scanner::new(text);
        for (i, &c) in chars.iter().enumerate() {
            assert_eq!(sc.peek(), Some(c), "peek at {i}");
            assert_eq!(sc.peek2(), chars.get(i + 1).copied(), "peek2 at {i}");
            assert_eq!(sc.bump(), Some(c));
            assert_eq!(sc.next_col(), i + 2);
        }
        assert_eq!((sc.peek(), sc.peek2(), sc.bump()), (None, None, None));
    }
}
