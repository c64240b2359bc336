//! The machine's trips: an E-stop or a limit switch that holds it, kept in the state file (a
//! restart does not forget it), seen in a job's end or by the fine thread between jobs, and
//! `reset`, the operator's end of an E-stop's.
//!
//! Functions of the configuration, the machine and what was read; the control loop reads the
//! claimed device's idle watch and hands the reading over.

use super::super::refusal::Refusal;
use super::unwritten;
use crate::config::Config;
use crate::machine::Machine;
use crate::runtime::idle::IdleSeen;
use crate::runtime::{JobSummary, Outcome};
use crate::vocab::{SafetyInputs, Trip};

/// `reset` after an E-stop; `estop_reads`: the E-stop input reads pressed now (or cannot be
/// read), and the reset is refused.
pub(in crate::daemon) fn reset(
    machine: &mut Machine,
    estop_reads: bool,
) -> Result<String, Refusal> {
    match machine.state.trip {
        None => return Err(Refusal::BadArgument("nothing to reset: no E-stop".into())),
        Some(Trip::Limit(switch)) => {
            return Err(Refusal::BadArgument(format!(
                "limit switch {switch}: jog away from it (a jog towards {} on {}); reset \
                 is for the E-stop",
                if switch.positive { "-" } else { "+" },
                switch.axis
            )));
        }
        Some(Trip::EStop) => {}
    }
    if estop_reads {
        return Err(Refusal::BadArgument(
            "the E-stop input still reads pressed: release it first".into(),
        ));
    }
    set(machine, None);
    tracing::warn!(edmd_event = "reset", "reset: the E-stop is cleared");
    Ok("reset: the E-stop is cleared; the machine may move again".into())
}

/// The trip in force, written to the state file when it changes.
fn set(machine: &mut Machine, trip: Option<Trip>) {
    if machine.state.trip != trip {
        machine.state.trip = trip;
        // A failed write is logged and shown in the status; the next one may succeed.
        let _ = machine.save(false).map_err(unwritten);
    }
}

/// What an ended job leaves: an E-stop or a limit switch holds the machine (an E-stop
/// unhomes it with `homing.lost_on_estop`); a limit switch's trip is kept until the job's
/// last reading shows the switch open (a jog away that left it).
pub(in crate::daemon) fn after_job(config: &Config, machine: &mut Machine, summary: &JobSummary) {
    match summary.outcome {
        Outcome::Estop => {
            if config.homing.lost_on_estop {
                machine.state.homed.iter_mut().for_each(|h| *h = false);
            }
            set(machine, Some(Trip::EStop));
        }
        Outcome::Limit => {
            if let Some(switch) = summary.limit_switch {
                set(machine, Some(Trip::Limit(switch)));
            }
        }
        _ if summary.ticks > 0 => {
            if let Some(Trip::Limit(switch)) = machine.state.trip
                && !summary.limits_closed.contains(&switch.to_string())
            {
                tracing::info!("limit switch {switch} reads open: the trip is cleared");
                set(machine, None);
            }
        }
        _ => {}
    }
}

/// What the fine thread saw of the claimed device's inputs while idle, as LinuxCNC reads its
/// inputs when nothing moves: an E-stop pressed (even a pulse already released) or a limit
/// switch closed trips the machine; a limit switch's trip ends when the switch reads open
/// (the axis moved off it by hand, or the switch was freed). An E-stop's trip ends only with
/// [`reset`]. A device that failed (HAL's real-time side gone, a port that stopped
/// answering) trips it as an E-stop. True when it tripped now (a continuous jog's client,
/// still renewing, must not start it again once the trip is cleared).
pub(in crate::daemon) fn watch(machine: &mut Machine, seen: IdleSeen) -> bool {
    if let Some(fault) = seen.fault {
        if machine.state.trip != Some(Trip::EStop) {
            tracing::error!(
                edmd_event = "trip",
                "{fault}: the drives are off and the machine is held as in an E-stop"
            );
            set(machine, Some(Trip::EStop));
        }
        return false;
    }
    let Some(now) = seen.now else {
        return false;
    };
    // An E-stop is decided on what was seen (a pulse latched), a limit switch on what reads
    // now (a switch bouncing while nothing moves stops nothing).
    let latched = SafetyInputs {
        estop: seen.seen.estop || now.estop,
        limits: now.limits,
    };
    match machine.state.trip {
        Some(Trip::EStop) => false,
        Some(Trip::Limit(_)) if latched.estop => trip_idle(machine, Trip::EStop, now.estop),
        Some(Trip::Limit(switch)) if !now.limits.contains(switch) => {
            let next = Trip::of(now);
            tracing::info!(
                "limit switch {switch} reads open{}",
                match next {
                    Some(t) => format!("; now {}", t.name()),
                    None => ": the trip is cleared".to_string(),
                }
            );
            set(machine, next);
            false
        }
        Some(Trip::Limit(_)) => false,
        None => match Trip::of(latched) {
            Some(trip) => {
                let still = match trip {
                    Trip::EStop => now.estop,
                    Trip::Limit(s) => now.limits.contains(s),
                };
                trip_idle(machine, trip, still)
            }
            None => false,
        },
    }
}

/// An E-stop or a limit switch seen while idle; `still`: it reads so now (else it was a pulse
/// the fine thread latched). Always true: the machine tripped.
fn trip_idle(machine: &mut Machine, trip: Trip, still: bool) -> bool {
    tracing::warn!(
        edmd_event = "trip",
        "{}{} while idle: nothing moves until it is cleared",
        match trip {
            Trip::EStop => "E-stop pressed".to_string(),
            Trip::Limit(s) => format!("limit switch {s} closed"),
        },
        if still {
            ""
        } else {
            " (a pulse, released since)"
        }
    );
    set(machine, Some(trip));
    true
}
