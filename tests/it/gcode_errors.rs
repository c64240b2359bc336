//! Malformed programs: each must fail with the right line, column and message, and none may
//! panic — also not on random bytes.

use std::io::Cursor;

use crate::common;
use edmd::gcode::{BlockReader, GcodeError};
use edmd::vocab::Axis;
use proptest::prelude::*;

const XY: &[Axis] = &[Axis::X, Axis::Y];
const XYZ: &[Axis] = &[Axis::X, Axis::Y, Axis::Z];
const XYZUV: &[Axis] = &[Axis::X, Axis::Y, Axis::Z, Axis::U, Axis::V];

/// Runs the program to its first error.
fn first_error(program: &[u8], axes: &[Axis]) -> Option<GcodeError> {
    common::program_path(BlockReader::new(Cursor::new(program), "t.nc", axes)).find_map(Result::err)
}

struct Case {
    name: &'static str,
    program: &'static str,
    axes: &'static [Axis],
    line: u64,
    col: usize,
    gist: &'static str,
}

const fn case(
    name: &'static str,
    program: &'static str,
    line: u64,
    col: usize,
    gist: &'static str,
) -> Case {
    Case {
        name,
        program,
        axes: XY,
        line,
        col,
        gist,
    }
}

fn cases() -> Vec<Case> {
    vec![
        // ---- words and numbers
        case(
            "unknown G word",
            "G21\nG1 X1 G12 Y2\n",
            2,
            7,
            "unknown G word G12",
        ),
        case("unknown M word", "G21\nM52\n", 2, 1, "unknown M word M52"),
        case(
            "M99 in the main program",
            "G21\nM99\n",
            2,
            1,
            "M99 outside a subprogram",
        ),
        case(
            "unknown letter",
            "G1 X1 H5 F10\n",
            1,
            7,
            "word H is not used with G1",
        ),
        case(
            "undefined machining condition",
            "G1 X1 E5 F10\n",
            1,
            7,
            "E5: no such machining condition (generator.condition defines none)",
        ),
        case("pallet change", "M60\n", 1, 1, "unknown M word M60"),
        case(
            "missing number",
            "G1 X F10\n",
            1,
            4,
            "X must be followed by a number",
        ),
        case(
            "NaN literal",
            "G1 Xnan Y1 F10\n",
            1,
            4,
            "X must be followed by a number",
        ),
        case(
            "inf literal",
            "G1 X1 Yinf F10\n",
            1,
            7,
            "Y must be followed by a number",
        ),
        case(
            "huge literal",
            "G1 X12345678901 F10\n",
            1,
            4,
            "number out of range",
        ),
        case(
            "exponent literal",
            "G1 X1e5 F10\n",
            1,
            6,
            "exponent notation",
        ),
        case(
            "two decimal points",
            "G1 X1.2.3 F10\n",
            1,
            4,
            "`1.2.3` is not a number",
        ),
        case("repeated word", "G1 X1 X2 F10\n", 1, 7, "X given twice"),
        case(
            "conflicting motion",
            "G0 G1 X1\n",
            1,
            4,
            "G0 and G1 in one block",
        ),
        case(
            "conflicting units",
            "G20 G21\n",
            1,
            5,
            "G20 and G21 in one block",
        ),
        case(
            "wire offset register not set",
            "G41 D1\n",
            1,
            5,
            "D1 is not set: compensation.d_mm has registers 0 to 0",
        ),
        case(
            "wire offset register by H not set",
            "G41 H02\n",
            1,
            5,
            "H2 is not set: compensation.d_mm has registers 0 to 0",
        ),
        case(
            "wire offset by D and H",
            "G41 D0 H0\n",
            1,
            8,
            "D and H both name the offset register",
        ),
        case(
            "wire offset without D",
            "G42 G1 X1 F1\n",
            1,
            1,
            "G42 needs D",
        ),
        case(
            "wire offset outside G17",
            "G18 G41 D0\n",
            1,
            5,
            "XY plane (G17) only",
        ),
        case(
            "dynamic compensation",
            "G41.1 D1\n",
            1,
            1,
            "dynamic compensation",
        ),
        case("feed per revolution", "G95\n", 1, 1, "feed per revolution"),
        case("dwell without P", "G4\n", 1, 1, "G4 needs P"),
        case(
            "negative dwell",
            "G4 P-1\n",
            1,
            4,
            "dwell P (s) out of range",
        ),
        case(
            "probing without a feed",
            "G38.2 X1\n",
            1,
            1,
            "G38.2 needs a feed F (the probing speed)",
        ),
        case(
            "probing to where it is",
            "G1 X1 F10\nG38.2 X1\n",
            2,
            1,
            "G38.2 needs an end point away from where it starts",
        ),
        case(
            "undefined named parameter",
            "G1 X#<width> F1\n",
            1,
            5,
            "parameter #<width> is not set",
        ),
        case(
            "unclosed expression",
            "G1 X[1+2 F1\n",
            1,
            10,
            "`]` expected",
        ),
        case(
            "division by zero",
            "#1 = [2 / 0]\n",
            1,
            9,
            "division by zero",
        ),
        case(
            "block delete mid-line",
            "G1 X1 /Y2\n",
            1,
            7,
            "block delete `/` must start the line",
        ),
        case(
            "else without if",
            "G0 X1\no1 else\n",
            2,
            1,
            "O1 else: without its if",
        ),
        case(
            "zero feed",
            "G1 X1 F0\n",
            1,
            7,
            "feed F must be at least 0.001 mm/min",
        ),
        case(
            "negative feed",
            "G1 X1 F-5\n",
            1,
            7,
            "feed F must be at least 0.001 mm/min",
        ),
        case(
            "a feed below the minimum",
            "G1 X1 F0.0000001\n",
            1,
            7,
            "feed F must be at least 0.001 mm/min (a micrometre a minute)",
        ),
        case(
            "axis not on machine",
            "G1 Z5 F10\n",
            1,
            4,
            "axis Z is not on this machine",
        ),
        case(
            "axis words without motion",
            "G21\nX5 Y5\n",
            2,
            1,
            "without a motion mode",
        ),
        case(
            "word without motion",
            "G21\nI5\n",
            2,
            1,
            "word I is not used without a motion word",
        ),
        case(
            "percent with words",
            "% G1 X1\n",
            1,
            1,
            "`%` must stand alone",
        ),
        case(
            "fractional line number",
            "N1.5 G1 X1 F1\n",
            1,
            1,
            "N needs a whole number",
        ),
        // ---- comments
        case(
            "unterminated comment",
            "G21\nG1 X1 (to the left F10\n",
            2,
            7,
            "never closed",
        ),
        case(
            "nested comment",
            "(outer (inner) outer)\n",
            1,
            8,
            "comments do not nest",
        ),
        // ---- arcs
        case(
            "R and IJK together",
            "G0 X0 Y0\nG2 X10 Y0 I5 R5 F10\n",
            2,
            14,
            "both R and I/J/K",
        ),
        case(
            "arc without centre",
            "G0 X0 Y0\nG2 X10 Y0 F10\n",
            2,
            1,
            "needs its centre",
        ),
        case(
            "spiral too far from an arc",
            "G0 X0 Y0\nG2 X10 Y0 I4 J0 F10\n",
            2,
            11,
            "arc radius to the end differs from the radius to the start: 4.0000 mm and 6.0000 mm",
        ),
        case(
            "arc radius too small",
            "G0 X0 Y0\nG2 X10 Y0 R4 F10\n",
            2,
            11,
            "less than half the chord",
        ),
        case(
            "full circle with R",
            "G0 X1 Y0\nG2 X1 Y0 R3 F10\n",
            2,
            10,
            "full circle cannot be given with R",
        ),
        case(
            "zero radius",
            "G0 X1 Y0\nG2 X2 Y0 I0 J0 F10\n",
            2,
            10,
            "zero radius",
        ),
        case(
            "offset outside the plane",
            "G0 X0 Y0\nG17 G2 X10 K5 F10\n",
            2,
            12,
            "word K is not used in G17 (XY) arcs",
        ),
        Case {
            axes: XYZUV,
            ..case(
                "helical arc under a taper",
                "G0 X0 Y0 Z0\nG51 A2\nG2 X10 Y0 Z3 I5 F10\n",
                3,
                11,
                "helical arc: axis Z moves during a circular arc under a taper",
            )
        },
        case(
            "arc plane not on machine",
            "G18 G2 X1 I1 F10\n",
            1,
            5,
            "G18 arc needs axes Z and X on the machine",
        ),
        case(
            "arc turns not whole",
            "G0 X0 Y0\nG2 X10 Y0 I5 P2.5 F10\n",
            2,
            14,
            "arc P2.5: the number of turns is a whole number, 1 or more",
        ),
        case(
            "absolute centre missing J",
            "G90.1 G0 X10 Y0\nG2 X0 Y10 I0 F10\n",
            2,
            11,
            "J word missing in an absolute-centre arc",
        ),
        // ---- NURBS: G38
        case(
            "degree too high for the point count",
            "G0 X0 Y0\nG38 O5 C4 X0 Y0\n",
            2,
            8,
            "degree 5 needs at least 6 control points, got 4",
        ),
        case(
            "G38 degree out of range",
            "G38 O12 C20 X0 Y0\n",
            1,
            5,
            "degree O out of range",
        ),
        case(
            "G38 without C",
            "G38 O3 X0 Y0\n",
            1,
            1,
            "needs C<number of control points>",
        ),
        case(
            "G38 weight zero",
            "G0 X0 Y0\nG38 O2 C3 X0 Y0\nG38 X1 Y1 W0\nG38 X2 Y0\n",
            3,
            11,
            "weight W0 must be greater than 0",
        ),
        case(
            "G38 negative weight",
            "G0 X0 Y0\nG38 O2 C3 X0 Y0\nG38 X1 Y1 W-2\nG38 X2 Y0\n",
            3,
            11,
            "weight W-2 must be greater than 0",
        ),
        case(
            "G38 point without coordinates",
            "G0 X0 Y0\nG38 O2 C3 X0 Y0\nG38 W2\n",
            3,
            1,
            "missing coordinate",
        ),
        case(
            "G38 interrupted",
            "G0 X0 Y0\nG38 O2 C3 X0 Y0\nG1 X5\n",
            3,
            1,
            "G38 curve started at line 2 is interrupted by G1",
        ),
        case(
            "G38 start away from the tool",
            "G0 X0 Y0\nG38 O2 C3 X1 Y0\n",
            2,
            1,
            "first control point must be the current position",
        ),
        case(
            "file ends inside a G38 curve",
            "G0 X0 Y0\nG38 O2 C3 X0 Y0\nG38 X1 Y1\n",
            2,
            1,
            "never finished",
        ),
        case(
            "G38 knots decreasing",
            "G0 X0 Y0\nG38 O1 C3 X0 Y0 K0\nG38 X1 Y1 K0.6\nG38 X2 Y0 K0.5\n",
            4,
            11,
            "knots decrease: K0.5 is less than the previous knot 0.6",
        ),
        // ---- NURBS: G06.2
        case(
            "G06.2 knots decreasing",
            "G0 X0 Y0\nG06.2 P3 K0 X0 Y0\nK0 X1 Y1\nK0 X2 Y1\nK0.5 X3 Y0\nK0.4\nK1\nK1\n",
            6,
            1,
            "knots decrease",
        ),
        case(
            "G06.2 curve interrupted by G01",
            "G0 X0 Y0\nG06.2 P3 K0 X0 Y0\nK0 X1 Y1\nG01 X5 Y5\n",
            4,
            1,
            "G06.2 curve started at line 2 is interrupted by G01",
        ),
        case(
            "wrong knot count",
            "G0 X0 Y0\nG06.2 P4 K0 X0 Y0\nK0 X1 Y1\nK0 X2 Y1\nK0 X3 Y0\nK1\nK1\nG01 X0 Y0\n",
            8,
            1,
            "wrong knot count: the G06.2 curve started at line 2 has 4 control points of order 4 and needs 8 knots; 6 were given",
        ),
        case(
            "G06.2 weight zero",
            "G0 X0 Y0\nG06.2 P3 K0 X0 Y0 R1\nK0 X1 Y1 R0\n",
            3,
            10,
            "weight R0 must be greater than 0",
        ),
        case(
            "G06.2 block without K",
            "G0 X0 Y0\nG06.2 P3 K0 X0 Y0\nX1 Y1\n",
            3,
            1,
            "block without K",
        ),
        case(
            "G06.2 point after closing knots",
            "G0 X0 Y0\nG06.2 P2 K0 X0 Y0\nK1 X1 Y1\nK1\nK2 X2 Y2\n",
            5,
            1,
            "control point after the closing knot-only blocks",
        ),
        case(
            "G06.2 order out of range",
            "G06.2 P11 K0 X0 Y0\n",
            1,
            7,
            "order out of range",
        ),
        case(
            "G06.2 knots not clamped",
            "G0 X0 Y0\nG06.2 P3 K0 X0 Y0\nK0 X1 Y1\nK0.5 X2 Y1\nK0.5 X3 Y0\nK1\nK1\nK1\n",
            2,
            1,
            "invalid NURBS curve",
        ),
        case(
            "G06.2 interior multiplicity too high",
            "G0 X0 Y0\nG06.2 P2 K0 X0 Y0\nK0 X1 Y1\nK0.5 X2 Y1\nK0.5 X3 Y0\nK0.5 X4 Y0\nK1\nK1\n",
            2,
            1,
            "knot 0.5 is repeated 3 times",
        ),
        // ---- NURBS: G5.2
        case(
            "G5.3 without G5.2",
            "G0 X0 Y0\nG5.3\n",
            2,
            1,
            "G5.3 without G5.2",
        ),
        case(
            "G5.2 never closed",
            "G0 X0 Y0\nG5.2 X1 Y1\nX2 Y0 P1\nX3 Y1 P1\nM30\n",
            5,
            1,
            "G5.2 curve started at line 2 is interrupted by M30",
        ),
        case(
            "G5.2 at end of file",
            "G0 X0 Y0\nG5.2 X1 Y1\nX2 Y0 P1\n",
            2,
            1,
            "close it with G5.3",
        ),
        case(
            "G5.2 negative weight",
            "G0 X0 Y0\nG5.2 X1 Y1\nX2 Y0 P-1\n",
            3,
            7,
            "weight P-1 must be greater than 0",
        ),
        case(
            "G5.2 too few points for the order",
            "G0 X0 Y0\nG5.2 X1 Y1 L4\nX2 Y0 P1\nG5.3\n",
            2,
            1,
            "degree 3 needs at least 4 control points, got 3",
        ),
        case(
            "G5.2 order not whole",
            "G5.2 X1 Y1 L3.5\n",
            1,
            12,
            "L needs a whole number",
        ),
        case(
            "G5.3 with words",
            "G0 X0 Y0\nG5.2 X1 Y1\nX2 Y0 P1\nG5.3 X5\n",
            4,
            6,
            "only closes the curve",
        ),
        case(
            "G5.2 interrupted by G1",
            "G0 X0 Y0\nG5.2 X1 Y1\nG1 X2 Y0\n",
            3,
            1,
            "(close it with G5.3)",
        ),
        case(
            "G5.2 point without Y",
            "G0 X0 Y0\nG5.2 X1 Y1\nX2 P1\nX3 Y1 P1\nG5.3\n",
            3,
            1,
            "needs both X and Y",
        ),
        case(
            "G5.2 point without its weight",
            "G0 X0 Y0\nG5.2 X1 Y1\nX2 Y0\nX3 Y1 P1\nG5.3\n",
            3,
            1,
            "needs its weight P",
        ),
        // ---- O-word structure, checked as text (LinuxCNC's rules for its O-codes)
        case(
            "second else",
            "o1 if [1]\nG1 X1 F60\no1 else\nG1 X2\no1 else\nG1 X3\no1 endif\nM2\n",
            5,
            1,
            "O1 else: after the else at line 3",
        ),
        case(
            "elseif after else",
            "o1 if [0]\nG1 X1 F60\no1 else\nG1 X2 F60\no1 elseif [1]\no1 endif\nM2\n",
            5,
            1,
            "O1 elseif: after the else at line 3",
        ),
        case(
            "crossed constructs",
            "o1 if [1]\no2 while [#1 LT 2]\n#1=[#1+1]\no1 endif\no2 endwhile\nM2\n",
            4,
            1,
            "O2 while at line 2 must be closed first (endwhile)",
        ),
        case(
            "unterminated while before M2",
            "o1 while [#1 LT 3]\n#1=[#1+1]\nG1 X#1 F60\nM2\n",
            1,
            1,
            "O1 while at line 1 is never closed: O1 endwhile expected",
        ),
        case(
            "if without endif before M2",
            "o1 if [1]\nG1 X1 F60\nM2\n",
            1,
            1,
            "O1 if at line 1 is never closed: O1 endif expected",
        ),
        case(
            "a construct left open after M2",
            "G1 X1 F60\nM2\no<s> sub\no1 if [1]\no<s> endsub\n",
            5,
            1,
            "o<s> endsub: O1 if at line 4 must be closed first (endif)",
        ),
        case(
            "duplicate sub",
            "o1 sub\nG1 X1 F60\no1 endsub\no1 sub\nG1 X2 F60\no1 endsub\no1 call\nM2\n",
            4,
            1,
            "O1 sub: defined again (first at line 1)",
        ),
        case(
            "read-only position parameter",
            "G1 X1 F60\n#5420=3\nM2\n",
            2,
            1,
            "parameter #5420 is read-only",
        ),
        case(
            "read-only named parameter",
            "G1 X1 F60\nG1 Y1 #<_x> = 3\nM2\n",
            2,
            7,
            "parameter #<_x> is read-only",
        ),
        case(
            "exponent inside an expression",
            "#1=[1e300]\nM2\n",
            1,
            6,
            "exponent notation such as 1e3 is not G-code",
        ),
        case(
            "negative M98 count",
            "M98 P100 L-5\nM2\nO100\nG1 X1 F60\nM99\n",
            1,
            10,
            "M98's repeat count L out of range: -5 (allowed 0 to 1e9)",
        ),
        case(
            "weights too far apart",
            "G06.2 P4 K0 X0 Y0 R1\nK0 X1 Y1 R[10**200]\nK0 X2 Y0 R1\nK0 X3 Y1 R1\nK1\nK1\nK1\nK1\nM2\n",
            2,
            10,
            "weight 1e200: the curve's weights would range from 1 to 1e200",
        ),
        case(
            "nested too deep",
            format!("#1 = {}1{}\nM2\n", "[".repeat(257), "]".repeat(257)).leak(),
            1,
            262,
            "expression nested deeper than 256 levels",
        ),
        // ---- whole file
        case("empty file", "", 1, 1, "empty program"),
        case(
            "only comments",
            "(nothing)\n; here\n\n",
            1,
            1,
            "empty program",
        ),
    ]
}

