//! The job history and the machine's hour counters, kept across restarts.
//!
//! Every program job that ends (done, stopped, alarm, …; a dry run too, marked so) appends
//! one JSON line to the history file: program, start and end, outcome, machine and spark time,
//! the time of each pass of the technology table, shorts, turn-backs, wire breaks, where a
//! drilling move broke through, and its report folder. Jogs, MDI lines, homing and touch
//! cycles are the machine's, not jobs: they add to the hour counters only. The counters
//! (machine time moving, sparking time, jobs) are one small JSON file rewritten atomically
//! at each job's end.
//!
//! **Nothing lost.** A line that cannot be written (a full disk) is kept and written again
//! ([`History::retry`], every round of the control loop that has one waiting, and before the
//! next job's), in order; the status says so meanwhile. A line starts on a line of its own
//! even after a torn write (a power cut mid-line): the reader skips the torn line, says where
//! it is, and reads the next. A counters file that does not read (torn, a FIFO, something
//! else) is kept aside as `counters.json.bad-<time>` and the counters are rebuilt from the
//! history, never silently reset. The history is read off the control loop, a page at a time
//! from its end ([`HistoryFile::page`]): a long history costs its reader, not the machine.

mod file;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

pub use file::{HistoryFile, Page};

use serde::{Deserialize, Serialize};

use crate::record::{EventKind, Recording};
use crate::runtime::JobSummary;

/// One job of the history.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JobRecord {
    pub program: String,
    /// Local time, `YYYY-MM-DD HH:MM:SS`.
    pub started: String,
    pub ended: String,
    /// `done`, `stopped`, `alarm`, … (the summary's outcome).
    pub outcome: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// Spark off, servo out of the loop: nothing was cut.
    #[serde(default)]
    pub dry_run: bool,
    /// Run from this line.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub from_line: Option<u64>,
    /// A run from a line in passes: the pass the line was cut in.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub from_pass: Option<u8>,
    /// Machine time from start to end (s), holds and pauses included.
    pub machine_time_s: f64,
    /// Time the gap sparked (s): kept so the hour counters can be rebuilt from the history.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spark_s: Option<f64>,
    /// Each pass of the technology table: its number, condition and machine time.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub passes: Vec<PassTime>,
    /// The job's mean cut rate (mm²/min): what it advanced along the path times the part
    /// height (the adaptive law's estimate, else the technology's), over its machine time.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean_rate_mm2_per_min: Option<f64>,
    /// The technology it was cut with (`material=steel height=32 wire=0.25 (…)`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub technology: Option<String>,
    pub shorts: u64,
    pub turn_backs: u64,
    pub wire_breaks: u64,
    /// Where a drilling move broke through (machine mm), the first time.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub breakthrough_mm: Option<Vec<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub report: Option<String>,
}

pub use crate::report::PassTime;

/// The machine's counters over its life: what the hour meters of a control show.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct HourCounters {
    /// Program jobs ended (dry runs included).
    pub jobs: u64,
    /// Machine time of every job, jogs and MDI lines included (s).
    pub machine_s: f64,
    /// Time the gap sparked (normal or short gap readings while cutting, s).
    pub spark_s: f64,
}

/// The history file and the counters file, as the daemon keeps them.
#[derive(Debug)]
pub struct History {
    file: HistoryFile,
    counters_path: PathBuf,
    pub counters: HourCounters,
    /// Lines not yet written (a write failed), oldest first, each ending in a line break.
    pending: Vec<String>,
    /// The last write that failed, for the status.
    pub write_error: Option<String>,
    last_try: Option<Instant>,
}

/// How many jobs `edmd ctl jobs` and the page list at most.
pub const MAX_LISTED: usize = 200;
/// Lines kept while the history cannot be written; beyond, the oldest are dropped (said in
/// the log), so a disk that stays full cannot grow the daemon without bound.
const MAX_PENDING: usize = 10_000;
/// A failed write is tried again this often at most.
const RETRY_EVERY: Duration = Duration::from_secs(5);

