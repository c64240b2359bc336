//! Work offsets against LinuxCNC's interpreter: every program in `tests/data/offsets/` is read
//! by edmd and by `rs274 -g` (Debian's `linuxcnc-uspace`), and every move must end at the same
//! machine point (within rs274's printed precision); the refusals must be refusals in both.
//!
//! `rs274` prints its canonical calls in program coordinates and the offsets it hands to
//! motion (`SET_G5X_OFFSET`, `SET_G92_OFFSET`) in the units in force when it prints them, so
//! a machine point is the printed point plus both offsets, converted to mm as it is printed.
//! (edmd is stricter in one place: `G10 L2 P1.5` is refused for its fractional `P`, where
//! LinuxCNC 2.9 truncates it to `P1`.) Without `rs274` on the machine the comparison is skipped, unless `EDMD_LCNC_TESTS=1` (CI)
//! says it must run.

use crate::common;

use std::path::{Path, PathBuf};

use common::linuxcnc::{TOLERANCE_MM, end_points, linuxcnc_moves, rs274};

use edmd::gcode::{BlockReader, open_program};
use edmd::vocab::Axis;

const XYZ: &[Axis] = &[Axis::X, Axis::Y, Axis::Z];

fn edmd_moves(program: &Path) -> Result<Vec<[f64; 3]>, String> {
    let reader: BlockReader<_> = open_program(program, XYZ).map_err(|e| e.to_string())?;
    end_points(reader)
}

fn programs() -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/offsets");
    let mut all: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("tests/data/offsets")
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "ngc"))
        .collect();
    all.sort();
    all
}

#[test]
fn every_move_ends_where_linuxcnc_puts_it_in_machine_coordinates() {
    let Some(rs274) = rs274() else { return };
    let all = programs();
    assert!(
        all.len() >= 7,
        "the offset programs are in tests/data/offsets"
    );
    let mut compared = 0;
    for program in &all {
        let theirs = linuxcnc_moves(&rs274, program)
            .unwrap_or_else(|e| panic!("rs274 refuses {}: {e}", program.display()));
        let ours = edmd_moves(program).unwrap_or_else(|e| panic!("edmd refuses: {e}"));
        assert_eq!(
            ours.len(),
            theirs.len(),
            "{}: edmd makes {} moves, LinuxCNC {}\nedmd: {ours:?}\nrs274: {theirs:?}",
            program.display(),
            ours.len(),
            theirs.len()
        );
        for (k, (a, b)) in ours.iter().zip(&theirs).enumerate() {
            let off = a
                .iter()
                .zip(b)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f64::max);
            assert!(
                off <= TOLERANCE_MM,
                "{}: move {} ends at {a:?} in edmd, {b:?} in LinuxCNC",
                program.display(),
                k + 1
            );
            compared += 1;
        }
    }
    assert!(compared >= 50, "only {compared} moves compared");
    eprintln!(
        "{compared} moves of {} programs end where LinuxCNC's rs274 puts them",
        all.len()
    );
}

