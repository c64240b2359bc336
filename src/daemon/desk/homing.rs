//! Homing: where the machine is, found by its switches (`home`) or declared (`home --here`).
//!
//! Homing by a switch is a job like any other (check, pipeline, E-stop and limits read every
//! tick, the state file's write-ahead), from program text made here: a probing search towards
//! the switch, a probing back-off until it releases, a slow probing approach until it closes
//! again (the latch), then the final move. The gap input reads the axis's switch as the
//! probe's contact for that job ([`crate::vocab::HomeSwitch`]). When the job ends the axis's
//! position is rebased: the latch point becomes `home_position_mm`, and the steps taken
//! since (the final move) are kept. Axes home one job at a time in `sequence` order; the
//! next starts when the last one has latched, and a failure stops the rest.
//!
//! Soft limits do not apply to a homing job (the position is not known yet); the search
//! distance bounds it.

use super::super::refusal::Refusal;
use super::{Desk, Order};
use crate::config::{Config, GapKind, HomingAxis, OutputKind};
use crate::machine::Machine;
use crate::runtime::{JobSummary, LastProbe, Outcome};
use crate::vocab::{Axis, HomeSwitch};

/// The program that homes one axis (G91 probing moves, mm).
pub(in crate::daemon) fn homing_program(h: &HomingAxis) -> String {
    let s = if h.positive { 1.0 } else { -1.0 };
    let a = h.axis.letter();
    let mut text = format!(
        "G21 G91 (home {a}: search, back off, latch)\n\
         G38.2 {a}{:.6} F{:.3}\n\
         G38.4 {a}{:.6} F{:.3}\n\
         G38.2 {a}{:.6} F{:.3}\n",
        s * h.search_distance_mm,
        h.search_feed_mm_per_min,
        -s * h.latch_distance_mm,
        h.latch_feed_mm_per_min,
        s * h.latch_distance_mm,
        h.latch_feed_mm_per_min,
    );
    if h.final_move_mm != 0.0 {
        text.push_str(&format!("G0 {a}{:.6} (final move)\n", h.final_move_mm));
    }
    text.push_str("G90\n");
    text
}

/// `home --here [AXIS…] [--force]`: the axes are declared homed where they stand: at their
/// `home_position_mm` when they have a `[[homing.axis]]`, else at machine zero. Without axes
/// named, the axes without a switch. An axis with a switch is its switch's to home: declared
/// only with `force`, and the shift of its coordinates is reported (soft limits and work
/// offsets move with it). The machine is saved (and left as it was if it cannot be).
pub(in crate::daemon) fn here(
    config: &Config,
    machine: &mut Machine,
    axes: &[String],
    force: bool,
) -> Result<String, Refusal> {
    let desk = Desk { config, machine };
    let homing = &config.homing;
    let picked: Vec<(usize, Axis)> = if axes.is_empty() && !force {
        let free: Vec<_> = desk
            .axes(axes)?
            .into_iter()
            .filter(|(i, _)| homing.axis(*i).is_none())
            .collect();
        if free.is_empty() {
            return Err(Refusal::BadArgument(
                "every axis has a home switch: `home` homes them by it; `home --here AXIS \
                 --force` declares one homed where it stands"
                    .into(),
            ));
        }
        free
    } else {
        desk.axes(axes)?
    };
    let switched: Vec<String> = picked
        .iter()
        .filter(|(i, _)| homing.axis(*i).is_some())
        .map(|(_, a)| a.to_string())
        .collect();
    if !force && !switched.is_empty() {
        return Err(Refusal::BadArgument(format!(
            "{} {} a home switch: `home {}` homes by it; `home --here {} --force` declares \
             where it stands to be home_position_mm (moving its soft limits and offsets)",
            switched.join(" "),
            if switched.len() == 1 { "has" } else { "have" },
            switched.join(" "),
            switched.join(" ")
        )));
    }
    let before = machine.state.clone();
    let mut said = Vec::new();
    for &(i, axis) in &picked {
        let home_mm = homing.axis(i).map_or(0.0, |h| h.home_position_mm);
        let step = config.machine.step_mm[i];
        let was = machine.state.position[i];
        let now = (home_mm / step).round() as i64;
        machine.state.position[i] = now;
        let correction = if before.homed.get(i).copied().unwrap_or(false) && was != now {
            format!(
                " (was {:.4}: shifted {:+.4} mm)",
                was as f64 * step,
                (now - was) as f64 * step
            )
        } else {
            String::new()
        };
        machine.state.set_homed(i);
        said.push(format!("{axis}{home_mm:.4}{correction}"));
    }
    if let Err(e) = machine.save(false).map_err(super::unwritten) {
        machine.state = before;
        return Err(e);
    }
    tracing::info!(
        edmd_event = "home",
        "homed here: {} (machine coordinates of where the axes stand)",
        said.join(" ")
    );
    Ok(format!("homed here: {}", said.join(" ")))
}

