//! The report of a job that ran (`edmd run --report DIR`): what the machine did, from the
//! [`Recording`] its supervisor gathered, where `edmd plan` shows what was planned.
//!
//! - `path.svg`: the executed X–Y path over the programmed one, the stretches turned back over and re-advanced marked,
//!   the short circuits, jumps, wire breaks and probe contacts as dots, the start point and
//!   the direction it leaves in; on a four-axis wire machine the upper guide's path (X+U,
//!   Y+V) beside the lower guide's;
//! - `feed.svg`: the feed along the path against machine time, the gap state on a band of
//!   its own under it;
//! - `events.csv`: every servo event (short, turn-back, resume, starvation, alarm, jump, wire
//!   break, probe, end) with its machine time, source line and position;
//! - `summary.json`: the job's summary, as `--summary` writes it;
//! - `pulses.svg` (a gap that counts its pulses: the simulator, a discriminator through HAL):
//!   the share of normal, arc, short and open pulses against machine time, over the gap
//!   state's band, so an open gap reads open however the three-state band rounds it;
//! - `generator.svg` (the same): the off time in force and the adaptive law's estimate of
//!   the part height against machine time;
//! - `passes.csv` (a job in passes): each pass's technology row, condition, machine time,
//!   what it advanced, its mean cut rate and its wire breaks.
//!
//! Every series is decimated to a fixed number of points, so a report's size does not grow
//! with the job.

pub mod programmed;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::plot::{Band, Chart, Series, Style};
use crate::record::{EventKind, Recording};
use crate::runtime::JobSummary;

/// A report that could not be written.
#[derive(Debug, thiserror::Error)]
#[error("{path}: cannot write the report: {source}")]
pub struct ReportError {
    pub path: PathBuf,
    pub source: std::io::Error,
}

/// Writes the report of a finished job into `dir` (created if needed).
pub fn write_report(
    dir: &Path,
    recording: &mut Recording,
    summary: &JobSummary,
    passes: &[PassTime],
) -> Result<(), ReportError> {
    let fail = |path: &Path| {
        let path = path.to_path_buf();
        move |source| ReportError { path, source }
    };
    std::fs::create_dir_all(dir).map_err(fail(dir))?;
    let write = |name: &str, text: &str| {
        let path = dir.join(name);
        std::fs::write(&path, text).map_err(fail(&path))
    };
    recording.close(summary.ticks);
    let json = serde_json::to_string_pretty(summary).expect("a summary serialises");
    write("summary.json", &(json + "\n"))?;
    write("events.csv", &events_csv(recording, &summary.axes))?;
    if !passes.is_empty() {
        write("passes.csv", &passes_csv(passes))?;
    }
    let path = path_chart(recording, summary);
    write("path.svg", &path.render())?;
    let feed = Chart {
        title: "Feed and gap state".into(),
        x_label: "machine time (s)".into(),
        y_label: "feed (mm/min)".into(),
        series: vec![Series {
            name: "feed along the path".into(),
            color: "#1f8f3f",
            style: Style::Line,
            points: recording.feed.points(),
        }],
        band: Some(gap_band(recording)),
        ..Chart::default()
    };
    write("feed.svg", &feed.render())?;
    if let Some((pulses, generator)) = process_charts(recording) {
        write("pulses.svg", &pulses.render())?;
        write("generator.svg", &generator.render())?;
    }
    Ok(())
}

