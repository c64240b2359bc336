//! Validation of `[homing]` and of the simulator's home switches (`sim.home_switch_mm`):
//! each homed axis once, feeds the machine can run, and switch pins that are inputs no other
//! signal uses. What depends on other sections a user may change without thinking of homing
//! (the travel, the gap input) is held when `home` is asked for, so that the shipped entries
//! never make another setting an error.

use super::raw::{RawHoming, RawHomingAxis, RawRequired, RawSim};
use super::validate::{Invalid, feed, positive, short};
use super::{HomingAxis, HomingConfig, MachineConfig, OutputKind, ParportConfig};
use crate::parport::pins::is_input_pin;
use crate::vocab::Axis;

const KEY: &str = "homing.axis";
/// Latch distance when none is given, mm.
const DEFAULT_LATCH_DISTANCE_MM: f64 = 5.0;
/// Search distance of an axis without `machine.travel_mm` when none is given, mm.
const DEFAULT_SEARCH_DISTANCE_MM: f64 = 1000.0;
/// Longest search or latch distance accepted, mm.
const MAX_DISTANCE_MM: f64 = 1.0e4;

impl RawHoming {
    /// `[homing]`, validated on the machine and port of the rest of the configuration.
    pub(super) fn validate(
        self,
        machine: &MachineConfig,
        parport: &ParportConfig,
        output: OutputKind,
    ) -> Result<HomingConfig, Invalid> {
        homing(self, machine, parport, output)
    }
}

impl RawSim {
    /// `sim.home_switch_mm`: per axis letter, where the simulated switch is (an axis with no
    /// entry has it at its home position).
    pub(super) fn home_switches(
        &self,
        machine: &MachineConfig,
        homing: &HomingConfig,
    ) -> Result<Vec<Option<f64>>, Invalid> {
        sim_switches(&self.home_switch_mm, machine, homing)
    }
}

fn homing(
    raw: RawHoming,
    machine: &MachineConfig,
    parport: &ParportConfig,
    output: OutputKind,
) -> Result<HomingConfig, Invalid> {
    let required = match &raw.required {
        RawRequired::Flag(on) => *on,
        // A real machine's position is lost with its power; a simulated one's is not.
        RawRequired::Word(w) if w == "auto" => output.hardware(),
        RawRequired::Word(w) => {
            return Err((
                "homing.required",
                format!("{w:?}: true, false or \"auto\" (on with output.kind = \"parport\")"),
            ));
        }
    };
    let mut axes: Vec<HomingAxis> = Vec::with_capacity(raw.axis.len());
    for (n, entry) in raw.axis.iter().enumerate() {
        let Some(axis) = homing_axis(entry, machine, parport)
            .map_err(|(key, message)| (key, format!("entry {}: {message}", n + 1)))?
        else {
            continue;
        };
        if axes.iter().any(|a| a.axis == axis.axis) {
            return Err((KEY, format!("axis {} is listed twice", axis.axis)));
        }
        if let Some(pin) = axis.switch_pin
            && output != OutputKind::Parport
        {
            return Err((
                KEY,
                format!(
                    "entry {}: {}: switch_pin = {pin}: nothing reads the parallel port's \
                     inputs with output.kind = \"{}\"; use output.kind = \"parport\", or \
                     switch_pin = 0",
                    n + 1,
                    axis.axis,
                    output.name()
                ),
            ));
        }
        axes.push(axis);
    }
    // Stable: equal sequences home in the order listed.
    axes.sort_by_key(|a| a.sequence);
    Ok(HomingConfig {
        required,
        require_after_start: raw.require_after_start,
        lost_on_estop: raw.lost_on_estop,
        axes,
    })
}

