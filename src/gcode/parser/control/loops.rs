//! O-word loops: `while`/`endwhile`, `do`/`while`, `repeat`/`endrepeat`, with `break` and
//! `continue`. Each iteration and each entry spends from the program's loop budget. The
//! loops are the flow's ([`Flow`]): the reader evaluates a statement's condition or count
//! and moves to the place a loop going round returns.

use super::{Flow, Purpose, count_fits, mismatch};
use crate::gcode::lexer::{Keyword, Label, OWord};
use crate::gcode::lines::Pos;
use crate::gcode::parser::Step;

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

/// Where a loop statement's line stands in the text, and the program's loop budget.
pub(super) struct LoopLine {
    /// The line's number.
    pub(super) line: u64,
    /// Where the line starts (a `while` loop comes back to it).
    pub(super) start: Pos,
    /// Where the next line starts (a `do` or `repeat` body).
    pub(super) next: Pos,
    /// `[program] max_loop_iterations`.
    pub(super) limit: u64,
}

impl Flow {
    /// `while` (its condition `truth`): the end of a `do` loop, or the head of a `while` loop
    /// (entered again from its `endwhile`, counting the iterations). The place to read on
    /// from, when the loop goes round.
    pub(super) fn while_statement(
        &mut self,
        truth: bool,
        label: Label,
        at: &LoopLine,
    ) -> Step<Option<Pos>> {
        let closes_do = matches!(
            self.loops.last(),
            Some(Loop { label: l, kind: LoopKind::Do { .. }, .. }) if *l == label
        );
        if closes_do {
            let top = self.loops.last_mut().expect("checked above");
            if truth {
                top.iterations += 1;
                let line = top.line;
                let LoopKind::Do { body } = top.kind else {
                    unreachable!("checked above")
                };
                self.spend_on_loop(&label, line, at.limit)?;
                return Ok(Some(body));
            }
            self.loops.pop();
            return Ok(None);
        }
        let iterations = match self.reenter.take() {
            Some((l, n)) if l == label => n + 1,
            _ => 0,
        };
        if truth {
            self.spend_on_loop(&label, at.line, at.limit)?;
            self.loops.push(Loop {
                label,
                kind: LoopKind::While { at: at.start },
                iterations,
                line: at.line,
            });
        } else {
            self.start_skip(Some(label), Purpose::LoopExit, "endwhile", at.line);
        }
        Ok(None)
    }

    /// `endwhile`, `endrepeat` and `continue`: back to the loop's head (the place returned)
    /// or out of it.
    pub(super) fn loop_end(&mut self, o: &OWord, label: Label, at: &LoopLine) -> Step<Option<Pos>> {
        let Some(top) = self.current_loop(&label) else {
            return Err(mismatch(o, "not inside this loop"));
        };
        match (o.keyword, top.kind) {
            (Keyword::Endwhile | Keyword::Continue, LoopKind::While { at: head }) => {
                let top = self.loops.pop().expect("found above");
                self.reenter = Some((label, top.iterations));
                Ok(Some(head))
            }
            (Keyword::Endrepeat | Keyword::Continue, LoopKind::Repeat { body, remaining }) => {
                let top = self.loops.last_mut().expect("found above");
                top.iterations += 1;
                if remaining > 1 {
                    top.kind = LoopKind::Repeat {
                        body,
                        remaining: remaining - 1,
                    };
                    let line = top.line;
                    self.spend_on_loop(&label, line, at.limit)?;
                    return Ok(Some(body));
                }
                self.loops.pop();
                if o.keyword == Keyword::Continue {
                    self.start_skip(Some(label), Purpose::LoopExit, "endrepeat", at.line);
                }
                Ok(None)
            }
            (Keyword::Continue, LoopKind::Do { .. }) => {
                self.start_skip(Some(label), Purpose::DoContinue, "while", at.line);
                Ok(None)
            }
            _ => Err(mismatch(o, "does not close this kind of loop")),
        }
    }

    /// One round of the loop `label` (opened at `line`) spent from the program's budget
    /// (`limit` rounds in all).
    fn spend_on_loop(&mut self, label: &Label, line: u64, limit: u64) -> Step<()> {
        self.spend(limit, || format!("the loop {label} at line {line}"))
    }

    /// `do`: a loop whose test is at its end.
    pub(super) fn do_statement(&mut self, label: Label, at: &LoopLine) -> Step<()> {
        self.spend_on_loop(&label, at.line, at.limit)?;
        self.loops.push(Loop {
            label,
            kind: LoopKind::Do { body: at.next },
            iterations: 0,
            line: at.line,
        });
        Ok(())
    }

    /// `repeat` (its count `n`, rounded): the body so many times (none for a count below
    /// one).
    pub(super) fn repeat_statement(
        &mut self,
        n: f64,
        o: &OWord,
        label: Label,
        at: &LoopLine,
    ) -> Step<()> {
        if n < 1.0 {
            self.start_skip(Some(label), Purpose::LoopExit, "endrepeat", at.line);
            return Ok(());
        }
        let line = at.line;
        let what = || format!("the loop {label} at line {line}");
        count_fits(at.limit, what, n as u64, o.rest_col + 1)?;
        self.spend(at.limit, what)?;
        self.loops.push(Loop {
            label,
            kind: LoopKind::Repeat {
                body: at.next,
                remaining: n as u64,
            },
            iterations: 0,
            line: at.line,
        });
        Ok(())
    }

    /// `break`: out of the innermost loop, which must be `label`'s.
    pub(super) fn break_statement(&mut self, o: &OWord, label: Label, at: &LoopLine) -> Step<()> {
        let Some(top) = self.current_loop(&label) else {
            return Err(mismatch(o, "not inside this loop"));
        };
        let what = match top.kind {
            LoopKind::While { .. } => "endwhile",
            LoopKind::Do { .. } => "while",
            LoopKind::Repeat { .. } => "endrepeat",
        };
        self.loops.pop();
        self.start_skip(Some(label), Purpose::LoopExit, what, at.line);
        Ok(())
    }

    /// The innermost loop if it is `label`'s (a loop of the current call only).
    fn current_loop(&self, label: &Label) -> Option<&Loop> {
        let floor = self.frames.last().map_or(0, |f| f.loops);
        (self.loops.len() > floor)
            .then(|| self.loops.last())
            .flatten()
            .filter(|l| l.label == *label)
    }
}
