//! G-code as LinuxCNC reads it, item by item: every program here is read by edmd and by
//! `rs274 -g` (Debian's `linuxcnc-uspace`, made a mm machine: see `common::linuxcnc`), and
//! every move must end at the same machine point within 1 µm, or both must refuse the
//! program. The start state (`#5220`), the `G92` family under the wire offset, absolute arc
//! centres, arc turns (`P`), spirals, helices in the three planes, `M70`–`M73`, polar
//! coordinates, `G5.1`, `G28`/`G30` and the canned cycles. Without `rs274` the comparison is
//! skipped, unless `EDMD_LCNC_TESTS=1` (CI).

use crate::common;

use std::io::Cursor;
use std::path::Path;

use common::linuxcnc::{edmd_ends, linuxcnc_moves, rs274, worst_apart};
use edmd::gcode::{BlockReader, ProgramOptions};
use edmd::vocab::Axis;

const XYZ: &[Axis] = &[Axis::X, Axis::Y, Axis::Z];
/// rs274 prints 0.1 µm; edmd's spirals and helices are fitted within 0.01 µm…
const AGREE_MM: f64 = 1e-3;
/// …and in an inch program four decimals of an inch, ±1.27 µm.
const AGREE_INCH_MM: f64 = 0.000_05 * 25.4 + 1e-6;

/// edmd's reading of `text` (`D1` = 1 mm), end points or the error.
fn edmd(text: &str) -> Result<Vec<[f64; 3]>, String> {
    edmd_ends(text, 1.0)
}