#[test]
fn what_linuxcnc_refuses_edmd_refuses_at_the_same_line() {
    let Some(rs274) = rs274() else { return };
    let dir = std::env::temp_dir().join(format!("edmd-lcnc-offsets-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let refused = [
        "G2 G53 X1 Y1 R3 F100",
        "G91 G53 G0 X1",
        "G53 G91 G1 X1 F10",
        "G10 L2 P10 X1",
        "G10 L2 X1",
        "G10 L20 P1 R0 X1",
        "G10 L3 P1 X1",
    ];
    for (k, line) in refused.iter().enumerate() {
        let path = dir.join(format!("refused-{k}.ngc"));
        std::fs::write(&path, format!("G21 G90\n{line}\nM2\n")).unwrap();
        let theirs = linuxcnc_moves(&rs274, &path);
        assert!(theirs.is_err(), "LinuxCNC accepts `{line}`: {theirs:?}");
        let ours = edmd_moves(&path);
        let message = ours.expect_err(&format!("edmd accepts `{line}`"));
        assert!(
            message.contains(":2:"),
            "`{line}` should be refused at line 2: {message}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

// What the comparison cannot see: the start state a controller hands the reader, the table
// as parameters in mm (rs274 alone reports them in inches), and what a program leaves.

use std::io::Cursor;

use edmd::gcode::{ProgramOptions, WorkOffsets, WorkStart, WorkSystem};
use edmd::geometry::Point;

fn point(x: f64, y: f64, z: f64) -> Point {
    let mut p = Point::zeros();
    p[0] = x;
    p[1] = y;
    p[2] = z;
    p
}

fn reader(program: &str) -> BlockReader<Cursor<Vec<u8>>> {
    let options = ProgramOptions {
        d_mm: vec![0.0, 0.5],
        ..ProgramOptions::default()
    };
    BlockReader::with_options(
        Cursor::new(program.as_bytes().to_vec()),
        "t.ngc",
        XYZ,
        options,
    )
}

fn ends<R: std::io::BufRead + std::io::Seek>(r: &mut BlockReader<R>) -> Vec<[f64; 3]> {
    r.by_ref()
        .map(|b| {
            let e = b.unwrap_or_else(|e| panic!("{e}")).end();
            [e[0], e[1], e[2]].map(|v| (v * 1e6).round() / 1e6)
        })
        .collect()
}

#[test]
fn a_program_starts_where_the_machine_stands_in_the_active_system() {
    let mut offsets = WorkOffsets::default();
    offsets.set(WorkSystem::G54, point(100.0, 50.0, -10.0));
    offsets.set(WorkSystem::from_number(2).unwrap(), point(-5.0, 0.0, 0.0));
    let start = WorkStart {
        position_mm: point(103.0, 52.0, -10.0),
        offsets,
        system: WorkSystem::G54,
        modes: Default::default(),
        unhomed: false,
    };
    let mut r = reader(
        "G91 G1 X1 F10\n\
         G90 G1 X10 Y0 Z0\n\
         G1 X#5221 Y#5222 Z#5223\n\
         G55 G0 X1\n\
         G53 G0 X0 Y0 Z0\n\
         G1 X#<_x> Y[#5420 + 1]\n\
         M2\n",
    );
    r.start_at(&start);
    assert_eq!(
        ends(&mut r),
        [
            [104.0, 52.0, -10.0],  // incremental from where the machine stands
            [110.0, 50.0, -10.0],  // program X10 Y0 Z0 = machine + G54
            [200.0, 100.0, -20.0], // the table reads in mm
            [-4.0, 100.0, -20.0],  // G55 X1
            [0.0, 0.0, 0.0],       // G53: machine zero
            // #<_x> and #5420 read X in G55's coordinates: 5 (machine 0), so Y 6.
            [0.0, 6.0, 0.0],
        ]
    );
}

#[test]
fn g10_changes_the_table_and_a_program_end_returns_to_g54() {
    let mut r = reader(
        "G10 L2 P2 X1 Y2 Z3\n\
         G0 X4 Y4\n\
         G10 L20 P3 X0 Y0\n\
         G20 G10 L2 P9 X1\n\
         G21 G59.3\n\
         G0 X0\n\
         M30\n",
    );
    ends(&mut r);
    let table = r.work_offsets();
    assert_eq!(
        *table.get(WorkSystem::from_number(2).unwrap()),
        point(1.0, 2.0, 3.0)
    );
    assert_eq!(
        *table.get(WorkSystem::from_number(3).unwrap()),
        point(4.0, 4.0, 0.0)
    );
    assert_eq!(
        *table.get(WorkSystem::from_number(9).unwrap()),
        point(25.4, 0.0, 0.0)
    );
    assert_eq!(
        r.work_system(),
        WorkSystem::G54,
        "M30 ends in G54, as LinuxCNC's does"
    );

    let mut r = reader("G56\nG0 X1\n");
    ends(&mut r);
    assert_eq!(
        r.work_system().name(),
        "G56",
        "no program end: the system stays"
    );
}

#[test]
fn the_work_system_cannot_change_under_the_wire_offset() {
    for (program, col) in [
        ("G0 X-5 Y0\nG41 D1 G1 X0 Y0 F10\nG55\nG40 G1 X-5\n", 1),
        (
            "G0 X-5 Y0\nG41 D1 G1 X0 Y0 F10\nG10 L2 P0 X1\nG40 G1 X-5\n",
            1,
        ),
        ("G0 X-5 Y0\nG41 D1 G1 X0 Y0 F10\nG53 G1 X3\nG40 G1 X-5\n", 1),
    ] {
        let e = reader(program)
            .by_ref()
            .find_map(|b| b.err())
            .unwrap_or_else(|| panic!("accepted:\n{program}"));
        let text = e.to_string();
        assert!(
            text.starts_with(&format!("t.ngc:3:{col}: work offset:")) && text.contains("G40 first"),
            "{text}"
        );
    }
    // G10 on a system that is not active is allowed under the offset, as in LinuxCNC.
    let mut r = reader(
        "G0 X-5 Y0\nG41 D1 G1 X0 Y0 F10\nG10 L2 P2 X1\nG1 X10\nG1 Y10\nG40 G1 X20 Y20\nM2\n",
    );
    assert!(ends(&mut r).len() >= 5);
}
