//! The wire offset (`G41`/`G42` with `D`) on wire-EDM style programs: a die with corners trimmed
//! inside, a punch with a notch (rounded outside corners, trimmed inside ones), a NURBS punch, a
//! parametric slot from a subroutine, a die as Fanuc-style posts write it (`G41 H01`). Every compensated move is sampled densely and its
//! distance to the programmed contour is measured here, against contours the test builds from
//! closed forms (segments, arcs, a NURBS curve built directly), not by the code under test:
//! each sample must be `d` away within the chord tolerance, on the side G41/G42 names.

use std::f64::consts::PI;
use std::io::Cursor;

use crate::common;
use edmd::gcode::{Block, BlockReader, GcodeError, ProgramOptions};
use edmd::geometry::{NurbsCurve, clamped_uniform_knots, point};
use edmd::vocab::Axis;

const XY: &[Axis] = &[Axis::X, Axis::Y];
const TOL: f64 = 0.001;

fn read(program: &str, d: f64) -> Result<Vec<Block>, GcodeError> {
    let options = ProgramOptions {
        d_mm: vec![0.0, d],
        offset_tolerance_mm: TOL,
        ..ProgramOptions::default()
    };
    common::program_path(BlockReader::with_options(
        Cursor::new(program.as_bytes()),
        "w.ngc",
        XY,
        options,
    ))
    .collect::<Result<Vec<_>, _>>()
}

type V = (f64, f64);

/// A closed contour as the test knows it: a dense polygon (exact for segments; arcs and
/// curves sampled finely enough that the polygon's own error is far below the tolerance).
struct Contour(Vec<V>);

impl Contour {
    fn distance(&self, q: V) -> f64 {
        self.0
            .windows(2)
            .map(|w| segment_distance(q, w[0], w[1]))
            .fold(f64::INFINITY, f64::min)
    }

    /// Winding number test: `q` inside the closed polygon.
    fn inside(&self, q: V) -> bool {
        let mut inside = false;
        for w in self.0.windows(2) {
            let (a, b) = (w[0], w[1]);
            if (a.1 > q.1) != (b.1 > q.1) && q.0 < a.0 + (q.1 - a.1) * (b.0 - a.0) / (b.1 - a.1) {
                inside = !inside;
            }
        }
        inside
    }
}

fn segment_distance(q: V, a: V, b: V) -> f64 {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len2 = dx * dx + dy * dy;
    let t = if len2 == 0.0 {
        0.0
    } else {
        (((q.0 - a.0) * dx + (q.1 - a.1) * dy) / len2).clamp(0.0, 1.0)
    };
    (q.0 - a.0 - t * dx).hypot(q.1 - a.1 - t * dy)
}

/// Appends an arc about `c` from the polygon's last point, sweeping `sweep` radians.
fn arc_to(poly: &mut Vec<V>, c: V, sweep: f64) {
    let p = *poly.last().unwrap();
    let r = (p.0 - c.0).hypot(p.1 - c.1);
    let a0 = (p.1 - c.1).atan2(p.0 - c.0);
    let n = 20_000;
    for i in 1..=n {
        let a = a0 + sweep * i as f64 / n as f64;
        poly.push((c.0 + r * a.cos(), c.1 + r * a.sin()));
    }
}

/// Checks every compensated move of `blocks` on `lines` (the contour's source lines): each
/// of 400 samples per move is `d` from the contour within the tolerance, inside or not.
fn assert_offset(
    blocks: &[Block],
    lines: std::ops::RangeInclusive<u64>,
    contour: &Contour,
    d: f64,
    inside: bool,
) {
    let mut samples = 0;
    let mut worst: f64 = 0.0;
    for b in blocks.iter().filter(|b| lines.contains(&b.line)) {
        let (u0, u1) = (b.curve.u_min(), b.curve.u_max());
        for i in 0..=400 {
            let p = b.curve.point(u0 + (u1 - u0) * i as f64 / 400.0);
            let q = (p[0], p[1]);
            let dist = contour.distance(q);
            worst = worst.max((dist - d).abs());
            assert!(
                (dist - d).abs() <= TOL,
                "line {}: ({:.6}, {:.6}) is {dist:.6} mm from the contour, not {d}",
                b.line,
                q.0,
                q.1
            );
            assert_eq!(
                contour.inside(q),
                inside,
                "line {}: wrong side at {q:?}",
                b.line
            );
            samples += 1;
        }
    }
    assert!(samples > 1000, "only {samples} samples");
    eprintln!("{samples} samples, worst |distance - d| = {worst:.2e} mm");
}

