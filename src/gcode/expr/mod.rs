//! Parameters and expressions, as LinuxCNC's interpreter reads them.
//!
//! A word's value may be a number, a parameter (`#12`, `#<local>`, `#<_global>`, `#[1+2]`,
//! `##1`), a bracketed expression (`[#1 * 2 + 0.5]`) or a function (`SIN[30]`,
//! `ATAN[1]/[2]`, `EXISTS[#<x>]`), with any number of signs in front. Inside brackets the
//! binary operators bind, tightest first: `**`; `* / MOD`; `+ -`; `EQ NE GT GE LT LE`;
//! `AND OR XOR`, left to right within a level. Comparisons and logic give 1 or 0; any
//! non-zero value is true. Angles are degrees. Names are case-insensitive and spaces inside
//! `< >` do not count (`#<Feed Rate>` is `#<feedrate>`), as in LinuxCNC.
//!
//! Numbered parameters run from 1 to [`NUMBERED_MAX`] and start at 0; a named parameter must be
//! set before it is read. Names starting with `_` are global; others are local to the
//! subroutine call that set them. `#1`…`#30` are a subroutine's arguments and are restored
//! when it returns. Reading and writing go through [`Env`], so the interpreter can offer
//! read-only system values (`#<_x>`, `#<_metric>`, …) without storing them.
//!
//! Evaluation never panics and never yields NaN or infinity: a division by zero, a function
//! outside its domain or an overflow is an error at the column of the operator or function.
//!
//! **Bounded depth.** The evaluator is recursive descent, so a line nested deep enough would
//! overflow any thread's stack and abort the process (a 12 KB line of brackets did, on a 2 MiB
//! thread). Brackets, functions and parameter indirection (`##…`) nest at most
//! [`MAX_NESTING`] levels, counted on the [`Scanner`]; signs are read in a loop and cost no
//! depth. Every thread that parses runs on [`PARSER_STACK_BYTES`] of stack, which a test
//! shows holds the deepest accepted expression with room to spare.

use super::error::GcodeErrorKind;

mod params;
mod scanner;

pub(crate) use params::{Env, ParamRef, Params};
pub(crate) use scanner::Scanner;

/// Highest numbered parameter (LinuxCNC's `RS274NGC_MAX_PARAMETERS - 1`).
pub const NUMBERED_MAX: usize = 5602;
/// Numbered parameters that carry a subroutine's arguments.
pub(crate) const ARGUMENTS: usize = 30;
/// Deepest nesting of brackets, functions and parameter indirection in one value. LinuxCNC's
/// programs nest a handful of levels; a line nested deeper is refused rather than allowed to
/// exhaust the stack.
pub const MAX_NESTING: usize = 256;
/// The stack of every thread that parses programs. The deepest accepted expression
/// ([`MAX_NESTING`] levels of the costliest kind) needs a fraction of it in a debug build
/// (`tests/it/program_flow.rs` parses it on a thread of exactly this size); the rest is margin.
pub const PARSER_STACK_BYTES: usize = 8 << 20;

pub(crate) type ExprError = (usize, GcodeErrorKind);

/// Reads `#…` after the `#` was taken: which parameter it names.
pub(crate) fn param_ref(sc: &mut Scanner, env: &dyn Env) -> Result<ParamRef, ExprError> {
    sc.skip_ws();
    let col = sc.next_col();
    if sc.peek() == Some('<') {
        sc.bump();
        let name = sc.angle_name(col, "named parameter without its closing `>`", true)?;
        if name.is_empty() {
            return Err((
                col,
                GcodeErrorKind::Expression {
                    what: "empty parameter name `#<>`",
                },
            ));
        }
        return Ok(ParamRef::Named(name));
    }
    let v = value(sc, env)?;
    let n = v.round();
    if (v - n).abs() > 1e-6 || n < 1.0 || n > NUMBERED_MAX as f64 {
        return Err((
            col,
            GcodeErrorKind::ParameterNumber {
                value: v,
                max: NUMBERED_MAX,
            },
        ));
    }
    Ok(ParamRef::Numbered(n as usize))
}

