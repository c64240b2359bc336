//! Program flow: O-word subroutines and control structures, and Fanuc `M98`/`M99`
//! subprograms, without ever holding the program in memory.
//!
//! The reader is a streaming interpreter. Every construct that goes back (a loop, a call, a
//! return) **seeks** in the file to a line position it noted ([`Pos`]: byte offset and line
//! number); every construct that goes forward over lines it must not execute (a false `if`, a
//! subroutine body met in the main flow, a `break`) **skips**: it reads lines looking only at
//! their O-word ([`super::super::lexer::oword_of`]), evaluating nothing. So memory holds the
//! labels of subroutines (name → body position), the call stack and the loop stack, never the
//! lines, and a program of any length loops in constant memory.
//!
//! A subroutine may be defined before or after its call, or after `M2`/`M30` (Fanuc programs
//! put their subprograms there): a call to a label not seen yet scans ahead from the call,
//! noting every definition it passes, and seeks back. `#1`…`#30` carry the call's arguments
//! and are restored on return; named parameters without `_` are local to the call
//! ([`super::super::expr::Params`]). `M98 P<n> L<k>` runs the subprogram `O<n>` (up to its
//! `M99`) k times in the caller's scope, as Fanuc does.
//!
//! Guards: the whole program runs at most `max_loop_iterations` loop iterations and
//! subroutine calls **in all** (each run of a loop's body, each `call`, each run of an
//! `M98 … L` subprogram counts one), so nested loops multiply into the budget instead of
//! each passing its own limit (two nested `repeat [1000000]` would be 10^12 runs); a
//! `repeat` or `M98 L` asking for more than the whole budget is refused before its first run;
//! calls nest at most [`MAX_CALL_DEPTH`] deep (a recursion that never ends). Because the flow
//! depends only on the program's text and its parameters, replaying a program from its start
//! reaches the same line in the same loop iteration and call: that is how a checkpoint inside
//! a subroutine resumes (the interpreter state is rebuilt by the replay, never guessed).

mod args;
mod loops;

use std::collections::HashMap;
use std::io::{BufRead, Seek};

use crate::gcode::parser::system::ReaderEnv;

use super::{BlockReader, Fail, Letters, Step};
use crate::gcode::error::GcodeErrorKind;
use crate::gcode::expr::{ARGUMENTS, ParamRef};
use crate::gcode::lexer::Word;
use crate::gcode::lexer::{Keyword, Label, OWord, has_m99, oword_of, program_number_of};
use crate::gcode::lines::{Line, Pos};
use loops::{Loop, LoopKind, LoopLine};
mod saves;
pub(super) use saves::{SavedModes, StateCodes};

/// Deepest nesting of subroutine calls.
pub const MAX_CALL_DEPTH: usize = 64;

/// How a subroutine was entered.
#[derive(Debug, Clone)]
pub(super) enum CallKind {
    /// `o<name> call`: a new parameter scope, whose saved arguments are kept here.
    OWord {
        label: Label,
        saved: Box<[f64; ARGUMENTS]>,
    },
    /// `M98 P<n> L<k>`: the caller's scope, `remaining` more runs of the body at `body`.
    Fanuc { remaining: u64, body: Pos },
}

#[derive(Debug, Clone)]
pub(super) struct Frame {
    kind: CallKind,
    return_to: Pos,
    pub(super) call_line: u64,
    loops: usize,
    ifs: usize,
    /// The modes `M70` or `M73` saved in this call: each call level has its own, as in
    /// LinuxCNC (an `M72` restores only what its own level saved).
    pub(super) saved: Option<SavedModes>,
    /// `M73` asked for them back when the call returns.
    pub(super) restore_on_return: bool,
}

/// Why lines are being skipped, and what ends the skip.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Purpose {
    /// A false `if`/`elseif`: the next `elseif`, `else` or `endif` of the label.
    FalseIf,
    /// A taken branch is done: the `endif`.
    IfDone,
    /// A subroutine body met in the main flow: its `endsub`.
    SubBody,
    /// `break` or a false `while`/`repeat`: the loop's end line, then on after it.
    LoopExit,
    /// `continue` in a `do` loop: its closing `while`, which is then evaluated.
    DoContinue,
    /// A Fanuc subprogram met in the main flow: its `M99`.
    FanucBody,
}

