//! The wire offset against LinuxCNC's interpreter: entry and exit moves, corners, lines and
//! arcs, each program read by edmd (`G41 D1` with `d_mm = [0, r]`) and by `rs274 -g` (the same
//! program with `G41.1 D<2r>`, LinuxCNC's offset by diameter), and every compensated end point
//! must agree within 1 µm (rs274 prints 0.1 µm).
//!
//! The programs: LinuxCNC's own compensation examples as `linuxcnc-uspace` installs them
//! (`/usr/share/linuxcnc/ncfiles/comp-g1.ngc`, `comp311.ngc`, `comp311_2.ngc`, given a `D`
//! instead of their tool table; read from there, not copied here), and generated wire
//! programs: dies (the offset inside) and punches (outside), both directions, sharp and
//! rounded corners, a notch with concave corners, line and arc entries, and the usual exit
//! back along the entry line to the start hole. Without `rs274` the comparison is skipped,
//! unless `EDMD_LCNC_TESTS=1` (CI).

use crate::common;

use std::fmt::Write as _;
use std::path::Path;

use common::linuxcnc::{edmd_ends, linuxcnc_moves, rs274};

/// Every compensated end point within 1 µm of LinuxCNC's (rs274 prints 0.1 µm in mm)…
const AGREE_MM: f64 = 1e-3;
/// …or, in an inch program, within what it prints: four decimals of an inch, ±1.27 µm.
const AGREE_INCH_MM: f64 = 0.000_05 * 25.4 + 1e-6;

/// `text` with its offset words as edmd reads them (`G41 D1`) and as rs274 does (`G41.1
/// D<diameter>`, in the program's units); tool changes dropped (edmd has no tool table).
fn dialects(text: &str, diameter: f64) -> (String, String) {
    let (mut ours, mut theirs) = (String::new(), String::new());
    for line in text.lines() {
        let lower = line.to_ascii_lowercase();
        if lower.contains("m6") {
            // Kept as an empty line: errors name the same lines in both.
            ours.push('\n');
            theirs.push('\n');
            continue;
        }
        let mut a = String::new();
        let mut b = String::new();
        let mut rest = lower.as_str();
        while let Some(at) = rest.find("g4") {
            let (head, tail) = rest.split_at(at);
            a.push_str(head);
            b.push_str(head);
            let side = tail.as_bytes().get(2).copied();
            if matches!(side, Some(b'1') | Some(b'2')) && tail.as_bytes().get(3) != Some(&b'.') {
                let side = side.unwrap() as char;
                // Drop a `d<n>` that follows (a tool number in LinuxCNC's programs).
                let mut after = tail[3..].trim_start();
                if let Some(d) = after.strip_prefix('d') {
                    after = d.trim_start_matches(|c: char| c.is_ascii_digit() || c == ' ');
                }
                let _ = write!(a, "g4{side} d1 ");
                let _ = write!(b, "g4{side}.1 d{diameter} ");
                rest = after;
            } else {
                a.push_str(&tail[..2]);
                b.push_str(&tail[..2]);
                rest = &tail[2..];
            }
        }
        a.push_str(rest);
        b.push_str(rest);
        ours.push_str(&a);
        ours.push('\n');
        theirs.push_str(&b);
        theirs.push('\n');
    }
    (ours, theirs)
}

/// edmd's end points (mm, machine order X Y Z) of the program, `D1` = `radius_mm`.
fn edmd_moves(text: &str, radius_mm: f64) -> Result<Vec<[f64; 3]>, String> {
    edmd_ends(text, radius_mm)
}