/// `pulses.svg` and `generator.svg`, from the process trace; none from a gap that counted no
/// pulses.
fn process_charts(recording: &Recording) -> Option<(Chart, Chart)> {
    let trace = &recording.process;
    if trace
        .last()
        .is_none_or(|p| p.pulses.iter().sum::<u64>() == 0)
    {
        return None;
    }
    const CLASSES: [(&str, &str); 4] = [
        ("normal", "#1a7f37"),
        ("arc", "#cf5a00"),
        ("short", "#d1242f"),
        ("open", "#bf8700"),
    ];
    let mut shares: [Vec<(f64, f64)>; 4] = Default::default();
    let (mut off_time, mut height) = (Vec::new(), Vec::new());
    for pair in trace.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        let t = recording.secs(b.tick);
        let d: Vec<f64> = (0..4)
            .map(|c| b.pulses[c].saturating_sub(a.pulses[c]) as f64)
            .collect();
        let n: f64 = d.iter().sum();
        if n > 0.0 {
            for (share, d) in shares.iter_mut().zip(&d) {
                share.push((t, d / n * 100.0));
            }
        }
        off_time.push((t, b.off_time_us));
        if b.height_mm.is_finite() {
            height.push((t, b.height_mm));
        }
    }
    let pulses = Chart {
        title: "What the gap did: pulses by class".into(),
        x_label: "machine time (s)".into(),
        y_label: "share of the pulses (%)".into(),
        series: CLASSES
            .iter()
            .zip(shares)
            .map(|(&(name, color), points)| Series {
                name: name.into(),
                color,
                style: Style::Line,
                points,
            })
            .collect(),
        band: Some(gap_band(recording)),
        ..Chart::default()
    };
    let mut series = vec![Series {
        name: "off time in force (µs)".into(),
        color: "#1f5fbf",
        style: Style::Line,
        points: off_time,
    }];
    if !height.is_empty() {
        series.push(Series {
            name: "estimated part height (mm)".into(),
            color: "#8250df",
            style: Style::Line,
            points: height,
        });
    }
    let generator = Chart {
        title: "The generator: off time and estimated height".into(),
        x_label: "machine time (s)".into(),
        y_label: "µs, mm".into(),
        series,
        ..Chart::default()
    };
    Some((pulses, generator))
}

/// One pass of a job in passes: the technology row it came from, its condition and its
/// machine time (from its start to the next pass's, holds within it included).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PassTime {
    pub pass: u64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub condition: Option<u32>,
    /// The technology table's row (`32 mm, between the 30 and 40 mm rows`); none for
    /// `[wire] pass`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub row: Option<String>,
    pub time_s: f64,
    /// Advanced along the path in the pass (mm; a turn-back and its re-advance count
    /// nothing); none from a job recorded without its process.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cut_mm: Option<f64>,
    /// The pass's mean cut rate: what it advanced times the part height, over its time
    /// (mm²/min). The height is the adaptive law's estimate where it ran, else the
    /// technology's; none without either.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean_rate_mm2_per_min: Option<f64>,
    /// Wire breaks within the pass.
    #[serde(default)]
    pub wire_breaks: u64,
}

/// The mean cut rate (mm²/min) of a stretch that advanced `cut_mm` in `time_s`, at the
/// estimated height where the law ran, else at `part_height_mm`.
pub fn mean_rate(
    stretch: &crate::record::CutStretch,
    time_s: f64,
    part_height_mm: Option<f64>,
) -> Option<f64> {
    let height = stretch.height_estimate_mm.or(part_height_mm)?;
    (time_s > 0.0).then(|| stretch.cut_mm.max(0.0) * height / time_s * 60.0)
}