/// `home [AXIS…]`: the axes to home by their switches (all with a switch when none is
/// named), in `sequence` order, each checked before anything moves.
pub(in crate::daemon) fn by_switch(desk: Desk, axes: &[String]) -> Result<Vec<usize>, Refusal> {
    let config = desk.config;
    let homing = &config.homing;
    // The port's switch pins (HAL's home-sw pins) are read whatever the gap input; without
    // them only a simulated machine (the simulator, a script) has switches.
    if !config.output.kind.hardware() && matches!(config.gap.kind, GapKind::None | GapKind::Iio) {
        return Err(Refusal::BadArgument(format!(
            "gap.kind = \"{}\" reads no home switches: `home --here` declares where the \
             machine stands to be home",
            format!("{:?}", config.gap.kind).to_lowercase()
        )));
    }
    let order: Vec<usize> = if axes.is_empty() {
        if homing.axes.is_empty() {
            return Err(Refusal::BadArgument(
                "no axis has a home switch ([[homing.axis]]): `home --here` declares where \
                 the machine stands to be home"
                    .into(),
            ));
        }
        homing.axes.iter().map(|h| h.index).collect()
    } else {
        let picked = desk.axes(axes)?;
        if let Some((_, axis)) = picked.iter().find(|(i, _)| homing.axis(*i).is_none()) {
            return Err(Refusal::BadArgument(format!(
                "{axis} has no home switch ([[homing.axis]]): `home --here {axis}` declares \
                 where it stands to be its home"
            )));
        }
        // In the configured order, whatever order they were named in.
        homing
            .axes
            .iter()
            .map(|h| h.index)
            .filter(|i| picked.iter().any(|(p, _)| p == i))
            .collect()
    };
    for &i in &order {
        can_home(config, homing.axis(i).expect("a switched axis"))?;
    }
    Ok(order)
}

/// What makes an axis's homing impossible in this configuration, said before it moves.
fn can_home(config: &Config, h: &HomingAxis) -> Result<(), Refusal> {
    let axis = h.axis;
    if config.output.kind == OutputKind::Parport && h.switch_pin.is_none() {
        return Err(Refusal::BadArgument(format!(
            "{axis} has no switch_pin in [[homing.axis]] and this machine reads the parallel \
             port: give the switch's input pin, or `home --here {axis}`"
        )));
    }
    let rest = h.home_position_mm + h.final_move_mm;
    if let Some(t) = config.machine.travel[h.index]
        && !(t.min_mm..=t.max_mm).contains(&rest)
    {
        return Err(Refusal::BadArgument(format!(
            "homing {axis} would end at {rest} mm (home_position_mm + final_move_mm), outside \
             machine.travel_mm [{}, {}]: fix one or the other",
            t.min_mm, t.max_mm
        )));
    }
    Ok(())
}

/// The homing job of axis `i` (it has a `[[homing.axis]]`).
pub(in crate::daemon) fn axis_job(desk: Desk, i: usize) -> Order {
    let config = desk.config;
    let h = config.homing.axis(i).expect("a homed axis").clone();
    let step = config.machine.step_mm[i];
    let state = &desk.machine.state;
    // The simulated switch: at the home position once the axis was homed, else where
    // `sim.home_switch_mm` puts it in the coordinates the machine believes.
    let switch_mm = if state.homed[i] {
        h.home_position_mm
    } else {
        config.sim.home_switch_mm[i].unwrap_or(h.home_position_mm)
    };
    let switch = HomeSwitch {
        axis: i,
        positive: h.positive,
        pin: h.switch_pin,
        at_steps: (switch_mm / step).round() as i64 - state.position[i],
    };
    tracing::info!(
        edmd_event = "homing",
        "homing {}: searching {} at {:.0} mm/min (up to {:.1} mm)",
        h.axis,
        if h.positive { "+" } else { "-" },
        h.search_feed_mm_per_min,
        h.search_distance_mm
    );
    Order::generated(
        desk,
        &format!("home-{}", h.axis),
        homing_program(&h),
        super::JobKind::Home {
            switch,
            feed_mm_per_min: h.search_feed_mm_per_min,
        },
        String::new(),
    )
}

