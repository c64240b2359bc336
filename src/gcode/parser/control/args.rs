//! An O-word statement's bracketed arguments (`call [1] [2]`, `while [#1 LT 3]`,
//! `return [#2]`), read with the parameters as expressions see them.

use super::control;
use crate::gcode::error::GcodeErrorKind;
use crate::gcode::expr::{self, Scanner};
use crate::gcode::lexer::OWord;
use crate::gcode::parser::system::ReaderEnv;
use crate::gcode::parser::{Fail, Step};

impl<R> ReaderEnv<'_, R> {
    /// Values of `[…]` arguments after the keyword, as many as there are.
    pub(super) fn arguments(&self, text: &str, o: &OWord) -> Step<Vec<f64>> {
        let mut sc = Scanner::at(text, o.rest, o.rest_col);
        let mut args = Vec::new();
        loop {
            sc.skip_ws();
            match sc.peek() {
                None | Some('(' | ';') => return Ok(args),
                Some('[') => args.push(expr::value(&mut sc, self).map_err(Fail::from)?),
                Some(c) => {
                    return Err((
                        sc.next_col(),
                        GcodeErrorKind::UnexpectedChar {
                            ch: c,
                            hint: " (O-word arguments are bracketed: [value])",
                        },
                    )
                        .into());
                }
            }
        }
    }

    /// The statement's one `[value]`: `None` if it has none and none is `required`.
    pub(super) fn one_argument(&self, text: &str, o: &OWord, required: bool) -> Step<Option<f64>> {
        let args = self.arguments(text, o)?;
        match (args.len(), required) {
            (0, true) => Err((
                o.rest_col + 1,
                control(format!("{} {} needs a [value]", o.label, o.keyword.name())),
            )
                .into()),
            (0 | 1, _) => Ok(args.first().copied()),
            _ => Err((
                o.rest_col + 1,
                control(format!(
                    "{} {} takes one [value]",
                    o.label,
                    o.keyword.name()
                )),
            )
                .into()),
        }
    }

    /// The statement's one required `[value]` as a condition: anything but 0 is true.
    pub(super) fn condition(&self, text: &str, o: &OWord) -> Step<bool> {
        Ok(self.one_argument(text, o, true)? != Some(0.0))
    }
}
