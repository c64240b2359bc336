//! LinuxCNC's interpreter as a reference: `rs274 -g` (Debian's `linuxcnc-uspace`) run on a
//! program, its canonical calls read back as machine end points. Without `rs274` on the
//! machine the comparisons are skipped, unless `EDMD_LCNC_TESTS=1` (CI) says they must run.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Mutex;

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
    found
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
    // tests take turns.
    static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());
    let _turn = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
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
        } else if let Some(a) = call_args(line, "ARC_FEED") {
            // XY plane: first end, second end, centre, centre, turn, Z end.
            let p = [a[0], a[1], a[5]];
            moves.push(std::array::from_fn(|i| p[i] * scale + g5x[i] + g92[i]));
        } else if !line.trim().is_empty()
            && !line.contains("N.....")
            && !line.starts_with("executing")
        {
            return Err(line.trim().to_string());
        }
    }
    // edmd makes no block of a move that goes nowhere.
    let mut from = [0.0; 3];
    moves.retain(|p| {
        let moved = p
            .iter()
            .zip(&from)
            .any(|(a, b)| (a - b).abs() > TOLERANCE_MM);
        from = *p;
        moved
    });
    Ok(moves)
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
