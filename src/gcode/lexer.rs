//! One line of G-code into words: a letter and a value, with the column of the letter.
//!
//! Accepted: `( )` comments (not nested; `(MSG,…)`, `(DEBUG,…)` and `(PRINT,…)` are kept as
//! the line's message), `;` comments to the end of the line, a `%` tape mark alone on its line,
//! a block-delete `/` at the start, spaces between a letter and its value. A value is a plain
//! decimal (`-1`, `+.5`, `2.`) or, as LinuxCNC reads them, a parameter or a bracketed
//! expression ([`super::expr`]: `X#1`, `Y-[#<w> / 2]`). Parameter assignments (`#1 = 2`,
//! `#<w> = [#1 * 2]`) are collected apart from the words, to be applied after the line is read.
//! A line whose first word is an `O` followed by a keyword (`o<slot> sub`, `O100 if […]`) is an
//! O-word statement: its label and keyword are returned and its arguments are left for the
//! interpreter to evaluate ([`OWord::rest`]). There are no exponents, NaN or infinities in
//! G-code, and a literal with more than 9 integer digits or 32 characters is out of range
//! rather than silently huge.

use super::error::GcodeErrorKind;
use super::expr::{self, Env, ParamRef, Scanner};

/// One word of a block. `text` is the number as written, or the value of an expression (for
/// G/M codes and messages).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Word {
    pub letter: char,
    pub value: f64,
    pub col: usize,
    pub text: WordText,
}

/// A word's value as text, held inline: a literal has at most [`MAX_NUMBER_CHARS`]
/// characters, so lexing a line allocates nothing per word. An expression's value written
/// longer (a tiny number's every decimal) is cut at that many bytes.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) struct WordText {
    len: u8,
    bytes: [u8; MAX_NUMBER_CHARS],
}

impl WordText {
    pub(crate) fn new(text: &str) -> WordText {
        let mut t = WordText {
            len: 0,
            bytes: [0; MAX_NUMBER_CHARS],
        };
        let _ = std::fmt::Write::write_str(&mut t, text);
        t
    }

    pub(crate) fn as_str(&self) -> &str {
        // Only whole characters are ever copied in (`write_str`).
        std::str::from_utf8(&self.bytes[..usize::from(self.len)]).unwrap_or("")
    }
}

impl std::fmt::Write for WordText {
    /// Appends what fits, whole characters only.
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        let at = usize::from(self.len);
        let mut n = s.len().min(MAX_NUMBER_CHARS - at);
        while !s.is_char_boundary(n) {
            n -= 1;
        }
        self.bytes[at..at + n].copy_from_slice(&s.as_bytes()[..n]);
        self.len += n as u8;
        Ok(())
    }
}

impl std::ops::Deref for WordText {
    type Target = str;
    fn deref(&self) -> &str {
        self.as_str()
    }
}

impl std::fmt::Display for WordText {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::fmt::Debug for WordText {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        std::fmt::Debug::fmt(self.as_str(), f)
    }
}

/// An O-word's label: `O100` or `o<name>` (lower case).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub(crate) enum Label {
    Number(u32),
    Name(String),
}

impl std::fmt::Display for Label {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Label::Number(n) => write!(f, "O{n}"),
            Label::Name(s) => write!(f, "o<{s}>"),
        }
    }
}

/// The O-word keywords.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Keyword {
    Sub,
    Endsub,
    Call,
    Return,
    If,
    Elseif,
    Else,
    Endif,
    While,
    Endwhile,
    Do,
    Repeat,
    Endrepeat,
    Break,
    Continue,
}

impl Keyword {
    /// Longest first, so `endsub` is not read as `end…` of another and `elseif` before `else`.
    const ALL: [(&'static str, Keyword); 15] = [
        ("endrepeat", Keyword::Endrepeat),
        ("endwhile", Keyword::Endwhile),
        ("continue", Keyword::Continue),
        ("endsub", Keyword::Endsub),
        ("elseif", Keyword::Elseif),
        ("repeat", Keyword::Repeat),
        ("return", Keyword::Return),
        ("endif", Keyword::Endif),
        ("while", Keyword::While),
        ("break", Keyword::Break),
        ("call", Keyword::Call),
        ("else", Keyword::Else),
        ("sub", Keyword::Sub),
        ("if", Keyword::If),
        ("do", Keyword::Do),
    ];

    pub(crate) fn name(self) -> &'static str {
        Keyword::ALL
            .iter()
            .find(|(_, k)| *k == self)
            .map_or("?", |(n, _)| n)
    }
}

