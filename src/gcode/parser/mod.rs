//! The modal G-code interpreter: lines in, [`Block`]s out, one at a time.
//!
//! This file is the reader's loop: pull a line ([`super::lines`]), lex it
//! ([`super::lexer`]), index its words by letter, then hand the block to the modal
//! interpreter ([`modal`]: units, distance mode, plane, feed, lines; the `G` words are
//! classified by [`codes`]), which passes arcs to [`arc`], NURBS curves to [`nurbs`] (the
//! three dialects, collected over several lines until they close) and canned cycles to
//! [`cycles`]. Those forms are functions of the interpreter's state and what the reader lends
//! them for the block ([`state::BlockEnv`]), not methods of the reader. Every failure is a
//! [`Fail`] (column and kind) that the loop locates (`file:line:col` and the line's text)
//! before it leaves the reader.

mod arc;
mod axes;
mod codes;
mod control;
mod cycles;
mod modal;
mod modes;
mod nurbs;
mod offsets;
mod params;
mod polar;
mod state;
mod structure;
mod system;

use std::io::{BufRead, Seek};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use super::error::{GcodeError, GcodeErrorKind, OPERATOR_MESSAGE, Warning};
use super::lexer::{Word, lex, program_number_of};
use super::lines::{Line, LineSource, MAX_LINE_BYTES};
use super::work::{StartModes, WorkOffsets, WorkStart, WorkSystem};
use super::{Block, ProgramOptions};
use crate::geometry::Point;
use crate::vocab::Axis;
use axes::MachineAxes;
use nurbs::PendingCurve;
use state::{Diagnostics, InterpState, LineScratch, ProgramFlow};
use system::ReaderEnv;

pub use arc::ARC_RADIUS_TOLERANCE_MM;
pub use control::MAX_CALL_DEPTH;

/// Most control points in one NURBS curve: a curve is held whole until it closes.
pub const MAX_CURVE_POINTS: usize = 100_000;
/// How close the first control point of a curve must be to the current position, mm.
pub const CURVE_START_TOLERANCE_MM: f64 = 0.0005;
pub(super) const MM_PER_INCH: f64 = 25.4;
/// Largest coordinate magnitude accepted, mm.
pub(super) const MAX_COORD_MM: f64 = 1.0e6;

/// A failure inside the interpreter, before the location is attached. `at` is `None` for the
/// current line, or another line (the start of a curve) with its text.
pub(super) struct Fail {
    pub(super) col: usize,
    pub(super) kind: GcodeErrorKind,
    pub(super) at: Option<(u64, String)>,
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

pub(super) type Step<T> = Result<T, Fail>;

/// The words of one block, looked up by letter (`A`…`Z`, then the polar `@` and `^`).
#[derive(Clone, Copy)]
pub(super) struct Letters<'w> {
    by_letter: [Option<&'w Word>; 28],
}

/// The slot of a word letter in [`Letters`].
fn letter_slot(letter: char) -> usize {
    match letter {
        '@' => 26,
        '^' => 27,
        _ => (letter as u8 - b'A') as usize,
    }
}

impl<'w> Letters<'w> {
    /// The same words but `drop`: words a code consumed (G64's `P`/`Q`, G43's `H`).
    pub(super) fn without(mut self, drop: &[char]) -> Letters<'w> {
        for &letter in drop {
            self.by_letter[letter_slot(letter)] = None;
        }
        self
    }

    pub(super) fn get(&self, letter: char) -> Option<&'w Word> {
        self.by_letter[letter_slot(letter)]
    }

    pub(super) fn present(&self) -> impl Iterator<Item = &'w Word> + '_ {
        self.by_letter.iter().flatten().copied()
    }
}

