//! LinuxCNC's interpreter as a reference: `rs274 -g` (Debian's `linuxcnc-uspace`) run on a
//! program, its canonical calls read back as machine end points. Without `rs274` on the
//! machine the comparisons are skipped, unless `EDMD_LCNC_TESTS=1` (CI) says they must run.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;

/// rs274 prints four decimals; three rounded figures add up to at most 1.5e-4 mm.
pub const TOLERANCE_MM: f64 = 2e-4;

pub fn rs274() -> Option<PathBuf> {
    let found = std::env::var_os("EDMD_RS274")
        .map(PathBuf::from)
        .or_else(|| {
            let p = PathBuf::from("/usr/bin/rs274");
            p.exists().then_some(p)
        });
    if found.is_none() {
        assert!(
            std::env::var_os("EDMD_LCNC_TESTS").is_none_or(|v| v != "1"),
            "EDMD_LCNC_TESTS=1 but rs274 is not installed (apt-get install linuxcnc-uspace)"
        );
        eprintln!("rs274 not found: the comparison with LinuxCNC is skipped");
    }
    static MM: OnceLock<PathBuf> = OnceLock::new();
    found.map(|p| MM.get_or_init(|| mm_machine(&p)).clone())
}

/// A copy of `rs274` that reads programs as a mm machine does.
///
/// Debian's standalone `rs274` (2.9.0~pre1) answers `GET_EXTERNAL_LENGTH_UNITS` with inches,
/// so the interpreter keeps its parameters and tool data in inches: `#5221` reads 0.3937
/// after `G10 L2 P1 X10` in a mm program, and `G0 X[#5221]` goes 0.3937 mm. Newer LinuxCNC
/// reads `[TRAJ] LINEAR_UNITS` for that; this build does not, so the copy's function returns
/// 1.0 (mm) instead: `movabs rax, 1.0; movq xmm0, rax; ret`, 16 bytes, patched only where the
/// function is the known 9-byte constant load, in a private copy under the test target dir.
fn mm_machine(rs274: &Path) -> PathBuf {
    const SYMBOL: &[u8] = b"_Z25GET_EXTERNAL_LENGTH_UNITSv";
    let mut image = std::fs::read(rs274).expect("rs274 reads");
    let at = elf_symbol_offset(&image, SYMBOL).expect("rs274 exports GET_EXTERNAL_LENGTH_UNITS");
    let code = &image[at..at + 16];
    // `movsd xmm0, [rip + …]; ret`, then padding up to the next 16-byte function.
    assert!(
        code.starts_with(&[0xf2, 0x0f, 0x10, 0x05]) && code[8] == 0xc3 && at.is_multiple_of(16),
        "rs274's GET_EXTERNAL_LENGTH_UNITS is not the constant load this patch knows: {code:02x?}"
    );
    let mut patch = vec![0x48, 0xb8];
    patch.extend_from_slice(&1.0f64.to_le_bytes());
    patch.extend_from_slice(&[0x66, 0x48, 0x0f, 0x6e, 0xc0, 0xc3]);
    image[at..at + 16].copy_from_slice(&patch);
    let dir =
        Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rs274-mm-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let out = dir.join("rs274");
    std::fs::write(&out, &image).expect("patched rs274 writes");
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&out, std::fs::Permissions::from_mode(0o755)).expect("chmod");
    out
}