/// An O-word statement: `label keyword` and where its arguments start in the line.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct OWord {
    pub col: usize,
    pub label: Label,
    pub keyword: Keyword,
    /// Byte offset of the text after the keyword, and the column before it.
    pub rest: usize,
    pub rest_col: usize,
}

/// A parameter assignment, applied after the line's words were read (LinuxCNC's order).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Assign {
    pub target: ParamRef,
    pub value: f64,
}

/// What else a line held besides its words.
#[derive(Debug, Default, Clone, PartialEq)]
pub(crate) struct LineInfo {
    /// Column of a `%` tape mark, if the line is one.
    pub percent: Option<usize>,
    /// The line has a comment.
    pub comment: bool,
    /// Column of a block-delete `/` that starts the line.
    pub block_delete: Option<usize>,
    /// The line is an O-word statement.
    pub oword: Option<OWord>,
    /// `(MSG,…)`, `(DEBUG,…)` or `(PRINT,…)`: the text for the operator.
    pub message: Option<(usize, String)>,
}

pub(crate) type LexError = (usize, GcodeErrorKind);

const MAX_INT_DIGITS: usize = 9;
const MAX_NUMBER_CHARS: usize = 32;

/// Splits `line` into `words` and `assigns` (both cleared first), reading parameters from `env`.
pub(crate) fn lex(
    line: &str,
    words: &mut Vec<Word>,
    assigns: &mut Vec<Assign>,
    env: &dyn Env,
) -> Result<LineInfo, LexError> {
    words.clear();
    assigns.clear();
    let mut info = LineInfo::default();
    let mut sc = Scanner::new(line);
    sc.skip_ws();
    if sc.peek() == Some('/') {
        sc.bump();
        info.block_delete = Some(sc.col);
    }
    while let Some(ch) = sc.bump() {
        let col = sc.col;
        match ch {
            ' ' | '\t' => {}
            '(' => comment(&mut sc, line, col, &mut info)?,
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
            '#' => {
                if let Some(pc) = info.percent {
                    return Err((pc, GcodeErrorKind::MisplacedPercent));
                }
                let target = expr::param_ref(&mut sc, env)?;
                if env.read_only(&target) {
                    return Err((
                        col,
                        GcodeErrorKind::ReadOnlyParameter {
                            name: target.to_string(),
                        },
                    ));
                }
                sc.expect(
                    '=',
                    "`=` expected: a parameter on its own is assigned with #n = value",
                )?;
                let value = expr::value(&mut sc, env)?;
                assigns.push(Assign { target, value });
            }
            // `@` and `^`: LinuxCNC's polar radius and angle.
            c if c.is_ascii_alphabetic() || c == '@' || c == '^' => {
                if let Some(pc) = info.percent {
                    return Err((pc, GcodeErrorKind::MisplacedPercent));
                }
                let letter = c.to_ascii_uppercase();
                if letter == 'O'
                    && words.iter().all(|w| w.letter == 'N')
                    && assigns.is_empty()
                    && let Some(oword) = oword_after_o(&mut sc.clone(), col)?
                {
                    info.oword = Some(oword);
                    return Ok(info);
                }
                words.push(word(&mut sc, line, letter, col, env)?);
            }
            other => {
                let hint = match other {
                    '/' => " (block delete `/` must start the line)",
                    '[' | ']' => " (an expression must follow a word letter, as in X[1+2])",
                    _ => "",
                };
                return Err((col, GcodeErrorKind::UnexpectedChar { ch: other, hint }));
            }
        }
    }
    Ok(info)
}

