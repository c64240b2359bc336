//! The modal state of an RS274 controller and the blocks it turns into motion: G-code
//! words classified into their groups (motion, units, distance mode, arc centres, plane, and
//! the modes edmd is always in), M and feed words, and `G0`/`G1` lines. Arcs go to
//! [`super::arc`], NURBS curves to [`super::nurbs`].

use std::io::{BufRead, Seek};

use super::codes::{GCode, Motion, OffsetCode, Probing, g_codes};
use super::nurbs::curve_letters;
use super::{BlockReader, Fail, Letters, MAX_COORD_MM, Step, first_col, whole, whole_as};
use crate::gcode::error::{GcodeErrorKind, Warning};
use crate::gcode::lexer::Word;
use crate::gcode::{Block, BlockKind, NurbsForm, Pause, Plane, VendorAction, WireOffset};
use crate::geometry::{NurbsCurve, Point};
use crate::vocab::Axis;

#[derive(Debug, Clone)]
pub(super) struct Modal {
    pub(super) inch: bool,
    pub(super) incremental: bool,
    pub(super) arc_centre_absolute: bool,
    pub(super) plane: Plane,
    pub(super) motion: Option<Motion>,
    /// mm/min
    pub(super) feed: Option<f64>,
    /// The wire's tilt (`G51`/`G52`): the tangent of its angle from vertical, + to the left
    /// of the direction of travel; 0: vertical (`G50`).
    pub(super) taper: f64,
    /// `G41`/`G42`/`G40`.
    pub(super) wire_offset: WireOffsetMode,
}

/// The wire offset as the program set it (`G41`/`G42`, `G40`) and where its moves stand. The
/// reader refuses what cannot happen under it (changing offsets, probing, a second `G41`);
/// every move carries the offset it is cut with ([`crate::gcode::Block::wire_offset`]) and
/// the path's wire-offset stage does the geometry.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(super) enum WireOffsetMode {
    #[default]
    Off,
    /// `G41`/`G42` given: the next move is the entry.
    Entry(WireOffset),
    On(WireOffset),
    /// `G40` given while on: the next move is the exit.
    Exit,
}

impl WireOffsetMode {
    /// The offset is on, or about to be, or its exit move is still to come.
    pub(super) fn engaged(self) -> bool {
        self != WireOffsetMode::Off
    }

    /// `G41` (`left`) or `G42` with offset `d_mm`, in `plane`, on a machine that has X and Y
    /// (`has_xy`). Errors are messages for the G word.
    pub(super) fn start(
        &mut self,
        left: bool,
        d_mm: f64,
        plane: Plane,
        has_xy: bool,
    ) -> Result<(), String> {
        if plane != Plane::XY {
            return Err("the wire offset works in the XY plane (G17) only".into());
        }
        if !has_xy {
            return Err("the wire offset needs axes X and Y on the machine".into());
        }
        if matches!(self, WireOffsetMode::On(_) | WireOffsetMode::Exit) {
            return Err("the wire offset is already on: cancel it with G40 first".into());
        }
        *self = if d_mm == 0.0 {
            WireOffsetMode::Off
        } else {
            WireOffsetMode::Entry(WireOffset { left, d_mm })
        };
        Ok(())
    }

    /// `G40`.
    pub(super) fn cancel(&mut self) {
        *self = match *self {
            WireOffsetMode::Off | WireOffsetMode::Entry(_) => WireOffsetMode::Off,
            WireOffsetMode::On(_) | WireOffsetMode::Exit => WireOffsetMode::Exit,
        };
    }

    /// A move was read: the offset it is cut with; the entry and the exit move the mode on.
    pub(super) fn stamp_move(&mut self) -> Option<WireOffset> {
        match *self {
            WireOffsetMode::Off => None,
            WireOffsetMode::Entry(w) | WireOffsetMode::On(w) => {
                *self = WireOffsetMode::On(w);
                Some(w)
            }
            WireOffsetMode::Exit => {
                *self = WireOffsetMode::Off;
                None
            }
        }
    }
}

