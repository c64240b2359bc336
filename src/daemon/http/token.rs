//! The bearer token of `daemon.http_token_file`: made once (256 random bits from the kernel,
//! hex, mode 0600), read at every start, compared in constant time.

use std::io::{Read, Write};
use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
use std::path::Path;

/// Why the token file could not be read or made.
#[derive(Debug, thiserror::Error)]
pub enum TokenError {
    #[error("{path}: cannot read the HTTP token: {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}: cannot create the HTTP token: {source}")]
    Create {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}: the HTTP token file is empty; delete it to have a new token made")]
    Empty { path: String },
}

/// The token in `path`; a new one (64 hex digits) written there first when there is none.
pub fn load_or_create(path: &Path) -> Result<String, TokenError> {
    let name = path.display().to_string();
    match std::fs::read_to_string(path) {
        Ok(text) => {
            let token = text.trim().to_string();
            if token.is_empty() {
                return Err(TokenError::Empty { path: name });
            }
            if let Ok(meta) = std::fs::metadata(path)
                && meta.permissions().mode() & 0o077 != 0
            {
                tracing::warn!(
                    "{name}: the HTTP token is readable by others (mode {:o}); chmod 600 it",
                    meta.permissions().mode() & 0o777
                );
            }
            Ok(token)
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => create(path),
        Err(source) => Err(TokenError::Read { path: name, source }),
    }
}

fn create(path: &Path) -> Result<String, TokenError> {
    let fail = |source| TokenError::Create {
        path: path.display().to_string(),
        source,
    };
    let mut bytes = [0u8; 32];
    std::fs::File::open("/dev/urandom")
        .and_then(|mut f| f.read_exact(&mut bytes))
        .map_err(fail)?;
    let token: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .open(path)
        .map_err(fail)?;
    file.write_all(format!("{token}\n").as_bytes())
        .and_then(|()| file.sync_all())
        .map_err(fail)?;
    tracing::info!("{}: a new HTTP token was made (mode 0600)", path.display());
    Ok(token)
}

/// `a == b`, in time that depends on the lengths only.
pub fn same(a: &[u8], b: &[u8]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_token_is_made_private_and_then_kept() {
        let dir = std::env::temp_dir().join(format!("edmd-token-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("token");
        let made = load_or_create(&path).unwrap();
        assert_eq!(made.len(), 64);
        assert!(made.bytes().all(|b| b.is_ascii_hexdigit()));
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600);
        assert_eq!(load_or_create(&path).unwrap(), made);
        let other = dir.join("other");
        assert_ne!(load_or_create(&other).unwrap(), made, "random, not fixed");
        std::fs::write(&path, "\n").unwrap();
        assert!(matches!(
            load_or_create(&path),
            Err(TokenError::Empty { .. })
        ));
    }

    #[test]
    fn comparison() {
        assert!(same(b"abc", b"abc"));
        assert!(!same(b"abc", b"abd"));
        assert!(!same(b"abc", b"ab"));
        assert!(!same(b"", b"a"));
    }
}
