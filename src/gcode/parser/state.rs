//! The reader's parts, by how long what they hold lives (Grbl's `parser_state_t` against
//! `parser_block_t`):
//!
//! - [`InterpState`]: the interpreter's state, from block to block: the modal groups, the
//!   position, the work system and `G92` offsets, the parameters, the M-state (flushing, condition) and the
//!   stops waiting for the next motion. What needs only it is its own: a block's target and
//!   feed, the block itself, the work systems (their parameter numbers in [`super::offsets`]).
//! - [`ProgramFlow`]: where reading is in the text: the lines, the O-word flow control and
//!   the structure check (fed here, line by line), and how the program ends.
//! - [`LineScratch`]: the line being read, rebuilt every line: its words, its assignments,
//!   its number and where it starts.
//! - [`Diagnostics`]: the warnings, each given once.
//! - [`BlockEnv`]: the axes, the warnings and the line, lent for one block to the forms (an
//!   arc, a curve, a canned cycle) that change the state.

use std::io::{BufRead, Seek};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use super::axes::MachineAxes;
use super::control::{Flow, SavedModes};
use super::modes::Modal;
use super::params::{ACTIVE_SYSTEM, PARAM_AXES, PROBE_PARAMS, param_slot, table_param};
use super::structure::Structure;
use super::{Fail, Letters, MAX_COORD_MM, MM_PER_INCH, Step};
use crate::gcode::error::GcodeErrorKind;
use crate::gcode::error::Warning;
use crate::gcode::expr::{ParamRef, Params};
use crate::gcode::lexer::{Assign, Word, oword_of};
use crate::gcode::lines::{Line, LineSource, Pos};
use crate::gcode::work::{WorkOffsets, WorkStart, WorkSystem};
use crate::gcode::{Block, BlockKind, Pause, Plane, ProgramOptions};
use crate::geometry::{NurbsCurve, Point};
use crate::vocab::Axis;

/// What the canned cycles keep from block to block.
#[derive(Debug, Clone, Default)]
pub(super) struct CycleState {
    /// `G98`: out to the initial level after a hole; `G99` (false, the default): to R.
    pub retract_to_initial: bool,
    /// The Z (machine, mm) the series of cycles started at; cleared by any other motion.
    pub initial_level: Option<f64>,
    /// The last cycle's `R`, `Z`, `P` and `Q`, as written (program units).
    pub r: f64,
    pub z: f64,
    pub p: f64,
    pub q: f64,
}

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
                wire_offset: super::modes::WireOffsetMode::Off,
            },
            position: Point::zeros(),
            system: WorkSystem::G54,
            g5x: Point::zeros(),
            g92: Point::zeros(),
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

/// The structure check, fed as the reader meets lines ([`super::structure`]).
impl<R: BufRead + Seek> ProgramFlow<R> {
    /// Shows `text`, line `line_no` starting at byte `start`, to the structure check if the
    /// reader meets it for the first time (loops and calls read lines again; the check sees
    /// each line once, in file order). `block_delete`: a `/` line is deleted, not checked.
    pub fn note_structure(
        &mut self,
        start: u64,
        line_no: u64,
        text: &str,
        block_delete: bool,
    ) -> Step<()> {
        if start < self.scanned.offset {
            return Ok(());
        }
        self.scanned = self.lines.position();
        if block_delete && text.trim_start().starts_with('/') {
            return Ok(());
        }
        match oword_of(text) {
            Some(o) => self
                .structure
                .note(&o, line_no)
                .map_err(|(col, message)| Fail {
                    col,
                    kind: GcodeErrorKind::Control(message),
                    at: Some((line_no, text.to_string())),
                }),
            None => Ok(()),
        }
    }

