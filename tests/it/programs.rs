//! Real programs through the public API: what each block must be, measured against closed forms
//! and against curves built directly from the published data.

use std::f64::consts::PI;
use std::io::Cursor;
use std::path::Path;

use edmd::config::Config;
use edmd::gcode::{Block, BlockKind, BlockReader, NurbsForm, Plane, Warning, open_program};
use edmd::geometry::{NurbsCurve, point};
use edmd::vocab::Axis;

const XY: &[Axis] = &[Axis::X, Axis::Y];
const XYZ: &[Axis] = &[Axis::X, Axis::Y, Axis::Z];

fn parse(program: &str, axes: &[Axis]) -> (Vec<Block>, Vec<Warning>) {
    let mut reader = BlockReader::new(Cursor::new(program.as_bytes()), "t.nc", axes);
    let blocks = reader
        .by_ref()
        .collect::<Result<Vec<_>, _>>()
        .unwrap_or_else(|e| panic!("{e}"));
    (blocks, reader.take_warnings())
}

fn parse_file(path: &str, axes: &[Axis]) -> (Vec<Block>, Vec<Warning>) {
    let full = Path::new(env!("CARGO_MANIFEST_DIR")).join(path);
    let mut reader = open_program(&full, axes).unwrap();
    let blocks = reader
        .by_ref()
        .collect::<Result<Vec<_>, _>>()
        .unwrap_or_else(|e| panic!("{e}"));
    (blocks, reader.take_warnings())
}

fn nurbs_blocks(blocks: &[Block]) -> Vec<&Block> {
    blocks
        .iter()
        .filter(|b| matches!(b.kind, BlockKind::Nurbs { .. }))
        .collect()
}

fn feed_length(blocks: &[Block]) -> f64 {
    blocks
        .iter()
        .filter(|b| b.kind != BlockKind::Rapid)
        .map(|b| b.curve.length())
        .sum()
}

#[test]
fn huang_table1_is_the_papers_clamped_uniform_cubic() {
    let (blocks, warnings) = parse_file("programs/huang-table1-g38.nc", XY);
    let curves = nurbs_blocks(&blocks);
    assert_eq!(curves.len(), 1);
    let c = &curves[0].curve;
    let pts = [
        (10.0, 0.0),
        (20.0, 20.0),
        (12.0, 8.0),
        (10.0, 20.0),
        (8.0, 8.0),
        (0.0, 20.0),
        (10.0, 0.0),
    ];
    let points: Vec<_> = pts.iter().map(|&(x, y)| point(&[x, y])).collect();
    let want = NurbsCurve::new(
        3,
        2,
        &points,
        &[1.0; 7],
        vec![0.0, 0.0, 0.0, 0.0, 0.25, 0.5, 0.75, 1.0, 1.0, 1.0, 1.0],
    )
    .unwrap();
    assert_eq!(c, &want);
    assert_eq!(curves[0].line, 5);
    assert_eq!(
        curves[0].kind,
        BlockKind::Nurbs {
            form: NurbsForm::G38
        }
    );
    // No F in the paper's program: accepted, with one warning.
    assert_eq!(curves[0].feed_mm_per_min, None);
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert!(warnings[0].message.contains("without a programmed F"));
}

#[test]
fn jin_table1_carries_its_weights_and_feed() {
    let (blocks, warnings) = parse_file("programs/jin-table1-g06_2.nc", XY);
    assert!(warnings.is_empty(), "{warnings:?}");
    let c = &nurbs_blocks(&blocks)[0].curve;
    assert_eq!(c.degree(), 3);
    let weights: Vec<f64> = (0..7).map(|i| c.weight(i)).collect();
    assert_eq!(weights, [1.0, 10.0, 10.0, 1.0, 10.0, 10.0, 1.0]);
    assert_eq!(
        c.knots(),
        &[0.0, 0.0, 0.0, 0.0, 0.25, 0.5, 0.75, 1.0, 1.0, 1.0, 1.0]
    );
    assert_eq!(c.control_point(1), point(&[-150.0, -150.0]));
    assert_eq!(blocks[0].feed_mm_per_min, Some(18000.0));
}