#[derive(Debug, Clone)]
pub(super) struct Skip {
    label: Option<Label>,
    purpose: Purpose,
    /// The line that started the skip, for "never closed".
    from_line: u64,
    what: &'static str,
}

/// The flow state: labels seen, calls and loops in progress, the skip in progress.
#[derive(Debug, Default, Clone)]
pub(super) struct Flow {
    subs: HashMap<Label, Pos>,
    fanuc_subs: HashMap<u32, Pos>,
    pub(super) frames: Vec<Frame>,
    loops: Vec<Loop>,
    ifs: Vec<(Label, u64)>,
    pub(super) skip: Option<Skip>,
    /// A `while` loop going round: its label and iterations so far.
    reenter: Option<(Label, u64)>,
    /// Loop iterations and calls run so far, against `max_loop_iterations`.
    spent: u64,
}

impl Flow {
    /// Lines of the calls in progress, innermost first; `None` in the main program.
    #[allow(clippy::box_collection)]
    pub(super) fn call_lines(&self) -> Option<Box<Vec<u64>>> {
        (!self.frames.is_empty())
            .then(|| Box::new(self.frames.iter().rev().map(|f| f.call_line).collect()))
    }

    /// Skips lines until `what` closes the construct `label` opened at `from_line`.
    fn start_skip(
        &mut self,
        label: Option<Label>,
        purpose: Purpose,
        what: &'static str,
        from_line: u64,
    ) {
        self.skip = Some(Skip {
            label,
            purpose,
            from_line,
            what,
        });
    }

    /// The end of the file was reached inside a construct: it was never closed. (A program
    /// that ends with M2/M30 inside one is fine: nothing after M2 runs.)
    pub(super) fn unclosed(&self) -> Option<Fail> {
        let open = |label: &Label, line: u64, what: &str| Fail {
            col: 1,
            kind: control(format!(
                "{label} at line {line} is never closed: {what} expected before the end of the file"
            )),
            at: Some((line, String::new())),
        };
        if let Some(frame) = self.frames.last() {
            let what = match &frame.kind {
                CallKind::OWord { label, .. } => format!("{label} endsub"),
                CallKind::Fanuc { .. } => "M99".to_string(),
            };
            return Some(Fail {
                col: 1,
                kind: control(format!(
                    "the subroutine called at line {} has no end: {what} expected",
                    frame.call_line
                )),
                at: Some((frame.call_line, String::new())),
            });
        }
        if let Some(l) = self.loops.last() {
            let what = match l.kind {
                LoopKind::While { .. } => "endwhile",
                LoopKind::Do { .. } => "while",
                LoopKind::Repeat { .. } => "endrepeat",
            };
            return Some(open(&l.label, l.line, what));
        }
        if let Some((label, line)) = self.ifs.last() {
            return Some(open(label, *line, "endif"));
        }
        let skip = self.skip.as_ref()?;
        let label = skip
            .label
            .as_ref()
            .map_or_else(|| "the subprogram".to_string(), |l| l.to_string());
        Some(Fail {
            col: 1,
            kind: control(format!(
                "{label} at line {} is never closed: {} expected",
                skip.from_line, skip.what
            )),
            at: Some((skip.from_line, String::new())),
        })
    }

    /// One more run of a loop's body or of a subroutine (`what` names it for the error):
    /// spent from the program's budget.
    fn spend(&mut self, limit: u64, what: impl FnOnce() -> String) -> Step<()> {
        self.spent += 1;
        if self.spent > limit {
            return Err(Fail {
                col: 1,
                kind: GcodeErrorKind::FlowBudget { at: what(), limit },
                at: None,
            });
        }
        Ok(())
    }

    fn check_depth(&self, col: usize) -> Step<()> {
        if self.frames.len() >= MAX_CALL_DEPTH {
            return Err((
                col,
                GcodeErrorKind::CallDepth {
                    limit: MAX_CALL_DEPTH,
                },
            )
                .into());
        }
        Ok(())
    }