/// A homing job whose probing move found no switch: why, in the words of homing (which move
/// of [`homing_program`] missed, how far it went, what to check), in place of the probing
/// move's "line 2: … segment 39, step 1000".
pub(in crate::daemon) fn say_why_it_failed(
    config: &Config,
    switch: &HomeSwitch,
    summary: &mut JobSummary,
) {
    if summary.outcome != Outcome::ProbeMissed {
        return;
    }
    let Some(h) = config.homing.axis(switch.axis) else {
        return;
    };
    let a = h.axis;
    let toward = if h.positive { "+" } else { "-" };
    let words = match summary.stopped_at.as_ref().map(|s| s.line) {
        Some(2) => format!(
            "homing {a}: the home switch did not close within the search, {:.1} mm {toward}              at {:.0} mm/min: is the axis farther than that from its switch              (homing.axis.search_distance_mm), and does the switch reach its input?",
            h.search_distance_mm, h.search_feed_mm_per_min
        ),
        Some(3) => format!(
            "homing {a}: the home switch closed but did not open again backing off {:.1} mm:              a switch stuck closed, or a latch_distance_mm shorter than its travel",
            h.latch_distance_mm
        ),
        _ => format!(
            "homing {a}: the home switch did not close again on the slow approach within              {:.1} mm (homing.axis.latch_distance_mm): a switch that closes unevenly",
            h.latch_distance_mm
        ),
    };
    summary.error = Some(words);
}

/// How a homing job ended: its outcome, why it failed, and its last probe (the latch).
pub(in crate::daemon) struct HomingEnd<'a> {
    pub outcome: Outcome,
    pub error: Option<&'a str>,
    pub last_probe: &'a LastProbe,
}

impl<'a> From<&'a JobSummary> for HomingEnd<'a> {
    fn from(summary: &'a JobSummary) -> HomingEnd<'a> {
        HomingEnd {
            outcome: summary.outcome,
            error: summary.error.as_deref(),
            last_probe: &summary.last_probe,
        }
    }
}

/// A homing job ended (the machine's position is already its ledger's): the latch point
/// becomes the home position; the next axis to home, if any. Anything but a latch stops the
/// homing (the queue is emptied).
pub(in crate::daemon) fn latched(
    config: &Config,
    machine: &mut Machine,
    switch: &HomeSwitch,
    end: HomingEnd,
) -> Option<usize> {
    let i = switch.axis;
    let h = config.homing.axis(i).expect("a homed axis");
    let step = config.machine.step_mm[i];
    let latch = match (&end.last_probe.probe_mm, end.outcome) {
        (Some(mm), Outcome::Done) if end.last_probe.probe_contact == Some(true) => {
            (mm[i] / step).round() as i64
        }
        _ => {
            let why = match end.outcome {
                Outcome::Done => "no latch".to_string(),
                _ => end.error.unwrap_or(end.outcome.name()).to_string(),
            };
            // A missed switch is already said in homing's words (`say_why_it_failed`).
            let why = match end.outcome {
                Outcome::ProbeMissed => why,
                _ => format!(
                    "homing {} failed: {why} (no switch within {:.1} mm, or it did not release \
                     within {:.1} mm?)",
                    h.axis, h.search_distance_mm, h.latch_distance_mm
                ),
            };
            tracing::error!(
                edmd_event = "home_failed",
                "{why}; the axis stays unhomed{}",
                if machine.homing_queue.is_empty() {
                    String::new()
                } else {
                    "; the other axes are not homed either".to_string()
                }
            );
            machine.homing_queue.clear();
            let _ = machine.save(false).map_err(super::unwritten);
            return None;
        }
    };
    let home = (h.home_position_mm / step).round() as i64;
    let correction = home - latch;
    machine.state.position[i] += correction;
    machine.state.set_homed(i);
    let _ = machine.save(false).map_err(super::unwritten);
    tracing::info!(
        edmd_event = "home",
        "homed {}: the switch latched where the machine believed {:.4} mm; it is \
         {:.4} mm (a correction of {:+.4} mm); now at {:.4} mm",
        h.axis,
        latch as f64 * step,
        h.home_position_mm,
        correction as f64 * step,
        machine.state.position[i] as f64 * step
    );
    (!machine.homing_queue.is_empty()).then(|| machine.homing_queue.remove(0))
}

/// A job starts: a homing job's axis is unhomed until it latches.
pub(in crate::daemon) fn started(machine: &mut Machine, switch: Option<&HomeSwitch>) {
    if let Some(switch) = switch {
        machine.state.homed[switch.axis] = false;
    }
}
