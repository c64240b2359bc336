//! One line of G-code into words: a letter and a number, with the column of the letter.
//!
//! Accepted: `( )` comments (not nested), `;` comments to the end of the line, a `%` tape mark
//! alone on its line, spaces between a letter and its number. Numbers are plain decimals
//! (`-1`, `+.5`, `2.`); there are no exponents, NaN or infinities in G-code, and a literal with
//! more than 9 integer digits or 32 characters is out of range rather than silently huge.

use super::error::GcodeErrorKind;

/// One word of a block. `text` is the number as written (for G/M codes and messages).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Word {
    pub letter: char,
    pub value: f64,
    pub col: usize,
    pub text: String,
}

/// What else a line held besides its words.
#[derive(Debug, Default, Clone, Copy, PartialEq)]
pub(crate) struct LineInfo {
    /// Column of a `%` tape mark, if the line is one.
    pub percent: Option<usize>,
    /// The line has a comment.
    pub comment: bool,
}

pub(crate) type LexError = (usize, GcodeErrorKind);

const MAX_INT_DIGITS: usize = 9;
const MAX_NUMBER_CHARS: usize = 32;

/// Splits `line` into `words` (cleared first).
pub(crate) fn lex(line: &str, words: &mut Vec<Word>) -> Result<LineInfo, LexError> {
    words.clear();
    let mut info = LineInfo::default();
    let mut it = line.chars().peekable();
    let mut col = 0usize; // column of the last char taken
    while let Some(ch) = it.next() {
        col += 1;
        match ch {
            ' ' | '\t' => {}
            '(' => {
                let open = col;
                loop {
                    match it.next() {
                        None => return Err((open, GcodeErrorKind::UnterminatedComment)),
                        Some(c) => {
                            col += 1;
                            match c {
                                ')' => break,
                                '(' => return Err((col, GcodeErrorKind::NestedComment)),
                                _ => {}
                            }
                        }
                    }
                }
                info.comment = true;
            }
            ';' => {
                info.comment = true;
                break;
            }
            '%' => {
                if !words.is_empty() || info.percent.is_some() {
                    return Err((col, GcodeErrorKind::MisplacedPercent));
                }
                info.percent = Some(col);
            }
            c if c.is_ascii_alphabetic() => {
                if let Some(pc) = info.percent {
                    return Err((pc, GcodeErrorKind::MisplacedPercent));
                }
                let letter = c.to_ascii_uppercase();
                let letter_col = col;
                while matches!(it.peek(), Some(' ' | '\t')) {
                    it.next();
                    col += 1;
                }
                let mut text = String::new();
                if let Some(&s) = it.peek().filter(|s| matches!(s, '+' | '-')) {
                    text.push(s);
                    it.next();
                    col += 1;
                }
                while let Some(&d) = it.peek().filter(|d| d.is_ascii_digit() || **d == '.') {
                    text.push(d);
                    it.next();
                    col += 1;
                }
                // `X1e308`: an exponent glued to a number is not a word `E`, and G-code has no
                // exponent notation; say so rather than "word E is not used".
                if !text.is_empty() && matches!(it.peek(), Some('e' | 'E')) {
                    let mut ahead = it.clone();
                    ahead.next();
                    if matches!(ahead.peek(), Some(c) if c.is_ascii_digit() || *c == '+' || *c == '-')
                    {
                        return Err((
                            col + 1,
                            GcodeErrorKind::UnexpectedChar {
                                ch: it.peek().copied().unwrap_or('e'),
                                hint: " (exponent notation such as 1e3 is not G-code: write the \
                                       number out)",
                            },
                        ));
                    }
                }
                if text.is_empty()
                    && let Some(hint) = it.peek().and_then(|&c| unsupported_syntax(c))
                {
                    let ch = it.peek().copied().unwrap_or(' ');
                    return Err((col + 1, GcodeErrorKind::UnexpectedChar { ch, hint }));
                }
                words.push(number_word(letter, letter_col, text)?);
            }
            other => {
                let hint = unsupported_syntax(other).unwrap_or("");
                return Err((col, GcodeErrorKind::UnexpectedChar { ch: other, hint }));
            }
        }
    }
    Ok(info)
}

