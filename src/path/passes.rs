//! Passes from the technology table (`[[wire.pass]]`, `--passes N`): the program run once per
//! pass, each time with the pass's wire offset in every `D` register, its condition in place of
//! every `E`, its feed as a ceiling, and, where the pass says `reverse`, the whole pass run the
//! other way round.
//!
//! A pass is a transformation of what the interpreter reads ([`options`]) and a stage over
//! the blocks it makes ([`PassStage`], [`Reversal`]), in the one path the check and the
//! producer both read, so a resume replays the same block sequence. A reversed pass is the pass's blocks in reverse order,
//! each run backwards ([`crate::gcode::Block::reversed`]): the offset path is the same, walked
//! from its end (for the usual program, in along the exit line and out along the entry).
//! Those blocks are held in memory for the pass (the program's compensated path; a wire
//! contour, not a million-line mould program). Each pass starts where the last ended, so the
//! program must end where it starts (the start hole), and it may not probe.

use std::collections::VecDeque;

use super::{Stage, StageError};
use crate::gcode::{Block, BlockKind, ProgramOptions};

/// One pass of the technology table (`[[wire.pass]]`): the wire offset (every `D` of the
/// program reads it), the condition (every `E` of the program reads it), a feed ceiling, and
/// the direction.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WirePass {
    pub offset_mm: f64,
    pub condition: u32,
    pub feed_mm_per_min: Option<f64>,
    /// Cut this pass the other way round.
    pub reverse: bool,
}

/// `D` registers a pass fills (D1 and up).
const REGISTERS: usize = 100;

/// Why a program cannot be cut in passes.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PassError {
    #[error(
        "{program}:{line}:1: a probing move cannot be cut in passes (where it stops would move \
         every pass after it)"
    )]
    Probe { program: String, line: u64 },
    #[error(
        "{program}: passes need a program that ends where it starts (the start hole), so each \
         pass starts where the last ended: it starts at {start} and ends at {end}. Start the \
         job with the wire at the program's start hole (a program that begins elsewhere: jog \
         or MDI there first), or end the program where it starts"
    )]
    NotClosed {
        program: String,
        start: String,
        end: String,
    },
    #[error("--passes {asked}: [wire] pass has {have} passes")]
    TooMany { asked: usize, have: usize },
    #[error(
        "pass {pass}: the job is not cut in passes (no technology table with passes, no \
         --passes); a run from a line without passes cuts the program as written"
    )]
    PassWithoutPasses { pass: u8 },
    #[error("pass {pass}: the job cuts {have} passes")]
    PassBeyond { pass: u8, have: usize },
    #[error(
        "pass {pass} runs the contour the other way round (reverse = true): a run from a line \
         starts in a pass that runs it as programmed (an earlier pass, this one then run \
         whole, or a later one)"
    )]
    ReversedFromLine { pass: u8 },
    #[error(
        "a job that leaves a tab (wire.tab_mm = {tab_mm}) is not run from a line: the tab is \
         planned over every pass whole; run it from a line with wire.tab_mm = 0 and cut the \
         tab's place by hand"
    )]
    TabbedFromLine { tab_mm: f64 },
    #[error(
        "--tab {tab_mm}: a tab is left by a job in passes (a technology table's, or \
         --passes N); this job cuts the program once, as written"
    )]
    TabWithoutPasses { tab_mm: f64 },
    #[error(
        "--passes: wire.pass: pass {pass}: condition = {condition} is not one of [generator] \
         condition: give the pass one that is, or define E{condition}"
    )]
    Undefined { pass: usize, condition: u32 },
}

/// A run from a line in `passes`: its pass is one of them (pass 1 where none is given), and
/// the job leaves no tab.
pub fn from_line_fits(
    from: Option<&super::FromLine>,
    passes: &[WirePass],
    tab_mm: f64,
) -> Result<(), PassError> {
    let Some(from) = from else {
        return Ok(());
    };
    match from.pass {
        Some(pass) if passes.is_empty() => Err(PassError::PassWithoutPasses { pass }),
        Some(pass) if usize::from(pass) > passes.len() => Err(PassError::PassBeyond {
            pass,
            have: passes.len(),
        }),
        Some(pass) if passes[usize::from(pass) - 1].reverse => {
            Err(PassError::ReversedFromLine { pass })
        }
        _ if !passes.is_empty() && tab_mm > 0.0 => Err(PassError::TabbedFromLine { tab_mm }),
        _ => Ok(()),
    }
}

