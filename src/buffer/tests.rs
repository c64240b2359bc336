//! The loop buffer against its model, under real threads, and its trail.

use super::*;
use proptest::prelude::*;
use std::collections::VecDeque;

fn block(seq: u64) -> StepBlock {
    StepBlock {
        seq,
        ..StepBlock::EMPTY
    }
}

/// The reference model: executed blocks and pending blocks as two deques.
#[derive(Default)]
struct Model {
    reserved: VecDeque<u64>,
    pending: VecDeque<u64>,
    in_hand: Option<u64>,
    closed: bool,
    next_seq: u64,
}

#[derive(Debug, Clone)]
enum Op {
    Push,
    Next,
    Previous,
    Close,
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        4 => Just(Op::Push),
        4 => Just(Op::Next),
        2 => Just(Op::Previous),
        1 => Just(Op::Close),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// The ring behaves like the two-deque model: the same fetch results, the same blocks
    /// handed out, the same free space, whatever the interleaving.
    #[test]
    fn ring_matches_model(
        capacity in 2usize..9,
        reserved_frac in 0.0f64..1.0,
        ops in proptest::collection::vec(op(), 1..200),
    ) {
        let reserved = ((capacity - 1) as f64 * reserved_frac) as usize;
        let buffer = LoopBuffer::new(capacity, reserved);
        let mut consumer = buffer.consumer(false);
        let mut m = Model::default();
        let mut out = StepBlock::EMPTY;
        for op in ops {
            match op {
                Op::Push => {
                    let held = m.reserved.len() + m.pending.len() + usize::from(m.in_hand.is_some());
                    let expect = held < capacity && !m.closed;
                    if m.closed {
                        continue; // the producer never pushes after closing
                    }
                    prop_assert_eq!(buffer.try_push(&block(m.next_seq)), expect);
                    if expect {
                        m.pending.push_back(m.next_seq);
                        m.next_seq += 1;
                    }
                }
                Op::Next => {
                    if let Some(done) = m.in_hand.take() {
                        m.reserved.push_back(done);
                        if m.reserved.len() > reserved {
                            m.reserved.pop_front();
                        }
                    }
                    let expect = match m.pending.pop_front() {
                        Some(seq) => { m.in_hand = Some(seq); Fetch::Block }
                        None if m.closed => Fetch::End,
                        None => Fetch::Empty,
                    };
                    prop_assert_eq!(consumer.next(&mut out), expect);
                    if let Some(seq) = m.in_hand {
                        prop_assert_eq!(out.seq, seq);
                    }
                }
                Op::Previous => {
                    let expect = !m.reserved.is_empty();
                    prop_assert_eq!(consumer.previous(&mut out), expect);
                    if expect {
                        if let Some(back) = m.in_hand.take() {
                            m.pending.push_front(back);
                        }
                        let seq = m.reserved.pop_back().unwrap();
                        m.in_hand = Some(seq);
                        prop_assert_eq!(out.seq, seq);
                    }
                }
                Op::Close => {
                    buffer.close();
                    m.closed = true;
                }
            }
            let areas = buffer.areas();
            prop_assert_eq!(areas.reserved as usize, m.reserved.len());
            prop_assert_eq!(
                areas.unprocessed as usize,
                m.pending.len() + usize::from(m.in_hand.is_some())
            );
            prop_assert!(areas.reserved as usize <= reserved);
        }
    }