/// The moves chain: each starts where the one before ended.
fn assert_continuous(blocks: &[Block]) {
    for w in blocks.windows(2) {
        let gap = (w[0].end() - w[1].start()).norm();
        assert!(
            gap < 1e-9,
            "gap of {gap} mm between lines {} and {}",
            w[0].line,
            w[1].line
        );
    }
}

const DIE: &str = "\
(die: a 20 x 12 opening with a rounded corner, cut counter-clockwise, wire inside: G41)
G21 G90 G17
G0 X5 Y5
G41 D1 G1 X5 Y0 F60
G1 X20 Y0
G1 X20 Y10
G3 X18 Y12 I-2 J0
G1 X0 Y12
G1 X0 Y0
G1 X5 Y0
G40 G1 X5 Y5
M2
";

fn die_contour() -> Contour {
    let mut p = vec![(5.0, 0.0), (20.0, 0.0), (20.0, 10.0)];
    arc_to(&mut p, (18.0, 10.0), PI / 2.0);
    p.extend([(0.0, 12.0), (0.0, 0.0), (5.0, 0.0)]);
    Contour(p)
}

#[test]
fn die_corners_are_trimmed_inside() {
    let d = 0.25;
    let blocks = read(DIE, d).unwrap();
    assert_continuous(&blocks);
    assert_offset(&blocks, 5..=10, &die_contour(), d, true);
    // Concave corners only: no corner arcs; the programmed arc's radius shrinks by d.
    let arcs: Vec<f64> = blocks
        .iter()
        .filter_map(|b| match b.kind {
            edmd::gcode::BlockKind::Arc { radius, .. } => Some(radius),
            _ => None,
        })
        .collect();
    assert_eq!(arcs, vec![2.0 - d]);
    // Entry from the start hole and exit back to it, uncompensated at their far ends.
    assert_eq!((blocks[1].start()[0], blocks[1].start()[1]), (5.0, 5.0));
    let last = blocks.last().unwrap();
    assert_eq!((last.end()[0], last.end()[1]), (5.0, 5.0));
    // D0 is no offset at all: the programmed path.
    let plain = read(DIE, 0.0).unwrap();
    let zero = read(&DIE.replace("D1", "D0"), d).unwrap();
    assert_eq!(plain.len(), zero.len());
    for (a, b) in plain.iter().zip(&zero) {
        assert_eq!(a.curve, b.curve);
    }
}

const PUNCH: &str = "\
(punch with a notch: 30 x 20 outline, a 4 mm wide, 5 mm deep notch in the top edge)
(cut counter-clockwise with the wire outside: G42)
G21 G90 G17
G0 X-5 Y-5
G42 D1 G1 X0 Y0 F60
G1 X30 Y0
G1 X30 Y20
G1 X17 Y20
G1 X17 Y15
G1 X13 Y15
G1 X13 Y20
G1 X0 Y20
G1 X0 Y0
G40 G1 X-5 Y-5
M2
";

#[test]
fn punch_corners_are_rounded_outside_and_the_notch_trimmed() {
    let d = 0.3;
    let blocks = read(PUNCH, d).unwrap();
    assert_continuous(&blocks);
    let contour = Contour(vec![
        (0.0, 0.0),
        (30.0, 0.0),
        (30.0, 20.0),
        (17.0, 20.0),
        (17.0, 15.0),
        (13.0, 15.0),
        (13.0, 20.0),
        (0.0, 20.0),
        (0.0, 0.0),
    ]);
    assert_offset(&blocks, 6..=12, &contour, d, false);
    // Three outer corners and the notch's two top corners are convex on the outside: arcs of
    // radius d about them; the notch's bottom corners are concave: trimmed. (The fourth outer
    // corner is where the entry and exit moves meet the contour.)
    let corner_arcs = blocks
        .iter()
        .filter(|b| matches!(b.kind, edmd::gcode::BlockKind::Arc { radius, .. } if radius == d))
        .count();
    assert_eq!(corner_arcs, 5);
}

#[test]
fn a_notch_narrower_than_the_wire_is_refused() {
    let e = read(PUNCH, 2.5).unwrap_err().to_string();
    assert!(e.contains("wire offset"), "{e}");
    assert!(e.starts_with("w.ngc:1"), "{e}");
}