impl<R: BufRead + Seek> BlockReader<R> {
    pub(super) fn start_block(
        &mut self,
        line_no: u64,
        text: &str,
        letters: &Letters,
        words: &[Word],
    ) -> Step<Option<Block>> {
        let codes = g_codes(words)?;
        let mut kept = *letters;
        // M98 takes P (the subprogram) and L (the count).
        let m98 = words.iter().find(|w| w.letter == 'M' && w.value == 98.0);
        let m98 = match m98 {
            Some(m) => {
                let call = letters_p_l(letters, m)?;
                kept = kept.without(&['P', 'L']);
                // An error about the count points at L, any other at M98.
                let count_col = letters.get('L').map_or(m.col, |l| l.col);
                Some((m.col, count_col, call))
            }
            None => None,
        };
        let later = self.apply_g_codes(&codes, &mut kept)?;
        let motion_word = later.motion;
        if let (Some((_, _, r)), Some((_, m))) = (later.reference, motion_word) {
            return Err((
                m.col,
                GcodeErrorKind::ConflictingG {
                    a: r.text.to_string(),
                    b: m.text.to_string(),
                },
            )
                .into());
        }
        if let Some((code, w)) = later.offset {
            if let Some((_, m)) = motion_word {
                return Err((
                    m.col,
                    GcodeErrorKind::ConflictingG {
                        a: w.text.to_string(),
                        b: m.text.to_string(),
                    },
                )
                    .into());
            }
            self.coordinate_offset(code, w, &kept)?;
            let axis_letters: Vec<char> = self.axes.iter().map(|a| a.letter()).collect();
            kept = kept.without(&axis_letters);
            if code == OffsetCode::Table {
                kept = kept.without(&['L', 'P', 'R']);
            }
        }
        if let Some(g53) = later.machine {
            let motion = match motion_word {
                Some((GCode::Motion(m), _)) => Some(m),
                Some(_) => None,
                None => self.state.modal.motion,
            };
            self.check_machine_move(g53, matches!(motion, Some(Motion::Rapid | Motion::Linear)))?;
        }
        self.scratch.machine_move = later.machine.is_some();
        let letters = &kept;
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
        let MWords {
            program_end,
            pause,
            m99,
        } = self.m_codes(line_no, words)?;
        self.condition_and_feed(line_no, letters)?;

        let block = match later.reference {
            Some((g30, store, w)) => self.reference_point(g30, store, w, line_no, letters),
            None => self.motion_of(motion_word, line_no, text, letters, words),
        };
        self.scratch.machine_move = false;
        let block = block?;
        if program_end {
            self.program.ended_at = Some(line_no);
            self.end_in_g54();
        }
        if let Some(p) = pause {
            self.state.pending_pause = Some((line_no, p));
        }
        if let Some((col, count_col, (number, count))) = m98 {
            self.call_fanuc(number, count, col, count_col)?;
        }
        if let Some(col) = m99 {
            self.return_fanuc(col)?;
        }
        Ok(block)
    }

    /// The M words of a block: program end, pauses, flushing, a subprogram return.
    fn m_codes(&mut self, line_no: u64, words: &[Word]) -> Step<MWords> {
        let mut program_end = false;
        let mut pause = None;
        let mut m99 = None;
        for w in words.iter().filter(|w| w.letter == 'M') {
            let code = whole(w, 0.0, 9999.0)? as u32;
            match code {
                2 | 30 => program_end = true,
                0 => pause = Some(Pause::Program),
                1 if self.options.optional_stop => pause = Some(Pause::Optional),
                1 => self.diag.once_about(
                    self.scratch.line_no,
                    "M1 off",
                    w.col,
                    "M1 (optional stop) does not pause: program.optional_stop is off".into(),
                ),
                7 | 8 => self.state.flushing = true,
                9 => self.state.flushing = false,
                3..=6 => self.diag.once_per_letter(
                    line_no,
                    w,
                    "spindle and tool change words (M3-M6) do nothing on an EDM and are ignored",
                ),
                98 => {}
                99 => m99 = Some(w.col),
                70..=73 => self.modal_state_code(code, w.col)?,
                _ if self.options.mcodes.iter().any(|m| m.number == code) => {
                    if let Some(p) = self.vendor_m(code, w)? {
                        pause = Some(p);
                    }
                }
                _ => {
                    return Err((
                        w.col,
                        GcodeErrorKind::UnknownM {
                            code: w.text.to_string(),
                        },
                    )
                        .into());
                }
            }
        }
        Ok(MWords {
            program_end,
            pause,
            m99,
        })
    }

