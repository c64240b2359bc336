//! The O-word structure of a program, checked as text: every construct closed, in order, once.
//!
//! The interpreter ([`super::control`]) executes the flow, so on its own it only ever sees the
//! branches it takes: a second `else` after a taken branch, an `elseif` after the `else`, an
//! `if` or a loop left open before `M2`, two constructs that cross, or a subroutine defined
//! twice would pass unnoticed (the second definition silently winning). A control must refuse
//! such a program before it moves, not half-way through a part, so every line is also shown to
//! [`Structure`] once, in file order, the first time the reader meets it (loops and calls read
//! lines again; they are not shown again), and the rest of the file after the program's end is
//! scanned for it too. It sees O-word statements only and evaluates nothing.
//!
//! The rules, which LinuxCNC's documentation states for its O-codes:
//! - `if` … (`elseif` …)* (`else` …)? `endif`, with no `elseif` after the `else`;
//! - `while` … `endwhile`, `do` … `while`, `repeat` … `endrepeat`; `break` and `continue`
//!   inside a loop of their label;
//! - `sub` … `endsub`, not inside another `sub`, each label defined once; `return` inside a
//!   `sub`;
//! - constructs nest: the innermost open one is the one closed.

use std::collections::HashMap;

use crate::gcode::lexer::{Keyword, Label, OWord};

/// A construct still open, with the line that opened it.
#[derive(Debug, Clone)]
struct Open {
    label: Label,
    kind: Kind,
    line: u64,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    /// An `if`, and the line of its `else` once one was seen.
    If {
        else_at: Option<u64>,
    },
    While,
    Do,
    Repeat,
    Sub,
}

impl Kind {
    fn opener(self) -> &'static str {
        match self {
            Kind::If { .. } => "if",
            Kind::While => "while",
            Kind::Do => "do",
            Kind::Repeat => "repeat",
            Kind::Sub => "sub",
        }
    }

    fn closer(self) -> &'static str {
        match self {
            Kind::If { .. } => "endif",
            Kind::While => "endwhile",
            Kind::Do => "while",
            Kind::Repeat => "endrepeat",
            Kind::Sub => "endsub",
        }
    }

    fn is_loop(self) -> bool {
        matches!(self, Kind::While | Kind::Do | Kind::Repeat)
    }
}

/// What is wrong, and at which column of the line.
pub(super) type StructureError = (usize, String);

/// The open constructs and the subroutines defined so far.
#[derive(Debug, Default, Clone)]
pub(super) struct Structure {
    open: Vec<Open>,
    subs: HashMap<Label, u64>,
}

impl Structure {
    /// Notes the O-word statement `o` of line `line`.
    pub(super) fn note(&mut self, o: &OWord, line: u64) -> Result<(), StructureError> {
        let shown = format!("{} {}", o.label, o.keyword.name());
        let fail = |what: String| Err((o.col, format!("{shown}: {what}")));
        let top = self
            .open
            .last()
            .filter(|t| t.label == o.label)
            .map(|t| t.kind);
        match o.keyword {
            Keyword::Sub => {
                if let Some(s) = self.open.iter().find(|s| s.kind == Kind::Sub) {
                    return fail(format!(
                        "a subroutine cannot be defined inside another ({} sub at line {} is \
                         still open)",
                        s.label, s.line
                    ));
                }
                if let Some(first) = self.subs.get(&o.label) {
                    return fail(format!(
                        "defined again (first at line {first}); a subroutine is defined once"
                    ));
                }
                self.subs.insert(o.label.clone(), line);
                self.push(o, Kind::Sub, line);
            }
            Keyword::If => self.push(o, Kind::If { else_at: None }, line),
            Keyword::While if top == Some(Kind::Do) => {
                self.open.pop();
            }
            Keyword::While => self.push(o, Kind::While, line),
            Keyword::Do => self.push(o, Kind::Do, line),
            Keyword::Repeat => self.push(o, Kind::Repeat, line),
            Keyword::Elseif | Keyword::Else => match top {
                Some(Kind::If { else_at: Some(at) }) => {
                    return fail(format!(
                        "after the else at line {at}: an if has one else, and it comes last"
                    ));
                }
                Some(Kind::If { else_at: None }) => {
                    if o.keyword == Keyword::Else {
                        let open = self.open.last_mut().expect("top is open");
                        open.kind = Kind::If {
                            else_at: Some(line),
                        };
                    }
                }
                _ => return fail(self.not_closing(&o.label, "if")),
            },
            Keyword::Endif | Keyword::Endwhile | Keyword::Endrepeat | Keyword::Endsub => {
                let wants = match o.keyword {
                    Keyword::Endif => "if",
                    Keyword::Endwhile => "while",
                    Keyword::Endrepeat => "repeat",
                    _ => "sub",
                };
                match top {
                    Some(kind) if kind.opener() == wants && kind != Kind::Do => {
                        self.open.pop();
                    }
                    _ => return fail(self.not_closing(&o.label, wants)),
                }
            }
            Keyword::Break | Keyword::Continue => {
                let inner = self.open.iter().rev().take_while(|c| c.kind != Kind::Sub);
                if !inner
                    .filter(|c| c.kind.is_loop())
                    .any(|c| c.label == o.label)
                {
                    return fail(format!("not inside a loop {}", o.label));
                }
            }
            Keyword::Return => {
                if !self.open.iter().any(|c| c.kind == Kind::Sub) {
                    return fail("not inside a subroutine".to_string());
                }
            }
            Keyword::Call => {}
        }
        Ok(())
    }

