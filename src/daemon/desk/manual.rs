//! Motion the operator asks for by hand: a jog (one positioning move on one axis, spark off,
//! held to the soft limits) and MDI (G-code lines typed in). Both become jobs through the same
//! pipeline as a program (check, soft limits, servo, turn-back, checkpoints, the state
//! file's write-ahead), from program text made here. A continuous jog's renewals and its
//! dead-man are the control loop's (they follow the job in hand).

use std::time::Duration;

use super::super::refusal::Refusal;
use super::{Desk, JobKind, Order};
use crate::machine::travel::{JogEnd, jog_end};
use crate::vocab::Axis;

/// Longest MDI text accepted, bytes.
const MAX_MDI_BYTES: usize = 16 * 1024;
/// Longest jog, mm (and how far a continuous jog aims on an axis without soft limits).
const MAX_JOG_MM: f64 = 1.0e4;
/// How long a continuous jog moves without a renewal.
pub(in crate::daemon) const DEAD_MAN: Duration = Duration::from_millis(250);

/// `+` or `-`: a direction as a jog names it.
pub(in crate::daemon) fn sign(positive: bool) -> char {
    if positive { '+' } else { '-' }
}

/// `jog AXIS DISTANCE [--feed F]`: a `G53 G0` to where the axis would be, at the jog feed
/// (at most `machine.max_jog_feed_mm_per_min`), stopped at the soft limit it would pass.
pub(in crate::daemon) fn jog(
    desk: Desk,
    axis: &str,
    distance_mm: f64,
    feed: Option<f64>,
) -> Result<Order, Refusal> {
    let (i, axis) = desk.axis(axis)?;
    desk.refuse_if_tripped(Some((axis, distance_mm > 0.0)))?;
    desk.refuse_if_unhomed()?;
    // Less than a step moves nothing: it would be a jog that never ends or never starts.
    let step = desk.config.machine.step_mm[i];
    if !distance_mm.is_finite() || distance_mm.abs() < step || distance_mm.abs() > MAX_JOG_MM {
        return Err(Refusal::BadArgument(format!(
            "jog distance {distance_mm} mm: give a move of at least one step ({step} mm on \
             {axis}) and at most {MAX_JOG_MM} mm, either way"
        )));
    }
    let feed = jog_feed(desk, feed)?;
    let here = desk.machine.state.position_mm()[i];
    let (target, note) = jog_target(desk, i, axis, distance_mm)?;
    Ok(jog_job(
        desk,
        axis,
        target,
        feed,
        format!("jog {axis} {here:.4} -> {target:.4} mm at {feed:.0} mm/min{note}"),
    ))
}

/// A new continuous jog of axis `i` (`letter`) towards the soft limit (or [`MAX_JOG_MM`]),
/// once the loop has found no jog to renew.
pub(in crate::daemon) fn continuous(
    desk: Desk,
    i: usize,
    letter: Axis,
    positive: bool,
    feed: Option<f64>,
) -> Result<Order, Refusal> {
    desk.refuse_if_tripped(Some((letter, positive)))?;
    desk.refuse_if_unhomed()?;
    let feed = jog_feed(desk, feed)?;
    let way = if positive { MAX_JOG_MM } else { -MAX_JOG_MM };
    let (target, note) = jog_target(desk, i, letter, way)?;
    Ok(jog_job(
        desk,
        letter,
        target,
        feed,
        format!(
            "jog {letter}{} at {feed:.0} mm/min while renewed every {} ms{note}",
            sign(positive),
            DEAD_MAN.as_millis()
        ),
    ))
}

/// The jog feed asked for, capped at `machine.max_jog_feed_mm_per_min`.
fn jog_feed(desk: Desk, feed: Option<f64>) -> Result<f64, Refusal> {
    let max = desk.config.machine.max_jog_feed_mm_per_min;
    let min = crate::vocab::MIN_FEED_MM_PER_MIN;
    match feed {
        None => Ok(max),
        Some(f) if f.is_finite() && f >= min => Ok(f.min(max)),
        Some(f) => Err(Refusal::BadArgument(format!(
            "jog feed {f} mm/min: at least {min} mm/min (a micrometre a minute), at most \
             machine.max_jog_feed_mm_per_min = {max}"
        ))),
    }
}

/// Where a jog of `distance_mm` on axis `i` ends: clamped to the soft limit it would pass
/// (with a note), refused when the axis already stands at or past it.
fn jog_target(
    desk: Desk,
    i: usize,
    axis: Axis,
    distance_mm: f64,
) -> Result<(f64, String), Refusal> {
    let here = desk.machine.state.position_mm()[i];
    match jog_end(here, distance_mm, desk.config.machine.travel[i]) {
        JogEnd::Full(target) => Ok((target, String::new())),
        JogEnd::AtLimit(limit) => Ok((limit, format!(" (stops at the soft limit {limit} mm)"))),
        JogEnd::Past(limit) => Err(Refusal::BadArgument(format!(
            "{axis} stands at {here:.4} mm, at or past its {} soft limit {limit} mm: \
             jog the other way",
            if distance_mm > 0.0 { "upper" } else { "lower" }
        ))),
    }
}

/// The job of a jog to machine coordinate `target` on `axis`.
fn jog_job(desk: Desk, axis: Axis, target: f64, feed: f64, said: String) -> Order {
    let text = format!("G21 G90\nG53 G0 {}{target:.6}\n", axis.letter());
    let kind = JobKind::Jog {
        feed_mm_per_min: feed,
    };
    Order::generated(desk, "jog", text, kind, said)
}

/// `mdi LINES`: the lines as a job, checked like a program (soft limits included), in the
/// work system and offsets of the machine and the units and distance mode the last MDI
/// lines left.
pub(in crate::daemon) fn mdi(desk: Desk, lines: &str) -> Result<Order, Refusal> {
    desk.refuse_if_tripped(None)?;
    desk.refuse_if_unhomed()?;
    if lines.trim().is_empty() || lines.len() > MAX_MDI_BYTES {
        return Err(Refusal::BadArgument(format!(
            "MDI needs 1 to {MAX_MDI_BYTES} bytes of G-code"
        )));
    }
    let text = format!("{}\n", lines.trim_end());
    let mut order = Order::generated(desk, "mdi", text, JobKind::Mdi, "mdi: checking".into());
    order.launch.start.modes = desk.machine.mdi_modes;
    Ok(order)
}
