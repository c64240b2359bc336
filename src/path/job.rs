//! A job's path: the program read once per pass (or once), through its stages, as one
//! stream of blocks with the passes' starts marked, built from one [`PathSpec`].

use std::collections::VecDeque;
use std::io::{BufRead, Seek};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use super::from_line::{ApproachPlan, FromLine, Gate};
use super::passes::{self, PassStage, WirePass};
use super::tabs::{self, PassProgram, TabbedBlock};
use super::{PathError, Pipeline};
use crate::gcode::{
    Block, BlockKind, BlockReader, GcodeError, ProgramOptions, StartModes, Warning, WorkOffsets,
    WorkStart, WorkSystem,
};
use crate::geometry::Point;
use crate::vocab::Axis;

/// What a job cuts of its program: all of it once (the default), from a line, or once per
/// pass of the technology table.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CutPlan {
    pub from_line: Option<FromLine>,
    pub passes: Vec<WirePass>,
    /// In passes: the tab left (mm; 0: none), see [`tabs`].
    pub tab_mm: f64,
    /// A dry run: every feed move at this feed (mm/min), in place of its programmed one. It
    /// cuts nothing (the spark is off, the servo out of the loop).
    pub dry_run_feed_mm_per_min: Option<f64>,
    /// A run from a line that recovers a stopped job of the same program: where that job
    /// stopped (machine mm), the end of the kerf it cut (see [`super::from_line`]).
    pub kerf_end: Option<Point>,
}

impl CutPlan {
    /// Where the wire stands as the job starts, when it is not where the program starts: a
    /// run from a line from where a stopped job stopped.
    pub fn wire_stands(&self) -> Option<&Point> {
        self.from_line
            .filter(|f| f.wire_at == super::from_line::WireAt::Stopped)
            .and(self.kerf_end.as_ref())
    }

    /// Passes that leave a tab.
    pub fn tabbed(&self) -> bool {
        self.tab_mm > 0.0 && !self.passes.is_empty()
    }

    /// `block` as this plan moves it: a dry run's feed moves at the dry run's feed.
    fn moved(&self, mut block: Block) -> Block {
        if let Some(feed) = self.dry_run_feed_mm_per_min
            && !matches!(block.kind, BlockKind::Rapid | BlockKind::Probe(_))
        {
            block.feed_mm_per_min = Some(feed);
        }
        block
    }
}

/// Everything a job's path is made from: plain settings, read from the configuration once.
#[derive(Debug, Clone, PartialEq)]
pub struct PathSpec {
    pub axes: Vec<Axis>,
    /// How the program reads.
    pub program: ProgramOptions,
    /// Where the job starts: the machine position, the work offsets and the active system.
    pub work: WorkStart,
    /// What of the program is cut.
    pub cut: CutPlan,
    /// The feed of a run from a line's approach and of a tabbed run's travel, mm/min.
    pub approach_feed_mm_per_min: f64,
    /// The height a direct approach crosses at.
    pub safe_z_mm: Option<f64>,
}

impl PathSpec {
    /// Where the machine stands as the job starts: where the program starts ([`Self::work`]),
    /// unless the wire stands elsewhere ([`CutPlan::wire_stands`]).
    pub fn machine_start(&self) -> WorkStart {
        match self.cut.wire_stands() {
            Some(at) => WorkStart {
                position_mm: *at,
                ..self.work.clone()
            },
            None => self.work.clone(),
        }
    }
}

/// What a job's path hands on.
// Handed on one at a time by value, never kept in bulk: a box would cost an allocation per
// block for nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum PathItem {
    /// The next block to cut.
    Block(Block),
    /// The blocks after this are pass `pass` (from 1) of the table; `at_start_hole`: it
    /// starts there (every pass does but those of a tabbed run after the first).
    PassStart { pass: u8, at_start_hole: bool },
    /// A run from a line's direct approach left this much of the program's path out (mm;
    /// its own moves counted against it), before the block that follows.
    Skipped { mm: f64 },
}

