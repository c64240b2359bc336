//! Parameters, expressions, O-word control, Fanuc subprograms, G92, dwell, stops, flushing and
//! block delete, through the public reader: each program's path is checked point by point
//! against the positions worked out by hand (or by a plain Rust loop doing what the program
//! says), and each error by its `file:line:col` and wording.

use std::io::Cursor;

use edmd::gcode::{Block, BlockReader, GcodeError, Pause, ProgramOptions, Warning};
use edmd::vocab::Axis;

const XY: &[Axis] = &[Axis::X, Axis::Y];

fn read_with(
    program: &str,
    options: ProgramOptions,
) -> Result<(Vec<Block>, Vec<Warning>), GcodeError> {
    let mut reader =
        BlockReader::with_options(Cursor::new(program.as_bytes()), "t.ngc", XY, options);
    let blocks = reader.by_ref().collect::<Result<Vec<_>, _>>()?;
    Ok((blocks, reader.take_warnings()))
}

fn read(program: &str) -> (Vec<Block>, Vec<Warning>) {
    read_with(program, ProgramOptions::default()).unwrap_or_else(|e| panic!("{e}"))
}

fn error(program: &str) -> String {
    match read_with(program, ProgramOptions::default()) {
        Ok(_) => panic!("the program should be refused:\n{program}"),
        Err(e) => e.to_string().lines().next().unwrap_or("").to_string(),
    }
}

/// Each block's end point and source line, rounded to 1 nm.
fn ends(blocks: &[Block]) -> Vec<(u64, f64, f64)> {
    let r = |v: f64| (v * 1e6).round() / 1e6;
    blocks
        .iter()
        .map(|b| (b.line, r(b.end()[0]), r(b.end()[1])))
        .collect()
}

