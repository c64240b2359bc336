//! The reader's parts, by how long what they hold lives (Grbl's `parser_state_t` against
//! `parser_block_t`):
//!
//! - [`InterpState`]: the interpreter's state, from block to block: the modal groups, the
//!   position, the work system and `G92` offsets, the parameters, the M-state (flushing, condition) and the
//!   stops waiting for the next motion.
//! - [`ProgramFlow`]: where reading is in the text: the lines, the O-word flow control and
//!   the structure check, and how the program ends.
//! - [`LineScratch`]: the line being read, rebuilt every line: its words, its assignments,
//!   its number and where it starts.
//! - [`Output`]: what is on its way out: the NURBS curve being collected.
//! - [`Diagnostics`]: the warnings, each given once.

use std::io::{BufRead, Seek};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use super::control::{Flow, SavedModes};
use super::cycles::CycleState;
use super::modal::Modal;
use super::nurbs::PendingCurve;
use super::structure::Structure;
use super::{Fail, MM_PER_INCH, Step};
use crate::gcode::error::GcodeErrorKind;
use crate::gcode::error::Warning;
use crate::gcode::expr::Params;
use crate::gcode::lexer::{Assign, Word};
use crate::gcode::lines::{LineSource, Pos};
use crate::gcode::work::WorkSystem;
use crate::gcode::{Block, Pause, Plane};
use crate::geometry::Point;

/// The interpreter's state: what one block leaves for the next.
pub(super) struct InterpState {
    pub modal: Modal,
    /// Machine position, mm (what a program point means: see [`super::offsets`]).
    pub position: Point,
    /// The active work system and its offset, mm (loaded from the table in the parameters
    /// when the system is selected or its entry set).
    pub system: WorkSystem,
    pub g5x: Point,
    /// G92 offset, mm: machine position = program position + g5x + g92.
    pub g92: Point,
    /// The offset G92.2 suspended, for G92.3.
    pub saved_g92: Option<Point>,
    pub params: Params,
    /// M7/M8 on, M9 off.
    pub flushing: bool,
    /// `E<number>` in force (0: none yet).
    pub condition: u32,
    /// G4 dwell (s) and M0/M1 pause waiting for the next motion.
    pub pending_dwell: f64,
    pub pending_pause: Option<(u64, Pause)>,
    /// The canned cycles' held words and levels.
    pub cycle: CycleState,
    /// The modes `M70`/`M73` saved, for `M72`.
    pub saved_modes: Option<SavedModes>,
    /// Some axis is not homed ([`crate::gcode::WorkStart::unhomed`]).
    pub unhomed: bool,
}

impl InterpState {
    /// Millimetres per program unit (`G20`: inches, `G21`: mm).
    pub fn scale(&self) -> f64 {
        if self.modal.inch { MM_PER_INCH } else { 1.0 }
    }

    /// Program point + this = machine point, mm.
    pub fn offset(&self) -> Point {
        self.g5x + self.g92
    }

    /// At the machine origin, in G54, G21 G90 G17 G94 with no motion mode and no feed.
    pub fn new() -> InterpState {
        InterpState {
            modal: Modal {
                inch: false,
                incremental: false,
                arc_centre_absolute: false,
                plane: Plane::XY,
                motion: None,
                feed: None,
                taper: 0.0,
                wire_offset: super::modal::WireOffsetMode::Off,
            },
            position: Point::zeros(),
            system: WorkSystem::G54,
            g5x: Point::zeros(),
            g92: Point::zeros(),
            saved_g92: None,
            params: Params::default(),
            flushing: false,
            condition: 0,
            pending_dwell: 0.0,
            pending_pause: None,
            cycle: CycleState::default(),
            saved_modes: None,
            unhomed: false,
        }
    }
}

