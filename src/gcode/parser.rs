//! The modal G-code interpreter: lines in, [`Block`]s out, one at a time.

use std::io::BufRead;
use std::sync::Arc;

use super::error::{GcodeError, GcodeErrorKind, Warning};
use super::lexer::{Word, lex};
use super::lines::{Line, LineSource, MAX_LINE_BYTES};
use super::{Block, BlockKind, NurbsForm, Plane};
use crate::config::Axis;
use crate::geometry::{MAX_DEGREE, NurbsCurve, NurbsError, Point, circular_arc};

/// Most control points in one NURBS curve: a curve is held whole until it closes.
pub const MAX_CURVE_POINTS: usize = 100_000;
/// How far apart the start and end radii of an `I J K` arc may be, mm (plus [`ARC_RADIUS_REL`]
/// of the radius): CAM output rounded to 3 decimals in mm or 4 in inch stays inside.
pub const ARC_RADIUS_TOLERANCE_MM: f64 = 0.002;
const ARC_RADIUS_REL: f64 = 1e-5;
/// How close the first control point of a curve must be to the current position, mm.
pub const CURVE_START_TOLERANCE_MM: f64 = 0.0005;
const MM_PER_INCH: f64 = 25.4;
/// Largest coordinate magnitude accepted, mm.
const MAX_COORD_MM: f64 = 1.0e6;

/// A failure inside the interpreter, before the location is attached. `at` is `None` for the
/// current line, or another line (the start of a curve) with its text.
struct Fail {
    col: usize,
    kind: GcodeErrorKind,
    at: Option<(u64, String)>,
}

impl From<(usize, GcodeErrorKind)> for Fail {
    fn from((col, kind): (usize, GcodeErrorKind)) -> Self {
        Fail {
            col,
            kind,
            at: None,
        }
    }
}

type Step<T> = Result<T, Fail>;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Motion {
    Rapid,
    Linear,
    Cw,
    Ccw,
}

/// What a G word does.
#[derive(Debug, Clone, Copy, PartialEq)]
enum GCode {
    Motion(Motion),
    /// G80: cancels the modal motion (it is in the motion group).
    MotionCancel,
    Curve(NurbsForm),
    CurveEnd,
    Inch(bool),
    Incremental(bool),
    ArcCentreAbsolute(bool),
    Plane(Plane),
    /// A mode edmd is always in (G40, G49, G54, G61, G64, G94): accepted, nothing to do.
    Accepted(u8),
}

impl GCode {
    /// Modal group: two words of one group in a block conflict.
    fn group(self) -> u8 {
        match self {
            GCode::Motion(_) | GCode::MotionCancel | GCode::Curve(_) | GCode::CurveEnd => 1,
            GCode::Inch(_) => 2,
            GCode::Incremental(_) => 3,
            GCode::ArcCentreAbsolute(_) => 4,
            GCode::Plane(_) => 5,
            GCode::Accepted(g) => g,
        }
    }
}

/// `G` number times ten (`G06.2` is 62), so codes compare exactly.
fn g_code_tenths(w: &Word) -> Step<u32> {
    let tenths = w.value * 10.0;
    if w.value < 0.0 || (tenths - tenths.round()).abs() > 1e-6 || tenths > 9999.0 {
        return Err((
            w.col,
            GcodeErrorKind::UnknownG {
                code: w.text.clone(),
            },
        )
            .into());
    }
    Ok(tenths.round() as u32)
}

fn g_name(tenths: u32) -> String {
    if tenths.is_multiple_of(10) {
        format!("{}", tenths / 10)
    } else {
        format!("{}.{}", tenths / 10, tenths % 10)
    }
}

fn classify_g(tenths: u32, col: usize) -> Step<GCode> {
    let unsupported = |why: &'static str| -> Step<GCode> {
        Err((
            col,
            GcodeErrorKind::UnsupportedG {
                code: g_name(tenths),
                why,
            },
        )
            .into())
    };
    Ok(match tenths {
        0 => GCode::Motion(Motion::Rapid),
        10 => GCode::Motion(Motion::Linear),
        20 => GCode::Motion(Motion::Cw),
        30 => GCode::Motion(Motion::Ccw),
        380 => GCode::Curve(NurbsForm::G38),
        62 => GCode::Curve(NurbsForm::Fanuc),
        52 => GCode::Curve(NurbsForm::LinuxCnc),
        53 => GCode::CurveEnd,
        800 => GCode::MotionCancel,
        200 => GCode::Inch(true),
        210 => GCode::Inch(false),
        900 => GCode::Incremental(false),
        910 => GCode::Incremental(true),
        901 => GCode::ArcCentreAbsolute(true),
        911 => GCode::ArcCentreAbsolute(false),
        170 => GCode::Plane(Plane::XY),
        180 => GCode::Plane(Plane::ZX),
        190 => GCode::Plane(Plane::YZ),
        400 => GCode::Accepted(7),
        490 => GCode::Accepted(8),
        540 => GCode::Accepted(12),
        610 | 611 | 640 => GCode::Accepted(13),
        940 => GCode::Accepted(6),
        410 | 411 | 420 | 421 => {
            return unsupported(
                "cutter compensation; post the program with the offset applied (G40)",
            );
        }
        430..=439 => return unsupported("tool length offsets"),
        930 => return unsupported("inverse time feed; use G94 (units per minute)"),
        950 => return unsupported("feed per revolution; use G94 (units per minute)"),
        40 => return unsupported("dwell"),
        50 | 51 => return unsupported("LinuxCNC splines; use the G5.2/G5.3 NURBS form"),
        60 | 61 => return unsupported("this is a G06.x code edmd does not have; use G06.2"),
        70 | 80 => return unsupported("lathe modes"),
        100 | 280 | 281 | 300 | 301 | 520 | 530 | 920..=923 | 550..=590 | 591..=593 => {
            return unsupported(
                "coordinate offsets and homing; edmd works in machine coordinates (G54)",
            );
        }
        330 | 331 | 760 => return unsupported("threading"),
        382..=385 => {
            return unsupported(
                "probing (edmd's G38 without a decimal is the seed-000 NURBS block)",
            );
        }
        730 | 740 | 810..=890 => return unsupported("canned cycles"),
        960 | 970 => return unsupported("spindle speed modes"),
        _ => {
            return Err((
                col,
                GcodeErrorKind::UnknownG {
                    code: g_name(tenths),
                },
            )
                .into());
        }
    })
}

