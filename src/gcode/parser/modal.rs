//! A block's dispatch: its G codes applied in order to the modal groups ([`super::modes`];
//! classified by [`super::codes`]), its M and feed words, then its motion: `G0`/`G1` lines
//! here; arcs to [`super::arc`], NURBS curves to [`super::nurbs`], canned cycles to
//! [`super::cycles`], the offsets' codes, `G28`/`G30` and probing to [`super::offsets`]. Those
//! are functions of the interpreter's state and the [`super::state::BlockEnv`] lent for the
//! block.

use std::io::{BufRead, Seek};

use super::arc::arc_block;
use super::axes::MachineAxes;
use super::codes::{GCode, LaterCodes, Motion, OffsetCode, Probing, g_codes};
use super::cycles::{MoveList, cycle_moves};
use super::nurbs::{PendingCurve, curve_letters, quad_spline};
use super::offsets::{check_machine_move, coordinate_offset, probe_block, reference_point};
use super::state::{BlockEnv, InterpState};
use super::{BlockReader, Fail, Letters, Step, first_col, whole, whole_as};
use crate::gcode::error::{GcodeErrorKind, OPERATOR_MESSAGE, Warning};
use crate::gcode::lexer::Word;
use crate::gcode::{Block, BlockKind, NurbsForm, Pause, VendorAction};
use crate::geometry::NurbsCurve;
use crate::vocab::Axis;

impl<R: BufRead + Seek> BlockReader<R> {
    /// The interpreter's state and what a block's form reads beside it, lent for one block.
    fn form_parts(&mut self) -> (&mut InterpState, BlockEnv<'_>) {
        let env = BlockEnv {
            options: &self.options,
            axes: &self.axes,
            diag: &mut self.diag,
            line: &self.scratch,
        };
        (&mut self.state, env)
    }

