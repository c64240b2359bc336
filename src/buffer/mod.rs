//! The loop buffer: the one place where the producer and the consumer meet.
//!
//! Seed 000 Fig. 4 draws it as a ring of blocks split into three areas that move round it:
//!
//! ```text
//!            oldest              cursor                         tail
//!   ───────────┼── reserved ───────┼──── unprocessed ─────────────┼──── unused ────────┐
//!              │ executed blocks,  │ the block in hand (being     │ free slots the     │
//!              │ kept for turn-back│ interpolated) and the ones   │ producer may fill  │
//!              │ (at most          │ the producer has written     │                    │
//!              │  `buffer.reserved`)│ ahead of it                 │                    │
//!   ◄──────────────────────────────── capacity slots, modulo ─────────────────────────┘
//! ```
//!
//! Behind the reserved area, the **trail** ([`trail`]) keeps the rest of the current cut for
//! a rethread's way back to the start hole; only that walk goes below `oldest`.
//!
//! Positions are sequence numbers (`u64`, never wrapping in practice) taken modulo the capacity
//! to find a slot, so "which area is this block in" is a comparison, not modular arithmetic.
//!
//! - The **producer** writes at `tail` and sleeps on a condvar while the ring is full
//!   (`tail - oldest == capacity`). It is woken when the consumer frees a slot.
//! - The **consumer** holds a copy of the block at `cursor`. Going forward it completes that
//!   block (`cursor += 1`), which moves it into the reserved area; once the reserved area holds
//!   more than `buffer.reserved` blocks its oldest slot is freed (`oldest += 1`). Turning back
//!   it steps `cursor` down into the reserved area and copies that block out again; nothing is
//!   freed while it retraces, so re-advancing finds the same blocks.
//!
//! **Why a mutex and not a lock-free ring.** Both sides hold the lock for exactly one copy of
//! one [`StepBlock`] (about 150 bytes) plus a few integer updates; the producer prepares its
//! block before it locks. The consumer locks once per block, not once per tick. Measured
//! (`cargo bench --bench runtime -- buffer`, `BENCHMARKS.md`): a producer thread hands blocks
//! to a consumer thread at 12.4 M blocks/s through this ring and 14.0 M/s through a crossbeam
//! `ArrayQueue`, within each other's noise, and the consumer's `next()` costs 17 ns per
//! block. A consumer at the step cap needs a block every few ticks, so neither is near a limit.
//! The single ring keeps the reserved area where seed 000 puts it: a lock-free queue hands a
//! block over once, so turn-back would need a second ring on the consumer's side.
//!
//! In **virtual time** the consumer waits for the producer when it has run dry (time stands
//! still while it waits, so the result does not depend on thread scheduling); in real time it
//! never waits: an empty buffer is a starvation, counted by the fine interpolator.

use parking_lot::{Condvar, Mutex};

mod block;
mod trail;

pub use block::{Activity, BlockFlags, StepBlock};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use trail::Trail;

/// What the consumer gets when it asks for the next block.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fetch {
    /// The block was copied out.
    Block,
    /// The producer has not written it yet (a starvation in real time).
    Empty,
    /// The program is over: every block has been handed out and the producer has closed.
    End,
}

/// The consumer's view of the loop buffer: the fine interpolator only ever asks for the next
/// or the previous block. [`Consumer`] is the real one; tests and benches use [`VecSource`].
pub trait BlockSource {
    /// Completes the block in hand (if any) and copies the next one into `out`.
    fn next(&mut self, out: &mut StepBlock) -> Fetch;
    /// Releases the block in hand (if any) back to the unprocessed area and copies the block
    /// before it, the newest of the reserved area, into `out`. `false` when the reserved area
    /// is exhausted: the turn-back can go no further.
    fn previous(&mut self, out: &mut StepBlock) -> bool;
    /// Like [`previous`](Self::previous), but past the reserved area along the trail of
    /// older executed blocks where the source keeps one: the way back to the start hole.
    fn previous_on_trail(&mut self, out: &mut StepBlock) -> bool {
        self.previous(out)
    }
}