#[derive(Debug, Clone)]
struct Modal {
    inch: bool,
    incremental: bool,
    arc_centre_absolute: bool,
    plane: Plane,
    motion: Option<Motion>,
    /// mm/min
    feed: Option<f64>,
}

/// A NURBS curve being collected over several lines.
struct PendingCurve {
    form: NurbsForm,
    start_line: u64,
    start_col: usize,
    start_text: String,
    degree: usize,
    /// G38's `C`: how many control points the header announced.
    announced_points: Option<usize>,
    points: Vec<Point>,
    weights: Vec<f64>,
    /// Knots as given (G06.2 always; G38 when its lines carry K).
    knots: Vec<f64>,
    knots_given: bool,
    /// Knot-only blocks seen so far (the closing knots).
    closing_knots: usize,
    feed: Option<f64>,
}

impl PendingCurve {
    fn order(&self) -> usize {
        self.degree + 1
    }

    fn interrupted(&self, by: String, hint: &'static str) -> GcodeErrorKind {
        if self.closing_knots > 0 || (self.knots_given && self.form == NurbsForm::G38) {
            let need = self.points.len() + self.order();
            return GcodeErrorKind::KnotCount(format!(
                "the {} curve started at line {} has {} control points of order {} and needs {need} knots; {} were given before {by}",
                self.form.name(),
                self.start_line,
                self.points.len(),
                self.order(),
                self.knots.len()
            ));
        }
        GcodeErrorKind::NurbsInterrupted {
            form: self.form.name(),
            start_line: self.start_line,
            by,
            hint,
        }
    }

    fn close_hint(&self) -> &'static str {
        match self.form {
            NurbsForm::LinuxCnc => " (close it with G5.3)",
            NurbsForm::Fanuc => " (it ends after as many knot-only K blocks as its order P)",
            NurbsForm::G38 => " (it ends after the number of points given by C)",
        }
    }
}

/// The words of one block, looked up by letter.
struct Letters<'w> {
    by_letter: [Option<&'w Word>; 26],
}

impl<'w> Letters<'w> {
    fn get(&self, letter: char) -> Option<&'w Word> {
        self.by_letter[(letter as u8 - b'A') as usize]
    }

    fn present(&self) -> impl Iterator<Item = &'w Word> + '_ {
        self.by_letter.iter().flatten().copied()
    }
}

/// Reads a program one block at a time. See the module docs of [`crate::gcode`].
pub struct BlockReader<R> {
    lines: LineSource<R>,
    source_name: Arc<str>,
    axes: Vec<Axis>,
    modal: Modal,
    position: Point,
    pending: Option<PendingCurve>,
    warnings: Vec<Warning>,
    warned_letters: Vec<char>,
    warned_no_feed: bool,
    words: Vec<Word>,
    saw_content: bool,
    ended_at: Option<u64>,
    done: bool,
}

impl<R: BufRead> BlockReader<R> {
    /// A reader for a machine with `axes`, starting at the machine origin, in G21 G90 G17 G94
    /// with no motion mode and no feed. `source_name` prefixes every error (`file:line:col`).
    pub fn new(reader: R, source_name: &str, axes: &[Axis]) -> Self {
        Self {
            lines: LineSource::new(reader),
            source_name: source_name.into(),
            axes: axes.to_vec(),
            modal: Modal {
                inch: false,
                incremental: false,
                arc_centre_absolute: false,
                plane: Plane::XY,
                motion: None,
                feed: None,
            },
            position: Point::zeros(),
            pending: None,
            warnings: Vec::new(),
            warned_letters: Vec::new(),
            warned_no_feed: false,
            words: Vec::new(),
            saw_content: false,
            ended_at: None,
            done: false,
        }
    }

    /// Takes the warnings collected so far.
    pub fn take_warnings(&mut self) -> Vec<Warning> {
        std::mem::take(&mut self.warnings)
    }

    /// Current position in mm, machine axis order.
    pub fn position(&self) -> Point {
        self.position
    }

    /// The line of the M2/M30 that ended the program, if one did.
    pub fn program_end_line(&self) -> Option<u64> {
        self.ended_at
    }

    fn error(&self, line: u64, text: &str, fail: Fail) -> GcodeError {
        let (line, text) = match fail.at {
            Some((l, t)) => (l, t),
            None => (line, text.to_string()),
        };
        GcodeError {
            source_name: self.source_name.clone(),
            line,
            col: fail.col,
            kind: fail.kind,
            text,
        }
    }

