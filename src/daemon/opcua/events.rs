//! What happened between two statuses, as OPC UA events: holds, shorts and alarms.
//!
//! The server reads the status on a period; a count that grew or a state entered between two
//! reads is one event (five shorts within one period are one event that says five). A job
//! that ends other than done or stopped is an alarm with its outcome and error.

use crate::daemon::protocol::{DaemonState, Status};
use crate::runtime::Outcome;

/// Which event type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EventKind {
    Hold,
    Short,
    Alarm,
}

impl EventKind {
    /// OPC UA severity (1 to 1000).
    pub fn severity(self) -> u16 {
        match self {
            EventKind::Short => 200,
            EventKind::Hold => 400,
            EventKind::Alarm => 800,
        }
    }
}

/// One event to raise.
#[derive(Debug, Clone, PartialEq)]
pub struct Happened {
    pub kind: EventKind,
    pub message: String,
}

fn holding(state: DaemonState) -> bool {
    matches!(
        state,
        DaemonState::Holding | DaemonState::Held | DaemonState::Paused
    )
}

/// Where the job stands, for a message: ` at line N of P`.
fn place(status: &Status) -> String {
    status
        .job
        .as_ref()
        .map(|j| format!(" at line {} of {}", j.line, j.program))
        .unwrap_or_default()
}

/// The events between `before` and `now`.
pub fn between(before: &Status, now: &Status) -> Vec<Happened> {
    let mut out = Vec::new();
    let mut push = |kind, message: String| out.push(Happened { kind, message });
    if holding(now.state) && !holding(before.state) {
        let why = now
            .job
            .as_ref()
            .and_then(|j| j.pause.clone())
            .unwrap_or_else(|| "hold".to_string());
        push(EventKind::Hold, format!("{why}{}", place(now)));
    }
    let (b, n) = (&before.counters.servo, &now.counters.servo);
    if n.shorts > b.shorts {
        push(
            EventKind::Short,
            format!(
                "{} short circuit(s){} ({} in all)",
                n.shorts - b.shorts,
                place(now),
                n.shorts
            ),
        );
    }
    for (what, was, is) in [
        ("servo alarm(s)", b.alarms, n.alarms),
        ("collision(s) during a rapid", b.collisions, n.collisions),
        ("wire break(s)", b.wire_breaks, n.wire_breaks),
    ] {
        if is > was {
            push(
                EventKind::Alarm,
                format!("{} {what}{}", is - was, place(now)),
            );
        }
    }
    if let Some(last) = &now.last_job
        && before.last_job.as_ref() != Some(last)
        && !matches!(last.outcome, Outcome::Done | Outcome::Stopped)
    {
        let error = last
            .error
            .as_ref()
            .map(|e| format!(": {e}"))
            .unwrap_or_default();
        push(
            EventKind::Alarm,
            format!("{} ended: {}{error}", last.program, last.outcome.name()),
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kinds(events: &[Happened]) -> Vec<EventKind> {
        events.iter().map(|e| e.kind).collect()
    }

    #[test]
    fn a_hold_is_one_event_when_it_begins() {
        let running = Status::bare(DaemonState::Running);
        let holding = Status::bare(DaemonState::Holding);
        let held = Status::bare(DaemonState::Held);
        let events = between(&running, &holding);
        assert_eq!(kinds(&events), [EventKind::Hold]);
        assert_eq!(events[0].message, "hold");
        assert!(
            between(&holding, &held).is_empty(),
            "braking to held is the same hold"
        );
        assert!(between(&held, &held).is_empty());
        assert_eq!(kinds(&between(&held, &running)), []);
        assert_eq!(
            kinds(&between(&running, &Status::bare(DaemonState::Paused))),
            [EventKind::Hold]
        );
    }

    #[test]
    fn counts_that_grew_are_one_event_each() {
        let before = Status::bare(DaemonState::Running);
        let mut now = before.clone();
        now.counters.servo.shorts = 5;
        now.counters.servo.wire_breaks = 1;
        let events = between(&before, &now);
        assert_eq!(kinds(&events), [EventKind::Short, EventKind::Alarm]);
        assert_eq!(events[0].message, "5 short circuit(s) (5 in all)");
        assert_eq!(events[1].message, "1 wire break(s)");
        assert!(
            between(&now, &now).is_empty(),
            "nothing new, nothing raised"
        );
    }

    #[test]
    fn a_job_that_ends_badly_is_an_alarm_once() {
        let before = Status::bare(DaemonState::Running);
        let mut now = Status::bare(DaemonState::Idle);
        let summary = |outcome| {
            let mut s: crate::runtime::JobSummary = serde_json::from_value(serde_json::json!({
                "program": "p.ngc", "outcome": "done", "error": null, "axes": ["X"],
                "blocks": 1, "segments": 1, "steps_per_axis": [0], "end_steps": [0],
                "program_end_steps": [0], "end_mm": [0.0], "events_forward": 0,
                "events_backward": 0, "shorts": 0, "turn_backs": 0,
                "deepest_turn_back_blocks": 0, "alarms": 0, "starvations": 0,
                "overruns": 0, "missed_deadlines": 0, "latency_us": null, "tick_us": 50,
                "ticks": 0, "virtual_time": true, "virtual_time_s": 0.0, "wall_time_s": 0.0,
                "buffer_capacity": 1, "buffer_high_water": 0, "events_dropped": 0,
                "trace_dropped": 0, "rt_refused": []
            }))
            .unwrap();
            s.outcome = outcome;
            s
        };
        now.last_job = Some(summary(Outcome::Done));
        assert!(between(&before, &now).is_empty(), "done is no alarm");
        now.last_job = Some(summary(Outcome::Stopped));
        assert!(
            between(&before, &now).is_empty(),
            "an abort is asked for, no alarm"
        );
        let mut limit = summary(Outcome::Limit);
        limit.error = Some("X+ limit switch".into());
        now.last_job = Some(limit);
        let events = between(&before, &now);
        assert_eq!(kinds(&events), [EventKind::Alarm]);
        assert_eq!(events[0].message, "p.ngc ended: limit: X+ limit switch");
        assert!(
            between(&now, &now).is_empty(),
            "the same last job again is not new"
        );
    }
}