#[test]
fn fanuc_ten_point_cubic_reproduces_the_published_vector() {
    let (blocks, _) = parse_file("tests/data/fanuc-g06_2-ten-point-cubic.nc", XY);
    assert_eq!(blocks.len(), 3);
    let nurbs = nurbs_blocks(&blocks)[0];
    assert_eq!(nurbs.line, 8);
    let d = nurbs.curve.derivs(3.5);
    assert!((d.point[0] - 37.943895833).abs() < 1e-8);
    assert!((d.point[1] - 55.599625).abs() < 1e-8);
    assert!((d.d1[0] - 8.799875).abs() < 1e-8);
    assert!((d.d1[1] - -2.6215).abs() < 1e-8);
    assert_eq!(blocks[2].end(), point(&[100.0, -10.0]));
}

#[test]
fn linuxcnc_butterfly_follows_g5_2_conventions() {
    let (blocks, warnings) = parse_file("tests/data/linuxcnc-g5_2-butterfly.ngc", XYZ);
    let curves = nurbs_blocks(&blocks);
    assert_eq!(curves.len(), 6);
    // The current position is the first control point; the default order is 3.
    let upper_right = &curves[0].curve;
    assert_eq!(upper_right.control_point(0), point(&[0.0, 0.0, -4.0]));
    assert_eq!(upper_right.num_points(), 8);
    assert_eq!(upper_right.degree(), 2);
    assert_eq!(upper_right.weight(0), 1.0);
    assert_eq!(upper_right.weight(1), 2.0);
    // LinuxCNC's knots: clamped uniform in whole numbers up to n - order + 2.
    assert_eq!(
        upper_right.knots(),
        &[0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 6.0, 6.0]
    );
    assert_eq!(curves[1].curve.degree(), 3); // L4
    // `G5.2 P1` without X Y: weight of the first point, then the points follow.
    let lower_left = &curves[3].curve;
    assert_eq!(lower_left.num_points(), 7);
    assert_eq!(lower_left.control_point(1), point(&[-6.0, -4.0, -4.0]));
    assert_eq!(lower_left.weight(2), 1.5);
    // The wings mirror each other, so their lengths agree.
    assert!((curves[2].curve.length() - curves[3].curve.length()).abs() < 1e-9);
    assert_eq!(curves[4].feed_mm_per_min, Some(400.0));
    // M3 and S warn once each; nothing else.
    assert_eq!(warnings.len(), 2, "{warnings:?}");
    assert_eq!(blocks.last().unwrap().end(), point(&[-7.0, 11.0, 25.0]));
}

#[test]
fn arcs_in_all_planes_match_their_closed_form_lengths_and_directions() {
    let (blocks, _) = parse_file("tests/data/arcs-all-planes.nc", XYZ);
    assert_eq!(blocks.len(), 8);
    assert!((feed_length(&blocks) - (37.5 * PI + 10.0)).abs() < 1e-9);
    let planes: Vec<Plane> = blocks
        .iter()
        .filter_map(|b| match b.kind {
            BlockKind::Arc { plane, .. } => Some(plane),
            _ => None,
        })
        .collect();
    use Plane::*;
    assert_eq!(planes, [XY, XY, XY, ZX, YZ, YZ, XY]);
    // Full circle: four quarter pieces, back to the start.
    assert_eq!(blocks[2].curve.num_points(), 9);
    assert_eq!(blocks[2].start(), blocks[2].end());
    // G18 G3 from X20 to X30 about X25 passes through Z+5 (counter-clockwise from +Z to +X).
    let mid = blocks[3].curve.point(0.5);
    assert!((mid - point(&[25.0, 0.0, 5.0])).norm() < 1e-12, "{mid:?}");
    // G19 G2 from Y0 to Y10 about Y5 passes through Z+5 (clockwise in Y-Z).
    let mid = blocks[4].curve.point(0.5);
    assert!((mid - point(&[30.0, 5.0, 5.0])).norm() < 1e-12, "{mid:?}");
    // G17 G2 from X0 to X10 about X5 passes through Y+5.
    let mid = blocks[0].curve.point(0.5);
    assert!((mid - point(&[5.0, 5.0, 0.0])).norm() < 1e-12, "{mid:?}");
    // Every sample of every arc is on its circle.
    for b in &blocks {
        if let BlockKind::Arc { center, radius, .. } = b.kind {
            for i in 0..=500 {
                let p = b.curve.point(i as f64 / 500.0);
                assert!(((p - center).norm() - radius).abs() < 1e-12 * radius);
            }
        }
    }
}

