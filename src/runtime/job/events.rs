//! Servo events, from the consumer's queue to the log and the job's recording (the main
//! thread; never the consumer).

use super::super::tick::consumer::EventRecord;
use super::spec::JobSpec;
use crate::record::{EventKind, Recorder, Recording};
use crate::servo::{Excursion, PauseKind, ServoEvent};

/// Logs one servo event (from the main thread, never the consumer). A programmed stop holds
/// the job where the spec says an operator is there to resume it (the daemon), and is passed
/// otherwise (`edmd run`).
pub(crate) fn log_event(program: &str, record: &EventRecord, spec: &JobSpec) {
    let pauses = spec.run_loop.program_pauses;
    let t = spec.tick.ticks_to_secs(record.tick);
    let line = record.line;
    match record.event {
        ServoEvent::Short { at } => tracing::info!(
            edmd_event = "short",
            edmd_program = program,
            edmd_line = line,
            "{program}:{line}: short circuit at t={t:.4} s (segment {}, step {}): turning back",
            at.seq,
            at.event
        ),
        ServoEvent::Cleared { depth } => tracing::info!(
            edmd_event = "turn_back",
            edmd_program = program,
            edmd_line = line,
            "{program}:{line}: gap cleared at t={t:.4} s after turning back over {depth} blocks: re-advancing"
        ),
        ServoEvent::Resumed { .. } => {
            tracing::debug!("{program}:{line}: back at the short at t={t:.4} s: machining on")
        }
        ServoEvent::Starved { at } => tracing::warn!(
            "{program}:{line}: loop buffer empty at t={t:.4} s (segment {}): holding",
            at.seq
        ),
        ServoEvent::Done => tracing::info!("{program}: program end at t={t:.4} s"),
        ServoEvent::Condition { number } => tracing::info!(
            edmd_event = "condition",
            edmd_program = program,
            edmd_line = line,
            "{program}:{line}: machining condition E{number} from t={t:.4} s"
        ),
        ServoEvent::Override { rapid, percent } => tracing::info!(
            edmd_event = "override",
            edmd_program = program,
            edmd_line = line,
            "{program}:{line}: {} override {percent} % from t={t:.4} s",
            if rapid { "rapid" } else { "feed" }
        ),
        ServoEvent::PassStart { number } => tracing::info!(
            edmd_event = "pass",
            edmd_program = program,
            edmd_line = line,
            "{program}:{line}: pass {number} starts at t={t:.4} s"
        ),
        ServoEvent::Flushing { on } => tracing::info!(
            edmd_event = "flushing",
            edmd_program = program,
            edmd_line = line,
            "{program}:{line}: flushing {} at t={t:.4} s",
            if on { "on" } else { "off" }
        ),
        event @ (ServoEvent::Alarm { .. }
        | ServoEvent::Collision { .. }
        | ServoEvent::Paused { .. }
        | ServoEvent::WireBreak { .. }
        | ServoEvent::ProbeMissed { .. }) => log_stop(program, line, t, event, pauses),
        event => log_excursion(program, line, t, event, spec),
    }
}