/// The ring and its three areas, as sequence numbers.
#[derive(Debug)]
struct Ring {
    slots: Box<[StepBlock]>,
    reserved: u64,
    /// First block of the reserved area.
    oldest: u64,
    /// The block in hand, or the next one to hand out when `in_hand` is false.
    cursor: u64,
    in_hand: bool,
    /// Next slot the producer writes.
    tail: u64,
    /// The producer has written its last block.
    closed: bool,
    /// The job is being torn down: nobody waits any more.
    aborted: bool,
    /// A stop was asked for: the consumer no longer waits for the producer (it reports an
    /// empty buffer and brakes), the producer may still fill the ring.
    interrupted: bool,
    /// Deepest fill seen (`tail - oldest`), for the summary.
    high_water: u64,
    /// Executed blocks older than `oldest`, back to the start of the cut.
    trail: Trail,
}

impl Ring {
    fn capacity(&self) -> u64 {
        self.slots.len() as u64
    }

    fn slot(&self, seq: u64) -> usize {
        (seq % self.capacity()) as usize
    }

    /// No slot to write: the ring is full, or the consumer walks the trail below the
    /// reserved area (the slots it will come back through are not to be overwritten, nor the
    /// trail cleared under it; the producer is ahead anyway).
    fn full(&self) -> bool {
        self.tail - self.oldest == self.capacity() || self.cursor < self.oldest
    }

    /// Writes `block` at the tail (the caller checked there is a free slot); the block it
    /// overwrites, executed and freed, goes to the trail.
    fn write(&mut self, block: &StepBlock, dropped: &mut VecDeque<Vec<StepBlock>>) {
        let slot = self.slot(self.tail);
        if self.tail >= self.capacity() {
            self.trail.archive(&self.slots[slot], dropped);
        }
        self.slots[slot] = *block;
        self.tail += 1;
        self.high_water = self.high_water.max(self.tail - self.oldest);
    }

    /// The block `seq`: from its slot while the ring still holds it (freed slots too, until
    /// overwritten), from the trail before that.
    fn get(&self, seq: u64) -> Option<&StepBlock> {
        if seq >= self.tail {
            None
        } else if seq + self.capacity() >= self.tail {
            Some(&self.slots[self.slot(seq)])
        } else {
            self.trail.get(seq)
        }
    }

    /// Completes the block in hand (if any) and copies out the next; the flag says whether
    /// that made room for the producer: the oldest reserved slot freed (the reserved area
    /// outgrew its size), or a walk on the trail back up to the reserved area.
    fn next(&mut self, out: &mut StepBlock) -> (Fetch, bool) {
        let mut freed = false;
        if self.in_hand {
            self.cursor += 1;
            self.in_hand = false;
            if self.cursor > self.oldest + self.reserved {
                self.oldest += 1;
                freed = true;
            }
            freed |= self.cursor == self.oldest;
        }
        let fetch = if let Some(block) = self.get(self.cursor) {
            *out = *block;
            self.in_hand = true;
            Fetch::Block
        } else if self.closed {
            Fetch::End
        } else {
            Fetch::Empty
        };
        (fetch, freed)
    }

    /// Walks back one block into the reserved area; `on_trail`: on below it along the trail,
    /// where there is one (a walk already on the trail goes on there either way).
    fn previous(&mut self, out: &mut StepBlock, on_trail: bool) -> bool {
        let leaves_ring = self.cursor == self.oldest;
        if self.cursor == 0 || (leaves_ring && !(on_trail && self.trail.enabled())) {
            return false;
        }
        let Some(block) = self.get(self.cursor - 1) else {
            return false;
        };
        *out = *block;
        self.cursor -= 1;
        self.in_hand = true;
        true
    }
}

/// Fill levels of the three areas, for status reports and tests.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Areas {
    pub reserved: u64,
    pub unprocessed: u64,
    pub unused: u64,
    pub high_water: u64,
}