    fn push_frame(&mut self, kind: CallKind, return_to: Pos, call_line: u64) {
        let frame = Frame {
            kind,
            return_to,
            call_line,
            loops: self.loops.len(),
            ifs: self.ifs.len(),
            saved: None,
            restore_on_return: false,
        };
        self.frames.push(frame);
    }
}

fn control(msg: String) -> GcodeErrorKind {
    GcodeErrorKind::Control(msg)
}

impl<R: BufRead + Seek> BlockReader<R> {
    /// A line read while skipping: `true` if the skip ended on it and the line is to be
    /// processed as usual (a `do` loop's closing `while`), `false` if it was consumed.
    pub(super) fn skip_line(&mut self, text: &str) -> Step<bool> {
        let Some(skip) = self.program.flow.skip.clone() else {
            return Ok(true);
        };
        if skip.purpose == Purpose::FanucBody {
            if has_m99(text) {
                self.program.flow.skip = None;
            }
            return Ok(false);
        }
        let Some(o) = oword_of(text) else {
            return Ok(false);
        };
        if Some(&o.label) != skip.label.as_ref() {
            return Ok(false);
        }
        match (skip.purpose, o.keyword) {
            (Purpose::FalseIf, Keyword::Elseif) if ReaderEnv::of(self).condition(text, &o)? => {
                self.program.flow.ifs.push((o.label, self.scratch.line_no));
                self.program.flow.skip = None;
            }
            (Purpose::FalseIf, Keyword::Else) => {
                self.program.flow.ifs.push((o.label, self.scratch.line_no));
                self.program.flow.skip = None;
            }
            (Purpose::FalseIf | Purpose::IfDone, Keyword::Endif)
            | (Purpose::SubBody, Keyword::Endsub)
            | (Purpose::LoopExit, Keyword::Endwhile | Keyword::Endrepeat | Keyword::While) => {
                self.program.flow.skip = None;
            }
            (Purpose::DoContinue, Keyword::While) => {
                self.program.flow.skip = None;
                return Ok(true);
            }
            _ => {}
        }
        Ok(false)
    }