/// The file offset of the dynamic symbol `name` in the ELF64 little-endian `image`.
fn elf_symbol_offset(image: &[u8], name: &[u8]) -> Option<usize> {
    let u16_at = |o: usize| u16::from_le_bytes(image[o..o + 2].try_into().unwrap()) as usize;
    let u32_at = |o: usize| u32::from_le_bytes(image[o..o + 4].try_into().unwrap()) as usize;
    let u64_at = |o: usize| u64::from_le_bytes(image[o..o + 8].try_into().unwrap()) as usize;
    let (shoff, shentsize, shnum) = (u64_at(0x28), u16_at(0x3a), u16_at(0x3c));
    let section = |i: usize| shoff + i * shentsize;
    let dynsym = (0..shnum).map(section).find(|&s| u32_at(s + 4) == 11)?;
    let strtab = u64_at(section(u32_at(dynsym + 0x28)) + 0x18);
    let (symoff, symsize) = (u64_at(dynsym + 0x18), u64_at(dynsym + 0x20));
    let vaddr = (0..symsize / 24).map(|k| symoff + 24 * k).find_map(|sym| {
        let start = strtab + u32_at(sym);
        let end = start + image[start..].iter().position(|&b| b == 0)?;
        (&image[start..end] == name).then(|| u64_at(sym + 8))
    })?;
    let (phoff, phentsize, phnum) = (u64_at(0x20), u16_at(0x36), u16_at(0x38));
    (0..phnum).map(|i| phoff + i * phentsize).find_map(|ph| {
        let (offset, va, size) = (u64_at(ph + 8), u64_at(ph + 0x10), u64_at(ph + 0x20));
        (u32_at(ph) == 1 && (va..va + size).contains(&vaddr)).then(|| vaddr - va + offset)
    })
}

/// The numbers inside `NAME(…)` on an rs274 output line.
pub fn call_args(line: &str, name: &str) -> Option<Vec<f64>> {
    let at = line.find(&format!("{name}("))?;
    let inner = &line[at + name.len() + 1..line.rfind(')')?];
    Some(
        inner
            .split(',')
            .filter_map(|s| s.trim().parse::<f64>().ok())
            .collect(),
    )
}

/// What rs274 makes of `program`: the machine end point (X Y Z, mm) of every move, or its
/// error message.
pub fn linuxcnc_moves(rs274: &Path, program: &Path) -> Result<Vec<[f64; 3]>, String> {
    // Two rs274 processes at once disturb each other (seen: one prints nothing), so the
    // tests take turns: by a file lock, because a test runner may run each test in a process
    // of its own (cargo nextest does), where a mutex would not be shared.
    let turn = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(std::env::temp_dir().join("edmd-tests-rs274.lock"))
        .expect("the rs274 lock file opens");
    turn.lock().expect("rs274's turn");
    let out = Command::new(rs274)
        .arg("-g")
        .arg(program)
        .stdin(Stdio::null())
        .output()
        .expect("rs274 runs");
    let text =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    let mut scale = 1.0;
    let mut g5x = [0.0; 3];
    let mut g92 = [0.0; 3];
    let mut moves: Vec<[f64; 3]> = Vec::new();
    let mut plane = 0;
    // A full circle ends where it starts and still moves.
    let mut arcs = std::collections::HashSet::new();
    for line in text.lines() {
        if line.contains("USE_LENGTH_UNITS(CANON_UNITS_INCHES)") {
            scale = 25.4;
        } else if line.contains("USE_LENGTH_UNITS(CANON_UNITS_MM)") {
            scale = 1.0;
        } else if let Some(a) = call_args(line, "SET_G5X_OFFSET") {
            g5x = [a[1] * scale, a[2] * scale, a[3] * scale];
        } else if let Some(a) = call_args(line, "SET_G92_OFFSET") {
            g92 = [a[0] * scale, a[1] * scale, a[2] * scale];
        } else if let Some(a) =
            call_args(line, "STRAIGHT_FEED").or_else(|| call_args(line, "STRAIGHT_TRAVERSE"))
        {
            moves.push(std::array::from_fn(|i| a[i] * scale + g5x[i] + g92[i]));
        } else if line.contains("SELECT_PLANE(CANON_PLANE_") {
            plane = ["XY", "XZ", "YZ"]
                .iter()
                .position(|p| line.contains(&format!("CANON_PLANE_{p})")))
                .unwrap_or(0);
        } else if let Some(a) = call_args(line, "ARC_FEED") {
            // First end, second end, centre, centre, turns, third axis end: the plane's
            // axes in its own order (XY: X Y Z; XZ: Z X Y; YZ: Y Z X).
            let p = match plane {
                0 => [a[0], a[1], a[5]],
                1 => [a[1], a[5], a[0]],
                _ => [a[5], a[0], a[1]],
            };
            moves.push(std::array::from_fn(|i| p[i] * scale + g5x[i] + g92[i]));
            arcs.insert(moves.len() - 1);
        } else if line.contains("NURBS_FEED(") {
            // rs274 prints no end point for a spline: compared as unknown.
            moves.push([f64::NAN; 3]);
        } else if !line.trim().is_empty() && !is_canon_call(line) && line != "executing" {
            return Err(line.trim().to_string());
        }
    }
    // edmd makes no block of a move that goes nowhere.
    let mut from = [0.0; 3];
    let mut index = 0;
    // After a spline, whose end is unknown, the next move is kept whatever its end.
    let mut after_unknown = false;
    moves.retain(|p| {
        index += 1;
        if p[0].is_nan() {
            after_unknown = true;
            return true;
        }
        if std::mem::take(&mut after_unknown) || arcs.contains(&(index - 1)) {
            from = *p;
            return true;
        }
        let moved = p
            .iter()
            .zip(&from)
            .any(|(a, b)| (a - b).abs() > TOLERANCE_MM);
        from = *p;
        moved
    });
    Ok(moves)
}

