//! The history file as any thread reads it, a page at a time from its end, and as the
//! control loop's [`super::History`] appends to it: a torn last line ended before the next,
//! a FIFO or a device in its place refused at once.

use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use super::{HourCounters, JobRecord};

/// The history file, as any thread reads and the control loop's [`History`] appends to it.
#[derive(Debug, Clone)]
pub struct HistoryFile {
    path: PathBuf,
}

/// A page of the history, newest first.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Page {
    pub jobs: Vec<JobRecord>,
    /// The lines passed over that do not read as jobs, each named by where it starts
    /// (`byte 1234: …`).
    pub unreadable: Vec<String>,
    /// Older jobs follow this page.
    pub more: bool,
}

/// Lines named as unreadable in a page, at most.
const MAX_NAMED: usize = 20;
/// How much of the file a page read takes at a time, from its end.
pub(super) const CHUNK: u64 = 64 * 1024;

impl HistoryFile {
    pub fn new(path: &Path) -> HistoryFile {
        HistoryFile {
            path: path.to_path_buf(),
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub(super) fn exists(&self) -> bool {
        self.path.exists()
    }

    /// Appends `lines` (each ending in a line break), first ending a torn last line of the
    /// file with one, then syncs.
    pub(super) fn append(&self, lines: &[String]) -> Result<(), String> {
        if lines.is_empty() {
            return Ok(());
        }
        let failed = |e: std::io::Error| format!("{}: {e}", self.path.display());
        if let Some(dir) = self.path.parent() {
            std::fs::create_dir_all(dir).map_err(failed)?;
        }
        // Opening for reading and appending without waiting: a FIFO put in its place is an
        // error, not a wedged control loop.
        let mut f = open_append(&self.path).map_err(failed)?;
        let len = f.metadata().map_err(failed)?.len();
        let mut text = String::new();
        if len > 0 {
            let mut last = [0u8];
            f.seek(SeekFrom::Start(len - 1)).map_err(failed)?;
            f.read_exact(&mut last).map_err(failed)?;
            if last[0] != b'\n' {
                text.push('\n');
            }
        }
        for line in lines {
            text.push_str(line);
        }
        f.write_all(text.as_bytes())
            .and_then(|()| f.sync_data())
            .map_err(failed)
    }

    /// `count` jobs, newest first, after the newest `skip`, reading the file backwards from
    /// its end (so the newest page costs the same however long the history is). No file is
    /// an empty page.
    pub fn page(&self, skip: usize, count: usize) -> std::io::Result<Page> {
        let mut page = Page::default();
        let mut seen = 0usize;
        self.backwards(|offset, line| {
            match serde_json::from_slice::<JobRecord>(line) {
                Ok(job) => {
                    if seen >= skip + count {
                        page.more = true;
                        return false;
                    }
                    if seen >= skip {
                        page.jobs.push(job);
                    }
                    seen += 1;
                }
                Err(e) => {
                    if page.unreadable.len() < MAX_NAMED {
                        page.unreadable.push(format!(
                            "byte {offset}: not a job ({})",
                            if line.last().is_some() && !text_complete(line) {
                                "a torn line".to_string()
                            } else {
                                e.to_string()
                            }
                        ));
                    }
                }
            }
            true
        })?;
        Ok(page)
    }

    /// The counters the whole history gives (for counters that were lost), and how many
    /// lines did not read.
    pub(super) fn totals(&self) -> (HourCounters, usize) {
        let mut counters = HourCounters::default();
        let mut unreadable = 0;
        let _ = self.backwards(|_, line| {
            match serde_json::from_slice::<JobRecord>(line) {
                Ok(job) => {
                    counters.jobs += 1;
                    counters.machine_s += job.machine_time_s;
                    counters.spark_s += job.spark_s.unwrap_or(0.0);
                }
                Err(_) => unreadable += 1,
            }
            true
        });
        (counters, unreadable)
    }

    /// Calls `line(offset, bytes)` for every non-blank line, the last first, until it answers
    /// `false`.
    fn backwards(&self, mut line: impl FnMut(u64, &[u8]) -> bool) -> std::io::Result<()> {
        let mut f = match crate::sys::open_regular(&self.path) {
            Ok(f) => f,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
            Err(e) => return Err(e),
        };
        let mut end = f.metadata()?.len();
        // The bytes after the last line break seen, not yet a whole line.
        let mut tail: Vec<u8> = Vec::new();
        while end > 0 {
            let start = end.saturating_sub(CHUNK);
            let mut chunk = vec![0u8; (end - start) as usize];
            f.seek(SeekFrom::Start(start))?;
            f.read_exact(&mut chunk)?;
            chunk.extend_from_slice(&tail);
            // Every line that starts after a line break in this chunk is whole.
            let mut stop = chunk.len();
            while let Some(nl) = chunk[..stop].iter().rposition(|&b| b == b'\n') {
                let text = &chunk[nl + 1..stop];
                if !text.iter().all(u8::is_ascii_whitespace) && !line(start + nl as u64 + 1, text) {
                    return Ok(());
                }
                stop = nl;
            }
            tail = chunk[..stop].to_vec();
            end = start;
        }
        if !tail.iter().all(u8::is_ascii_whitespace) {
            line(0, &tail);
        }
        Ok(())
    }
}

/// A JSON line that ends as a record ends (a torn write stops anywhere else).
fn text_complete(line: &[u8]) -> bool {
    line.iter()
        .rev()
        .find(|b| !b.is_ascii_whitespace())
        .is_some_and(|&b| b == b'}')
}

/// Opens `path` to read and append, creating it, without waiting on a FIFO and only if it is
/// a regular file.
fn open_append(path: &Path) -> std::io::Result<std::fs::File> {
    use std::os::unix::fs::OpenOptionsExt;
    let f = std::fs::OpenOptions::new()
        .read(true)
        .append(true)
        .create(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)?;
    if !f.metadata()?.file_type().is_file() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "not a regular file",
        ));
    }
    Ok(f)
}
