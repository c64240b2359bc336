//! A job's program: a private, immutable copy of the file the operator named.
//!
//! A controller must execute exactly what it checked. Reading the operator's file twice (once
//! to check it, once to run it) lets an edit in between, or during the run, move the machine
//! along a path nothing validated. So a job first copies its program: streamed in fixed-size
//! chunks (memory stays flat whatever the file's size), hashed (SHA-256) in the same pass,
//! synced to disk and made read-only. The check and the producer read only the copy; errors
//! still name the operator's file, so `file:line:col` points where the operator can look.
//!
//! The copy is named by its hash (`<sha256>.nc`) in the daemon's state directory, so a
//! checkpoint that names the hash finds the very bytes it was cut from, however the original
//! changes afterwards. `edmd run` copies into the temporary directory and removes the copy
//! when the job ends ([`TempCopy`]).
//!
//! Copying reports its progress and can be cancelled ([`Progress`]); so can the check that
//! follows, which counts the bytes it has read.

use std::fs::File;
use std::io::{Read, Write};
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, Ordering};

use sha2::{Digest, Sha256};

/// Bytes copied per read: large enough for disk throughput, small enough for flat memory.
const CHUNK: usize = 256 * 1024;

/// The program a job runs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct JobProgram {
    /// The file the job reads: the private copy.
    pub path: PathBuf,
    /// The program as the operator named it (errors, status and logs use this).
    pub name: String,
    /// SHA-256 of the bytes (hex).
    pub sha256: String,
    pub bytes: u64,
}

impl JobProgram {
    /// A program read in place, not copied (tests and benches over files nobody edits).
    pub fn in_place(path: &Path) -> std::io::Result<JobProgram> {
        Ok(JobProgram {
            path: path.to_path_buf(),
            name: path.display().to_string(),
            sha256: sha256_file(path)?,
            bytes: std::fs::metadata(path)?.len(),
        })
    }
}

/// What a check before a job is doing, shared with whoever reports it (status, `edmd ctl`).
#[derive(Debug, Default)]
pub struct Progress {
    phase: AtomicU8,
    done: AtomicU64,
    total: AtomicU64,
    /// Shared with the program reader of the check, which looks at it on every line.
    cancel: Arc<AtomicBool>,
}

/// The phases of a check.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// Copying the program (bytes copied of its size).
    Copying,
    /// Parsing the copy and checking every end point (bytes read of its size).
    Checking,
}

impl Phase {
    pub fn name(self) -> &'static str {
        match self {
            Phase::Copying => "copying",
            Phase::Checking => "checking",
        }
    }
}

impl Progress {
    pub fn new() -> Progress {
        Progress::default()
    }

    /// Current phase, bytes done and bytes in all.
    pub fn get(&self) -> (Phase, u64, u64) {
        let phase = if self.phase.load(Ordering::Relaxed) == 0 {
            Phase::Copying
        } else {
            Phase::Checking
        };
        (
            phase,
            self.done.load(Ordering::Relaxed),
            self.total.load(Ordering::Relaxed),
        )
    }

    pub fn start(&self, phase: Phase, total: u64) {
        self.phase
            .store(u8::from(phase == Phase::Checking), Ordering::Relaxed);
        self.total.store(total, Ordering::Relaxed);
        self.done.store(0, Ordering::Relaxed);
    }

    fn advance_to(&self, done: u64) {
        self.done.store(done, Ordering::Relaxed);
    }

    /// Asks the copy or the check to give up (abort, shutdown).
    pub fn cancel(&self) {
        self.cancel.store(true, Ordering::Relaxed);
    }

    pub fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }

    /// The cancel flag, for a program reader to look at ([`crate::gcode::BlockReader::cancel_on`]).
    pub fn cancel_flag(&self) -> Arc<AtomicBool> {
        self.cancel.clone()
    }
}

/// Why a program could not be copied.
#[derive(Debug, thiserror::Error)]
pub enum CopyError {
    #[error("{program}: cannot read the program: {source}")]
    Read {
        program: String,
        source: std::io::Error,
    },
    #[error("{dir}: cannot keep a copy of the program there: {source}")]
    Write {
        dir: PathBuf,
        source: std::io::Error,
    },
    #[error("{program}: cancelled while copying")]
    Cancelled { program: String },
}

