//! Where the wire stands before a run from a line: the operator says it, the desk holds it to
//! what the machine knows.
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

use super::Desk;
use crate::checkpoint::Checkpoint;
use crate::daemon::refusal::Refusal;
use crate::gcode::WorkStart;
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
