//! The machine's axes as a block's words meet them: which letters name an axis here, which
//! name an axis the machine does not have, and which words a form accepts. It holds only the
//! axis list the reader was made for, so every check a form makes of its words is answered
//! without the interpreter's state.

use std::ops::Deref;

use super::codes::Motion;
use super::{Letters, Step};
use crate::gcode::error::GcodeErrorKind;
use crate::gcode::lexer::Word;
use crate::vocab::Axis;

/// The machine's axes, in the order every point is in.
pub(super) struct MachineAxes {
    axes: Vec<Axis>,
}

impl Deref for MachineAxes {
    type Target = [Axis];

    fn deref(&self) -> &[Axis] {
        &self.axes
    }
}

impl MachineAxes {
    pub(super) fn new(axes: &[Axis]) -> MachineAxes {
        MachineAxes {
            axes: axes.to_vec(),
        }
    }

    /// The axes' letters for a message: "X, Y, Z".
    pub(super) fn list(&self) -> String {
        self.axes
            .iter()
            .map(|a| a.letter().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// Whether a block in motion mode `m` moves: it has axis words, or, for an arc, a centre
    /// or radius (a full circle needs no axis words). A bare `G1` only sets the mode.
    pub(super) fn moves(&self, m: Motion, letters: &Letters) -> Step<bool> {
        if self.first_word(letters)?.is_some() {
            return Ok(true);
        }
        let arc_words = matches!(m, Motion::Cw | Motion::Ccw)
            && ['I', 'J', 'K', 'R']
                .iter()
                .any(|&l| letters.get(l).is_some());
        Ok(arc_words)
    }

    /// The axis a word names: `Some` for one of the machine's axes, `None` for a letter that is
    /// no axis, an error for an axis letter the machine does not have.
    pub(super) fn of_word(&self, w: &Word) -> Step<Option<Axis>> {
        match Axis::from_letter(w.letter) {
            Some(axis) if !self.axes.contains(&axis) => Err((
                w.col,
                GcodeErrorKind::AxisNotOnMachine {
                    axis: w.letter,
                    axes: self.list(),
                },
            )
                .into()),
            found => Ok(found),
        }
    }

    /// The first axis word of the block, checking that every axis word names a machine axis.
    pub(super) fn first_word<'w>(&self, letters: &Letters<'w>) -> Step<Option<&'w Word>> {
        let mut first: Option<&Word> = None;
        for w in letters.present() {
            let polar = matches!(w.letter, '@' | '^');
            if (polar || self.of_word(w)?.is_some()) && first.is_none_or(|f| w.col < f.col) {
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
            if allow_axes && (matches!(w.letter, '@' | '^') || self.of_word(w)?.is_some()) {
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
}