/// A comment from its `(` (read) to its `)`: a message comment is kept for the line.
#[inline]
fn comment(sc: &mut Scanner, line: &str, col: usize, info: &mut LineInfo) -> Result<(), LexError> {
    let start = sc.pos;
    loop {
        match sc.bump() {
            None => return Err((col, GcodeErrorKind::UnterminatedComment)),
            Some(')') => break,
            Some('(') => return Err((sc.col, GcodeErrorKind::NestedComment)),
            Some(_) => {}
        }
    }
    let body = &line[start..sc.pos - 1];
    if let Some(text) = message(body) {
        info.message = Some((col, text.to_string()));
    }
    info.comment = true;
    Ok(())
}

/// The word of `letter` (at `col`, read): its value, a number or an expression.
#[inline]
fn word(
    sc: &mut Scanner,
    line: &str,
    letter: char,
    col: usize,
    env: &dyn Env,
) -> Result<Word, LexError> {
    sc.skip_ws();
    let value_col = sc.next_col();
    let evaluated = matches!(
        (sc.peek(), sc.peek2()),
        (Some('#' | '['), _) | (Some('+' | '-'), Some('#' | '['))
    );
    if evaluated {
        let value = expr::value(sc, env)?;
        if !value.is_finite() {
            return Err((
                value_col,
                GcodeErrorKind::NumberOutOfRange {
                    letter,
                    text: format!("{value}"),
                },
            ));
        }
        let mut text = WordText::new("");
        let _ = std::fmt::Write::write_fmt(&mut text, format_args!("{value}"));
        return Ok(Word {
            letter,
            value,
            col,
            text,
        });
    }
    let start = sc.pos;
    if matches!(sc.peek(), Some('+' | '-')) {
        sc.bump();
    }
    while matches!(sc.peek(), Some(d) if d.is_ascii_digit() || d == '.') {
        sc.bump();
    }
    let text = &line[start..sc.pos];
    // `X1e308`: an exponent glued to a number is not a word `E`; say so rather
    // than "word E is not used".
    if !text.is_empty() {
        expr::no_exponent(sc)?;
    }
    number_word(letter, col, text)
}

/// The text of a `(MSG, …)`, `(DEBUG, …)` or `(PRINT, …)` comment.
fn message(body: &str) -> Option<&str> {
    let trimmed = body.trim_start();
    for tag in ["MSG,", "DEBUG,", "PRINT,"] {
        if let Some(head) = trimmed.get(..tag.len())
            && head.eq_ignore_ascii_case(tag)
        {
            return Some(trimmed[tag.len()..].trim());
        }
    }
    None
}

/// After an `O` at `col`: the label and keyword of an O-word statement, or `None` for a
/// Fanuc program number (`O1000` with no keyword), which is an ordinary word.
fn oword_after_o(sc: &mut Scanner, col: usize) -> Result<Option<OWord>, LexError> {
    sc.skip_ws();
    let label = if sc.peek() == Some('<') {
        sc.bump();
        let name = sc.angle_name(col, "O-word name without its closing `>`", false)?;
        Label::Name(name)
    } else {
        let start = sc.pos;
        while matches!(sc.peek(), Some(d) if d.is_ascii_digit()) {
            sc.bump();
        }
        match sc.s[start..sc.pos].parse::<u32>() {
            Ok(n) => Label::Number(n),
            Err(_) => return Ok(None),
        }
    };
    sc.skip_ws();
    // LinuxCNC drops spaces before it reads a line, so `else if` is `elseif` and `end sub`
    // is `endsub` (LinuxCNC's own probing macros write `else if`).
    let keyword = Keyword::ALL.iter().find_map(|&(name, keyword)| {
        let mut probe = sc.clone();
        if !probe.eat_word(name) {
            return None;
        }
        let rest = probe.clone();
        probe.skip_ws();
        (!probe.peek().is_some_and(|c| c.is_ascii_alphabetic())).then_some((keyword, rest))
    });
    match (keyword, &label) {
        (Some((keyword, rest)), _) => {
            *sc = rest;
            Ok(Some(OWord {
                col,
                label,
                keyword,
                rest: sc.pos,
                rest_col: sc.col,
            }))
        }
        (None, Label::Number(_)) => Ok(None),
        (None, Label::Name(_)) => Err((
            sc.next_col(),
            GcodeErrorKind::Expression {
                what: "an O-word needs a keyword: sub, endsub, call, return, if, elseif, else, \
                   endif, while, endwhile, do, repeat, endrepeat, break or continue",
            },
        )),
    }
}

