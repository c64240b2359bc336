//! Tabs (`wire.tab_mm`): a run in passes that leaves the slug attached until the operator
//! has secured it.
//!
//! A wire program enters from the start hole (the `G41`/`G42` entry move), cuts the contour
//! and leaves (the `G40` exit move). With a tab the passes become one chain in the kerf:
//!
//! 1. the first pass enters and cuts the contour up to `tab_mm` before it closes (the tab's
//!    start, T);
//! 2. each later pass cuts the same stretch at its own offset and condition, forward (from
//!    the contour's start to T) or, where it says `reverse`, backward (from T). A pass that
//!    starts at the other end from where the last one stopped first travels there along the
//!    last pass's own path, spark off; then one short spark-off move across the kerf to its
//!    own offset;
//! 3. the job pauses ("secure the slug");
//! 4. the tab is cut with the last pass's offset and condition, and the exit takes the wire
//!    back to the start hole. After a forward pass that is the tab and the exit as
//!    programmed; after a reversed one (standing at the contour's start) the tab is cut
//!    backward from the contour's closing point, and the wire travels back over the tab it
//!    has just cut to where the exit starts.
//!
//! The contour is split at its length minus the tab (lines, arcs and NURBS alike, exactly:
//! [`crate::gcode::Block::split_at_length`]). The plan is a pure function of the passes'
//! blocks, so the check and the producer cut the same blocks and a resume replays them.

use super::approach::path_approach;
use super::passes::WirePass;
use crate::gcode::{Block, BlockKind, Pause};
use crate::geometry::{NurbsCurve, Point};

/// Why a program cannot be cut with a tab.
#[derive(Debug, thiserror::Error)]
pub enum TabError {
    #[error(
        "{program}: wire.tab_mm needs a wire contour between a G41/G42 entry move and a G40 \
         exit move: {what}"
    )]
    NoContour { program: String, what: &'static str },
    #[error(
        "{program}:{entry}:1: the contour from the entry at line {entry} to the exit at line \
         {exit} is not closed (it starts at {start} and ends at {end}, {gap:.4} mm apart): a \
         tab holds the slug of a closed contour (wire.tab_mm = 0 cuts it without one)"
    )]
    NotClosed {
        program: String,
        entry: u64,
        exit: u64,
        start: String,
        end: String,
        gap: f64,
    },
    #[error(
        "{program}: wire.tab_mm = {tab} mm is not shorter than the contour ({length:.4} mm at \
         pass {pass}'s offset)"
    )]
    TooLong {
        program: String,
        tab: f64,
        length: f64,
        pass: usize,
    },
    #[error(
        "{program}: with a tab the first pass cuts forward (it enters along the entry move), \
         but [wire] pass 1 says reverse = true"
    )]
    FirstReversed { program: String },
}

/// One pass's program as read with the pass's offset: its blocks, and the lines of its
/// entry and exit moves.
#[derive(Debug, Clone)]
pub struct PassProgram {
    pub blocks: Vec<Block>,
    pub entry_line: Option<u64>,
    pub exit_line: Option<u64>,
}

impl PassProgram {
    /// A pass's program as its path made it; the entry and exit moves are where the wire
    /// offset the blocks carry ([`Block::wire_offset`]) comes on and goes off (the latest
    /// of each).
    pub fn new(blocks: Vec<Block>) -> PassProgram {
        let (mut entry_line, mut exit_line, mut on) = (None, None, false);
        for b in &blocks {
            match (on, b.wire_offset.is_some()) {
                (false, true) => entry_line = Some(b.line),
                (true, false) => exit_line = Some(b.line),
                _ => {}
            }
            on = b.wire_offset.is_some();
        }
        PassProgram {
            blocks,
            entry_line,
            exit_line,
        }
    }
}

/// A block of the tabbed job and the pass it belongs to (the tab is the last pass's).
#[derive(Debug, Clone)]
pub struct TabbedBlock {
    pub block: Block,
    /// 1-based.
    pub pass: u8,
    /// The first block of its pass.
    pub starts_pass: bool,
}

/// A pass's program split up: up to and including the entry, the contour to the tab's start,
/// the tab, the exit and what follows it.
#[derive(Debug)]
struct Parts {
    before: Vec<Block>,
    cut: Vec<Block>,
    tab: Vec<Block>,
    after: Vec<Block>,
}

impl Parts {
    fn start(&self) -> Point {
        self.cut[0].start()
    }

