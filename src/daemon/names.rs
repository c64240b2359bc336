//! The names clients give (programs, uploads): no control characters, and a program only from
//! inside the program directory.

use std::path::{Component, Path, PathBuf};

use super::refusal::NameRefusal;

/// `text` holds a control character (a newline in a name would forge a log line).
pub fn has_control(text: &str) -> bool {
    text.chars().any(char::is_control)
}

/// Resolves a program a client names inside `program_dir`: no `..` component, and the real
/// path (symlinks followed) must be a regular file below the real program directory. A name
/// that is missing, leaves the directory or is not a file gets one answer, with no path in
/// it, so that a client learns nothing of the machine's other files; the daemon's log says
/// which it was.
pub fn confine(program_dir: &Path, requested: &str) -> Result<PathBuf, NameRefusal> {
    if requested.is_empty() {
        return Err(NameRefusal::Empty);
    }
    if has_control(requested) {
        return Err(NameRefusal::ControlCharacter {
            name: requested.to_string(),
        });
    }
    let refuse = |why: String| {
        tracing::warn!("program {requested:?} refused: {why}");
        NameRefusal::NoSuchProgram {
            name: requested.to_string(),
        }
    };
    let path = Path::new(requested);
    if path.components().any(|c| c == Component::ParentDir) {
        return Err(refuse("`..` in the name".to_string()));
    }
    let dir = program_dir
        .canonicalize()
        .map_err(|source| NameRefusal::ProgramDir {
            dir: program_dir.to_path_buf(),
            source,
        })?;
    let joined = if path.is_absolute() {
        path.to_path_buf()
    } else {
        dir.join(path)
    };
    let real = joined
        .canonicalize()
        .map_err(|e| refuse(format!("{}: {e}", joined.display())))?;
    if !real.starts_with(&dir) {
        return Err(refuse(format!(
            "it resolves to {}, outside {}",
            real.display(),
            dir.display()
        )));
    }
    if !real.is_file() {
        return Err(refuse(format!("{} is not a regular file", real.display())));
    }
    Ok(real)
}
