//! O-word loops: `while`/`endwhile`, `do`/`while`, `repeat`/`endrepeat`, with `break` and
//! `continue`. Each iteration and each entry spends from the program's loop budget.

use std::io::{BufRead, Seek};

use crate::gcode::parser::system::ReaderEnv;

use super::{Flow, Purpose, count_fits, mismatch};
use crate::gcode::lexer::{Keyword, Label, OWord};
use crate::gcode::lines::Pos;
use crate::gcode::parser::{BlockReader, Step};

#[derive(Debug, Clone, Copy)]
pub(super) enum LoopKind {
    /// `while` at the top: the `while` line, to evaluate again.
    While {
        at: Pos,
    },
    /// `do` … `while`: the first line of the body.
    Do {
        body: Pos,
    },
    Repeat {
        body: Pos,
        remaining: u64,
    },
}

#[derive(Debug, Clone)]
pub(super) struct Loop {
    pub(super) label: Label,
    pub(super) kind: LoopKind,
    pub(super) iterations: u64,
    pub(super) line: u64,
}

impl<R: BufRead + Seek> BlockReader<R> {
    /// `while`: the end of a `do` loop, or the head of a `while` loop (entered again from its
    /// `endwhile`, counting the iterations).
    pub(super) fn while_statement(&mut self, text: &str, o: &OWord, label: Label) -> Step<()> {
        let closes_do = matches!(
            self.program.flow.loops.last(),
            Some(Loop { label: l, kind: LoopKind::Do { .. }, .. }) if *l == label
        );
        let truth = ReaderEnv::of(self).condition(text, o)?;
        if closes_do {
            let top = self.program.flow.loops.last_mut().expect("checked above");
            if truth {
                top.iterations += 1;
                let line = top.line;
                let LoopKind::Do { body } = top.kind else {
                    unreachable!("checked above")
                };
                self.go_round(&label, line, body)?;
            } else {
                self.program.flow.loops.pop();
            }
            return Ok(());
        }
        let iterations = match self.program.flow.reenter.take() {
            Some((l, n)) if l == label => n + 1,
            _ => 0,
        };
        if truth {
            let line = self.scratch.line_no;
            self.spend_on_loop(&label, line)?;
            let at = Pos {
                offset: self.scratch.line_start,
                line: self.scratch.line_no,
            };
            self.program.flow.loops.push(Loop {
                label,
                kind: LoopKind::While { at },
                iterations,
                line: self.scratch.line_no,
            });
        } else {
            self.program.flow.start_skip(
                Some(label),
                Purpose::LoopExit,
                "endwhile",
                self.scratch.line_no,
            );
        }
        Ok(())
    }

    /// `endwhile`, `endrepeat` and `continue`: back to the loop's head or out of it.
    pub(super) fn loop_end(&mut self, o: &OWord, label: Label) -> Step<()> {
        let Some(top) = self.program.flow.current_loop(&label) else {
            return Err(mismatch(o, "not inside this loop"));
        };
        match (o.keyword, top.kind) {
            (Keyword::Endwhile | Keyword::Continue, LoopKind::While { at }) => {
                let top = self.program.flow.loops.pop().expect("found above");
                self.program.flow.reenter = Some((label, top.iterations));
                self.program.seek(at)?;
            }
            (Keyword::Endrepeat | Keyword::Continue, LoopKind::Repeat { body, remaining }) => {
                let top = self.program.flow.loops.last_mut().expect("found above");
                top.iterations += 1;
                if remaining > 1 {
                    top.kind = LoopKind::Repeat {
                        body,
                        remaining: remaining - 1,
                    };
                    let line = top.line;
                    self.go_round(&label, line, body)?;
                } else {
                    self.program.flow.loops.pop();
                    if o.keyword == Keyword::Continue {
                        self.program.flow.start_skip(
                            Some(label),
                            Purpose::LoopExit,
                            "endrepeat",
                            self.scratch.line_no,
                        );
                    }
                }
            }
            (Keyword::Continue, LoopKind::Do { .. }) => {
                self.program.flow.start_skip(
                    Some(label),
                    Purpose::DoContinue,
                    "while",
                    self.scratch.line_no,
                );
            }
            _ => return Err(mismatch(o, "does not close this kind of loop")),
        }
        Ok(())
    }

    /// Another round of the loop `label` (opened at `line`) from `to`, spent from the budget.
    fn go_round(&mut self, label: &Label, line: u64, to: Pos) -> Step<()> {
        self.spend_on_loop(label, line)?;
        self.program.seek(to)
    }

    /// One round of the loop `label` (opened at `line`) spent from the program's budget.
    fn spend_on_loop(&mut self, label: &Label, line: u64) -> Step<()> {
        self.program
            .flow
            .spend(self.options.max_loop_iterations, || {
                format!("the loop {label} at line {line}")
            })
    }

    /// `do`: a loop whose test is at its end.
    pub(super) fn do_statement(&mut self, label: Label) -> Step<()> {
        let line = self.scratch.line_no;
        self.spend_on_loop(&label, line)?;
        let body = self.program.lines.position();
        self.program.flow.loops.push(Loop {
            label,
            kind: LoopKind::Do { body },
            iterations: 0,
            line: self.scratch.line_no,
        });
        Ok(())
    }

    /// `repeat`: the body so many times (none for a count below one).
    pub(super) fn repeat_statement(&mut self, text: &str, o: &OWord, label: Label) -> Step<()> {
        let n = ReaderEnv::of(self)
            .one_argument(text, o, true)?
            .unwrap_or(0.0)
            .round();
        if n < 1.0 {
            self.program.flow.start_skip(
                Some(label),
                Purpose::LoopExit,
                "endrepeat",
                self.scratch.line_no,
            );
        } else {
            let line = self.scratch.line_no;
            let what = || format!("the loop {label} at line {line}");
            count_fits(
                self.options.max_loop_iterations,
                what,
                n as u64,
                o.rest_col + 1,
            )?;
            self.program
                .flow
                .spend(self.options.max_loop_iterations, what)?;
            let body = self.program.lines.position();
            self.program.flow.loops.push(Loop {
                label,
                kind: LoopKind::Repeat {
                    body,
                    remaining: n as u64,
                },
                iterations: 0,
                line: self.scratch.line_no,
            });
        }
        Ok(())
    }

    /// `break`: out of the innermost loop, which must be `label`'s.
    pub(super) fn break_statement(&mut self, o: &OWord, label: Label) -> Step<()> {
        let Some(top) = self.program.flow.current_loop(&label) else {
            return Err(mismatch(o, "not inside this loop"));
        };
        let what = match top.kind {
            LoopKind::While { .. } => "endwhile",
            LoopKind::Do { .. } => "while",
            LoopKind::Repeat { .. } => "endrepeat",
        };
        self.program.flow.loops.pop();
        self.program
            .flow
            .start_skip(Some(label), Purpose::LoopExit, what, self.scratch.line_no);
        Ok(())
    }
}

impl Flow {
    /// The innermost loop if it is `label`'s (a loop of the current call only).
    fn current_loop(&self, label: &Label) -> Option<&Loop> {
        let floor = self.frames.last().map_or(0, |f| f.loops);
        (self.loops.len() > floor)
            .then(|| self.loops.last())
            .flatten()
            .filter(|l| l.label == *label)
    }
}
