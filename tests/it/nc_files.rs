//! LinuxCNC's own sample programs against its interpreter: every `.ngc` under Debian's
//! `/usr/share/linuxcnc/ncfiles` (as `linuxcnc-uspace` installs them; or under
//! `EDMD_NCFILES=DIR`, a checkout's `nc_files`) is read by edmd on an X/Y/Z machine and by
//! `rs274 -g` (a mm machine). Every program both read with moves must end each move where
//! rs274 does (1 µm; in a program with `G20`, what four decimals of an inch resolve), and the
//! count of such programs must not fall (a reading that breaks shows as a refusal here).
//! The programs are LinuxCNC's, read where they are installed, never copied here. Without
//! `rs274` the comparison is skipped, unless `EDMD_LCNC_TESTS=1` (CI).

use crate::common;

use std::path::{Path, PathBuf};

use common::linuxcnc::{edmd_ends, linuxcnc_moves, rs274, without_moves_under, worst_apart};

/// Debian's LinuxCNC 2.9 sample programs that both read with moves, all agreeing: measured
/// when this test was written; fewer means edmd reads fewer of them.
const DEBIAN_AGREEING: usize = 11;
const AGREE_MM: f64 = 1e-3;
const AGREE_INCH_MM: f64 = 3.0 * 0.000_05 * 25.4 + 1e-6;

fn programs(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let path = e.path();
        if path.is_dir() {
            programs(&path, out);
        } else if path.extension().is_some_and(|x| x == "ngc") {
            out.push(path);
        }
    }
}

#[test]
fn linuxcncs_sample_programs_that_both_read_end_every_move_where_rs274_does() {
    let Some(rs274) = rs274() else { return };
    let given = std::env::var_os("EDMD_NCFILES").map(PathBuf::from);
    let debian = Path::new("/usr/share/linuxcnc/ncfiles");
    let dir = given.clone().unwrap_or_else(|| debian.to_path_buf());
    let mut all = Vec::new();
    programs(&dir, &mut all);
    all.sort();
    if all.is_empty() {
        assert!(
            std::env::var_os("EDMD_LCNC_TESTS").is_none_or(|v| v != "1"),
            "no programs under {}",
            dir.display()
        );
        return;
    }
    let (mut agreeing, mut moves) = (0, 0);
    let mut apart = Vec::new();
    // Read by one of the two only: shown, not judged here (README lists edmd's refusals).
    let mut only = Vec::new();
    for path in &all {
        let Ok(text) = std::fs::read_to_string(path) else {
            continue; // Not UTF-8: refused by both, each for its own reason.
        };
        let upper = text.to_ascii_uppercase();
        if upper.contains("G38") || upper.contains("G43") {
            // Where a probing program goes depends on where its probe touches (rs274's
            // standalone canon answers a probe its own way: README, "probing"); a tool length
            // offset on where rs274's own tool table puts each tool, which edmd has not.
            continue;
        }
        let (ours, theirs) = match (edmd_ends(&text, 1.0), linuxcnc_moves(&rs274, path)) {
            (Ok(ours), Ok(theirs)) => (ours, theirs),
            (Ok(_), Err(e)) => {
                only.push(format!("edmd only: {}: rs274: {e}", path.display()));
                continue;
            }
            (Err(e), Ok(_)) => {
                only.push(format!("rs274 only: {}: edmd: {e}", path.display()));
                continue;
            }
            (Err(_), Err(_)) => continue,
        };
        if ours.is_empty() && theirs.is_empty() {
            continue; // Definitions only.
        }
        let bound = if upper.contains("G20") {
            AGREE_INCH_MM
        } else {
            AGREE_MM
        };
        let theirs = without_null_moves_after_splines(theirs, &ours);
        let ours = if ours.len() == theirs.len() {
            ours
        } else {
            without_moves_under(ours, bound)
        };
        let worst = worst_apart(&ours, &theirs);
        if ours.len() == theirs.len() && worst <= bound {
            agreeing += 1;
            moves += ours.len();
        } else {
            apart.push(format!(
                "{}: edmd {} moves, rs274 {} (worst {worst:.6} mm)",
                path.display(),
                ours.len(),
                theirs.len()
            ));
        }
    }
    println!(
        "{}: {} programs, {agreeing} read with moves by both agree on {moves} moves",
        dir.display(),
        all.len()
    );
    for o in &only {
        println!("  {o}");
    }
    assert!(apart.is_empty(), "apart from rs274:\n{}", apart.join("\n"));
    if given.is_none() {
        assert!(
            agreeing >= DEBIAN_AGREEING,
            "{agreeing} of Debian's sample programs agree, {DEBIAN_AGREEING} did"
        );
    }
}

/// rs274's moves without a move that goes nowhere from a spline's end: rs274 prints no end
/// for a spline (read as unknown), and edmd makes no block of such a move, so a closed curve
/// followed by a rapid to its start point reads as one move more in rs274's list.
fn without_null_moves_after_splines(theirs: Vec<[f64; 3]>, ours: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let mut kept: Vec<[f64; 3]> = Vec::with_capacity(theirs.len());
    for p in theirs {
        let after_spline = kept.last().is_some_and(|q| q[0].is_nan());
        let spline_end = ours.get(kept.len() - usize::from(after_spline)).copied();
        let nowhere = |q: [f64; 3]| (0..3).all(|i| (q[i] - p[i]).abs() <= 2e-4);
        if after_spline && spline_end.is_some_and(nowhere) {
            continue;
        }
        kept.push(p);
    }
    kept
}
