//! Helpers shared by the integration tests.

pub mod daemon;
pub mod web;

use std::path::PathBuf;

/// The repository root (where `edmd` runs in the tests).
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A scratch directory for one test of one test binary, kept apart by process id.
pub fn scratch(suite: &str, name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("edmd-{suite}-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}
