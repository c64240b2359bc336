//! Replays every saved fuzz input on stable Rust: the seed corpora (`fuzz/seeds/<target>/`)
//! and every input a fuzzing run found to crash (`fuzz/regressions/<target>/`, kept forever).
//! The checks are the fuzz targets' own (`fuzz/checks.rs`), so a crash fixed once stays fixed.

#[path = "../../fuzz/checks.rs"]
mod checks;

use std::path::Path;

fn replay(target: &str, check: fn(&[u8])) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz");
    let mut replayed = 0;
    for kind in ["seeds", "regressions"] {
        let dir = root.join(kind).join(target);
        let mut files: Vec<_> = std::fs::read_dir(&dir)
            .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
            .map(|entry| entry.expect("directory entry").path())
            .filter(|path| path.is_file() && !path.ends_with(".keep"))
            .collect();
        files.sort();
        for path in files {
            let data = std::fs::read(&path).expect("saved input");
            let outcome = std::panic::catch_unwind(|| check(&data));
            assert!(outcome.is_ok(), "{} fails its check again", path.display());
            replayed += 1;
        }
    }
    assert!(replayed > 0, "no saved inputs for {target}");
}

#[test]
fn gcode_inputs_replay() {
    replay("gcode", checks::gcode);
}

#[test]
fn config_inputs_replay() {
    replay("config", checks::config);
}

#[test]
fn protocol_inputs_replay() {
    replay("protocol", checks::protocol);
}