const NURBS_PUNCH: &str = "\
(NURBS punch: a cubic G5.2 top edge, then straight sides; cut clockwise, wire outside: G41)
G21 G90 G17
G0 X-5 Y0
G41 D1 G1 X0 Y0 F60
G5.2 X5 Y10 P1 L4
X10 Y-5 P2
X15 Y5 P1
X20 Y0 P1
G5.3
G1 X20 Y-10
G1 X0 Y-10
G1 X0 Y0
G40 G1 X-5 Y0
M2
";

#[test]
fn a_nurbs_contour_is_offset_within_the_tolerance() {
    // The top edge built directly: LinuxCNC's G5.2 takes the current point as the first
    // control point and clamped uniform knots.
    let pts = [
        (0.0, 0.0),
        (5.0, 10.0),
        (10.0, -5.0),
        (15.0, 5.0),
        (20.0, 0.0),
    ];
    let weights = [1.0, 1.0, 2.0, 1.0, 1.0];
    let curve = NurbsCurve::new(
        3,
        2,
        &pts.iter().map(|&(x, y)| point(&[x, y])).collect::<Vec<_>>(),
        &weights,
        clamped_uniform_knots(5, 3),
    )
    .unwrap();
    let n = 50_000;
    let mut poly: Vec<V> = (0..=n)
        .map(|i| {
            let p =
                curve.point(curve.u_min() + (curve.u_max() - curve.u_min()) * i as f64 / n as f64);
            (p[0], p[1])
        })
        .collect();
    poly.extend([(20.0, -10.0), (0.0, -10.0), (0.0, 0.0)]);
    let contour = Contour(poly);
    for d in [0.15, 0.5] {
        let blocks = read(NURBS_PUNCH, d).unwrap();
        assert_continuous(&blocks);
        assert_offset(&blocks, 5..=12, &contour, d, false);
    }
    // Tighter than its smallest radius on the inner side: refused, naming the curve's line.
    let e = read(NURBS_PUNCH, 4.0).unwrap_err().to_string();
    assert!(
        e.starts_with("w.ngc:5:1: wire offset: the curve turns tighter"),
        "{e}"
    );
}

