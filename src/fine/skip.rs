//! Resuming a job: the walk along the program, emitting nothing, to a checkpoint's point.

use super::Interpolator;
use crate::buffer::BlockFlags;
use crate::buffer::{BlockSource, Fetch};
use crate::servo::PathPoint;
use crate::vocab::MAX_AXES;

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
        self.servo.on_block();
        self.servo.on_forward(self.here());
        // The first run honoured every stop up to here.
        self.stops.resumed();
        Ok(())
    }
}
