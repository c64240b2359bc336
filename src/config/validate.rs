//! Validation: the raw layer in, the [`Config`] the rest of edmd trusts out. Each failure is
//! the offending key and what is wrong; [`Config::parse`](super::Config) attaches where the
//! value came from.

use std::path::PathBuf;

use super::raw::{
    RawBuffer, RawCompensation, RawConfig, RawDaemon, RawFine, RawGap, RawGenerator,
    RawInterpolation, RawMachine, RawOutput,
};
use super::*;
use crate::vocab::MAX_AXES;

pub(super) type Invalid = (&'static str, String);

/// A fraction in (0, 1].
pub(super) fn fraction(key: &'static str, v: f64) -> Result<f64, Invalid> {
    if v.is_finite() && v > 0.0 && v <= 1.0 {
        Ok(v)
    } else {
        Err((
            key,
            format!("must be a fraction above 0 and at most 1, got {v}"),
        ))
    }
}

/// A physical quantity: greater than 0 and at most `max` (a bound no machine reaches, so a
/// typo such as `1e300` is caught here with its unit rather than misbehaving later).
pub(super) fn positive(
    key: &'static str,
    value: f64,
    max: f64,
    unit: &str,
) -> Result<f64, Invalid> {
    if value.is_finite() && value > 0.0 && value <= max {
        Ok(value)
    } else {
        Err((
            key,
            format!(
                "must be greater than 0 and at most {} {unit}, got {}",
                short(max),
                short(value)
            ),
        ))
    }
}

/// A feed (mm/min): at least [`crate::vocab::MIN_FEED_MM_PER_MIN`], at most `max`.
pub(super) fn feed(key: &'static str, value: f64, max: f64) -> Result<f64, Invalid> {
    let min = crate::vocab::MIN_FEED_MM_PER_MIN;
    if value.is_finite() && value >= min && value <= max {
        Ok(value)
    } else {
        Err((
            key,
            format!(
                "must be at least {} and at most {} mm/min, got {}",
                short(min),
                short(max),
                short(value)
            ),
        ))
    }
}

/// A number as a person would write it: `1e300`, not three hundred digits.
pub(super) fn short(value: f64) -> String {
    let magnitude = value.abs();
    if magnitude != 0.0 && !(1e-4..1e7).contains(&magnitude) {
        format!("{value:e}")
    } else {
        format!("{value}")
    }
}

/// A quantity that may be 0 (off): from 0 to `max`.
pub(super) fn at_most(key: &'static str, value: f64, max: f64, unit: &str) -> Result<f64, Invalid> {
    if value.is_finite() && (0.0..=max).contains(&value) {
        Ok(value)
    } else {
        Err((
            key,
            format!("must be 0 to {} {unit}, got {}", short(max), short(value)),
        ))
    }
}

pub(super) fn in_range(key: &'static str, value: i64, lo: i64, hi: i64) -> Result<i64, Invalid> {
    if (lo..=hi).contains(&value) {
        Ok(value)
    } else {
        Err((key, format!("must be {lo} to {hi}, got {value}")))
    }
}

fn non_empty(key: &'static str, value: String) -> Result<PathBuf, Invalid> {
    if value.trim().is_empty() {
        Err((key, "must not be empty".to_string()))
    } else {
        Ok(PathBuf::from(value))
    }
}

impl RawConfig {
    pub(super) fn validate(self) -> Result<Config, Invalid> {
        let machine = machine(self.machine)?;
        let interpolation = interpolation(self.interpolation)?;
        let buffer = buffer(self.buffer)?;
        let fine = fine(self.fine)?;
        let output = output(self.output)?;
        if output.kind.hardware() && fine.virtual_time {
            return Err((
                "fine.virtual_time",
                format!(
                    "must be false with output.kind = \"{}\": virtual time cannot drive real \
                     hardware",
                    output.kind.name()
                ),
            ));
        }
        if output.kind.hardware() && fine.ticks_per_wake > 1 {
            return Err((
                "fine.ticks_per_wake",
                format!(
                    "must be 1 with output.kind = \"{}\": a machine's drives take each step at \
                     its own tick, not in bursts",
                    output.kind.name()
                ),
            ));
        }
        let gap = gap(self.gap)?;
        if self.servo.law == ServoLaw::Ratio && gap.kind != GapKind::Sim {
            return Err((
                "servo.law",
                "\"ratio\" needs pulse counts per window: gap.kind = \"sim\" (no hardware input \
                 counts them yet)"
                    .to_string(),
            ));
        }
        let hal_volts = gap.kind == GapKind::Hal && self.hal.reads_voltage();
        if self.servo.law == ServoLaw::Voltage
            && !matches!(gap.kind, GapKind::Iio | GapKind::Sim)
            && !hal_volts
        {
            return Err((
                "servo.law",
                "\"voltage\" needs a gap voltage: gap.kind = \"iio\" (an ADC), \"hal\" with \
                 hal.gap_input = \"voltage\", or \"sim\""
                    .to_string(),
            ));
        }
        if gap.kind == GapKind::Parport && output.kind != OutputKind::Parport {
            return Err((
                "gap.kind",
                "\"parport\" reads the status pins of the output port and needs output.kind = \"parport\""
                    .to_string(),
            ));
        }

        let parport = self.parport.validate(&machine, &fine, &output, &gap)?;
        let hal = self.hal.validate(output.kind, gap.kind)?;

        let servo = self.servo.validate(&machine)?;
        let homing = self.homing.validate(&machine, &parport, output.kind)?;
        let daemon = daemon(self.daemon)?;
        let log = LogConfig {
            level: self.log.level,
            format: self.log.format,
        };
        let p = self.program;
        if !(1..=1_000_000_000).contains(&p.max_loop_iterations) {
            return Err((
                "program.max_loop_iterations",
                format!("must be 1 to 1000000000, got {}", p.max_loop_iterations),
            ));
        }
        let compensation = compensation(self.compensation)?;
        let conditions = conditions(self.generator)?;
        let wire = self.wire.validate(&compensation)?;
        let sim = self.sim.validate(&machine, &homing, wire.diameter_mm)?;
        let sinker = self.sinker.validate(&conditions)?;
        let adaptive = self.adaptive.validate(fine.tick)?;
        let technology = TechnologyConfig {
            dir: non_empty("technology.dir", self.technology.dir)?,
        };
        let mut mcodes = Vec::new();
        for m in p.mcode {
            let code = m.validate(&mcodes, &conditions)?;
            mcodes.push(code);
        }
        let program = ProgramConfig {
            block_delete: p.block_delete,
            optional_stop: p.optional_stop,
            max_loop_iterations: p.max_loop_iterations as u64,
            mcodes,
        };
        Ok(Config {
            machine,
            interpolation,
            buffer,
            fine,
            output,
            gap,
            parport,
            hal,
            servo,
            sim,
            daemon,
            log,
            program,
            compensation,
            conditions,
            technology,
            adaptive,
            homing,
            wire,
            sinker,
        })
    }
}

fn machine(m: RawMachine) -> Result<MachineConfig, Invalid> {
    if m.axes.is_empty() || m.axes.len() > MAX_AXES {
        return Err((
            "machine.axes",
            format!("must list 1 to {} axes, got {}", MAX_AXES, m.axes.len()),
        ));
    }
    let mut axes = Vec::with_capacity(m.axes.len());
    for name in &m.axes {
        let axis = match name.trim().to_ascii_uppercase().as_str() {
            s if s.chars().count() == 1 => Axis::from_letter(s.chars().next().unwrap_or(' ')),
            _ => None,
        }
        .ok_or_else(|| {
            (
                "machine.axes",
                format!("\"{name}\" is not an axis; use X, Y, Z, A, B, C, U or V"),
            )
        })?;
        if axes.contains(&axis) {
            return Err(("machine.axes", format!("axis {axis} is listed twice")));
        }
        axes.push(axis);
    }
    if m.step_mm.len() != axes.len() {
        return Err((
            "machine.step_mm",
            format!(
                "has {} values but machine.axes has {} axes; give one step size per axis",
                m.step_mm.len(),
                axes.len()
            ),
        ));
    }
    for &s in &m.step_mm {
        positive("machine.step_mm", s, 10.0, "mm")?;
    }
    let travel = travel(&axes, &m.travel_mm)?;
    let safe_z_mm = safe_z(&axes, &travel, m.safe_z_mm)?;
    Ok(MachineConfig {
        safe_z_mm,
        travel,
        axes,
        step_mm: m.step_mm,
        max_feed_mm_per_min: feed("machine.max_feed_mm_per_min", m.max_feed_mm_per_min, 1e6)?,
        max_normal_accel_mm_per_s2: positive(
            "machine.max_normal_accel_mm_per_s2",
            m.max_normal_accel_mm_per_s2,
            1e7,
            "mm/s²",
        )?,
        max_jog_feed_mm_per_min: feed(
            "machine.max_jog_feed_mm_per_min",
            m.max_jog_feed_mm_per_min,
            1e6,
        )?,
        dry_run_feed_mm_per_min: feed(
            "machine.dry_run_feed_mm_per_min",
            m.dry_run_feed_mm_per_min,
            1e6,
        )?,
        max_tangential_accel_mm_per_s2: positive(
            "machine.max_tangential_accel_mm_per_s2",
            m.max_tangential_accel_mm_per_s2,
            1e7,
            "mm/s²",
        )?,
        max_jerk_mm_per_s3: at_most(
            "machine.max_jerk_mm_per_s3",
            m.max_jerk_mm_per_s3,
            1e12,
            "mm/s³",
        )?,
    })
}

/// `machine.safe_z_mm`: only on a machine with Z, and inside Z's travel.
fn safe_z(
    axes: &[Axis],
    travel: &[Option<Travel>],
    safe_z: Option<f64>,
) -> Result<Option<f64>, Invalid> {
    const KEY: &str = "machine.safe_z_mm";
    let Some(z) = safe_z else { return Ok(None) };
    let Some(index) = axes.iter().position(|&a| a == Axis::Z) else {
        return Err((KEY, "is set but machine.axes has no Z".to_string()));
    };
    if !z.is_finite() {
        return Err((KEY, format!("must be a number of mm, not {z}")));
    }
    if let Some(t) = travel[index]
        && !(t.min_mm..=t.max_mm).contains(&z)
    {
        return Err((
            KEY,
            format!(
                "{z} mm is outside Z's travel [{}, {}] (machine.travel_mm)",
                t.min_mm, t.max_mm
            ),
        ));
    }
    Ok(Some(z))
}

/// `machine.travel_mm`: `[lowest, highest]` per axis letter; axes the machine does not have
/// are not used (the shipped table names X and Y, whatever `axes` a user lists).
fn travel(
    axes: &[Axis],
    table: &std::collections::BTreeMap<String, Vec<f64>>,
) -> Result<Vec<Option<Travel>>, Invalid> {
    const KEY: &str = "machine.travel_mm";
    for letter in table.keys() {
        let known = letter.chars().count() == 1
            && Axis::from_letter(letter.chars().next().unwrap_or(' ')).is_some();
        if !known {
            return Err((
                KEY,
                format!("\"{letter}\" is not an axis; use X, Y, Z, A, B, C, U or V"),
            ));
        }
    }
    axes.iter()
        .map(|axis| {
            let Some(range) = table.get(&axis.letter().to_string()) else {
                return Ok(None);
            };
            match range[..] {
                [min_mm, max_mm]
                    if min_mm.is_finite()
                        && max_mm.is_finite()
                        && min_mm < max_mm
                        && min_mm.abs().max(max_mm.abs()) <= MAX_TRAVEL_MM =>
                {
                    Ok(Some(Travel { min_mm, max_mm }))
                }
                _ => Err((
                    KEY,
                    format!(
                        "{axis} = {range:?}: give [lowest, highest] in mm, lowest below highest, \
                         within ±{}",
                        short(MAX_TRAVEL_MM)
                    ),
                )),
            }
        })
        .collect::<Result<Vec<_>, Invalid>>()
}

/// Largest soft limit accepted, mm (the interpreter's coordinate range).
const MAX_TRAVEL_MM: f64 = 1.0e6;

fn interpolation(i: RawInterpolation) -> Result<InterpolationConfig, Invalid> {
    Ok(InterpolationConfig {
        predictor: i.predictor,
        segmentation: i.segmentation,
        chord_tolerance_mm: positive(
            "interpolation.chord_tolerance_mm",
            i.chord_tolerance_mm,
            10.0,
            "mm",
        )?,
        period_ms: positive("interpolation.period_ms", i.period_ms, 1000.0, "ms")?,
        max_segment_mm: positive("interpolation.max_segment_mm", i.max_segment_mm, 1e6, "mm")?,
        lookahead_segments: in_range(
            "interpolation.lookahead_segments",
            i.lookahead_segments,
            2,
            1 << 20,
        )? as usize,
        fluctuation_tolerance: positive(
            "interpolation.fluctuation_tolerance",
            i.fluctuation_tolerance,
            1.0,
            "(a fraction of the step)",
        )?,
        max_corrections: in_range("interpolation.max_corrections", i.max_corrections, 1, 64)?
            as u32,
    })
}

fn buffer(b: RawBuffer) -> Result<BufferConfig, Invalid> {
    const MAX_CAPACITY: i64 = 1 << 24;
    if !(2..=MAX_CAPACITY).contains(&b.capacity) {
        return Err((
            "buffer.capacity",
            format!("must be 2 to {MAX_CAPACITY} blocks, got {}", b.capacity),
        ));
    }
    if b.reserved < 0 || b.reserved >= b.capacity {
        return Err((
            "buffer.reserved",
            format!(
                "must be at least 0 and less than buffer.capacity ({}), got {}",
                b.capacity, b.reserved
            ),
        ));
    }
    Ok(BufferConfig {
        capacity: b.capacity as usize,
        reserved: b.reserved as usize,
        trail_blocks: in_range("buffer.trail_blocks", b.trail_blocks, 0, 1 << 26)? as usize,
    })
}

fn fine(f: RawFine) -> Result<FineConfig, Invalid> {
    let tick = u32::try_from(f.tick_us)
        .ok()
        .and_then(TickPeriod::from_us)
        .ok_or_else(|| {
            (
                "fine.tick_us",
                format!("must be 1 to {} µs, got {}", TickPeriod::MAX_US, f.tick_us),
            )
        })?;
    Ok(FineConfig {
        tick,
        virtual_time: f.virtual_time,
        ticks_per_wake: in_range("fine.ticks_per_wake", f.ticks_per_wake, 1, 1000)? as u32,
        rt_priority: in_range("fine.rt_priority", f.rt_priority, 0, 99)? as u8,
        lock_memory: f.lock_memory,
        cpu: match f.cpu {
            -1 => None,
            cpu @ 0..=4095 => Some(cpu as usize),
            cpu => {
                return Err((
                    "fine.cpu",
                    format!("must be -1 (any CPU) or a CPU number 0 to 4095, got {cpu}"),
                ));
            }
        },
    })
}

fn output(o: RawOutput) -> Result<OutputConfig, Invalid> {
    Ok(OutputConfig {
        kind: o.kind,
        path: non_empty("output.path", o.path)?,
        trace: o.trace,
        fault_at_tick: match in_range("output.fault_at_tick", o.fault_at_tick, 0, i64::MAX)? {
            0 => None,
            tick => Some(tick as u64),
        },
    })
}

fn gap(g: RawGap) -> Result<GapConfig, Invalid> {
    let channel = g.iio_channel.trim().to_string();
    if channel.is_empty()
        || !channel
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_')
    {
        return Err((
            "gap.iio_channel",
            format!("\"{channel}\" is not an IIO channel name such as \"voltage0\""),
        ));
    }
    let iio = crate::gap::IioSettings {
        device: PathBuf::from(g.iio_device.clone()),
        channel,
        gain: positive("gap.iio_gain", g.iio_gain, 1e6, "V/V")?,
        rate_hz: positive("gap.iio_rate_hz", g.iio_rate_hz, 1e6, "Hz")?,
    };
    let volts = crate::vocab::GapVolts {
        short_below: positive("gap.short_below_v", g.short_below_v, 1e4, "V")?,
        open_above: positive("gap.open_above_v", g.open_above_v, 1e4, "V")?,
    };
    if volts.open_above <= volts.short_below {
        return Err((
            "gap.open_above_v",
            format!(
                "{} V must be above gap.short_below_v ({} V)",
                volts.open_above, volts.short_below
            ),
        ));
    }
    Ok(GapConfig {
        kind: g.kind,
        script: non_empty("gap.script", g.script)?,
        trace: g.trace,
        volts,
        iio,
    })
}

fn daemon(d: RawDaemon) -> Result<DaemonConfig, Invalid> {
    let state_dir = non_empty("daemon.state_dir", d.state_dir)?;
    // "" puts a file under the state directory, by its usual name.
    let under = |value: &str, name: &str| match value.trim() {
        "" => state_dir.join(name),
        path => PathBuf::from(path),
    };
    let checkpoint = under(&d.checkpoint, "checkpoint.json");
    Ok(DaemonConfig {
        socket: non_empty("daemon.socket", d.socket)?,
        socket_mode: u32::from_str_radix(d.socket_mode.trim_start_matches("0o"), 8)
            .ok()
            .filter(|m| *m <= 0o777)
            .ok_or((
                "daemon.socket_mode",
                format!(
                    "{:?} is not an octal permission like \"0660\"",
                    d.socket_mode
                ),
            ))?,
        socket_group: (!d.socket_group.trim().is_empty()).then_some(d.socket_group),
        program_dir: non_empty("daemon.program_dir", d.program_dir)?,
        state_file: under(&d.state_file, "machine-state.json"),
        job_history: under(&d.job_history, "jobs.jsonl"),
        checkpoint,
        checkpoint_interval_s: (non_negative(
            "daemon.checkpoint_interval_s",
            d.checkpoint_interval_s,
        )? > 0.0)
            .then_some(d.checkpoint_interval_s),
        status_interval_s: (non_negative("daemon.status_interval_s", d.status_interval_s)? > 0.0)
            .then_some(d.status_interval_s),
        max_clients: in_range("daemon.max_clients", d.max_clients, 1, 1024)? as usize,
        report_dir: match d.report_dir.trim() {
            "off" => None,
            _ => Some(under(&d.report_dir, "reports")),
        },
        http: match d.http.trim() {
            "" => None,
            addr => Some(addr.parse().map_err(|_| {
                (
                    "daemon.http",
                    format!(
                        "{addr:?} is not an address and port such as \"127.0.0.1:8080\" \
                         (\"\" turns HTTP off)"
                    ),
                )
            })?),
        },
        http_token_file: under(&d.http_token_file, "http-token"),
        http_allowed_hosts: d
            .http_allowed_hosts
            .iter()
            .map(|h| {
                let name = h.trim().trim_end_matches('.').to_ascii_lowercase();
                let ok = !name.is_empty()
                    && name
                        .chars()
                        .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '.');
                ok.then_some(name).ok_or((
                    "daemon.http_allowed_hosts",
                    format!("{h:?} is not a host name (letters, digits, `-` and `.`)"),
                ))
            })
            .collect::<Result<_, _>>()?,
        http_max_connections: in_range(
            "daemon.http_max_connections",
            d.http_max_connections,
            1,
            65_536,
        )? as usize,
        opcua: super::opcua::endpoint(&d.opcua).map_err(|e| ("daemon.opcua", e))?,
        opcua_users_file: under(&d.opcua_users_file, "opcua-users"),
        opcua_pki_dir: under(&d.opcua_pki_dir, "opcua-pki"),
        mqtt: d.mqtt.validate(&crate::sys::host_name())?,
        state_dir,
    })
}