/// One entry; `None` for an axis the machine does not have (like `machine.travel_mm`, the
/// shipped list names X and Y whatever `axes` a user lists).
fn homing_axis(
    e: &RawHomingAxis,
    machine: &MachineConfig,
    parport: &ParportConfig,
) -> Result<Option<HomingAxis>, Invalid> {
    let letter = e.axis.trim().to_ascii_uppercase();
    let axis = match letter.chars().collect::<Vec<_>>()[..] {
        [c] => Axis::from_letter(c),
        _ => None,
    }
    .ok_or_else(|| (KEY, format!("axis {:?} is not an axis letter", e.axis)))?;
    let Some(index) = machine.axes.iter().position(|&a| a == axis) else {
        return Ok(None);
    };
    let positive_way = match e.direction.trim() {
        "+" => true,
        "-" => false,
        other => {
            return Err((
                KEY,
                format!("{axis}: direction {other:?}: \"+\" or \"-\", the way to the switch"),
            ));
        }
    };
    let max_feed = machine.max_feed_mm_per_min;
    let search_feed = feed(KEY, e.search_feed_mm_per_min, max_feed)
        .map_err(|(k, m)| (k, format!("{axis}: search_feed_mm_per_min {m}")))?;
    let latch_feed = feed(KEY, e.latch_feed_mm_per_min, search_feed).map_err(|(k, m)| {
        (
            k,
            format!("{axis}: latch_feed_mm_per_min (at most the search feed) {m}"),
        )
    })?;
    let travel = machine.travel[index];
    if !e.home_position_mm.is_finite() || e.home_position_mm.abs() > MAX_DISTANCE_MM * 100.0 {
        return Err((KEY, format!("{axis}: home_position_mm is not a coordinate")));
    }
    if !e.final_move_mm.is_finite() || e.final_move_mm.abs() > MAX_DISTANCE_MM {
        return Err((KEY, format!("{axis}: final_move_mm is not a distance")));
    }
    if e.final_move_mm != 0.0 && (e.final_move_mm > 0.0) == positive_way {
        return Err((
            KEY,
            format!(
                "{axis}: final_move_mm = {} runs into the switch (direction {}): move away \
                 from it",
                short(e.final_move_mm),
                e.direction.trim()
            ),
        ));
    }
    let search_distance = match (e.search_distance_mm, travel) {
        (Some(d), _) => positive(KEY, d, MAX_DISTANCE_MM, "mm")
            .map_err(|(k, m)| (k, format!("{axis}: search_distance_mm {m}")))?,
        // From anywhere in the travel to a switch just past its end.
        (None, Some(t)) => 1.25 * (t.max_mm - t.min_mm),
        // An axis without soft limits: as far as a machine's travel goes.
        (None, None) => DEFAULT_SEARCH_DISTANCE_MM,
    };
    let latch_distance = positive(
        KEY,
        e.latch_distance_mm.unwrap_or(DEFAULT_LATCH_DISTANCE_MM),
        MAX_DISTANCE_MM,
        "mm",
    )
    .map_err(|(k, m)| (k, format!("{axis}: latch_distance_mm {m}")))?;
    let switch_pin = switch_pin(axis, e.switch_pin, parport)?;
    let sequence = u32::try_from(e.sequence)
        .ok()
        .filter(|&s| s <= 99)
        .ok_or_else(|| (KEY, format!("{axis}: sequence {}: 0 to 99", e.sequence)))?;
    Ok(Some(HomingAxis {
        index,
        axis,
        switch_pin,
        positive: positive_way,
        search_feed_mm_per_min: search_feed,
        latch_feed_mm_per_min: latch_feed,
        home_position_mm: e.home_position_mm,
        final_move_mm: e.final_move_mm,
        sequence,
        search_distance_mm: search_distance,
        latch_distance_mm: latch_distance,
    }))
}

/// The switch's input pin (0: none; `home` refuses such an axis on the parallel port). A pin
/// no other input signal uses (axes may share one switch).
fn switch_pin(axis: Axis, pin: i64, parport: &ParportConfig) -> Result<Option<u8>, Invalid> {
    if pin == 0 {
        return Ok(None);
    }
    if !is_input_pin(pin) {
        return Err((
            KEY,
            format!("{axis}: switch_pin = {pin}: not an input pin (10, 11, 12, 13, 15)"),
        ));
    }
    let pin = pin as u8;
    let p = parport;
    let others = [
        (p.short_pin, "parport.short_pin"),
        (p.open_pin, "parport.open_pin"),
        (p.probe_pin, "parport.probe_pin"),
        (p.wire_break_pin, "parport.wire_break_pin"),
        (p.estop_pin, "parport.estop_pin"),
    ];
    let used = others
        .iter()
        .find(|(p, _)| *p == Some(pin))
        .map(|(_, key)| *key)
        .or_else(|| {
            p.limit_pins
                .iter()
                .any(|&(_, p)| p == pin)
                .then_some("parport.limit_pins")
        });
    if let Some(key) = used {
        return Err((
            KEY,
            format!("{axis}: switch_pin = {pin} is already used by {key}"),
        ));
    }
    Ok(Some(pin))
}

fn sim_switches(
    table: &std::collections::BTreeMap<String, f64>,
    machine: &MachineConfig,
    homing: &HomingConfig,
) -> Result<Vec<Option<f64>>, Invalid> {
    const SIM_KEY: &str = "sim.home_switch_mm";
    let mut out = vec![None; machine.axes.len()];
    for (letter, &mm) in table {
        let axis = match letter
            .trim()
            .to_ascii_uppercase()
            .chars()
            .collect::<Vec<_>>()[..]
        {
            [c] => Axis::from_letter(c),
            _ => None,
        }
        .ok_or_else(|| (SIM_KEY, format!("\"{letter}\" is not an axis letter")))?;
        if !mm.is_finite() || mm.abs() > MAX_DISTANCE_MM * 100.0 {
            return Err((SIM_KEY, format!("{axis} = {mm}: not a coordinate")));
        }
        // Axes the machine does not home are not used (like `machine.travel_mm`).
        if let Some(i) = machine.axes.iter().position(|&a| a == axis)
            && homing.axis(i).is_some()
        {
            out[i] = Some(mm);
        }
    }
    Ok(out)
}