#[test]
fn inch_program_is_converted_to_millimetres() {
    let (blocks, _) = parse_file("tests/data/inch-g20-plate.nc", XY);
    assert_eq!(blocks.len(), 10);
    let want = (4.0 + 4.0 * PI * 0.25 / 2.0) * 25.4;
    assert!((feed_length(&blocks) - want).abs() < 1e-9);
    assert_eq!(blocks[1].feed_mm_per_min, Some(20.0 * 25.4));
    assert!((blocks[2].end() - point(&[50.8, 6.35])).norm() < 1e-12);
    assert_eq!(blocks.last().unwrap().end(), point(&[0.0, 0.0]));
}

#[test]
fn incremental_mode_applies_to_nurbs_control_points() {
    let absolute = "G0 X5 Y5\nF100\nG06.2 P3 K0 X5 Y5 R1\nK0 X7 Y9 R2\nK0 X10 Y9\nK1 X12 Y5\nK2\nK2\nK2\nM30\n";
    let incremental = "G0 X5 Y5\nF100\nG91\nG06.2 P3 K0 X0 Y0 R1\nK0 X2 Y4 R2\nK0 X3 Y0\nK1 X2 Y-4\nK2\nK2\nK2\nM30\n";
    let (a, _) = parse(absolute, XY);
    let (b, _) = parse(incremental, XY);
    assert_eq!(a[1].curve, b[1].curve);

    // G5.2 under G91 follows LinuxCNC: offsets from the curve's start point (X1 Y1).
    let g52_abs = "G0 X1 Y1\nF100\nG5.2 X2 Y3\nX4 Y3 P1\nX5 Y1 P1\nG5.3\nM30\n";
    let g52_inc = "G0 X1 Y1\nF100\nG91 G5.2 X1 Y2\nX3 Y2 P1\nX4 Y0 P1\nG5.3\nM30\n";
    assert_eq!(parse(g52_abs, XY).0[1].curve, parse(g52_inc, XY).0[1].curve);

    let g38_abs = "G0 X1 Y1\nG38 O2 C3 X1 Y1 F50\nG38 X3 Y4\nG38 X6 Y1\nM30\n";
    let g38_inc = "G0 X1 Y1\nG91\nG38 O2 C3 X0 Y0 F50\nG38 X2 Y3\nG38 X3 Y-3\nM30\n";
    assert_eq!(parse(g38_abs, XY).0[1].curve, parse(g38_inc, XY).0[1].curve);
}

#[test]
fn g38_with_explicit_knots_uses_them() {
    let program = "G0 X0 Y0\nG38 O2 C4 X0 Y0 K0 F60\nG38 X1 Y2 K0\nG38 X3 Y2 K0\nG38 X4 Y0 K2\nG38 K5\nG38 K5\nG38 K5\nM30\n";
    let (blocks, _) = parse(program, XY);
    assert_eq!(
        blocks[0].curve.knots(),
        &[0.0, 0.0, 0.0, 2.0, 5.0, 5.0, 5.0]
    );
    assert_eq!(blocks[0].end(), point(&[4.0, 0.0]));
}