    fn next_block(&mut self) -> Result<Option<Block>, GcodeError> {
        loop {
            let next = self.lines.next_line().map_err(|e| GcodeError {
                source_name: self.source_name.clone(),
                line: 0,
                col: 0,
                kind: GcodeErrorKind::Io(e),
                text: String::new(),
            })?;
            let Some((line_no, line)) = next else {
                return self.finish().map(|()| None);
            };
            let text = match line {
                Line::Text(t) => t.to_string(),
                Line::TooLong => {
                    return Err(self.error(
                        line_no,
                        "",
                        (
                            1,
                            GcodeErrorKind::LineTooLong {
                                limit: MAX_LINE_BYTES,
                            },
                        )
                            .into(),
                    ));
                }
                Line::BadUtf8 { valid_prefix } => {
                    let col = valid_prefix.chars().count() + 1;
                    let shown = valid_prefix.to_string();
                    return Err(self.error(
                        line_no,
                        &shown,
                        (col, GcodeErrorKind::InvalidUtf8).into(),
                    ));
                }
            };
            let mut words = std::mem::take(&mut self.words);
            let result = self.process_line(line_no, &text, &mut words);
            self.words = words;
            match result {
                Ok(Some(block)) => return Ok(Some(block)),
                Ok(None) if self.done => return Ok(None),
                Ok(None) => {}
                Err(fail) => return Err(self.error(line_no, &text, fail)),
            }
        }
    }

    fn finish(&mut self) -> Result<(), GcodeError> {
        self.done = true;
        if let Some(p) = &self.pending {
            let kind = GcodeErrorKind::NurbsUnterminated {
                form: p.form.name(),
                start_line: p.start_line,
                hint: p.close_hint(),
            };
            let fail = Fail {
                col: p.start_col,
                kind,
                at: Some((p.start_line, p.start_text.clone())),
            };
            return Err(self.error(0, "", fail));
        }
        if !self.saw_content {
            return Err(self.error(1, "", (1, GcodeErrorKind::EmptyProgram).into()));
        }
        if self.ended_at.is_none() {
            self.warnings.push(Warning {
                line: 0,
                col: 0,
                message: "the program has no M2/M30 end".to_string(),
            });
        }
        Ok(())
    }

    fn process_line(
        &mut self,
        line_no: u64,
        text: &str,
        words: &mut Vec<Word>,
    ) -> Step<Option<Block>> {
        let info = lex(text, words).map_err(Fail::from)?;
        if words.is_empty() && info.percent.is_none() {
            return Ok(None);
        }
        self.saw_content = true;
        if let Some(end_line) = self.ended_at {
            if words.is_empty() {
                return Ok(None); // a closing `%`
            }
            self.warnings.push(Warning {
                line: line_no,
                col: words[0].col,
                message: format!(
                    "text after the program end (M2/M30 at line {end_line}) is ignored"
                ),
            });
            self.done = true;
            return Ok(None);
        }
        if words.is_empty() {
            return Ok(None); // `%` tape mark
        }
        let letters = collect_letters(words)?;
        if let Some(n) = letters.get('N') {
            whole(n, 0.0, 1e9)?;
        }
        if self.pending.is_some() {
            return self.continue_curve(&letters, words);
        }
        self.start_block(line_no, text, &letters, words)
    }

    // ---- ordinary blocks --------------------------------------------------------------------

