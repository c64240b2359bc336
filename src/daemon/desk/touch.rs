//! `find`: the wire-touch cycles ([`crate::touch`] is their arithmetic).
//!
//! A cycle is a sequence of jobs, one per move, each from program text the cycle writes and
//! each through the same pipeline as any program (check, soft limits, E-stop and limit
//! switches, the state file's write-ahead). When a move's job ends, its end point and its
//! last probe go back to the cycle, which answers with the next move or the result; anything
//! but a clean end (an abort, an E-stop, a refused check) ends the cycle as failed. The result
//! is logged, shown in the status (`machine.find`), and with `--system` written into that
//! work offset as `G10 L20` would: the found edge, corner or centre reads 0 there.
//!
//! [`TouchCycles`] owns the cycle in hand and the status; the control loop only launches the
//! moves it orders and hands back how each ended.

use super::super::protocol::FindStatus;
use super::super::refusal::Refusal;
use super::{Desk, JobKind, Order};
use crate::config::Config;
use crate::gcode::WorkSystem;
use crate::machine::Machine;
use crate::runtime::{JobSummary, Outcome};
use crate::touch::{FindCycle, FindSettings, Found, MoveEnd, MoveKind, Next, Target};

/// A cycle in progress.
struct FindRun {
    id: u64,
    cycle: FindCycle,
    /// The work system the result goes into.
    system: Option<WorkSystem>,
    /// Indices of X and Y in the machine's axes.
    plane: [usize; 2],
}

/// The touch cycles: the one in progress and the running or last one, as the status shows
/// it.
#[derive(Default)]
pub(in crate::daemon) struct TouchCycles {
    run: Option<FindRun>,
    status: Option<FindStatus>,
}

impl TouchCycles {
    /// The running or last cycle, as the status shows it.
    pub fn status(&self) -> Option<&FindStatus> {
        self.status.as_ref()
    }

    /// `find TARGET [--system G5x]`: the cycle's first move.
    pub fn start(
        &mut self,
        config: &Config,
        machine: &mut Machine,
        target: &str,
        system: Option<&str>,
    ) -> Result<Order, Refusal> {
        let desk = Desk { config, machine };
        desk.refuse_if_tripped(None)?;
        desk.refuse_if_unhomed()?;
        let target = Target::parse(target).map_err(|e| Refusal::BadArgument(e.to_string()))?;
        let plane = config.machine.plane_axes().ok_or_else(|| {
            Refusal::BadArgument(format!(
                "find touches in the X/Y plane: this machine's axes are {}",
                config.machine.axis_names().join(", ")
            ))
        })?;
        let system = system
            .map(|name| {
                WorkSystem::parse(name).ok_or_else(|| {
                    Refusal::BadArgument(format!("{name:?} is not a work system (G54 … G59.3)"))
                })
            })
            .transpose()?;
        let settings = FindSettings::from_config(config, plane);
        let condition = settings.touch.condition;
        if !config.conditions.iter().any(|c| c.number == condition) {
            return Err(Refusal::BadArgument(format!(
                "wire.touch_condition = {condition} is not one of [generator] condition: add \
                 the generator's least-energy condition for touching, or name one"
            )));
        }
        let position = machine.state.position_mm();
        let mut cycle = FindCycle::new(target, settings, plane.map(|i| position[i]));
        let id = self.status.as_ref().map_or(1, |s| s.id + 1);
        let first = cycle.begin();
        self.status = Some(FindStatus {
            id,
            target: target.name(),
            state: "running".into(),
            message: "touching".into(),
            point_mm: Vec::new(),
            diameter_mm: None,
            system: system.map(|s| s.name().to_string()),
        });
        self.run = Some(FindRun {
            id,
            cycle,
            system,
            plane,
        });
        let t = &settings.touch;
        let said = format!(
            "find {id}: {}: touching in E{} at {:.0} mm/min",
            target.name(),
            t.condition,
            t.feed_mm_per_min
        );
        tracing::info!(
            edmd_event = "find",
            "{said}{}",
            system.map(|s| format!(", into {s}")).unwrap_or_default()
        );
        // A first move is all a cycle can answer at its start; anything else ended it.
        match self.next(config, machine, first) {
            Some(order) => Ok(Order { said, ..order }),
            None => Err(Refusal::BadArgument(
                self.status
                    .as_ref()
                    .map_or_else(String::new, |s| s.message.clone()),
            )),
        }
    }

    /// A move's job ended: its end and last probe go back to the cycle, which orders the next
    /// move or ends (a found target written into its work system on `machine`).
    pub fn moved(
        &mut self,
        config: &Config,
        machine: &mut Machine,
        summary: &JobSummary,
    ) -> Option<Order> {
        let run = self.run.as_mut()?;
        if summary.outcome != Outcome::Done {
            let why = summary
                .error
                .clone()
                .unwrap_or_else(|| summary.outcome.name().to_string());
            self.fail(&format!("the move did not end: {why}"));
            return None;
        }
        let step = &config.machine.step_mm;
        let at_mm = run
            .plane
            .map(|i| summary.end_steps.get(i).copied().unwrap_or(0) as f64 * step[i]);
        let probe = &summary.last_probe;
        let contact_mm = match (&probe.probe_mm, probe.probe_contact) {
            (Some(mm), Some(true)) => Some(run.plane.map(|i| mm[i])),
            _ => None,
        };
        let next = run.cycle.moved(MoveEnd { at_mm, contact_mm });
        self.next(config, machine, next)
    }