#[test]
fn r_form_arcs_choose_minor_or_major_by_sign() {
    // The tool starts at the origin, so the arc is the only block.
    let (minor, _) = parse("G2 X6 Y0 R5 F10\n", XY);
    let (major, _) = parse("G2 X6 Y0 R-5 F10\n", XY);
    let sweep = |b: &Block| match b.kind {
        BlockKind::Arc { sweep, .. } => sweep,
        _ => panic!("not an arc"),
    };
    let half_angle = (3.0f64 / 5.0).asin();
    assert!((sweep(&minor[0]) + 2.0 * half_angle).abs() < 1e-12);
    assert!((sweep(&major[0]) + 2.0 * PI - 2.0 * half_angle).abs() < 1e-12);
    // Clockwise from (0,0) to (6,0): the minor arc's centre is (3,-4), so its middle is (3,1);
    // the major arc's centre is (3,4) and it swings over the top, through (3,9).
    assert!((minor[0].curve.point(0.5) - point(&[3.0, 1.0])).norm() < 1e-12);
    assert!((major[0].curve.point(0.5) - point(&[3.0, 9.0])).norm() < 1e-12);
}

#[test]
fn program_end_and_tape_marks() {
    let (blocks, warnings) = parse("%\nG0 X1\nM30\n%\n", XY);
    assert_eq!(blocks.len(), 1);
    assert!(warnings.is_empty(), "{warnings:?}");
    let (blocks, warnings) = parse("G0 X1\nM2\nG0 X5\nG0 X9\n", XY);
    assert_eq!(blocks.len(), 1, "nothing after M2 runs");
    assert_eq!(warnings.len(), 1);
    assert_eq!(warnings[0].line, 3);
    assert!(warnings[0].message.contains("after the program end"));
    let (_, warnings) = parse("G0 X1\n", XY);
    assert!(warnings[0].message.contains("no M2/M30"));
}

#[test]
fn a_closing_percent_ends_the_program() {
    // `%`, three blocks, `%`, then a move: LinuxCNC and Fanuc stop reading at the second `%`.
    let (blocks, warnings) = parse("%\nG1 X1 F60\nG1 X2\nG1 X3\n%\nG1 X99 Y99\nG1 X5\n", XY);
    assert_eq!(blocks.len(), 3);
    assert_eq!(blocks[2].end()[0], 3.0);
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert_eq!(warnings[0].line, 6);
    assert!(
        warnings[0]
            .message
            .contains("after the closing `%` (line 5)")
    );
    // Without an opening mark too, and a closing `%` is an end: no "no M2/M30" warning.
    let (blocks, warnings) = parse("G1 X1 F60\n%\n\n", XY);
    assert_eq!(blocks.len(), 1);
    assert!(warnings.is_empty(), "{warnings:?}");
    // A curve still open at the closing `%` is unterminated, as at the end of the file.
    let mut reader = BlockReader::new(
        Cursor::new(&b"G0 X0 Y0\nG5.2 X1 Y1 P1 L4\nX2 Y0 P1\n%\nX3 Y1\n"[..]),
        "t.nc",
        XY,
    );
    let err = reader.find_map(Result::err).expect("an unterminated curve");
    assert!(err.to_string().contains("t.nc:2:"), "{err}");
}

#[test]
fn a_byte_order_mark_is_not_text() {
    let (blocks, warnings) = parse("\u{feff}%\nG1 X1 F60\nM30\n%\n", XY);
    assert_eq!(blocks.len(), 1);
    assert!(warnings.is_empty(), "{warnings:?}");
    let (blocks, _) = parse("\u{feff}G1 X2 F60\nM30\n", XY);
    assert_eq!(blocks[0].end()[0], 2.0);
    // Only at the start of the file: elsewhere it is still an unexpected character.
    let mut reader = BlockReader::new(
        Cursor::new("G1 X1 F60\n\u{feff}G1 X2\n".as_bytes()),
        "t.nc",
        XY,
    );
    let err = reader
        .find_map(Result::err)
        .expect("a BOM inside the program");
    assert!(err.to_string().starts_with("t.nc:2:1:"), "{err}");
}

#[test]
fn accepted_modes_and_ignored_words() {
    let (blocks, warnings) = parse(
        "N10 G17 G21 G40 G49 G54 G64 G80 G90 G94\nG61\nT1 M6\nS1000 M3\nG0 X1 Y1\nM8\nM5\nM30\n",
        XY,
    );
    assert_eq!(blocks.len(), 1);
    // T, M6 (first M), S: one warning per letter, not per occurrence.
    let letters: Vec<char> = warnings
        .iter()
        .map(|w| w.message.chars().next().unwrap())
        .collect();
    assert_eq!(letters, ['M', 'T', 'S'], "{warnings:?}");
}