impl History {
    /// The history at `path` and the counters at `counters_path`. Counters that do not read
    /// are kept aside and rebuilt from the history (said in the log).
    pub fn open(path: &Path, counters_path: &Path) -> History {
        let file = HistoryFile::new(path);
        let counters = match crate::sys::read_regular(counters_path) {
            Ok(text) => match serde_json::from_str(&text) {
                Ok(c) => c,
                Err(e) => rebuilt(
                    &file,
                    counters_path,
                    &format!("not the hour counters ({e})"),
                ),
            },
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                if file.exists() {
                    rebuilt(&file, counters_path, "missing beside a history")
                } else {
                    HourCounters::default()
                }
            }
            Err(e) => rebuilt(&file, counters_path, &format!("cannot be read ({e})")),
        };
        History {
            file,
            counters_path: counters_path.to_path_buf(),
            counters,
            pending: Vec::new(),
            write_error: None,
            last_try: None,
        }
    }

    /// The history file, for readers off the control loop.
    pub fn file(&self) -> HistoryFile {
        self.file.clone()
    }

    /// A job ended: its record (program jobs only) appended, the counters added to.
    pub fn add(&mut self, record: Option<&JobRecord>, machine_s: f64, spark_s: f64) {
        self.counters.machine_s += machine_s;
        self.counters.spark_s += spark_s;
        if let Some(r) = record {
            self.counters.jobs += 1;
            let mut line = serde_json::to_string(r).expect("plain data");
            line.push('\n');
            self.pending.push(line);
            if self.pending.len() > MAX_PENDING {
                let dropped = self.pending.len() - MAX_PENDING;
                self.pending.drain(..dropped);
                tracing::error!(
                    "job history: {dropped} unwritten line(s) dropped ({MAX_PENDING} kept)"
                );
            }
        }
        self.write();
    }

    /// Lines still waiting: tried again when the last try is [`RETRY_EVERY`] old.
    pub fn retry(&mut self) {
        if !self.pending.is_empty() && self.last_try.is_none_or(|t| t.elapsed() >= RETRY_EVERY) {
            self.write();
        }
    }

    /// Writes what waits, then the counters.
    fn write(&mut self) {
        self.last_try = Some(Instant::now());
        let result = self.file.append(&self.pending).and_then(|()| {
            let counters = serde_json::to_vec_pretty(&self.counters).expect("plain data");
            crate::sys::write_atomic(&self.counters_path, &counters)
                .map_err(|e| format!("{}: {e}", self.counters_path.display()))
        });
        match result {
            Ok(()) => {
                if self.write_error.take().is_some() {
                    tracing::info!("job history: written again, nothing lost");
                }
                self.pending.clear();
            }
            Err(e) => {
                if self.write_error.as_ref() != Some(&e) {
                    tracing::error!(
                        "job history: {e}; {} line(s) kept to be written later",
                        self.pending.len()
                    );
                }
                self.write_error = Some(e);
            }
        }
    }

    /// The last `n` jobs, newest first, read now (tests and the daemon's own start only:
    /// clients read pages off the loop).
    pub fn last(&self, n: usize) -> (Vec<JobRecord>, usize) {
        match self.file.page(0, n) {
            Ok(page) => (page.jobs, page.unreadable.len()),
            Err(_) => (Vec::new(), 0),
        }
    }
}