/// rs274's reading of `text` (`G41 D1` written `G41.1 D2`, its offset by diameter).
fn linuxcnc(rs274: &Path, name: &str, text: &str) -> Result<Vec<[f64; 3]>, String> {
    let theirs = text
        .replace("G41 D1", "G41.1 D2")
        .replace("G42 D1", "G42.1 D2");
    let dir = std::env::temp_dir().join(format!("edmd-gcode-lcnc-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, theirs).unwrap();
    linuxcnc_moves(rs274, &path)
}

/// Both read `text` and agree move for move (a spline's end, which rs274 does not print,
/// is checked by the move after it).
fn agree(rs274: &Path, name: &str, text: &str) -> usize {
    let theirs =
        linuxcnc(rs274, name, text).unwrap_or_else(|e| panic!("rs274 refuses {name}: {e}\n{text}"));
    let ours = edmd(text).unwrap_or_else(|e| panic!("edmd refuses {name}: {e}\n{text}"));
    let worst = worst_apart(&ours, &theirs);
    let bound = if text.contains("G20") {
        AGREE_INCH_MM
    } else {
        AGREE_MM
    };
    assert!(
        ours.len() == theirs.len() && worst <= bound,
        "{name}: edmd makes {} moves, LinuxCNC {} (worst difference {worst:.6} mm)\n\
         edmd:  {ours:?}\nrs274: {theirs:?}\nprogram:\n{text}",
        ours.len(),
        theirs.len()
    );
    ours.len()
}

/// Both refuse `text`; edmd's message says `gist`.
fn both_refuse(rs274: &Path, name: &str, text: &str, gist: &str) {
    let theirs = linuxcnc(rs274, name, text);
    assert!(
        theirs.is_err(),
        "{name}: rs274 accepts it: {theirs:?}\n{text}"
    );
    let ours = edmd(text);
    match ours {
        Err(e) => assert!(e.contains(gist), "{name}: edmd says {e:?}, not {gist:?}"),
        Ok(m) => panic!(
            "{name}: edmd accepts what rs274 refuses ({}): {m:?}\n{text}",
            theirs.unwrap_err()
        ),
    }
}

#[test]
fn the_start_state_reads_g54_as_active() {
    let Some(rs274) = rs274() else { return };
    agree(
        &rs274,
        "p5220.ngc",
        "G21\nG0 X[#5220] Y1\nG10 L2 P1 X10\nG0 X[#5221] Y[#5220]\nM2\n",
    );
}

#[test]
fn the_g92_family_is_refused_under_the_wire_offset() {
    let Some(rs274) = rs274() else { return };
    let program = |code: &str| {
        format!(
            "G21 G0 X-5 Y0\nG92 X-4\nG41 D1\nG1 X0 Y0 F100\nX10\n{code}\nX20\nG40\nG0 X30 Y-5\nM2\n"
        )
    };
    let gist = "the G92 offset cannot change with the wire offset on";
    both_refuse(&rs274, "g92comp.ngc", &program("G92 X0 Y0"), gist);
    // LinuxCNC takes these but never hands motion the new offset (a deliberate difference).
    for code in ["G92.1", "G92.2", "G92.3"] {
        let err = edmd(&program(code)).expect_err(code);
        assert!(err.contains(gist), "{err}");
        let theirs = linuxcnc(&rs274, "g92x.ngc", &program(code)).expect("rs274 takes it");
        assert!(
            (theirs[3][0] - 19.0).abs() < 1e-3,
            "{code}: rs274 cut on with the old offset, X20 at machine 19: {theirs:?}"
        );
    }
}

#[test]
fn an_absolute_centre_arc_needs_both_centre_words() {
    let Some(rs274) = rs274() else { return };
    both_refuse(
        &rs274,
        "g901.ngc",
        "G21 G90.1 G0 X10 Y0\nG2 X0 Y10 I0 F100\nM2\n",
        "J word missing in an absolute-centre arc",
    );
    both_refuse(
        &rs274,
        "g901k.ngc",
        "G21 G90.1 G18 G0 X10 Z0\nG2 X0 Z10 K0 F100\nM2\n",
        "I word missing in an absolute-centre arc",
    );
    agree(
        &rs274,
        "g901ok.ngc",
        "G21 G90.1 G0 X10 Y0\nG3 X0 Y10 I0 J0 F100\nM2\n",
    );
}

#[test]
fn arcs_turn_p_times() {
    let Some(rs274) = rs274() else { return };
    for (name, arc) in [
        ("p2full.ngc", "G3 X10 Y0 I-10 J0 P2"),
        ("p3part.ngc", "G2 X0 Y-10 I-10 J0 P3"),
        ("p2r.ngc", "G3 X0 Y10 R10 P2"),
        ("p2helix.ngc", "G3 X10 Y0 Z-3 I-10 J0 P2"),
    ] {
        agree(
            &rs274,
            name,
            &format!("G21 G0 X10 Y0 Z0\n{arc} F100\nG1 X12\nM2\n"),
        );
    }
    // Ends where one turn would: the move after checks the curve's end, the length its turns.
    let blocks = edmd::gcode::BlockReader::new(
        Cursor::new("G21 G0 X10 Y0\nG3 X10 Y0 I-10 J0 P2 F100\nM2\n".as_bytes()),
        "p.ngc",
        XYZ,
    );
    let arc: Vec<_> = blocks.filter_map(Result::ok).collect();
    let length = arc[1].curve.length();
    assert!(
        (length - 2.0 * std::f64::consts::TAU * 10.0).abs() < 1e-4,
        "{length}"
    );
}

#[test]
fn centre_arcs_whose_radii_differ_are_spirals_within_linuxcncs_tolerance() {
    let Some(rs274) = rs274() else { return };
    agree(
        &rs274,
        "spiral3um.ngc",
        "G21 G0 X10 Y0\nG3 X0 Y10.003 I-10 J0 F100\nM2\n",
    );
    agree(
        &rs274,
        "spiral25um.ngc",
        "G21 G0 X10 Y0\nG3 X0 Y10.025 I-10 J0 F100\nM2\n",
    );
    // 0.1 % of a 100 mm radius is more than 28 µm: 90 µm passes there.
    agree(
        &rs274,
        "spiral90um.ngc",
        "G21 G0 X100 Y0\nG3 X0 Y100.09 I-100 J0 F100\nM2\n",
    );
    agree(
        &rs274,
        "spiralinch.ngc",
        "G20 G0 X1 Y0\nG3 X0 Y1.0005 I-1 J0 F10\nG1 X-1\nM2\n",
    );
    both_refuse(
        &rs274,
        "spiral40um.ngc",
        "G21 G0 X10 Y0\nG3 X0 Y10.04 I-10 J0 F100\nM2\n",
        "arc radius to the end differs from the radius to the start",
    );
    both_refuse(
        &rs274,
        "spiral3mm.ngc",
        "G21 G0 X5000 Y0\nG3 X0 Y5003 I-5000 J0 F100\nM2\n",
        "arc radius to the end differs from the radius to the start",
    );
    // The curve really is the spiral: its middle is halfway between the radii.
    let blocks: Vec<_> = BlockReader::new(
        Cursor::new("G21 G0 X10 Y0\nG3 X-10.02 Y0 I-10 J0 F100\nM2\n".as_bytes()),
        "p.ngc",
        XYZ,
    )
    .filter_map(Result::ok)
    .collect();
    let mid = blocks[1].curve.point(0.5);
    assert!((mid[0].hypot(mid[1]) - 10.01).abs() < 1e-4, "{mid:?}");
}

#[test]
fn helical_arcs_in_the_three_planes() {
    let Some(rs274) = rs274() else { return };
    agree(
        &rs274,
        "helixes.ngc",
        "G21 G0 X10 Y0 Z0\nG17 G2 X-10 Y0 Z-2 I-10 J0 F100\nG3 X10 Y0 Z-4 R10\n\
         G18 G2 X0 Z6 Y5 I-10 K0\nG19 G3 Y15 Z16 X-5 J10 K0\nG17 G3 X-5 Y15 Z0 I0 J10 P3\nM2\n",
    );
}

#[test]
fn m70_to_m73_save_and_restore_the_modes() {
    let Some(rs274) = rs274() else { return };
    agree(
        &rs274,
        "m70.ngc",
        "G21 G90 G0 X1 Y1\nG1 X2 F100\nM70\nG20 G91 G1 X1 F10\nM72\nG1 X5 Y5\nM71\nM2\n",
    );
    agree(
        &rs274,
        "m73.ngc",
        "o100 sub\nM73\nG20 G91\nG1 X0.1 F10\no100 endsub\nG21 G90 G1 X1 Y1 F100\no100 call\nG1 X5 Y5\nM2\n",
    );
    agree(
        &rs274,
        "m70g55.ngc",
        "G21 G10 L2 P2 X100\nG0 X1 Y1\nM70\nG55\nG0 X1 Y1\nM72\nG0 X2 Y2\nM2\n",
    );
    both_refuse(&rs274, "m72.ngc", "G21 G0 X1\nM72\nM2\n", "M72");
}

#[test]
fn polar_coordinates() {
    let Some(rs274) = rs274() else { return };
    agree(
        &rs274,
        "polar.ngc",
        "G21 G10 L2 P1 X5 Y-3\nG0 @10 ^30\nG1 ^75 F100\nG1 @4\nG91 G1 ^15\nG1 @2\n\
         G90 G2 @6 ^0 R20\nG20 G0 @1 ^45\nM2\n",
    );
    both_refuse(
        &rs274,
        "polarxy.ngc",
        "G21 G0 @10 ^30 X1\nM2\n",
        "X or Y cannot be given",
    );
}

#[test]
fn g5_1_quadratic_splines() {
    let Some(rs274) = rs274() else { return };
    agree(
        &rs274,
        "g51.ngc",
        "G21 G0 X0 Y0\nG5.1 X10 Y0 I5 J5 F100\nG5.1 X20 Y5 I3 J-4\nG1 X25\nM2\n",
    );
    both_refuse(
        &rs274,
        "g51j.ngc",
        "G21 G0 X0 Y0\nG5.1 X10 Y0 I5 F100\nM2\n",
        "needs both I and J",
    );
    // Its middle is the control points' (1,0), (6,5), (10,0) weighted 1/4, 1/2, 1/4.
    let blocks: Vec<_> = BlockReader::new(
        Cursor::new("G21 G0 X1 Y0\nG5.1 X10 Y0 I5 J5 F100\nM2\n".as_bytes()),
        "p.ngc",
        XYZ,
    )
    .collect::<Result<_, _>>()
    .expect("reads");
    let mid = blocks[1].curve.point(0.5);
    assert!(
        (mid[0] - 5.75).abs() < 1e-12 && (mid[1] - 2.5).abs() < 1e-12,
        "{mid:?}"
    );
}

#[test]
fn g28_and_g30_go_to_their_stored_positions() {
    let Some(rs274) = rs274() else { return };
    agree(
        &rs274,
        "g28.ngc",
        "G21 G0 X10 Y20 Z5\nG28.1\nG0 X50 Y50 Z10\nG28\nG0 X1 Y2 Z3\nG28 Z8\n\
         #5181 = 7\n#5182 = -3\nG30 X4 Y4\nG10 L2 P1 X100\nG30\nM2\n",
    );
    both_refuse(
        &rs274,
        "g28comp.ngc",
        "G21 G0 X-5 Y0\nG41 D1\nG1 X0 Y0 F100\nG28\nM2\n",
        "G28 cannot be used with the wire offset on",
    );
}

#[test]
fn g28_is_refused_on_an_unhomed_machine() {
    let mut reader = BlockReader::new(Cursor::new("G28\nM2\n".as_bytes()), "p.ngc", XYZ);
    reader.start_at(&edmd::gcode::WorkStart {
        unhomed: true,
        ..Default::default()
    });
    let err = reader.find_map(Result::err).expect("refused");
    assert!(
        err.to_string().contains("the machine is not homed"),
        "{err}"
    );
}

#[test]
fn canned_cycles_move_as_linuxcncs() {
    let Some(rs274) = rs274() else { return };
    agree(
        &rs274,
        "g81.ngc",
        "G21 G0 X0 Y0 Z10\nG81 X5 Y5 Z-2 R2 F100\nX10\nY10 Z-3\nG98 X15 R4\nG80\nG0 Z20\nM2\n",
    );
    agree(
        &rs274,
        "g82.ngc",
        "G21 G0 X0 Y0 Z10\nG99 G82 X5 Y5 Z-2 R2 P0.5 F100\nX10 P1\nG80\nM2\n",
    );
    agree(
        &rs274,
        "g83.ngc",
        "G21 G0 X0 Y0 Z10\nG83 X20 Y0 Z-3.5 R1 Q1 F100\nG98 X25 Q1.5\nG80\nM2\n",
    );
    agree(
        &rs274,
        "g73.ngc",
        "G21 G0 X0 Y0 Z10\nG73 X20 Y0 Z-3.5 R1 Q1 F100\nX30 Z-1.2\nG80\nM2\n",
    );
    agree(
        &rs274,
        "g91l.ngc",
        "G21 G0 X0 Y0 Z10\nG91 G81 X5 Y2 Z-4 R-7 L4 F100\nG90 G80\nG0 X0 Y0\nM2\n",
    );
    agree(
        &rs274,
        "g81below.ngc",
        "G21 G0 X0 Y0 Z0\nG98 G81 X5 Y5 Z-2 R2 F100\nX10\nG80\nM2\n",
    );
    agree(
        &rs274,
        "g81offset.ngc",
        "G21 G10 L2 P1 Z-50 X10\nG0 X0 Y0 Z10\nG81 X5 Y5 Z-2 R2 F100\nG80\nM2\n",
    );
    agree(
        &rs274,
        "g81inch.ngc",
        "G20 G0 X0 Y0 Z1\nG81 X0.5 Y0.5 Z-0.1 R0.1 F10\nX1\nG80\nM2\n",
    );
    both_refuse(
        &rs274,
        "g81comp.ngc",
        "G21 G0 X-5 Y0\nG41 D1\nG1 X0 Y0 F100\nG81 X5 Y5 Z-2 R2\nM2\n",
        "G81 cannot run with the wire offset on",
    );
    both_refuse(
        &rs274,
        "g83q.ngc",
        "G21 G0 X0 Y0 Z10\nG83 X5 Y5 Z-2 R2 F100\nM2\n",
        "G83 needs Q",
    );
}

#[test]
fn a_dwell_cycle_dwells_at_the_bottom_of_each_hole() {
    let blocks: Vec<_> = BlockReader::new(
        Cursor::new("G21 G0 X0 Y0 Z10\nG82 X5 Y5 Z-2 R2 P0.5 F100\nX10\nG80\nM2\n".as_bytes()),
        "p.ngc",
        XYZ,
    )
    .collect::<Result<_, _>>()
    .expect("reads");
    // Over the hole, down to R, plunge, out (after the dwell): twice.
    let dwells: Vec<f64> = blocks.iter().map(|b| b.dwell_s).collect();
    assert_eq!(
        dwells,
        vec![0.0, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.5],
        "{dwells:?}"
    );
    let plunges = blocks.iter().filter(|b| b.sinks(2)).count();
    assert_eq!(plunges, 2);
}

#[test]
fn d_sets_a_pecks_clearance() {
    let ends = edmd("G21 G0 X0 Y0 Z10\nG73 X20 Y0 Z-2.5 R1 Q1 D0.5 F100\nG80\nM2\n").unwrap();
    let z: Vec<f64> = ends.iter().map(|p| p[2]).collect();
    // Down to R, pecks to 0, -1 and -2 backing off 0.5 after each, the bottom, out to R.
    assert_eq!(
        z,
        vec![10.0, 10.0, 1.0, 0.0, 0.5, -1.0, -0.5, -2.0, -1.5, -2.5, 1.0],
        "{z:?}"
    );
}

#[test]
fn wire_offset_corners_within_the_band_of_a_reversal_go_round_the_tip() {
    let Some(rs274) = rs274() else { return };
    let mut accepted = 0;
    for (name, back) in [
        ("tipup.ngc", "X10 Y0.001"),
        ("tipexact.ngc", "X10 Y0"),
        ("tipdown.ngc", "X10 Y-0.001"),
        ("tip2deg.ngc", "X10 Y0.3"),
        ("tip4deg.ngc", "X10 Y0.6"),
        ("tip4degdown.ngc", "X10 Y-0.6"),
    ] {
        let text = format!(
            "G21 G0 X0 Y-5\nG41 D1\nG1 X10 Y0 F100\nX20\n{back}\nX5 Y3\nG40\nG0 X0 Y-5\nM2\n"
        );
        accepted += usize::from(same_verdict(&rs274, name, &text));
    }
    // A line into an arc turning back within the band, the offset inside and outside it.
    for (name, arc) in [
        ("tiparc_in.ngc", "G3 X10 Y0.7 I0 J5"),
        ("tiparc_out.ngc", "G2 X10 Y-0.7 I0 J-5"),
        ("tiparc_177.ngc", "G2 X10.1 Y0.74 I0.05 J5.3"),
        ("tiparc_177in.ngc", "G3 X10.1 Y0.74 I0.05 J5.3"),
    ] {
        let text = format!(
            "G21 G0 X0 Y-5\nG41 D1\nG1 X10 Y0 F100\nX20\n{arc}\nG1 X5 Y8\nG40\nG0 X0 Y10\nM2\n"
        );
        accepted += usize::from(same_verdict(&rs274, name, &text));
    }
    assert!(accepted >= 5, "{accepted} of 10 accepted by both");
}

/// Both accept `text` and agree, or both refuse it; `true` if accepted.
fn same_verdict(rs274: &Path, name: &str, text: &str) -> bool {
    match linuxcnc(rs274, name, text) {
        Ok(_) => {
            agree(rs274, name, text);
            true
        }
        Err(e) => {
            let ours = edmd(text);
            assert!(
                ours.is_err(),
                "{name}: rs274 refuses ({e}), edmd accepts: {ours:?}\n{text}"
            );
            false
        }
    }
}

#[test]
fn offset_arcs_whose_radii_differ_run_from_the_last_point_to_the_end_radius() {
    let Some(rs274) = rs274() else { return };
    // Arcs whose end radius is 3 to 20 µm off the start's, met tangentially, at convex and
    // concave corners, from lines and from arcs, the offset inside and outside.
    let contours = [
        "G1 X10 Y0\nG3 X20 Y10.012 I0 J10\nG3 X10 Y20 I-10.005 J0\nG1 X0\nG1 Y0",
        "G1 X10 Y0\nG2 X20 Y-10.008 I0 J-10\nG1 X25\nG3 X30 Y-4.997 I0 J5\nG1 Y5\nG1 X0\nG1 Y0",
        "G1 X10 Y0\nG3 X16 Y6.02 I0 J6\nG2 X22 Y12 I6.003 J0\nG3 X16 Y18 I-6 J0.004\nG1 X0\nG1 Y0",
        "G1 X10 Y0\nG3 X18 Y0.015 I4 J0\nG1 X25 Y0\nG1 Y12\nG1 X0\nG1 Y0",
    ];
    let mut moves = 0;
    for (k, contour) in contours.iter().enumerate() {
        for side in ["G41", "G42"] {
            let text = format!(
                "G21 G0 X-5 Y-5\n{side} D1\nG1 X0 Y0 F100\n{contour}\nG40\nG0 X-5 Y-5\nM2\n"
            );
            if same_verdict(&rs274, &format!("spiraloffset{k}{side}.ngc"), &text) {
                moves += edmd(&text).unwrap().len();
            }
        }
    }
    assert!(moves >= 40, "{moves} moves compared");
}

#[test]
fn a_machine_builders_m_codes_do_what_the_table_says() {
    use edmd::gcode::{Pause, VendorAction, VendorM};
    let options = ProgramOptions {
        conditions: vec![1, 2],
        mcodes: vec![
            VendorM {
                number: 60,
                action: VendorAction::Pause("thread the wire".into()),
            },
            VendorM {
                number: 50,
                action: VendorAction::Ignore("no wire cutter".into()),
            },
            VendorM {
                number: 84,
                action: VendorAction::Flush(true),
            },
            VendorM {
                number: 85,
                action: VendorAction::Flush(false),
            },
            VendorM {
                number: 82,
                action: VendorAction::Condition(2),
            },
        ],
        ..ProgramOptions::default()
    };
    let text = "G21 G0 X1\nM50\nM60\nG1 X2 F10\nM84 M82\nG1 X3\nM85\nM50\nG1 X4\nM2\n";
    let mut reader =
        BlockReader::with_options(Cursor::new(text.as_bytes()), "p.ngc", XYZ, options.clone());
    let blocks: Vec<_> = reader.by_ref().collect::<Result<_, _>>().expect("reads");
    assert_eq!(blocks[1].pause, Some((3, Pause::Program)));
    assert_eq!((blocks[2].flushing, blocks[2].condition), (true, 2));
    assert_eq!((blocks[3].flushing, blocks[3].condition), (false, 2));
    let warnings: Vec<String> = reader
        .take_warnings()
        .into_iter()
        .map(|w| w.message)
        .collect();
    assert!(
        warnings.contains(&"message: M60: thread the wire".to_string()),
        "{warnings:?}"
    );
    let ignored = warnings
        .iter()
        .filter(|w| w.starts_with("M50 does nothing here"))
        .count();
    assert_eq!(ignored, 1, "said once: {warnings:?}");
    // Without the table, M60 is an error that says where a machine builder maps it.
    let err = edmd("G21\nM60\nM2\n").unwrap_err();
    assert!(
        err.contains("unknown M word M60") && err.contains("[[program.mcode]]"),
        "{err}"
    );
}

/// Round three (issue [4/7]): `G80` beside another motion code is passed over (the safe-start
/// line of Fanuc and Haas posts), in either order; two other motion codes stay refused.
#[test]
fn g80_beside_a_motion_code_is_passed_over() {
    let Some(rs274) = rs274() else { return };
    agree(
        &rs274,
        "g80.ngc",
        "G21 G90 G17\nG0 X0 Y0 Z5\nG0 G80 X1\nG1 G80 X2 F100\nG81 G80 X3 Z-1 R1\nX4\n\
         G80 G81 X5 Z-1 R1\nG80\nG0 X6\nM2\n",
    );
    both_refuse(&rs274, "g0g1.ngc", "G21 G90\nG0 G1 X5 F100\nM2\n", "G0");
}

/// Round three: `M70`–`M73` act before the G codes of their line (`G91 M70` saves `G90`),
/// save and restore whether the `G92` offset is applied (`G92.2`/`G92.3`), and `M72`
/// restores `G40`, ending a wire offset the save did not have.
#[test]
fn m70_to_m73_act_first_and_restore_g92_and_the_wire_offset() {
    let Some(rs274) = rs274() else { return };
    agree(
        &rs274,
        "m70first.ngc",
        "G21 G90 F100\nG0 X0 Y0\nG91 M70\nG1 X1\nM72\nG1 X5\nM2\n",
    );
    agree(
        &rs274,
        "m72g92.ngc",
        "G21 G90 F100\nG0 X5 Y0\nG92 X10\nG1 X1\nM70\nG92.2\nG1 X2\nM72\nG1 X3\nM2\n",
    );
    agree(
        &rs274,
        "m73g92.ngc",
        "o100 sub\nM73\nG92.2\nG1 X1\no100 endsub\nG21 G90 F100\nG0 X5 Y0\nG92 X10\n\
         o100 call\nG1 X3\nM2\n",
    );
    agree(
        &rs274,
        "m72g40.ngc",
        "G21 G90 F100\nG0 X0 Y0\nM70\nG41 D1\nG1 X10 Y0\nG1 X10 Y10\nM72\nG1 X0 Y10\n\
         G1 X0 Y0\nM2\n",
    );
}

/// Round three: what rs274 refuses or reads on with around `M70`–`M73` and `O` numbers: an
/// `M72` at the top level of what a subroutine saved is refused; `M73` outside a subroutine
/// saves nothing and reads on; six-digit `O` numbers are names like any other.
#[test]
fn the_save_stack_and_long_o_numbers_as_rs274_reads_them() {
    let Some(rs274) = rs274() else { return };
    both_refuse(
        &rs274,
        "m70sub.ngc",
        "G21 G90 F100\no100 sub\nM70\no100 endsub\no100 call\nM72\nM2\n",
        "M72",
    );
    agree(&rs274, "m73top.ngc", "G21 G90 F100\nM73\nG1 X1\nM2\n");
    agree(
        &rs274,
        "o123456.ngc",
        "G21 G90 F100\nO123456 sub\nG1 X1\nO123456 endsub\nO123456 call\nG1 X2\nM2\n",
    );
}

/// Round three: in `G91` a canned cycle's polar words step each repeat round the origin (a
/// bolt circle in one block, as LinuxCNC's `hole-circle.ngc` drills it); at the origin the
/// step is indeterminate and both refuse.
#[test]
fn polar_words_step_a_g91_cycles_repeats() {
    let Some(rs274) = rs274() else { return };
    let holes = agree(
        &rs274,
        "boltcircle.ngc",
        "G21 G90 G17 F100\nG0 X0 Y0 Z1\nG0 @10 ^0\nG91 G81 R-0.9 Z-0.5 ^60 L6\nG90 G80\n\
         G0 @5 ^45\nG91 G83 R-0.9 Z-0.5 Q0.2 @1.5 ^-30 L3\nG90 G80\n\
         G0 X5 Y0\nG91 G81 R-0.9 Z-0.5 X1 Y2 L2\nG90 G80\nM2\n",
    );
    assert!(holes > 6 * 4, "{holes} moves");
    both_refuse(
        &rs274,
        "polarorigin.ngc",
        "G21 G90 G17 F100\nG0 X0 Y0 Z1\nG91 G81 R-0.9 Z-0.5 @2 L3\nG90 G80\nM2\n",
        "indeterminate at the origin",
    );
}

/// Round three: `G83`/`G73` in inches where the depth is an exact multiple of `Q` peck as
/// often as LinuxCNC's (it steps the pecks in the program's units, where `0.1 + 0.1 + 0.1`
/// is not `0.3`), in G90 and G91, from R planes and depths of a few decimals.
#[test]
fn inch_pecks_at_an_exact_multiple_of_q_count_as_rs274_counts_them() {
    let Some(rs274) = rs274() else { return };
    let mut program = String::from("G20 G90 G17 F10\nG0 X0 Y0 Z1\n");
    let mut cases = 0;
    for (k, q) in [0.1, 0.03, 0.07, 0.2, 0.05, 0.013].iter().enumerate() {
        for n in 1..=6 {
            for (r, mode) in [(0.1, "G90"), (0.0, "G90"), (-0.25, "G90"), (-0.4, "G91")] {
                let depth = q * f64::from(n);
                let (r_word, z_word) = if mode == "G91" {
                    (r, -depth)
                } else {
                    (r, r - depth)
                };
                let cycle = ["G83", "G73"][(k + n as usize) % 2];
                program.push_str(&format!(
                    "{mode} {cycle} X{:.4} Y{:.4} R{r_word:.4} Z{z_word:.4} Q{q:.4}\nG90 G80\nG0 Z1\n",
                    0.1 * n as f64,
                    0.1 * k as f64
                ));
                cases += 1;
            }
        }
    }
    program.push_str("M2\n");
    let moves = agree(&rs274, "inchpecks.ngc", &program);
    assert!(
        cases >= 100 && moves > 4 * cases,
        "{cases} cycles, {moves} moves"
    );
}

/// Round three: a `G5.2` control point takes both `X` and `Y` whatever the plane (a curve
/// written in G18 with X Z points is refused, not flattened to XY), and every line after the
/// `G5.2` its weight `P`; the `G5.2` line itself may leave `P` out, and its `Z` is ignored.
#[test]
fn g5_2_points_need_x_y_and_a_weight_as_in_linuxcnc() {
    let Some(rs274) = rs274() else { return };
    let curve = |plane: &str, first: &str, second: &str| {
        format!(
            "G21 G90 {plane} F100\nG0 X0 Y0\nG5.2 {first} L3\n{second}\nX3 Y1 P1\nG5.3\nG1 X0 Y0\nM2\n"
        )
    };
    agree(&rs274, "g18xy.ngc", &curve("G18", "X1 Y1 P1", "X2 Y0 P1"));
    agree(&rs274, "firstp.ngc", &curve("G17", "X1 Y1", "X2 Y0 P1"));
    agree(
        &rs274,
        "firstz.ngc",
        &curve("G17", "X1 Y1 Z1 P1", "X2 Y0 P1"),
    );
    agree(&rs274, "weightonly.ngc", &curve("G17", "P2", "X2 Y0 P1"));
    let needs = "needs both X and Y";
    both_refuse(
        &rs274,
        "g18xz.ngc",
        &curve("G18", "X1 Z1 P1", "X2 Z0 P1"),
        needs,
    );
    both_refuse(
        &rs274,
        "g19yz.ngc",
        &curve("G19", "Y1 Z1 P1", "Y2 Z0 P1"),
        needs,
    );
    both_refuse(&rs274, "noy.ngc", &curve("G17", "X1 Y1 P1", "X2 P1"), needs);
    both_refuse(
        &rs274,
        "nop.ngc",
        &curve("G17", "X1 Y1 P1", "X2 Y0"),
        "needs its weight P",
    );
}

/// Round three, item 10: after a probing move rs274's moves are off by 0.254 mm, because its
/// standalone canon ends `STRAIGHT_PROBE` that far short of the target, backed off along the
/// move (0.01 inch, whatever the units), where edmd's `check` ends it at the target (a job ends
/// it at the contact). Measured here, and said in README.
#[test]
fn after_a_probe_rs274_stands_0_254_mm_short_of_the_target_along_the_move() {
    let Some(rs274) = rs274() else { return };
    let cases: [(&str, &str, [f64; 3], [f64; 3]); 3] = [
        (
            "probez.ngc",
            "G21 G90 F100\nG0 X0 Y0 Z5\nG38.2 Z-10\nG91 G1 X1\nM2\n",
            [0.0, 0.0, 5.0],
            [0.0, 0.0, -10.0],
        ),
        (
            "probexy.ngc",
            "G21 G90 F100\nG0 X1 Y0 Z5\nG38.3 X10 Y10\nG91 G1 Z1\nM2\n",
            [1.0, 0.0, 5.0],
            [10.0, 10.0, 5.0],
        ),
        (
            "probeinch.ngc",
            "G20 G90 F10\nG0 X0 Y0 Z1\nG38.2 Z-1\nG91 G1 X0.1\nM2\n",
            [0.0, 0.0, 25.4],
            [0.0, 0.0, -25.4],
        ),
    ];
    for (name, text, start, target) in cases {
        let theirs = linuxcnc(&rs274, name, text).expect("rs274 reads it");
        let ours = edmd(text).expect("edmd reads it");
        let (a, b) = (ours.last().unwrap(), theirs.last().unwrap());
        let length = (0..3)
            .map(|i| (target[i] - start[i]).powi(2))
            .sum::<f64>()
            .sqrt();
        for i in 0..3 {
            let back_off = 0.254 * (target[i] - start[i]) / length;
            assert!(
                (a[i] - back_off - b[i]).abs() < 2e-4,
                "{name}: edmd {a:?}, rs274 {b:?}: not 0.254 mm back along the probe"
            );
        }
    }
}