/// The events that stop the motion: alarms, collisions, programmed stops, wire breaks, a
/// missed probe. `pauses`: an operator is there to resume (the daemon).
fn log_stop(program: &str, line: u64, t: f64, event: ServoEvent, pauses: bool) {
    match event {
        ServoEvent::Alarm {
            at,
            depth,
            timed_out,
        } => tracing::error!(
            edmd_event = "alarm",
            edmd_program = program,
            edmd_line = line,
            "{program}:{line}: ALARM at t={t:.4} s: {} ({depth} blocks back, segment {}); motion \
             stopped, position kept{}",
            if timed_out {
                "the short outlasted servo.max_short_s while turning back"
            } else {
                "still shorted after turning back over the whole reserved area"
            },
            at.seq,
            if pauses {
                "; the job holds: flush the gap, then `edmd ctl resume` re-advances"
            } else {
                ""
            }
        ),
        ServoEvent::Collision { at } => tracing::error!(
            edmd_event = "collision",
            edmd_program = program,
            edmd_line = line,
            "{program}:{line}: COLLISION at t={t:.4} s: the gap shorted during a rapid (segment {}, \
             step {}); motion stopped, position kept{}",
            at.seq,
            at.event,
            if pauses {
                "; the job holds until `edmd ctl resume`"
            } else {
                ""
            }
        ),
        ServoEvent::Paused {
            kind: PauseKind::SingleBlock,
            ..
        } => tracing::info!(
            edmd_event = "single_block",
            edmd_program = program,
            edmd_line = line,
            "{program}:{line}: single block: stopped before this line at t={t:.4} s: \
             `edmd ctl resume` runs it"
        ),
        ServoEvent::Paused {
            kind: PauseKind::Slug,
            ..
        } => tracing::warn!(
            edmd_event = "slug",
            edmd_program = program,
            edmd_line = line,
            "{program}:{line}: TAB: the passes are done up to the tab at t={t:.4} s: secure the \
             slug, then {}",
            if pauses {
                "`edmd ctl resume` cuts the tab"
            } else {
                "(edmd run has no operator channel: the tab is cut at once)"
            }
        ),
        ServoEvent::Paused { .. } => tracing::warn!(
            edmd_event = "pause",
            edmd_program = program,
            edmd_line = line,
            "{program}:{line}: programmed stop (M0/M1) before this line at t={t:.4} s: {}",
            if pauses {
                "paused until `edmd ctl resume`"
            } else {
                "not waiting (edmd run has no operator channel; edmd serve holds the job here)"
            }
        ),
        ServoEvent::WireBreak { at, open } => tracing::error!(
            edmd_event = "wire_break",
            edmd_program = program,
            edmd_line = line,
            "{program}:{line}: WIRE BREAK at t={t:.4} s ({}; segment {}, step {}): motion \
             stopped, position kept{}",
            if open {
                "the gap stayed open over servo.max_open_mm of cutting"
            } else {
                "the wire-break input"
            },
            at.seq,
            at.event,
            if pauses {
                "; the job holds: `edmd ctl rethread` goes back to the start hole (`--here`: \
                 thread where it broke), then `edmd ctl resume`"
            } else {
                ""
            }
        ),
        ServoEvent::ProbeMissed { .. } => tracing::error!(
            edmd_event = "probe_missed",
            edmd_program = program,
            edmd_line = line,
            "{program}:{line}: the probing move reached its end point without contact at \
             t={t:.4} s: the job stops"
        ),
        // The others are logged by log_event.
        _ => {}
    }
}