/// The O-word statement of `line`, if it is one, without evaluating anything: for skipping
/// over lines (a false `if`, a subroutine's body) and for finding a subroutine ahead.
pub(crate) fn oword_of(line: &str) -> Option<OWord> {
    let mut sc = Scanner::new(line);
    sc.skip_ws();
    if sc.peek() == Some('/') {
        sc.bump();
        sc.skip_ws();
    }
    if matches!(sc.peek(), Some('N' | 'n')) {
        sc.bump();
        sc.skip_ws();
        while matches!(sc.peek(), Some(d) if d.is_ascii_digit() || d == '.') {
            sc.bump();
        }
        sc.skip_ws();
    }
    if !matches!(sc.peek(), Some('O' | 'o')) {
        return None;
    }
    sc.bump();
    let col = sc.col;
    oword_after_o(&mut sc, col).ok().flatten()
}

/// A Fanuc program or subprogram number standing alone (`O1000`, `O1000 (comment)`, `:1000`
/// is not read): its number.
pub(crate) fn program_number_of(line: &str) -> Option<u32> {
    let mut sc = Scanner::new(line);
    sc.skip_ws();
    if !matches!(sc.bump(), Some('O' | 'o')) {
        return None;
    }
    sc.skip_ws();
    let start = sc.pos;
    while matches!(sc.peek(), Some(d) if d.is_ascii_digit()) {
        sc.bump();
    }
    let n = sc.s[start..sc.pos].parse().ok()?;
    sc.skip_ws();
    match sc.peek() {
        None | Some('(' | ';') => Some(n),
        _ => None,
    }
}

/// Whether `line` holds an `M99` word (outside comments), for finding a subprogram's end.
pub(crate) fn has_m99(line: &str) -> bool {
    let mut in_comment = false;
    let b = line.as_bytes();
    let mut i = 0;
    while i < b.len() {
        match b[i] {
            b'(' => in_comment = true,
            b')' => in_comment = false,
            b';' if !in_comment => return false,
            b'M' | b'm' if !in_comment => {
                let mut j = i + 1;
                while j < b.len() && b[j] == b' ' {
                    j += 1;
                }
                let start = j;
                while j < b.len() && b[j].is_ascii_digit() {
                    j += 1;
                }
                if line[start..j].parse::<u32>() == Ok(99) {
                    return true;
                }
            }
            _ => {}
        }
        i += 1;
    }
    false
}

