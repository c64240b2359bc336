//! The bearer token of `daemon.http_token_file`: made once (256 random bits from the kernel,
//! hex, mode 0600), read at every start and on SIGHUP, compared in constant time.
//!
//! A token an operator wrote must be worth guessing against: at least [`MIN_TOKEN_CHARS`]
//! characters (128 bits as hex) of the RFC 6750 token alphabet, or the daemon refuses it.
//! The file must be a regular file: a FIFO put in its place is an error, not a daemon
//! waiting for a writer.

use std::path::Path;

/// Fewest characters a token may have: 128 bits written as hex.
pub const MIN_TOKEN_CHARS: usize = 32;

/// Why the token file could not be read or made, or what is wrong with the token in it.
#[derive(Debug, thiserror::Error)]
pub enum TokenError {
    #[error("{path}: cannot read the HTTP token (daemon.http_token_file): {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}: cannot create the HTTP token: {source}")]
    Create {
        path: String,
        source: std::io::Error,
    },
    #[error(
        "{path}: the HTTP token is {chars} characters; a token needs at least {MIN_TOKEN_CHARS} \
         (128 bits as hex). Delete the file to have a new one made, or write a longer one"
    )]
    TooShort { path: String, chars: usize },
    #[error(
        "{path}: the HTTP token holds {found:?}; a token is letters, digits and - . _ ~ + / \
         (RFC 6750), on one line"
    )]
    BadCharacter { path: String, found: char },
}

/// The token in `path`; a new one (64 hex digits) written there first when there is none.
pub fn load_or_create(path: &Path) -> Result<String, TokenError> {
    let name = path.display().to_string();
    match crate::sys::read_private(path) {
        Ok(Some(file)) => {
            let token = validate(&name, file.text.trim())?;
            if let Some(mode) = file.loose_mode {
                tracing::warn!(
                    "{name}: the HTTP token is readable by others (mode {mode:o}); chmod 600 it"
                );
            }
            Ok(token)
        }
        Ok(None) => create(path),
        Err(source) => Err(TokenError::Read { path: name, source }),
    }
}

/// The token if it is long enough and of the token alphabet.
fn validate(path: &str, token: &str) -> Result<String, TokenError> {
    if let Some(found) = token
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || "-._~+/=".contains(*c)))
    {
        return Err(TokenError::BadCharacter {
            path: path.to_string(),
            found,
        });
    }
    let chars = token.chars().count();
    if chars < MIN_TOKEN_CHARS {
        return Err(TokenError::TooShort {
            path: path.to_string(),
            chars,
        });
    }
    Ok(token.to_string())
}

fn create(path: &Path) -> Result<String, TokenError> {
    let fail = |source| TokenError::Create {
        path: path.display().to_string(),
        source,
    };
    let token = crate::sys::random_hex(32).map_err(fail)?;
    crate::sys::create_private(path, &format!("{token}\n")).map_err(fail)?;
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
    use std::os::unix::fs::PermissionsExt;

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

        // Written by hand: too short, or not a token, is refused.
        for (text, why) in [
            ("\n", "is 0 characters"),
            ("abc\n", "is 3 characters"),
            ("0123456789abcdef0123456789abcde\n", "is 31 characters"),
            ("0123456789abcdef 0123456789abcdef\n", "holds ' '"),
        ] {
            std::fs::write(&path, text).unwrap();
            let e = load_or_create(&path).unwrap_err().to_string();
            assert!(e.contains(why), "{text:?}: {e}");
        }
        std::fs::write(&path, "0123456789abcdef0123456789abcdef\n").unwrap();
        assert_eq!(load_or_create(&path).unwrap().len(), 32);

        // A FIFO in its place is an error at once.
        std::fs::remove_file(&path).unwrap();
        let made = std::process::Command::new("mkfifo")
            .arg(&path)
            .status()
            .unwrap();
        assert!(made.success());
        let e = load_or_create(&path).unwrap_err().to_string();
        assert!(e.contains("a FIFO, not a regular file"), "{e}");
    }

    #[test]
    fn comparison() {
        assert!(same(b"abc", b"abc"));
        assert!(!same(b"abc", b"abd"));
        assert!(!same(b"abc", b"ab"));
        assert!(!same(b"", b"a"));
    }
}
