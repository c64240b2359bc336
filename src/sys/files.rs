//! Opening files that someone else may have replaced: a file the daemon reads (its token, a
//! sysfs attribute, a gap script, a program) can be swapped for a FIFO, which an ordinary
//! `open` would wait on for ever (until a writer comes) and a `read` after it too. These
//! open without blocking and refuse anything that is not a regular file, so a FIFO (or a
//! device, or a directory) is an error at once, not a wedged thread.

use std::fs::File;
use std::io;
use std::os::unix::fs::OpenOptionsExt;
use std::path::Path;

/// Opens `path` for reading without waiting on it, and only if it is a regular file (a
/// symbolic link is followed to what it names).
pub fn open_regular(path: &Path) -> io::Result<File> {
    // O_NONBLOCK: opening a FIFO with no writer returns at once instead of waiting. On a
    // regular file the flag changes nothing.
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)?;
    let kind = file.metadata()?.file_type();
    if !kind.is_file() {
        use std::os::unix::fs::FileTypeExt;
        let what = if kind.is_fifo() {
            "a FIFO"
        } else if kind.is_dir() {
            "a directory"
        } else if kind.is_char_device() || kind.is_block_device() {
            "a device"
        } else if kind.is_socket() {
            "a socket"
        } else {
            "not a file"
        };
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{what}, not a regular file"),
        ));
    }
    Ok(file)
}

/// The whole of the regular file at `path`, as text (see [`open_regular`]).
pub fn read_regular(path: &Path) -> io::Result<String> {
    use std::io::Read;
    let mut text = String::new();
    open_regular(path)?.read_to_string(&mut text)?;
    Ok(text)
}

/// Writes `bytes` to `path` atomically: to `PATH.tmp`, synced, renamed over `path`, and the
/// directory synced, so a power cut leaves the old file or the new one, never a torn one. A
/// write that fails removes its temporary file.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    use std::io::Write;
    let tmp = temporary_path(path);
    let written = (|| {
        let mut file = std::fs::File::create(&tmp)?;
        file.write_all(bytes)?;
        file.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = written {
        // A full disk leaves a short temporary file: it is not the file, remove it.
        let _ = std::fs::remove_file(&tmp);
        return Err(e);
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    // Makes the rename itself durable; a directory that cannot be opened (unusual
    // permissions) still has the rename, just not yet on disk.
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

/// Where [`write_atomic`] writes before it renames over `path`.
pub fn temporary_path(path: &Path) -> std::path::PathBuf {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    std::path::PathBuf::from(tmp)
}

/// `bytes` random bytes from the kernel, as lower-case hex (secrets: tokens, passwords).
pub fn random_hex(bytes: usize) -> io::Result<String> {
    use std::io::Read;
    let mut raw = vec![0u8; bytes];
    File::open("/dev/urandom")?.read_exact(&mut raw)?;
    Ok(raw.iter().map(|b| format!("{b:02x}")).collect())
}

/// A secret's file as read: its text, and its permission bits when others than its owner
/// may read it (the reader warns: a secret should be mode 0600).
#[derive(Debug)]
pub struct PrivateText {
    pub text: String,
    pub loose_mode: Option<u32>,
}

/// The secret at `path` (see [`read_regular`]), `None` when there is no file: the half of
/// load-or-create that the HTTP token and the OPC UA users share.
pub fn read_private(path: &Path) -> io::Result<Option<PrivateText>> {
    use std::os::unix::fs::PermissionsExt;
    match read_regular(path) {
        Ok(text) => {
            let loose_mode = std::fs::metadata(path)
                .ok()
                .map(|meta| meta.permissions().mode() & 0o777)
                .filter(|mode| mode & 0o077 != 0);
            Ok(Some(PrivateText { text, loose_mode }))
        }
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(e),
    }
}

/// Writes `text` to a new file at `path` that only its owner may read (mode 0600), and
/// syncs it; an existing file is an error, never overwritten.
pub fn create_private(path: &Path, text: &str) -> io::Result<()> {
    use std::io::Write;
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .open(path)?;
    file.write_all(text.as_bytes())?;
    file.sync_all()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_private_file_is_read_with_its_loose_mode_and_a_missing_one_is_none() {
        use std::os::unix::fs::PermissionsExt;
        let dir = std::env::temp_dir().join(format!("edmd-private-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("secret");
        assert!(read_private(&path).unwrap().is_none());
        create_private(&path, "s3cret\n").unwrap();
        let file = read_private(&path).unwrap().unwrap();
        assert_eq!((file.text.as_str(), file.loose_mode), ("s3cret\n", None));
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o640)).unwrap();
        assert_eq!(
            read_private(&path).unwrap().unwrap().loose_mode,
            Some(0o640)
        );
        assert!(
            read_private(&dir).is_err(),
            "a directory is an error, not a missing file"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_fifo_is_refused_at_once() {
        let dir = std::env::temp_dir().join(format!("edmd-files-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let fifo = dir.join("fifo");
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap();
        assert!(made.success());
        let started = std::time::Instant::now();
        let err = read_regular(&fifo).unwrap_err();
        assert!(started.elapsed() < std::time::Duration::from_secs(1));
        assert_eq!(err.kind(), io::ErrorKind::InvalidInput);
        assert_eq!(err.to_string(), "a FIFO, not a regular file");
        assert!(
            read_regular(&dir)
                .unwrap_err()
                .to_string()
                .contains("directory")
        );
        assert!(
            read_regular(Path::new("/dev/null"))
                .unwrap_err()
                .to_string()
                .contains("device")
        );
        let file = dir.join("token");
        std::fs::write(&file, "abc\n").unwrap();
        assert_eq!(read_regular(&file).unwrap(), "abc\n");
        std::os::unix::fs::symlink(&file, dir.join("link")).unwrap();
        assert_eq!(read_regular(&dir.join("link")).unwrap(), "abc\n");
    }
}