/// The loop buffer shared by the producer and the consumer threads.
#[derive(Debug)]
pub struct LoopBuffer {
    ring: Mutex<Ring>,
    /// The producer waits here for a free slot.
    space: Condvar,
    /// A virtual-time consumer waits here for a block.
    data: Condvar,
    /// The trail's next block needs a chunk: the producer allocates one (of `trail_chunk`
    /// blocks) before it locks.
    trail_wants_chunk: AtomicBool,
    trail_chunk: usize,
}

/// The producer gave up because the job was aborted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("the job was aborted")]
pub struct Aborted;

impl LoopBuffer {
    /// `capacity` slots of which at most `reserved` hold executed blocks (`reserved < capacity`,
    /// as the configuration guarantees).
    pub fn new(capacity: usize, reserved: usize) -> LoopBuffer {
        assert!(
            capacity >= 2 && reserved < capacity,
            "buffer: 2 <= capacity and reserved < capacity"
        );
        LoopBuffer {
            ring: Mutex::new(Ring {
                slots: vec![StepBlock::EMPTY; capacity].into_boxed_slice(),
                reserved: reserved as u64,
                oldest: 0,
                cursor: 0,
                in_hand: false,
                tail: 0,
                closed: false,
                aborted: false,
                interrupted: false,
                high_water: 0,
                trail: Trail::new(0),
            }),
            space: Condvar::new(),
            data: Condvar::new(),
            trail_wants_chunk: AtomicBool::new(false),
            trail_chunk: 0,
        }
    }

    /// Keeps up to `blocks` executed blocks beyond the reserved area, back to the start of
    /// the cut, for the way back to the start hole (`buffer.trail_blocks`; 0: none).
    pub fn with_trail(self, blocks: usize) -> LoopBuffer {
        let mut ring = self.ring.into_inner();
        ring.trail = Trail::new(blocks);
        LoopBuffer {
            trail_wants_chunk: AtomicBool::new(ring.trail.wants_chunk()),
            trail_chunk: trail::chunk_len(blocks),
            ring: Mutex::new(ring),
            ..self
        }
    }

    /// Producer: writes `block` at the tail, sleeping while there is no free slot.
    pub fn push(&self, block: &StepBlock) -> Result<(), Aborted> {
        let chunk = self.chunk_for_trail();
        let mut ring = self.ring.lock();
        while ring.full() && !ring.aborted {
            self.space.wait(&mut ring);
        }
        if ring.aborted {
            return Err(Aborted);
        }
        let dropped = self.write(&mut ring, block, chunk);
        drop(ring);
        self.data.notify_one();
        drop(dropped);
        Ok(())
    }

    /// Producer: like [`push`](Self::push) but never sleeps; `false` when the ring is full.
    pub fn try_push(&self, block: &StepBlock) -> bool {
        let chunk = self.chunk_for_trail();
        let mut ring = self.ring.lock();
        if ring.full() || ring.aborted {
            return false;
        }
        let dropped = self.write(&mut ring, block, chunk);
        drop(ring);
        self.data.notify_one();
        drop(dropped);
        true
    }

    /// A chunk of trail, allocated here (outside the lock) when the trail asked for one.
    fn chunk_for_trail(&self) -> Option<Vec<StepBlock>> {
        self.trail_wants_chunk
            .load(Ordering::Acquire)
            .then(|| Vec::with_capacity(self.trail_chunk))
    }

    /// Writes under the lock; returns the trail's chunks to free once it is released.
    fn write(
        &self,
        ring: &mut Ring,
        block: &StepBlock,
        chunk: Option<Vec<StepBlock>>,
    ) -> VecDeque<Vec<StepBlock>> {
        if let Some(chunk) = chunk {
            ring.trail.give_chunk(chunk);
        }
        let mut dropped = VecDeque::new();
        ring.write(block, &mut dropped);
        self.trail_wants_chunk
            .store(ring.trail.wants_chunk(), Ordering::Release);
        dropped
    }

    /// Producer: the program has no more blocks.
    pub fn close(&self) {
        self.ring.lock().closed = true;
        self.data.notify_all();
    }