fn compensation(c: RawCompensation) -> Result<CompensationConfig, Invalid> {
    let d_mm = c.d_mm;
    if d_mm.first() != Some(&0.0) {
        return Err((
            "compensation.d_mm",
            "must start with D0 = 0.0 (then D1, D2, …)".to_string(),
        ));
    }
    if d_mm.len() > 100 {
        return Err((
            "compensation.d_mm",
            format!("has {} registers; at most 100", d_mm.len()),
        ));
    }
    for &d in &d_mm {
        if !(0.0..=10.0).contains(&d) {
            return Err((
                "compensation.d_mm",
                format!("{d} is not a wire offset: each must be 0 to 10 mm"),
            ));
        }
    }
    Ok(CompensationConfig { d_mm })
}

fn conditions(generator: RawGenerator) -> Result<Vec<Condition>, Invalid> {
    let mut conditions: Vec<Condition> = Vec::new();
    for c in generator.condition {
        let key = "generator.condition";
        let condition = c.validate(key, super::FeedRule::Given)?;
        if conditions.iter().any(|x| x.number == condition.number) {
            return Err((key, format!("E{} is defined twice", condition.number)));
        }
        conditions.push(condition);
    }
    Ok(conditions)
}

pub(super) fn non_negative(key: &'static str, value: f64) -> Result<f64, Invalid> {
    if value.is_finite() && value >= 0.0 {
        Ok(value)
    } else {
        Err((key, format!("must be a finite number >= 0, got {value}")))
    }
}
