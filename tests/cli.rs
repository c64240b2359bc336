//! The `edmd` binary as a user runs it: exit codes, output, error format.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn edmd(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_edmd"))
        .args(args)
        .current_dir(repo())
        .output()
        .expect("edmd runs")
}

fn text(out: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn check_accepts_the_papers_programs_in_shared_cases() {
    for name in ["huang-table1-g38.nc", "jin-table1-g06_2.nc"] {
        let path = Path::new("../shared/cases").join(name);
        let out = edmd(&["check", path.to_str().unwrap()]);
        let (stdout, stderr) = text(&out);
        assert_eq!(out.status.code(), Some(0), "{name}: {stdout}{stderr}");
        assert!(stdout.contains("nurbs"), "{stdout}");
        assert!(stdout.contains("blocks: "), "{stdout}");
    }
}

#[test]
fn check_prints_each_block_then_totals() {
    let out = edmd(&["check", "programs/jin-table1-g06_2.nc"]);
    let (stdout, _) = text(&out);
    assert_eq!(out.status.code(), Some(0));
    let row = stdout
        .lines()
        .find(|l| l.contains("nurbs"))
        .expect("a nurbs row");
    // line, kind, length, degree, points, knot range
    assert!(row.trim_start().starts_with("5  nurbs"), "{row}");
    assert!(
        row.contains("G06.2 degree 3, 7 points, knots [0, 1]"),
        "{row}"
    );
    assert!(stdout.contains("blocks: 1 (rapid 0, line 0, arc 0, nurbs 1 with 7 control points)"));
    assert!(stdout.contains("feed: 18000 to 18000 mm/min"));
    assert!(stdout.contains("program end: line 16"));
}

#[test]
fn check_reads_every_test_program() {
    let cases = [
        ("tests/data/linuxcnc-g5_2-butterfly.ngc", true, "nurbs 6"),
        (
            "tests/data/fanuc-g06_2-ten-point-cubic.nc",
            false,
            "nurbs 1",
        ),
        ("tests/data/arcs-all-planes.nc", true, "arc 7"),
        (
            "tests/data/inch-g20-plate.nc",
            false,
            "length: 141.4982 mm at feed",
        ),
    ];
    for (program, xyz, expect) in cases {
        let mut args = vec!["check", "--quiet", program];
        if xyz {
            args.extend(["--config", "tests/data/xyz.toml"]);
        }
        let out = edmd(&args);
        let (stdout, stderr) = text(&out);
        assert_eq!(out.status.code(), Some(0), "{program}: {stdout}{stderr}");
        assert!(stdout.contains(expect), "{program}: {stdout}");
        assert!(
            !stdout.contains("    line  kind"),
            "--quiet prints no table"
        );
    }
}

#[test]
fn set_overrides_work_without_a_config_file() {
    let out = edmd(&[
        "check",
        "-q",
        "tests/data/arcs-all-planes.nc",
        "--set",
        "machine.axes=[\"X\",\"Y\",\"Z\"]",
        "--set",
        "machine.step_mm=[0.001,0.001,0.001]",
    ]);
    let (stdout, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(0), "{stdout}{stderr}");
}

#[test]
fn a_bad_program_exits_2_with_file_line_col_and_the_text() {
    let dir = std::env::temp_dir().join(format!("edmd-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let prog = dir.join("bad.nc");
    std::fs::write(&prog, "G21 G90\nG0 X0 Y0\nG1 X5 Y5 F100\nG2 X10 Y0 I5 R5\n").unwrap();
    let out = edmd(&["check", prog.to_str().unwrap()]);
    let (stdout, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(2), "{stdout}{stderr}");
    let want = format!("{}:4:14: arc with both R and I/J/K", prog.display());
    assert!(stderr.contains(&want), "{stderr}");
    assert!(stderr.contains(" 4 | G2 X10 Y0 I5 R5"), "{stderr}");
    // Blocks before the error were reported, the totals were not.
    assert!(stdout.contains("line "), "{stdout}");
    assert!(!stdout.contains("blocks:"), "{stdout}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_missing_program_exits_2() {
    let out = edmd(&["check", "no/such/file.nc"]);
    let (_, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr.contains("no/such/file.nc: cannot read the program"),
        "{stderr}"
    );
}

#[test]
fn a_bad_config_exits_2_naming_key_and_line() {
    let dir = std::env::temp_dir().join(format!("edmd-cfg-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cfg = dir.join("bad.toml");
    std::fs::write(&cfg, "[buffer]\ncapacity = 16\nreserved = 16\n").unwrap();
    let out = edmd(&[
        "check",
        "programs/huang-table1-g38.nc",
        "--config",
        cfg.to_str().unwrap(),
    ]);
    let (_, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr.contains(&format!("{}:3:1: buffer.reserved", cfg.display())),
        "{stderr}"
    );
    let out = edmd(&[
        "check",
        "programs/huang-table1-g38.nc",
        "--set",
        "interpolation.predictor=adams",
    ]);
    let (_, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr.contains("--set interpolation.predictor=adams"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn usage_errors_exit_2() {
    let out = edmd(&["check"]);
    assert_eq!(out.status.code(), Some(2));
    let out = edmd(&["frobnicate"]);
    assert_eq!(out.status.code(), Some(2));
}