/// What is on its way out of the reader.
struct Output {
    /// A NURBS curve being collected over several lines.
    pending: Option<PendingCurve>,
    /// The moves after the first of a block that makes several (a canned cycle, `G28`),
    /// handed out before the next line is read.
    queued: std::collections::VecDeque<Block>,
    /// The room a block that makes several moves makes them in, kept from one such block to
    /// the next: a canned cycle's holes cost no allocation of their own.
    room: Vec<Block>,
}

impl Output {
    /// The first of `blocks` (with the dwell and pause waiting in `state` for a motion), the
    /// others queued behind it.
    fn emit_all(&mut self, state: &mut InterpState, mut blocks: Vec<Block>) -> Option<Block> {
        let first = {
            let mut made = blocks.drain(..);
            let first = made.next().map(|first| {
                state.block(first.line, first.kind, first.curve, first.feed_mm_per_min)
            });
            if let Some(first) = &first {
                for mut b in made {
                    b.flushing = first.flushing;
                    b.condition = first.condition;
                    self.queued.push_back(b);
                }
            }
            first
        };
        self.room = blocks;
        first
    }

    /// The room to make a block's moves in (see [`Output::room`]).
    pub(super) fn take_room(&mut self) -> Vec<Block> {
        std::mem::take(&mut self.room)
    }
}

/// Reads a program one block at a time. See the module docs of [`crate::gcode`].
pub struct BlockReader<R> {
    options: ProgramOptions,
    source_name: Arc<str>,
    axes: MachineAxes,
    state: InterpState,
    program: ProgramFlow<R>,
    scratch: LineScratch,
    out: Output,
    diag: Diagnostics,
}

impl<R: BufRead + Seek> BlockReader<R> {
    /// A reader for a machine with `axes`, starting at the machine origin, in G21 G90 G17 G94
    /// with no motion mode and no feed. `source_name` prefixes every error (`file:line:col`).
    pub fn new(reader: R, source_name: &str, axes: &[Axis]) -> Self {
        Self::with_options(reader, source_name, axes, ProgramOptions::default())
    }

    /// [`BlockReader::new`] with the `[program]` options (block delete, optional stop, loop
    /// limit).
    pub fn with_options(
        reader: R,
        source_name: &str,
        axes: &[Axis],
        options: ProgramOptions,
    ) -> Self {
        let mut reader = Self {
            options,
            source_name: source_name.into(),
            axes: MachineAxes::new(axes),
            state: InterpState::new(),
            program: ProgramFlow::new(LineSource::new(reader)),
            scratch: LineScratch::default(),
            out: Output {
                pending: None,
                queued: Default::default(),
                room: Vec::new(),
            },
            diag: Diagnostics::default(),
        };
        // G54 is active from the start, and `#5220` says so (LinuxCNC: 1).
        reader
            .state
            .load_system(&reader.axes, crate::gcode::work::WorkSystem::G54);
        reader
    }

    /// Makes the reader give up, with [`GcodeErrorKind::Cancelled`], at the first line it
    /// reads after `flag` is set: however long the program runs between blocks (loops that
    /// move nothing), a cancel is seen within one line.
    pub fn cancel_on(&mut self, flag: Arc<AtomicBool>) {
        self.program.cancel = Some(flag);
    }

    /// Takes the warnings collected so far.
    pub fn take_warnings(&mut self) -> Vec<Warning> {
        std::mem::take(&mut self.diag.warnings)
    }

    /// Current position in mm, machine axis order.
    pub fn position(&self) -> Point {
        self.state.position
    }

    /// The options the program is read with.
    pub fn options(&self) -> &ProgramOptions {
        &self.options
    }

    /// The machine's axes, in the order every point is in.
    pub fn axes(&self) -> &[Axis] {
        &self.axes
    }

    /// The line of the M2/M30 that ended the program, if one did.
    pub fn program_end_line(&self) -> Option<u64> {
        self.program.ended_at
    }

    /// Starts the program at `start`: the machine position, the work offsets (written to their
    /// parameters) and the active system. Call before the first block is read.
    pub fn start_at(&mut self, start: &WorkStart) {
        self.state.start_at(&self.axes, start);
    }