    /// A machine builder's M-code (`[[program.mcode]]`): its action; a pause to wait for.
    fn vendor_m(&mut self, code: u32, w: &Word) -> Step<Option<Pause>> {
        let action = self
            .options
            .mcodes
            .iter()
            .find(|m| m.number == code)
            .map(|m| m.action.clone());
        let line = self.scratch.line_no;
        match action {
            Some(VendorAction::Flush(on)) => self.state.flushing = on,
            Some(VendorAction::Condition(n)) => self.state.condition = n,
            Some(VendorAction::Pause(message)) => {
                self.diag.warnings.push(Warning {
                    line,
                    col: w.col,
                    message: format!("message: M{code}: {message}"),
                });
                return Ok(Some(Pause::Program));
            }
            Some(VendorAction::Ignore(why)) if !self.diag.warned_vendor.contains(&code) => {
                self.diag.warned_vendor.push(code);
                self.diag.warnings.push(Warning {
                    line,
                    col: w.col,
                    message: format!("M{code} does nothing here: {why}"),
                });
            }
            Some(VendorAction::Ignore(_)) | None => {}
        }
        Ok(None)
    }

    /// The words that set state beside motion: `S`/`T` (ignored, with a warning), the
    /// machining condition `E` and the feed `F`.
    fn condition_and_feed(&mut self, line_no: u64, letters: &Letters) -> Step<()> {
        for letter in ['S', 'T'] {
            if let Some(w) = letters.get(letter) {
                self.diag.once_per_letter(
                    line_no,
                    w,
                    "spindle speed (S) and tool (T) words do nothing on an EDM and are ignored",
                );
            }
        }
        if let Some(e) = letters.get('E') {
            let n = whole(e, 0.0, 999.0)? as u32;
            if !self.options.conditions.contains(&n) {
                let defined: Vec<String> = self
                    .options
                    .conditions
                    .iter()
                    .map(|c| format!("E{c}"))
                    .collect();
                return Err((
                    e.col,
                    GcodeErrorKind::Control(format!(
                        "E{}: no such machining condition (generator.condition defines {})",
                        e.text,
                        if defined.is_empty() {
                            "none".to_string()
                        } else {
                            defined.join(", ")
                        }
                    )),
                )
                    .into());
            }
            self.state.condition = n;
        }
        if let Some(f) = letters.get('F') {
            // The lexer only yields finite numbers, so this also covers the sign.
            if f.value * self.state.scale() < crate::vocab::MIN_FEED_MM_PER_MIN {
                return Err((f.col, GcodeErrorKind::BadFeed).into());
            }
            self.state.modal.feed = Some(f.value * self.state.scale());
        }
        Ok(())
    }

