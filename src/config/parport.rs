//! Validation of `[parport]`: pins of the right kind, one signal each, the drives' timing.

use super::raw::RawParport;
use super::validate::{Invalid, in_range};
use super::*;
use crate::parport::StepTiming;
use crate::parport::pins::{is_input_pin, is_output_pin};

impl RawParport {
    /// Pins must exist and be of the right kind, and no pin may carry two signals, whatever
    /// the output; the number of axes and the timing against the tick only matter when the
    /// port is in use (a simulation with a short tick must not trip over the port's timing).
    pub(super) fn validate(
        self,
        machine: &MachineConfig,
        fine: &FineConfig,
        output: &OutputConfig,
        gap: &GapConfig,
    ) -> Result<ParportConfig, Invalid> {
        const OUTPUTS: &str = "an output pin: 1-9, 14, 16 or 17";
        const INPUTS: &str = "an input pin: 10, 11, 12, 13 or 15";
        let output_pin = |key: &'static str, pin: i64| {
            if is_output_pin(pin) {
                Ok(pin as u8)
            } else {
                Err((key, format!("{pin} is not {OUTPUTS}")))
            }
        };
        let optional = |key: &'static str, pin: i64, ok: fn(i64) -> bool, what: &str| match pin {
            0 => Ok(None),
            p if ok(p) => Ok(Some(p as u8)),
            p => Err((key, format!("{p} is not {what} (or 0 for none)"))),
        };
        let step_pins = self
            .step_pins
            .iter()
            .map(|&p| output_pin("parport.step_pins", p))
            .collect::<Result<Vec<_>, _>>()?;
        let dir_pins = self
            .dir_pins
            .iter()
            .map(|&p| output_pin("parport.dir_pins", p))
            .collect::<Result<Vec<_>, _>>()?;
        let enable_pin = optional(
            "parport.enable_pin",
            self.enable_pin,
            is_output_pin,
            OUTPUTS,
        )?;
        let flush_pin = optional("parport.flush_pin", self.flush_pin, is_output_pin, OUTPUTS)?;
        let spark_pin = optional("parport.spark_pin", self.spark_pin, is_output_pin, OUTPUTS)?;
        let condition_pins = self
            .condition_pins
            .iter()
            .map(|&p| output_pin("parport.condition_pins", p))
            .collect::<Result<Vec<_>, _>>()?;
        if condition_pins.len() > 10 {
            return Err((
                "parport.condition_pins",
                format!(
                    "{} pins; at most 10 (conditions up to 1023)",
                    condition_pins.len()
                ),
            ));
        }
        let short_pin = optional("parport.short_pin", self.short_pin, is_input_pin, INPUTS)?;
        let open_pin = optional("parport.open_pin", self.open_pin, is_input_pin, INPUTS)?;
        let probe_pin = optional("parport.probe_pin", self.probe_pin, is_input_pin, INPUTS)?;
        let wire_break_pin = optional(
            "parport.wire_break_pin",
            self.wire_break_pin,
            is_input_pin,
            INPUTS,
        )?;
        let estop_pin = optional("parport.estop_pin", self.estop_pin, is_input_pin, INPUTS)?;
        let limit_pins = limit_pins(&self.limit_pins, machine, INPUTS)?;
        let mut seen: Vec<(u8, &'static str)> = Vec::new();
        let signals = step_pins
            .iter()
            .map(|&p| (p, "parport.step_pins"))
            .chain(dir_pins.iter().map(|&p| (p, "parport.dir_pins")))
            .chain(enable_pin.map(|p| (p, "parport.enable_pin")))
            .chain(flush_pin.map(|p| (p, "parport.flush_pin")))
            .chain(spark_pin.map(|p| (p, "parport.spark_pin")))
            .chain(
                condition_pins
                    .iter()
                    .map(|&p| (p, "parport.condition_pins")),
            )
            .chain(short_pin.map(|p| (p, "parport.short_pin")))
            .chain(open_pin.map(|p| (p, "parport.open_pin")))
            .chain(probe_pin.map(|p| (p, "parport.probe_pin")))
            .chain(wire_break_pin.map(|p| (p, "parport.wire_break_pin")))
            .chain(estop_pin.map(|p| (p, "parport.estop_pin")))
            .chain(limit_pins.iter().map(|&(_, p)| (p, "parport.limit_pins")));
        for (pin, key) in signals {
            if let Some((_, first)) = seen.iter().find(|(p, _)| *p == pin) {
                return Err((key, format!("pin {pin} is already used by {first}")));
            }
            seen.push((pin, key));
        }
        let invert_pins = invert_pins(&self.invert_pins)?;
        let ns = |key: &'static str, v: i64| in_range(key, v, 0, 1_000_000_000).map(|v| v as u64);
        let p = ParportConfig {
            step_pins,
            dir_pins,
            enable_pin,
            flush_pin,
            spark_pin,
            condition_pins,
            invert_pins,
            step_length_ns: in_range(
                "parport.step_length_ns",
                self.step_length_ns,
                1,
                1_000_000_000,
            )? as u64,
            step_space_ns: ns("parport.step_space_ns", self.step_space_ns)?,
            dir_setup_ns: ns("parport.dir_setup_ns", self.dir_setup_ns)?,
            dir_hold_ns: ns("parport.dir_hold_ns", self.dir_hold_ns)?,
            short_pin,
            open_pin,
            probe_pin,
            wire_break_pin,
            estop_pin,
            limit_pins,
            gap_filter_ticks: in_range("parport.gap_filter_ticks", self.gap_filter_ticks, 1, 1000)?
                as u32,
        };
        in_use(&p, machine, fine, output, gap)?;
        Ok(p)
    }
}

