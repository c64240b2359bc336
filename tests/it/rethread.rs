//! Back to the start hole from anywhere (issue [5/9]): after a wire break far along a
//! contour, many times the loop buffer's reserved area from the start hole, `rethread` goes
//! back along the whole cut to the start hole and `resume` returns to the break and finishes
//! exactly, every step back matched by one forward. The real `edmd serve`, scripted gap.

use crate::common;

use common::daemon::*;
use edmd::output::read_pulse_log;

/// Blocks the loop buffer keeps for turn-back in this test.
const RESERVED: usize = 4;

/// A rapid to X1, then a zigzag of 0.1 mm × 0.02 mm lines (one block each) to X9.
fn zigzag() -> (String, [i64; 2]) {
    let mut text = String::from("G21 G90\nG0 X1\nF300\n");
    for i in 1..=80 {
        let y = if i % 2 == 1 { 0.02 } else { 0.0 };
        text.push_str(&format!("G1 X{:.1} Y{y:.2}\n", 1.0 + 0.1 * f64::from(i)));
    }
    text.push_str("M2\n");
    (text, [9000, 0])
}

#[test]
fn a_wire_break_ten_reserved_areas_from_the_start_hole_rethreads_there() {
    let dir = scratch("rethread-far");
    let (program, end) = zigzag();
    std::fs::write(dir.join("programs/zigzag.ngc"), program).unwrap();
    // The wire breaks 1.4 s into the job (ticks of 50 µs), some 6 mm along the zigzag.
    std::fs::write(dir.join("gap.txt"), "0 normal\n28000 wire-break\n").unwrap();
    let mut sets = script_sets(&dir, "pulses.csv");
    sets.retain(|s| !s.starts_with("buffer."));
    sets.push("buffer.capacity=8".into());
    sets.push(format!("buffer.reserved={RESERVED}"));
    let daemon = Daemon::start(&dir, &sets, &[]);
    daemon.ok(&["run", "zigzag.ngc"]);
    let broken = daemon.wait_for("the wire break's hold", |s| {
        s["state"] == "wire-break" && s["job"]["feed_mm_per_min"] == 0.0
    });
    let at_break = position(&broken);
    // Each zigzag block is 0.1 mm of X: the break is this many blocks from the start hole.
    let blocks_back = (at_break[0] - 1000) / 100;
    assert!(
        blocks_back >= 10 * RESERVED as i64,
        "the break is {blocks_back} blocks from the start hole: {broken}"
    );
    daemon.wait_for("the hold checkpoint", |s| {
        s["checkpoint"]["reason"] == "hold" && s["checkpoint"]["still"] == true
    });

    daemon.ok(&["rethread"]);
    let threading = daemon.wait_for("the start hole", |s| s["state"] == "threading");
    assert_eq!(position(&threading), vec![1000, 0], "{threading}");
    daemon.resume_to_the_end(&end);

    // Every pulse accounted: the rapid, the zigzag, and the way back and forth over the
    // cut up to the break, each X step once each way.
    let (_, rows) = read_pulse_log(&dir.join("pulses.csv")).unwrap();
    let x: i64 = rows.iter().map(|r| i64::from(r.steps[0]).abs()).sum();
    assert_eq!(x, 9000 + 2 * (at_break[0] - 1000));
    // The way back retraces the cut: the positions visited on the way back are the ones
    // visited on the way forward, in reverse.
    let mut position = [0i64; 2];
    let mut visited = vec![];
    for row in &rows {
        for (p, s) in position.iter_mut().zip(&row.steps) {
            *p += i64::from(*s);
        }
        visited.push(position);
    }
    let first_break = visited
        .iter()
        .position(|p| *p == [at_break[0], at_break[1]]);
    let first_break = first_break.expect("the break point on the record");
    let forward: Vec<_> = visited[..=first_break]
        .iter()
        .filter(|p| p[0] >= 1000)
        .collect();
    let back: Vec<_> = visited[first_break..]
        .iter()
        .take_while(|p| **p != [1000, 0])
        .chain(std::iter::once(&[1000, 0]))
        .collect();
    let mut dedup_forward = forward.clone();
    dedup_forward.dedup();
    let mut dedup_back = back.clone();
    dedup_back.dedup();
    dedup_back.reverse();
    assert!(
        dedup_back == dedup_forward,
        "the way back is not the cut reversed ({} points back, {} forward)",
        dedup_back.len(),
        dedup_forward.len()
    );
}
