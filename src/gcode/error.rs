//! Errors and warnings for programs: where (`file:line:col`), what, and the offending text.

use std::fmt;
use std::sync::Arc;

use crate::vocab::Num;

use crate::geometry::NurbsError;

/// What is wrong with a program. The location and text are in [`GcodeError`].
#[derive(Debug, thiserror::Error)]
pub enum GcodeErrorKind {
    #[error("cannot read the program: {0}")]
    Io(#[from] std::io::Error),
    #[error("empty program: no G-code in the file")]
    EmptyProgram,
    #[error("line is longer than {limit} bytes")]
    LineTooLong { limit: usize },
    #[error(
        "invalid UTF-8 (bytes of another encoding, such as Latin-1, are read in comments only)"
    )]
    InvalidUtf8,
    #[error("comment opened here is never closed with `)`")]
    UnterminatedComment,
    #[error("`(` inside a comment: comments do not nest")]
    NestedComment,
    #[error("unexpected character {ch:?}{hint}")]
    UnexpectedChar { ch: char, hint: &'static str },
    #[error("`%` must stand alone on its line")]
    MisplacedPercent,
    #[error("{letter} must be followed by a number")]
    MissingNumber { letter: char },
    #[error("`{text}` is not a number (after {letter})")]
    BadNumber { letter: char, text: String },
    #[error("{letter}{text}: number out of range")]
    NumberOutOfRange { letter: char, text: String },
    #[error("{letter}{text}: {letter} needs a whole number")]
    NotAWholeNumber { letter: char, text: String },
    #[error("unknown G word G{code}")]
    UnknownG { code: String },
    #[error("G{code} is not supported: {why}")]
    UnsupportedG { code: String, why: &'static str },
    #[error(
        "unknown M word M{code} (a machine builder's M-code is given its action in [[program.mcode]])"
    )]
    UnknownM { code: String },
    #[error("word {letter} is not used {context}")]
    UnexpectedWord { letter: char, context: String },
    #[error("{letter} given twice in one block")]
    RepeatedWord { letter: char },
    #[error("G{a} and G{b} in one block: they set the same mode")]
    ConflictingG { a: String, b: String },
    #[error("axis {axis} is not on this machine (machine.axes = [{axes}])")]
    AxisNotOnMachine { axis: char, axes: String },
    #[error("axis words without a motion mode: program G0, G1, G2 or G3 first")]
    NoMotionMode,
    #[error(
        "feed F must be at least {} mm/min (a micrometre a minute)",
        crate::vocab::MIN_FEED_MM_PER_MIN
    )]
    BadFeed,
    #[error("work offset: {0}")]
    WorkOffset(String),
    #[error("polar coordinates: {0}")]
    Polar(String),
    /// A canned cycle or `G28`/`G30` that cannot run as written.
    #[error("{0}")]
    Cycle(String),
    #[error("missing coordinate: {what}")]
    MissingCoordinate { what: String },
    #[error("arc with both R and I/J/K: give the radius or the centre, not both")]
    ArcRAndCentre,
    #[error("arc needs its centre (I/J/K) or its radius (R)")]
    ArcMissingCentre,
    #[error("arc radius {} mm is less than half the chord ({} mm)", Num(*.radius), Num(*.half_chord))]
    ArcRadiusTooSmall { radius: f64, half_chord: f64 },
    #[error("arc centre coincides with its start point (zero radius)")]
    ArcZeroRadius,
    #[error("a full circle cannot be given with R: use I/J/K for the centre")]
    ArcFullCircleWithR,
    #[error("helical arc: axis {axis} moves during a circular arc {why}")]
    HelicalArc { axis: char, why: &'static str },
    #[error("arc radius to the end differs from the radius to the start: {start:.4} mm and {end:.4} mm (a spiral is accepted up to {limit} mm apart)", limit = Num(*.limit))]
    ArcSpiralTooFar { start: f64, end: f64, limit: f64 },
    #[error(
        "{letter} word missing in an absolute-centre arc (G90.1 needs both centre coordinates)"
    )]
    ArcCentreWordMissing { letter: char },
    #[error("arc P{text}: the number of turns is a whole number, 1 or more")]
    ArcTurns { text: String },
    #[error("{plane} arc needs axes {a} and {b} on the machine (machine.axes = [{axes}])")]
    ArcPlaneNotOnMachine {
        plane: &'static str,
        a: char,
        b: char,
        axes: String,
    },
    #[error("{what} out of range: {} (allowed {} to {})", Num(*.value), Num(*.min), Num(*.max))]
    OutOfRange {
        what: &'static str,
        value: f64,
        min: f64,
        max: f64,
    },
    #[error("weight {letter}{} must be greater than 0", Num(*.value))]
    BadWeight { letter: char, value: f64 },
    #[error(
        "weight {}: the curve's weights would range from {} to {}, further apart than {} (the \
         largest over the smallest), which double precision cannot evaluate faithfully",
        Num(*.weight), Num(*.low), Num(*.high), Num(*.max)
    )]
    WeightRatio {
        weight: f64,
        low: f64,
        high: f64,
        max: f64,
    },
    #[error("knots decrease: K{} is less than the previous knot {}", Num(*.value), Num(*.previous))]
    KnotsDecreasing { value: f64, previous: f64 },
    #[error("wrong knot count: {0}")]
    KnotCount(String),
    #[error("{form} block without K: every block of a {form} curve carries a knot")]
    MissingKnot { form: &'static str },
    #[error("control point after the closing knot-only blocks of the {form} curve")]
    PointAfterClosingKnots { form: &'static str },
    #[error("{} curve started at line {start_line} is interrupted by {by}{hint}", form.name())]
    NurbsInterrupted {
        form: super::NurbsForm,
        start_line: u64,
        by: Box<str>,
        hint: &'static str,
    },
    #[error("{form} curve started at line {start_line} is never finished{hint}")]
    NurbsUnterminated {
        form: &'static str,
        start_line: u64,
        hint: &'static str,
    },
    #[error("G5.3 without G5.2: no NURBS curve is open")]
    NurbsEndWithoutStart,
    #[error(
        "curve starts at {first} but the tool is at {current}: the first control point must be the current position"
    )]
    NurbsStartMismatch { first: String, current: String },
    #[error("curve has more than {limit} control points: split it into several curves")]
    TooManyPoints { limit: usize },
    #[error("invalid NURBS curve: {0}")]
    Nurbs(#[from] NurbsError),
    #[error("expression: {what}")]
    Expression { what: &'static str },
    #[error("expression nested deeper than {limit} levels (brackets, functions and #)")]
    NestedTooDeep { limit: usize },
    #[error("parameter number {} out of range (1 to {max})", Num(*.value))]
    ParameterNumber { value: f64, max: usize },
    #[error("parameter {name} is read-only: it is the interpreter's own value")]
    ReadOnlyParameter { name: String },
    #[error("parameter {name} is not set")]
    UndefinedParameter { name: String },
    #[error("{function}: argument outside the function's domain")]
    MathDomain { function: &'static str },
    #[error("{0}")]
    Control(String),
    #[error("wire offset: {0}")]
    WireOffset(String),
    #[error("orbit: {0}")]
    Orbit(String),
    #[error("taper: {0}")]
    Taper(String),
    #[error("{0}")]
    Probing(String),
    #[error(
        "{label} asks for {runs} runs, more than the whole program may make \
         (program.max_loop_iterations = {limit})"
    )]
    LoopLimit {
        label: String,
        runs: u64,
        limit: u64,
    },
    #[error(
        "{at}: the program has run {limit} loop iterations and subroutine calls in all, its \
         budget (program.max_loop_iterations); a runaway loop?"
    )]
    FlowBudget { at: String, limit: u64 },
    #[error("reading the program was cancelled")]
    Cancelled,
    #[error("subroutine calls nested deeper than {limit}")]
    CallDepth { limit: usize },
    #[error("no subroutine {label} in the program{searched}")]
    SubroutineNotFound {
        label: String,
        searched: &'static str,
    },
}