#[test]
fn subroutine_with_arguments_loops_and_branches() {
    let program = "\
#<step> = 2.5
#1 = 0
o<side> sub
  G1 X[#1 * #<_step_scale>] Y#2 F120
o<side> endsub
#<_step_scale> = 1
G0 X0 Y0
o10 while [#1 LT 4]
  #1 = [#1 + 1]
  o20 if [#1 MOD 2 EQ 0]
    o<side> call [#1 * #<step>] [1]
  o20 elseif [#1 EQ 3]
    G1 X0 Y[#1] F120
  o20 else
    G1 Y-1 F120
  o20 endif
o10 endwhile
M2
";
    // The same program written as a Rust loop.
    let mut expect = Vec::new();
    let (mut x, mut y) = (0.0_f64, 0.0_f64);
    for i in 1..=4 {
        let (line, nx, ny) = if i % 2 == 0 {
            (4, i as f64 * 2.5, 1.0)
        } else if i == 3 {
            (13, 0.0, 3.0)
        } else {
            (15, x, -1.0)
        };
        if (nx, ny) != (x, y) {
            expect.push((line, nx, ny));
        }
        (x, y) = (nx, ny);
    }
    let (blocks, warnings) = read(program);
    assert_eq!(ends(&blocks), expect);
    assert!(warnings.is_empty(), "{warnings:?}");
}

#[test]
fn repeat_do_while_break_continue_and_return_values() {
    let program = "\
G0 X0 Y0
F60
o1 repeat [3]
  G91 G1 X1
o1 endrepeat
G90
#5 = 0
o2 do
  #5 = [#5 + 1]
  o3 if [#5 EQ 2]
    o2 continue
  o3 endif
  o4 if [#5 EQ 4]
    o2 break
  o4 endif
  G1 Y#5
o2 while [#5 LT 10]
o<twice> sub
  o<twice> return [#1 * 2]
o<twice> endsub
o<twice> call [21]
G1 X#<_value>
M30
";
    let (blocks, _) = read(program);
    assert_eq!(
        ends(&blocks),
        vec![
            (4, 1.0, 0.0),
            (4, 2.0, 0.0),
            (4, 3.0, 0.0),
            (16, 3.0, 1.0), // #5 = 1
            (16, 3.0, 3.0), // #5 = 2 skipped by continue, 3 drawn, 4 breaks
            (22, 42.0, 3.0),
        ]
    );
}

#[test]
fn assignments_take_effect_after_the_line_and_locals_are_scoped() {
    let program = "\
#1 = 5 G0 X#1 Y0
#<a> = 1
o<s> sub
  #<a> = 7
  G0 Y#<a>
o<s> endsub
o<s> call
G0 X#<a>
M2
";
    let (blocks, _) = read(program);
    // X#1 reads the old #1 (0): no move on line 1; the sub's #<a> is its own.
    assert_eq!(ends(&blocks), vec![(5, 0.0, 7.0), (8, 1.0, 7.0)]);
}

#[test]
fn fanuc_subprograms_after_m30_run_l_times_in_the_callers_scope() {
    let program = "\
%
O0001 (main)
G90 G0 X0 Y0
#100 = 0.5
M98 P2000 L3
G90 G1 X10 F100
M30
O2000 (step)
G91 G1 X#100 F100
#100 = [#100 * 2]
M99
%
";
    let (blocks, warnings) = read(program);
    assert_eq!(
        ends(&blocks),
        vec![(9, 0.5, 0.0), (9, 1.5, 0.0), (9, 3.5, 0.0), (6, 10.0, 0.0)]
    );
    assert!(
        warnings.iter().all(|w| !w.message.contains("ignored")),
        "a subprogram after M30 is not ignored text: {warnings:?}"
    );
}

#[test]
fn g92_family_shifts_the_program_origin() {
    let program = "\
G0 X5 Y5
G92 X0 Y0
G1 X1 Y0 F100
#10 = #5211
G92.2
G1 X1 Y0
G92.3
G1 X2 Y#10
G92.1
G1 X0 Y0
G20 G92 X1
G21 G1 X0
M2
";
    let (blocks, _) = read(program);
    assert_eq!(
        ends(&blocks),
        vec![
            (1, 5.0, 5.0),
            (3, 6.0, 5.0),
            (6, 1.0, 0.0),  // suspended: machine coordinates
            (8, 7.0, 10.0), // restored; #5211 held the X offset, 5
            (10, 0.0, 0.0),
            (12, -25.4, 0.0), // X1 inch at the origin: program 0 is 25.4 mm to the left
        ]
    );
}

#[test]
fn dwell_pause_flushing_and_block_delete() {
    let program = "\
G0 X0 Y0
M8
G4 P1.5
G1 X1 F100
M0
G4 P0.25 G1 X2
M9 M1
/ G1 X9
G1 X3
M2
";
    let (blocks, _) = read(program);
    assert_eq!(
        ends(&blocks),
        vec![(4, 1.0, 0.0), (6, 2.0, 0.0), (8, 9.0, 0.0), (9, 3.0, 0.0)]
    );
    assert_eq!(
        (blocks[0].dwell_s, blocks[0].pause, blocks[0].flushing),
        (1.5, None, true)
    );
    assert_eq!(blocks[1].dwell_s, 0.25);
    assert_eq!(blocks[1].pause, Some((5, Pause::Program)));
    assert_eq!(
        (blocks[2].pause, blocks[2].flushing),
        (None, false),
        "M1 is off by default"
    );

    let options = ProgramOptions {
        block_delete: true,
        optional_stop: true,
        ..ProgramOptions::default()
    };
    let (blocks, _) = read_with(program, options).unwrap();
    assert_eq!(
        ends(&blocks),
        vec![(4, 1.0, 0.0), (6, 2.0, 0.0), (9, 3.0, 0.0)]
    );
    assert_eq!(blocks[2].pause, Some((7, Pause::Optional)));
}

#[test]
fn messages_go_to_the_operator() {
    let (_, warnings) = read("G0 X1 (MSG, thread the wire)\nM2\n");
    assert_eq!(warnings[0].message, "message: thread the wire");
    assert_eq!((warnings[0].line, warnings[0].col), (1, 7));
}

#[test]
fn errors_name_the_line_and_the_calls() {
    assert_eq!(
        error("o<s> call [2]\nM2\no<s> sub\nG1 X[#1 / 0] F1\no<s> endsub\n"),
        "t.ngc:4:9: expression: division by zero (in a subroutine called at line 1)"
    );
    assert_eq!(
        error(
            "o<a> sub\no<b> call\no<a> endsub\no<b> sub\nG1 X#<nope> F1\no<b> endsub\no<a> call\nM2\n"
        ),
        "t.ngc:5:5: parameter #<nope> is not set (in a subroutine called at line 2, from line 7)"
    );
    assert_eq!(
        error("#1 = 0\no7 while [1]\n#1 = [#1 + 1]\no7 endwhile\n"),
        "t.ngc:2:1: the loop O7 at line 2: the program has run 1000000 loop iterations and \
         subroutine calls in all, its budget (program.max_loop_iterations); a runaway loop?"
    );
    assert_eq!(
        error("G0 X1\no1 if [1]\nG0 X2\n"),
        "t.ngc:2:1: O1 if at line 2 is never closed: O1 endif expected"
    );
    assert_eq!(
        error("o<missing> call\nM2\n"),
        "t.ngc:1:1: no subroutine o<missing> in the program (edmd reads subroutines from the program's own file only)"
    );
    assert!(error("G0 X1\nM99\n").starts_with("t.ngc:2:1: M99 outside a subprogram"));
    assert!(error("o1 endif\n").contains("O1 endif: without its if"));
    assert!(
        error("o<r> sub\no<r> call\no<r> endsub\no<r> call\nM2\n")
            .contains("nested deeper than 64")
    );
    assert_eq!(
        error("G1 X#0 F1\n"),
        "t.ngc:1:6: parameter number 0 out of range (1 to 5602)"
    );
    assert_eq!(
        error("G4\n"),
        "t.ngc:1:1: missing coordinate: G4 needs P, the dwell in seconds"
    );
    assert_eq!(
        error("G92\n"),
        "t.ngc:1:1: missing coordinate: G92 needs the axis words that name the current point"
    );
    let options = ProgramOptions {
        max_loop_iterations: 10,
        ..ProgramOptions::default()
    };
    let e = read_with(
        "o1 repeat [11]\nG91 G1 X1 F1\no1 endrepeat\nM2\n",
        options.clone(),
    )
    .unwrap_err();
    assert!(
        e.to_string()
            .starts_with("t.ngc:1:10: the loop O1 at line 1 asks for 11 runs"),
        "{e}"
    );
    let e = read_with("M98 P1 L11\nM30\nO1\nM99\n", options).unwrap_err();
    assert!(
        e.to_string()
            .starts_with("t.ngc:1:8: M98 P1 at line 1 asks for 11 runs"),
        "{e}"
    );
}

/// The budget is the whole program's: loops inside loops, calls and `M98 L` repeats all spend
/// from one count, so two nested loops of a million (10^12 runs) stop at the first million.
#[test]
fn nested_loops_calls_and_m98_spend_one_budget() {
    let options = ProgramOptions {
        max_loop_iterations: 100,
        ..ProgramOptions::default()
    };
    let run = |program: &str| read_with(program, options.clone());
    // 10 x 9 = 90 inner runs + 10 outer = 100: exactly the budget.
    let inner = "o1 repeat [10]\no2 repeat [9]\n#1 = [#1 + 1]\no2 endrepeat\no1 endrepeat\nG1 X#1 F60\nM2\n";
    let (blocks, _) = run(inner).unwrap();
    assert_eq!(blocks[0].end()[0], 90.0);
    // One more inner run is over it, however the runs are split between the loops.
    let over = inner.replace("[9]", "[10]");
    let e = run(&over).unwrap_err().to_string();
    assert!(
        e.contains("the loop O2 at line 2: the program has run 100 loop iterations"),
        "{e}"
    );
    // Calls count: 50 loop runs + 50 calls = 100; a 51st call is over.
    let calls = |n: u32| {
        format!(
            "o<s> sub\n#<_n> = [#<_n> + 1]\no<s> endsub\n#<_n> = 0\no1 repeat [{n}]\no<s> call\no1 endrepeat\nG1 X#<_n> F60\nM2\n"
        )
    };
    assert_eq!(run(&calls(50)).unwrap().0[0].end()[0], 50.0);
    // Without the calls, 51 runs would be far inside the budget.
    let e = run(&calls(51)).unwrap_err().to_string();
    assert!(e.contains("the program has run 100 loop iterations"), "{e}");
    let e = run(&calls(50).replace("o1 repeat [50]", "o1 repeat [49]\no<s> call")).unwrap_err();
    assert!(
        e.to_string().contains("the call of o<s> at line 6"),
        "the call that overspends is named: {e}"
    );
    // M98 L: each run of the subprogram counts.
    let fanuc = |l: u32| {
        format!(
            "o1 repeat [10]\nM98 P7 L{l}\no1 endrepeat\nG1 X#1 F60\nM30\nO7\n#1 = [#1 + 1]\nM99\n"
        )
    };
    assert_eq!(run(&fanuc(9)).unwrap().0[0].end()[0], 90.0);
    let e = run(&fanuc(10)).unwrap_err().to_string();
    assert!(e.contains("the program has run 100 loop iterations"), "{e}");
}

/// The reader gives up at the next line once its cancel flag is set, however long the
/// program runs without producing a block.
#[test]
fn a_cancelled_reader_stops_inside_a_loop_that_moves_nothing() {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    let program = "o1 while [1]\n#1 = [#1 + 1]\no1 endwhile\nM2\n";
    let options = ProgramOptions {
        max_loop_iterations: 1_000_000_000,
        ..ProgramOptions::default()
    };
    let mut reader =
        BlockReader::with_options(Cursor::new(program.as_bytes()), "t.ngc", XY, options);
    let flag = Arc::new(AtomicBool::new(false));
    reader.cancel_on(flag.clone());
    let started = std::time::Instant::now();
    let canceller = std::thread::spawn(move || {
        std::thread::sleep(std::time::Duration::from_millis(100));
        flag.store(true, Ordering::Relaxed);
        std::time::Instant::now()
    });
    let e = reader.next().expect("an item").unwrap_err();
    let cancelled_at = canceller.join().unwrap();
    assert!(e.to_string().contains("cancelled"), "{e}");
    let late = cancelled_at.elapsed();
    assert!(
        late < std::time::Duration::from_millis(100),
        "gave up {late:?} after the cancel"
    );
    assert!(started.elapsed() >= std::time::Duration::from_millis(100));
}

/// Expressions nest at most MAX_NESTING levels; anything deeper is a located error, never a
/// stack overflow. The deepest accepted expression of each kind parses on a thread of
/// PARSER_STACK_BYTES, and a quarter of it: the limit fits the stack with room to spare.
#[test]
fn expression_depth_is_bounded_and_fits_the_parser_stack() {
    use edmd::gcode::{MAX_NESTING, PARSER_STACK_BYTES};
    let n = MAX_NESTING;
    // Each kind at the limit: brackets with an operator at every level (the deepest
    // recursion per level), functions, ATAN's two values, parameter indirection, EXISTS.
    let kinds: Vec<(String, String)> = vec![
        ("brackets", format!("{}1{}", "[1+".repeat(n), "]".repeat(n))),
        (
            "functions",
            format!("{}1{}", "ABS[".repeat(n), "]".repeat(n)),
        ),
        (
            "atan",
            format!("{}1{}", "ATAN[".repeat(n), "]/[1]".repeat(n)),
        ),
        ("indirection", format!("{}1", "#".repeat(n))),
        (
            "signs and brackets",
            format!("{}1{}", "-[-".repeat(n), "]".repeat(n)),
        ),
    ]
    .into_iter()
    .map(|(k, e)| (k.to_string(), e))
    .collect();
    for (kind, expr) in &kinds {
        // Parameter #1 holds 1, so `##…#1` is 1 at any depth.
        let program = format!("#1 = 1\n#2 = {expr}\nG1 X[#2 GT 0] F60\nM2\n");
        for stack in [PARSER_STACK_BYTES, PARSER_STACK_BYTES / 4] {
            let text = program.clone();
            let result = std::thread::Builder::new()
                .stack_size(stack)
                .spawn(move || read_with(&text, ProgramOptions::default()).map(|(b, _)| b.len()))
                .unwrap()
                .join()
                .expect("no overflow");
            assert_eq!(result.unwrap(), 1, "{kind} at depth {n}, stack {stack}");
        }
        // One level more is refused, where the 257th level opens.
        let deeper = match kind.as_str() {
            "brackets" => format!("[1+{expr}]"),
            "functions" => format!("ABS[{expr}]"),
            "atan" => format!("ATAN[{expr}]/[1]"),
            "indirection" => format!("#{expr}"),
            _ => format!("-[-{expr}]"),
        };
        let e = error(&format!("#1 = 1\n#2 = {deeper}\nM2\n"));
        assert!(
            e.contains(&format!("expression nested deeper than {n} levels")),
            "{kind}: {e}"
        );
        assert!(e.starts_with("t.ngc:2:"), "{kind}: {e}");
    }
    // 60,000 signs cost no depth at all.
    let signs = format!("#1 = {}1\nG1 X#1 F60\nM2\n", "-".repeat(60_000));
    assert_eq!(read(&signs).0[0].end()[0], 1.0);
}

/// A loop of a million iterations reads a file of a few lines: the reader seeks back and keeps
/// no lines, so it finishes and holds nothing but its position.
#[test]
fn long_loops_stream_from_a_short_file() {
    let program = "G0 X0 Y0\nF600\n#1 = 0\no1 while [#1 LT 200000]\n#1 = [#1 + 1]\nG1 X[#1 MOD 2]\no1 endwhile\nM2\n";
    let reader = BlockReader::new(Cursor::new(program.as_bytes()), "t.ngc", XY);
    let mut count = 0u64;
    let mut last = 0.0;
    for b in reader {
        let b = b.unwrap();
        assert_eq!(b.line, 6);
        last = b.end()[0];
        count += 1;
    }
    assert_eq!((count, last), (200_000, 0.0));
}

/// As LinuxCNC's `retval.ngc`: a `return` inside an `if` may carry the if's label; it returns
/// from the subroutine that runs, with its value, and the if's state goes with the call.
#[test]
fn return_from_inside_an_if_with_the_ifs_label() {
    let program = "\
o1000 sub
o1010 if [#1 GT 0]
o1010    return [123 * #1]
o1010 endif
o1000 endsub [4712]
F60
o1000 call [0]
G1 X#<_value>
o1000 call [2]
G1 X#<_value>
M2
";
    let (blocks, _) = read(program);
    assert_eq!(ends(&blocks), vec![(8, 4712.0, 0.0), (10, 246.0, 0.0)]);
}

/// `G38.2`…`G38.5` are modal probing moves (as in LinuxCNC), `G31` a one-shot one (as on a
/// Fanuc): straight moves at the programmed feed, to their end points as far as the reader
/// knows; `probed` tells it where the machine stopped, the program goes on from there and
/// `#5061`… (program coordinates) and `#5070` say so.
#[test]
fn probing_moves_and_their_results() {
    use edmd::gcode::{BlockKind, Probe};
    let program = "G1 X1 F10\nG38.2 X3 F5\nY1\nG92 X0\nG31 X2\nY2\n\
                   G1 X[#5061 + 1] Y[#5062 + #5070]\n";
    let mut reader = BlockReader::new(Cursor::new(program.as_bytes()), "t.ngc", XY);
    let mut kinds = Vec::new();
    let mut blocks = Vec::new();
    while let Some(block) = reader.next() {
        let block = block.unwrap_or_else(|e| panic!("{e}"));
        if let BlockKind::Probe(p) = block.kind {
            kinds.push(p);
            if block.line == 5 {
                // The G31 touched 0.5 mm short of its end point (machine X 1.5 + 1.5).
                let mut at = block.end();
                at[0] -= 0.5;
                reader.probed(&at, true);
            }
        }
        blocks.push(block);
    }
    let probe = |away, must_touch| Probe { away, must_touch };
    // G38.2 twice (modal: `Y1` probes too), G31 (G38.3's semantics), then `Y2`: after the
    // one-shot G31 the motion mode is G38.2 again.
    assert_eq!(
        kinds,
        vec![
            probe(false, true),
            probe(false, true),
            probe(false, false),
            probe(false, true)
        ]
    );
    assert_eq!(blocks[1].feed_mm_per_min, Some(5.0));
    assert_eq!(blocks[4].start()[0], 4.5, "from where the probe stopped");
    // G92 X0 at machine X3: the probe stopped at machine 4.5 = program 1.5, #5070 = 1.
    let last = blocks.last().unwrap();
    assert_eq!((last.end()[0], last.end()[1]), (3.0 + 1.5 + 1.0, 1.0 + 1.0));
}

#[test]
fn no_probing_under_a_wire_offset() {
    let options = ProgramOptions {
        d_mm: vec![0.0, 0.1],
        ..ProgramOptions::default()
    };
    let e = read_with("G1 X1 F10\nG41 D1\nG1 X2\nG31 X5\n", options).unwrap_err();
    let text = e.to_string();
    assert!(
        text.starts_with("t.ngc:4:1: G38.3 under a wire offset"),
        "{text}"
    );
}

/// LinuxCNC drops spaces before it reads a line: `else if` is `elseif` (its own probing
/// macros write it so), `end if` is `endif`. Checked against `rs274`: the branch taken is
/// the `elseif`'s.
#[test]
fn spaces_inside_o_word_keywords_count_for_nothing() {
    let program = "#1 = 2\no1 if [#1 EQ 1]\nG1 X1 F60\no1 else if [#1 EQ 2]\nG1 X2 F60\no1 else\nG1 X3 F60\no1 end if\nM2\n";
    let (blocks, _) = read(program);
    assert_eq!(ends(&blocks), vec![(5, 2.0, 0.0)]);
}