    /// The block's motion: the motion word's, or the modal motion's when axis words ask for
    /// it, or none.
    fn motion_of(
        &mut self,
        motion_word: Option<(GCode, &Word)>,
        line_no: u64,
        text: &str,
        letters: &Letters,
        words: &[Word],
    ) -> Step<Option<Block>> {
        let previous = self.state.modal.motion;
        Ok(match motion_word {
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
                self.state.modal.motion = None;
                self.state.cycle.initial_level = None;
                self.check_letters(letters, false, "", "with G80")?;
                None
            }
            Some((GCode::Motion(m), w)) => {
                if !matches!(m, Motion::Probe(Probing { one_shot: true, .. })) {
                    self.state.modal.motion = Some(m);
                }
                if self.moves(m, letters)? {
                    self.motion_block(m, previous == Some(m), line_no, letters, w.col)?
                } else {
                    self.check_letters(letters, false, "", "without axis words")?;
                    None
                }
            }
            _ => match self.state.modal.motion {
                Some(m) if self.moves(m, letters)? => {
                    self.motion_block(m, true, line_no, letters, first_col(words))?
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
        })
    }

    /// A motion block, taking the dwell and pause waiting for it.
    pub(super) fn block(
        &mut self,
        line: u64,
        kind: BlockKind,
        curve: NurbsCurve,
        feed: Option<f64>,
    ) -> Block {
        let mut block = Block::new(line, kind, curve, feed);
        block.dwell_s = std::mem::take(&mut self.state.pending_dwell);
        block.pause = self.state.pending_pause.take();
        block.flushing = self.state.flushing;
        block.condition = self.state.condition;
        block
    }

    /// A dwell or pause that no motion follows: said once, as it changes nothing.
    pub(super) fn trailing_stops(&mut self) {
        if self.state.pending_dwell > 0.0 || self.state.pending_pause.is_some() {
            let line = self
                .state
                .pending_pause
                .map_or(self.scratch.line_no, |(l, _)| l);
            self.diag.warnings.push(Warning {
                line,
                col: 1,
                message: "a dwell or stop after the last motion does nothing".into(),
            });
            self.state.pending_dwell = 0.0;
            self.state.pending_pause = None;
        }
    }

    /// Whether a block in motion mode `m` moves: it has axis words, or, for an arc, a centre
    /// or radius (a full circle needs no axis words). A bare `G1` only sets the mode.
    pub(super) fn moves(&self, m: Motion, letters: &Letters) -> Step<bool> {
        if self.first_axis_word(letters)?.is_some() {
            return Ok(true);
        }
        let arc_words = matches!(m, Motion::Cw | Motion::Ccw)
            && ['I', 'J', 'K', 'R']
                .iter()
                .any(|&l| letters.get(l).is_some());
        Ok(arc_words)
    }

    pub(super) fn axes_list(&self) -> String {
        self.axes
            .iter()
            .map(|a| a.letter().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The axis a word names: `Some` for one of the machine's axes, `None` for a letter that is
    /// no axis, an error for an axis letter the machine does not have.
    pub(super) fn machine_axis(&self, w: &Word) -> Step<Option<Axis>> {
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
    pub(super) fn first_axis_word<'w>(&self, letters: &Letters<'w>) -> Step<Option<&'w Word>> {
        let mut first: Option<&Word> = None;
        for w in letters.present() {
            let polar = matches!(w.letter, '@' | '^');
            if (polar || self.machine_axis(w)?.is_some()) && first.is_none_or(|f| w.col < f.col) {
                first = Some(w);
            }
        }
        Ok(first)
    }

    /// Rejects any word outside G M N F S T, `extra`, and (with `allow_axes`) the machine's
    /// axes. An axis letter the machine does not have is reported as such either way.
    pub(super) fn check_letters(
        &self,
        letters: &Letters,
        allow_axes: bool,
        extra: &str,
        context: &str,
    ) -> Step<()> {
        self.check_letters_with(letters, allow_axes, &|c| extra.contains(c), &|| {
            context.to_string()
        })
    }

    /// [`check_letters`](Self::check_letters) with the form's own letters as a test and the
    /// error's context made only for an error: an arc's context names its plane, and writing
    /// it for every arc block cost a tenth of reading one.
    pub(super) fn check_letters_with(
        &self,
        letters: &Letters,
        allow_axes: bool,
        extra: &dyn Fn(char) -> bool,
        context: &dyn Fn() -> String,
    ) -> Step<()> {
        for w in letters.present() {
            if extra(w.letter) || "GMNFSTE".contains(w.letter) {
                continue; // a form's own word (G38's C) wins over an axis letter
            }
            if allow_axes && (matches!(w.letter, '@' | '^') || self.machine_axis(w)?.is_some()) {
                continue;
            }
            return Err((
                w.col,
                GcodeErrorKind::UnexpectedWord {
                    letter: w.letter,
                    context: context(),
                },
            )
                .into());
        }
        Ok(())
    }

    /// The point reached from `base` by the block's axis words (absolute or incremental),
    /// and whether any axis word was present. Letters in `reserved` are not axis words here.
    pub(super) fn target(
        &self,
        base: &Point,
        letters: &Letters,
        reserved: &str,
    ) -> Step<(Point, bool)> {
        let mut p = *base;
        let mut any = false;
        // A G53 move names machine coordinates.
        let offset = if self.scratch.machine_move {
            Point::zeros()
        } else {
            self.state.offset()
        };
        for (i, axis) in self.axes.iter().enumerate() {
            if reserved.contains(axis.letter()) {
                continue;
            }
            if let Some(w) = letters.get(axis.letter()) {
                let v = w.value * self.state.scale();
                p[i] = if self.state.modal.incremental {
                    base[i] + v
                } else {
                    v + offset[i]
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
        let frame = super::polar::PolarFrame {
            axes: &self.axes,
            offset: self.state.offset(),
            scale: self.state.scale(),
            incremental: self.state.modal.incremental,
            machine_move: self.scratch.machine_move,
        };
        let polar = super::polar::polar_end(&frame, base, letters)?;
        if let Some(([ix, iy], [x, y])) = polar {
            p[ix] = x;
            p[iy] = y;
            any = true;
        }
        Ok((p, any))
    }

    /// The programmed feed for a feed move. On an EDM the gap servo sets the advance speed and
    /// `F` is only an upper limit, so a program without one (seed 000's G38 example) is valid:
    /// it runs at up to the machine maximum, and the operator is told once.
    pub(super) fn feed_limit(&mut self, col: usize) -> Option<f64> {
        if self.state.modal.feed.is_none() {
            self.diag.once_about(
                self.scratch.line_no,
                "no feed",
                col,
                "feed move without a programmed F: it runs at up to machine.max_feed_mm_per_min, as the gap servo allows".into(),
            );
        }
        self.state.modal.feed
    }

    /// The block's motion in mode `motion`; `continuing`: the mode was already in force (a
    /// canned cycle's words hold).
    pub(super) fn motion_block(
        &mut self,
        motion: Motion,
        continuing: bool,
        line_no: u64,
        letters: &Letters,
        col: usize,
    ) -> Step<Option<Block>> {
        if !matches!(motion, Motion::Cycle(_)) {
            // Any other motion ends a series of cycles (LinuxCNC's `cycle_il_flag`).
            self.state.cycle.initial_level = None;
        }
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
                let (target, _) = self.target(&self.state.position, letters, "")?;
                let feed = match motion {
                    Motion::Linear => self.feed_limit(col),
                    _ => None,
                };
                if target == self.state.position {
                    return Ok(None);
                }
                let curve = NurbsCurve::line(self.axes.len(), &self.state.position, &target)
                    .map_err(|e| Fail::from((col, e.into())))?;
                self.state.position = target;
                let kind = if motion == Motion::Rapid {
                    BlockKind::Rapid
                } else {
                    BlockKind::Line
                };
                Ok(Some(self.block(line_no, kind, curve, feed)))
            }
            Motion::Cw | Motion::Ccw => {
                self.arc_block(motion == Motion::Ccw, line_no, letters, col)
            }
            Motion::Probe(p) => self.probe_block(p.probe, line_no, letters, col),
            Motion::QuadSpline => self.quad_spline(line_no, letters, col).map(Some),
            Motion::Cycle(c) => self.cycle_block(c, continuing, line_no, letters, col),
        }
    }
}

/// M98's subprogram number (P) and count (L, default 1).
fn letters_p_l(letters: &Letters, m: &Word) -> Step<(u32, u64)> {
    let Some(p) = letters.get('P') else {
        return Err((
            m.col,
            GcodeErrorKind::MissingCoordinate {
                what: "M98 needs P, the subprogram number".into(),
            },
        )
            .into());
    };
    let number = whole_as(p, 0.0, 99_999_999.0, "M98's subprogram number P")? as u32;
    let count = match letters.get('L') {
        Some(l) => whole_as(l, 0.0, 1e9, "M98's repeat count L")? as u64,
        None => 1,
    };
    Ok((number, count))
}

/// What a block's M words ask for after its motion.
struct MWords {
    program_end: bool,
    pause: Option<Pause>,
    m99: Option<usize>,
}