    fn start_block(
        &mut self,
        line_no: u64,
        text: &str,
        letters: &Letters,
        words: &[Word],
    ) -> Step<Option<Block>> {
        let mut codes: Vec<(GCode, &Word)> = Vec::new();
        for w in words.iter().filter(|w| w.letter == 'G') {
            let code = classify_g(g_code_tenths(w)?, w.col)?;
            if let Some((_, other)) = codes.iter().find(|(c, _)| c.group() == code.group()) {
                return Err((
                    w.col,
                    GcodeErrorKind::ConflictingG {
                        a: other.text.clone(),
                        b: w.text.clone(),
                    },
                )
                    .into());
            }
            codes.push((code, w));
        }
        let mut motion_word: Option<(GCode, &Word)> = None;
        for &(code, w) in &codes {
            match code {
                GCode::Inch(inch) => self.modal.inch = inch,
                GCode::Incremental(inc) => self.modal.incremental = inc,
                GCode::ArcCentreAbsolute(abs) => self.modal.arc_centre_absolute = abs,
                GCode::Plane(p) => self.modal.plane = p,
                GCode::Accepted(_) => {}
                GCode::Motion(_) | GCode::MotionCancel | GCode::Curve(_) | GCode::CurveEnd => {
                    motion_word = Some((code, w));
                }
            }
        }
        if let Some(o) = letters.get('O')
            && !matches!(motion_word, Some((GCode::Curve(NurbsForm::G38), _)))
        {
            // Fanuc's program number (`O1000`) stands alone on its line.
            if words.iter().all(|w| matches!(w.letter, 'O' | 'N')) {
                whole(o, 0.0, 99_999.0)?;
                return Ok(None);
            }
            return Err((
                o.col,
                GcodeErrorKind::UnexpectedWord {
                    letter: 'O',
                    context: "here: O is a program number alone on its line, or G38's degree"
                        .into(),
                },
            )
                .into());
        }
        let mut program_end = false;
        for w in words.iter().filter(|w| w.letter == 'M') {
            let code = whole(w, 0.0, 9999.0)? as u32;
            match code {
                2 | 30 => program_end = true,
                3..=9 => self.warn_once(
                    line_no,
                    w,
                    "spindle, tool change and coolant words (M3-M9) do nothing on an EDM and are ignored",
                ),
                0 | 1 | 60 => {
                    return Err((
                        w.col,
                        GcodeErrorKind::UnknownM {
                            code: format!("{} (program pause is not supported)", w.text),
                        },
                    )
                        .into());
                }
                _ => {
                    return Err((
                        w.col,
                        GcodeErrorKind::UnknownM {
                            code: w.text.clone(),
                        },
                    )
                        .into());
                }
            }
        }
        for letter in ['S', 'T'] {
            if let Some(w) = letters.get(letter) {
                self.warn_once(
                    line_no,
                    w,
                    "spindle speed (S) and tool (T) words do nothing on an EDM and are ignored",
                );
            }
        }
        if let Some(f) = letters.get('F') {
            // The lexer only yields finite numbers, so this also covers the sign.
            if f.value <= 0.0 {
                return Err((f.col, GcodeErrorKind::BadFeed).into());
            }
            self.modal.feed = Some(f.value * self.scale());
        }

        let block = match motion_word {
            Some((GCode::Curve(form), w)) => {
                self.check_letters(
                    letters,
                    true,
                    curve_letters(form, true),
                    &format!("with {}", form.name()),
                )?;
                self.open_curve(form, line_no, text, w, letters)?
            }
            Some((GCode::CurveEnd, w)) => {
                return Err((w.col, GcodeErrorKind::NurbsEndWithoutStart).into());
            }
            Some((GCode::MotionCancel, _)) => {
                self.modal.motion = None;
                self.check_letters(letters, false, "", "with G80")?;
                None
            }
            Some((GCode::Motion(m), w)) => {
                self.modal.motion = Some(m);
                if self.moves(m, letters)? {
                    self.motion_block(m, line_no, letters, w.col)?
                } else {
                    self.check_letters(letters, false, "", "without axis words")?;
                    None
                }
            }
            _ => match self.modal.motion {
                Some(m) if self.moves(m, letters)? => {
                    self.motion_block(m, line_no, letters, first_col(words))?
                }
                Some(_) => {
                    self.check_letters(letters, false, "", "without axis words")?;
                    None
                }
                None => {
                    if let Some(w) = self.first_axis_word(letters)? {
                        return Err((w.col, GcodeErrorKind::NoMotionMode).into());
                    }
                    self.check_letters(letters, false, "", "without a motion word")?;
                    None
                }
            },
        };
        if program_end {
            self.ended_at = Some(line_no);
        }
        Ok(block)
    }

    /// Whether a block in motion mode `m` moves: it has axis words, or, for an arc, a centre
    /// or radius (a full circle needs no axis words). A bare `G1` only sets the mode.
    fn moves(&self, m: Motion, letters: &Letters) -> Step<bool> {
        if self.first_axis_word(letters)?.is_some() {
            return Ok(true);
        }
        let arc_words = matches!(m, Motion::Cw | Motion::Ccw)
            && ['I', 'J', 'K', 'R']
                .iter()
                .any(|&l| letters.get(l).is_some());
        Ok(arc_words)
    }

    fn warn_once(&mut self, line: u64, w: &Word, message: &str) {
        if !self.warned_letters.contains(&w.letter) {
            self.warned_letters.push(w.letter);
            self.warnings.push(Warning {
                line,
                col: w.col,
                message: format!("{}{}: {message}", w.letter, w.text),
            });
        }
    }

    fn scale(&self) -> f64 {
        if self.modal.inch { MM_PER_INCH } else { 1.0 }
    }

    fn axes_list(&self) -> String {
        self.axes
            .iter()
            .map(|a| a.letter().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The axis a word names: `Some` for one of the machine's axes, `None` for a letter that is
    /// no axis, an error for an axis letter the machine does not have.
    fn machine_axis(&self, w: &Word) -> Step<Option<Axis>> {
        match Axis::from_letter(w.letter) {
            Some(axis) if !self.axes.contains(&axis) => Err((
                w.col,
                GcodeErrorKind::AxisNotOnMachine {
                    axis: w.letter,
                    axes: self.axes_list(),
                },
            )
                .into()),
            found => Ok(found),
        }
    }

    /// The first axis word of the block, checking that every axis word names a machine axis.
    fn first_axis_word<'w>(&self, letters: &Letters<'w>) -> Step<Option<&'w Word>> {
        let mut first: Option<&Word> = None;
        for w in letters.present() {
            if self.machine_axis(w)?.is_some() && first.is_none_or(|f| w.col < f.col) {
                first = Some(w);
            }
        }
        Ok(first)
    }

    /// Rejects any word outside G M N F S T, `extra`, and (with `allow_axes`) the machine's
    /// axes. An axis letter the machine does not have is reported as such either way.
    fn check_letters(
        &self,
        letters: &Letters,
        allow_axes: bool,
        extra: &str,
        context: &str,
    ) -> Step<()> {
        for w in letters.present() {
            if extra.contains(w.letter) || "GMNFST".contains(w.letter) {
                continue; // a form's own word (G38's C) wins over an axis letter
            }
            if self.machine_axis(w)?.is_some() && allow_axes {
                continue;
            }
            return Err((
                w.col,
                GcodeErrorKind::UnexpectedWord {
                    letter: w.letter,
                    context: context.to_string(),
                },
            )
                .into());
        }
        Ok(())
    }