#[test]
fn modal_motion_needs_axis_words_and_nurbs_cancels_it() {
    let (blocks, _) = parse("G1 F10\nX1\nY1\nG91.1\nG0\nX0 Y0\n", XY);
    assert_eq!(blocks.len(), 3);
    assert_eq!(blocks[2].kind, BlockKind::Rapid);
    let err = BlockReader::new(
        Cursor::new("G0 X0 Y0\nG5.2 X1 Y1\nX2 Y0 P1\nG5.3\nX5\n"),
        "t.nc",
        XY,
    )
    .find_map(Result::err)
    .unwrap();
    assert!(err.to_string().contains("without a motion mode"), "{err}");
}

#[test]
fn zero_length_moves_produce_no_block() {
    let (blocks, _) = parse("G0 X1\nG1 X1 F10\nG0 X1 Y0\nM30\n", XY);
    assert_eq!(blocks.len(), 1);
}

#[test]
fn a_large_program_streams_block_by_block() {
    // 200,000 lines, generated on the fly: the reader holds one line at a time.
    struct Generated {
        line: u64,
        total: u64,
        buf: Vec<u8>,
        pos: usize,
    }
    impl std::io::Read for Generated {
        fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
            if self.pos == self.buf.len() {
                if self.line == self.total {
                    return Ok(0);
                }
                self.line += 1;
                self.buf = format!(
                    "G1 X{}.{:03} Y{} F600\n",
                    self.line / 1000,
                    self.line % 1000,
                    self.line % 2
                )
                .into_bytes();
                self.pos = 0;
            }
            let n = out.len().min(self.buf.len() - self.pos);
            out[..n].copy_from_slice(&self.buf[self.pos..self.pos + n]);
            self.pos += n;
            Ok(n)
        }
    }
    // A program without loops or calls never seeks back.
    impl std::io::Seek for Generated {
        fn seek(&mut self, _: std::io::SeekFrom) -> std::io::Result<u64> {
            Err(std::io::ErrorKind::Unsupported.into())
        }
    }
    let source = Generated {
        line: 0,
        total: 200_000,
        buf: Vec::new(),
        pos: 0,
    };
    let reader = BlockReader::new(std::io::BufReader::new(source), "gen.nc", XY);
    let mut count = 0u64;
    let mut last = None;
    for block in reader {
        let block = block.unwrap();
        count += 1;
        last = Some(block.end());
    }
    assert_eq!(count, 200_000);
    assert_eq!(last, Some(point(&[200.0, 0.0])));
}

#[test]
fn the_default_config_axes_read_the_shipped_programs() {
    let cfg = Config::default();
    for p in [
        "programs/huang-table1-g38.nc",
        "programs/jin-table1-g06_2.nc",
    ] {
        assert!(!parse_file(p, &cfg.machine.axes).0.is_empty());
    }
}

#[test]
fn spindle_speed_modes_are_accepted_with_one_warning() {
    // LinuxCNC's NURBS examples start this way.
    let (blocks, warnings) = parse(
        "G21 G90 G17\nG96 M3 S200\nG1 X1 F100\nG97 S1000\nG1 X2\nM30\n",
        XY,
    );
    assert_eq!(blocks.len(), 2);
    let spindle: Vec<_> = warnings
        .iter()
        .filter(|w| w.message.contains("G96/G97"))
        .collect();
    assert_eq!(spindle.len(), 1, "{warnings:?}");
    assert_eq!((spindle[0].line, spindle[0].col), (2, 1));
}