/// A program error with its place: `source:line:col: message`, then the line with a caret.
#[derive(Debug)]
pub struct GcodeError {
    pub source_name: Arc<str>,
    /// 1-based line number.
    pub line: u64,
    /// 1-based column, in characters.
    pub col: usize,
    pub kind: GcodeErrorKind,
    /// The offending line (or a window of it around the column), for the excerpt.
    pub text: String,
    /// Lines of the calls that led here, innermost first (`None` in the main program).
    /// Boxed so that the error stays small on every `Result` path (the lint's 128 bytes).
    #[allow(clippy::box_collection)]
    pub called_from: Option<Box<Vec<u64>>>,
}

impl std::error::Error for GcodeError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        Some(&self.kind)
    }
}

impl fmt::Display for GcodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line == 0 {
            return write!(f, "{}: {}", self.source_name, self.kind);
        }
        write!(
            f,
            "{}:{}:{}: {}",
            self.source_name, self.line, self.col, self.kind
        )?;
        let chain = self
            .called_from
            .as_deref()
            .map_or(&[][..], |v| v.as_slice());
        if let Some((first, rest)) = chain.split_first() {
            write!(f, " (in a subroutine called at line {first}")?;
            const SHOWN: usize = 3;
            for l in rest.iter().take(SHOWN) {
                write!(f, ", from line {l}")?;
            }
            if rest.len() > SHOWN {
                let last = rest[rest.len() - 1];
                write!(f, ", … {} calls deep, from line {last}", rest.len() + 1)?;
            }
            write!(f, ")")?;
        }
        if !self.text.is_empty() {
            let (excerpt, caret) = excerpt(&self.text, self.col);
            let gutter = self.line.to_string();
            let pad = " ".repeat(gutter.len());
            write!(
                f,
                "\n {gutter} | {excerpt}\n {pad} | {}^",
                " ".repeat(caret)
            )?;
        }
        Ok(())
    }
}

