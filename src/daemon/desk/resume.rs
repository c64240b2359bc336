//! Where a resume starts: the checkpoint's job replayed from its start, refused when the
//! machine moved since or the work offsets changed (the same program would resume in another
//! place), unless forced.
//!
//! **A run from a line after a stop.** Where the wire stands: the operator says it, the desk
//! holds it to what the machine knows.
//!
//! A wire in the work can only move along the kerf it cut. A run from a line by the path
//! therefore needs to know where the wire stands (`--wire-at`): at the program's start hole,
//! or where a stopped job of the same program stopped. The stopped job's checkpoint (the
//! current one or the one kept aside) says both where that job started and where it
//! stopped; the machine's position says where the wire is. The desk checks the two agree
//! and hands the path the end of the kerf ([`crate::path::from_line`] does the rest):
//!
//! | wire at      | stopped job of this program | the job starts (program read from)  |
//! |--------------|-----------------------------|-------------------------------------|
//! | `start-hole` | none                        | here (trusting the operator)        |
//! | `start-hole` | yes: machine at its start   | here; kerf ends where it stopped    |
//! | `stopped`    | yes: machine where it stopped | its start; the wire here, the kerf's end |
//!
//! Anything else is refused, in the program's work coordinates, with what to do. A direct
//! approach (a sinker's) lifts out of the cut and needs none of this.

use super::super::refusal::Refusal;
use super::Desk;
use crate::checkpoint::Checkpoint;
use crate::gcode::{WorkStart, WorkSystem};
use crate::geometry::Point;
use crate::path::{Approach, FromLine, WireAt, from_line::ON_PATH_MM};

/// How a run from a line recovers: where the program is read from, where the kerf ends, and
/// the program (SHA-256) whose kerf it is.
#[derive(Debug, Clone, PartialEq)]
pub(in crate::daemon) struct Recovery {
    pub start: WorkStart,
    pub kerf_end: Option<Point>,
    pub sha256: Option<String>,
}

impl Desk<'_> {
    /// Where the checkpoint's job started: the resume replays it from there. Refused when the
    /// work offsets it started with differ from the machine's now (unless `force`): the same
    /// program would resume in another place.
    pub fn resume_start(&self, cp: &Checkpoint, force: bool) -> Result<WorkStart, Refusal> {
        let machine = &self.config.machine;
        // The machine must stand where the checkpoint's job stopped (a jog or MDI since
        // moved it): a resume walks there without moving.
        let here = &self.machine.state.position[..machine.axes.len()];
        if here != cp.position_steps.as_slice() {
            let mm = |steps: &[i64]| {
                steps
                    .iter()
                    .zip(&machine.step_mm)
                    .zip(&machine.axes)
                    .map(|((s, mm), a)| format!("{a}{:.4}", *s as f64 * mm))
                    .collect::<Vec<_>>()
                    .join(" ")
            };
            if !force {
                return Err(Refusal::NotAtCheckpoint {
                    here: mm(here),
                    checkpoint: mm(&cp.position_steps),
                });
            }
            tracing::warn!(
                "resume --force: the machine stands at {}, the checkpoint at {}",
                mm(here),
                mm(&cp.position_steps)
            );
        }
        let Some(record) = &cp.start else {
            return Ok(WorkStart::default());
        };
        let start = record
            .work_start(&machine.axes, &machine.step_mm)
            .map_err(|e| Refusal::MachineState(format!("the checkpoint's start: {e}")))?;
        let now = &self.machine.state.offsets;
        let mut changed = Vec::new();
        for system in WorkSystem::all() {
            let (was, is) = (start.offsets.get(system), now.get(system));
            for (i, axis) in machine.axes.iter().enumerate() {
                if (was[i] - is[i]).abs() > 1e-9 {
                    changed.push(format!(
                        "{system} {axis}: {:.4} then, {:.4} now",
                        was[i], is[i]
                    ));
                }
            }
        }
        if !changed.is_empty() {
            if !force {
                return Err(Refusal::OffsetsChanged {
                    changed: changed.join("; "),
                });
            }
            tracing::warn!(
                "resume --force: the work offsets changed ({}); the job resumes with the \
                 offsets it started with",
                changed.join("; ")
            );
        }
        Ok(start)
    }

    /// A run from `from` of `program`, with `wire_at` as the operator says and `stopped` the
    /// kept checkpoint of that program, if any.
    pub(in crate::daemon) fn recovery(
        &self,
        program: &str,
        from: &FromLine,
        wire_at: Option<WireAt>,
        stopped: Option<&Checkpoint>,
    ) -> Result<Recovery, Refusal> {
        let here = self.machine.state.work_start();
        let plain = Recovery {
            start: here.clone(),
            kerf_end: None,
            sha256: None,
        };
        if from.approach == Approach::Direct {
            return match wire_at {
                None => Ok(plain),
                Some(_) => Err(Refusal::BadArgument(
                    "a direct approach lifts out of the cut to reach the line: --wire-at is \
                     for the path approach (a wire in its kerf)"
                        .into(),
                )),
            };
        }
        let axes = &self.config.machine.axes;
        let step_mm = &self.config.machine.step_mm;
        let Some(wire_at) = wire_at else {
            return Err(Refusal::WireAtUnsaid {
                at: here.text_of(&here.position_mm, axes),
            });
        };
        let stopped = stopped.and_then(|cp| {
            let start = cp.start.as_ref()?.work_start(axes, step_mm).ok()?;
            Some((cp, start))
        });
        let apart = |a: &Point, b: &Point| (a - b).norm() > ON_PATH_MM;
        match (wire_at, stopped) {
            (WireAt::StartHole, None) => Ok(plain),
            (WireAt::StartHole, Some((cp, start))) => {
                if apart(&here.position_mm, &start.position_mm) {
                    let stood = !apart(&here.position_mm, &cp.stopped_at());
                    return Err(Refusal::NotAtStartHole {
                        program: program.to_string(),
                        at: start.text_of(&here.position_mm, axes),
                        start_hole: start.text_of(&start.position_mm, axes),
                        stopped_here: stood,
                    });
                }
                Ok(Recovery {
                    kerf_end: Some(cp.stopped_at()),
                    sha256: Some(cp.program_sha256.clone()),
                    ..plain
                })
            }
            (WireAt::Stopped, None) => Err(Refusal::NoStoppedJob {
                program: program.to_string(),
            }),
            (WireAt::Stopped, Some((cp, start))) => {
                if apart(&here.position_mm, &cp.stopped_at()) {
                    return Err(Refusal::NotWhereItStopped {
                        program: program.to_string(),
                        at: start.text_of(&here.position_mm, axes),
                        stopped: start.text_of(&cp.stopped_at(), axes),
                        line: cp.line,
                    });
                }
                Ok(Recovery {
                    start,
                    kerf_end: Some(here.position_mm),
                    sha256: Some(cp.program_sha256.clone()),
                })
            }
        }
    }
}