    /// The point reached from `base` by the block's axis words (absolute or incremental),
    /// and whether any axis word was present. Letters in `reserved` are not axis words here.
    fn target(&self, base: &Point, letters: &Letters, reserved: &str) -> Step<(Point, bool)> {
        let mut p = *base;
        let mut any = false;
        for (i, axis) in self.axes.iter().enumerate() {
            if reserved.contains(axis.letter()) {
                continue;
            }
            if let Some(w) = letters.get(axis.letter()) {
                let v = w.value * self.scale();
                p[i] = if self.modal.incremental {
                    base[i] + v
                } else {
                    v
                };
                if p[i].abs() > MAX_COORD_MM {
                    return Err((
                        w.col,
                        GcodeErrorKind::OutOfRange {
                            what: "coordinate (mm)",
                            value: p[i],
                            min: -MAX_COORD_MM,
                            max: MAX_COORD_MM,
                        },
                    )
                        .into());
                }
                any = true;
            }
        }
        Ok((p, any))
    }

    /// The programmed feed for a feed move. On an EDM the gap servo sets the advance speed and
    /// `F` is only an upper limit, so a program without one (seed 000's G38 example) is valid:
    /// it runs at up to the machine maximum, and the operator is told once.
    fn feed_limit(&mut self, line: u64, col: usize) -> Option<f64> {
        if self.modal.feed.is_none() && !self.warned_no_feed {
            self.warned_no_feed = true;
            self.warnings.push(Warning {
                line,
                col,
                message: "feed move without a programmed F: it runs at up to machine.max_feed_mm_per_min, as the gap servo allows".into(),
            });
        }
        self.modal.feed
    }

    fn motion_block(
        &mut self,
        motion: Motion,
        line_no: u64,
        letters: &Letters,
        col: usize,
    ) -> Step<Option<Block>> {
        match motion {
            Motion::Rapid | Motion::Linear => {
                self.check_letters(
                    letters,
                    true,
                    "",
                    if motion == Motion::Rapid {
                        "with G0"
                    } else {
                        "with G1"
                    },
                )?;
                let (target, _) = self.target(&self.position, letters, "")?;
                let feed = match motion {
                    Motion::Linear => self.feed_limit(line_no, col),
                    _ => None,
                };
                if target == self.position {
                    return Ok(None);
                }
                let curve = NurbsCurve::line(self.axes.len(), &self.position, &target)
                    .map_err(|e| Fail::from((col, e.into())))?;
                self.position = target;
                Ok(Some(Block {
                    line: line_no,
                    kind: if motion == Motion::Rapid {
                        BlockKind::Rapid
                    } else {
                        BlockKind::Line
                    },
                    curve,
                    feed_mm_per_min: feed,
                }))
            }
            Motion::Cw | Motion::Ccw => {
                self.arc_block(motion == Motion::Ccw, line_no, letters, col)
            }
        }
    }

    fn arc_block(
        &mut self,
        ccw: bool,
        line_no: u64,
        letters: &Letters,
        col: usize,
    ) -> Step<Option<Block>> {
        let plane = self.modal.plane;
        let [la, lb] = plane.axis_letters();
        let [oa, ob] = plane.offset_letters();
        let context = format!("in {} ({}) arcs", plane.g_code(), plane.name());
        let extra: String = [oa, ob, 'R', 'P'].iter().collect();
        self.check_letters(letters, true, &extra, &context)?;
        if let Some(p) = letters.get('P') {
            return Err((
                p.col,
                GcodeErrorKind::UnexpectedWord {
                    letter: 'P',
                    context: "in arcs (multi-turn arcs are not supported)".into(),
                },
            )
                .into());
        }
        let index = |letter: char| {
            Axis::from_letter(letter).and_then(|a| self.axes.iter().position(|&m| m == a))
        };
        let (Some(ia), Some(ib)) = (index(la), index(lb)) else {
            return Err((
                col,
                GcodeErrorKind::ArcPlaneNotOnMachine {
                    plane: plane.g_code(),
                    a: la,
                    b: lb,
                    axes: self.axes_list(),
                },
            )
                .into());
        };
        let feed = self.feed_limit(line_no, col);
        let (end, _) = self.target(&self.position, letters, "")?;
        let start = self.position;
        for (i, axis) in self.axes.iter().enumerate() {
            if i != ia && i != ib && end[i] != start[i] {
                let w = letters.get(axis.letter()).map_or(col, |w| w.col);
                return Err((
                    w,
                    GcodeErrorKind::HelicalArc {
                        axis: axis.letter(),
                    },
                )
                    .into());
            }
        }
        let radius_word = letters.get('R');
        let (off_a, off_b) = (letters.get(oa), letters.get(ob));
        if let (Some(r), Some(o)) = (radius_word, off_a.or(off_b)) {
            return Err((r.col.max(o.col), GcodeErrorKind::ArcRAndCentre).into());
        }
        let chord_a = end[ia] - start[ia];
        let chord_b = end[ib] - start[ib];
        let chord = chord_a.hypot(chord_b);
        let full_circle = chord < 1e-9;
        let mut center = start;
        if let Some(r) = radius_word {
            if full_circle {
                return Err((r.col, GcodeErrorKind::ArcFullCircleWithR).into());
            }
            let radius = r.value * self.scale();
            let half = chord / 2.0;
            let tol = ARC_RADIUS_TOLERANCE_MM + ARC_RADIUS_REL * radius.abs();
            let h_sq = radius * radius - half * half;
            if h_sq < 0.0 && half - radius.abs() > tol {
                return Err((
                    r.col,
                    GcodeErrorKind::ArcRadiusTooSmall {
                        radius: radius.abs(),
                        half_chord: half,
                    },
                )
                    .into());
            }
            let h = h_sq.max(0.0).sqrt();
            // Centre to the left of the chord for a counter-clockwise minor arc; R < 0 asks for
            // the major arc, which puts it on the other side.
            let side = if ccw == (radius > 0.0) { 1.0 } else { -1.0 };
            center[ia] = start[ia] + chord_a / 2.0 - side * h * chord_b / chord;
            center[ib] = start[ib] + chord_b / 2.0 + side * h * chord_a / chord;
        } else {
            if off_a.is_none() && off_b.is_none() {
                return Err((col, GcodeErrorKind::ArcMissingCentre).into());
            }
            let s = self.scale();
            let va = off_a.map(|w| w.value * s);
            let vb = off_b.map(|w| w.value * s);
            if self.modal.arc_centre_absolute {
                center[ia] = va.unwrap_or(start[ia]);
                center[ib] = vb.unwrap_or(start[ib]);
            } else {
                center[ia] = start[ia] + va.unwrap_or(0.0);
                center[ib] = start[ib] + vb.unwrap_or(0.0);
            }
            let r_start = (start[ia] - center[ia]).hypot(start[ib] - center[ib]);
            let r_end = (end[ia] - center[ia]).hypot(end[ib] - center[ib]);
            let offset_col = off_a.or(off_b).map_or(col, |w| w.col);
            if r_start < 1e-9 {
                return Err((offset_col, GcodeErrorKind::ArcZeroRadius).into());
            }
            if (r_start - r_end).abs() > ARC_RADIUS_TOLERANCE_MM + ARC_RADIUS_REL * r_start {
                return Err((
                    offset_col,
                    GcodeErrorKind::ArcRadiusMismatch {
                        start: r_start,
                        end: r_end,
                    },
                )
                    .into());
            }
        }
        let a0 = (start[ib] - center[ib]).atan2(start[ia] - center[ia]);
        let a1 = (end[ib] - center[ib]).atan2(end[ia] - center[ia]);
        let tau = std::f64::consts::TAU;
        let sweep = if full_circle {
            if ccw { tau } else { -tau }
        } else if ccw {
            let s = (a1 - a0).rem_euclid(tau);
            if s == 0.0 { tau } else { s }
        } else {
            let s = (a0 - a1).rem_euclid(tau);
            -(if s == 0.0 { tau } else { s })
        };
        let curve = circular_arc(self.axes.len(), [ia, ib], &center, &start, &end, sweep)
            .map_err(|e| Fail::from((col, e.into())))?;
        let radius = (start[ia] - center[ia]).hypot(start[ib] - center[ib]);
        self.position = end;
        Ok(Some(Block {
            line: line_no,
            kind: BlockKind::Arc {
                center,
                radius,
                sweep,
                plane,
            },
            curve,
            feed_mm_per_min: feed,
        }))
    }