/// A job's path: the runs of the program its spec asks for, one after the other.
pub struct JobPath<'s, R, F> {
    spec: &'s PathSpec,
    name: String,
    /// Opens the program for one run, read with the options given.
    open: F,
    cancel: Option<Arc<AtomicBool>>,
    /// The runs not yet started: a pass (number from 1, the pass), or the one run without.
    runs: VecDeque<Option<(u8, WirePass)>>,
    current: Option<Pipeline<R>>,
    /// A run from a line: its gate is on the first run opened only (the pass it is cut
    /// in); the later passes are cut whole.
    gated: bool,
    /// Where the last block handed on ends (machine mm): where the next run starts.
    last_end: Option<Point>,
    /// A tabbed job's blocks, planned once every pass is read.
    planned: Option<VecDeque<TabbedBlock>>,
    items: VecDeque<PathItem>,
    warnings: Option<Vec<Warning>>,
    left: Option<(WorkOffsets, WorkSystem, StartModes)>,
}

impl<'s, R, F> JobPath<'s, R, F>
where
    R: BufRead + Seek,
    F: FnMut(ProgramOptions) -> Result<BlockReader<R>, GcodeError>,
{
    /// The path of program `name` (as errors name it) as `spec` cuts it, each run opened by
    /// `open`; every reader gives up at its next line once `cancel` is set.
    pub fn new(spec: &'s PathSpec, name: &str, open: F, cancel: Option<Arc<AtomicBool>>) -> Self {
        let runs = if spec.cut.passes.is_empty() {
            VecDeque::from([None])
        } else if spec.cut.tabbed() {
            VecDeque::new()
        } else {
            // A run from a line in pass k starts with pass k.
            let first = spec.cut.from_line.and_then(|f| f.pass).unwrap_or(1);
            (1..)
                .zip(&spec.cut.passes)
                .skip(usize::from(first.max(1)) - 1)
                .map(|(n, p)| Some((n, *p)))
                .collect()
        };
        JobPath {
            spec,
            name: name.to_string(),
            open,
            cancel,
            runs,
            current: None,
            gated: false,
            last_end: None,
            planned: None,
            items: VecDeque::new(),
            warnings: None,
            left: None,
        }
    }

    /// The next item, `None` at the job's end.
    pub fn next_item(&mut self) -> Result<Option<PathItem>, PathError> {
        loop {
            if let Some(item) = self.items.pop_front() {
                return Ok(Some(item));
            }
            if self.spec.cut.tabbed() {
                return self.next_tabbed();
            }
            if let Some(run) = &mut self.current {
                match run.next() {
                    Some(Ok(block)) => {
                        let block = self.spec.cut.moved(block);
                        self.last_end = Some(block.end());
                        let mm = run.take_skipped_mm();
                        if mm == 0.0 {
                            return Ok(Some(PathItem::Block(block)));
                        }
                        self.items.push_back(PathItem::Block(block));
                        return Ok(Some(PathItem::Skipped { mm }));
                    }
                    Some(Err(e)) => return Err(e),
                    None => {
                        let mut run = self.current.take().expect("a run");
                        self.ended(&mut run);
                    }
                }
                continue;
            }
            let Some(run) = self.runs.pop_front() else {
                return Ok(None);
            };
            let pass = run.map(|(_, p)| p);
            let mut pipeline = self.open_run(pass.as_ref())?;
            if let Some((number, pass)) = run {
                if pass.reverse {
                    pipeline = pipeline.reversed();
                }
                self.items.push_back(PathItem::PassStart {
                    pass: number,
                    at_start_hole: true,
                });
            }
            self.current = Some(pipeline);
        }
    }

    /// A probing move ended at `at` (machine mm), touching or not: the program reads on
    /// from there.
    pub fn probed(&mut self, at: &Point, contact: bool) {
        if let Some(run) = &mut self.current {
            run.reader().probed(at, contact);
        }
    }

    /// The program's warnings, from its first run (every run reads the same text).
    pub fn take_warnings(&mut self) -> Vec<Warning> {
        self.warnings.take().unwrap_or_default()
    }

    /// The work offsets and the active system where the program is now read to (`None`
    /// between runs and in a tabbed job, read whole first).
    pub fn in_force(&mut self) -> Option<(WorkOffsets, WorkSystem)> {
        let reader = self.current.as_mut()?.reader();
        Some((reader.work_offsets(), reader.work_system()))
    }

    /// The work offsets, the active system and the modes the last run left.
    pub fn left(&self) -> Option<&(WorkOffsets, WorkSystem, StartModes)> {
        self.left.as_ref()
    }

    /// One run of the program: with `pass`'s offsets, condition and feed, and the approach
    /// of a run from a line.
    fn open_run(&mut self, pass: Option<&WirePass>) -> Result<Pipeline<R>, PathError> {
        let spec = self.spec;
        let mut reader = (self.open)(passes::options(&spec.program, pass))?;
        if let Some(cancel) = &self.cancel {
            reader.cancel_on(cancel.clone());
        }
        // A run starts where the one before it ended: the start hole, every pass ending
        // where it started, but after a pass cut from a line (which started where the wire
        // stood) only there.
        match self.last_end {
            Some(end) => reader.start_at(&WorkStart {
                position_mm: end,
                ..spec.work.clone()
            }),
            None => reader.start_at(&spec.work),
        }
        let mut pipeline = Pipeline::new(reader);
        if let Some(pass) = pass {
            pipeline = pipeline.with_pass(PassStage::new(*pass, &self.name));
        }
        if let Some(from) = spec.cut.from_line.filter(|_| !self.gated) {
            self.gated = true;
            let approach = ApproachPlan {
                origin: spec.machine_start().position_mm,
                axes: spec.axes.clone(),
                safe_z_mm: spec.safe_z_mm,
                feed_mm_per_min: spec.approach_feed_mm_per_min,
                kerf_end: spec.cut.kerf_end,
                work: spec.work.clone(),
            };
            pipeline = pipeline.with_gate(Gate::new(from, &self.name, approach));
        }
        Ok(pipeline)
    }

    /// A run read to its end: the warnings of the first, what the last leaves.
    fn ended(&mut self, run: &mut Pipeline<R>) {
        let reader = run.reader();
        if self.warnings.is_none() {
            self.warnings = Some(reader.take_warnings());
        }
        self.left = Some((reader.work_offsets(), reader.work_system(), reader.modes()));
    }

    /// A tabbed job: every pass read whole, the chain planned ([`tabs::plan`]), then handed
    /// on with each pass's start marked (only the first starts at the start hole).
    fn next_tabbed(&mut self) -> Result<Option<PathItem>, PathError> {
        if self.planned.is_none() {
            let spec = self.spec;
            let mut read = Vec::new();
            for pass in &spec.cut.passes {
                let mut run = self.open_run(Some(pass))?;
                let blocks = run.by_ref().collect::<Result<Vec<_>, _>>()?;
                self.ended(&mut run);
                read.push(PassProgram::new(blocks));
            }
            let planned = tabs::plan(
                read,
                &spec.cut.passes,
                spec.cut.tab_mm,
                spec.approach_feed_mm_per_min,
                &self.name,
            )?;
            self.planned = Some(planned.into());
        }
        let planned = self.planned.as_mut().expect("planned");
        let Some(b) = planned.pop_front() else {
            return Ok(None);
        };
        if b.starts_pass {
            self.items.push_back(PathItem::Block(b.block));
            return Ok(Some(PathItem::PassStart {
                pass: b.pass,
                at_start_hole: b.pass == 1,
            }));
        }
        Ok(Some(PathItem::Block(b.block)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::path::{Approach, WireAt};
    use std::io::Cursor;

    /// A die: from the start hole at the origin, `G41` round the 4 mm square, back out.
    const DIE: &str = "G21 G90 G17\nG41 D1\nG1 X0 Y-2 F600\nG1 X2 Y-2\nG1 X2 Y2\nG1 X-2 Y2\n\
                       G1 X-2 Y-2\nG1 X0 Y-2\nG40 G1 X0 Y0\nM2\n";

    fn spec(cut: CutPlan) -> PathSpec {
        PathSpec {
            axes: vec![Axis::X, Axis::Y, Axis::Z],
            program: ProgramOptions {
                d_mm: vec![0.0, 0.2],
                ..ProgramOptions::default()
            },
            work: WorkStart::default(),
            cut,
            approach_feed_mm_per_min: 120.0,
            safe_z_mm: Some(5.0),
        }
    }

    fn items(spec: &PathSpec, text: &str) -> Result<Vec<PathItem>, PathError> {
        let open = |options| {
            Ok(BlockReader::with_options(
                Cursor::new(text.as_bytes().to_vec()),
                "t.ngc",
                &spec.axes,
                options,
            ))
        };
        let mut path = JobPath::new(spec, "t.ngc", open, None);
        let mut out = Vec::new();
        while let Some(item) = path.next_item()? {
            out.push(item);
        }
        Ok(out)
    }

    fn blocks(items: &[PathItem]) -> Vec<&Block> {
        items
            .iter()
            .filter_map(|i| match i {
                PathItem::Block(b) => Some(b),
                _ => None,
            })
            .collect()
    }

    fn pass(offset_mm: f64, condition: u32, reverse: bool) -> WirePass {
        WirePass {
            offset_mm,
            condition,
            feed_mm_per_min: Some(300.0),
            reverse,
        }
    }

    #[test]
    fn passes_are_marked_cut_at_their_offset_and_a_reversed_one_runs_backwards() {
        let whole = items(&spec(CutPlan::default()), DIE).unwrap();
        assert!(whole.iter().all(|i| matches!(i, PathItem::Block(_))));
        let cut = CutPlan {
            passes: vec![pass(0.2, 3, false), pass(0.1, 1, true)],
            ..CutPlan::default()
        };
        let got = items(&spec(cut), DIE).unwrap();
        let starts: Vec<usize> = got
            .iter()
            .enumerate()
            .filter(|(_, i)| matches!(i, PathItem::PassStart { .. }))
            .map(|(k, _)| k)
            .collect();
        assert_eq!(starts.len(), 2);
        assert_eq!(
            got[starts[1]],
            PathItem::PassStart {
                pass: 2,
                at_start_hole: true
            }
        );
        let first = blocks(&got[..starts[1]]);
        let second = blocks(&got[starts[1]..]);
        assert_eq!(first.len(), blocks(&whole).len());
        assert!(first.iter().all(|b| b.condition == 3));
        assert!(first.iter().all(|b| b.feed_mm_per_min == Some(300.0)));
        assert!(second.iter().all(|b| b.condition == 1));
        // The second pass backwards: its first move is the exit run the other way, from
        // the start hole, and it ends there.
        assert_eq!(second[0].start(), Point::zeros());
        assert_eq!(second.last().unwrap().end(), Point::zeros());
        // At 0.1 mm inside the square, not 0.2.
        let x_max = second.iter().map(|b| b.end()[0]).fold(f64::MIN, f64::max);
        assert!((x_max - 1.9).abs() < 1e-9, "{x_max}");
    }

    #[test]
    fn a_tabbed_run_marks_only_its_first_pass_at_the_start_hole() {
        let cut = CutPlan {
            passes: vec![pass(0.2, 3, false), pass(0.1, 1, true)],
            tab_mm: 1.0,
            ..CutPlan::default()
        };
        let got = items(&spec(cut), DIE).unwrap();
        let marks: Vec<&PathItem> = got
            .iter()
            .filter(|i| matches!(i, PathItem::PassStart { .. }))
            .collect();
        assert_eq!(
            marks,
            [
                &PathItem::PassStart {
                    pass: 1,
                    at_start_hole: true
                },
                &PathItem::PassStart {
                    pass: 2,
                    at_start_hole: false
                }
            ]
        );
        let all = blocks(&got);
        assert_eq!(all.last().unwrap().end(), Point::zeros());
        assert!(
            all.iter()
                .any(|b| matches!(b.pause, Some((_, crate::gcode::Pause::Slug))))
        );
    }

    /// A run from a line in pass 2 of 3, the wire standing on the contour: pass 2 is gated
    /// (its approach from where the wire stands, dark), pass 3 is whole and starts where
    /// pass 2 ended (the start hole), not where the wire stood.
    #[test]
    fn a_run_from_a_line_in_a_pass_gates_that_pass_only_and_the_next_starts_at_its_end() {
        let mut spec = spec(CutPlan {
            from_line: Some(FromLine {
                line: 6,
                approach: Approach::Path,
                pass: Some(2),
                wire_at: WireAt::StartHole,
            }),
            passes: vec![
                pass(0.2, 3, false),
                pass(0.15, 2, false),
                pass(0.1, 1, false),
            ],
            ..CutPlan::default()
        });
        spec.work.position_mm = Point::from_fn(|i, _| if i == 0 { 2.2 } else { 0.0 });
        let got = items(&spec, DIE).unwrap();
        let starts: Vec<&PathItem> = got
            .iter()
            .filter(|i| matches!(i, PathItem::PassStart { .. }))
            .collect();
        assert_eq!(starts.len(), 2, "passes 2 and 3 only: {got:?}");
        let all = blocks(&got);
        let pass2: Vec<&&Block> = all.iter().filter(|b| b.condition == 2).collect();
        let pass3: Vec<&&Block> = all.iter().filter(|b| b.condition == 1).collect();
        // Pass 2: dark up to line 6, cut from it; it starts where the wire stands.
        assert_eq!(pass2[0].start().x, 2.2);
        assert!(
            pass2
                .iter()
                .take_while(|b| b.line < 6)
                .all(|b| b.spark_off.is_some())
        );
        assert!(
            pass2
                .iter()
                .skip_while(|b| b.line < 6)
                .all(|b| b.spark_off.is_none())
        );
        // Pass 3: whole, lit, from the start hole where pass 2 ended.
        assert_eq!(pass2.last().unwrap().end(), Point::zeros());
        assert_eq!(pass3[0].start(), Point::zeros());
        assert!(pass3.iter().all(|b| b.spark_off.is_none()));
        assert_eq!(pass3[0].line, 3);
    }

    #[test]
    fn a_direct_approach_tells_the_path_it_skipped() {
        let text = "G21 G90\nG0 X0 Y0 Z5\nG1 Z-1 F60\nG1 X5\nG1 X0\nG1 Z-2\nG1 X5\nM2\n";
        let whole = items(&spec(CutPlan::default()), text).unwrap();
        let length = |items: &[PathItem]| -> f64 {
            items
                .iter()
                .map(|i| match i {
                    PathItem::Block(b) => b.curve.length(),
                    PathItem::Skipped { mm } => *mm,
                    PathItem::PassStart { .. } => 0.0,
                })
                .sum()
        };
        let from = |approach| CutPlan {
            from_line: Some(FromLine {
                line: 7,
                approach,
                pass: None,
                wire_at: WireAt::StartHole,
            }),
            ..CutPlan::default()
        };
        let direct = items(&spec(from(Approach::Direct)), text).unwrap();
        // 22 mm of program before line 7, 12 mm of approach: up to the safe height and
        // down to line 7's start (nothing across: it lies below the start).
        assert_eq!(direct[0], PathItem::Skipped { mm: 10.0 }, "{direct:?}");
        let moves = blocks(&direct);
        assert_eq!(moves.len(), 3);
        assert_eq!(moves[1].end(), moves[2].start());
        assert!(moves[..2].iter().all(|b| b.spark_off.is_some()));
        // Progress counts the whole program: what was skipped and what was moved.
        assert!((length(&direct) - length(&whole)).abs() < 1e-9);
        let along = items(&spec(from(Approach::Path)), text).unwrap();
        assert_eq!(blocks(&along).len(), blocks(&whole).len());
        assert!((length(&along) - length(&whole)).abs() < 1e-9);
        // Line 9 has no move: nothing to start from.
        let e = items(
            &spec(CutPlan {
                from_line: Some(FromLine {
                    pass: None,
                    line: 9,
                    approach: Approach::Path,
                    wire_at: WireAt::StartHole,
                }),
                ..CutPlan::default()
            }),
            text,
        )
        .unwrap_err();
        assert!(matches!(e, PathError::FromLine(_)), "{e}");
    }
}