    fn tab_start(&self) -> Point {
        self.cut.last().expect("a cut").end()
    }
}

/// The tabbed job: every pass in `passes` (read with the offsets of `table`), leaving a tab of
/// `tab_mm`, then the slug's pause, then the tab. `feed_mm_per_min`: the spark-off travel's.
pub fn plan(
    passes: Vec<PassProgram>,
    table: &[WirePass],
    tab_mm: f64,
    feed_mm_per_min: f64,
    program: &str,
) -> Result<Vec<TabbedBlock>, TabError> {
    if table.first().is_some_and(|p| p.reverse) {
        return Err(TabError::FirstReversed {
            program: program.to_string(),
        });
    }
    let parts = passes
        .into_iter()
        .zip(table)
        .enumerate()
        .map(|(k, (pass, t))| split(pass, t.offset_mm, tab_mm, k + 1, program))
        .collect::<Result<Vec<_>, _>>()?;
    let travel = |b: Block| path_approach(b, feed_mm_per_min);
    let mut out = Vec::new();
    let mut emit = |blocks: Vec<Block>, pass: usize, starts: bool| {
        for (i, block) in blocks.into_iter().enumerate() {
            out.push(TabbedBlock {
                block,
                pass: u8::try_from(pass).unwrap_or(u8::MAX),
                starts_pass: starts && i == 0,
            });
        }
    };
    let first = &parts[0];
    emit(
        first.before.iter().chain(&first.cut).cloned().collect(),
        1,
        true,
    );
    // Where the wire stands: at the tab's start (after a forward pass) or the contour's start.
    let mut at_tab = true;
    let mut here = first.tab_start();
    for (k, (p, t)) in parts.iter().zip(table).enumerate().skip(1) {
        let last = &parts[k - 1];
        let mut blocks = Vec::new();
        if t.reverse {
            if !at_tab {
                blocks.extend(last.cut.iter().cloned().map(travel));
                here = last.tab_start();
            }
            blocks.extend(across(&here, &p.tab_start(), &p.cut[0], feed_mm_per_min));
            blocks.extend(p.cut.iter().rev().map(Block::reversed));
            here = p.start();
        } else {
            if at_tab {
                blocks.extend(last.cut.iter().rev().map(|b| travel(b.reversed())));
                here = last.start();
            }
            blocks.extend(across(&here, &p.start(), &p.cut[0], feed_mm_per_min));
            blocks.extend(p.cut.iter().cloned());
            here = p.tab_start();
        }
        at_tab = !t.reverse;
        emit(blocks, k + 1, true);
    }
    let last = parts.last().expect("one pass at least");
    let mut blocks = Vec::new();
    if at_tab {
        blocks.extend(last.tab.iter().cloned());
    } else {
        // From the contour's start to its closing point (the same point where the contour
        // has no corner there), the tab backward, and back over it to where the exit starts.
        let closing = last.tab.last().expect("a tab").end();
        blocks.extend(across(&here, &closing, &last.tab[0], feed_mm_per_min));
        blocks.extend(last.tab.iter().rev().map(Block::reversed));
        blocks.extend(last.tab.iter().cloned().map(travel));
    }
    blocks.extend(last.after.iter().cloned());
    let line = blocks[0].line;
    blocks[0].pause = Some((line, Pause::Slug));
    emit(blocks, parts.len(), false);
    Ok(out)
}

/// A short spark-off move from `from` to `to` (none where they meet), as `template`'s line.
fn across(from: &Point, to: &Point, template: &Block, feed_mm_per_min: f64) -> Option<Block> {
    if (from - to).norm() < 1e-9 {
        return None;
    }
    let curve = NurbsCurve::line(template.curve.dim(), from, to).ok()?;
    let mut block = template.clone();
    block.kind = BlockKind::Line;
    block.curve = curve;
    Some(path_approach(block, feed_mm_per_min))
}