/// Both readings of `text` (offset by `diameter` in the program's units, `radius_mm` in mm)
/// agree move for move; returns the number of moves compared and the largest difference (mm).
fn agree(
    rs274: &Path,
    dir: &Path,
    name: &str,
    text: &str,
    diameter: f64,
    radius_mm: f64,
) -> (usize, f64) {
    let (ours, theirs) = dialects(text, diameter);
    let path = dir.join(name);
    std::fs::write(&path, &theirs).unwrap();
    let reference = linuxcnc_moves(rs274, &path)
        .unwrap_or_else(|e| panic!("rs274 refuses {name}: {e}\n{theirs}"));
    let mine =
        edmd_moves(&ours, radius_mm).unwrap_or_else(|e| panic!("edmd refuses {name}: {e}\n{ours}"));
    let inch = text.to_ascii_lowercase().contains("g20");
    let bound = if inch { AGREE_INCH_MM } else { AGREE_MM };
    let worst = mine
        .iter()
        .zip(&reference)
        .map(|(a, b)| (0..3).map(|i| (a[i] - b[i]).abs()).fold(0.0, f64::max))
        .fold(0.0, f64::max);
    assert!(
        mine.len() == reference.len() && worst <= bound,
        "{name}: edmd makes {} moves, LinuxCNC {} (worst difference {worst:.6} mm)\n\
         edmd:  {mine:?}\nrs274: {reference:?}\nprogram:\n{ours}",
        mine.len(),
        reference.len()
    );
    (mine.len(), worst)
}

#[test]
fn linuxcncs_own_compensation_programs_end_every_move_where_rs274_does() {
    let Some(rs274) = rs274() else { return };
    let dir = common::scratch("wire-offset-linuxcnc", "ncfiles");
    let installed = Path::new("/usr/share/linuxcnc/ncfiles");
    // Tool 4 of LinuxCNC's sample tool table is 1" in diameter (the programs say so).
    for name in ["comp-g1.ngc", "comp311.ngc", "comp311_2.ngc"] {
        let Ok(text) = std::fs::read_to_string(installed.join(name)) else {
            assert!(
                std::env::var_os("EDMD_LCNC_TESTS").is_none_or(|v| v != "1"),
                "{name} is not in {}",
                installed.display()
            );
            continue;
        };
        let (n, worst) = agree(&rs274, &dir, name, &text, 1.0, 12.7);
        eprintln!("{name}: {n} moves agree, worst {:.2} µm", worst * 1e3);
    }
}

/// A closed contour of a wire part, counter-clockwise from its first point: a `w` × `h`
/// rectangle at the origin with corner radius `rc` (0: sharp), and with `notch` a rectangular
/// notch in the top edge (two concave corners).
fn contour(w: f64, h: f64, rc: f64, notch: bool) -> Vec<String> {
    let mut moves = Vec::new();
    let arc = |x: f64, y: f64, i: f64, j: f64| format!("G3 X{x:.4} Y{y:.4} I{i:.4} J{j:.4}");
    // From the middle of the bottom edge.
    moves.push(format!("G1 X{:.4} Y0", w - rc));
    if rc > 0.0 {
        moves.push(arc(w, rc, 0.0, rc));
    }
    moves.push(format!("G1 X{w:.4} Y{:.4}", h - rc));
    if rc > 0.0 {
        moves.push(arc(w - rc, h, -rc, 0.0));
    }
    if notch {
        let (a, b, depth) = (w * 0.65, w * 0.35, h * 0.3);
        moves.push(format!("G1 X{a:.4} Y{h:.4}"));
        moves.push(format!("G1 X{a:.4} Y{:.4}", h - depth));
        moves.push(format!("G1 X{b:.4} Y{:.4}", h - depth));
        moves.push(format!("G1 X{b:.4} Y{h:.4}"));
    }
    moves.push(format!("G1 X{rc:.4} Y{h:.4}"));
    if rc > 0.0 {
        moves.push(arc(0.0, h - rc, 0.0, -rc));
    }
    moves.push(format!("G1 X0 Y{rc:.4}"));
    if rc > 0.0 {
        moves.push(arc(rc, 0.0, rc, 0.0));
    }
    moves.push(format!("G1 X{:.4} Y0", w / 2.0));
    moves
}