    /// After the program's end (`M2`/`M30`), the lines the flow never reached are still part
    /// of the program's text (subroutines live there): their structure is checked up to the
    /// end of the file or a closing `%`.
    pub fn scan_to_the_end(&mut self, block_delete: bool) -> Step<()> {
        if self.closed_at.is_some() {
            return Ok(());
        }
        let io = |e| Fail::from((1, GcodeErrorKind::Io(e)));
        if self.lines.position().offset < self.scanned.offset {
            self.lines.seek(self.scanned).map_err(io)?;
        }
        loop {
            self.cancelled()?;
            let start = self.lines.position().offset;
            let Some((line_no, line)) = self.lines.next_line().map_err(io)? else {
                return Ok(());
            };
            let Line::Text(text) = line else { continue };
            if text.trim_start().starts_with('%') {
                return Ok(());
            }
            let text = text.to_string();
            self.note_structure(start, line_no, &text, block_delete)?;
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
    /// The line being read, its room kept from line to line.
    pub text: String,
    pub words: Vec<Word>,
    pub assigns: Vec<Assign>,
    /// The line's number (for warnings raised deep in a block).
    pub line_no: u64,
    /// Byte offset where the line starts.
    pub line_start: u64,
    /// The line has `G53`: its move is in machine coordinates.
    pub machine_move: bool,
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

/// What a block's form (an arc, a curve, a canned cycle) reads of the reader besides the
/// interpreter's state it changes: the machine's axes, the warnings and the line being read.
/// The reader lends it for one block, so each form is a function of the state and this, not
/// a method of the reader.
pub(super) struct BlockEnv<'r> {
    pub options: &'r ProgramOptions,
    pub axes: &'r MachineAxes,
    pub diag: &'r mut Diagnostics,
    pub line: &'r LineScratch,
}

impl BlockEnv<'_> {
    /// [`InterpState::target`] for this line (a `G53` line's in machine coordinates).
    pub fn target(
        &self,
        state: &InterpState,
        base: &Point,
        letters: &Letters,
        reserved: &str,
    ) -> Step<(Point, bool)> {
        state.target(self.axes, self.line.machine_move, base, letters, reserved)
    }

    /// [`InterpState::target_here`] for this line: from where the machine stands.
    pub fn target_here(&self, state: &InterpState, letters: &Letters) -> Step<(Point, bool)> {
        state.target_here(self.axes, self.line.machine_move, letters)
    }

    /// [`InterpState::feed_limit`], its warning given at this line.
    pub fn feed_limit(&mut self, state: &InterpState, col: usize) -> Option<f64> {
        state.feed_limit(self.diag, self.line.line_no, col)
    }

    /// A warning about `about` at this line, the first time it comes up.
    pub fn warn_once(&mut self, about: &'static str, col: usize, message: String) {
        self.diag.once_about(self.line.line_no, about, col, message);
    }
}

/// What the state makes of a block: its target, its feed, the block itself.
impl InterpState {
    /// A motion block, taking the dwell and pause waiting for it.
    pub fn block(
        &mut self,
        line: u64,
        kind: BlockKind,
        curve: NurbsCurve,
        feed: Option<f64>,
    ) -> Block {
        let mut block = Block::new(line, kind, curve, feed);
        block.dwell_s = std::mem::take(&mut self.pending_dwell);
        block.pause = self.pending_pause.take();
        block.flushing = self.flushing;
        block.condition = self.condition;
        block
    }