/// Splits a pass's program into its parts, the contour cut `tab_mm` before it closes.
fn split(
    pass: PassProgram,
    offset_mm: f64,
    tab_mm: f64,
    number: usize,
    program: &str,
) -> Result<Parts, TabError> {
    let no_contour = |what| TabError::NoContour {
        program: program.to_string(),
        what,
    };
    let entry = pass
        .entry_line
        .ok_or_else(|| no_contour("there is no G41/G42 entry move"))?;
    let exit = pass
        .exit_line
        .ok_or_else(|| no_contour("there is no G40 exit move"))?;
    let mut blocks = pass.blocks;
    let first_entry = blocks
        .iter()
        .position(|b| b.line == entry)
        .ok_or_else(|| no_contour("the entry move has no motion"))?;
    let contour_from = first_entry
        + blocks[first_entry..]
            .iter()
            .take_while(|b| b.line == entry)
            .count();
    let contour_to = contour_from
        + blocks[contour_from..]
            .iter()
            .position(|b| b.line == exit)
            .ok_or_else(|| no_contour("the exit move comes before the entry"))?;
    if contour_to == contour_from {
        return Err(no_contour("no move lies between the entry and the exit"));
    }
    let after = blocks.split_off(contour_to);
    let contour = blocks.split_off(contour_from);
    let before = blocks;
    let (start, end) = (contour[0].start(), contour.last().expect("a move").end());
    // The offset contour of a closed program closes up to the corner at its closing point,
    // in the program's plane (X Y): a tapered contour's upper guide (U V) meets its start at
    // another corner offset, and the tab is cut where the lower one closes.
    let gap = (end - start).fixed_rows::<2>(0).norm();
    if gap > 2.0 * offset_mm + 1e-3 {
        let at = |p: &Point| format!("X{:.4} Y{:.4}", p[0], p[1]);
        return Err(TabError::NotClosed {
            program: program.to_string(),
            entry,
            exit,
            start: at(&start),
            end: at(&end),
            gap,
        });
    }
    let lengths: Vec<f64> = contour.iter().map(|b| b.curve.length()).collect();
    let length: f64 = lengths.iter().sum();
    if tab_mm >= length {
        return Err(TabError::TooLong {
            program: program.to_string(),
            tab: tab_mm,
            length,
            pass: number,
        });
    }
    let (cut, tab) = cut_at(contour, &lengths, length - tab_mm);
    Ok(Parts {
        before,
        cut,
        tab,
        after,
    })
}

