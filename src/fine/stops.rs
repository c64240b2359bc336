//! Programmed and operator stops: the hold, a `G4` dwell's ticks, an `M0`/`M1` pause, and
//! which blocks have had their stops honoured (a re-advance or a resume does not repeat them).

use crate::buffer::{BlockFlags, StepBlock};
use crate::servo::PauseKind;

/// What keeps the electrode still, apart from the servo.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Stops {
    /// Held by the operator (or a pause, a collision, a wire break): brake to a standstill
    /// under `a_T` and stay there.
    pub hold: bool,
    /// Ticks of a `G4` dwell still to wait.
    pub dwell_left: u64,
    /// Blocks before this sequence number have had their stops honoured.
    pub stops_from: u64,
    /// A pause was met while fetching: reported by the tick that met it.
    pub paused: Option<PauseKind>,
    /// Single block: the operator's switch (from the thread loop); a pause before every
    /// program block while it is on (not before the moves of a run-from-line approach,
    /// which the job made: the first stop is before the line's block).
    pub single_block: bool,
    /// The last block entered ended a program block: the next one starts a new one.
    pub after_block_end: bool,
}

impl Stops {
    /// A block entered going forward: the first time, its dwell (in ticks of `dt`) and its
    /// pause are taken on.
    pub fn on_enter(&mut self, block: &StepBlock, dt: f64) {
        if block.seq < self.stops_from {
            return;
        }
        self.stops_from = block.seq + 1;
        let starts_block = std::mem::replace(
            &mut self.after_block_end,
            block.flags.contains(BlockFlags::LAST_OF_BLOCK),
        );
        if block.dwell_s > 0.0 {
            self.dwell_left += (block.dwell_s / dt).round() as u64;
        }
        if block.flags.contains(BlockFlags::PAUSE) {
            self.hold = true;
            self.paused = Some(if block.flags.contains(BlockFlags::TAB) {
                PauseKind::Slug
            } else {
                PauseKind::Program
            });
        } else if self.single_block && starts_block && !block.flags.contains(BlockFlags::APPROACH) {
            self.hold = true;
            self.paused = Some(PauseKind::SingleBlock);
        }
    }

    /// Takes the pause met while fetching, once.
    pub fn take_pause(&mut self) -> Option<PauseKind> {
        self.paused.take()
    }

    /// Waits one tick of a dwell, if one is owed.
    pub fn dwell_tick(&mut self) -> bool {
        if self.dwell_left == 0 {
            return false;
        }
        self.dwell_left -= 1;
        true
    }

    /// A resumed job stands where its first run stood: every stop up to here was honoured.
    pub fn resumed(&mut self) {
        self.dwell_left = 0;
        self.paused = None;
        self.hold = false;
    }
}