    // ---- NURBS curves -----------------------------------------------------------------------

    fn open_curve(
        &mut self,
        form: NurbsForm,
        line_no: u64,
        text: &str,
        g_word: &Word,
        letters: &Letters,
    ) -> Step<Option<Block>> {
        let feed = self.feed_limit(line_no, g_word.col);
        let degree = match form {
            NurbsForm::G38 => {
                let o = letters.get('O').ok_or((
                    g_word.col,
                    GcodeErrorKind::MissingCoordinate {
                        what: "the first G38 block needs O<degree>".into(),
                    },
                ))?;
                whole(o, 1.0, MAX_DEGREE as f64)? as usize
            }
            NurbsForm::Fanuc => {
                let p = letters.get('P').ok_or((
                    g_word.col,
                    GcodeErrorKind::MissingCoordinate {
                        what: "the first G06.2 block needs P<order>".into(),
                    },
                ))?;
                whole(p, 2.0, (MAX_DEGREE + 1) as f64)? as usize - 1
            }
            NurbsForm::LinuxCnc => match letters.get('L') {
                Some(l) => whole(l, 2.0, (MAX_DEGREE + 1) as f64)? as usize - 1,
                None => 2, // LinuxCNC's default order is 3
            },
        };
        let mut curve = PendingCurve {
            form,
            start_line: line_no,
            start_col: g_word.col,
            start_text: text.to_string(),
            degree,
            announced_points: None,
            points: Vec::new(),
            weights: Vec::new(),
            knots: Vec::new(),
            knots_given: false,
            closing_knots: 0,
            feed,
        };
        if form == NurbsForm::G38 {
            let c = letters.get('C').ok_or((
                g_word.col,
                GcodeErrorKind::MissingCoordinate {
                    what: "the first G38 block needs C<number of control points>".into(),
                },
            ))?;
            let count = whole(c, 2.0, MAX_CURVE_POINTS as f64)? as usize;
            if count < degree + 1 {
                return Err((
                    c.col,
                    NurbsError::TooFewPoints {
                        points: count,
                        degree,
                    }
                    .into(),
                )
                    .into());
            }
            curve.announced_points = Some(count);
            curve.knots_given = letters.get('K').is_some();
        }
        if form == NurbsForm::LinuxCnc {
            // The current position is the first control point; a G5.2 without axis words only
            // sets that point's weight.
            let (_, any) = self.target(&self.position, letters, "")?;
            let p0_weight = if any { 1.0 } else { weight(letters.get('P'))? };
            curve.points.push(self.position);
            curve.weights.push(p0_weight);
            if any {
                self.add_point(&mut curve, letters, g_word.col)?;
            }
        } else {
            let first = self.add_point(&mut curve, letters, g_word.col)?;
            let gap = (first - self.position).norm();
            if gap > CURVE_START_TOLERANCE_MM {
                return Err((
                    g_word.col,
                    GcodeErrorKind::NurbsStartMismatch {
                        first: self.format_point(&first),
                        current: self.format_point(&self.position),
                    },
                )
                    .into());
            }
            // Within tolerance: start exactly where the tool is, so no step is lost or invented.
            curve.points[0] = self.position;
        }
        self.pending = Some(curve);
        Ok(None)
    }