    /// The point reached from `base` by the block's axis words for `axes` (absolute or
    /// incremental; `machine_move`: a `G53` line's, in machine coordinates), and whether any
    /// axis word was present. Letters in `reserved` are not axis words here.
    pub fn target(
        &self,
        axes: &[Axis],
        machine_move: bool,
        base: &Point,
        letters: &Letters,
        reserved: &str,
    ) -> Step<(Point, bool)> {
        let mut p = *base;
        let mut any = false;
        // A G53 move names machine coordinates.
        let offset = if machine_move {
            Point::zeros()
        } else {
            self.offset()
        };
        for (i, axis) in axes.iter().enumerate() {
            if reserved.contains(axis.letter()) {
                continue;
            }
            if let Some(w) = letters.get(axis.letter()) {
                let v = w.value * self.scale();
                p[i] = if self.modal.incremental {
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
            axes,
            offset: self.offset(),
            scale: self.scale(),
            incremental: self.modal.incremental,
            machine_move,
        };
        let polar = super::polar::polar_end(&frame, base, letters)?;
        if let Some(([ix, iy], [x, y])) = polar {
            p[ix] = x;
            p[iy] = y;
            any = true;
        }
        Ok((p, any))
    }

    /// [`target`](Self::target) from where the machine stands, every axis word an axis.
    pub fn target_here(
        &self,
        axes: &[Axis],
        machine_move: bool,
        letters: &Letters,
    ) -> Step<(Point, bool)> {
        self.target(axes, machine_move, &self.position, letters, "")
    }

    /// The programmed feed for a feed move. On an EDM the gap servo sets the advance speed and
    /// `F` is only an upper limit, so a program without one (seed 000's G38 example) is valid:
    /// it runs at up to the machine maximum, and the operator is told once (in `diag`, at
    /// `line`).
    pub fn feed_limit(&self, diag: &mut Diagnostics, line: u64, col: usize) -> Option<f64> {
        if self.modal.feed.is_none() {
            diag.once_about(
                line,
                "no feed",
                col,
                "feed move without a programmed F: it runs at up to machine.max_feed_mm_per_min, as the gap servo allows".into(),
            );
        }
        self.modal.feed
    }
}

impl InterpState {
    /// The modes `M70` saves.
    pub fn saved_modes(&self) -> SavedModes {
        SavedModes {
            g92_applied: self.g92_applied(),
            offset_off: !self.modal.wire_offset.engaged(),
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

/// The work offsets are the state's: the table lives in its parameters.
impl InterpState {
    /// `system`'s offset as its parameters hold it, mm.
    pub(super) fn table_entry(&self, axes: &[Axis], system: WorkSystem) -> Point {
        let mut offset = Point::zeros();
        for (i, &axis) in axes.iter().enumerate() {
            offset[i] = self.params.numbered(table_param(system, param_slot(axis)));
        }
        offset
    }

    /// Makes `system` active, loading its offset from the table.
    pub(super) fn load_system(&mut self, axes: &[Axis], system: WorkSystem) {
        self.system = system;
        self.g5x = self.table_entry(axes, system);
        self.params.set(
            &ParamRef::Numbered(ACTIVE_SYSTEM),
            f64::from(system.number()),
        );
    }

    /// `G54`…`G59.3`: selecting another system loads its offset (the machine does not move;
    /// the program's coordinates of where it stands change). Selecting the active one again
    /// does nothing, as in LinuxCNC (a table parameter assigned since is not reloaded).
    pub(super) fn select_system(
        &mut self,
        axes: &[Axis],
        system: WorkSystem,
        w: &Word,
    ) -> Step<()> {
        if self.modal.wire_offset.engaged() {
            return Err((
                w.col,
                GcodeErrorKind::WorkOffset(format!(
                    "G{}: the work system cannot change with the wire offset on (G40 first)",
                    w.text
                )),
            )
                .into());
        }
        if system != self.system {
            self.load_system(axes, system);
        }
        Ok(())
    }

    /// `M72` (and a return from a call that gave `M73`): the modes `saved` back, the work
    /// system selected as by its G word (`col`: where to point an error).
    pub(super) fn restore_modes(
        &mut self,
        axes: &[Axis],
        saved: SavedModes,
        col: usize,
    ) -> Step<()> {
        if saved.system != self.system {
            if self.modal.wire_offset.engaged() {
                return Err((
                    col,
                    GcodeErrorKind::WorkOffset(
                        "the restored modes change the work system, which cannot change with \
                         the wire offset on (G40 first)"
                            .into(),
                    ),
                )
                    .into());
            }
            self.load_system(axes, saved.system);
        }
        // LinuxCNC's restore ends cutter compensation begun since the save (as a G40 line:
        // the last offset move ends at its own offset point), then sets the G92 offset
        // applied or not as it was (G92.3 or G92.2).
        if saved.offset_off {
            self.modal.wire_offset.cancel();
        }
        if saved.g92_applied != self.g92_applied() {
            self.apply_g92(axes, saved.g92_applied);
        }
        let modal = &mut self.modal;
        modal.inch = saved.inch;
        modal.incremental = saved.incremental;
        modal.arc_centre_absolute = saved.arc_centre_absolute;
        modal.plane = saved.plane;
        modal.feed = saved.feed;
        self.flushing = saved.flushing;
        self.condition = saved.condition;
        self.cycle.retract_to_initial = saved.retract_to_initial;
        Ok(())
    }

    /// A program end (`M2`/`M30`) returns to `G54`, as LinuxCNC's does.
    pub(super) fn end_in_g54(&mut self, axes: &[Axis]) {
        if self.system != WorkSystem::G54 {
            self.load_system(axes, WorkSystem::G54);
        }
    }

    /// The program's coordinates of the machine point `machine`, mm.
    pub(super) fn program_point(&self, machine: &Point) -> Point {
        machine - self.g5x - self.g92
    }
}

impl InterpState {
    /// Starts the program at `start`: the machine position, the work offsets (written to
    /// their parameters for `axes`), the active system, the units and distance mode.
    pub(super) fn start_at(&mut self, axes: &[Axis], start: &WorkStart) {
        self.position = start.position_mm;
        for system in WorkSystem::all() {
            let offset = start.offsets.get(system);
            for (i, &axis) in axes.iter().enumerate() {
                let p = table_param(system, param_slot(axis));
                self.params.set(&ParamRef::Numbered(p), offset[i]);
            }
        }
        self.load_system(axes, start.system);
        self.unhomed = start.unhomed;
        self.modal.inch = start.modes.inch;
        self.modal.incremental = start.modes.incremental;
    }

    /// The work offsets as the program has left them (`G10` changes them), mm.
    pub(super) fn work_offsets(&self, axes: &[Axis]) -> WorkOffsets {
        let mut table = WorkOffsets::default();
        for system in WorkSystem::all() {
            table.set(system, self.table_entry(axes, system));
        }
        table
    }

    /// A probing move ended at `at` (mm, machine axes; with `contact`, or at its end point
    /// without): the program goes on from there. LinuxCNC's `#5061`… (`X Y Z A B C U V W`,
    /// program coordinates) hold the point and `#5070` is 1 with contact, 0 without.
    pub(super) fn probed(&mut self, axes: &[Axis], at: &Point, contact: bool) {
        self.position = *at;
        let scale = self.scale();
        let program = self.program_point(at);
        for (i, axis) in axes.iter().enumerate() {
            if let Some(k) = PARAM_AXES.iter().position(|&l| l == axis.letter()) {
                let v = program[i] / scale;
                self.params.set(&ParamRef::Numbered(PROBE_PARAMS + k), v);
            }
        }
        self.params.set(
            &ParamRef::Numbered(PROBE_PARAMS + 9),
            if contact { 1.0 } else { 0.0 },
        );
    }
}