/// Why a character that other controllers accept is not G-code edmd reads.
fn unsupported_syntax(c: char) -> Option<&'static str> {
    match c {
        '#' => Some(" (parameters are not supported)"),
        '[' | ']' => Some(" (expressions are not supported)"),
        '/' => Some(" (block delete is not supported)"),
        '<' | '>' => Some(" (named parameters are not supported)"),
        _ => None,
    }
}

fn number_word(letter: char, col: usize, text: String) -> Result<Word, LexError> {
    let unsigned = text.trim_start_matches(['+', '-']);
    let digits = unsigned.chars().filter(char::is_ascii_digit).count();
    if digits == 0 {
        return Err(if unsigned.is_empty() {
            (col, GcodeErrorKind::MissingNumber { letter })
        } else {
            (col, GcodeErrorKind::BadNumber { letter, text })
        });
    }
    if unsigned.matches('.').count() > 1 {
        return Err((col, GcodeErrorKind::BadNumber { letter, text }));
    }
    let int_digits = unsigned
        .split('.')
        .next()
        .unwrap_or("")
        .trim_start_matches('0');
    if int_digits.len() > MAX_INT_DIGITS || text.len() > MAX_NUMBER_CHARS {
        return Err((col, GcodeErrorKind::NumberOutOfRange { letter, text }));
    }
    let value: f64 = text.parse().map_err(|_| {
        (
            col,
            GcodeErrorKind::BadNumber {
                letter,
                text: text.clone(),
            },
        )
    })?;
    Ok(Word {
        letter,
        value,
        col,
        text,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn words(line: &str) -> Vec<(char, f64, usize)> {
        let mut w = Vec::new();
        lex(line, &mut w).unwrap();
        w.into_iter().map(|w| (w.letter, w.value, w.col)).collect()
    }

    fn err(line: &str) -> (usize, String) {
        let mut w = Vec::new();
        let (col, kind) = lex(line, &mut w).unwrap_err();
        (col, kind.to_string())
    }

    #[test]
    fn words_comments_and_columns() {
        assert_eq!(
            words("n10 g1 x-1.5 Y+.25 (cut) f 600 ; rest"),
            vec![
                ('N', 10.0, 1),
                ('G', 1.0, 5),
                ('X', -1.5, 8),
                ('Y', 0.25, 14),
                ('F', 600.0, 26)
            ]
        );
        assert_eq!(words("G06.2 K0"), vec![('G', 6.2, 1), ('K', 0.0, 7)]);
        assert_eq!(words("X2."), vec![('X', 2.0, 1)]);
        assert_eq!(words("(µ comment) X1"), vec![('X', 1.0, 13)]);
    }

    #[test]
    fn percent_alone_is_a_tape_mark() {
        let mut w = Vec::new();
        assert_eq!(lex(" % ", &mut w).unwrap().percent, Some(2));
        assert_eq!(err("% G1").0, 1);
        assert_eq!(err("G1 %").0, 4);
    }

    #[test]
    fn malformed_numbers_and_characters() {
        assert_eq!(err("G1 X"), (4, "X must be followed by a number".into()));
        assert_eq!(err("G1 Xnan"), (4, "X must be followed by a number".into()));
        assert_eq!(err("X1.2.3").1, "`1.2.3` is not a number (after X)");
        assert_eq!(err("X-").1, "X must be followed by a number");
        assert_eq!(err("X-.").1, "`-.` is not a number (after X)");
        assert_eq!(err("X1234567890").1, "X1234567890: number out of range");
        assert_eq!(words("X0000000001.5")[0].1, 1.5); // leading zeros are not digits of range
        assert_eq!(err("G1 #1=2").0, 4);
        assert!(err("G1 X[1+2]").1.contains("expressions are not supported"));
        assert_eq!(err("G1 (open").0, 4);
        assert_eq!(err("(a (b) c)").0, 4);
    }
}