    /// Executes an O-word statement met in the flow.
    pub(super) fn statement(&mut self, text: &str, o: OWord) -> Step<()> {
        let label = o.label.clone();
        let mismatch = |what: &str| mismatch(&o, what);
        match o.keyword {
            Keyword::Sub => {
                if !self.program.flow.frames.is_empty() {
                    return Err(mismatch("a subroutine cannot be defined inside another"));
                }
                let body = self.program.lines.position();
                self.program.flow.subs.insert(label.clone(), body);
                self.program.flow.start_skip(
                    Some(label),
                    Purpose::SubBody,
                    "endsub",
                    self.scratch.line_no,
                );
            }
            Keyword::Endsub | Keyword::Return => {
                let value = ReaderEnv::of(self).one_argument(text, &o, false)?;
                match self.program.flow.frames.last() {
                    // LinuxCNC lets `return` carry any label (its own `retval.ngc` returns
                    // with the label of the `if` around it); `endsub` must name the sub.
                    Some(Frame {
                        kind: CallKind::OWord { label: l, .. },
                        ..
                    }) if *l == label || o.keyword == Keyword::Return => {}
                    Some(_) => return Err(mismatch("not the subroutine that is running")),
                    None => return Err(mismatch("not inside a call of this subroutine")),
                }
                if let Some(v) = value {
                    self.state.params.set(&ParamRef::Named("_value".into()), v);
                }
                self.state.params.set(
                    &ParamRef::Named("_value_returned".into()),
                    if value.is_some() { 1.0 } else { 0.0 },
                );
                self.return_from_call()?;
            }
            Keyword::Call => {
                let args = ReaderEnv::of(self).arguments(text, &o)?;
                if args.len() > ARGUMENTS {
                    return Err(mismatch("at most 30 arguments"));
                }
                let body = match self.program.flow.subs.get(&label) {
                    Some(&p) => p,
                    None => self.find_ahead(
                        |reader| reader.program.flow.subs.get(&label).copied(),
                        &label.to_string(),
                        o.col,
                    )?,
                };
                self.program.flow.check_depth(o.col)?;
                let line = self.scratch.line_no;
                self.program
                    .flow
                    .spend(self.options.max_loop_iterations, || {
                        format!("the call of {label} at line {line}")
                    })?;
                let saved = Box::new(self.state.params.enter(&args));
                self.program.flow.push_frame(
                    CallKind::OWord { label, saved },
                    self.program.lines.position(),
                    self.scratch.line_no,
                );
                self.program.seek(body)?;
            }
            Keyword::If => {
                if ReaderEnv::of(self).condition(text, &o)? {
                    self.program.flow.ifs.push((label, self.scratch.line_no));
                } else {
                    self.program.flow.start_skip(
                        Some(label),
                        Purpose::FalseIf,
                        "elseif, else or endif",
                        self.scratch.line_no,
                    );
                }
            }
            Keyword::Elseif | Keyword::Else => {
                if self.program.flow.ifs.last().map(|(l, _)| l) != Some(&label) {
                    return Err(mismatch("without its if"));
                }
                self.program.flow.ifs.pop();
                self.program.flow.start_skip(
                    Some(label),
                    Purpose::IfDone,
                    "endif",
                    self.scratch.line_no,
                );
            }
            Keyword::Endif => {
                if self.program.flow.ifs.pop().map(|(l, _)| l) != Some(label) {
                    return Err(mismatch("without its if"));
                }
            }
            Keyword::While
            | Keyword::Do
            | Keyword::Repeat
            | Keyword::Endwhile
            | Keyword::Endrepeat
            | Keyword::Continue
            | Keyword::Break => self.loop_statement(text, &o, label)?,
        }
        Ok(())
    }

    /// A loop's statement: its condition or count evaluated here, the loop's business done by
    /// the flow, and the reading moved to where a loop going round returns.
    fn loop_statement(&mut self, text: &str, o: &OWord, label: Label) -> Step<()> {
        let at = LoopLine {
            line: self.scratch.line_no,
            start: Pos {
                offset: self.scratch.line_start,
                line: self.scratch.line_no,
            },
            next: self.program.lines.position(),
            limit: self.options.max_loop_iterations,
        };
        let back_to = match o.keyword {
            Keyword::While => {
                let truth = ReaderEnv::of(self).condition(text, o)?;
                self.program.flow.while_statement(truth, label, &at)?
            }
            Keyword::Do => {
                self.program.flow.do_statement(label, &at)?;
                None
            }
            Keyword::Repeat => {
                let n = ReaderEnv::of(self)
                    .one_argument(text, o, true)?
                    .unwrap_or(0.0)
                    .round();
                self.program.flow.repeat_statement(n, o, label, &at)?;
                None
            }
            Keyword::Break => {
                self.program.flow.break_statement(o, label, &at)?;
                None
            }
            _ => self.program.flow.loop_end(o, label, &at)?,
        };
        match back_to {
            Some(pos) => self.program.seek(pos),
            None => Ok(()),
        }
    }

    fn return_from_call(&mut self) -> Step<()> {
        let frame = self.program.flow.frames.pop().expect("caller checked");
        if let CallKind::OWord { saved, .. } = &frame.kind {
            self.state.params.leave(saved);
        }
        self.program.flow.loops.truncate(frame.loops);
        self.program.flow.ifs.truncate(frame.ifs);
        if let (true, Some(saved)) = (frame.restore_on_return, frame.saved) {
            self.state.restore_modes(&self.axes, saved, 1)?;
        }
        self.program.seek(frame.return_to)
    }