/// Reads a parameter's value (the `#` already taken).
fn read_param(sc: &mut Scanner, env: &dyn Env, col: usize) -> Result<f64, ExprError> {
    match param_ref(sc, env)? {
        ParamRef::Numbered(n) => Ok(env.numbered(n)),
        ParamRef::Named(name) => env.named(&name).ok_or((
            col,
            GcodeErrorKind::UndefinedParameter {
                name: format!("#<{name}>"),
            },
        )),
    }
}

/// A real value: signs, then a number, parameter, bracketed expression or function.
pub(crate) fn value(sc: &mut Scanner, env: &dyn Env) -> Result<f64, ExprError> {
    // Signs in a loop, not by recursion: `- - - … 1` costs no stack.
    let mut negative = false;
    loop {
        sc.skip_ws();
        match sc.peek() {
            Some('-') => negative = !negative,
            Some('+') => {}
            _ => break,
        }
        sc.bump();
    }
    let col = sc.next_col();
    let v = match sc.peek() {
        Some('#') => {
            sc.bump();
            sc.enter(col)?;
            let v = read_param(sc, env, col)?;
            sc.leave();
            v
        }
        Some('[') => {
            sc.bump();
            sc.enter(col)?;
            let v = expression(sc, env)?;
            sc.expect(']', "`]` expected to close the expression")?;
            sc.leave();
            v
        }
        Some(c) if c.is_ascii_digit() || c == '.' => number(sc)?,
        // A function's argument is bracketed, and the bracket counts the level.
        Some(c) if c.is_ascii_alphabetic() => function(sc, env, col)?,
        _ => {
            return Err((
                col,
                GcodeErrorKind::Expression {
                    what: "a number, parameter or `[` expected",
                },
            ));
        }
    };
    Ok(if negative { -v } else { v })
}

/// A plain decimal literal (digits with at most one point).
fn number(sc: &mut Scanner) -> Result<f64, ExprError> {
    let col = sc.next_col();
    let start = sc.pos;
    while matches!(sc.peek(), Some(c) if c.is_ascii_digit() || c == '.') {
        sc.bump();
    }
    let text = &sc.s[start..sc.pos];
    no_exponent(sc)?;
    let digits = text.chars().filter(char::is_ascii_digit).count();
    if digits == 0 || text.matches('.').count() > 1 || text.len() > 32 {
        return Err((
            col,
            GcodeErrorKind::Expression {
                what: "malformed number",
            },
        ));
    }
    text.parse().map_err(|_| {
        (
            col,
            GcodeErrorKind::Expression {
                what: "malformed number",
            },
        )
    })
}

/// After the digits of a number: `1e300` is not G-code (LinuxCNC reads the `e` as an unknown
/// operation or word); say so where the exponent starts, rather than "`]` expected".
pub(crate) fn no_exponent(sc: &Scanner) -> Result<(), ExprError> {
    if matches!(sc.peek(), Some('e' | 'E'))
        && matches!(sc.peek2(), Some(c) if c.is_ascii_digit() || c == '+' || c == '-')
    {
        return Err((
            sc.next_col(),
            GcodeErrorKind::UnexpectedChar {
                ch: sc.peek().unwrap_or('e'),
                hint: " (exponent notation such as 1e3 is not G-code: write the number out)",
            },
        ));
    }
    Ok(())
}

const FUNCTIONS: [&str; 14] = [
    "ABS", "ACOS", "ASIN", "ATAN", "COS", "EXISTS", "EXP", "FIX", "FUP", "LN", "ROUND", "SIN",
    "SQRT", "TAN",
];