/// At most [`EXCERPT_CHARS`] characters of `text` around 1-based `col`, with control characters
/// made visible; returns the excerpt and the caret's 0-based offset in it.
fn excerpt(text: &str, col: usize) -> (String, usize) {
    const EXCERPT_CHARS: usize = 100;
    let chars: Vec<char> = text.chars().collect();
    let at = col.saturating_sub(1).min(chars.len());
    let start = at.saturating_sub(EXCERPT_CHARS / 2);
    let end = (start + EXCERPT_CHARS).min(chars.len());
    let mut out: String = chars[start..end]
        .iter()
        .map(|&c| if c.is_control() { '\u{fffd}' } else { c })
        .collect();
    let mut caret = at - start;
    if start > 0 {
        out.insert_str(0, "...");
        caret += 3;
    }
    if end < chars.len() {
        out.push_str("...");
    }
    (out, caret)
}

/// How a warning that is a message to the operator (`(MSG, …)`, a pause M-code's text)
/// begins: the job shows the text after it at the stop it precedes.
pub const OPERATOR_MESSAGE: &str = "message: ";

/// Something edmd accepts but wants the operator to know (an ignored spindle word, text after M30).
#[derive(Debug, Clone, PartialEq)]
pub struct Warning {
    pub line: u64,
    pub col: usize,
    pub message: String,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_has_location_excerpt_and_caret() {
        let e = GcodeError {
            source_name: "p.nc".into(),
            line: 12,
            col: 8,
            kind: GcodeErrorKind::UnknownG { code: "7".into() },
            text: "G01 X1 G7 Y2".into(),
            called_from: None,
        };
        assert_eq!(
            e.to_string(),
            "p.nc:12:8: unknown G word G7\n 12 | G01 X1 G7 Y2\n    |        ^"
        );
    }

    #[test]
    fn long_lines_are_windowed_around_the_column() {
        let text = "X".repeat(500);
        let (ex, caret) = excerpt(&text, 300);
        assert_eq!(ex.chars().count(), 106);
        assert_eq!(ex.chars().nth(caret), Some('X'));
        assert_eq!(caret, 53);
    }
}