/// Where reading is in the program's text, and how it ends.
pub(super) struct ProgramFlow<R> {
    pub lines: LineSource<R>,
    pub flow: Flow,
    /// The O-word structure of the text, checked once per line in file order.
    pub structure: Structure,
    /// The first line not yet shown to `structure`.
    pub scanned: Pos,
    /// Set by another thread to make the reader give up at its next line.
    pub cancel: Option<Arc<AtomicBool>>,
    pub ended_at: Option<u64>,
    /// The line of the `%` that closed the program (a tape mark after its first block).
    pub closed_at: Option<u64>,
    /// A block was read (a `%` alone is not one).
    pub saw_block: bool,
    pub saw_content: bool,
    pub done: bool,
}

impl<R: BufRead + Seek> ProgramFlow<R> {
    /// Reads on from `pos` (a loop's head, a subroutine's body, a return).
    pub fn seek(&mut self, pos: Pos) -> Step<()> {
        self.lines
            .seek(pos)
            .map_err(|e| Fail::from((1, GcodeErrorKind::Io(e))))
    }

    /// Another thread asked the reader to give up.
    pub fn cancelled(&self) -> Step<()> {
        match &self.cancel {
            Some(flag) if flag.load(Ordering::Relaxed) => {
                Err((1, GcodeErrorKind::Cancelled).into())
            }
            _ => Ok(()),
        }
    }
}

impl<R> ProgramFlow<R> {
    pub fn new(lines: LineSource<R>) -> ProgramFlow<R> {
        ProgramFlow {
            lines,
            flow: Flow::default(),
            structure: Structure::default(),
            scanned: Pos { offset: 0, line: 1 },
            cancel: None,
            ended_at: None,
            closed_at: None,
            saw_block: false,
            saw_content: false,
            done: false,
        }
    }
}

/// The line being read.
#[derive(Default)]
pub(super) struct LineScratch {
    pub words: Vec<Word>,
    pub assigns: Vec<Assign>,
    /// The line's number (for warnings raised deep in a block).
    pub line_no: u64,
    /// Byte offset where the line starts.
    pub line_start: u64,
    /// The line has `G53`: its move is in machine coordinates.
    pub machine_move: bool,
}

/// What is on its way out of the reader.
pub(super) struct Output {
    /// A NURBS curve being collected over several lines.
    pub pending: Option<PendingCurve>,
    /// The moves after the first of a block that makes several (a canned cycle, `G28`),
    /// handed out before the next line is read.
    pub queued: std::collections::VecDeque<Block>,
}

/// Warnings, each kind given once per program.
#[derive(Default)]
pub(super) struct Diagnostics {
    pub warnings: Vec<Warning>,
    pub warned_letters: Vec<char>,
    /// Warnings given once per program, by what they are about.
    pub warned_about: Vec<&'static str>,
    /// The machine builder's M-codes already said to do nothing.
    pub warned_vendor: Vec<u32>,
}

impl Diagnostics {
    /// A warning about `about`, the first time it comes up (at `line`, `col`).
    pub fn once_about(&mut self, line: u64, about: &'static str, col: usize, message: String) {
        if !self.warned_about.contains(&about) {
            self.warned_about.push(about);
            self.warnings.push(Warning { line, col, message });
        }
    }

    /// A warning about the word `w`'s letter, the first time it is met (at `line`).
    pub fn once_per_letter(&mut self, line: u64, w: &Word, message: &str) {
        if !self.warned_letters.contains(&w.letter) {
            self.warned_letters.push(w.letter);
            self.warnings.push(Warning {
                line,
                col: w.col,
                message: format!("{}{}: {message}", w.letter, w.text),
            });
        }
    }
}

impl InterpState {
    /// The modes `M70` saves.
    pub fn saved_modes(&self) -> SavedModes {
        SavedModes {
            inch: self.modal.inch,
            incremental: self.modal.incremental,
            arc_centre_absolute: self.modal.arc_centre_absolute,
            plane: self.modal.plane,
            feed: self.modal.feed,
            flushing: self.flushing,
            condition: self.condition,
            retract_to_initial: self.cycle.retract_to_initial,
            system: self.system,
        }
    }
}