const SLOT: &str = "\
(parametric slot: a stadium of length len and end radius r about cx, cy)
(drawn by a subroutine, cut counter-clockwise with the wire inside: G41)
G21 G90 G17
#<len> = 8
#<r> = 1.5
#<cx> = 10
#<cy> = 5
o<stadium> sub
  G1 X[#1 + #3 / 2] Y[#2 - #4]
  G3 X[#1 + #3 / 2] Y[#2 + #4] I0 J#4
  G1 X[#1 - #3 / 2] Y[#2 + #4]
  G3 X[#1 - #3 / 2] Y[#2 - #4] I0 J-#4
  G1 X#1 Y[#2 - #4]
o<stadium> endsub
G0 X#<cx> Y#<cy>
G41 D1 G1 X#<cx> Y[#<cy> - #<r>] F30
o<stadium> call [#<cx>] [#<cy>] [#<len>] [#<r>]
G40 G1 X#<cx> Y#<cy>
M2
";

#[test]
fn a_parametric_slot_from_a_subroutine() {
    let d = 0.2;
    let blocks = read(SLOT, d).unwrap();
    assert_continuous(&blocks);
    // The stadium in closed form: distance to its boundary is |dist to the core segment - r|.
    let (len, r, cx, cy) = (8.0, 1.5, 10.0, 5.0);
    let core = ((cx - len / 2.0, cy), (cx + len / 2.0, cy));
    let mut samples = 0;
    for b in blocks.iter().filter(|b| (9..=13).contains(&b.line)) {
        for i in 0..=400 {
            let p = b
                .curve
                .point(b.curve.u_min() + (b.curve.u_max() - b.curve.u_min()) * i as f64 / 400.0);
            let to_core = segment_distance((p[0], p[1]), core.0, core.1);
            assert!(to_core < r, "outside the slot at {p:?}");
            assert!(
                ((r - to_core) - d).abs() <= 1e-9,
                "line {}: {} from the edge",
                b.line,
                r - to_core
            );
            samples += 1;
        }
    }
    assert!(samples > 2000);
}

#[test]
fn moves_the_offset_cannot_take_are_errors_naming_the_line() {
    let err = |p: &str| read(p, 0.2).unwrap_err().to_string();
    // As LinuxCNC: the entry must be longer than the offset (an arc entry is a move like
    // a line's: `tests/it/wire_offset_linuxcnc.rs`).
    let e = err("G0 X0 Y0\nG41 D1 G1 X0.15 F10\n");
    assert!(
        e.starts_with(
            "w.ngc:2:1: wire offset: the entry move (the first move after G41/G42) is 0.15 mm \
             long, not longer than the wire offset 0.2 mm"
        ),
        "{e}"
    );
    let e = err("G0 X0 Y0\nG41 D1 G1 X1 F10\nG1 X2\nG40 G3 X4 I1 J0\n");
    assert!(
        e.starts_with("w.ngc:4:1: wire offset: the first move after G40"),
        "{e}"
    );
    let three = ProgramOptions {
        d_mm: vec![0.0, 0.2],
        ..ProgramOptions::default()
    };
    let e = common::program_path(BlockReader::with_options(
        Cursor::new(&b"G0 X0 Y0\nG41 D1 G1 X1 F10\nG1 X2 Z1\nM2\n"[..]),
        "w.ngc",
        &[Axis::X, Axis::Y, Axis::Z],
        three,
    ))
    .find_map(Result::err)
    .unwrap()
    .to_string();
    assert!(
        e.starts_with("w.ngc:3:1: wire offset: only X and Y may move"),
        "{e}"
    );
    let e = err("G0 X0 Y0\nG41 D1 G1 X1 F10\nG1 X2\nG42 D1 G1 X3\n");
    assert!(
        e.starts_with("w.ngc:4:1: wire offset: the wire offset is already on"),
        "{e}"
    );
}

/// Every configuration the repository ships keeps its files in a state directory of its own:
/// trying an example never writes into the service's (`/var/lib/edmd`, the default file's).
#[test]
fn every_shipped_configuration_has_a_state_directory_of_its_own() {
    let repo = common::repo();
    let mut dirs = std::collections::BTreeMap::new();
    for file in [
        "config/edmd.toml",
        "config/fanuc-wire.toml",
        "config/hal/sim.toml",
    ] {
        let config = edmd::config::Config::load(Some(&repo.join(file)), &[]).expect(file);
        let dir = config.daemon.state_dir.clone();
        if let Some(other) = dirs.insert(dir.clone(), file) {
            panic!("{file} and {other} share {}", dir.display());
        }
        // Its history and checkpoint live there unless the file names another place.
        assert!(config.daemon.job_history.starts_with(&dir), "{file}");
    }
    // And no other configuration hides in config/ (the technology tables are not ones).
    let shipped: Vec<_> = ["config", "config/hal"]
        .iter()
        .flat_map(|d| std::fs::read_dir(repo.join(d)).unwrap())
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    assert_eq!(shipped.len(), dirs.len(), "{shipped:?}");
}

/// A wire program as Fanuc-style posts write it (`G41 H01`, `N` numbers, `G92` at the start
/// hole, the wire and flushing M-codes) reads with the shipped example layer
/// `config/fanuc-wire.toml`: `H01` offsets as `D1` does, the M-codes pause and flush as its
/// tables say, and nothing is refused.
#[test]
fn a_fanuc_style_wire_program_cuts_with_h_registers_and_the_example_m_codes() {
    let repo = common::repo();
    let config = edmd::config::Config::load(Some(&repo.join("config/fanuc-wire.toml")), &[])
        .expect("the example layer loads");
    let options = ProgramOptions::from_config(&config);
    let text = std::fs::read_to_string(repo.join("tests/data/fanuc-wire-die.nc")).unwrap();
    let read = |text: &str| -> Vec<Block> {
        let reader = BlockReader::with_options(
            Cursor::new(text.as_bytes().to_vec()),
            "fanuc-wire-die.nc",
            XY,
            options.clone(),
        );
        common::program_path(reader)
            .collect::<Result<_, _>>()
            .expect("reads")
    };
    let by_h = read(&text);
    let by_d = read(&text.replace("H01", "D1"));
    assert_eq!(by_h.len(), by_d.len());
    for (h, d) in by_h.iter().zip(&by_d) {
        assert_eq!(h.end(), d.end(), "H01 is the register D1 is");
    }
    assert_continuous(&by_h);
    // The die's corners: 0.145 mm inside the 10 mm square.
    let corner = by_h
        .iter()
        .map(|b| b.end())
        .find(|p| p[0] > 4.0 && p[1] > 4.0)
        .expect("a corner");
    assert!(
        (corner[0] - 4.855).abs() < 1e-9 && (corner[1] - 4.855).abs() < 1e-9,
        "{corner:?}"
    );
    // M60 paused before the cut (its line, 6), M80 turned the flushing on for all of it.
    assert_eq!(by_h[0].pause.map(|(line, _)| line), Some(6), "M60");
    assert!(by_h.iter().all(|b| b.flushing), "M80");
}
