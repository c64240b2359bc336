//! What reading a program allocates: a canned cycle's moves and a straight line's block
//! are made without a heap allocation of their own (a line's curve is kept in the block, a
//! cycle's moves are made in room kept from the last cycle, a line's text in room kept from
//! the last line). Counted by a global allocator that counts this thread's allocations.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

// SAFETY: every call is passed to the system allocator unchanged; the count is a
// thread-local integer, which neither allocates nor frees.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.with(|n| n.set(n.get() + 1));
        // SAFETY: the caller's contract is the system allocator's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: as above.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.with(|n| n.set(n.get() + 1));
        // SAFETY: as above.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static COUNTING: Counting = Counting;

fn allocations() -> u64 {
    ALLOCATIONS.with(Cell::get)
}

/// Reads `text` block by block; the allocations made while reading the blocks after the
/// first `warm` (when every room has grown to what the program needs), and their number.
fn allocations_after(text: &str, warm: usize) -> (u64, usize) {
    let axes = [
        edmd::vocab::Axis::X,
        edmd::vocab::Axis::Y,
        edmd::vocab::Axis::Z,
    ];
    let mut reader =
        edmd::gcode::BlockReader::new(std::io::Cursor::new(text.as_bytes()), "a.ngc", &axes);
    let mut blocks = 0;
    let mut from = None;
    for block in reader.by_ref() {
        let block = block.expect("the program reads");
        blocks += 1;
        if blocks == warm {
            from = Some(allocations());
        }
        drop(block);
    }
    let from = from.expect("more blocks than the warm-up");
    (allocations() - from, blocks - warm)
}

#[test]
fn canned_cycles_and_lines_make_their_moves_without_allocating() {
    let mut drill = String::from("G21 G90 G17 F100\nG0 X0 Y0 Z5\nG81 X1 Y1 Z-2 R1\n");
    for k in 0..1000 {
        drill.push_str(&format!("X{} Y{}\n", 2 + k % 50, 1 + k / 50));
    }
    drill.push_str("G83 X0 Y0 Z-3 R1 Q0.5\n");
    for k in 0..300 {
        drill.push_str(&format!("X{} Y{}\n", 2 + k % 50, 1 + k / 50));
    }
    drill.push_str("G80\nM2\n");
    let (made, blocks) = allocations_after(&drill, 300);
    // Near 10,000 moves (five a hole, a peck three more): the only allocations are the
    // rooms growing (doubling) to the first deep hole's 30-odd moves, a handful each.
    assert!(blocks > 9000, "{blocks} blocks");
    assert!(made <= 16, "{made} allocations for {blocks} cycle moves");

    let mut lines = String::from("G21 G90 G17 F100\n");
    for k in 0..2000 {
        lines.push_str(&format!("G1 X{} Y{:.3}\n", k % 7, k as f64 * 0.01));
    }
    lines.push_str("M2\n");
    let (made, blocks) = allocations_after(&lines, 100);
    // The line's room growing as its numbers lengthen: a few in all, none a line.
    assert!(made <= 8, "{made} allocations for {blocks} lines");
}