    /// `M98 P<number> L<count>` at column `col`, the count at `count_col`.
    pub(super) fn call_fanuc(
        &mut self,
        number: u32,
        count: u64,
        col: usize,
        count_col: usize,
    ) -> Step<()> {
        if count == 0 {
            return Ok(());
        }
        let line = self.scratch.line_no;
        let what = || format!("M98 P{number} at line {line}");
        count_fits(self.options.max_loop_iterations, what, count, count_col)?;
        self.program
            .flow
            .spend(self.options.max_loop_iterations, what)?;
        let body = match self.program.flow.fanuc_subs.get(&number) {
            Some(&p) => p,
            None => self.find_ahead(
                |reader| reader.program.flow.fanuc_subs.get(&number).copied(),
                &format!("O{number}"),
                col,
            )?,
        };
        self.program.flow.check_depth(col)?;
        self.program.flow.push_frame(
            CallKind::Fanuc {
                remaining: count - 1,
                body,
            },
            self.program.lines.position(),
            self.scratch.line_no,
        );
        self.program.seek(body)
    }

    /// The line's `M70`–`M73`, which act before its G codes, as in LinuxCNC (its order of
    /// execution: F, then the modal state's M codes, then the G codes): `G91 M70` saves G90,
    /// and `G91 M72` ends in G91. `M71` and `M72` act here; `M70`/`M73` save the modes as
    /// they are here, once the line's F (set before them) is known
    /// ([`modal_state_last`](Self::modal_state_last)).
    pub(in crate::gcode::parser) fn modal_state_first(
        &mut self,
        words: &[Word],
    ) -> Step<StateCodes> {
        let codes: Vec<(u32, usize)> = words
            .iter()
            .filter(|w| w.letter == 'M' && (70.0..=73.0).contains(&w.value))
            .map(|w| Ok((super::whole(w, 70.0, 73.0)? as u32, w.col)))
            .collect::<Step<_>>()?;
        let before = self.state.saved_modes();
        let mut restored = false;
        for &(code, col) in codes.iter().filter(|(c, _)| matches!(c, 71 | 72)) {
            self.restore_code(code, col)?;
            restored |= code == 72;
        }
        Ok(StateCodes {
            codes,
            before,
            restored,
        })
    }

    /// The line's `M70`/`M73`: the modes before its G codes, with its F and E.
    pub(in crate::gcode::parser) fn modal_state_last(
        &mut self,
        line: StateCodes,
        letters: &Letters,
    ) {
        for &(code, col) in line.codes.iter().filter(|(c, _)| matches!(c, 70 | 73)) {
            let mut modes = line.before.clone();
            if letters.get('F').is_some() {
                modes.feed = self.state.modal.feed;
            }
            if letters.get('E').is_some() {
                modes.condition = self.state.condition;
            }
            self.save_code(code, col, modes);
        }
    }

    /// `M71` forgets the modal state this call level saved, `M72` restores it (LinuxCNC's
    /// order: before the block's G codes, so `G91 M72` ends in G91).
    fn restore_code(&mut self, code: u32, col: usize) -> Step<()> {
        if code == 71 {
            *self.saved_slot() = None;
            return Ok(());
        }
        let Some(saved) = self.saved_slot().clone() else {
            return Err((
                col,
                control(
                    "M72: no modal state to restore at this call level (M70 saves one; a \
                     subroutine's is its own)"
                        .into(),
                ),
            )
                .into());
        };
        self.state.restore_modes(&self.axes, saved, col)
    }

    /// `M70` saves `modes` (the modal state before the block's G codes, with its F), `M73`
    /// saves them to be restored when the subroutine it is given in returns. Outside a
    /// subroutine `M73` only saves, as LinuxCNC reads it (said once).
    fn save_code(&mut self, code: u32, col: usize, modes: SavedModes) {
        *self.saved_slot() = Some(modes);
        if code == 73 {
            match self.program.flow.frames.last_mut() {
                Some(frame) => frame.restore_on_return = true,
                None => self.diag.once_about(
                    self.scratch.line_no,
                    "M73 at the top level",
                    col,
                    "M73 outside a subroutine: the modes are saved (M72 restores them) but \
                     no return restores them"
                        .into(),
                ),
            }
        }
    }