/// The contour's blocks up to `at` mm of its length, and the rest.
fn cut_at(contour: Vec<Block>, lengths: &[f64], at: f64) -> (Vec<Block>, Vec<Block>) {
    let mut cut = Vec::new();
    let mut tab = Vec::new();
    let mut done = 0.0;
    for (block, &length) in contour.into_iter().zip(lengths) {
        if done + length <= at {
            cut.push(block);
        } else if done >= at {
            tab.push(block);
        } else {
            match block.split_at_length(at - done) {
                Some((a, b)) => {
                    cut.push(a);
                    tab.push(b);
                }
                None => tab.push(block),
            }
        }
        done += length;
    }
    (cut, tab)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::point;

    fn line(n: u64, a: [f64; 2], b: [f64; 2]) -> Block {
        let curve = NurbsCurve::line(2, &point(&a), &point(&b)).unwrap();
        Block::new(n, BlockKind::Line, curve, Some(60.0))
    }

    /// A 10 mm square die, entered from (5, 5) along +X at offset `d` (drawn as if offset,
    /// which is all the plan looks at).
    fn square() -> PassProgram {
        PassProgram {
            blocks: vec![
                line(2, [5.0, 5.0], [10.0, 5.0]),
                line(3, [10.0, 5.0], [10.0, 10.0]),
                line(4, [10.0, 10.0], [0.0, 10.0]),
                line(5, [0.0, 10.0], [0.0, 0.0]),
                line(6, [0.0, 0.0], [10.0, 0.0]),
                line(7, [10.0, 0.0], [10.0, 5.0]),
                line(8, [10.0, 5.0], [5.0, 5.0]),
            ],
            entry_line: Some(2),
            exit_line: Some(8),
        }
    }

    fn pass(reverse: bool) -> WirePass {
        WirePass {
            offset_mm: 0.1,
            condition: 1,
            feed_mm_per_min: None,
            reverse,
        }
    }

    fn cutting_length(blocks: &[TabbedBlock], pass: u8) -> f64 {
        blocks
            .iter()
            .filter(|b| b.pass == pass && b.block.spark_off.is_none())
            .map(|b| b.block.curve.length())
            .sum()
    }

    #[test]
    fn passes_stop_at_the_tab_and_the_tab_is_cut_after_the_slug_pause() {
        for reverse_last in [false, true] {
            let table = [pass(false), pass(true), pass(reverse_last)];
            let blocks = plan(vec![square(); 3], &table, 2.0, 60.0, "p").unwrap();
            // Pass 1: the entry and the contour less the tab (40 - 2 mm).
            assert!((cutting_length(&blocks, 1) - (5.0 + 38.0)).abs() < 1e-9);
            assert!((cutting_length(&blocks, 2) - 38.0).abs() < 1e-9);
            // Pass 3 cuts the contour and, after the pause, the tab and the exit.
            assert!((cutting_length(&blocks, 3) - (38.0 + 2.0 + 5.0)).abs() < 1e-9);
            let paused: Vec<_> = blocks.iter().filter(|b| b.block.pause.is_some()).collect();
            assert_eq!(paused.len(), 1);
            assert_eq!(paused[0].block.pause.unwrap().1, Pause::Slug);
            // Each block starts where the last ended, and the job ends at the start hole.
            for w in blocks.windows(2) {
                assert!((w[0].block.end() - w[1].block.start()).norm() < 1e-9);
            }
            let end = blocks.last().unwrap().block.end();
            assert!((end - point(&[5.0, 5.0])).norm() < 1e-9);
            // The tab's cut starts 2 mm before the contour closes, at (10, 3), or ends there.
            let tab: Vec<_> = blocks
                .iter()
                .skip_while(|b| b.block.pause.is_none())
                .filter(|b| b.block.spark_off.is_none())
                .collect();
            let t = point(&[10.0, 3.0]);
            let touches = |b: &TabbedBlock| {
                (b.block.start() - t).norm() < 1e-9 || (b.block.end() - t).norm() < 1e-9
            };
            assert!(
                tab.iter().any(|b| touches(b)),
                "reverse_last {reverse_last}"
            );
        }
    }

    /// A tapered contour: the upper guide (U V) leans another way at the closing point than
    /// at the start (its corner offsets differ by 0.6 mm), the program plane (X Y)
    /// closes: the tab is planned.
    #[test]
    fn a_tapered_contour_closes_in_the_program_plane() {
        let line4 = |n: u64, a: [f64; 4], b: [f64; 4]| {
            let curve = NurbsCurve::line(4, &point(&a), &point(&b)).unwrap();
            Block::new(n, BlockKind::Line, curve, Some(60.0))
        };
        let tapered = PassProgram {
            blocks: vec![
                line4(2, [5.0, 5.0, 0.0, 0.0], [10.0, 5.0, 0.4, 0.0]),
                line4(3, [10.0, 5.0, 0.4, 0.0], [10.0, 10.0, 0.4, 0.4]),
                line4(4, [10.0, 10.0, 0.4, 0.4], [0.0, 10.0, -0.4, 0.4]),
                line4(5, [0.0, 10.0, -0.4, 0.4], [0.0, 0.0, -0.4, -0.4]),
                line4(6, [0.0, 0.0, -0.4, -0.4], [10.0, 0.0, 0.4, -0.4]),
                line4(7, [10.0, 0.0, 0.4, -0.4], [10.0, 5.0, 0.4, 0.6]),
                line4(8, [10.0, 5.0, 0.4, 0.6], [5.0, 5.0, 0.0, 0.0]),
            ],
            entry_line: Some(2),
            exit_line: Some(8),
        };
        // The contour ends 0.6 mm from its start in U V, 0 in X Y.
        let blocks = plan(vec![tapered], &[pass(false)], 2.0, 60.0, "p").unwrap();
        let paused = blocks.iter().filter(|b| b.block.pause.is_some()).count();
        assert_eq!(paused, 1, "the slug pause before the tab");
    }

    #[test]
    fn refusals() {
        let open = PassProgram {
            blocks: vec![
                line(2, [5.0, 5.0], [10.0, 5.0]),
                line(3, [10.0, 5.0], [10.0, 10.0]),
                line(4, [10.0, 10.0], [5.0, 5.0]),
            ],
            entry_line: Some(2),
            exit_line: Some(4),
        };
        let err = plan(vec![open], &[pass(false)], 1.0, 60.0, "p").unwrap_err();
        assert!(err.to_string().starts_with("p:2:1: the contour"), "{err}");
        let err = plan(vec![square()], &[pass(true)], 1.0, 60.0, "p").unwrap_err();
        assert!(matches!(err, TabError::FirstReversed { .. }));
        let err = plan(vec![square()], &[pass(false)], 45.0, 60.0, "p").unwrap_err();
        assert!(matches!(err, TabError::TooLong { .. }));
        let mut bare = square();
        bare.entry_line = None;
        let err = plan(vec![bare], &[pass(false)], 1.0, 60.0, "p").unwrap_err();
        assert!(matches!(err, TabError::NoContour { .. }));
    }
}