fn function(sc: &mut Scanner, env: &dyn Env, col: usize) -> Result<f64, ExprError> {
    // Longest names first so that ASIN is not read as ABS… (none is a prefix of another, but
    // keep the order explicit).
    let Some(name) = FUNCTIONS.iter().copied().find(|f| sc.eat_word(f)) else {
        return Err((
            col,
            GcodeErrorKind::Expression {
                what: "unknown function (ABS ACOS ASIN ATAN COS EXISTS EXP FIX FUP LN ROUND SIN SQRT TAN)",
            },
        ));
    };
    sc.skip_ws();
    if sc.peek() != Some('[') {
        return Err((
            sc.next_col(),
            GcodeErrorKind::Expression {
                what: "`[` expected after the function name",
            },
        ));
    }
    if name == "EXISTS" {
        // Its bracket is read here, not by `value`: the level is counted here.
        sc.bump();
        sc.enter(col)?;
        sc.skip_ws();
        if sc.peek() != Some('#') {
            return Err((
                sc.next_col(),
                GcodeErrorKind::Expression {
                    what: "EXISTS takes a named parameter: EXISTS[#<name>]",
                },
            ));
        }
        sc.bump();
        let exists = match param_ref(sc, env)? {
            ParamRef::Named(n) => env.named(&n).is_some(),
            ParamRef::Numbered(_) => true,
        };
        sc.expect(']', "`]` expected after EXISTS's parameter")?;
        sc.leave();
        return Ok(if exists { 1.0 } else { 0.0 });
    }
    let arg = value(sc, env)?;
    let domain = |ok: bool| -> Result<(), ExprError> {
        if ok {
            Ok(())
        } else {
            Err((col, GcodeErrorKind::MathDomain { function: name }))
        }
    };
    let v = match name {
        "ABS" => arg.abs(),
        "ACOS" => {
            domain((-1.0..=1.0).contains(&arg))?;
            arg.acos().to_degrees()
        }
        "ASIN" => {
            domain((-1.0..=1.0).contains(&arg))?;
            arg.asin().to_degrees()
        }
        "ATAN" => {
            sc.expect('/', "ATAN takes two values: ATAN[y]/[x]")?;
            sc.skip_ws();
            if sc.peek() != Some('[') {
                return Err((
                    sc.next_col(),
                    GcodeErrorKind::Expression {
                        what: "ATAN takes two values: ATAN[y]/[x]",
                    },
                ));
            }
            let x = value(sc, env)?;
            arg.atan2(x).to_degrees()
        }
        "COS" => arg.to_radians().cos(),
        "EXP" => arg.exp(),
        "FIX" => arg.floor(),
        "FUP" => arg.ceil(),
        "LN" => {
            domain(arg > 0.0)?;
            arg.ln()
        }
        "ROUND" => arg.round(),
        "SIN" => arg.to_radians().sin(),
        "SQRT" => {
            domain(arg >= 0.0)?;
            arg.sqrt()
        }
        "TAN" => arg.to_radians().tan(),
        _ => unreachable!("every name in FUNCTIONS is handled"),
    };
    finite(v, col)
}

fn finite(v: f64, col: usize) -> Result<f64, ExprError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err((
            col,
            GcodeErrorKind::Expression {
                what: "the result is too large",
            },
        ))
    }
}

#[derive(Clone, Copy, PartialEq)]
enum Op {
    Pow,
    Mul,
    Div,
    Mod,
    Add,
    Sub,
    Eq,
    Ne,
    Gt,
    Ge,
    Lt,
    Le,
    And,
    Or,
    Xor,
}

impl Op {
    fn precedence(self) -> u8 {
        match self {
            Op::Pow => 4,
            Op::Mul | Op::Div | Op::Mod => 3,
            Op::Add | Op::Sub => 2,
            Op::Eq | Op::Ne | Op::Gt | Op::Ge | Op::Lt | Op::Le => 1,
            Op::And | Op::Or | Op::Xor => 0,
        }
    }
}