#[test]
fn every_malformed_program_fails_at_the_right_place() {
    let cases = cases();
    assert!(cases.len() >= 30, "{} cases", cases.len());
    let mut failures = Vec::new();
    for c in &cases {
        let Some(err) = first_error(c.program.as_bytes(), c.axes) else {
            failures.push(format!("{}: no error for {:?}", c.name, c.program));
            continue;
        };
        let msg = err.to_string();
        if (err.line, err.col) != (c.line, c.col) {
            failures.push(format!(
                "{}: at {}:{}, expected {}:{}\n{msg}",
                c.name, err.line, err.col, c.line, c.col
            ));
        }
        if !msg.starts_with(&format!("t.nc:{}:{}: ", err.line, err.col)) {
            failures.push(format!("{}: no file:line:col prefix in {msg}", c.name));
        }
        if !msg.contains(c.gist) {
            failures.push(format!("{}: {msg:?} lacks {:?}", c.name, c.gist));
        }
        // The offending text is shown under the message, with a caret.
        let has_excerpt = msg.contains(" | ") && msg.ends_with('^');
        if !err.text.is_empty() && !has_excerpt {
            failures.push(format!("{}: no excerpt with a caret in {msg}", c.name));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

#[test]
fn invalid_utf8_is_reported_at_its_column() {
    // Latin-1 in a comment is read (an older editor's `Ø`); anywhere else it is an error.
    assert!(first_error(b"G21\nG1 X1 (caf\xe9, \xd8 5 mm) F1\n; \xe9\n", XY).is_none());
    let err = first_error(b"G21\nG1 X1 F1 caf\xe9\n", XY).unwrap();
    assert_eq!((err.line, err.col), (2, 13));
    assert!(err.to_string().contains("invalid UTF-8"), "{err}");
}

#[test]
fn a_ten_megabyte_line_is_an_error_not_a_memory_spike() {
    let mut program = b"G21\n(".to_vec();
    program.extend(std::iter::repeat_n(b'x', 10 * 1024 * 1024));
    program.extend_from_slice(b")\nM30\n");
    let err = first_error(&program, XY).unwrap();
    assert_eq!(err.line, 2);
    assert!(
        err.to_string().contains("line is longer than 65536 bytes"),
        "{err}"
    );
}

#[test]
fn nothing_is_emitted_after_an_error() {
    let program = "G0 X1\nG1 X2 F10\nG7\nG1 X3\n";
    let items: Vec<_> =
        common::program_path(BlockReader::new(Cursor::new(program), "t.nc", XY)).collect();
    assert_eq!(items.len(), 3);
    assert!(items[0].is_ok() && items[1].is_ok() && items[2].is_err());
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 2000,
        rng_seed: proptest::test_runner::RngSeed::Fixed(0xED3D),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        for item in common::program_path(BlockReader::new(Cursor::new(&bytes), "fuzz.nc", XYZ)) {
            if let Err(e) = item {
                let _ = e.to_string();
            }
        }
    }

    #[test]
    fn random_gcode_like_text_never_panics(
        tokens in proptest::collection::vec(
            prop_oneof![
                Just("G0".to_string()), Just("G1".to_string()), Just("G2".to_string()),
                Just("G3".to_string()), Just("G38".to_string()), Just("G06.2".to_string()),
                Just("G5.2".to_string()), Just("G5.3".to_string()), Just("G91".to_string()),
                Just("G20".to_string()), Just("G18".to_string()), Just("M30".to_string()),
                Just("\n".to_string()), Just("(".to_string()), Just(")".to_string()),
                "[XYZIJKRPLOCWF] ?-?[0-9]{0,3}(\\.[0-9]{0,3})?",
            ],
            0..60,
        )
    ) {
        let program = tokens.join(" ");
        for item in common::program_path(BlockReader::new(Cursor::new(program.as_bytes()), "fuzz.nc", XYZ)) {
            match item {
                Ok(block) => {
                    // Whatever parses is a finite, evaluable curve.
                    let c = &block.curve;
                    let p = c.point(0.5 * (c.u_min() + c.u_max()));
                    prop_assert!(p.iter().all(|v| v.is_finite()));
                }
                Err(e) => { let _ = e.to_string(); }
            }
        }
    }
}

#[test]
fn exponent_notation_is_named_not_taken_for_a_word_e() {
    let err = first_error(b"G21\nG1 X1e308 F1\n", XY).unwrap();
    assert_eq!((err.line, err.col), (2, 6));
    assert!(err.to_string().contains("exponent notation"), "{err}");
}