    /// A line of the open curve `curve`: its block once the line closes it.
    pub(super) fn curve_line(
        &mut self,
        mut curve: PendingCurve,
        letters: &Letters,
        words: &[Word],
    ) -> Step<Option<Block>> {
        let (state, mut env) = self.form_parts();
        if curve.take_line(state, &mut env, letters, words)? {
            return curve.close(state, env.axes).map(Some);
        }
        self.out.pending = Some(curve);
        Ok(None)
    }

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
        let state_codes = self.modal_state_first(words)?;
        let (state, mut env) = self.form_parts();
        let later = apply_g_codes(state, &mut env, &codes, &mut kept)?;
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
            coordinate_offset(&mut self.state, &self.axes, code, w, &kept)?;
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
            let straight = matches!(motion, Some(Motion::Rapid | Motion::Linear));
            check_machine_move(&self.state, g53, straight)?;
        }
        self.scratch.machine_move = later.machine.is_some();
        let letters = &kept;
        if let Some(o) = letters.get('O')
            && !matches!(motion_word, Some((GCode::Curve(NurbsForm::G38), _)))
        {
            // Fanuc's program number (`O1000`) stands alone on its line.
            if words.iter().all(|w| matches!(w.letter, 'O' | 'N')) {
                // Any whole number, as LinuxCNC reads it (posts write six digits and more).
                whole(o, 0.0, f64::from(u32::MAX))?;
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
        self.condition_and_feed(line_no, &state_codes.feed_words(letters))?;
        self.modal_state_last(state_codes, letters);

        let block = match later.reference {
            Some((g30, store, w)) => {
                let (state, mut env) = self.form_parts();
                reference_point(state, &mut env, g30, store, w, line_no, letters)
                    .map(|moves| self.out.emit_all(&mut self.state, moves))
            }
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
                // Done before the G codes (start_block).
                70..=73 => {}
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
                    message: format!("{OPERATOR_MESSAGE}M{code}: {message}"),
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
                let (state, mut env) = self.form_parts();
                let curve = PendingCurve::open(state, &mut env, form, text, w, letters)?;
                self.out.pending = Some(curve);
                None
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
                let (state, mut env) = self.form_parts();
                arc_block(
                    state,
                    &mut env,
                    motion == Motion::Ccw,
                    line_no,
                    letters,
                    col,
                )
                .map(Some)
            }
            Motion::Probe(p) => {
                let (state, mut env) = self.form_parts();
                probe_block(state, &mut env, p.probe, line_no, letters, col)
            }
            Motion::QuadSpline => {
                let (state, mut env) = self.form_parts();
                quad_spline(state, &mut env, line_no, letters, col).map(Some)
            }
            Motion::Cycle(c) => {
                let at = self.state.position;
                let room = self.out.take_room();
                let moves = MoveList::new(at, line_no, self.axes.len(), room);
                let (state, mut env) = self.form_parts();
                let moves = cycle_moves(state, &mut env, c, continuing, letters, col, moves)?;
                Ok(self.out.emit_all(&mut self.state, moves))
            }
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

/// Longest dwell accepted, s (a P in milliseconds by mistake is caught well before a day).
const MAX_DWELL_S: f64 = 86_400.0;
/// Steepest taper accepted (degrees from vertical).
const MAX_TAPER_DEG: f64 = 30.0;

/// Takes the G codes of a block in order: the modal groups they set, a dwell, the wire
/// offset, the work system; returns the words that act later (motion, offset, `G53`).
pub(super) fn apply_g_codes<'w>(
    state: &mut InterpState,
    env: &mut BlockEnv,
    codes: &[(GCode, &'w Word)],
    kept: &mut Letters<'w>,
) -> Step<LaterCodes<'w>> {
    let mut later = LaterCodes::default();
    for &(code, w) in codes {
        match code {
            GCode::Dwell => {
                let Some(p) = kept.get('P') else {
                    return Err((
                        w.col,
                        GcodeErrorKind::MissingCoordinate {
                            what: "G4 needs P, the dwell in seconds".into(),
                        },
                    )
                        .into());
                };
                if !(0.0..=MAX_DWELL_S).contains(&p.value) {
                    return Err((
                        p.col,
                        GcodeErrorKind::OutOfRange {
                            what: "dwell P (s)",
                            value: p.value,
                            min: 0.0,
                            max: MAX_DWELL_S,
                        },
                    )
                        .into());
                }
                state.pending_dwell += p.value;
                *kept = kept.without(&['P']);
            }
            GCode::Offset(o) => later.offset = Some((o, w)),
            GCode::MachineCoords => later.machine = Some(w),
            GCode::Reference { g30, store } => later.reference = Some((g30, store, w)),
            GCode::Retract { initial_level } => {
                state.cycle.retract_to_initial = initial_level;
            }
            GCode::WorkSystem(system) => state.select_system(env.axes, system, w)?,
            GCode::CompOff => state.modal.wire_offset.cancel(),
            GCode::Comp { left } => {
                let d = wire_offset(&env.options.d_mm, w, kept)?;
                *kept = kept.without(&['D', 'H']);
                let plane = state.modal.plane;
                let has_xy = env.axes.contains(&Axis::X) && env.axes.contains(&Axis::Y);
                state
                    .modal
                    .wire_offset
                    .start(left, d, plane, has_xy)
                    .map_err(|m| Fail::from((w.col, GcodeErrorKind::WireOffset(m))))?;
            }
            GCode::TaperOff => state.modal.taper = 0.0,
            GCode::Taper { left } => {
                state.modal.taper = taper_angle(env.axes, w, kept.get('A'), left)?;
                *kept = kept.without(&['A']);
            }
            GCode::Inch(inch) => state.modal.inch = inch,
            GCode::Incremental(inc) => state.modal.incremental = inc,
            GCode::ArcCentreAbsolute(abs) => state.modal.arc_centre_absolute = abs,
            GCode::Plane(p) => state.modal.plane = p,
            GCode::Accepted(_) => {}
            GCode::Ignored {
                takes,
                only_with_words,
                why,
                ..
            } => {
                let with_words = takes.iter().any(|&l| kept.get(l).is_some());
                *kept = kept.without(takes);
                if with_words || !only_with_words {
                    env.warn_once(why, w.col, why.to_string());
                }
            }
            GCode::SpindleMode => env.warn_once(
                "spindle mode",
                w.col,
                format!(
                    "G{}: spindle speed modes (G96/G97) do nothing on an EDM and are ignored",
                    w.text
                ),
            ),
            GCode::Motion(_) | GCode::MotionCancel | GCode::Curve(_) | GCode::CurveEnd => {
                later.motion = Some((code, w));
            }
        }
    }
    Ok(later)
}

/// The tilt `A` gives `G51`/`G52`, as the signed tangent of the angle (+: to the left of
/// the direction of travel), on a machine that can tilt the wire.
fn taper_angle(axes: &MachineAxes, g: &Word, a: Option<&Word>, left: bool) -> Step<f64> {
    let fail = |col, message: String| Fail::from((col, GcodeErrorKind::Taper(message)));
    let has = |axis| axes.contains(&axis);
    if !(has(Axis::X) && has(Axis::Y) && has(Axis::U) && has(Axis::V)) {
        return Err(fail(
            g.col,
            format!(
                "G{} tilts the wire with the upper guide: it needs the axes X, Y, U and V \
                 (machine.axes has {})",
                g.text,
                axes.list()
            ),
        ));
    }
    let Some(a) = a else {
        return Err(fail(
            g.col,
            format!(
                "G{} needs A, the wire's angle from vertical in degrees",
                g.text
            ),
        ));
    };
    if !(0.0..=MAX_TAPER_DEG).contains(&a.value) {
        return Err(fail(
            a.col,
            format!(
                "A{}: the taper angle is 0 to {MAX_TAPER_DEG} degrees (G51 tilts left of \
                 the direction of travel, G52 right)",
                a.text
            ),
        ));
    }
    let tan = a.value.to_radians().tan();
    Ok(if left { tan } else { -tan })
}

/// The wire offset `G41`/`G42` (the word `g`) asks for: the register its `D` names, or its
/// `H` as the Fanuc-style wire controls write it (`G41 H01`; the same registers,
/// `compensation.d_mm`).
fn wire_offset(registers: &[f64], g: &Word, letters: &Letters) -> Step<f64> {
    let fail = |col: usize, what: String| Fail::from((col, GcodeErrorKind::WireOffset(what)));
    let register = match (letters.get('D'), letters.get('H')) {
        (Some(d), None) => d,
        (None, Some(h)) => h,
        (Some(_), Some(h)) => {
            return Err(fail(
                h.col,
                format!(
                    "G{}: D and H both name the offset register; give one",
                    g.text
                ),
            ));
        }
        (None, None) => {
            return Err(fail(
                g.col,
                format!(
                    "G{} needs D (or H, as Fanuc-style wire programs write it), the offset \
                     register (compensation.d_mm)",
                    g.text
                ),
            ));
        }
    };
    let k = whole(register, 0.0, 99.0)? as usize;
    registers.get(k).copied().ok_or_else(|| {
        fail(
            register.col,
            format!(
                "{}{k} is not set: compensation.d_mm has registers 0 to {}",
                register.letter,
                registers.len() - 1
            ),
        )
    })
}