    /// Where this call level keeps the modes `M70`/`M73` saved.
    fn saved_slot(&mut self) -> &mut Option<SavedModes> {
        match self.program.flow.frames.last_mut() {
            Some(frame) => &mut frame.saved,
            None => &mut self.state.saved_modes,
        }
    }

    /// `M99`: the end of a Fanuc subprogram.
    pub(super) fn return_fanuc(&mut self, col: usize) -> Step<()> {
        match self.program.flow.frames.last_mut() {
            Some(Frame {
                kind: CallKind::Fanuc {
                    remaining, body, ..
                },
                ..
            }) => {
                if *remaining > 0 {
                    *remaining -= 1;
                    let body = *body;
                    let line = self.program.flow.frames.last().map_or(0, |f| f.call_line);
                    self.program
                        .flow
                        .spend(self.options.max_loop_iterations, || {
                            format!("the M98 at line {line}")
                        })?;
                    return self.program.seek(body);
                }
                self.return_from_call()
            }
            Some(Frame {
                kind: CallKind::OWord { label, .. },
                ..
            }) => Err((
                col,
                control(format!("M99 inside {label}: end it with endsub or return")),
            )
                .into()),
            None => Err((
                col,
                control(
                    "M99 outside a subprogram (in a main program it would repeat the program \
                     forever): end the program with M2 or M30"
                        .into(),
                ),
            )
                .into()),
        }
    }

    /// A Fanuc program number met in the flow after the first block: a subprogram's start.
    /// Its body is noted and skipped up to its `M99`.
    pub(super) fn fanuc_definition(&mut self, number: u32) {
        let body = self.program.lines.position();
        self.program.flow.fanuc_subs.insert(number, body);
        self.program
            .flow
            .start_skip(None, Purpose::FanucBody, "M99", self.scratch.line_no);
    }

    /// Reads ahead from here, noting every subroutine definition, until `found` knows the
    /// body's position; then seeks back. The subroutine not being there is an error at `col`.
    fn find_ahead(
        &mut self,
        found: impl Fn(&Self) -> Option<Pos>,
        name: &str,
        col: usize,
    ) -> Step<Pos> {
        let back = self.program.lines.position();
        let line_no = self.scratch.line_no;
        let io = |e| Fail::from((col, GcodeErrorKind::Io(e)));
        let result = loop {
            self.program.cancelled()?;
            let start = self.program.lines.position().offset;
            let Some((line_no, line)) = self.program.lines.next_line().map_err(io)? else {
                break None;
            };
            let Line::Text(text) = line else { continue };
            let text = text.to_string();
            self.program
                .note_structure(start, line_no, &text, self.options.block_delete)?;
            if let Some(OWord {
                label,
                keyword: Keyword::Sub,
                ..
            }) = oword_of(&text)
            {
                let body = self.program.lines.position();
                self.program.flow.subs.entry(label).or_insert(body);
            } else if let Some(n) = program_number_of(&text) {
                let body = self.program.lines.position();
                self.program.flow.fanuc_subs.entry(n).or_insert(body);
            }
            if let Some(pos) = found(self) {
                break Some(pos);
            }
        };
        self.program.seek(back)?;
        self.scratch.line_no = line_no;
        result.ok_or_else(|| {
            Fail::from((
                col,
                GcodeErrorKind::SubroutineNotFound {
                    label: name.to_string(),
                    searched: " (edmd reads subroutines from the program's own file only)",
                },
            ))
        })
    }
}

/// An O-word statement that does not fit the structure it is in.
fn mismatch(o: &OWord, what: &str) -> Fail {
    let shown = format!("{} {}", o.label, o.keyword.name());
    (o.col, control(format!("{shown}: {what}"))).into()
}

/// A loop of `runs` iterations fits the program's budget of `limit`.
/// A count asked for up front (`repeat [n]`, `M98 L<n>`) that alone exceeds the budget.
fn count_fits(limit: u64, what: impl FnOnce() -> String, runs: u64, col: usize) -> Step<()> {
    if runs > limit {
        return Err((
            col,
            GcodeErrorKind::LoopLimit {
                label: what(),
                runs,
                limit,
            },
        )
            .into());
    }
    Ok(())
}
