//! The job history and the machine's hour counters, kept across restarts.
//!
//! Every program job that ends (done, stopped, alarm, …; a dry run too, marked so) appends
//! one JSON line to the history file: program, start and end, outcome, machine time, the
//! time of each pass of the technology table, shorts, turn-backs, wire breaks, where a
//! drilling move broke through, and its report folder. Jogs, MDI lines, homing and touch
//! cycles are the machine's, not jobs: they add to the hour counters only. The counters
//! (machine time moving, sparking time, jobs) are one small JSON file rewritten atomically
//! at each job's end. A history line that cannot be written is logged and shown, never
//! fatal: the job has ended either way.

use std::io::Write;
use std::path::{Path, PathBuf};

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
    /// Machine time from start to end (s), holds and pauses included.
    pub machine_time_s: f64,
    /// Each pass of the technology table: its number, condition and machine time.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub passes: Vec<PassTime>,
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
    path: PathBuf,
    counters_path: PathBuf,
    pub counters: HourCounters,
    /// The last write that failed, for the status.
    pub write_error: Option<String>,
}

/// How many jobs `edmd ctl jobs` and the page list at most.
pub const MAX_LISTED: usize = 200;

impl History {
    /// The history at `path` and the counters at `counters_path` (read when present; a
    /// counters file that cannot be read starts from zero, said in the log).
    pub fn open(path: &Path, counters_path: &Path) -> History {
        let counters = match std::fs::read_to_string(counters_path) {
            Ok(text) => serde_json::from_str(&text).unwrap_or_else(|e| {
                tracing::warn!(
                    "{}: not the hour counters ({e}); they start from zero",
                    counters_path.display()
                );
                HourCounters::default()
            }),
            Err(_) => HourCounters::default(),
        };
        History {
            path: path.to_path_buf(),
            counters_path: counters_path.to_path_buf(),
            counters,
            write_error: None,
        }
    }

    /// A job ended: its record (program jobs only) appended, the counters added to.
    pub fn add(&mut self, record: Option<&JobRecord>, machine_s: f64, spark_s: f64) {
        self.counters.machine_s += machine_s;
        self.counters.spark_s += spark_s;
        let mut result = Ok(());
        if let Some(r) = record {
            self.counters.jobs += 1;
            result = append_line(&self.path, r);
        }
        let counters = serde_json::to_vec_pretty(&self.counters).expect("plain data");
        let result = result.and_then(|()| {
            crate::sys::write_atomic(&self.counters_path, &counters)
                .map_err(|e| format!("{}: {e}", self.counters_path.display()))
        });
        match result {
            Ok(()) => self.write_error = None,
            Err(e) => {
                tracing::error!("job history: {e}");
                self.write_error = Some(e);
            }
        }
    }

    /// The last `n` jobs, newest first (lines that do not read are skipped and counted).
    pub fn last(&self, n: usize) -> (Vec<JobRecord>, usize) {
        let Ok(text) = std::fs::read_to_string(&self.path) else {
            return (Vec::new(), 0);
        };
        let mut bad = 0;
        let mut jobs: Vec<JobRecord> = text
            .lines()
            .filter(|l| !l.trim().is_empty())
            .filter_map(|l| serde_json::from_str(l).map_err(|_| bad += 1).ok())
            .collect();
        jobs.reverse();
        jobs.truncate(n);
        (jobs, bad)
    }
}

/// The history as `edmd ctl jobs` prints it: one job a line, newest first, its passes
/// after it.
pub fn table(jobs: &[JobRecord], unreadable: usize) -> String {
    use std::fmt::Write;
    let mut t = String::new();
    if jobs.is_empty() {
        t.push_str("no jobs in the history yet");
    }
    for j in jobs {
        let _ = write!(
            t,
            "{}  {:<8} {}{}{}  {}  {} shorts, {} wire breaks",
            j.started,
            j.outcome,
            j.program,
            if j.dry_run { " (dry run)" } else { "" },
            j.from_line
                .map(|l| format!(" from line {l}"))
                .unwrap_or_default(),
            duration(j.machine_time_s),
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
                "    pass {}{}  {}{}",
                p.pass,
                p.condition.map(|c| format!(" E{c}")).unwrap_or_default(),
                duration(p.time_s),
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
    if unreadable > 0 {
        let _ = write!(
            t,
            "\n({unreadable} lines of the history file do not read as jobs)"
        );
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

fn append_line(path: &Path, record: &JobRecord) -> Result<(), String> {
    let mut line = serde_json::to_string(record).expect("plain data");
    line.push('\n');
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .and_then(|mut f| f.write_all(line.as_bytes()).and_then(|()| f.sync_data()))
        .map_err(|e| format!("{}: {e}", path.display()))
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
    from_line: Option<u64>,
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
        from_line,
        machine_time_s: summary.virtual_time_s,
        passes,
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
mod tests {
    use super::*;

    #[test]
    fn the_history_appends_and_lists_newest_first_and_the_counters_persist() {
        let dir = std::env::temp_dir().join(format!("edmd-history-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let (jobs, counters) = (
            dir.join("state/jobs.jsonl"),
            dir.join("state/counters.json"),
        );
        let mut h = History::open(&jobs, &counters);
        let record = |program: &str| JobRecord {
            program: program.into(),
            started: local_time(),
            ended: local_time(),
            outcome: "done".into(),
            error: None,
            dry_run: false,
            from_line: None,
            machine_time_s: 60.0,
            passes: vec![PassTime {
                pass: 1,
                condition: Some(4),
                row: Some("30 mm row".into()),
                time_s: 60.0,
            }],
            technology: Some("material=steel height=30 wire=0.25 (…)".into()),
            shorts: 2,
            turn_backs: 2,
            wire_breaks: 0,
            breakthrough_mm: None,
            report: None,
        };
        h.add(Some(&record("a.nc")), 60.0, 50.0);
        h.add(None, 5.0, 0.0);
        h.add(Some(&record("b.nc")), 60.0, 40.0);
        assert_eq!(h.write_error, None);
        let (listed, bad) = h.last(10);
        assert_eq!(bad, 0);
        assert_eq!(
            listed
                .iter()
                .map(|r| r.program.as_str())
                .collect::<Vec<_>>(),
            ["b.nc", "a.nc"]
        );
        assert_eq!(listed[0].passes[0].condition, Some(4));
        // A restart reads the counters back.
        let again = History::open(&jobs, &counters);
        assert_eq!(
            again.counters,
            HourCounters {
                jobs: 2,
                machine_s: 125.0,
                spark_s: 90.0
            }
        );
        assert_eq!(again.last(1).0.len(), 1);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_local_time_reads_as_a_date_and_a_clock() {
        let t = local_time();
        assert_eq!(t.len(), 19, "{t}");
        assert_eq!(&t[10..11], " ");
        assert_eq!(&t[13..14], ":");
    }
}