    fn push(&mut self, o: &OWord, kind: Kind, line: u64) {
        self.open.push(Open {
            label: o.label.clone(),
            kind,
            line,
        });
    }

    /// Why a closing word does not close the innermost construct.
    fn not_closing(&self, label: &Label, wants: &str) -> String {
        match self.open.last() {
            None => format!("without its {wants}"),
            Some(top) if top.label == *label => format!(
                "{label} {} at line {} is open here, not a {label} {wants}",
                top.kind.opener(),
                top.line
            ),
            Some(top) => format!(
                "{} {} at line {} must be closed first ({}); constructs nest, they do not cross",
                top.label,
                top.kind.opener(),
                top.line,
                top.kind.closer()
            ),
        }
    }

    /// At the end of the file: the innermost construct left open, as `(line, message)`.
    pub(super) fn unclosed(&self) -> Option<(u64, String)> {
        let top = self.open.last()?;
        Some((
            top.line,
            format!(
                "{} {} at line {} is never closed: {} {} expected",
                top.label,
                top.kind.opener(),
                top.line,
                top.label,
                top.kind.closer()
            ),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gcode::lexer::oword_of;

    /// Notes every O-word of `text`; the first error as `(line, col, message)`, or the
    /// construct left open.
    fn check(text: &str) -> Result<(), (u64, usize, String)> {
        let mut s = Structure::default();
        for (i, line) in text.lines().enumerate() {
            if let Some(o) = oword_of(line) {
                s.note(&o, i as u64 + 1)
                    .map_err(|(col, m)| (i as u64 + 1, col, m))?;
            }
        }
        match s.unclosed() {
            Some((line, m)) => Err((line, 1, m)),
            None => Ok(()),
        }
    }

    #[test]
    fn well_formed_programs_pass() {
        check("o1 if [1]\no1 elseif [2]\no1 else\no1 endif").unwrap();
        check("o1 while [1]\no2 if [1]\no1 break\no2 endif\no1 endwhile").unwrap();
        check("o1 do\no1 continue\no1 while [1]").unwrap();
        check(
            "o1 repeat [3]\no1 endrepeat\no<s> sub\no2 if [1]\no<s> return\no2 endif\no<s> endsub",
        )
        .unwrap();
        // A sub may close an if around its `return` with the if's label (LinuxCNC's retval.ngc).
        check("o<f> sub\no1 if [1]\no1 return [2]\no1 endif\no<f> endsub\no<f> call").unwrap();
    }

    #[test]
    fn each_malformation_is_named_where_it_is() {
        let cases: [(&str, u64, &str); 11] = [
            (
                "o1 if [1]\no1 else\no1 else\no1 endif",
                3,
                "after the else at line 2",
            ),
            (
                "o1 if [0]\no1 else\no1 elseif [1]\no1 endif",
                3,
                "after the else at line 2",
            ),
            (
                "o1 if [1]\no2 while [1]\no1 endif\no2 endwhile",
                3,
                "O2 while at line 2 must be closed first (endwhile)",
            ),
            (
                "o1 while [1]\nG1 X1\nM2",
                1,
                "O1 while at line 1 is never closed: O1 endwhile",
            ),
            (
                "o1 if [1]\nM2",
                1,
                "O1 if at line 1 is never closed: O1 endif expected",
            ),
            (
                "o1 sub\no1 endsub\no1 sub\no1 endsub",
                3,
                "defined again (first at line 1)",
            ),
            (
                "o1 sub\no2 sub\no2 endsub\no1 endsub",
                2,
                "cannot be defined inside another",
            ),
            ("o1 endif", 1, "O1 endif: without its if"),
            (
                "o1 do\no1 endwhile",
                2,
                "O1 do at line 1 is open here, not a O1 while",
            ),
            (
                "o1 repeat [2]\no2 break\no1 endrepeat",
                2,
                "not inside a loop O2",
            ),
            ("o1 return", 1, "not inside a subroutine"),
        ];
        for (text, line, needle) in cases {
            let (at, col, message) = check(text).unwrap_err();
            assert_eq!(at, line, "{text:?}: {message}");
            assert_eq!(col, 1, "{text:?}");
            assert!(message.contains(needle), "{text:?}: {message}");
        }
    }
}