/// Copies `original` into `dir` as `<sha256>.nc` (read-only, synced), streaming and hashing
/// in one pass. A copy with that name already there holds the same bytes and is kept. A
/// program is a regular file: a FIFO in its place (swapped in after the daemon confined the
/// name) is refused at once rather than waited on for ever.
pub fn copy_program(
    original: &Path,
    dir: &Path,
    progress: &Progress,
) -> Result<JobProgram, CopyError> {
    let name = original.display().to_string();
    let read_error = |source| CopyError::Read {
        program: name.clone(),
        source,
    };
    let write_error = |source| CopyError::Write {
        dir: dir.to_path_buf(),
        source,
    };
    let mut source = crate::sys::open_regular(original).map_err(read_error)?;
    let size = source.metadata().map_err(read_error)?.len();
    progress.start(Phase::Copying, size);
    std::fs::create_dir_all(dir).map_err(write_error)?;
    let incoming = dir.join(format!(".incoming-{}.nc", std::process::id()));
    let mut copy = File::create(&incoming).map_err(write_error)?;
    let hashed = hash_stream(&mut source, &mut copy, Some(progress));
    let (sha256, bytes) = match hashed {
        Ok(h) => h,
        Err(e) => {
            let _ = std::fs::remove_file(&incoming);
            return Err(match e {
                StreamError::Cancelled => CopyError::Cancelled { program: name },
                StreamError::Write(e) => write_error(e),
                StreamError::Read(e) => read_error(e),
            });
        }
    };
    let finished = copy
        .sync_all()
        .and_then(|()| {
            let mut perms = copy.metadata()?.permissions();
            perms.set_mode(0o444);
            copy.set_permissions(perms)
        })
        .and_then(|()| std::fs::rename(&incoming, dir.join(format!("{sha256}.nc"))));
    if let Err(e) = finished {
        let _ = std::fs::remove_file(&incoming);
        return Err(write_error(e));
    }
    Ok(JobProgram {
        path: copy_path(dir, &sha256),
        name,
        sha256,
        bytes,
    })
}

/// Where [`copy_program`] keeps the copy of the program with this hash.
pub fn copy_path(dir: &Path, sha256: &str) -> PathBuf {
    dir.join(format!("{sha256}.nc"))
}

enum StreamError {
    Read(std::io::Error),
    Write(std::io::Error),
    Cancelled,
}

/// Reads `from` to its end into `to`, hashing; reports progress and honours its cancel flag.
fn hash_stream(
    from: &mut impl Read,
    to: &mut impl Write,
    progress: Option<&Progress>,
) -> Result<(String, u64), StreamError> {
    let mut hasher = Sha256::new();
    let mut chunk = vec![0u8; CHUNK];
    let mut bytes = 0u64;
    loop {
        if progress.is_some_and(Progress::cancelled) {
            return Err(StreamError::Cancelled);
        }
        let n = match from.read(&mut chunk) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(StreamError::Read(e)),
        };
        hasher.update(&chunk[..n]);
        to.write_all(&chunk[..n]).map_err(StreamError::Write)?;
        bytes += n as u64;
        if let Some(p) = progress {
            p.advance_to(bytes);
        }
    }
    Ok((hex(&hasher.finalize()), bytes))
}

/// SHA-256 of a file, streamed (hex): memory stays flat whatever its size.
pub fn sha256_file(path: &Path) -> std::io::Result<String> {
    let mut file = File::open(path)?;
    match hash_stream(&mut file, &mut std::io::sink(), None) {
        Ok((sha256, _)) => Ok(sha256),
        Err(StreamError::Read(e) | StreamError::Write(e)) => Err(e),
        Err(StreamError::Cancelled) => Err(std::io::Error::other("cancelled")),
    }
}

fn hex(bytes: &[u8]) -> String {
    use std::fmt::Write;
    bytes.iter().fold(String::new(), |mut s, b| {
        let _ = write!(s, "{b:02x}");
        s
    })
}

/// A reader that counts what passes through it into a [`Progress`] (the check's).
pub struct CountingReader<'a, R> {
    inner: R,
    read: u64,
    progress: &'a Progress,
}