    /// Either side: stop waiting, the job is over (error or abort). A producer blocked in
    /// [`push`](Self::push) returns [`Aborted`].
    pub fn abort(&self) {
        let mut ring = self.ring.lock();
        ring.aborted = true;
        ring.closed = true;
        drop(ring);
        self.space.notify_all();
        self.data.notify_all();
    }

    /// The job is being torn down (a producer waiting for something else gives up).
    pub fn aborted(&self) -> bool {
        self.ring.lock().aborted
    }

    /// Supervisor: a stop was asked for. A consumer waiting for the producer (virtual time,
    /// or the walk to a checkpoint) returns [`Fetch::Empty`] at once and from now on, so the
    /// fine interpolator can brake to a standstill whatever the producer is doing.
    pub fn interrupt(&self) {
        self.ring.lock().interrupted = true;
        self.data.notify_all();
    }

    pub fn areas(&self) -> Areas {
        let ring = self.ring.lock();
        // A walk on the trail counts from the reserved area's start.
        let cursor = ring.cursor.max(ring.oldest);
        let unprocessed = ring.tail - cursor;
        let reserved = cursor - ring.oldest;
        Areas {
            reserved,
            unprocessed,
            unused: ring.capacity() - reserved - unprocessed,
            high_water: ring.high_water,
        }
    }

    /// The consumer's end. `wait_for_producer`: in virtual time, wait for a block rather than
    /// report [`Fetch::Empty`].
    pub fn consumer(&self, wait_for_producer: bool) -> Consumer<'_> {
        Consumer {
            buffer: self,
            wait_for_producer,
        }
    }
}

/// The consumer's end of a [`LoopBuffer`].
#[derive(Debug)]
pub struct Consumer<'a> {
    buffer: &'a LoopBuffer,
    wait_for_producer: bool,
}

impl Consumer<'_> {
    /// Switches between waiting for the producer (virtual time) and reporting an empty
    /// buffer (real time).
    pub fn set_wait_for_producer(&mut self, wait: bool) {
        self.wait_for_producer = wait;
    }
}

impl BlockSource for Consumer<'_> {
    fn next(&mut self, out: &mut StepBlock) -> Fetch {
        let buffer = self.buffer;
        let mut ring = buffer.ring.lock();
        let (mut fetch, freed) = ring.next(out);
        if freed {
            // Before any wait: with `reserved = capacity - 1` the slot just freed is the only
            // one, and a producer asleep for it is what this consumer would wait for.
            buffer.space.notify_one();
        }
        while fetch == Fetch::Empty && self.wait_for_producer && !ring.aborted && !ring.interrupted
        {
            buffer.data.wait(&mut ring);
            fetch = ring.next(out).0;
        }
        fetch
    }

    fn previous(&mut self, out: &mut StepBlock) -> bool {
        self.buffer.ring.lock().previous(out, false)
    }

    fn previous_on_trail(&mut self, out: &mut StepBlock) -> bool {
        self.buffer.ring.lock().previous(out, true)
    }
}

/// A [`BlockSource`] over a vector, with the loop buffer's own ring and reserved-area rule:
/// the fine interpolator without threads, for tests and benches.
#[derive(Debug)]
pub struct VecSource {
    ring: Ring,
}

impl VecSource {
    pub fn new(blocks: Vec<StepBlock>, reserved: usize) -> VecSource {
        let tail = blocks.len() as u64;
        VecSource {
            ring: Ring {
                slots: blocks.into_boxed_slice(),
                reserved: reserved as u64,
                oldest: 0,
                cursor: 0,
                in_hand: false,
                tail,
                closed: true,
                aborted: false,
                interrupted: false,
                high_water: tail,
                trail: Trail::new(0),
            },
        }
    }
}

impl BlockSource for VecSource {
    fn next(&mut self, out: &mut StepBlock) -> Fetch {
        self.ring.next(out).0
    }

    fn previous(&mut self, out: &mut StepBlock) -> bool {
        self.ring.previous(out, false)
    }
}

#[cfg(test)]
mod tests;