/// Jumps, rethreads and probes.
fn log_excursion(program: &str, line: u64, t: f64, event: ServoEvent, spec: &JobSpec) {
    match event {
        ServoEvent::Jump { at } => tracing::debug!(
            "{program}:{line}: jump at t={t:.4} s (segment {}, step {})",
            at.seq,
            at.event
        ),
        ServoEvent::Retreated {
            why: Excursion::Jump,
            mm,
            ..
        } => tracing::debug!("{program}:{line}: jump up {mm:.4} mm at t={t:.4} s: coming down"),
        ServoEvent::Retreated {
            why: Excursion::Rethread,
            at,
            mm,
            exhausted,
        } => tracing::warn!(
            edmd_event = "rethread",
            edmd_program = program,
            edmd_line = line,
            "{program}:{line}: back {mm:.3} mm along the path at t={t:.4} s (segment {}, step {}){}: \
             thread the wire, then `edmd ctl resume` returns to the break point",
            at.seq,
            at.event,
            if exhausted {
                ", as far as the executed blocks kept go (buffer.reserved): short of the start hole"
            } else {
                ", at the start hole"
            }
        ),
        ServoEvent::Returned {
            why: Excursion::Jump,
            ..
        } => tracing::trace!("{program}:{line}: down from the jump at t={t:.4} s"),
        ServoEvent::Returned {
            why: Excursion::Rethread,
            at,
        } => tracing::info!(
            edmd_event = "rethreaded",
            edmd_program = program,
            edmd_line = line,
            "{program}:{line}: back at the break point at t={t:.4} s (segment {}, step {}): \
             cutting on",
            at.seq,
            at.event
        ),
        ServoEvent::Probed {
            steps,
            contact,
            away,
            ..
        } => tracing::info!(
            edmd_event = "probe",
            edmd_program = program,
            edmd_line = line,
            "{program}:{line}: probe {} at t={t:.4} s: {}",
            match (contact, away) {
                (true, false) => "contact",
                (true, true) => "contact lost",
                (false, false) => "reached its end point without contact",
                (false, true) => "reached its end point still in contact",
            },
            spec.position_text(&steps)
        ),
        ServoEvent::Breakthrough {
            steps,
            last_spark,
            found: true,
            ..
        } => tracing::info!(
            edmd_event = "breakthrough",
            edmd_program = program,
            edmd_line = line,
            "{program}:{line}: breakthrough at t={t:.4} s: the last spark at {}, stopped at {} \
             ({:.4} mm further): the program goes on from there",
            spec.position_text(&last_spark),
            spec.position_text(&steps),
            spec.distance_mm(&last_spark, &steps)
        ),
        ServoEvent::Breakthrough {
            steps,
            found: false,
            ..
        } => tracing::warn!(
            edmd_event = "no_breakthrough",
            edmd_program = program,
            edmd_line = line,
            "{program}:{line}: the drilling move reached its end at {} at t={t:.4} s without \
             breaking through",
            spec.position_text(&steps)
        ),
        // The others are logged by log_event.
        _ => {}
    }
}

/// Hands a batch of samples and servo events to the recording, in tick order.
pub(crate) fn record_batch(recording: &mut Recording, recorder: &Recorder, events: &[EventRecord]) {
    let mut events = events.iter().peekable();
    let mut take_events = |recording: &mut Recording, before: u64| {
        while let Some(e) = events.next_if(|e| e.tick <= before) {
            let (kind, depth) = match e.event {
                ServoEvent::Short { .. } => (EventKind::Short, None),
                ServoEvent::Cleared { depth } => (EventKind::TurnBack, Some(depth)),
                ServoEvent::Resumed { .. } => (EventKind::Resumed, None),
                ServoEvent::Starved { .. } => (EventKind::Starved, None),
                ServoEvent::Alarm { depth, .. } => (EventKind::Alarm, Some(depth)),
                ServoEvent::Done => (EventKind::Done, None),
                ServoEvent::Paused { .. } => (EventKind::Pause, None),
                ServoEvent::Collision { .. } => (EventKind::Collision, None),
                ServoEvent::Condition { number } => (EventKind::Condition, Some(number as u64)),
                ServoEvent::PassStart { number } => (EventKind::Pass, Some(u64::from(number))),
                ServoEvent::Flushing { on: true } => (EventKind::FlushOn, None),
                ServoEvent::Flushing { on: false } => (EventKind::FlushOff, None),
                ServoEvent::Override { rapid, percent } => (
                    if rapid {
                        EventKind::RapidOverride
                    } else {
                        EventKind::FeedOverride
                    },
                    Some(u64::from(percent)),
                ),
                ServoEvent::Jump { .. } => (EventKind::Jump, None),
                ServoEvent::Retreated { .. } | ServoEvent::Returned { .. } => continue,
                ServoEvent::WireBreak { .. } => (EventKind::WireBreak, None),
                ServoEvent::Probed { contact, .. } => (EventKind::Probe, Some(contact as u64)),
                ServoEvent::ProbeMissed { .. } => (EventKind::ProbeMissed, None),
                ServoEvent::Breakthrough { found, .. } => {
                    (EventKind::Breakthrough, Some(found as u64))
                }
            };
            recording.event(e.tick, e.line, kind, depth);
        }
    };
    recorder.drain(|sample| {
        take_events(recording, sample.tick.saturating_sub(1));
        recording.sample(sample);
    });
    take_events(recording, u64::MAX);
}
