//! The trail: executed blocks older than the reserved area, back to the start of the cut.
//!
//! The reserved area keeps `buffer.reserved` executed blocks, which is what a short's
//! turn-back needs. A wire break needs more: the way back to the start hole is the whole
//! contour cut so far, however long. The trail keeps the blocks that have left the ring (the
//! producer archives a freed slot just before it overwrites it), so the consumer can walk on
//! below the reserved area during a rethread and forward again on the way back to the break.
//!
//! It holds only what a purposeful retreat can use: a block that starts a cut (a rapid, a
//! probing move, a pass that starts at the start hole) clears what came before it, so its size is the
//! current contour's, not the program's, and it is capped (`buffer.trail_blocks`): past the
//! cap the oldest blocks go and a rethread parks at the oldest one left, as it says.
//!
//! Memory is taken in chunks; the producer hands over a chunk it allocated outside the lock
//! ([`Trail::wants_chunk`], [`Trail::give_chunk`]), so the consumer never waits on an
//! allocation.

use std::collections::VecDeque;

use super::{BlockFlags, StepBlock};

/// Blocks per chunk (each about 200 bytes).
const CHUNK: usize = 4096;

/// Blocks per chunk of a trail of at most `cap` blocks.
pub(super) fn chunk_len(cap: usize) -> usize {
    CHUNK.min(cap).max(1)
}

#[derive(Debug, Default)]
pub(super) struct Trail {
    chunks: VecDeque<Vec<StepBlock>>,
    /// Sequence number of the first block held.
    first: u64,
    len: u64,
    /// At most this many blocks (0: no trail).
    cap: u64,
    /// A chunk the producer allocated for the next block.
    spare: Option<Vec<StepBlock>>,
}

impl Trail {
    pub fn new(cap: usize) -> Trail {
        Trail {
            cap: cap as u64,
            ..Trail::default()
        }
    }

    pub fn enabled(&self) -> bool {
        self.cap > 0
    }

    fn chunk_len(&self) -> usize {
        chunk_len(self.cap as usize)
    }

    /// The next block needs a chunk that is not there yet.
    pub fn wants_chunk(&self) -> bool {
        self.enabled()
            && self.spare.is_none()
            && self.chunks.back().is_none_or(|c| c.len() == c.capacity())
    }

    /// A chunk for the blocks to come (allocated with [`Trail::new_chunk`]).
    pub fn give_chunk(&mut self, chunk: Vec<StepBlock>) {
        if self.spare.is_none() {
            self.spare = Some(chunk);
        }
    }

    fn new_chunk(&self) -> Vec<StepBlock> {
        Vec::with_capacity(self.chunk_len())
    }

    /// Keeps `block`, the oldest block that leaves the ring. What it displaces (a cut that
    /// ended, blocks over the cap) goes into `dropped`, for the caller to free after unlocking.
    pub fn archive(&mut self, block: &StepBlock, dropped: &mut VecDeque<Vec<StepBlock>>) {
        if !self.enabled() {
            return;
        }
        let flags = block.flags;
        let starts_cut = flags.intersects(BlockFlags::PROBE | BlockFlags::START_HOLE)
            || (flags.contains(BlockFlags::RAPID) && !flags.contains(BlockFlags::IN_KERF));
        if starts_cut || self.len == 0 {
            dropped.append(&mut self.chunks);
            self.first = block.seq;
            self.len = 0;
        }
        debug_assert_eq!(block.seq, self.first + self.len, "the trail is contiguous");
        if self.len == self.cap
            && let Some(front) = self.chunks.pop_front()
        {
            self.first += front.len() as u64;
            self.len -= front.len() as u64;
            dropped.push_back(front);
        }
        if self.chunks.back().is_none_or(|c| c.len() == c.capacity()) {
            let chunk = self.spare.take().unwrap_or_else(|| self.new_chunk());
            self.chunks.push_back(chunk);
        }
        self.chunks.back_mut().expect("a chunk").push(*block);
        self.len += 1;
    }

    /// The block `seq`, if the trail holds it.
    pub fn get(&self, seq: u64) -> Option<&StepBlock> {
        let offset = seq.checked_sub(self.first).filter(|&o| o < self.len)? as usize;
        let front = self.chunks.front()?.len();
        // Every chunk but the first is full from its start (the first may have lost nothing:
        // chunks are only ever dropped whole).
        if offset < front {
            return self.chunks[0].get(offset);
        }
        let chunk = self.chunk_len();
        let rest = offset - front;
        self.chunks.get(1 + rest / chunk)?.get(rest % chunk)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn block(seq: u64, flags: BlockFlags) -> StepBlock {
        StepBlock {
            seq,
            flags,
            ..StepBlock::EMPTY
        }
    }

    #[test]
    fn keeps_the_cut_since_its_start_up_to_the_cap() {
        let mut trail = Trail::new(10_000);
        let mut dropped = VecDeque::new();
        for seq in 0..3 {
            trail.archive(&block(seq, BlockFlags::NONE), &mut dropped);
        }
        // A rapid starts a new cut: what came before can no longer be walked back to.
        trail.archive(&block(3, BlockFlags::RAPID), &mut dropped);
        for seq in 4..9_000 {
            if trail.wants_chunk() {
                let chunk = trail.new_chunk();
                trail.give_chunk(chunk);
            }
            trail.archive(&block(seq, BlockFlags::NONE), &mut dropped);
        }
        assert_eq!(dropped.len(), 1);
        assert!(trail.get(2).is_none());
        for seq in 3..9_000 {
            assert_eq!(trail.get(seq).map(|b| b.seq), Some(seq));
        }
        assert!(trail.get(9_000).is_none());
        // Over the cap the oldest chunk goes, whole.
        for seq in 9_000..12_000 {
            trail.archive(&block(seq, BlockFlags::NONE), &mut dropped);
        }
        assert!(trail.get(4_098).is_none());
        assert_eq!(trail.get(4_099).map(|b| b.seq), Some(4_099));
        assert_eq!(trail.get(11_999).map(|b| b.seq), Some(11_999));
        assert!(trail.len <= trail.cap);
    }

    #[test]
    fn a_pass_from_the_start_hole_starts_a_cut_and_no_trail_keeps_nothing() {
        let mut trail = Trail::new(100);
        let mut dropped = VecDeque::new();
        trail.archive(&block(0, BlockFlags::NONE), &mut dropped);
        trail.archive(&block(1, BlockFlags::START_HOLE), &mut dropped);
        assert!(trail.get(0).is_none());
        assert_eq!(trail.get(1).map(|b| b.seq), Some(1));
        let mut off = Trail::new(0);
        off.archive(&block(0, BlockFlags::NONE), &mut dropped);
        assert!(off.get(0).is_none() && !off.wants_chunk());
    }
}