/// The counters that did not read, kept aside, and the ones the history gives instead.
fn rebuilt(file: &HistoryFile, counters_path: &Path, why: &str) -> HourCounters {
    let mut aside = counters_path.as_os_str().to_owned();
    aside.push(format!(".bad-{}", crate::sys::local_stamp()));
    let aside = PathBuf::from(aside);
    let kept = match std::fs::rename(counters_path, &aside) {
        Ok(()) => format!("kept as {}", aside.display()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => "none to keep".to_string(),
        Err(e) => format!("not moved aside ({e})"),
    };
    let (counters, unreadable) = file.totals();
    tracing::warn!(
        "{}: {why}; {kept}; the counters are rebuilt from the history: {} jobs, {:.0} s \
         machine time, {:.0} s spark time (jogs and MDI lines are not in the history; {} \
         unreadable lines skipped)",
        counters_path.display(),
        counters.jobs,
        counters.machine_s,
        counters.spark_s,
        unreadable
    );
    counters
}

/// The history as `edmd ctl jobs` prints it: one job a line, newest first, its passes
/// after it.
pub fn table(page: &Page) -> String {
    use std::fmt::Write;
    let jobs = &page.jobs;
    let mut t = String::new();
    if jobs.is_empty() {
        t.push_str("no jobs in the history yet");
    }
    for j in jobs {
        let _ = write!(
            t,
            "{}  {:<8} {}{}{}  {}{}  {} shorts, {} wire breaks",
            j.started,
            j.outcome,
            j.program,
            if j.dry_run { " (dry run)" } else { "" },
            j.from_line
                .map(|l| format!(" from line {l}"))
                .unwrap_or_default()
                + &j.from_pass
                    .map(|p| format!(" in pass {p}"))
                    .unwrap_or_default(),
            duration(j.machine_time_s),
            j.mean_rate_mm2_per_min
                .map(|r| format!(" at {r:.0} mm²/min"))
                .unwrap_or_default(),
            j.shorts,
            j.wire_breaks
        );
        if let Some(e) = &j.error {
            let _ = write!(t, "  ({e})");
        }
        t.push('\n');
        if let Some(tech) = &j.technology {
            let _ = writeln!(t, "    technology {tech}");
        }
        for p in &j.passes {
            let _ = writeln!(
                t,
                "    pass {}{}  {}{}{}{}{}",
                p.pass,
                p.condition.map(|c| format!(" E{c}")).unwrap_or_default(),
                duration(p.time_s),
                p.cut_mm.map(|c| format!("  {c:.3} mm")).unwrap_or_default(),
                p.mean_rate_mm2_per_min
                    .map(|r| format!(" at {r:.0} mm²/min"))
                    .unwrap_or_default(),
                match p.wire_breaks {
                    0 => String::new(),
                    1 => ", 1 wire break".into(),
                    n => format!(", {n} wire breaks"),
                },
                p.row
                    .as_ref()
                    .map(|r| format!("  ({r})"))
                    .unwrap_or_default()
            );
        }
        if let Some(at) = &j.breakthrough_mm {
            let at: Vec<String> = at.iter().map(|v| format!("{v:.4}")).collect();
            let _ = writeln!(t, "    broke through at {} mm", at.join(" "));
        }
    }
    if !page.unreadable.is_empty() {
        let _ = write!(
            t,
            "\n({} line(s) of the history file do not read as jobs, skipped: {})",
            page.unreadable.len(),
            page.unreadable.join("; ")
        );
    }
    if page.more {
        t.push_str("\n(older jobs follow: --skip)");
    }
    t.trim_end().to_string()
}

/// A duration as the history shows it: `1 h 02 min`, `3 min 07 s`, `12.4 s`.
fn duration(s: f64) -> String {
    let whole = s.round() as u64;
    match whole {
        0..60 => format!("{s:.1} s"),
        60..3600 => format!("{} min {:02} s", whole / 60, whole % 60),
        _ => format!("{} h {:02} min", whole / 3600, whole / 60 % 60),
    }
}

/// Local time now as the history writes it: `YYYY-MM-DD HH:MM:SS`.
pub fn local_time() -> String {
    let stamp = crate::sys::local_stamp();
    match stamp.as_bytes().get(10) {
        Some(b'T') => format!("{} {}", &stamp[..10], stamp[11..].replace('-', ":")),
        _ => stamp,
    }
}

/// The record of a program job that ended.
pub fn record_of(
    summary: &JobSummary,
    recording: &Recording,
    started: String,
    dry_run: bool,
    from_line: Option<crate::path::FromLine>,
    (passes, technology): (Vec<PassTime>, Option<String>),
    report: Option<&Path>,
) -> JobRecord {
    JobRecord {
        program: summary.program.clone(),
        started,
        ended: local_time(),
        outcome: summary.outcome.name().to_string(),
        error: summary.error.clone(),
        dry_run,
        from_line: from_line.map(|f| f.line),
        from_pass: from_line.and_then(|f| f.pass),
        machine_time_s: summary.virtual_time_s,
        spark_s: None,
        passes,
        mean_rate_mm2_per_min: None,
        technology,
        shorts: summary.servo.shorts,
        turn_backs: summary.servo.turn_backs,
        wire_breaks: summary.servo.wire_breaks,
        breakthrough_mm: recording
            .events
            .iter()
            .find(|e| e.kind == EventKind::Breakthrough && e.depth == Some(1))
            .map(|e| e.position_mm.clone()),
        report: report.map(|p| p.display().to_string()),
    }
}

#[cfg(test)]
mod tests;
