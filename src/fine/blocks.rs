//! The block in hand and the pulse ledger: taking the next block from the source and
//! entering it (its condition, its excursions, its lattice walk), booking every step a tick
//! returns, and a resumed job's walk along the program, emitting nothing, to its checkpoint's
//! point. Every phase of a tick and every excursion shares these; they call nothing else of
//! the interpolator's, so its files call one way: the tick's phases and the excursions down
//! to here.

use super::{Interpolator, Tick};
use crate::buffer::{BlockFlags, BlockSource, Fetch};
use crate::servo::{PathPoint, Travel};
use crate::vocab::MAX_AXES;

impl Interpolator {
    /// Copies the next block with steps into hand, passing over blocks of zero steps.
    pub(super) fn fetch_forward<S: BlockSource + ?Sized>(&mut self, source: &mut S) -> Fetch {
        loop {
            if self.motion.has_block {
                self.motion.passed_mm = self.motion.block.path_end_mm;
            }
            let fetch = source.next(&mut self.motion.block);
            if fetch != Fetch::Block {
                self.motion.has_block = false;
                return fetch;
            }
            self.counters.blocks_entered += 1;
            self.enter_block(false);
            self.stops.on_enter(&self.motion.block, self.settings.dt);
            if self.motion.walk.events() > 0 {
                return Fetch::Block;
            }
        }
    }

    /// The block just copied into hand becomes the one walked: its machining condition, its
    /// excursions' settings and its lattice walk (from its end, `at_end`, going backward).
    pub(super) fn enter_block(&mut self, at_end: bool) {
        self.process.enter(self.motion.block.condition);
        self.excursions.on_enter(
            self.process.servo(),
            &self.settings.excursions,
            self.settings.dt,
        );
        self.motion.enter(at_end, &self.settings.step_mm);
    }

    /// Output bookkeeping of one event: the ledger, the pulse counters, the tick's direction.
    #[inline]
    pub(super) fn apply(&mut self, tick: &mut Tick) {
        for i in 0..MAX_AXES {
            let s = tick.steps[i];
            self.motion.position[i] += s as i64;
            self.counters.pulses[i] += s.unsigned_abs() as u64;
        }
        tick.dir = self.motion.dir;
    }
}

/// Why a resumed job could not walk to its checkpoint.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SkipError {
    #[error("the program ends before segment {seq}, step {event} of the checkpoint")]
    PastEnd { seq: u64, event: i64 },
    #[error(
        "segment {seq} of the program has {events} steps, not the checkpoint's step {event}: \
         the program or the motion settings are not those of the checkpoint"
    )]
    NoSuchPoint { seq: u64, event: i64, events: i64 },
    #[error(
        "segment {seq}, step {event} of the program is at {found:?} steps, the checkpoint says \
         {expected:?}: the program or the motion settings are not those of the checkpoint"
    )]
    Position {
        seq: u64,
        event: i64,
        found: Vec<i64>,
        expected: Vec<i64>,
    },
    #[error(
        "the program probes at line {line} before the checkpoint: where that probe touched is \
         not known to a resumed job; run the program from its start"
    )]
    Probed { line: u64 },
    #[error(
        "the program drills through at line {line} before the checkpoint (sinker.breakthrough): \
         where that drill broke through is not known to a resumed job; run the program from \
         its start"
    )]
    Drilled { line: u64 },
}

impl Interpolator {
    /// Before the first tick of a resumed job: walks forward along the program, emitting
    /// nothing, to `target` and checks that the ledger there is `expected`. The blocks passed
    /// go through the source as if executed, so the reserved area behind the electrode is
    /// full again for turn-back. Pulse counters are not touched: nothing was emitted.
    pub fn skip_to<S: BlockSource + ?Sized>(
        &mut self,
        target: PathPoint,
        expected: &[i64],
        source: &mut S,
    ) -> Result<(), SkipError> {
        while !(self.motion.has_block && self.motion.block.seq >= target.seq) {
            if self.motion.has_block {
                self.motion.walk_silently_to(None);
            }
            // The source waits for the producer, so `Empty` means the job was aborted.
            if self.fetch_forward(source) != Fetch::Block {
                return Err(SkipError::PastEnd {
                    seq: target.seq,
                    event: target.event,
                });
            }
            if self.motion.block.flags.contains(BlockFlags::PROBE) {
                return Err(SkipError::Probed {
                    line: self.motion.block.line,
                });
            }
            // Passing the end of a drilling move watched for breakthrough: where it ended is
            // the run's (the producer waits to hear it); into one, the run decides again.
            let drill_end = BlockFlags::BREAKTHROUGH | BlockFlags::LAST_OF_BLOCK;
            if self.motion.block.flags.contains(drill_end) && self.motion.block.seq < target.seq {
                return Err(SkipError::Drilled {
                    line: self.motion.block.line,
                });
            }
        }
        if self.motion.block.seq != target.seq || target.event > self.motion.walk.events() {
            return Err(SkipError::NoSuchPoint {
                seq: target.seq,
                event: target.event,
                events: if self.motion.block.seq == target.seq {
                    self.motion.walk.events()
                } else {
                    0
                },
            });
        }
        self.motion.walk_silently_to(Some(target.event));
        let n = expected.len().min(MAX_AXES);
        if self.motion.position[..n] != expected[..n] {
            return Err(SkipError::Position {
                seq: target.seq,
                event: target.event,
                found: self.motion.position[..n].to_vec(),
                expected: expected[..n].to_vec(),
            });
        }
        self.servo.observe(Travel::BlockInHand);
        self.servo.observe(Travel::Forward {
            at: self.motion.here(),
        });
        // The first run honoured every stop up to here.
        self.stops.resumed();
        Ok(())
    }
}
