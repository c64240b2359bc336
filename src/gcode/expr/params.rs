//! The parameter store (numbered, global named, per-call local) and what an expression may
//! read from its reader ([`Env`]).

use std::collections::HashMap;

use super::{ARGUMENTS, NUMBERED_MAX};

/// A parameter named on the left of `=` or read in an expression.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum ParamRef {
    Numbered(usize),
    /// Lower-case, without spaces.
    Named(String),
}

impl std::fmt::Display for ParamRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ParamRef::Numbered(n) => write!(f, "#{n}"),
            ParamRef::Named(name) => write!(f, "#<{name}>"),
        }
    }
}

/// Where parameter values come from.
pub(crate) trait Env {
    fn numbered(&self, n: usize) -> f64;
    fn named(&self, name: &str) -> Option<f64>;
    /// The parameter is the interpreter's own and a program may not assign it.
    fn read_only(&self, _param: &ParamRef) -> bool {
        false
    }
}

/// The parameter store: numbered, global and per-call local named parameters.
#[derive(Debug, Clone)]
pub(crate) struct Params {
    numbered: Vec<f64>,
    globals: HashMap<String, f64>,
    /// Local named parameters, one map per active call (index 0: the main program).
    locals: Vec<HashMap<String, f64>>,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            numbered: vec![0.0; NUMBERED_MAX + 1],
            globals: HashMap::new(),
            locals: vec![HashMap::new()],
        }
    }
}

impl Params {
    pub(crate) fn numbered(&self, n: usize) -> f64 {
        self.numbered.get(n).copied().unwrap_or(0.0)
    }

    pub(crate) fn named(&self, name: &str) -> Option<f64> {
        if name.starts_with('_') {
            self.globals.get(name).copied()
        } else {
            self.locals.last().and_then(|m| m.get(name)).copied()
        }
    }

    pub(crate) fn set(&mut self, target: &ParamRef, value: f64) {
        match target {
            ParamRef::Numbered(n) => {
                if let Some(slot) = self.numbered.get_mut(*n) {
                    *slot = value;
                }
            }
            ParamRef::Named(name) if name.starts_with('_') => {
                self.globals.insert(name.clone(), value);
            }
            ParamRef::Named(name) => {
                if let Some(m) = self.locals.last_mut() {
                    m.insert(name.clone(), value);
                }
            }
        }
    }

    /// Enters a subroutine: saves `#1`…`#30`, sets them to `args` (the rest 0), opens a fresh
    /// local scope. Returns the saved arguments for [`Params::leave`].
    pub(crate) fn enter(&mut self, args: &[f64]) -> [f64; ARGUMENTS] {
        let mut saved = [0.0; ARGUMENTS];
        saved.copy_from_slice(&self.numbered[1..=ARGUMENTS]);
        for (i, slot) in self.numbered[1..=ARGUMENTS].iter_mut().enumerate() {
            *slot = args.get(i).copied().unwrap_or(0.0);
        }
        self.locals.push(HashMap::new());
        saved
    }

    /// Leaves a subroutine: restores `#1`…`#30` and drops its locals.
    pub(crate) fn leave(&mut self, saved: &[f64; ARGUMENTS]) {
        self.numbered[1..=ARGUMENTS].copy_from_slice(saved);
        if self.locals.len() > 1 {
            self.locals.pop();
        }
    }
}
