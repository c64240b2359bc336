//! The modal state of an RS274 controller and the blocks it turns into motion: G-code
//! words classified into their groups (motion, units, distance mode, arc centres, plane, and
//! the modes edmd is always in), M and feed words, and `G0`/`G1` lines. Arcs go to
//! [`super::arc`], NURBS curves to [`super::nurbs`].

use std::io::{BufRead, Seek};

use super::codes::{GCode, Motion, OffsetCode, Probing, g_codes};
use super::nurbs::curve_letters;
use super::{BlockReader, Fail, Letters, Step, first_col, whole, whole_as};
use crate::gcode::error::{GcodeErrorKind, Warning};
use crate::gcode::lexer::Word;
use crate::gcode::{Block, BlockKind, NurbsForm, Pause, Plane, VendorAction, WireOffset};
use crate::geometry::NurbsCurve;

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
            self.state.end_in_g54(&self.axes);
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
                self.axes.check_letters(
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
                self.axes.check_letters(letters, false, "", "with G80")?;
                None
            }
            Some((GCode::Motion(m), w)) => {
                if !matches!(m, Motion::Probe(Probing { one_shot: true, .. })) {
                    self.state.modal.motion = Some(m);
                }
                if self.axes.moves(m, letters)? {
                    self.motion_block(m, previous == Some(m), line_no, letters, w.col)?
                } else {
                    self.axes
                        .check_letters(letters, false, "", "without axis words")?;
                    None
                }
            }
            _ => match self.state.modal.motion {
                Some(m) if self.axes.moves(m, letters)? => {
                    self.motion_block(m, true, line_no, letters, first_col(words))?
                }
                Some(_) => {
                    self.axes
                        .check_letters(letters, false, "", "without axis words")?;
                    None
                }
                None => {
                    if let Some(w) = self.axes.first_word(letters)? {
                        return Err((w.col, GcodeErrorKind::NoMotionMode).into());
                    }
                    self.axes
                        .check_letters(letters, false, "", "without a motion word")?;
                    None
                }
            },
        })
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
                self.axes.check_letters(
                    letters,
                    true,
                    "",
                    if motion == Motion::Rapid {
                        "with G0"
                    } else {
                        "with G1"
                    },
                )?;
                let (target, _) =
                    self.state
                        .target_here(&self.axes, self.scratch.machine_move, letters)?;
                let feed = match motion {
                    Motion::Linear => {
                        self.state
                            .feed_limit(&mut self.diag, self.scratch.line_no, col)
                    }
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
                Ok(Some(self.state.block(line_no, kind, curve, feed)))
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
