//! The OPC UA users of `daemon.opcua_users_file`: who may call Hold and Abort.
//!
//! One `name:password` per line (blank lines and `#` comments skipped), mode 0600, like the
//! HTTP token: made once when missing (one user, `operator`, with 128 random bits as hex),
//! read at every start and on SIGHUP. A password written by hand needs at least
//! [`MIN_PASSWORD_CHARS`] characters. Passwords are compared in constant time, and every
//! user is compared, so the answer's timing tells neither which names exist nor how much of a
//! password was right.

use std::path::Path;

/// Fewest characters a password may have.
pub const MIN_PASSWORD_CHARS: usize = 16;

/// Why the users file could not be read or made, or what is wrong in it.
#[derive(Debug, thiserror::Error)]
pub enum UsersError {
    #[error("{path}: cannot read the OPC UA users (daemon.opcua_users_file): {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}: cannot create the OPC UA users file: {source}")]
    Create {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}:{line}:{col}: {what}")]
    Bad {
        path: String,
        line: usize,
        col: usize,
        what: String,
    },
    #[error(
        "{path}: names no user; write one `name:password` per line, or delete the file to have \
         one made"
    )]
    Empty { path: String },
}

/// The users and their passwords.
#[derive(Clone, PartialEq, Eq)]
pub struct Users(Vec<(String, String)>);

impl std::fmt::Debug for Users {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list()
            .entries(self.0.iter().map(|(name, _)| name))
            .finish()
    }
}

impl Users {
    /// Whether `name` is a user and `password` is theirs.
    pub fn check(&self, name: &str, password: &str) -> bool {
        let mut found = false;
        for (n, p) in &self.0 {
            let same_name = crate::daemon::http::token::same(n.as_bytes(), name.as_bytes());
            let same_password = crate::daemon::http::token::same(p.as_bytes(), password.as_bytes());
            found |= same_name & same_password;
        }
        found
    }

    pub fn len(&self) -> usize {
        self.0.len()
    }

    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}

/// The users in `path`; a new file with one user, `operator`, written there first when there
/// is none.
pub fn load_or_create(path: &Path) -> Result<Users, UsersError> {
    let name = path.display().to_string();
    match crate::sys::read_private(path) {
        Ok(Some(file)) => {
            let users = parse(&name, &file.text)?;
            if let Some(mode) = file.loose_mode {
                tracing::warn!(
                    "{name}: the OPC UA passwords are readable by others (mode {mode:o}); chmod 600 it"
                );
            }
            Ok(users)
        }
        Ok(None) => create(path),
        Err(source) => Err(UsersError::Read { path: name, source }),
    }
}

fn parse(path: &str, text: &str) -> Result<Users, UsersError> {
    let mut users: Vec<(String, String)> = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let bad = |col: usize, what: String| UsersError::Bad {
            path: path.to_string(),
            line: i + 1,
            col,
            what,
        };
        let indent = raw.len() - raw.trim_start().len();
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let Some((name, password)) = line.split_once(':') else {
            return Err(bad(indent + 1, "expected `name:password`".into()));
        };
        if name.is_empty()
            || !name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || "._-".contains(c))
        {
            return Err(bad(
                indent + 1,
                format!("{name:?} is not a user name (letters, digits, `.`, `_` and `-`)"),
            ));
        }
        let col = indent + name.len() + 2;
        if let Some(c) = password.chars().find(|c| c.is_control()) {
            return Err(bad(col, format!("the password holds {c:?}")));
        }
        let chars = password.chars().count();
        if chars < MIN_PASSWORD_CHARS {
            return Err(bad(
                col,
                format!(
                    "the password of {name:?} is {chars} characters; a password needs at least \
                     {MIN_PASSWORD_CHARS}"
                ),
            ));
        }
        if users.iter().any(|(n, _)| n == name) {
            return Err(bad(indent + 1, format!("{name:?} is named twice")));
        }
        users.push((name.to_string(), password.to_string()));
    }
    if users.is_empty() {
        return Err(UsersError::Empty {
            path: path.to_string(),
        });
    }
    Ok(Users(users))
}

fn create(path: &Path) -> Result<Users, UsersError> {
    let fail = |source| UsersError::Create {
        path: path.display().to_string(),
        source,
    };
    let password = crate::sys::random_hex(16).map_err(fail)?;
    let text = format!(
        "# OPC UA users allowed to call Hold and Abort: one `name:password` per line.\n\
         operator:{password}\n"
    );
    // Its directory too (a state directory not made yet): a missing one is not a reason for
    // the server not to start.
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(fail)?;
    }
    crate::sys::create_private(path, &text).map_err(fail)?;
    tracing::info!(
        "{}: OPC UA user `operator` made with a random password (mode 0600)",
        path.display()
    );
    Ok(Users(vec![("operator".to_string(), password)]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    #[test]
    fn a_missing_file_is_made_private_with_one_operator() {
        let dir = std::env::temp_dir().join(format!("edmd-opcua-users-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        // Its directory is made as well.
        let path = dir.join("state/users");
        let made = load_or_create(&path).unwrap();
        assert_eq!(made.len(), 1);
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600);
        let text = std::fs::read_to_string(&path).unwrap();
        let password = text
            .lines()
            .find_map(|l| l.strip_prefix("operator:"))
            .unwrap();
        assert_eq!(password.len(), 32);
        assert!(made.check("operator", password));
        assert!(!made.check("operator", "0123456789abcdef0123456789abcdef"));
        assert_eq!(load_or_create(&path).unwrap(), made, "kept, not made again");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn lines_are_checked_with_their_place() {
        let users = parse(
            "u",
            "# shop\n\nalice:correct horse battery\n  bob-2:0123456789abcdef\n",
        )
        .unwrap();
        assert_eq!(users.len(), 2);
        assert!(users.check("alice", "correct horse battery"));
        assert!(users.check("bob-2", "0123456789abcdef"));
        assert!(!users.check("alice", "0123456789abcdef"), "not another's");
        assert!(!users.check("carol", "correct horse battery"));
        assert!(!users.check("alice", ""));
        for (text, error) in [
            ("alice\n", "u:1:1: expected `name:password`"),
            (
                "\n  al ice:0123456789abcdef\n",
                "u:2:3: \"al ice\" is not a user name",
            ),
            (
                "alice:short\n",
                "u:1:7: the password of \"alice\" is 5 characters",
            ),
            (
                "a:0123456789abcdef\na:0123456789abcdef\n",
                "u:2:1: \"a\" is named twice",
            ),
            ("# only a comment\n", "u: names no user"),
        ] {
            let e = parse("u", text).unwrap_err().to_string();
            assert!(e.starts_with(error), "{text:?}: {e}");
        }
    }
}