impl<'a, R: Read> CountingReader<'a, R> {
    pub fn new(inner: R, progress: &'a Progress) -> Self {
        CountingReader {
            inner,
            read: 0,
            progress,
        }
    }
}

impl<R: Read> Read for CountingReader<'_, R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.read += n as u64;
        self.progress.advance_to(self.read);
        Ok(n)
    }
}

/// Loops and calls seek back; progress shows the furthest point read.
impl<R: std::io::Seek> std::io::Seek for CountingReader<'_, R> {
    fn seek(&mut self, pos: std::io::SeekFrom) -> std::io::Result<u64> {
        self.read = self.inner.seek(pos)?;
        Ok(self.read)
    }
}

/// A copy in the temporary directory for one `edmd run`, removed when dropped.
#[derive(Debug)]
pub struct TempCopy(pub JobProgram);

impl TempCopy {
    /// Copies `original` into `$TMPDIR/edmd-<pid>/`.
    pub fn new(original: &Path) -> Result<TempCopy, CopyError> {
        TempCopy::new_with(original, &Progress::new())
    }

    /// [`TempCopy::new`], reporting to (and cancelled through) `progress`.
    pub fn new_with(original: &Path, progress: &Progress) -> Result<TempCopy, CopyError> {
        let dir = std::env::temp_dir().join(format!("edmd-{}", std::process::id()));
        copy_program(original, &dir, progress).map(TempCopy)
    }
}

impl Drop for TempCopy {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0.path);
        if let Some(dir) = self.0.path.parent() {
            let _ = std::fs::remove_dir(dir);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("edmd-copy-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn the_copy_is_named_by_its_hash_and_outlives_edits_of_the_original() {
        let dir = scratch("hash");
        let original = dir.join("a.nc");
        std::fs::write(&original, "G1 X1 F60\nM30\n").unwrap();
        let progress = Progress::new();
        let copy = copy_program(&original, &dir.join("jobs"), &progress).unwrap();
        assert_eq!(copy.sha256, sha256_file(&original).unwrap());
        assert_eq!(copy.path, copy_path(&dir.join("jobs"), &copy.sha256));
        assert_eq!(copy.name, original.display().to_string());
        assert_eq!(copy.bytes, 14);
        assert_eq!(progress.get(), (Phase::Copying, 14, 14));
        std::fs::write(&original, "G1 X900 F60\nM30\n").unwrap();
        assert_eq!(
            std::fs::read_to_string(&copy.path).unwrap(),
            "G1 X1 F60\nM30\n"
        );
        let mode = std::fs::metadata(&copy.path).unwrap().permissions().mode();
        assert_eq!(mode & 0o222, 0, "read-only");
        // The same bytes again: the same copy.
        std::fs::write(&original, "G1 X1 F60\nM30\n").unwrap();
        let again = copy_program(&original, &dir.join("jobs"), &Progress::new()).unwrap();
        assert_eq!(again.path, copy.path);
        // SHA-256 of "abc", the standard's own example.
        std::fs::write(&original, "abc").unwrap();
        assert_eq!(
            sha256_file(&original).unwrap(),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }

    #[test]
    fn a_cancelled_copy_leaves_nothing() {
        let dir = scratch("cancel");
        let original = dir.join("a.nc");
        std::fs::write(&original, "G1 X1 F60\n".repeat(100_000)).unwrap();
        let progress = Progress::new();
        progress.cancel();
        let e = copy_program(&original, &dir.join("jobs"), &progress).unwrap_err();
        assert!(matches!(e, CopyError::Cancelled { .. }), "{e}");
        assert_eq!(std::fs::read_dir(dir.join("jobs")).unwrap().count(), 0);
        let e = copy_program(&dir.join("missing.nc"), &dir.join("jobs"), &progress).unwrap_err();
        assert!(e.to_string().contains("missing.nc: cannot read"), "{e}");
    }

    #[test]
    fn a_temporary_copy_goes_with_its_job() {
        let dir = scratch("temp");
        let original = dir.join("a.nc");
        std::fs::write(&original, "G1 X1 F60\n").unwrap();
        let copy = TempCopy::new(&original).unwrap();
        let path = copy.0.path.clone();
        assert!(path.exists());
        drop(copy);
        assert!(!path.exists());
    }
}
