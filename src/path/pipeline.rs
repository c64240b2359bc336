//! One reading of a program through the stages: the reader's moves in, the blocks the
//! machine cuts out, one at a time, holding no more than the stages look ahead.

use std::collections::VecDeque;
use std::io::{BufRead, Seek};

use super::from_line::Gate;
use super::orbit::Orbiting;
use super::passes::{PassStage, Reversal};
use super::taper::Taper;
use super::wire_offset::WireOffsetStage;
use super::{PathError, Stage, StageError};
use crate::gcode::{Block, BlockReader};

/// How many stages a path has (those a job does not use pass blocks on unchanged).
const STAGES: usize = 6;

/// The stages, in the order blocks go through them.
struct Stages {
    wire_offset: WireOffsetStage,
    taper: Taper,
    orbit: Orbiting,
    pass: Option<PassStage>,
    gate: Option<Gate>,
    reversal: Option<Reversal>,
}

impl Stages {
    fn get(&mut self, i: usize) -> Option<&mut dyn Stage> {
        match i {
            0 => Some(&mut self.wire_offset),
            1 => Some(&mut self.taper),
            2 => Some(&mut self.orbit),
            3 => self.pass.as_mut().map(|s| s as &mut dyn Stage),
            4 => self.gate.as_mut().map(|s| s as &mut dyn Stage),
            5 => self.reversal.as_mut().map(|s| s as &mut dyn Stage),
            _ => None,
        }
    }
}

/// A program read through its path: an iterator of the blocks the machine cuts.
pub struct Pipeline<R> {
    reader: BlockReader<R>,
    stages: Stages,
    /// `queues[i]`: what stage `i` made final, for stage `i + 1` (the last: to hand out).
    queues: [VecDeque<Block>; STAGES],
    /// The reader has ended; then the stages finish one by one, each one's last blocks
    /// going through the ones after it before the next finishes.
    read_all: bool,
    finished: usize,
    failed: bool,
}

impl<R: BufRead + Seek> Pipeline<R> {
    /// The program's own path (wire offset, taper, orbit) over what `reader` reads, with the
    /// reader's options.
    pub fn new(reader: BlockReader<R>) -> Pipeline<R> {
        let options = reader.options();
        let axes = reader.axes();
        let tolerance = options.offset_tolerance_mm;
        let stages = Stages {
            wire_offset: WireOffsetStage::new(axes, tolerance),
            taper: Taper::new(axes, options.guides, options.thickness_mm, tolerance),
            orbit: Orbiting::new(axes, options.orbit.clone(), tolerance),
            pass: None,
            gate: None,
            reversal: None,
        };
        Pipeline {
            reader,
            stages,
            queues: Default::default(),
            read_all: false,
            finished: 0,
            failed: false,
        }
    }

    /// Every block cut in a pass's condition, at most its feed.
    pub fn with_pass(mut self, pass: PassStage) -> Self {
        self.stages.pass = Some(pass);
        self
    }

    /// The blocks before a line moved (or left out) as its approach says.
    pub fn with_gate(mut self, gate: Gate) -> Self {
        self.stages.gate = Some(gate);
        self
    }

    /// The whole path cut the other way round.
    pub fn reversed(mut self) -> Self {
        self.stages.reversal = Some(Reversal::default());
        self
    }

    /// The reader (its warnings, the work offsets and modes the program leaves).
    pub fn reader(&mut self) -> &mut BlockReader<R> {
        &mut self.reader
    }

    /// The path a run from a line has left out since last asked (mm; 0 without one).
    pub fn take_skipped_mm(&mut self) -> f64 {
        self.stages.gate.as_mut().map_or(0.0, Gate::take_skipped_mm)
    }

    fn next_block(&mut self) -> Result<Option<Block>, PathError> {
        let last = STAGES - 1;
        loop {
            if let Some(block) = self.queues[last].pop_front() {
                return Ok(Some(block));
            }
            // The deepest block first: a stage sees the next block only when the ones
            // after it have taken everything it made.
            if let Some(i) = (0..last).rev().find(|&i| !self.queues[i].is_empty()) {
                let block = self.queues[i].pop_front().expect("not empty");
                if let Some(out) = self.feed(i + 1, block)? {
                    return Ok(Some(out));
                }
                continue;
            }
            if !self.read_all {
                match self.reader.next() {
                    Some(Ok(block)) => {
                        if let Some(out) = self.feed(0, block)? {
                            return Ok(Some(out));
                        }
                    }
                    Some(Err(e)) => return Err(e.into()),
                    None => self.read_all = true,
                }
                continue;
            }
            if self.finished == STAGES {
                return Ok(None);
            }
            let i = self.finished;
            self.finished += 1;
            if let Some(stage) = self.stages.get(i) {
                let done = stage.finish(&mut self.queues[i]);
                done.map_err(|e| self.located(e))?;
            }
        }
    }

    /// Hands `block` to stage `i`, past the stages that would pass it on unchanged (every
    /// queue after the one it came from is empty: nothing it would overtake). The block
    /// itself when every stage passed it.
    fn feed(&mut self, mut i: usize, block: Block) -> Result<Option<Block>, PathError> {
        while i < STAGES {
            match self.stages.get(i) {
                Some(stage) if !stage.passes(&block) => {
                    let pushed = stage.push(block, &mut self.queues[i]);
                    pushed.map_err(|e| self.located(e))?;
                    return Ok(None);
                }
                _ => i += 1,
            }
        }
        Ok(Some(block))
    }

    fn located(&self, e: StageError) -> PathError {
        match e {
            StageError::Move { line, kind } => self.reader.error_at_line(line, kind).into(),
            StageError::Job(e) => e,
        }
    }
}

impl<R: BufRead + Seek> Iterator for Pipeline<R> {
    type Item = Result<Block, PathError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        match self.next_block() {
            Ok(Some(b)) => Some(Ok(b)),
            Ok(None) => None,
            Err(e) => {
                self.failed = true;
                Some(Err(e))
            }
        }
    }
}