/// Reverses a counter-clockwise contour that starts and ends at `start` into a clockwise one.
fn reversed(moves: &[String], start: (f64, f64)) -> Vec<String> {
    // Each move's end point, with the start in front: the reversed moves run between them
    // backwards, an arc's centre kept (I J are relative to the reversed move's start).
    let word = |m: &str, c: char| -> Option<f64> {
        m.split_whitespace()
            .find_map(|w| w.strip_prefix(c).and_then(|v| v.parse().ok()))
    };
    let mut ends = vec![start];
    for m in moves {
        ends.push((word(m, 'X').unwrap(), word(m, 'Y').unwrap()));
    }
    let mut out = Vec::new();
    for k in (0..moves.len()).rev() {
        let (from, to) = (ends[k + 1], ends[k]);
        let m = &moves[k];
        if m.starts_with("G3") {
            let centre = (
                ends[k].0 + word(m, 'I').unwrap(),
                ends[k].1 + word(m, 'J').unwrap(),
            );
            out.push(format!(
                "G2 X{:.4} Y{:.4} I{:.4} J{:.4}",
                to.0,
                to.1,
                centre.0 - from.0,
                centre.1 - from.1
            ));
        } else {
            out.push(format!("G1 X{:.4} Y{:.4}", to.0, to.1));
        }
    }
    out
}

#[test]
fn generated_dies_and_punches_enter_corner_and_exit_as_rs274_does() {
    let Some(rs274) = rs274() else { return };
    let dir = common::scratch("wire-offset-linuxcnc", "generated");
    let radius = 0.15;
    let mut rng = edmd::rng::SplitMix64::new(35);
    let mut compared = (0, 0, 0.0_f64);
    for case in 0..60 {
        let w = 8.0 + 12.0 * rng.next_f64();
        let h = 6.0 + 10.0 * rng.next_f64();
        let rc = if case % 3 == 0 {
            0.0
        } else {
            0.5 + 2.0 * rng.next_f64()
        };
        let notch = case % 4 == 1;
        let die = case % 2 == 0;
        let clockwise = case % 5 >= 3;
        let arc_entry = case % 6 == 5;
        let start_contour = (w / 2.0, 0.0);
        let mut moves = contour(w, h, rc, notch);
        if clockwise {
            moves = reversed(&moves, start_contour);
        }
        // A die's start hole is inside the part, a punch's outside below it; the offset side
        // keeps the wire in the scrap: inside a die, outside a punch.
        let hole = if die {
            (w / 2.0, h * 0.4)
        } else {
            (w / 2.0, -3.0)
        };
        let left = die != clockwise;
        let mut text = String::from("G21 G90 G17\n");
        let _ = writeln!(text, "G0 X{:.4} Y{:.4}", hole.0, hole.1);
        let _ = writeln!(text, "{} D1", if left { "G41" } else { "G42" });
        if arc_entry {
            // A half circle from the start hole onto the contour's start point, arriving
            // along the contour's first move (+X counter-clockwise, -X clockwise).
            let centre_y = (hole.1 + start_contour.1) / 2.0;
            let g = if die != clockwise { "G3" } else { "G2" };
            let _ = writeln!(
                text,
                "{g} X{:.4} Y{:.4} I0 J{:.4} F100",
                start_contour.0,
                start_contour.1,
                centre_y - hole.1
            );
        } else {
            let _ = writeln!(
                text,
                "G1 X{:.4} Y{:.4} F100",
                start_contour.0, start_contour.1
            );
        }
        for m in &moves {
            text.push_str(m);
            text.push('\n');
        }
        // Out the way it came in: back to the start hole.
        let _ = writeln!(text, "G40 G1 X{:.4} Y{:.4}", hole.0, hole.1);
        text.push_str("M2\n");
        let name = format!("case{case}.ngc");
        let (n, worst) = agree(&rs274, &dir, &name, &text, 2.0 * radius, radius);
        compared = (compared.0 + 1, compared.1 + n, compared.2.max(worst));
    }
    eprintln!(
        "{} generated programs, {} moves agree, worst {:.2} µm",
        compared.0,
        compared.1,
        compared.2 * 1e3
    );
}

#[test]
fn the_dialect_rewrite_gives_each_reader_its_offset_words() {
    let (ours, theirs) = dialects("G0 X1\nT4 M6\ng41 d4 g1 y4\nG42\nG40 G1 X0\n", 0.3);
    assert_eq!(ours, "g0 x1\n\ng41 d1 g1 y4\ng42 d1 \ng40 g1 x0\n");
    assert_eq!(
        theirs,
        "g0 x1\n\ng41.1 d0.3 g1 y4\ng42.1 d0.3 \ng40 g1 x0\n"
    );
}

