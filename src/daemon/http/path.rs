//! The programs the page can run (the programmed path it draws of one is
//! [`crate::report::programmed`]'s).

use std::path::{Path, PathBuf};

use serde::Serialize;

/// Programs listed at most, and how deep below the program directory.
const MAX_LISTED: usize = 2000;
const MAX_DEPTH: usize = 3;

/// Why the programs could not be listed.
#[derive(Debug, thiserror::Error)]
pub enum PreviewError {
    #[error("the program directory: {0}")]
    ProgramDir(std::io::Error),
}

#[derive(Debug, Serialize)]
pub struct ProgramEntry {
    pub name: String,
    pub bytes: u64,
}

/// The regular files under `dir` that a `run` can name: four levels deep at most, at most
/// [`MAX_LISTED`], sorted by name. Hidden names, names with control characters, symbolic
/// links that leave `dir` (or dangle) and linked directories are left out: the list never
/// shows what `run` would refuse, and never walks out of the directory.
pub fn list_programs(dir: &Path) -> Result<Vec<ProgramEntry>, PreviewError> {
    let root = dir.canonicalize().map_err(PreviewError::ProgramDir)?;
    let mut out = Vec::new();
    walk(&root, &root, 0, &mut out).map_err(PreviewError::ProgramDir)?;
    out.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(out)
}

fn walk(root: &Path, dir: &Path, depth: usize, out: &mut Vec<ProgramEntry>) -> std::io::Result<()> {
    for entry in std::fs::read_dir(dir)? {
        if out.len() >= MAX_LISTED {
            return Ok(());
        }
        let Ok(entry) = entry else { continue };
        let file_name = entry.file_name();
        let Some(name) = file_name.to_str() else {
            continue;
        };
        if name.starts_with('.') || super::super::names::has_control(name) {
            continue;
        }
        let path = entry.path();
        let Ok(meta) = std::fs::symlink_metadata(&path) else {
            continue;
        };
        if meta.is_dir() {
            if depth < MAX_DEPTH {
                walk(root, &path, depth + 1, out)?;
            }
            continue;
        }
        let target: PathBuf = if meta.file_type().is_symlink() {
            // Followed only to a regular file inside the directory.
            match path.canonicalize() {
                Ok(real) if real.starts_with(root) => real,
                _ => continue,
            }
        } else {
            path.clone()
        };
        let Ok(real) = std::fs::metadata(&target) else {
            continue;
        };
        if real.is_file() {
            let shown = path.strip_prefix(root).unwrap_or(&path);
            out.push(ProgramEntry {
                name: shown.display().to_string(),
                bytes: real.len(),
            });
        }
    }
    Ok(())
}