/// The first `n` passes of the table (`n` = 0: none, the program as written), each in a
/// condition `defined` has.
pub fn first(table: &[WirePass], n: usize, defined: &[u32]) -> Result<Vec<WirePass>, PassError> {
    if n > table.len() {
        return Err(PassError::TooMany {
            asked: n,
            have: table.len(),
        });
    }
    if let Some((i, p)) = table[..n]
        .iter()
        .enumerate()
        .find(|(_, p)| !defined.contains(&p.condition))
    {
        return Err(PassError::Undefined {
            pass: i + 1,
            condition: p.condition,
        });
    }
    Ok(table[..n].to_vec())
}

#[cfg(test)]
#[test]
fn a_pass_in_a_condition_the_generator_lacks_is_refused_when_passes_are_cut() {
    let pass = |condition| WirePass {
        offset_mm: 0.1,
        condition,
        feed_mm_per_min: None,
        reverse: false,
    };
    let table = [pass(4), pass(7)];
    assert_eq!(first(&table, 1, &[4]), Ok(vec![pass(4)]));
    let e = first(&table, 2, &[1, 4]).unwrap_err();
    assert_eq!(
        e,
        PassError::Undefined {
            pass: 2,
            condition: 7
        }
    );
    assert!(
        e.to_string()
            .contains("pass 2: condition = 7 is not one of"),
        "{e}"
    );
}

/// The reader's options for `pass`: its offset in every `D` register from D1.
pub fn options(base: &ProgramOptions, pass: Option<&WirePass>) -> ProgramOptions {
    let mut options = base.clone();
    if let Some(pass) = pass {
        options.d_mm = std::iter::once(0.0)
            .chain(std::iter::repeat_n(pass.offset_mm, REGISTERS))
            .collect();
        if !options.conditions.contains(&pass.condition) {
            options.conditions.push(pass.condition);
        }
    }
    options
}

/// The pass stage: every block in the pass's condition, at most its feed.
#[derive(Debug, Clone)]
pub struct PassStage {
    pass: WirePass,
    program: String,
}

impl PassStage {
    pub fn new(pass: WirePass, program: &str) -> PassStage {
        PassStage {
            pass,
            program: program.to_string(),
        }
    }
}

impl Stage for PassStage {
    fn push(&mut self, block: Block, out: &mut VecDeque<Block>) -> Result<(), StageError> {
        out.push_back(block_of(block, &self.pass, &self.program)?);
        Ok(())
    }
}

/// A reversed pass: its blocks held to the end, then handed out last first, each run
/// backwards.
#[derive(Debug, Clone, Default)]
pub struct Reversal {
    held: Vec<Block>,
}

impl Stage for Reversal {
    fn push(&mut self, block: Block, _: &mut VecDeque<Block>) -> Result<(), StageError> {
        self.held.push(block);
        Ok(())
    }

    fn finish(&mut self, out: &mut VecDeque<Block>) -> Result<(), StageError> {
        out.extend(self.held.drain(..).rev().map(|b| b.reversed()));
        Ok(())
    }
}

/// A block as `pass` cuts it: in its condition, at most its feed.
fn block_of(mut block: Block, pass: &WirePass, program: &str) -> Result<Block, PassError> {
    if matches!(block.kind, BlockKind::Probe(_)) {
        return Err(PassError::Probe {
            program: program.to_string(),
            line: block.line,
        });
    }
    block.condition = pass.condition;
    if let (Some(cap), false) = (pass.feed_mm_per_min, block.kind == BlockKind::Rapid) {
        block.feed_mm_per_min = Some(block.feed_mm_per_min.map_or(cap, |f| f.min(cap)));
    }
    Ok(block)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{NurbsCurve, Point};

    const PASS: WirePass = WirePass {
        offset_mm: 0.12,
        condition: 3,
        feed_mm_per_min: Some(5.0),
        reverse: false,
    };

    #[test]
    fn a_pass_sets_every_register_the_condition_and_the_feed_ceiling() {
        let options = options(&ProgramOptions::default(), Some(&PASS));
        assert_eq!(options.d_mm[0], 0.0);
        assert!(options.d_mm[1..].iter().all(|&d| d == 0.12));
        let line = NurbsCurve::line(
            2,
            &Point::zeros(),
            &Point::from_fn(|i, _| f64::from(i == 0)),
        )
        .unwrap();
        let b = block_of(Block::new(4, BlockKind::Line, line, Some(60.0)), &PASS, "p").unwrap();
        assert_eq!((b.condition, b.feed_mm_per_min), (3, Some(5.0)));
        assert!(first(&[PASS], 2, &[3]).is_err());
        assert_eq!(first(&[PASS, PASS], 1, &[3]).unwrap().len(), 1);
    }
}