    /// The units and distance mode in force now (for the next MDI line).
    pub fn modes(&self) -> StartModes {
        StartModes {
            inch: self.state.modal.inch,
            incremental: self.state.modal.incremental,
        }
    }

    /// The work offsets as the program has left them (`G10` changes them), mm.
    pub fn work_offsets(&self) -> WorkOffsets {
        self.state.work_offsets(&self.axes)
    }

    /// The active work system.
    pub fn work_system(&self) -> WorkSystem {
        self.state.system
    }

    /// The probing move just read ended at `at` (mm, machine axes; with `contact`, or at its
    /// end point without): the program goes on from there (`#5061`… hold the point, `#5070`
    /// whether it touched).
    pub fn probed(&mut self, at: &Point, contact: bool) {
        self.state.probed(&self.axes, at, contact);
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
            called_from: self.program.flow.call_lines(),
        }
    }

    fn next_block(&mut self) -> Result<Option<Block>, GcodeError> {
        loop {
            if let Some(mut block) = self.out.queued.pop_front() {
                // Never under the wire offset: the block's codes refuse it.
                block.taper = self.state.modal.taper;
                return Ok(Some(block));
            }
            if self.program.done {
                return Ok(None);
            }
            if let Err(fail) = self.program.cancelled() {
                return Err(self.error(self.scratch.line_no, "", fail));
            }
            self.scratch.line_start = self.program.lines.position().offset;
            let next = self.program.lines.next_line().map_err(|e| GcodeError {
                source_name: self.source_name.clone(),
                line: 0,
                col: 0,
                kind: GcodeErrorKind::Io(e),
                text: String::new(),
                called_from: None,
            })?;
            let Some((line_no, line)) = next else {
                self.finish()?;
                continue;
            };
            let mut latin1_at = None;
            // The line's text in the room the last line's was in: a line costs no
            // allocation of its own.
            let mut text = std::mem::take(&mut self.scratch.text);
            text.clear();
            match line {
                Line::Text(t) => text.push_str(t),
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
                Line::BadUtf8 {
                    valid_prefix,
                    bytes,
                } => {
                    // Not UTF-8: read as Latin-1 (one character per byte), which is what an
                    // older editor saved. Accepted inside comments only; anywhere else it is
                    // an error at that column.
                    text.extend(bytes.iter().map(|&b| char::from(b)));
                    match non_ascii_outside_comments(&text) {
                        None => latin1_at = Some(valid_prefix.chars().count() + 1),
                        Some(col) => {
                            let shown = valid_prefix.to_string();
                            return Err(self.error(
                                line_no,
                                &shown,
                                (col, GcodeErrorKind::InvalidUtf8).into(),
                            ));
                        }
                    }
                }
            }
            if let Err(fail) = self.program.note_structure(
                self.scratch.line_start,
                line_no,
                &text,
                self.options.block_delete,
            ) {
                return Err(self.error(line_no, &text, fail));
            }
            if let Some(col) = latin1_at {
                self.scratch.line_no = line_no;
                self.diag.once_about(
                    self.scratch.line_no,
                    "latin1",
                    col,
                    "a comment is not UTF-8: read as Latin-1 (comments only)".to_string(),
                );
            }
            let mut words = std::mem::take(&mut self.scratch.words);
            let result = self.process_line(line_no, &text, &mut words);
            self.scratch.words = words;
            let made = match result {
                Ok(made) => made,
                Err(fail) => return Err(self.error(line_no, &text, fail)),
            };
            self.scratch.text = text;
            match made {
                Some(mut block) => {
                    block.taper = self.state.modal.taper;
                    block.wire_offset = self.state.modal.wire_offset.stamp_move();
                    return Ok(Some(block));
                }
                None if self.program.done => self.finish()?,
                None => {}
            }
        }
    }

    /// An error about a move read earlier, at `line` column 1, with the calls the reader is
    /// in now (the path's stages find what is wrong with a move a few moves later).
    pub fn error_at_line(&self, line: u64, kind: GcodeErrorKind) -> GcodeError {
        let fail = Fail {
            col: 1,
            kind,
            at: Some((line, String::new())),
        };
        self.error(line, "", fail)
    }

    fn finish(&mut self) -> Result<(), GcodeError> {
        self.program.done = true;
        if self.state.modal.wire_offset.engaged() {
            self.diag.warnings.push(Warning {
                line: self.scratch.line_no,
                col: 1,
                message: "the program ends with the wire offset on (no G40 exit move)".into(),
            });
        }
        if let Err(fail) = self.program.scan_to_the_end(self.options.block_delete) {
            return Err(self.error(0, "", fail));
        }
        if let Some((line, message)) = self.program.structure.unclosed() {
            let fail = Fail {
                col: 1,
                kind: GcodeErrorKind::Control(message),
                at: Some((line, String::new())),
            };
            return Err(self.error(0, "", fail));
        }
        if self.program.ended_at.is_none()
            && let Some(fail) = self.program.flow.unclosed()
        {
            return Err(self.error(0, "", fail));
        }
        if let Some(p) = &self.out.pending {
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
        if !self.program.saw_content {
            return Err(self.error(1, "", (1, GcodeErrorKind::EmptyProgram).into()));
        }
        self.trailing_stops();
        if self.program.ended_at.is_none() && self.program.closed_at.is_none() {
            self.diag.warnings.push(Warning {
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
        self.scratch.line_no = line_no;
        if self.program.flow.skip.is_some() && !self.skip_line(text)? {
            return Ok(None);
        }
        let mut assigns = std::mem::take(&mut self.scratch.assigns);
        let lexed = lex(text, words, &mut assigns, &ReaderEnv::of(self)).map_err(Fail::from);
        let info = match lexed {
            Ok(info) => info,
            Err(e) => {
                self.scratch.assigns = assigns;
                return Err(e);
            }
        };
        if info.block_delete.is_some() && self.options.block_delete {
            self.scratch.assigns = assigns;
            return Ok(None);
        }
        for a in assigns.drain(..) {
            self.state.params.set(&a.target, a.value);
        }
        self.scratch.assigns = assigns;
        if let Some((col, message)) = info.message {
            self.diag.warnings.push(Warning {
                line: line_no,
                col,
                message: format!("{OPERATOR_MESSAGE}{message}"),
            });
        }
        if let Some(o) = info.oword {
            self.program.saw_content = true;
            if self.program.ended_at.is_some() || self.program.closed_at.is_some() {
                return self.after_end(line_no, text, o.col);
            }
            if let Some(p) = &self.out.pending {
                let by = format!("{} {}", o.label, o.keyword.name());
                return Err((o.col, p.interrupted(by, p.close_hint())).into());
            }
            self.program.saw_block = true;
            self.statement(text, o)?;
            return Ok(None);
        }
        if words.is_empty() && info.percent.is_none() {
            return Ok(None);
        }
        self.program.saw_content = true;
        if self.program.ended_at.is_some() && words.is_empty() {
            return Ok(None); // a closing `%`
        }
        if self.program.ended_at.is_some() || self.program.closed_at.is_some() {
            return self.after_end(line_no, text, words.first().map_or(1, |w| w.col));
        }
        if words.is_empty() {
            // A tape mark: the opening one before the first block, the closing one after.
            if self.program.saw_block {
                self.program.closed_at = Some(line_no);
            }
            return Ok(None);
        }
        if self.program.saw_block
            && self.out.pending.is_none()
            && let Some(n) = program_number_of(text)
        {
            // A Fanuc subprogram in the flow (the main program did not end before it).
            self.fanuc_definition(n);
            return Ok(None);
        }
        self.program.saw_block = true;
        let letters = collect_letters(words)?;
        if let Some(n) = letters.get('N') {
            whole(n, 0.0, 1e9)?;
        }
        if let Some(curve) = self.out.pending.take() {
            return self.curve_line(curve, &letters, words);
        }
        self.start_block(line_no, text, &letters, words)
    }
}

impl<R: BufRead + Seek> BlockReader<R> {
    /// A line after the program's end (M2/M30 or the closing `%`): ignored with a warning,
    /// and reading stops, as LinuxCNC and Fanuc do. Subprograms there are found by their calls.
    fn after_end(&mut self, line_no: u64, text: &str, col: usize) -> Step<Option<Block>> {
        let message = match (self.program.ended_at, self.program.closed_at) {
            (Some(end_line), _) => {
                format!("text after the program end (M2/M30 at line {end_line}) is ignored")
            }
            (None, Some(closed)) => {
                format!("text after the closing `%` (line {closed}) is ignored")
            }
            (None, None) => return Ok(None),
        };
        self.program.done = true;
        if program_number_of(text).is_some() {
            // Fanuc subprograms follow the main program's M30: not "ignored text".
            return Ok(None);
        }
        self.diag.warnings.push(Warning {
            line: line_no,
            col,
            message,
        });
        Ok(None)
    }
}

/// The word's value as a whole number in `[min, max]`.
pub(super) fn whole(w: &Word, min: f64, max: f64) -> Step<f64> {
    let what = match w.letter {
        'O' => "degree O",
        'P' | 'L' => "order",
        'C' => "control point count C",
        'N' => "line number N",
        _ => "value",
    };
    whole_as(w, min, max, what)
}

/// [`whole`], the value named `what` in the error.
pub(super) fn whole_as(w: &Word, min: f64, max: f64, what: &'static str) -> Step<f64> {
    if w.value.fract() != 0.0 {
        return Err((
            w.col,
            GcodeErrorKind::NotAWholeNumber {
                letter: w.letter,
                text: w.text.to_string(),
            },
        )
            .into());
    }
    if w.value < min || w.value > max {
        return Err((
            w.col,
            GcodeErrorKind::OutOfRange {
                what,
                value: w.value,
                min,
                max,
            },
        )
            .into());
    }
    Ok(w.value)
}

pub(super) fn first_col(words: &[Word]) -> usize {
    words.first().map_or(1, |w| w.col)
}

/// Indexes the block's words by letter; G and M may repeat (checked later), others may not.
pub(super) fn collect_letters(words: &[Word]) -> Step<Letters<'_>> {
    let mut by_letter: [Option<&Word>; 28] = [None; 28];
    for w in words {
        if matches!(w.letter, 'G' | 'M') {
            continue;
        }
        let slot = &mut by_letter[letter_slot(w.letter)];
        if slot.is_some() {
            return Err((w.col, GcodeErrorKind::RepeatedWord { letter: w.letter }).into());
        }
        *slot = Some(w);
    }
    Ok(Letters { by_letter })
}

/// The column of the first non-ASCII character outside `( … )` and `;` comments, if any.
fn non_ascii_outside_comments(line: &str) -> Option<usize> {
    let mut in_comment = false;
    for (i, c) in line.chars().enumerate() {
        match c {
            '(' if !in_comment => in_comment = true,
            ')' if in_comment => in_comment = false,
            ';' if !in_comment => return None,
            c if !c.is_ascii() && !in_comment => return Some(i + 1),
            _ => {}
        }
    }
    None
}

impl<R: BufRead + Seek> Iterator for BlockReader<R> {
    type Item = Result<Block, GcodeError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.program.done && self.out.queued.is_empty() {
            return None;
        }
        match self.next_block() {
            Ok(Some(b)) => Some(Ok(b)),
            Ok(None) => None,
            Err(e) => {
                self.program.done = true;
                Some(Err(e))
            }
        }
    }
}