/// A random open chain under the offset from `rng`, in inches or mm (`scale` mm a unit):
/// lines and arcs (by `I J` or `R`), each tangent to the last or turned by up to a radian,
/// written to four decimals; entered and left by straight moves. Rounded to four decimals of
/// an inch, a tangent junction is a slight corner either way and an `I J` arc a slight
/// spiral: where a corner's offsets meet then moves far along the path, and rs274 has its
/// own construction for it.
fn chain(rng: &mut edmd::rng::SplitMix64, scale: f64, side: &str) -> String {
    let mut text = String::from(if scale == 1.0 { "G21" } else { "G20" });
    text.push_str(" G90 G17\n");
    let at = |x: f64, y: f64| format!("X{:.4} Y{:.4}", x / scale, y / scale);
    let (mut x, mut y) = (0.0f64, 0.0f64);
    let mut heading = rng.next_f64() * std::f64::consts::TAU;
    let _ = writeln!(
        text,
        "G0 {}\n{side} D1\nG1 {} F10",
        at(-5.0 * heading.cos(), -5.0 * heading.sin()),
        at(0.0, 0.0)
    );
    for _ in 0..8 {
        if rng.below(3) == 0 {
            heading += 2.0 * rng.next_f64() - 1.0;
        }
        if rng.below(2) == 0 {
            let l = 3.0 + 7.0 * rng.next_f64();
            (x, y) = (x + l * heading.cos(), y + l * heading.sin());
            let _ = writeln!(text, "G1 {}", at(x, y));
            continue;
        }
        let r = 2.0 + 8.0 * rng.next_f64();
        let turn = if rng.below(2) == 0 { 1.0 } else { -1.0 };
        let c = (x - turn * r * heading.sin(), y + turn * r * heading.cos());
        let sweep = turn * (0.5 + 2.0 * rng.next_f64());
        let to = (y - c.1).atan2(x - c.0) + sweep;
        let end = (c.0 + r * to.cos(), c.1 + r * to.sin());
        let g = if turn > 0.0 { "G3" } else { "G2" };
        if rng.below(3) == 0 && sweep.abs() < std::f64::consts::PI {
            let _ = writeln!(text, "{g} {} R{:.4}", at(end.0, end.1), r / scale);
        } else {
            let (i, j) = ((c.0 - x) / scale, (c.1 - y) / scale);
            let _ = writeln!(text, "{g} {} I{i:.4} J{j:.4}", at(end.0, end.1));
        }
        ((x, y), heading) = (end, heading + sweep);
    }
    let _ = writeln!(
        text,
        "G40 G1 {}\nM2",
        at(x + 5.0 * heading.cos(), y + 5.0 * heading.sin())
    );
    text
}

#[test]
fn chains_of_lines_and_slightly_spiral_arcs_meet_at_rs274s_corners_in_inches_and_mm() {
    let Some(rs274) = rs274() else { return };
    let dir = common::scratch("wire-offset-linuxcnc", "chains");
    let mut rng = edmd::rng::SplitMix64::new(7);
    let radius = 0.15;
    let (mut moves, mut worst) = (0, [0.0f64; 2]);
    for case in 0..300 {
        let inch = case % 2 == 0;
        let scale = if inch { 25.4 } else { 1.0 };
        let side = if rng.below(2) == 0 { "G41" } else { "G42" };
        let text = chain(&mut rng, scale, side);
        let name = format!("chain{case}.ngc");
        let (n, w) = agree(&rs274, &dir, &name, &text, 2.0 * radius / scale, radius);
        moves += n;
        worst[usize::from(inch)] = worst[usize::from(inch)].max(w);
    }
    eprintln!(
        "300 chains, {moves} moves agree, worst {:.2} µm in mm, {:.2} µm in inches",
        worst[0] * 1e3,
        worst[1] * 1e3
    );
}