    fn format_point(&self, p: &Point) -> String {
        let parts: Vec<String> = self
            .axes
            .iter()
            .enumerate()
            .map(|(i, a)| format!("{a}{:.4}", p[i] / self.scale()))
            .collect();
        parts.join(" ")
    }

    /// Adds the block's control point (and its weight and knot) to `curve`; returns the point.
    fn add_point(&self, curve: &mut PendingCurve, letters: &Letters, col: usize) -> Step<Point> {
        if curve.points.len() >= MAX_CURVE_POINTS {
            return Err((
                col,
                GcodeErrorKind::TooManyPoints {
                    limit: MAX_CURVE_POINTS,
                },
            )
                .into());
        }
        let base = curve.points.last().copied().unwrap_or(self.position);
        // G38's first line uses C for the point count, even on a machine with a C axis.
        let reserved = if curve.form == NurbsForm::G38 && curve.points.is_empty() {
            "C"
        } else {
            ""
        };
        let (p, any) = self.target(&base, letters, reserved)?;
        if !any {
            return Err((
                col,
                GcodeErrorKind::MissingCoordinate {
                    what: format!("{} control point without axis words", curve.form.name()),
                },
            )
                .into());
        }
        let w = weight(letters.get(curve.form.weight_letter()))?;
        if curve.form == NurbsForm::Fanuc || curve.knots_given {
            push_knot(curve, letters, col)?;
        } else if let Some(k) = letters.get('K') {
            return Err((
                k.col,
                GcodeErrorKind::UnexpectedWord {
                    letter: 'K',
                    context: "here: the first G38 block gave no knots, so none may follow".into(),
                },
            )
                .into());
        }
        curve.points.push(p);
        curve.weights.push(w);
        Ok(p)
    }

    fn continue_curve(&mut self, letters: &Letters, words: &[Word]) -> Step<Option<Block>> {
        let mut curve = self
            .pending
            .take()
            .expect("continue_curve with a pending curve");
        let result = self.continue_curve_inner(&mut curve, letters, words);
        match result {
            Ok(true) => self.close_curve(curve).map(Some),
            Ok(false) => {
                self.pending = Some(curve);
                Ok(None)
            }
            Err(e) => Err(e),
        }
    }

    /// Takes one line of an open curve; `true` when the curve is complete.
    fn continue_curve_inner(
        &mut self,
        curve: &mut PendingCurve,
        letters: &Letters,
        words: &[Word],
    ) -> Step<bool> {
        // Anything but the curve's own G word interrupts it.
        let mut own_g = false;
        for w in words.iter().filter(|w| matches!(w.letter, 'G' | 'M')) {
            let by = format!("{}{}", w.letter, w.text);
            if w.letter == 'G' {
                let code = classify_g(g_code_tenths(w)?, w.col)?;
                match (curve.form, code) {
                    (NurbsForm::G38, GCode::Curve(NurbsForm::G38))
                    | (NurbsForm::Fanuc, GCode::Curve(NurbsForm::Fanuc)) => {
                        own_g = true;
                        continue;
                    }
                    (NurbsForm::LinuxCnc, GCode::CurveEnd) => {
                        if let Some(other) = letters.present().find(|o| !"GN".contains(o.letter)) {
                            return Err((
                                other.col,
                                GcodeErrorKind::UnexpectedWord {
                                    letter: other.letter,
                                    context: "with G5.3 (it only closes the curve)".into(),
                                },
                            )
                                .into());
                        }
                        return Ok(true);
                    }
                    _ => {}
                }
            }
            return Err((w.col, curve.interrupted(by, curve.close_hint())).into());
        }
        if curve.form == NurbsForm::G38 && !own_g {
            return Err((
                first_col(words),
                GcodeErrorKind::NurbsInterrupted {
                    form: "G38",
                    start_line: curve.start_line,
                    by: "a block without G38".into(),
                    hint: " (every control point line starts with G38)",
                },
            )
                .into());
        }
        self.check_letters(
            letters,
            true,
            curve_letters(curve.form, false),
            curve.form.inside_name(),
        )?;
        let col = first_col(words);
        let has_axis = self.first_axis_word(letters)?.is_some();
        match curve.form {
            NurbsForm::LinuxCnc => {
                self.add_point(curve, letters, col)?;
                Ok(false)
            }
            NurbsForm::G38 => {
                let announced = curve.announced_points.unwrap_or(0);
                if curve.points.len() < announced {
                    self.add_point(curve, letters, col)?;
                    return Ok(curve.points.len() == announced && !curve.knots_given);
                }
                self.closing_knot(curve, letters, has_axis, col)
            }
            NurbsForm::Fanuc => {
                if has_axis || letters.get('R').is_some() {
                    if curve.closing_knots > 0 {
                        return Err((
                            col,
                            GcodeErrorKind::PointAfterClosingKnots {
                                form: curve.form.name(),
                            },
                        )
                            .into());
                    }
                    self.add_point(curve, letters, col)?;
                    return Ok(false);
                }
                self.closing_knot(curve, letters, has_axis, col)
            }
        }
    }