/// LinuxCNC's `G5.2` (interp_convert.cc, `convert_nurbs`): under G91 every control point is
/// relative to the curve's start; an order L below 3 is 3; only X and Y make the curve.
#[test]
fn g5_2_follows_linuxcnc_under_g91_with_low_orders_and_off_plane_words() {
    // From the origin: LinuxCNC ends at X3 Y1 (start + offset), not X6 Y2 (chained).
    let (blocks, warnings) = parse(
        "G21 G91 G17 F100\nG5.2 X1 Y1 P1\nX2 Y0 P1\nX3 Y1 P1\nG5.3\nM30\n",
        XY,
    );
    let c = &nurbs_blocks(&blocks)[0].curve;
    assert_eq!(c.end_point(), point(&[3.0, 1.0]));
    assert_eq!(c.control_point(2), point(&[2.0, 0.0]));
    assert!(
        warnings
            .iter()
            .any(|w| w.message.contains("relative to the curve's start")),
        "{warnings:?}"
    );
    // Absolute coordinates mean the same thing either way: no warning.
    let (_, warnings) = parse(
        "G21 G90 G17 F100\nG5.2 X1 Y1 P1\nX2 Y0 P1\nX3 Y1 P1\nG5.3\nM30\n",
        XY,
    );
    assert!(
        warnings.iter().all(|w| !w.message.contains("G91")),
        "{warnings:?}"
    );

    // L2 is order 3 (degree 2), not a polyline; L4 stays order 4.
    let (blocks, warnings) = parse(
        "G21 G90 F100\nG5.2 X1 Y1 P1 L2\nX2 Y0 P1\nX3 Y1 P1\nG5.3\nG5.2 X4 Y0 P1 L4\nX5 Y2 P1\nX6 Y0 P1\nX7 Y1 P1\nG5.3\nM30\n",
        XY,
    );
    let curves = nurbs_blocks(&blocks);
    assert_eq!(curves[0].curve.degree(), 2);
    assert_eq!(curves[1].curve.degree(), 3);
    let order = warnings
        .iter()
        .find(|w| w.message.contains("order below 3"))
        .unwrap();
    assert_eq!((order.line, order.col), (2, 15));

    // Z on a G5.2 line is not part of the curve: it stays at the start's Z.
    let (blocks, warnings) = parse(
        "G21 G90 F100\nG1 Z-2\nG5.2 X1 Y1 Z5 P1\nX2 Y0 P1\nX3 Y1 Z7 P1\nG5.3\nM30\n",
        XYZ,
    );
    let c = &nurbs_blocks(&blocks)[0].curve;
    for i in 0..c.num_points() {
        assert_eq!(c.control_point(i)[2], -2.0, "control point {i}");
    }
    let z = warnings
        .iter()
        .find(|w| w.message.contains("X and Y only"))
        .unwrap();
    assert_eq!((z.line, z.col), (3, 12));
}

#[test]
fn a_latin1_comment_is_read_with_one_warning() {
    let program = b"(Elektrode \xd8 5 mm)\nG1 X1 F60 (\xe9)\nM30\n";
    let mut reader = BlockReader::new(Cursor::new(&program[..]), "t.nc", XY);
    let blocks: Vec<Block> = reader.by_ref().collect::<Result<_, _>>().unwrap();
    assert_eq!(blocks.len(), 1);
    let warnings = reader.take_warnings();
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert_eq!(warnings[0].line, 1);
    assert!(warnings[0].message.contains("Latin-1"), "{warnings:?}");
}

#[test]
fn path_blending_and_tool_length_words_are_ignored_with_one_warning_each() {
    let (blocks, warnings) = parse(
        "G64 P0.01 Q0.005\nG43 H1\nG1 X1 F60\nG64 P0.02\nG43 H2 X2\nG49\nM30\n",
        XY,
    );
    assert_eq!(blocks.len(), 2);
    assert_eq!(blocks[1].end()[0], 2.0);
    assert_eq!(warnings.len(), 2, "{warnings:?}");
    assert!(warnings[0].message.contains("G64 P/Q"), "{warnings:?}");
    assert!(warnings[1].message.contains("G43"), "{warnings:?}");
    // A bare G64 is the mode edmd is in: no warning.
    let (_, warnings) = parse("G64\nG1 X1 F60\nM30\n", XY);
    assert!(warnings.is_empty(), "{warnings:?}");
}