fn operator(sc: &mut Scanner) -> Option<Op> {
    sc.skip_ws();
    let op = match sc.peek()? {
        '*' if sc.peek2() == Some('*') => {
            sc.bump();
            Op::Pow
        }
        '*' => Op::Mul,
        '/' => Op::Div,
        '+' => Op::Add,
        '-' => Op::Sub,
        c if c.is_ascii_alphabetic() => {
            const WORDS: [(&str, Op); 10] = [
                ("MOD", Op::Mod),
                ("EQ", Op::Eq),
                ("NE", Op::Ne),
                ("GT", Op::Gt),
                ("GE", Op::Ge),
                ("LT", Op::Lt),
                ("LE", Op::Le),
                ("AND", Op::And),
                ("OR", Op::Or),
                ("XOR", Op::Xor),
            ];
            return WORDS
                .iter()
                .find(|(w, _)| sc.eat_word(w))
                .map(|&(_, op)| op);
        }
        _ => return None,
    };
    sc.bump();
    Some(op)
}

fn apply(op: Op, a: f64, b: f64, col: usize) -> Result<f64, ExprError> {
    let truth = |x: bool| if x { 1.0 } else { 0.0 };
    let v = match op {
        Op::Pow => {
            if a < 0.0 && b.fract() != 0.0 {
                return Err((col, GcodeErrorKind::MathDomain { function: "**" }));
            }
            a.powf(b)
        }
        Op::Mul => a * b,
        Op::Div | Op::Mod if b == 0.0 => {
            return Err((
                col,
                GcodeErrorKind::Expression {
                    what: "division by zero",
                },
            ));
        }
        Op::Div => a / b,
        // LinuxCNC's MOD: the result has the sign of the divisor's magnitude (always ≥ 0).
        Op::Mod => a.rem_euclid(b.abs()),
        Op::Add => a + b,
        Op::Sub => a - b,
        Op::Eq => truth(a == b),
        Op::Ne => truth(a != b),
        Op::Gt => truth(a > b),
        Op::Ge => truth(a >= b),
        Op::Lt => truth(a < b),
        Op::Le => truth(a <= b),
        Op::And => truth(a != 0.0 && b != 0.0),
        Op::Or => truth(a != 0.0 || b != 0.0),
        Op::Xor => truth((a != 0.0) != (b != 0.0)),
    };
    finite(v, col)
}

/// The inside of `[ … ]`: values joined by binary operators (precedence climbing).
pub(crate) fn expression(sc: &mut Scanner, env: &dyn Env) -> Result<f64, ExprError> {
    climb(sc, env, 0)
}

fn climb(sc: &mut Scanner, env: &dyn Env, min: u8) -> Result<f64, ExprError> {
    let mut lhs = value(sc, env)?;
    loop {
        let save = sc.clone();
        let col = {
            let mut probe = sc.clone();
            probe.skip_ws();
            probe.next_col()
        };
        let Some(op) = operator(sc) else {
            *sc = save;
            return Ok(lhs);
        };
        if op.precedence() < min {
            *sc = save;
            return Ok(lhs);
        }
        let rhs = climb(sc, env, op.precedence() + 1)?;
        lhs = apply(op, lhs, rhs, col)?;
    }
}

