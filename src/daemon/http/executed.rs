//! The executed path of the running job (or the last one), for the page's backplot.
//!
//! The page must show everything cut so far, also when it is opened mid-job, so it cannot
//! build the path from the status samples it happens to see. Every daemon job records what
//! ran ([`crate::record::Recording`]: samples of the position every 20 ticks of motion and at
//! every gap change, drained by the job's supervisor, never by the real-time thread), and
//! the core hands the recording to this slot when the job starts. `GET /api/executed` reads
//! it: the path as the report's `path.svg` draws it (bounded to 20,000 points: a long job's
//! samples are merged pairwise as they come, so the points thin out evenly along the path),
//! the turn-back stretches and the rapids as strokes of their own, and where each short
//! struck, so the page draws them apart.

use std::sync::Arc;

use parking_lot::Mutex;
use serde::Serialize;

use axum::extract::State;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};

use super::{App, error};
use crate::record::{EventKind, Recording};

/// Shorts drawn at most (the first ones; the rest are counted).
const MAX_SHORTS: usize = 5_000;
/// The job's latest events listed.
const RECENT_EVENTS: usize = 100;

/// The recording of the running or last job, shared by the core (which fills it at each
/// job's start) and the web side (which reads it).
pub type ExecutedSlot = Arc<Mutex<Option<Executed>>>;

/// One job's recording and its program.
#[derive(Clone)]
pub struct Executed {
    pub program: String,
    pub recording: Arc<Mutex<Recording>>,
    /// The work system the program cuts in (the one it leaves), and its offset (mm, the
    /// first two axes): the page draws the path in the program's coordinates with it.
    pub work_system: String,
    pub work_offset_mm: [f64; 2],
    /// A dry run: the path was moved, nothing was cut.
    pub dry_run: bool,
}

/// What `GET /api/executed` serves (mm, the machine's first two axes).
#[derive(Debug, Serialize, PartialEq)]
pub struct ExecutedPath {
    pub program: String,
    /// The work system the job's program is in, and its offset: work = machine − offset.
    pub work_system: String,
    pub work_offset_mm: [f64; 2],
    /// A dry run's path: moved with the spark off, nothing cut.
    pub dry_run: bool,
    pub path: Vec<[f64; 2]>,
    /// The stretches walked while turning back and re-advancing.
    pub turn_backs: Vec<Vec<[f64; 2]>>,
    pub rapids: Vec<Vec<[f64; 2]>>,
    /// Where shorts struck.
    pub shorts: Vec<[f64; 2]>,
    pub shorts_left_out: usize,
    /// The job's latest events, oldest first (the report's `events.csv` rows).
    pub events: Vec<ExecutedEvent>,
}

/// One event of the job as the page lists it.
#[derive(Debug, Serialize, PartialEq)]
pub struct ExecutedEvent {
    /// Machine time from the job's start, s.
    pub t_s: f64,
    pub line: u64,
    pub kind: &'static str,
    /// Blocks turned back over (turn-backs, alarms).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth: Option<u64>,
}

/// A copy of what `executed` holds now (the recording's lock is held for the copy only).
fn executed_path(executed: &Executed) -> ExecutedPath {
    let recording = executed.recording.lock();
    let shorts: Vec<[f64; 2]> = recording
        .events
        .iter()
        .filter(|e| e.kind == EventKind::Short && e.position_mm.len() >= 2)
        .map(|e| [e.position_mm[0], e.position_mm[1]])
        .collect();
    let shorts_left_out = shorts.len().saturating_sub(MAX_SHORTS);
    ExecutedPath {
        program: executed.program.clone(),
        work_system: executed.work_system.clone(),
        work_offset_mm: executed.work_offset_mm,
        dry_run: executed.dry_run,
        path: recording
            .path
            .points()
            .into_iter()
            .map(|(x, y)| [x, y])
            .collect(),
        turn_backs: strokes(&recording.turn_back),
        rapids: strokes(&recording.rapids),
        shorts: shorts.into_iter().take(MAX_SHORTS).collect(),
        shorts_left_out,
        events: recording.events[recording.events.len().saturating_sub(RECENT_EVENTS)..]
            .iter()
            .map(|e| ExecutedEvent {
                t_s: recording.secs(e.tick),
                line: e.line,
                kind: e.kind.name(),
                depth: e.depth,
            })
            .collect(),
    }
}

/// The running or last job's executed path (`404` before the first job).
pub(super) async fn serve(State(app): State<Arc<App>>) -> Response {
    let Some(job) = app.executed.lock().clone() else {
        return error(StatusCode::NOT_FOUND, "no job has run yet");
    };
    match tokio::task::spawn_blocking(move || executed_path(&job)).await {
        Ok(path) => axum::Json(path).into_response(),
        Err(e) => error(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    }
}

/// Points between [`crate::plot::BREAK`]s as strokes.
fn strokes(points: &[(f64, f64)]) -> Vec<Vec<[f64; 2]>> {
    points
        .split(|p| p.0.is_nan())
        .filter(|s| !s.is_empty())
        .map(|s| s.iter().map(|&(x, y)| [x, y]).collect())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::GapState;
    use crate::record::Sample;
    use crate::vocab::{MAX_AXES, TickPeriod};

    #[test]
    fn a_recording_is_served_as_path_turn_backs_rapids_and_shorts() {
        let mut r = Recording::new(&[0.001, 0.001], TickPeriod::from_us(50).unwrap());
        let at = |tick: u64, x: i64, gap: GapState, rapid: bool| {
            let mut position = [0i64; MAX_AXES];
            position[0] = x;
            Sample {
                tick,
                position,
                gap,
                rapid,
            }
        };
        r.sample(&at(0, 0, GapState::Open, false));
        r.sample(&at(20, 1000, GapState::Open, true));
        r.sample(&at(40, 2000, GapState::Normal, false));
        r.sample(&at(60, 3000, GapState::Short, false));
        r.event(60, 4, EventKind::Short, None);
        r.sample(&at(80, 2500, GapState::Normal, false));
        r.event(80, 4, EventKind::Resumed, None);
        r.sample(&at(100, 3500, GapState::Normal, false));
        let executed = Executed {
            program: "p.nc".into(),
            recording: Arc::new(Mutex::new(r)),
            work_system: "G55".into(),
            work_offset_mm: [50.0, 0.0],
            dry_run: false,
        };
        let path = executed_path(&executed);
        assert_eq!(path.path.len(), 6);
        assert_eq!(
            (path.work_system.as_str(), path.work_offset_mm),
            ("G55", [50.0, 0.0])
        );
        assert_eq!(path.rapids, vec![vec![[0.0, 0.0], [1.0, 0.0]]]);
        assert_eq!(path.turn_backs, vec![vec![[3.0, 0.0], [2.5, 0.0]]]);
        assert_eq!(path.shorts, vec![[3.0, 0.0]]);
        let kinds: Vec<&str> = path.events.iter().map(|e| e.kind).collect();
        assert_eq!(kinds, ["short", "resumed"]);
        assert_eq!(path.events[1].t_s, 80.0 * 50e-6);
    }
}