    /// A knot-only block; `true` once all `order` closing knots are in.
    fn closing_knot(
        &self,
        curve: &mut PendingCurve,
        letters: &Letters,
        has_axis: bool,
        col: usize,
    ) -> Step<bool> {
        if has_axis {
            return Err((
                col,
                GcodeErrorKind::PointAfterClosingKnots {
                    form: curve.form.name(),
                },
            )
                .into());
        }
        push_knot(curve, letters, col)?;
        curve.closing_knots += 1;
        Ok(curve.closing_knots == curve.order())
    }

    fn close_curve(&mut self, curve: PendingCurve) -> Step<Block> {
        let knots = if curve.form == NurbsForm::Fanuc || curve.knots_given {
            curve.knots
        } else {
            clamped_uniform_knots(curve.points.len(), curve.degree, curve.form)
        };
        let at = |kind: GcodeErrorKind| Fail {
            col: curve.start_col,
            kind,
            at: Some((curve.start_line, curve.start_text.clone())),
        };
        let nurbs = NurbsCurve::new(
            curve.degree,
            self.axes.len(),
            &curve.points,
            &curve.weights,
            knots,
        )
        .map_err(|e| at(e.into()))?;
        self.position = nurbs.end_point();
        self.modal.motion = None;
        Ok(Block {
            line: curve.start_line,
            kind: BlockKind::Nurbs { form: curve.form },
            curve: nurbs,
            feed_mm_per_min: curve.feed,
        })
    }
}

/// Knots for a curve whose program gives none: clamped and uniform, on `[0, 1]` for G38 (seed 000,
/// Table I) and on `[0, n - order + 2]` in whole numbers for G5.2 (LinuxCNC's convention).
fn clamped_uniform_knots(points: usize, degree: usize, form: NurbsForm) -> Vec<f64> {
    let mut knots = crate::geometry::clamped_uniform_knots(points, degree);
    if form == NurbsForm::LinuxCnc {
        let spans = (points.saturating_sub(degree + 1) + 1) as f64;
        // Whole numbers: scale, then round away the division's last-bit noise.
        knots.iter_mut().for_each(|k| *k = (*k * spans).round());
    }
    knots
}

/// Appends the block's `K` (which must be there) to the curve's knots, refusing a decrease.
fn push_knot(curve: &mut PendingCurve, letters: &Letters, col: usize) -> Step<()> {
    let k = letters.get('K').ok_or((
        col,
        GcodeErrorKind::MissingKnot {
            form: curve.form.name(),
        },
    ))?;
    if let Some(&previous) = curve.knots.last()
        && k.value < previous
    {
        return Err((
            k.col,
            GcodeErrorKind::KnotsDecreasing {
                value: k.value,
                previous,
            },
        )
            .into());
    }
    curve.knots.push(k.value);
    Ok(())
}

fn weight(w: Option<&Word>) -> Step<f64> {
    match w {
        None => Ok(1.0),
        Some(w) if w.value > 0.0 => Ok(w.value),
        Some(w) => Err((
            w.col,
            GcodeErrorKind::BadWeight {
                letter: w.letter,
                value: w.value,
            },
        )
            .into()),
    }
}

/// The word's value as a whole number in `[min, max]`.
fn whole(w: &Word, min: f64, max: f64) -> Step<f64> {
    if w.value.fract() != 0.0 {
        return Err((
            w.col,
            GcodeErrorKind::NotAWholeNumber {
                letter: w.letter,
                text: w.text.clone(),
            },
        )
            .into());
    }
    if w.value < min || w.value > max {
        return Err((
            w.col,
            GcodeErrorKind::OutOfRange {
                what: match w.letter {
                    'O' => "degree O",
                    'P' | 'L' => "order",
                    'C' => "control point count C",
                    'N' => "line number N",
                    _ => "value",
                },
                value: w.value,
                min,
                max,
            },
        )
            .into());
    }
    Ok(w.value)
}

fn first_col(words: &[Word]) -> usize {
    words.first().map_or(1, |w| w.col)
}

/// Words (besides G M N F S T and axes) allowed in a curve's first block or its later blocks.
fn curve_letters(form: NurbsForm, first: bool) -> &'static str {
    match (form, first) {
        (NurbsForm::G38, true) => "OCWK",
        (NurbsForm::G38, false) => "WK",
        (NurbsForm::Fanuc, true) => "PKRQ",
        (NurbsForm::Fanuc, false) => "KRQ",
        (NurbsForm::LinuxCnc, true) => "PL",
        (NurbsForm::LinuxCnc, false) => "P",
    }
}

/// Indexes the block's words by letter; G and M may repeat (checked later), others may not.
fn collect_letters(words: &[Word]) -> Step<Letters<'_>> {
    let mut by_letter: [Option<&Word>; 26] = [None; 26];
    for w in words {
        if matches!(w.letter, 'G' | 'M') {
            continue;
        }
        let slot = &mut by_letter[(w.letter as u8 - b'A') as usize];
        if slot.is_some() {
            return Err((w.col, GcodeErrorKind::RepeatedWord { letter: w.letter }).into());
        }
        *slot = Some(w);
    }
    Ok(Letters { by_letter })
}

impl<R: BufRead> Iterator for BlockReader<R> {
    type Item = Result<Block, GcodeError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        match self.next_block() {
            Ok(Some(b)) => Some(Ok(b)),
            Ok(None) => None,
            Err(e) => {
                self.done = true;
                Some(Err(e))
            }
        }
    }
}