    /// A move's check was refused: the cycle ends.
    pub fn refused(&mut self, why: &str) {
        if self.run.is_some() {
            self.fail(&format!("a move was refused: {why}"));
        }
    }

    /// The job of the cycle's next move, or its end.
    fn next(
        &mut self,
        config: &Config,
        machine: &mut Machine,
        next: Result<Next, crate::touch::FindError>,
    ) -> Option<Order> {
        match next {
            Ok(Next::Run(m)) => {
                // A file name: `find-approach-xplus`.
                let slug = |s: crate::touch::Side| {
                    s.name()
                        .to_lowercase()
                        .replace('+', "plus")
                        .replace('-', "minus")
                };
                let name = match m.kind {
                    MoveKind::Approach(s) => format!("find-approach-{}", slug(s)),
                    MoveKind::Retouch(s) => format!("find-retouch-{}", slug(s)),
                    MoveKind::Position => "find-position".to_string(),
                };
                let kind = JobKind::Touch {
                    feed_mm_per_min: config.wire.touch.feed_mm_per_min,
                    first: m.first,
                };
                let desk = Desk {
                    config,
                    machine: &*machine,
                };
                Some(Order::generated(
                    desk,
                    &name,
                    m.program,
                    kind,
                    String::new(),
                ))
            }
            Ok(Next::Done(found)) => {
                self.found(machine, found);
                None
            }
            Err(e) => {
                self.fail(&e.to_string());
                None
            }
        }
    }

    fn fail(&mut self, why: &str) {
        let Some(run) = self.run.take() else {
            return;
        };
        let message = format!("{} failed: {why}", run.cycle.target().name());
        tracing::error!(edmd_event = "find_failed", "find {}: {message}", run.id);
        if let Some(s) = &mut self.status {
            s.state = "failed".into();
            s.message = message;
        }
    }

    /// The cycle found its target: log it, show it, write the offset.
    fn found(&mut self, machine: &mut Machine, found: Found) {
        let Some(run) = self.run.take() else {
            return;
        };
        let mut message = found_text(&found);
        if let Some(system) = run.system {
            match write_found(machine, system, run.plane, &found) {
                Ok(written) => message.push_str(&format!("; {system} {written} there")),
                Err(e) => {
                    // Put back to report the failure as the cycle's.
                    self.run = Some(run);
                    self.fail(&e.to_string());
                    return;
                }
            }
        }
        tracing::info!(edmd_event = "find", "find {}: {message}", run.id);
        if let Some(s) = &mut self.status {
            s.state = "found".into();
            s.message = message;
            s.point_mm = found.point_mm.to_vec();
            s.diameter_mm = found.diameter_mm;
        }
    }
}

/// `G10 L20` at the found point: its coordinates read 0 in `system`. Returns `X0 Y0`.
fn write_found(
    machine: &mut Machine,
    system: WorkSystem,
    plane: [usize; 2],
    found: &Found,
) -> Result<String, Refusal> {
    let state = &mut machine.state;
    let before = *state.offsets.get(system);
    let mut offset = before;
    let mut said = Vec::new();
    for (k, &i) in plane.iter().enumerate() {
        if let Some(mm) = found.point_mm[k] {
            offset[i] = mm;
            said.push(format!("{}0", ['X', 'Y'][k]));
        }
    }
    state.offsets.set(system, offset);
    if let Err(e) = machine.save(false).map_err(super::unwritten) {
        machine.state.offsets.set(system, before);
        return Err(e);
    }
    Ok(said.join(" "))
}

/// What a cycle found, as the log and the status say it.
fn found_text(f: &Found) -> String {
    let coord = |k: usize| f.point_mm[k].map(|v| format!("{}{v:.4}", ['X', 'Y'][k]));
    let point = [coord(0), coord(1)]
        .into_iter()
        .flatten()
        .collect::<Vec<_>>()
        .join(" ");
    let wire = f
        .wire_mm
        .iter()
        .enumerate()
        .filter_map(|(k, v)| v.map(|v| format!("{}{v:.4}", ['X', 'Y'][k])))
        .collect::<Vec<_>>()
        .join(" ");
    let tally = format!(
        "{} touch{}, {} retr{}",
        f.touches,
        if f.touches == 1 { "" } else { "es" },
        f.retries,
        if f.retries == 1 { "y" } else { "ies" }
    );
    match (f.target, f.diameter_mm) {
        (Target::Center, Some([dx, dy])) => format!(
            "hole centre {point}, diameter {:.4} mm (X {dx:.4}, Y {dy:.4}), {} rounds, {tally}",
            (dx + dy) / 2.0,
            f.rounds
        ),
        (target, _) => format!(
            "{} at {point} (machine; the wire touched at {wire}, its radius added), {tally}",
            target.name()
        ),
    }
}