/// What a job's recording says of its passes: each pass's machine time, from its start to
/// the next one's (or the job's end at `end_tick`), with the condition and the table row of
/// each (`conditions[k]`, `rows[k]` for pass k + 1), what it advanced, its mean cut rate (at
/// `part_height_mm` where the adaptive law did not estimate one) and its wire breaks.
pub fn pass_times(
    recording: &Recording,
    end_tick: u64,
    conditions: &[u32],
    rows: &[String],
    part_height_mm: Option<f64>,
) -> Vec<PassTime> {
    let starts: Vec<(u64, u64)> = recording
        .events
        .iter()
        .filter(|e| e.kind == EventKind::Pass)
        .map(|e| (e.depth.unwrap_or(0), e.tick))
        .collect();
    starts
        .iter()
        .enumerate()
        .map(|(i, &(pass, tick))| {
            let k = pass.checked_sub(1).map(|k| k as usize);
            let until = starts.get(i + 1).map_or(end_tick, |&(_, t)| t);
            let time_s = recording.tick.ticks_to_secs(until.saturating_sub(tick));
            let stretch = recording.cut_between(tick, until);
            PassTime {
                pass,
                condition: k.and_then(|k| conditions.get(k).copied()),
                row: k.and_then(|k| rows.get(k).cloned()),
                time_s,
                cut_mm: stretch.map(|s| s.cut_mm),
                mean_rate_mm2_per_min: stretch.and_then(|s| mean_rate(&s, time_s, part_height_mm)),
                wire_breaks: recording
                    .events
                    .iter()
                    .filter(|e| e.kind == EventKind::WireBreak && e.tick >= tick && e.tick < until)
                    .count() as u64,
            }
        })
        .collect()
}

/// `passes.csv`: a line per pass.
fn passes_csv(passes: &[PassTime]) -> String {
    let mut csv =
        String::from("pass,condition,row,time_s,cut_mm,mean_rate_mm2_per_min,wire_breaks\n");
    let figure = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.3}"));
    for p in passes {
        let _ = writeln!(
            csv,
            "{},{},\"{}\",{:.3},{},{},{}",
            p.pass,
            p.condition.map_or(String::new(), |c| format!("E{c}")),
            p.row.as_deref().unwrap_or_default().replace('"', "'"),
            p.time_s,
            figure(p.cut_mm),
            figure(p.mean_rate_mm2_per_min),
            p.wire_breaks
        );
    }
    csv
}

/// The gap state against machine time, on its own band: where each state begins (the
/// recording keeps shorts through its decimation, so a short is never lost from the band).
fn gap_band(recording: &Recording) -> Band {
    let mut changes: Vec<(f64, usize)> = Vec::new();
    for (t, level) in recording.gap.points() {
        // The recording's levels: 0 open, 1 normal, 2 short (the band's states in order).
        let state = level.round().clamp(0.0, 2.0) as usize;
        if changes.last().is_none_or(|&(_, s)| s != state) {
            changes.push((t, state));
        }
    }
    Band {
        label: "gap".into(),
        states: vec![
            ("gap open".into(), "#e8e8e8"),
            ("normal".into(), "#8fd18f"),
            ("short".into(), "#d02020"),
        ],
        changes,
    }
}

/// The executed path's name in the legend.
const EXECUTED: &str = "executed path";

/// `path.svg`: the executed path (and a four-axis machine's upper guide), the turn-backs and
/// the events as dots.
fn path_chart(recording: &Recording, summary: &JobSummary) -> Chart {
    let mut path = Chart {
        title: format!(
            "Executed path: {} ({})",
            summary.program,
            summary.outcome.name()
        ),
        x_label: "X (mm)".into(),
        y_label: "Y (mm)".into(),
        series: vec![
            Series {
                name: "programmed path".into(),
                color: "#b8b8b8",
                style: Style::Line,
                points: recording.programmed.clone(),
            },
            Series {
                name: EXECUTED.into(),
                color: "#1f5fbf",
                style: Style::Line,
                points: recording.path.points(),
            },
            Series {
                name: "rapids (G0)".into(),
                color: "#d08000",
                style: Style::Dashed,
                points: recording.rapids.clone(),
            },
            Series {
                name: "turned back and re-advanced".into(),
                color: "#d02020",
                style: Style::Line,
                points: recording.turn_back.clone(),
            },
            Series {
                name: format!("short circuits ({})", summary.servo.shorts),
                color: "#111111",
                style: Style::Dots,
                points: recording
                    .events
                    .iter()
                    .filter(|e| e.kind == EventKind::Short && e.position_mm.len() >= 2)
                    .map(|e| (e.position_mm[0], e.position_mm[1]))
                    .collect(),
            },
            dots(
                recording,
                EventKind::Jump,
                "#6f42c1",
                "jumps",
                summary.servo.jumps,
            ),
            dots(
                recording,
                EventKind::WireBreak,
                "#8c564b",
                "wire breaks",
                summary.servo.wire_breaks,
            ),
            dots(
                recording,
                EventKind::Probe,
                "#1f6feb",
                "probe contacts",
                summary.servo.probes,
            ),
        ],
        equal_axes: true,
        start: recording
            .start
            .map(|p| (p, recording.direction.unwrap_or((1.0, 0.0)))),
        ..Chart::default()
    };
    // The legend names only what happened (the executed path always); the programmed path
    // is drawn first, under the rest.
    path.series
        .retain(|s| s.name == EXECUTED || !s.points.is_empty());
    let executed = path
        .series
        .iter()
        .position(|s| s.name == EXECUTED)
        .expect("the executed path is kept");
    if let Some((_, upper)) = &recording.upper {
        // A four-axis wire machine: the lower guide's path above, the upper guide's too.
        path.series[executed].name = "executed path (lower guide, X/Y)".into();
        path.series.insert(
            executed + 1,
            Series {
                name: "upper guide (X+U, Y+V)".into(),
                color: "#2a9d8f",
                style: Style::Line,
                points: upper.points(),
            },
        );
    }
    path
}