/// `parport.limit_pins`: each axis end of the machine with its input pin.
fn limit_pins(
    table: &std::collections::BTreeMap<String, i64>,
    machine: &MachineConfig,
    inputs: &str,
) -> Result<Vec<(crate::vocab::LimitSwitch, u8)>, Invalid> {
    const KEY: &str = "parport.limit_pins";
    table
        .iter()
        .map(|(name, &pin)| {
            let switch = crate::vocab::LimitSwitch::parse(name).ok_or_else(|| {
                (
                    KEY,
                    format!("{name:?} is not a limit switch: an axis and its side, e.g. \"X+\""),
                )
            })?;
            if !machine.axes.contains(&switch.axis) {
                return Err((
                    KEY,
                    format!("{name}: axis {} is not on this machine", switch.axis),
                ));
            }
            if !is_input_pin(pin) {
                return Err((KEY, format!("{name} = {pin}: not {inputs}")));
            }
            Ok((switch, pin as u8))
        })
        .collect()
}

/// Pins whose level is inverted: signal pins, each once.
fn invert_pins(pins: &[i64]) -> Result<Vec<u8>, Invalid> {
    let mut invert_pins = Vec::with_capacity(pins.len());
    for &pin in pins {
        if !is_output_pin(pin) && !is_input_pin(pin) {
            return Err((
                "parport.invert_pins",
                format!("{pin} is not a signal pin (1-17; 18-25 are ground)"),
            ));
        }
        if invert_pins.contains(&(pin as u8)) {
            return Err(("parport.invert_pins", format!("pin {pin} is listed twice")));
        }
        invert_pins.push(pin as u8);
    }
    Ok(invert_pins)
}

/// What matters only when the port is in use: a step and a direction pin per axis, the
/// drives' timing within a tick, a gap input pin when the gap is read from the port.
fn in_use(
    p: &ParportConfig,
    machine: &MachineConfig,
    fine: &FineConfig,
    output: &OutputConfig,
    gap: &GapConfig,
) -> Result<(), Invalid> {
    if output.kind == OutputKind::Parport {
        let axes = machine.axes.len();
        for (key, pins) in [
            ("parport.step_pins", &p.step_pins),
            ("parport.dir_pins", &p.dir_pins),
        ] {
            if pins.len() < axes {
                return Err((
                    key,
                    format!(
                        "has {} pins but machine.axes has {axes} axes; give one pin per axis",
                        pins.len()
                    ),
                ));
            }
        }
        let timing = StepTiming {
            step_length_ns: p.step_length_ns,
            step_space_ns: p.step_space_ns,
            dir_setup_ns: p.dir_setup_ns,
            dir_hold_ns: p.dir_hold_ns,
        };
        if timing.min_tick_ns() > fine.tick.ns() {
            return Err((
                "fine.tick_us",
                format!(
                    "{} µs is too short for the drives' step timing: dir_setup_ns + \
                     step_length_ns + dir_hold_ns = {} ns and step_length_ns + step_space_ns \
                     = {} ns must both fit in one tick; raise fine.tick_us to at least {} or \
                     shorten the [parport] times",
                    fine.tick.us(),
                    p.dir_setup_ns + p.step_length_ns + p.dir_hold_ns,
                    p.step_length_ns + p.step_space_ns,
                    timing.min_tick_ns().div_ceil(1000)
                ),
            ));
        }
    }
    // The machine's inputs on the port are read whenever the port is the output; with any
    // other output nothing reads them, and a machine that believes its E-stop wired must not
    // validate.
    if output.kind != OutputKind::Parport {
        let unread = [
            ("parport.estop_pin", p.estop_pin),
            ("parport.probe_pin", p.probe_pin),
            ("parport.wire_break_pin", p.wire_break_pin),
        ]
        .into_iter()
        .find_map(|(key, pin)| pin.map(|pin| (key, pin.to_string())))
        .or_else(|| {
            (!p.limit_pins.is_empty()).then(|| {
                (
                    "parport.limit_pins",
                    p.limit_pins
                        .iter()
                        .map(|(s, pin)| format!("{s} = {pin}"))
                        .collect::<Vec<_>>()
                        .join(", "),
                )
            })
        });
        if let Some((key, pins)) = unread {
            return Err((
                key,
                format!(
                    "{pins}: nothing reads the parallel port's inputs with output.kind = \
                     \"{}\"; use output.kind = \"parport\", or set it to 0 (none)",
                    output.kind.name()
                ),
            ));
        }
    }
    if gap.kind == GapKind::Parport && p.short_pin.is_none() && p.open_pin.is_none() {
        return Err((
            "parport.short_pin",
            "gap.kind = \"parport\" needs parport.short_pin or parport.open_pin".to_string(),
        ));
    }
    Ok(())
}