/// The largest difference on any axis between two readings' end points, move for move (a
/// spline's end, which rs274 does not print, left out).
pub fn worst_apart(ours: &[[f64; 3]], theirs: &[[f64; 3]]) -> f64 {
    ours.iter()
        .zip(theirs)
        .filter(|(_, b)| !b[0].is_nan())
        .map(|(a, b)| (0..3).map(|i| (a[i] - b[i]).abs()).fold(0.0, f64::max))
        .fold(0.0, f64::max)
}

/// A canonical call rs274 prints (`  16 N..... NAME(…)`, or `N0080` where the program numbers
/// its lines), not an error message.
fn is_canon_call(line: &str) -> bool {
    let mut words = line.split_whitespace();
    words
        .next()
        .is_some_and(|n| n.bytes().all(|b| b.is_ascii_digit()))
        && words.next().is_some_and(|n| n.starts_with('N'))
}

/// The end points (X Y Z, mm) of the blocks edmd reads, or the first error's message.
pub fn end_points<R: std::io::BufRead + std::io::Seek>(
    reader: edmd::gcode::BlockReader<R>,
) -> Result<Vec<[f64; 3]>, String> {
    super::program_path(reader)
        .map(|b| {
            b.map(|b| {
                let e = b.end();
                [e[0], e[1], e[2]]
            })
            .map_err(|e| e.to_string())
        })
        .collect()
}

/// `ends` without the moves shorter than `bound` on every axis (but longer than nothing):
/// rs274 prints four decimals, so a move of less than that prints as no move and is left out
/// of its reading; edmd's 0.76 µm move of `G53 G1 Z-0.0394` (inch) after `Z-1` (mm) is real.
/// A move that ends exactly where it starts (a full circle) is kept.
pub fn without_moves_under(ends: Vec<[f64; 3]>, bound: f64) -> Vec<[f64; 3]> {
    let mut from = [0.0; 3];
    ends.into_iter()
        .filter(|p| {
            let d = (0..3).map(|i| (p[i] - from[i]).abs()).fold(0.0, f64::max);
            let keep = d == 0.0 || d > bound;
            if keep {
                from = *p;
            }
            keep
        })
        .collect()
}

/// edmd's reading of `text` on an X/Y/Z machine with `D1` = `d1_mm`: the end points of its
/// blocks, or the first error's message.
pub fn edmd_ends(text: &str, d1_mm: f64) -> Result<Vec<[f64; 3]>, String> {
    let options = edmd::gcode::ProgramOptions {
        d_mm: vec![0.0, d1_mm],
        ..edmd::gcode::ProgramOptions::default()
    };
    let axes = [
        edmd::vocab::Axis::X,
        edmd::vocab::Axis::Y,
        edmd::vocab::Axis::Z,
    ];
    end_points(edmd::gcode::BlockReader::with_options(
        std::io::Cursor::new(text.as_bytes()),
        "p.ngc",
        &axes,
        options,
    ))
}