/// The events of `kind` as dots where they happened, named with their count.
fn dots(
    recording: &Recording,
    kind: EventKind,
    color: &'static str,
    what: &str,
    count: u64,
) -> Series {
    Series {
        name: format!("{what} ({count})"),
        color,
        style: Style::Dots,
        points: recording
            .events
            .iter()
            .filter(|e| e.kind == kind && e.position_mm.len() >= 2)
            .map(|e| (e.position_mm[0], e.position_mm[1]))
            .collect(),
    }
}

/// `tick,time_s,line,event,depth,<axis>_mm...`, one row per event.
fn events_csv(recording: &Recording, axes: &[String]) -> String {
    let mut csv = String::from("tick,time_s,line,event,depth");
    for a in axes {
        let _ = write!(csv, ",{}_mm", a.to_ascii_lowercase());
    }
    csv.push('\n');
    // Times to the tick and positions to the step: the digits that mean something.
    let time_digits = decimals(recording.tick.ns() as f64 * 1e-9);
    let mm_digits = recording
        .step_mm
        .iter()
        .map(|s| decimals(*s))
        .max()
        .unwrap_or(3);
    for e in &recording.events {
        let _ = write!(
            csv,
            "{},{:.*},{},{},{}",
            e.tick,
            time_digits,
            recording.secs(e.tick),
            e.line,
            e.kind.name(),
            e.depth.map(|d| d.to_string()).unwrap_or_default()
        );
        for p in &e.position_mm {
            let _ = write!(csv, ",{p:.mm_digits$}");
        }
        csv.push('\n');
    }
    if recording.events_left_out > 0 {
        let _ = writeln!(
            csv,
            "# {} more events left out (the report keeps the first {})",
            recording.events_left_out,
            crate::record::MAX_EVENTS
        );
    }
    csv
}

/// The decimals that show a quantity of resolution `unit` (0.05 ms: 5; 1 µm in mm: 3).
fn decimals(unit: f64) -> usize {
    if unit.is_nan() || unit <= 0.0 {
        return 6;
    }
    let mut d = 0;
    while d < 12
        && ((unit * 10f64.powi(d as i32)).round() - unit * 10f64.powi(d as i32)).abs() > 1e-9
    {
        d += 1;
    }
    d
}

#[cfg(test)]
mod tests {
    #[test]
    fn decimals_show_the_resolution() {
        assert_eq!(super::decimals(50e-6), 5);
        assert_eq!(super::decimals(1e-3), 3);
        assert_eq!(super::decimals(0.0005), 4);
        assert_eq!(super::decimals(1e-4), 4);
        assert_eq!(super::decimals(1.0), 0);
    }
}
