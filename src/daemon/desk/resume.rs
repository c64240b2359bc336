//! Where a resume starts: the checkpoint's job replayed from its start, refused when the
//! machine moved since or the work offsets changed (the same program would resume in another
//! place), unless forced.

use super::super::refusal::Refusal;
use super::Desk;
use crate::checkpoint::Checkpoint;
use crate::gcode::{WorkStart, WorkSystem};

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
}
