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
fn check_accepts_the_papers_programs() {
    for name in ["huang-table1-g38.nc", "jin-table1-g06_2.nc"] {
        let path = Path::new("programs").join(name);
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

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("edmd-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

#[test]
fn plan_writes_trace_summary_and_plots() {
    let out_dir = temp_dir("plan");
    for mode in ["chord", "period"] {
        let dir = out_dir.join(mode);
        let out = edmd(&[
            "plan",
            "programs/jin-table1-g06_2.nc",
            "--out",
            dir.to_str().unwrap(),
            "--set",
            &format!("interpolation.segmentation={mode}"),
        ]);
        let (stdout, stderr) = text(&out);
        assert_eq!(out.status.code(), Some(0), "{stdout}{stderr}");
        assert!(stdout.contains("time-optimal bound"), "{stdout}");
        let trace = std::fs::read_to_string(dir.join("trace.csv")).unwrap();
        let mut lines = trace.lines();
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        for col in [
            "line",
            "kind",
            "u",
            "x",
            "y",
            "z",
            "t",
            "feed_mm_per_min",
            "chord_err",
            "chord_bound",
        ] {
            assert!(header.contains(&col), "missing column {col}: {header:?}");
        }
        let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap())
                .unwrap();
        let segments = json["segments"].as_u64().unwrap() as usize;
        assert_eq!(
            rows.len(),
            segments + 1,
            "one row for the start, one per segment"
        );
        // The first row is the path's start, at rest; the G0 to X0 Y0 is a zero move, so the
        // first block is the curve on line 5.
        let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
        assert_eq!(rows[0][col("t")], "0");
        let last = rows.last().unwrap();
        assert_eq!(last[col("kind")], "nurbs");
        assert_eq!(last[col("u")], "1");
        assert!(last[col("x")].parse::<f64>().unwrap().abs() < 1e-9);
        let max_err = rows
            .iter()
            .map(|r| r[col("chord_err")].parse::<f64>().unwrap())
            .fold(0.0, f64::max);
        assert!(max_err <= 0.001, "{max_err}");
        assert!(json["max_chord_error_mm"].as_f64().unwrap() <= 0.001);
        // Every segment carries its certified bound, within the tolerance.
        let max_bound = rows
            .iter()
            .map(|r| r[col("chord_bound")].parse::<f64>().unwrap())
            .fold(0.0, f64::max);
        assert!(max_bound > 0.0 && max_bound <= 0.001, "{max_bound}");
        assert_eq!(json["max_chord_bound_mm"].as_f64().unwrap(), max_bound);
        assert_eq!(json["segments_bound_over_tolerance"].as_u64(), Some(0));
        // Full precision: each number is the shortest text that reads back as the same
        // double, so coordinates carry more than the old 6 decimals.
        let long = rows
            .iter()
            .filter(|r| r[col("x")].split('.').nth(1).is_some_and(|d| d.len() > 6))
            .count();
        assert!(long > rows.len() / 2, "{long} of {} rows", rows.len());
        for r in &rows {
            let x = r[col("x")];
            assert_eq!(x.parse::<f64>().unwrap().to_string(), x);
        }
        let time = json["planned_time_s"].as_f64().unwrap();
        let bound = json["time_optimal_bound_s"].as_f64().unwrap();
        // The bound samples the same limits (one step per tick included) every 5 µm, the plan
        // takes chords: they agree to a few parts per million from below.
        assert!(
            time >= bound * (1.0 - 1e-5) && time <= 1.01 * bound,
            "{time} vs {bound}"
        );
        for svg in [
            "path.svg",
            "chord_error.svg",
            "feed.svg",
            "tangential_accel.svg",
        ] {
            let body = std::fs::read_to_string(dir.join(svg)).unwrap();
            assert!(body.starts_with("<svg") && body.contains("</svg>"), "{svg}");
        }
        // The fluctuation is period mode's figure; chord mode draws no empty chart.
        assert_eq!(
            dir.join("fluctuation.svg").exists(),
            mode == "period",
            "{mode}"
        );
        // The path plot marks where it starts; a two-axis program has no Z chart.
        let path = std::fs::read_to_string(dir.join("path.svg")).unwrap();
        assert!(path.contains(">start</text>"), "a start marker");
        assert!(!dir.join("path_z.svg").exists());
        assert!(
            std::fs::read_to_string(dir.join("summary.txt"))
                .unwrap()
                .contains("segments")
        );
    }
    let _ = std::fs::remove_dir_all(&out_dir);
}

/// The time-optimal bound is streamed: a program past the 10,000 blocks beyond which it used to
/// be skipped, long enough that its 5 µm samples held at once would take 60 MB, gets a bound
/// within 1 % of its plan (nothing on it is slow), and the plan's peak memory stays flat.
#[test]
fn plan_bounds_a_long_program_in_flat_memory() {
    let dir = temp_dir("plan-long");
    std::fs::create_dir_all(&dir).unwrap();
    let program = dir.join("long.ngc");
    let mut source = String::from("G21 G90 G17\nF600\n");
    for i in 1..=12_000 {
        // A zig-zag of 1 mm moves at 60° to each other.
        let (x, y) = (0.5 * i as f64, if i % 2 == 0 { 0.0 } else { 0.866 });
        source += &format!("G1 X{x:.4} Y{y:.4}\n");
    }
    std::fs::write(&program, source + "M2\n").unwrap();
    let out = dir.join("plan");
    let result = edmd(&[
        "plan",
        program.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(result.status.success(), "{:?}", text(&result));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(json["blocks"].as_u64(), Some(12_000));
    let time = json["planned_time_s"].as_f64().unwrap();
    let bound = json["time_optimal_bound_s"].as_f64().unwrap();
    assert!(
        bound <= time * (1.0 + 1e-5) && time <= 1.01 * bound,
        "{time} vs {bound}"
    );
    let peak_mib = json["peak_rss_kib"].as_u64().unwrap() as f64 / 1024.0;
    assert!(peak_mib < 32.0, "peak RSS {peak_mib:.1} MiB");
}

#[test]
fn plan_reports_bad_programs_with_their_location() {
    let dir = temp_dir("plan-bad");
    std::fs::create_dir_all(&dir).unwrap();
    let program = dir.join("bad.nc");
    std::fs::write(&program, "G21 G90\nG01 X1 Y1 F100\nG01 X2 Q7\n").unwrap();
    let out = edmd(&[
        "plan",
        program.to_str().unwrap(),
        "--out",
        dir.join("out").to_str().unwrap(),
    ]);
    let (_, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("bad.nc:3:"), "{stderr}");
    // The trace keeps what was written before the bad block: the header and the path's
    // first point (line 2's segment was still in the planner's window).
    let trace = std::fs::read_to_string(dir.join("out/trace.csv")).unwrap();
    let rows: Vec<&str> = trace.lines().collect();
    assert_eq!(rows.len(), 2, "{trace}");
    assert!(rows[0].starts_with("line,kind,u,x,y,z,t,"), "{trace}");
    assert!(rows[1].starts_with("2,line,,0,0,"), "{trace}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_closed_pipe_ends_quietly_not_in_a_panic() {
    // `edmd check PROGRAM | head -1`: the reader goes away after one line. The listing is
    // far longer than a pipe holds, so writing fails however the scheduling goes (a child
    // forked meanwhile by another test may hold the read end for a moment).
    let dir = temp_dir("closed-pipe");
    std::fs::create_dir_all(&dir).unwrap();
    let program = dir.join("long.nc");
    let text: String = (0..20_000)
        .map(|i| format!("G1 X{} Y{} F100\n", i % 50, i % 7))
        .collect();
    std::fs::write(&program, text).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .arg("check")
        .arg(&program)
        .current_dir(repo())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(out.status.code(), Some(141), "{stderr}");
}

#[test]
fn the_configuration_is_found_in_order_and_named() {
    let dir = temp_dir("config-search");
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("mine.toml");
    std::fs::write(&file, "[buffer]\ncapacity = 64\nreserved = 8\n").unwrap();
    let program = repo().join("programs/jin-table1-g06_2.nc");
    let check = |env: Option<&Path>, args: &[&str]| {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_edmd"));
        cmd.arg("check").arg(&program).args(["-q", "-v"]).args(args);
        cmd.current_dir(&dir).env_remove("EDMD_CONFIG");
        if let Some(path) = env {
            cmd.env("EDMD_CONFIG", path);
        }
        let out = cmd.output().unwrap();
        assert_eq!(out.status.code(), Some(0));
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let from_env = check(Some(&file), &[]);
    assert!(
        from_env.contains(&format!("configuration: {} ($EDMD_CONFIG)", file.display())),
        "{from_env}"
    );
    let explicit = check(
        Some(Path::new("/nonexistent")),
        &["--config", file.to_str().unwrap()],
    );
    assert!(explicit.contains("(--config)"), "{explicit}");
    // From a directory with no checkout's config: the installed one if there is one, else the
    // built-in default; either way it says which.
    let neither = check(None, &[]);
    assert!(
        neither.contains("/etc/edmd/edmd.toml (the installed one)")
            || neither.contains("configuration: the built-in default"),
        "{neither}"
    );
}

#[test]
fn plan_out_naming_a_file_is_bad_input() {
    let dir = temp_dir("plan-out-file");
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("not-a-dir");
    std::fs::write(&file, "x").unwrap();
    let out = edmd(&[
        "plan",
        "programs/jin-table1-g06_2.nc",
        "--out",
        file.to_str().unwrap(),
    ]);
    let (_, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("not a directory"), "{stderr}");
}

#[test]
fn run_logs_its_progress_when_not_on_a_terminal() {
    let out = edmd(&[
        "run",
        "tests/data/runtime-path.nc",
        "--set",
        "gap.kind=\"none\"",
        "--set",
        "output.kind=\"null\"",
        // Real time at 900 mm/min: about a second, so the progress shows.
        "--set",
        "fine.virtual_time=false",
        "--set",
        "servo.normal_feed_mm_per_min=900.0",
    ]);
    let (_, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains("progress: ") && stderr.contains(" % of 17.13"),
        "{stderr}"
    );
    assert!(stderr.contains("configuration: "), "{stderr}");
}

#[test]
fn plan_plots_rapids_dashed_z_on_its_own_and_the_legend_off_the_data() {
    let dir = temp_dir("plan-plots");
    std::fs::create_dir_all(&dir).unwrap();
    let program = dir.join("p.nc");
    std::fs::write(
        &program,
        "G21 G90\nG0 X5 Y5 Z2\nG1 Z0 F100\nG1 X10 Y5\nG0 Z2\nG0 X0 Y0\nM30\n",
    )
    .unwrap();
    let out_dir = dir.join("out");
    let out = edmd(&[
        "plan",
        program.to_str().unwrap(),
        "--out",
        out_dir.to_str().unwrap(),
        "--set",
        "machine.axes=[\"X\",\"Y\",\"Z\"]",
        "--set",
        "machine.step_mm=[0.001,0.001,0.001]",
    ]);
    let (stdout, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(0), "{stdout}{stderr}");
    let path = std::fs::read_to_string(out_dir.join("path.svg")).unwrap();
    assert!(path.contains("stroke-dasharray=\"5 4\""), "rapids dashed");
    assert!(path.contains("rapids (G0)"), "and named in the legend");
    // The legend sits above the plot frame, not inside it.
    let frame_top: f64 = 64.0;
    for legend in path
        .lines()
        .filter(|l| l.contains("width=\"12\" height=\"4\""))
    {
        let y: f64 = legend
            .split("y=\"")
            .nth(1)
            .unwrap()
            .split('"')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        assert!(y < frame_top, "legend at y {y}: {legend}");
    }
    let z = std::fs::read_to_string(out_dir.join("path_z.svg")).unwrap();
    assert!(
        z.contains("Z along the path") && z.contains("<path d=\"M"),
        "{z}"
    );
}

/// `edmd run` on a program with flushing, a dwell and a programmed stop: the log tells each,
/// the dwell adds its time to the machine time, and the stop does not wait without an operator.
#[test]
fn run_logs_flushing_dwells_and_passes_programmed_stops() {
    let dir = temp_dir("stops");
    std::fs::create_dir_all(&dir).unwrap();
    let program = dir.join("stops.ngc");
    let write = |dwell: &str| {
        std::fs::write(
            &program,
            format!(
                "G21 G90 G17\nG0 X0 Y0\nM8\nG1 X1 F600\n{dwell}\nG1 X2\nM0\nG1 X3\nM9\nG1 X4\nM2\n"
            ),
        )
        .unwrap();
        let out = edmd(&[
            "run",
            program.to_str().unwrap(),
            "--set",
            "gap.kind=\"none\"",
            "--set",
            "output.kind=\"null\"",
            "--set",
            "log.format=\"plain\"",
        ]);
        let (stdout, stderr) = text(&out);
        assert_eq!(out.status.code(), Some(0), "{stdout}{stderr}");
        let end: f64 = stderr
            .lines()
            .find_map(|l| l.split("program end at t=").nth(1))
            .and_then(|t| t.trim_end_matches(" s").parse().ok())
            .unwrap_or_else(|| panic!("no program end in {stderr}"));
        (stderr, end)
    };
    let (log, with_dwell) = write("G4 P0.75");
    assert!(log.contains("stops.ngc:4: flushing on"), "{log}");
    assert!(log.contains("stops.ngc:10: flushing off"), "{log}");
    assert!(
        log.contains("stops.ngc:8: programmed stop (M0/M1) before this line")
            && log.contains("not waiting"),
        "{log}"
    );
    let (_, without) = write("");
    let dwell = with_dwell - without;
    assert!((dwell - 0.75).abs() < 0.01, "the dwell took {dwell} s");
}

/// Rapids run at the machine's speed, not the servo's: `G0 X50` takes seconds, not the
/// 50 s the servo's normal feed would. A short during one is a collision: `edmd run` has no
/// operator to resume, so it stops there and exits 1 saying so.
#[test]
fn rapids_run_at_rapid_speed_and_a_short_in_one_is_a_collision() {
    let dir = temp_dir("rapids");
    std::fs::create_dir_all(&dir).unwrap();
    let program = dir.join("rapid.ngc");
    std::fs::write(&program, "G21 G90\nG0 X50\nG1 X51 F60\nG0 X0\nM2\n").unwrap();
    let run = |extra: &[&str]| {
        let mut args = vec![
            "run",
            program.to_str().unwrap(),
            "--set",
            "output.kind=\"null\"",
            "--set",
            "log.format=\"plain\"",
        ];
        args.extend_from_slice(extra);
        let out = edmd(&args);
        let (stdout, stderr) = text(&out);
        (out.status.code(), stdout, stderr)
    };
    let (code, stdout, stderr) = run(&[
        "--set",
        "sim.debris_shorts_per_mm=0",
        "--set",
        "sim.model=\"kinematic\"",
    ]);
    assert_eq!(code, Some(0), "{stdout}{stderr}");
    let end: f64 = stderr
        .lines()
        .find_map(|l| l.split("program end at t=").nth(1))
        .and_then(|t| t.trim_end_matches(" s").parse().ok())
        .unwrap_or_else(|| panic!("no program end in {stderr}"));
    // 100 mm of rapids at the one-step-per-tick cap (20 mm/s) and 1 mm cut at 1 mm/s.
    assert!((5.9..6.2).contains(&end), "took {end} s");
    // `plan` uses the same model: its planned time is the executed one.
    let out_dir = dir.join("plan");
    let out = edmd(&[
        "plan",
        program.to_str().unwrap(),
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    let (stdout, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(0), "{stdout}{stderr}");
    let planned: f64 = stdout
        .lines()
        .find_map(|l| l.strip_prefix("motion time"))
        .and_then(|t| t.split_whitespace().next()?.parse().ok())
        .unwrap_or_else(|| panic!("no motion time in {stdout}"));
    assert!(
        (planned - end).abs() < 0.02 * end,
        "planned {planned} s, ran {end} s"
    );

    // The gap shorts 1 s into the first rapid (tick 20000): a collision at X = 20 mm or so.
    let script = dir.join("gap.txt");
    std::fs::write(&script, "0 open\n20000 short\n").unwrap();
    let script_set = format!("gap.script=\"{}\"", script.display());
    let (code, stdout, stderr) = run(&["--set", "gap.kind=\"script\"", "--set", &script_set]);
    assert_eq!(code, Some(1), "{stdout}{stderr}");
    assert!(stderr.contains("rapid.ngc:2: COLLISION"), "{stderr}");
    assert!(stdout.contains("rapid.ngc: collision"), "{stdout}");
    assert!(
        stdout.contains("0 shorts, 0 turn-backs"),
        "no turn-back in a rapid: {stdout}"
    );
}

/// `gap.kind = "iio"` on a fake sysfs directory: a steady sparking voltage runs the job to its
/// end; a device that is not there is a clear startup error.
#[test]
fn run_reads_the_gap_voltage_through_iio() {
    let dir = temp_dir("iio");
    let dev = dir.join("iio:device0");
    std::fs::create_dir_all(&dev).unwrap();
    // 30 V at the gap: 1500 counts of 1 mV behind a 1:20 divider.
    std::fs::write(dev.join("in_voltage0_raw"), "1500\n").unwrap();
    std::fs::write(dev.join("in_voltage_scale"), "1.000000\n").unwrap();
    let device = format!("gap.iio_device=\"{}\"", dev.display());
    let run = |device: &str| {
        edmd(&[
            "run",
            "tests/data/runtime-path.nc",
            "--set",
            "gap.kind=\"iio\"",
            "--set",
            device,
            "--set",
            "gap.iio_gain=20.0",
            "--set",
            "output.kind=\"null\"",
            "--set",
            "fine.virtual_time=false",
            "--set",
            "servo.normal_feed_mm_per_min=600.0",
        ])
    };
    let out = run(&device);
    let (stdout, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(0), "{stdout}{stderr}");
    assert!(
        stdout.contains(": done") && stdout.contains("0 shorts"),
        "{stdout}"
    );
    let missing = format!("gap.iio_device=\"{}\"", dir.join("nope").display());
    let out = run(&missing);
    let (stdout, stderr) = text(&out);
    assert_ne!(out.status.code(), Some(0), "{stdout}{stderr}");
    assert!(
        stderr.contains("no such IIO device (gap.iio_device)"),
        "{stderr}"
    );
}

/// Machining conditions: `E<n>` selects one (modal); its feed drives the three-state servo, the
/// pulse log's `spark` is off on the rapid and `condition` follows the program; an undefined
/// number is an error naming the line.
#[test]
fn conditions_set_the_feed_and_show_in_the_pulse_log() {
    let dir = temp_dir("conditions");
    std::fs::create_dir_all(&dir).unwrap();
    let program = dir.join("e.ngc");
    std::fs::write(&program, "G21 G90\nG0 X1\nE2 G1 X2 F600\nE4 G1 X3\nM2\n").unwrap();
    let pulses = dir.join("pulses.csv");
    let out = edmd(&[
        "run",
        program.to_str().unwrap(),
        "--set",
        "gap.kind=\"none\"",
        "--set",
        "output.kind=\"file\"",
        "--set",
        &format!("output.path=\"{}\"", pulses.display()),
        "--set",
        "log.format=\"plain\"",
    ]);
    let (stdout, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(0), "{stdout}{stderr}");
    assert!(
        stderr.contains("e.ngc:3: machining condition E2"),
        "{stderr}"
    );
    assert!(
        stderr.contains("e.ngc:4: machining condition E4"),
        "{stderr}"
    );
    let (header, rows) = edmd::output::read_pulse_log(&pulses).unwrap();
    assert_eq!(header.tick_us, 50);
    // X position in steps at each row, and the ticks spent per millimetre of each condition.
    let mut x = 0i64;
    let mut first_tick_at = std::collections::BTreeMap::new();
    for r in &rows {
        x += r.steps[0] as i64;
        // (The tick that takes the rapid's last step already belongs to the cut.)
        if x < 1000 && r.steps[0] != 0 {
            assert!(!r.spark, "spark on during the rapid at tick {}", r.tick);
            assert_eq!(r.condition, 0);
        }
        if r.steps[0] != 0 {
            first_tick_at.entry(x).or_insert(r.tick);
        }
        if x > 1000 && x < 2000 && r.steps[0] != 0 {
            assert!(r.spark && r.condition == 2, "{r:?}");
        }
        if x > 2000 && x < 3000 && r.steps[0] != 0 {
            assert!(r.spark && r.condition == 4, "{r:?}");
        }
    }
    assert_eq!(x, 3000);
    let secs = |a: i64, b: i64| (first_tick_at[&b] - first_tick_at[&a]) as f64 * 50e-6;
    // E2 cuts at 25 mm/min, E4 at 90 mm/min: the feed over the middle of each millimetre.
    let e2 = 0.8 / secs(1100, 1900) * 60.0;
    let e4 = 0.8 / secs(2100, 2900) * 60.0;
    assert!((e2 - 25.0).abs() < 0.5, "E2 feed {e2} mm/min");
    assert!((e4 - 90.0).abs() < 1.0, "E4 feed {e4} mm/min");

    std::fs::write(&program, "G21 G90\nE7 G1 X1 F60\nM2\n").unwrap();
    let out = edmd(&["check", program.to_str().unwrap()]);
    let (stdout, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(2), "{stdout}{stderr}");
    assert!(
        stderr.contains("e.ngc:2:1: E7: no such machining condition (generator.condition defines E1, E2, E3, E4, E5, E9)"),
        "{stderr}"
    );
}

/// Completions and man pages come from the command-line definition itself: every command is
/// in them, nested ones included, and an unknown shell is a usage error.
#[test]
fn completions_and_man_pages_cover_every_command() {
    for (shell, marker) in [
        ("bash", "_edmd()"),
        ("zsh", "#compdef edmd"),
        ("fish", "complete -c edmd"),
    ] {
        let out = edmd(&["completions", shell]);
        assert!(out.status.success(), "{shell}");
        let (stdout, _) = text(&out);
        assert!(stdout.contains(marker), "{shell}: {marker} missing");
        for command in ["rethread", "monitor", "find", "completions"] {
            assert!(stdout.contains(command), "{shell}: no {command}");
        }
    }
    assert_eq!(edmd(&["completions", "tcsh"]).status.code(), Some(2));
    let dir = std::env::temp_dir().join(format!("edmd-cli-man-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let out = edmd(&["man", "--out", dir.to_str().unwrap()]);
    assert!(out.status.success(), "{:?}", text(&out));
    for page in [
        "edmd",
        "edmd-run",
        "edmd-ctl",
        "edmd-ctl-hold",
        "edmd-ctl-rethread",
    ] {
        let roff = std::fs::read_to_string(dir.join(format!("{page}.1")))
            .unwrap_or_else(|e| panic!("{page}.1: {e}"));
        assert!(
            roff.starts_with(".ie") || roff.contains(&format!(".TH {page} 1")),
            "{page}"
        );
    }
    // A page's synopsis names the command as typed.
    let hold = std::fs::read_to_string(dir.join("edmd-ctl-hold.1")).unwrap();
    assert!(hold.contains("edmd ctl hold"), "{hold}");
    // The main pages say which files the daemon keeps, and show it used.
    for page in ["edmd", "edmd-serve", "edmd-ctl"] {
        let roff = std::fs::read_to_string(dir.join(format!("{page}.1"))).unwrap();
        assert!(
            roff.contains(".SH FILES") && roff.contains("jobs.jsonl"),
            "{page}"
        );
        assert!(
            roff.contains(".SH EXAMPLES") && roff.contains("edmd ctl jobs"),
            "{page}"
        );
    }
    // edmd.toml(5), from the shipped configuration: every section, keys with defaults.
    let toml = std::fs::read_to_string(dir.join("edmd.toml.5")).unwrap();
    assert!(toml.starts_with(".TH edmd.toml 5"), "{toml}");
    for needle in [
        ".SH [DAEMON]",
        "\\fBstate_dir\\fR = \"/var/lib/edmd\"",
        "\\fBjob_history\\fR = \"\"",
        ".SH [WIRE]",
        "\\fBpass\\fR = [ … ]",
    ] {
        assert!(toml.contains(needle), "{needle} missing from edmd.toml(5)");
    }
    // A key's comment reads as text, not as roff requests.
    assert!(!toml.lines().any(|l| l.starts_with(".#")));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `plan`'s estimated time is the machine's: the papers' Huang program on the default
/// simulator runs within 25 % of it, and sparking throughout within 1 %.
#[test]
fn plans_estimated_time_is_within_a_quarter_of_the_run() {
    let dir = std::env::temp_dir().join(format!("edmd-cli-estimate-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let program = repo().join("programs/huang-table1-g38.nc");
    let program = program.to_str().unwrap();
    let out = edmd(&[
        "plan",
        program,
        "--out",
        dir.join("plan").to_str().unwrap(),
        "-q",
    ]);
    assert!(out.status.success(), "{:?}", text(&out));
    let plan: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("plan/summary.json")).unwrap())
            .unwrap();
    let run = |extra: &[&str]| {
        let summary = dir.join("run.json");
        let mut args = vec!["run", program, "--summary", summary.to_str().unwrap()];
        args.extend_from_slice(extra);
        let out = edmd(&args);
        assert!(out.status.success(), "{:?}", text(&out));
        let s: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
        s["virtual_time_s"].as_f64().unwrap()
    };
    let estimated = plan["estimated_time_s"].as_f64().unwrap();
    let motion = plan["planned_time_s"].as_f64().unwrap();
    // The estimate models the kinematic gap's erosion; on the discharge model the process sets
    // the speed.
    let cut = run(&["--set", "sim.model=\"kinematic\""]);
    println!("huang: estimated {estimated:.2} s, ran {cut:.2} s; motion {motion:.4} s");
    assert!(
        (cut / estimated - 1.0).abs() < 0.25,
        "estimated {estimated} s, ran {cut} s"
    );
    // With no gap input the gap reads sparking throughout: the estimate's own model.
    let steady = run(&["--set", "gap.kind=\"none\""]);
    println!("huang sparking throughout: ran {steady:.4} s");
    assert!(
        (steady / estimated - 1.0).abs() < 0.01,
        "estimated {estimated} s, ran {steady} s"
    );
    assert!(motion < estimated / 10.0);
    std::fs::remove_dir_all(&dir).unwrap();
}