    /// Two real threads on any ring that configuration accepts, `reserved = capacity - 1`
    /// included: a producer that sleeps while the ring is full, a virtual-time consumer
    /// that sleeps while it is empty and turns back into the reserved area at random.
    /// Every block arrives in order and the job reaches its end (a lost wake-up would
    /// leave both asleep: the deadline catches it).
    #[test]
    fn producer_and_waiting_consumer_never_wedge(
        (capacity, reserved) in (2usize..9).prop_flat_map(|c| (Just(c), 0..c)),
        moves in proptest::collection::vec(0u8..10, 1..400),
    ) {
        let total = 60u64;
        let (done_tx, done_rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let buffer = std::sync::Arc::new(LoopBuffer::new(capacity, reserved));
            let producer = {
                let buffer = buffer.clone();
                std::thread::spawn(move || {
                    for seq in 0..total {
                        buffer.push(&block(seq)).unwrap();
                    }
                    buffer.close();
                })
            };
            let mut consumer = buffer.consumer(true);
            let mut out = StepBlock::EMPTY;
            let mut furthest = None::<u64>;
            let mut moves = moves.into_iter().cycle();
            let mut turn_backs = 0;
            let result = loop {
                // About one move in five turns back (at most 300 in all, so the job ends);
                // the rest go forward.
                if moves.next().unwrap() < 2 && turn_backs < 300 && consumer.previous(&mut out) {
                    turn_backs += 1;
                    continue;
                }
                match consumer.next(&mut out) {
                    Fetch::Block => {
                        if furthest.is_none_or(|f| out.seq > f) {
                            if out.seq != furthest.map_or(0, |f| f + 1) {
                                break Err(format!("block {} after {furthest:?}", out.seq));
                            }
                            furthest = Some(out.seq);
                        }
                    }
                    Fetch::End => break Ok(furthest),
                    Fetch::Empty => break Err("empty while waiting".to_string()),
                }
            };
            producer.join().unwrap();
            let _ = done_tx.send(result);
        });
        let result = done_rx
            .recv_timeout(std::time::Duration::from_secs(5))
            .map_err(|_| TestCaseError::fail(format!(
                "capacity {capacity}, reserved {reserved}: wedged"
            )))?;
        prop_assert_eq!(result, Ok(Some(total - 1)));
    }

    /// `VecSource` follows the same rule as the ring (it stands in for it in tests).
    #[test]
    fn vec_source_matches_ring(
        reserved in 0usize..5,
        moves in proptest::collection::vec(any::<bool>(), 1..100),
    ) {
        let blocks: Vec<_> = (0..20).map(block).collect();
        let buffer = LoopBuffer::new(blocks.len() + 1, reserved);
        for b in &blocks {
            prop_assert!(buffer.try_push(b));
        }
        buffer.close();
        let mut ring = buffer.consumer(false);
        let mut vec = VecSource::new(blocks, reserved);
        let (mut a, mut b) = (StepBlock::EMPTY, StepBlock::EMPTY);
        for forward in moves {
            if forward {
                prop_assert_eq!(ring.next(&mut a), vec.next(&mut b));
            } else {
                prop_assert_eq!(ring.previous(&mut a), vec.previous(&mut b));
            }
            prop_assert_eq!(a.seq, b.seq);
        }
    }
}

/// With a trail, the way back goes on past the reserved area to the start of the cut
/// (not into the rapid before it), the producer writes nothing while the walk is below
/// the reserved area, and the way forward hands out the same blocks up to where it was.
#[test]
fn a_walk_on_the_trail_goes_back_to_the_start_of_the_cut_and_forward_again() {
    let buffer = LoopBuffer::new(4, 1).with_trail(1000);
    let mut consumer = buffer.consumer(false);
    let mut out = StepBlock::EMPTY;
    let mut pushed = 0;
    let mut push = |buffer: &LoopBuffer| {
        let flags = if pushed == 2 {
            BlockFlags::RAPID
        } else {
            BlockFlags::NONE
        };
        let ok = buffer.try_push(&StepBlock {
            flags,
            ..block(pushed)
        });
        pushed += u64::from(ok);
        ok
    };
    for _ in 0..40 {
        while push(&buffer) {}
        assert_eq!(consumer.next(&mut out), Fetch::Block);
    }
    assert_eq!(out.seq, 39);
    // The reserved area alone holds one block.
    assert!(consumer.previous(&mut out) && out.seq == 38);
    assert!(!consumer.previous(&mut out));
    // The trail holds the cut back to the rapid (seq 2), the rapid included.
    let mut back = vec![];
    while consumer.previous_on_trail(&mut out) {
        back.push(out.seq);
        assert!(!push(&buffer), "wrote while the walk is on the trail");
    }
    assert_eq!(back, (2..38).rev().collect::<Vec<_>>());
    for seq in 3..=40 {
        assert_eq!(consumer.next(&mut out), Fetch::Block, "{seq}");
        assert_eq!(out.seq, seq);
    }
    // Back in the ring: the producer writes again.
    assert!(push(&buffer));
}

#[test]
fn producer_sleeps_until_the_consumer_frees_a_slot() {
    let buffer = LoopBuffer::new(4, 1);
    std::thread::scope(|s| {
        let producer = s.spawn(|| {
            for seq in 0..100 {
                buffer.push(&block(seq)).unwrap();
            }
            buffer.close();
        });
        let mut consumer = buffer.consumer(true);
        let mut out = StepBlock::EMPTY;
        let mut seen = Vec::new();
        while consumer.next(&mut out) == Fetch::Block {
            seen.push(out.seq);
            assert!(buffer.areas().high_water <= 4);
        }
        producer.join().unwrap();
        assert_eq!(seen, (0..100).collect::<Vec<_>>());
    });
}

#[test]
fn abort_releases_a_waiting_producer() {
    let buffer = LoopBuffer::new(2, 0);
    buffer.push(&block(0)).unwrap();
    buffer.push(&block(1)).unwrap();
    std::thread::scope(|s| {
        let producer = s.spawn(|| buffer.push(&block(2)));
        std::thread::sleep(std::time::Duration::from_millis(20));
        buffer.abort();
        assert_eq!(producer.join().unwrap(), Err(Aborted));
    });
}