/// Evaluates `text` as one expression in brackets, for tests and messages.
#[cfg(test)]
pub(crate) fn eval(text: &str, env: &dyn Env) -> Result<f64, ExprError> {
    let mut sc = Scanner::new(text);
    let v = value(&mut sc, env)?;
    sc.skip_ws();
    if sc.peek().is_some() {
        return Err((
            sc.next_col(),
            GcodeErrorKind::Expression {
                what: "text after the expression",
            },
        ));
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    impl Env for Params {
        fn numbered(&self, n: usize) -> f64 {
            Params::numbered(self, n)
        }
        fn named(&self, name: &str) -> Option<f64> {
            Params::named(self, name)
        }
    }

    fn ev(text: &str) -> f64 {
        let mut p = Params::default();
        p.set(&ParamRef::Numbered(1), 3.0);
        p.set(&ParamRef::Numbered(3), 7.0);
        p.set(&ParamRef::Named("width".into()), 10.0);
        p.set(&ParamRef::Named("_g".into()), 2.0);
        eval(text, &p).unwrap_or_else(|e| panic!("{text}: {e:?}"))
    }

    fn err(text: &str) -> (usize, String) {
        let p = Params::default();
        let (col, kind) = eval(text, &p).unwrap_err();
        (col, kind.to_string())
    }

    #[test]
    fn precedence_and_associativity() {
        assert_eq!(ev("[1 + 2 * 3]"), 7.0);
        assert_eq!(ev("[2 ** 3 ** 2]"), 64.0); // left to right, as LinuxCNC
        assert_eq!(ev("[10 - 4 - 3]"), 3.0);
        assert_eq!(ev("[12 / 3 / 2]"), 2.0);
        assert_eq!(ev("[7 MOD 3]"), 1.0);
        assert_eq!(ev("[-7 MOD 3]"), 2.0);
        assert_eq!(ev("[1 + 2 GT 2]"), 1.0);
        assert_eq!(ev("[1 LT 2 AND 3 LT 2]"), 0.0);
        assert_eq!(ev("[1 XOR 0]"), 1.0);
        assert_eq!(ev("[-[2 + 1]]"), -3.0);
        assert_eq!(ev("-[2 + 1]"), -3.0);
        assert_eq!(ev("[2 * -3]"), -6.0);
        assert_eq!(ev("[1 eq 1.0]"), 1.0);
    }

    #[test]
    fn parameters_and_functions() {
        assert_eq!(ev("#1"), 3.0);
        assert_eq!(ev("##1"), 7.0); // #[#1] = #3
        assert_eq!(ev("#[1 + 2]"), 7.0);
        assert_eq!(ev("#2"), 0.0);
        assert_eq!(ev("#< Wid th >"), 10.0);
        assert_eq!(ev("#<_g>"), 2.0);
        assert!((ev("SIN[30]") - 0.5).abs() < 1e-15);
        assert!((ev("cos[60]") - 0.5).abs() < 1e-15);
        assert_eq!(ev("ATAN[1]/[1]"), 45.0);
        assert_eq!(ev("ATAN[1]/[-1]"), 135.0);
        assert_eq!(ev("SQRT[#1 * 3]"), 3.0);
        assert_eq!(
            ev("[FIX[-1.5] + FUP[1.2] + ROUND[2.5] + ABS[-1]]"),
            -2.0 + 2.0 + 3.0 + 1.0
        );
        assert_eq!(ev("EXISTS[#<width>]"), 1.0);
        assert_eq!(ev("EXISTS[#<nope>]"), 0.0);
        assert!((ev("LN[EXP[2]]") - 2.0).abs() < 1e-15);
    }

    #[test]
    fn errors_name_the_column() {
        assert_eq!(err("[1 / 0]"), (4, "expression: division by zero".into()));
        assert_eq!(err("SQRT[-1]").0, 1);
        assert!(err("SQRT[-1]").1.contains("SQRT"));
        assert_eq!(err("#<nope>"), (1, "parameter #<nope> is not set".into()));
        assert!(err("#0").1.contains("parameter number"));
        assert!(err("#6000").1.contains("parameter number"));
        assert_eq!(err("[1 + 2").0, 7);
        assert!(err("FOO[1]").1.contains("unknown function"));
        assert!(err("[10 ** 400]").1.contains("too large"));
        assert!(err("[1 + ]").1.contains("expected"));
    }

    #[test]
    fn subroutine_scopes() {
        let mut p = Params::default();
        p.set(&ParamRef::Numbered(1), 5.0);
        p.set(&ParamRef::Named("a".into()), 1.0);
        let saved = p.enter(&[9.0, 8.0]);
        assert_eq!(
            (p.numbered(1), p.numbered(2), p.numbered(3)),
            (9.0, 8.0, 0.0)
        );
        assert_eq!(p.named("a"), None);
        p.set(&ParamRef::Named("a".into()), 2.0);
        p.set(&ParamRef::Named("_r".into()), 4.0);
        p.leave(&saved);
        assert_eq!(p.numbered(1), 5.0);
        assert_eq!(p.named("a"), Some(1.0));
        assert_eq!(p.named("_r"), Some(4.0));
    }
}