fn number_word(letter: char, col: usize, text: &str) -> Result<Word, LexError> {
    let bad = || {
        (
            col,
            GcodeErrorKind::BadNumber {
                letter,
                text: text.to_string(),
            },
        )
    };
    let unsigned = text.trim_start_matches(['+', '-']);
    // One pass over the bytes: digits, dots, and the integer part's digits past leading zeros.
    let (mut digits, mut dots, mut int_digits, mut leading) = (0usize, 0usize, 0usize, true);
    for b in unsigned.bytes() {
        match b {
            b'.' => dots += 1,
            b'0'..=b'9' => {
                digits += 1;
                if dots == 0 {
                    leading &= b == b'0';
                    int_digits += usize::from(!leading);
                }
            }
            _ => {}
        }
    }
    if digits == 0 {
        return Err(if unsigned.is_empty() {
            (col, GcodeErrorKind::MissingNumber { letter })
        } else {
            bad()
        });
    }
    if dots > 1 {
        return Err(bad());
    }
    if int_digits > MAX_INT_DIGITS || text.len() > MAX_NUMBER_CHARS {
        return Err((
            col,
            GcodeErrorKind::NumberOutOfRange {
                letter,
                text: text.to_string(),
            },
        ));
    }
    let value: f64 = text.parse().map_err(|_| bad())?;
    Ok(Word {
        letter,
        value,
        col,
        text: WordText::new(text),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::gcode::expr::Params;

    struct P(Params);
    impl Env for P {
        fn numbered(&self, n: usize) -> f64 {
            self.0.numbered(n)
        }
        fn named(&self, name: &str) -> Option<f64> {
            self.0.named(name)
        }
    }

    fn env() -> P {
        let mut p = Params::default();
        p.set(&ParamRef::Numbered(1), 2.5);
        p.set(&ParamRef::Named("w".into()), 4.0);
        P(p)
    }

    fn lex_line(line: &str) -> Result<(Vec<Word>, Vec<Assign>, LineInfo), LexError> {
        let (mut w, mut a) = (Vec::new(), Vec::new());
        let info = lex(line, &mut w, &mut a, &env())?;
        Ok((w, a, info))
    }

    fn words(line: &str) -> Vec<(char, f64, usize)> {
        let (w, _, _) = lex_line(line).unwrap();
        w.into_iter().map(|w| (w.letter, w.value, w.col)).collect()
    }

    fn err(line: &str) -> (usize, String) {
        let (col, kind) = lex_line(line).unwrap_err();
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
        assert_eq!(lex_line(" % ").unwrap().2.percent, Some(2));
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
        assert_eq!(err("G1 #1 X2").0, 7);
        assert!(err("G1 X[1+2").1.contains("`]` expected"));
        assert!(err("G1 [1]").1.contains("must follow a word letter"));
        assert!(err("G1 X1 /").1.contains("must start the line"));
        assert_eq!(err("G1 (open").0, 4);
        assert_eq!(err("(a (b) c)").0, 4);
    }

    #[test]
    fn values_from_parameters_and_expressions() {
        assert_eq!(
            words("G1 X#1 Y-#<w> Z[#1 * 2]"),
            vec![('G', 1.0, 1), ('X', 2.5, 4), ('Y', -4.0, 8), ('Z', 5.0, 15)]
        );
        let (w, a, _) = lex_line("#1 = [#1 + 1] #<new>=3 X#1").unwrap();
        assert_eq!(w[0].value, 2.5, "assignments take effect after the line");
        assert_eq!(
            a,
            vec![
                Assign {
                    target: ParamRef::Numbered(1),
                    value: 3.5
                },
                Assign {
                    target: ParamRef::Named("new".into()),
                    value: 3.0
                },
            ]
        );
        assert!(err("X#<undefined>").1.contains("#<undefined> is not set"));
    }

    #[test]
    fn owords_block_delete_and_messages() {
        let (_, _, info) = lex_line("o<Slot Cut> call [1] [#1]").unwrap();
        let o = info.oword.unwrap();
        assert_eq!(
            (o.label, o.keyword, o.col),
            (Label::Name("slotcut".into()), Keyword::Call, 1)
        );
        assert_eq!(&"o<Slot Cut> call [1] [#1]"[o.rest..], " [1] [#1]");
        let (_, _, info) = lex_line("N10 O100 ELSEIF [1]").unwrap();
        assert_eq!(info.oword.unwrap().keyword, Keyword::Elseif);
        // A program number is a word, not a statement.
        let (w, _, info) = lex_line("O1000 (name)").unwrap();
        assert!(info.oword.is_none());
        assert_eq!(w[0].letter, 'O');
        assert!(err("o<x>").1.contains("needs a keyword"));
        let (w, _, info) = lex_line(" /G1 X1").unwrap();
        assert_eq!((info.block_delete, w.len()), (Some(2), 2));
        let (_, _, info) = lex_line("G0 X1 (msg, Insert the wire )").unwrap();
        assert_eq!(info.message, Some((7, "Insert the wire".into())));
        assert_eq!(
            oword_of("/ N5 o101 endwhile").unwrap().keyword,
            Keyword::Endwhile
        );
        assert_eq!(oword_of("G1 X1"), None);
        assert_eq!(program_number_of("O2000 (sub)"), Some(2000));
        assert_eq!(program_number_of("O2000 G1"), None);
        assert!(has_m99("N20 M99 (back)"));
        assert!(!has_m99("(M99) M9"));
    }
}
