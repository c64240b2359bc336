//! Configuration: TOML text and `--set` overrides in, a validated [`Config`] out.
//!
//! Two layers, as in ripgrep: a raw layer that is whatever serde can read, and the validated
//! [`Config`] that the rest of edmd trusts (positive step sizes, `reserved < capacity`, ...).
//!
//! The shipped `config/edmd.toml` is the single source of truth for which keys exist and what
//! their defaults are: it is embedded in the binary, a user's file is overlaid on it key by key,
//! and any key the default does not have is rejected with its line. Every error names where the
//! offending value came from: `file:line:col` for the file, the `--set` argument for an override.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;

/// The default configuration, exactly as shipped in `config/edmd.toml`.
pub const DEFAULT_CONFIG_TOML: &str = include_str!("../config/edmd.toml");

/// Where edmd looks for its configuration when no `--config` is given.
pub const DEFAULT_CONFIG_PATH: &str = "config/edmd.toml";

/// A configuration that could not be loaded: where, and what is wrong.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{path}: cannot read the configuration: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// `origin` is `file:line:col`, `--set key=value`, or `file` for a default value.
    #[error("{origin}: {message}")]
    Invalid { origin: String, message: String },
}

// ---- validated configuration ----------------------------------------------------------------

/// A machine axis letter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Axis {
    X,
    Y,
    Z,
    A,
    B,
    C,
    U,
    V,
}

impl Axis {
    pub const ALL: [Axis; 8] = [
        Axis::X,
        Axis::Y,
        Axis::Z,
        Axis::A,
        Axis::B,
        Axis::C,
        Axis::U,
        Axis::V,
    ];

    /// The axis for a G-code word letter (upper case), if it is one.
    pub fn from_letter(letter: char) -> Option<Axis> {
        Axis::ALL.into_iter().find(|a| a.letter() == letter)
    }

    pub fn letter(self) -> char {
        match self {
            Axis::X => 'X',
            Axis::Y => 'Y',
            Axis::Z => 'Z',
            Axis::A => 'A',
            Axis::B => 'B',
            Axis::C => 'C',
            Axis::U => 'U',
            Axis::V => 'V',
        }
    }
}

impl std::fmt::Display for Axis {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.letter())
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Predictor {
    Taylor,
    Hamming,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Segmentation {
    Chord,
    Period,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum OutputKind {
    Sim,
    File,
    Parport,
    Null,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GapKind {
    Sim,
    Script,
    Parport,
    None,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LogLevel {
    Error,
    Warn,
    Info,
    Debug,
    Trace,
}

impl LogLevel {
    /// The level as `tracing`'s filters spell it.
    pub fn name(self) -> &'static str {
        match self {
            LogLevel::Error => "error",
            LogLevel::Warn => "warn",
            LogLevel::Info => "info",
            LogLevel::Debug => "debug",
            LogLevel::Trace => "trace",
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LogFormat {
    Auto,
    Human,
    Plain,
    Json,
}

#[derive(Debug, Clone, PartialEq)]
pub struct MachineConfig {
    pub axes: Vec<Axis>,
    pub step_mm: Vec<f64>,
    pub max_feed_mm_per_min: f64,
    pub max_normal_accel_mm_per_s2: f64,
    pub max_tangential_accel_mm_per_s2: f64,
}

impl MachineConfig {
    /// The axis letters as strings, in machine order (for reports).
    pub fn axis_names(&self) -> Vec<String> {
        self.axes.iter().map(|a| a.letter().to_string()).collect()
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct InterpolationConfig {
    pub predictor: Predictor,
    pub segmentation: Segmentation,
    pub chord_tolerance_mm: f64,
    pub period_ms: f64,
    pub max_segment_mm: f64,
    pub lookahead_segments: usize,
    pub fluctuation_tolerance: f64,
    pub max_corrections: u32,
}

#[derive(Debug, Clone, PartialEq)]
pub struct BufferConfig {
    pub capacity: usize,
    pub reserved: usize,
}

#[derive(Debug, Clone, PartialEq)]
pub struct FineConfig {
    pub tick_us: u32,
    pub virtual_time: bool,
    /// SCHED_FIFO priority, 0 for none.
    pub rt_priority: u8,
    pub lock_memory: bool,
    /// CPU to pin the fine interpolation thread to.
    pub cpu: Option<usize>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct OutputConfig {
    pub kind: OutputKind,
    pub path: PathBuf,
    /// Log the output's state changes.
    pub trace: bool,
    /// Fail every write from this tick on (testing aid).
    pub fault_at_tick: Option<u64>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct GapConfig {
    pub kind: GapKind,
    pub script: PathBuf,
    /// Log the gap state's changes.
    pub trace: bool,
}

/// The parallel port (`[parport]`): pins are DB-25 pin numbers, times in ns.
#[derive(Debug, Clone, PartialEq)]
pub struct ParportConfig {
    pub step_pins: Vec<u8>,
    pub dir_pins: Vec<u8>,
    pub enable_pin: Option<u8>,
    pub invert_pins: Vec<u8>,
    pub step_length_ns: u64,
    pub step_space_ns: u64,
    pub dir_setup_ns: u64,
    pub dir_hold_ns: u64,
    pub short_pin: Option<u8>,
    pub open_pin: Option<u8>,
    pub gap_filter_ticks: u32,
}

#[derive(Debug, Clone, PartialEq)]
pub struct ServoConfig {
    pub normal_feed_mm_per_min: f64,
    pub open_feed_mm_per_min: f64,
    pub retract_feed_mm_per_min: f64,
}

/// The simulated gap (`[sim]`), lengths in mm and speeds in mm/s.
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    pub seed: u64,
    pub initial_gap_mm: f64,
    pub short_gap_mm: f64,
    pub open_gap_mm: f64,
    pub erosion_mm_per_s: f64,
    /// Debris shorts placed along the program's path.
    pub debris_shorts: u32,
    pub debris_shorts_per_s: f64,
    pub debris_clear_mm: f64,
    /// Scripted events file.
    pub events: Option<PathBuf>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct DaemonConfig {
    pub socket: PathBuf,
    /// Permission bits of the socket.
    pub socket_mode: u32,
    /// Group owning the socket (`None`: the daemon's own).
    pub socket_group: Option<String>,
    pub program_dir: PathBuf,
    pub checkpoint: PathBuf,
    /// Checkpoint period while cutting (s); `None`: only at standstills.
    pub checkpoint_interval_s: Option<f64>,
    /// Period of the status line in the log (s); `None`: no periodic line.
    pub status_interval_s: Option<f64>,
    /// Control connections served at once; more are refused with an error reply.
    pub max_clients: usize,
}

#[derive(Debug, Clone, PartialEq)]
pub struct LogConfig {
    pub level: LogLevel,
    pub format: LogFormat,
}

/// Every key of a configuration, `section.key` → its value as TOML text, in key order.
pub type KeyValues = std::collections::BTreeMap<String, String>;

/// A configuration every rule of which has been checked.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    pub machine: MachineConfig,
    pub interpolation: InterpolationConfig,
    pub buffer: BufferConfig,
    pub fine: FineConfig,
    pub output: OutputConfig,
    pub gap: GapConfig,
    pub parport: ParportConfig,
    pub servo: ServoConfig,
    pub sim: SimConfig,
    pub daemon: DaemonConfig,
    pub log: LogConfig,
}

impl Default for Config {
    /// The shipped default (`config/edmd.toml`).
    fn default() -> Self {
        Config::from_toml_str(DEFAULT_CONFIG_TOML, "<built-in default>", &[])
            .expect("the shipped default configuration is valid")
    }
}

impl Config {
    /// Loads `path` (or the shipped default when `path` is `None`) and applies `overrides`
    /// (`section.key=value` strings, in order).
    pub fn load(path: Option<&Path>, overrides: &[String]) -> Result<Config, ConfigError> {
        Config::load_with_keys(path, overrides).map(|(config, _)| config)
    }

    /// [`load`](Self::load), also returning every key's value (`section.key` → TOML text),
    /// defaults included: what a reload compares.
    pub fn load_with_keys(
        path: Option<&Path>,
        overrides: &[String],
    ) -> Result<(Config, KeyValues), ConfigError> {
        match path {
            None => Config::parse(DEFAULT_CONFIG_TOML, "<built-in default>", overrides),
            Some(path) => {
                let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
                    path: path.to_path_buf(),
                    source,
                })?;
                Config::parse(&text, &path.display().to_string(), overrides)
            }
        }
    }

    /// Parses and validates configuration text; `source` names it in error messages.
    pub fn from_toml_str(
        text: &str,
        source: &str,
        overrides: &[String],
    ) -> Result<Config, ConfigError> {
        Config::parse(text, source, overrides).map(|(config, _)| config)
    }

    fn parse(
        text: &str,
        source: &str,
        overrides: &[String],
    ) -> Result<(Config, KeyValues), ConfigError> {
        let mut origins = Origins::default();
        let user = parse_user_table(text, source, &mut origins)?;
        let mut merged = default_table();
        overlay(&mut merged, user, source, &origins)?;
        for arg in overrides {
            apply_override(&mut merged, arg, &mut origins)?;
        }
        let mut keys = KeyValues::new();
        for (section, table) in &merged {
            if let Some(table) = table.as_table() {
                for (key, value) in table {
                    keys.insert(format!("{section}.{key}"), value.to_string());
                }
            }
        }
        let raw: RawConfig =
            serde_path_to_error::deserialize(toml::Value::Table(merged)).map_err(|err| {
                let key = err.path().to_string();
                ConfigError::Invalid {
                    origin: origins.describe(&key, source),
                    message: format!("{key}: {}", err.inner().message()),
                }
            })?;
        let config = raw
            .validate()
            .map_err(|(key, message)| ConfigError::Invalid {
                origin: origins.describe(key, source),
                message: format!("{key}: {message}"),
            })?;
        Ok((config, keys))
    }
}

// ---- raw layer ------------------------------------------------------------------------------

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    machine: RawMachine,
    interpolation: RawInterpolation,
    buffer: RawBuffer,
    fine: RawFine,
    output: RawOutput,
    gap: RawGap,
    parport: RawParport,
    servo: RawServo,
    sim: RawSim,
    daemon: RawDaemon,
    log: RawLog,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMachine {
    axes: Vec<String>,
    step_mm: Vec<f64>,
    max_feed_mm_per_min: f64,
    max_normal_accel_mm_per_s2: f64,
    max_tangential_accel_mm_per_s2: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInterpolation {
    predictor: Predictor,
    segmentation: Segmentation,
    chord_tolerance_mm: f64,
    period_ms: f64,
    max_segment_mm: f64,
    lookahead_segments: i64,
    fluctuation_tolerance: f64,
    max_corrections: i64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBuffer {
    capacity: i64,
    reserved: i64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFine {
    tick_us: i64,
    virtual_time: bool,
    rt_priority: i64,
    lock_memory: bool,
    cpu: i64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawOutput {
    kind: OutputKind,
    path: String,
    trace: bool,
    fault_at_tick: i64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawGap {
    kind: GapKind,
    script: String,
    trace: bool,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawParport {
    step_pins: Vec<i64>,
    dir_pins: Vec<i64>,
    enable_pin: i64,
    invert_pins: Vec<i64>,
    step_length_ns: i64,
    step_space_ns: i64,
    dir_setup_ns: i64,
    dir_hold_ns: i64,
    short_pin: i64,
    open_pin: i64,
    gap_filter_ticks: i64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawServo {
    normal_feed_mm_per_min: f64,
    open_feed_mm_per_min: f64,
    retract_feed_mm_per_min: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSim {
    seed: i64,
    initial_gap_um: f64,
    short_gap_um: f64,
    open_gap_um: f64,
    erosion_mm_per_min: f64,
    debris_shorts: i64,
    debris_shorts_per_s: f64,
    debris_clear_um: f64,
    events: String,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDaemon {
    socket: String,
    socket_mode: String,
    socket_group: String,
    program_dir: String,
    checkpoint: String,
    checkpoint_interval_s: f64,
    status_interval_s: f64,
    max_clients: i64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLog {
    level: LogLevel,
    format: LogFormat,
}

type Invalid = (&'static str, String);

fn positive(key: &'static str, value: f64) -> Result<f64, Invalid> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err((
            key,
            format!("must be a finite number greater than 0, got {value}"),
        ))
    }
}

fn in_range(key: &'static str, value: i64, lo: i64, hi: i64) -> Result<i64, Invalid> {
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
    fn validate(self) -> Result<Config, Invalid> {
        let m = self.machine;
        if m.axes.is_empty() || m.axes.len() > crate::geometry::MAX_AXES {
            return Err((
                "machine.axes",
                format!(
                    "must list 1 to {} axes, got {}",
                    crate::geometry::MAX_AXES,
                    m.axes.len()
                ),
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
            positive("machine.step_mm", s)?;
        }
        let machine = MachineConfig {
            axes,
            step_mm: m.step_mm,
            max_feed_mm_per_min: positive("machine.max_feed_mm_per_min", m.max_feed_mm_per_min)?,
            max_normal_accel_mm_per_s2: positive(
                "machine.max_normal_accel_mm_per_s2",
                m.max_normal_accel_mm_per_s2,
            )?,
            max_tangential_accel_mm_per_s2: positive(
                "machine.max_tangential_accel_mm_per_s2",
                m.max_tangential_accel_mm_per_s2,
            )?,
        };

        let i = self.interpolation;
        let interpolation = InterpolationConfig {
            predictor: i.predictor,
            segmentation: i.segmentation,
            chord_tolerance_mm: positive("interpolation.chord_tolerance_mm", i.chord_tolerance_mm)?,
            period_ms: positive("interpolation.period_ms", i.period_ms)?,
            max_segment_mm: positive("interpolation.max_segment_mm", i.max_segment_mm)?,
            lookahead_segments: in_range(
                "interpolation.lookahead_segments",
                i.lookahead_segments,
                2,
                1 << 20,
            )? as usize,
            fluctuation_tolerance: positive(
                "interpolation.fluctuation_tolerance",
                i.fluctuation_tolerance,
            )?,
            max_corrections: in_range("interpolation.max_corrections", i.max_corrections, 1, 64)?
                as u32,
        };

        let b = self.buffer;
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
        let buffer = BufferConfig {
            capacity: b.capacity as usize,
            reserved: b.reserved as usize,
        };

        let f = self.fine;
        if !(1..=1_000_000).contains(&f.tick_us) {
            return Err((
                "fine.tick_us",
                format!("must be 1 to 1000000 µs, got {}", f.tick_us),
            ));
        }
        let fine = FineConfig {
            tick_us: f.tick_us as u32,
            virtual_time: f.virtual_time,
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
        };

        let output = OutputConfig {
            kind: self.output.kind,
            path: non_empty("output.path", self.output.path)?,
            trace: self.output.trace,
            fault_at_tick: match in_range(
                "output.fault_at_tick",
                self.output.fault_at_tick,
                0,
                i64::MAX,
            )? {
                0 => None,
                tick => Some(tick as u64),
            },
        };
        if output.kind == OutputKind::Parport && fine.virtual_time {
            return Err((
                "fine.virtual_time",
                "must be false with output.kind = \"parport\": virtual time cannot drive real hardware"
                    .to_string(),
            ));
        }
        let gap = GapConfig {
            kind: self.gap.kind,
            script: non_empty("gap.script", self.gap.script)?,
            trace: self.gap.trace,
        };
        if gap.kind == GapKind::Parport && output.kind != OutputKind::Parport {
            return Err((
                "gap.kind",
                "\"parport\" reads the status pins of the output port and needs output.kind = \"parport\""
                    .to_string(),
            ));
        }

        let parport = self.parport.validate(&machine, &fine, &output, &gap)?;

        let s = self.servo;
        let servo = ServoConfig {
            normal_feed_mm_per_min: positive(
                "servo.normal_feed_mm_per_min",
                s.normal_feed_mm_per_min,
            )?,
            open_feed_mm_per_min: positive("servo.open_feed_mm_per_min", s.open_feed_mm_per_min)?,
            retract_feed_mm_per_min: positive(
                "servo.retract_feed_mm_per_min",
                s.retract_feed_mm_per_min,
            )?,
        };

        let m = self.sim;
        let non_negative = |key: &'static str, value: f64| {
            if value.is_finite() && value >= 0.0 {
                Ok(value)
            } else {
                Err((key, format!("must be a finite number >= 0, got {value}")))
            }
        };
        let short_gap = positive("sim.short_gap_um", m.short_gap_um)?;
        let open_gap = positive("sim.open_gap_um", m.open_gap_um)?;
        if open_gap <= short_gap {
            return Err((
                "sim.open_gap_um",
                format!("must be greater than sim.short_gap_um ({short_gap}), got {open_gap}"),
            ));
        }
        let sim = SimConfig {
            seed: in_range("sim.seed", m.seed, 0, i64::MAX)? as u64,
            initial_gap_mm: non_negative("sim.initial_gap_um", m.initial_gap_um)? / 1000.0,
            short_gap_mm: short_gap / 1000.0,
            open_gap_mm: open_gap / 1000.0,
            erosion_mm_per_s: positive("sim.erosion_mm_per_min", m.erosion_mm_per_min)? / 60.0,
            debris_shorts: in_range("sim.debris_shorts", m.debris_shorts, 0, 100_000)? as u32,
            debris_shorts_per_s: non_negative("sim.debris_shorts_per_s", m.debris_shorts_per_s)?,
            debris_clear_mm: positive("sim.debris_clear_um", m.debris_clear_um)? / 1000.0,
            events: (!m.events.trim().is_empty()).then(|| PathBuf::from(m.events)),
        };
        let d = self.daemon;
        let daemon = DaemonConfig {
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
            checkpoint: non_empty("daemon.checkpoint", d.checkpoint)?,
            checkpoint_interval_s: (non_negative(
                "daemon.checkpoint_interval_s",
                d.checkpoint_interval_s,
            )? > 0.0)
                .then_some(d.checkpoint_interval_s),
            status_interval_s: (non_negative("daemon.status_interval_s", d.status_interval_s)?
                > 0.0)
                .then_some(d.status_interval_s),
            max_clients: in_range("daemon.max_clients", d.max_clients, 1, 1024)? as usize,
        };
        let log = LogConfig {
            level: self.log.level,
            format: self.log.format,
        };
        Ok(Config {
            machine,
            interpolation,
            buffer,
            fine,
            output,
            gap,
            parport,
            servo,
            sim,
            daemon,
            log,
        })
    }
}

impl RawParport {
    /// Pins must exist and be of the right kind, and no pin may carry two signals, whatever
    /// the output; the number of axes and the timing against the tick only matter when the
    /// port is in use (a simulation with a short tick must not trip over the port's timing).
    fn validate(
        self,
        machine: &MachineConfig,
        fine: &FineConfig,
        output: &OutputConfig,
        gap: &GapConfig,
    ) -> Result<ParportConfig, Invalid> {
        use crate::parport::pins::{is_input_pin, is_output_pin};
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
        let short_pin = optional("parport.short_pin", self.short_pin, is_input_pin, INPUTS)?;
        let open_pin = optional("parport.open_pin", self.open_pin, is_input_pin, INPUTS)?;
        let mut seen: Vec<(u8, &'static str)> = Vec::new();
        let signals = step_pins
            .iter()
            .map(|&p| (p, "parport.step_pins"))
            .chain(dir_pins.iter().map(|&p| (p, "parport.dir_pins")))
            .chain(enable_pin.map(|p| (p, "parport.enable_pin")))
            .chain(short_pin.map(|p| (p, "parport.short_pin")))
            .chain(open_pin.map(|p| (p, "parport.open_pin")));
        for (pin, key) in signals {
            if let Some((_, first)) = seen.iter().find(|(p, _)| *p == pin) {
                return Err((key, format!("pin {pin} is already used by {first}")));
            }
            seen.push((pin, key));
        }
        let mut invert_pins = Vec::with_capacity(self.invert_pins.len());
        for &pin in &self.invert_pins {
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
        let ns = |key: &'static str, v: i64| in_range(key, v, 0, 1_000_000_000).map(|v| v as u64);
        let p = ParportConfig {
            step_pins,
            dir_pins,
            enable_pin,
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
            gap_filter_ticks: in_range("parport.gap_filter_ticks", self.gap_filter_ticks, 1, 1000)?
                as u32,
        };
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
            let timing = crate::parport::StepTiming {
                step_length_ns: p.step_length_ns,
                step_space_ns: p.step_space_ns,
                dir_setup_ns: p.dir_setup_ns,
                dir_hold_ns: p.dir_hold_ns,
            };
            let tick_ns = fine.tick_us as u64 * 1000;
            if timing.min_tick_ns() > tick_ns {
                return Err((
                    "fine.tick_us",
                    format!(
                        "{} µs is too short for the drives' step timing: dir_setup_ns + \
                         step_length_ns + dir_hold_ns = {} ns and step_length_ns + step_space_ns \
                         = {} ns must both fit in one tick; raise fine.tick_us to at least {} or \
                         shorten the [parport] times",
                        fine.tick_us,
                        p.dir_setup_ns + p.step_length_ns + p.dir_hold_ns,
                        p.step_length_ns + p.step_space_ns,
                        timing.min_tick_ns().div_ceil(1000)
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
        Ok(p)
    }
}

// ---- where values came from -----------------------------------------------------------------

#[derive(Default)]
struct Origins {
    /// `section.key` (and `section`) to `line:col` in the user's file.
    file: HashMap<String, (usize, usize)>,
    /// `section.key` to the `--set` argument that last set it.
    overrides: HashMap<String, String>,
}

impl Origins {
    /// Where the value at `key` came from, for an error message. A path deeper than
    /// `section.key` (an array element) is traced back to its key.
    fn describe(&self, key: &str, source: &str) -> String {
        let mut candidate = key.to_string();
        loop {
            if let Some(arg) = self.overrides.get(&candidate) {
                return format!("--set {arg}");
            }
            if let Some((line, col)) = self.file.get(&candidate) {
                return format!("{source}:{line}:{col}");
            }
            match candidate.rfind(['.', '[']) {
                Some(cut) => candidate.truncate(cut),
                None => return source.to_string(),
            }
        }
    }
}

/// 1-based line and column (in characters) of byte `offset` in `text`.
pub(crate) fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..text.floor_char_boundary(offset)];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    (line, before[line_start..].chars().count() + 1)
}

fn default_table() -> toml::Table {
    toml::from_str(DEFAULT_CONFIG_TOML).expect("the shipped default configuration parses")
}

/// Parses the user's text, records where each key stands, and returns it as a table.
fn parse_user_table(
    text: &str,
    source: &str,
    origins: &mut Origins,
) -> Result<toml::Table, ConfigError> {
    let at = |offset: usize, message: &str| {
        let (line, col) = line_col(text, offset);
        ConfigError::Invalid {
            origin: format!("{source}:{line}:{col}"),
            message: message.to_string(),
        }
    };
    let spanned = toml::de::DeTable::parse(text)
        .map_err(|e| at(e.span().map_or(0, |s| s.start), e.message()))?;
    for (section, value) in spanned.get_ref() {
        let name = section.get_ref().to_string();
        origins
            .file
            .insert(name.clone(), line_col(text, section.span().start));
        if let Some(table) = value.get_ref().as_table() {
            for (key, _) in table {
                origins.file.insert(
                    format!("{name}.{}", key.get_ref()),
                    line_col(text, key.span().start),
                );
            }
        }
    }
    toml::from_str(text).map_err(|e| at(e.span().map_or(0, |s| s.start), e.message()))
}

/// Puts the user's keys over the defaults; a section or key the default lacks is an error.
fn overlay(
    merged: &mut toml::Table,
    user: toml::Table,
    source: &str,
    origins: &Origins,
) -> Result<(), ConfigError> {
    for (section, value) in user {
        let origin = origins.describe(&section, source);
        let Some(toml::Value::Table(defaults)) = merged.get_mut(&section) else {
            return Err(ConfigError::Invalid {
                origin,
                message: format!(
                    "unknown section [{section}]; the sections are {}",
                    section_names()
                ),
            });
        };
        let toml::Value::Table(keys) = value else {
            return Err(ConfigError::Invalid {
                origin,
                message: format!("{section} must be a table ([{section}])"),
            });
        };
        for (key, value) in keys {
            if !defaults.contains_key(&key) {
                return Err(ConfigError::Invalid {
                    origin: origins.describe(&format!("{section}.{key}"), source),
                    message: unknown_key_message(&section, &key, defaults),
                });
            }
            defaults.insert(key, value);
        }
    }
    Ok(())
}

fn section_names() -> String {
    default_table()
        .keys()
        .map(|k| format!("[{k}]"))
        .collect::<Vec<_>>()
        .join(", ")
}

fn unknown_key_message(section: &str, key: &str, known: &toml::Table) -> String {
    let names: Vec<&str> = known.keys().map(String::as_str).collect();
    format!(
        "unknown key `{key}` in [{section}]; the keys are {}",
        names.join(", ")
    )
}

/// Applies one `section.key=value` override.
fn apply_override(
    merged: &mut toml::Table,
    arg: &str,
    origins: &mut Origins,
) -> Result<(), ConfigError> {
    let fail = |message: String| ConfigError::Invalid {
        origin: format!("--set {arg}"),
        message,
    };
    let (path, value_text) = arg
        .split_once('=')
        .ok_or_else(|| fail("expected section.key=value".to_string()))?;
    let path = path.trim();
    let (section, key) = path
        .split_once('.')
        .ok_or_else(|| fail(format!("`{path}` is not of the form section.key")))?;
    let Some(toml::Value::Table(keys)) = merged.get_mut(section) else {
        return Err(fail(format!(
            "unknown section [{section}]; the sections are {}",
            section_names()
        )));
    };
    if !keys.contains_key(key) {
        return Err(fail(unknown_key_message(section, key, keys)));
    }
    let value = parse_override_value(value_text.trim())
        .ok_or_else(|| fail(format!("`{value_text}` is not a TOML value")))?;
    keys.insert(key.to_string(), value);
    origins.overrides.insert(path.to_string(), arg.to_string());
    Ok(())
}

/// A TOML value, or a bare word taken as a string (`--set output.kind=file`).
fn parse_override_value(text: &str) -> Option<toml::Value> {
    if let Ok(mut table) = toml::from_str::<toml::Table>(&format!("v = {text}")) {
        return table.remove("v");
    }
    let bare = !text.is_empty()
        && text
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "_./:+-@".contains(c));
    bare.then(|| toml::Value::String(text.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(text: &str, overrides: &[&str]) -> Result<Config, String> {
        let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
        Config::from_toml_str(text, "edmd.toml", &overrides).map_err(|e| e.to_string())
    }

    #[test]
    fn shipped_default_is_valid_and_matches_design() {
        let c = Config::default();
        assert_eq!(c.machine.axes, vec![Axis::X, Axis::Y]);
        assert_eq!(c.machine.step_mm, vec![0.001, 0.001]);
        assert_eq!(c.interpolation.predictor, Predictor::Taylor);
        assert_eq!(c.interpolation.segmentation, Segmentation::Chord);
        assert_eq!(c.buffer.capacity, 1024);
        assert_eq!(c.buffer.reserved, 256);
        assert_eq!(c.fine.tick_us, 50);
        assert!(c.fine.virtual_time);
        assert_eq!(c.output.kind, OutputKind::Sim);
        assert_eq!(c.gap.kind, GapKind::Sim);
        assert_eq!(c.daemon.socket, PathBuf::from("/run/edmd/edmd.sock"));
    }

    #[test]
    fn every_default_key_is_commented_in_the_shipped_file() {
        // Each `key = value` line is preceded by a comment line (possibly a run of them).
        let lines: Vec<&str> = DEFAULT_CONFIG_TOML.lines().collect();
        for (i, line) in lines.iter().enumerate() {
            let t = line.trim();
            if t.is_empty() || t.starts_with('#') || t.starts_with('[') {
                continue;
            }
            assert!(
                i > 0 && lines[i - 1].trim().starts_with('#'),
                "line {} `{t}` has no comment above it",
                i + 1
            );
        }
    }

    #[test]
    fn a_partial_file_keeps_the_other_defaults() {
        let c = load("[buffer]\ncapacity = 64\nreserved = 16\n", &[]).unwrap();
        assert_eq!(c.buffer.capacity, 64);
        assert_eq!(c.machine, Config::default().machine);
    }

    #[test]
    fn unknown_key_is_named_with_its_line() {
        let err = load("[buffer]\ncapacity = 64\ncapcity = 3\n", &[]).unwrap_err();
        assert!(
            err.starts_with("edmd.toml:3:1: unknown key `capcity` in [buffer]"),
            "{err}"
        );
        let err = load("\n[bufer]\n", &[]).unwrap_err();
        assert!(
            err.starts_with("edmd.toml:2:2: unknown section [bufer]"),
            "{err}"
        );
    }

    #[test]
    fn validation_errors_point_at_the_key() {
        let err = load("[buffer]\ncapacity = 100\nreserved = 100\n", &[]).unwrap_err();
        assert!(
            err.starts_with("edmd.toml:3:1: buffer.reserved: must be at least 0 and less than"),
            "{err}"
        );
        let err = load("[machine]\nstep_mm = [0.001, 0.0]\n", &[]).unwrap_err();
        assert!(
            err.starts_with(
                "edmd.toml:2:1: machine.step_mm: must be a finite number greater than 0"
            ),
            "{err}"
        );
        let err = load("[interpolation]\nchord_tolerance_mm = -1\n", &[]).unwrap_err();
        assert!(
            err.contains("edmd.toml:2:1: interpolation.chord_tolerance_mm"),
            "{err}"
        );
        let err = load("[machine]\naxes = [\"X\", \"Q\"]\nstep_mm = [1, 1]\n", &[]).unwrap_err();
        assert!(err.contains("\"Q\" is not an axis"), "{err}");
        let err = load("[machine]\naxes = [\"X\", \"Y\", \"Z\"]\n", &[]).unwrap_err();
        assert!(
            err.contains("machine.step_mm: has 2 values but machine.axes has 3"),
            "{err}"
        );
    }

    #[test]
    fn type_errors_and_bad_enum_values_are_located() {
        let err = load("[buffer]\ncapacity = \"big\"\n", &[]).unwrap_err();
        assert!(
            err.starts_with("edmd.toml:2:1: buffer.capacity: invalid type"),
            "{err}"
        );
        let err = load("[interpolation]\npredictor = \"adams\"\n", &[]).unwrap_err();
        assert!(
            err.contains("edmd.toml:2:1: interpolation.predictor: unknown variant `adams`"),
            "{err}"
        );
    }

    #[test]
    fn syntax_errors_carry_line_and_column() {
        let err = load("[buffer]\ncapacity = = 3\n", &[]).unwrap_err();
        assert!(err.starts_with("edmd.toml:2:"), "{err}");
    }

    #[test]
    fn overrides_apply_in_order_and_are_validated() {
        let c = load(
            "",
            &[
                "buffer.capacity=64",
                "buffer.reserved=8",
                "output.kind=file",
                "machine.axes=[\"X\",\"Y\",\"Z\"]",
                "machine.step_mm=[0.001,0.001,0.0005]",
                "buffer.capacity=128",
            ],
        )
        .unwrap();
        assert_eq!(c.buffer.capacity, 128);
        assert_eq!(c.output.kind, OutputKind::File);
        assert_eq!(c.machine.axes.len(), 3);
        let err = load("", &["buffer.reserved=5000"]).unwrap_err();
        assert!(
            err.starts_with("--set buffer.reserved=5000: buffer.reserved"),
            "{err}"
        );
        let err = load("", &["buffer.size=5"]).unwrap_err();
        assert!(err.contains("unknown key `size` in [buffer]"), "{err}");
        let err = load("", &["capacity=5"]).unwrap_err();
        assert!(err.contains("not of the form section.key"), "{err}");
        let err = load("", &["fine.tick_us=fast"]).unwrap_err();
        assert!(
            err.starts_with("--set fine.tick_us=fast: fine.tick_us: invalid type"),
            "{err}"
        );
    }

    #[test]
    fn cross_key_rules() {
        let err = load("[output]\nkind = \"parport\"\n", &[]).unwrap_err();
        assert!(err.contains("fine.virtual_time: must be false"), "{err}");
        let err = load("[gap]\nkind = \"parport\"\n", &[]).unwrap_err();
        assert!(err.contains("gap.kind"), "{err}");
    }

    #[test]
    fn parport_pins_and_timing_are_checked() {
        const PORT: &str = "[output]\nkind = \"parport\"\n[fine]\nvirtual_time = false\n";
        let c = load(PORT, &[]).unwrap();
        assert_eq!(c.parport.step_pins, [2, 4, 6, 8]);
        assert_eq!(c.parport.dir_pins, [3, 5, 7, 9]);
        assert_eq!(
            (c.parport.short_pin, c.parport.open_pin),
            (Some(10), Some(11))
        );
        assert_eq!(c.parport.enable_pin, None);
        let err = |text: &str, sets: &[&str]| load(text, sets).unwrap_err();
        assert!(
            err("[parport]\ninvert_pins = [20]\n", &[]).contains("20 is not a signal pin"),
            "ground pins cannot be inverted"
        );
        assert!(err("[parport]\ninvert_pins = [2, 2]\n", &[]).contains("pin 2 is listed twice"));
        assert!(
            err("[parport]\nenable_pin = 9\n", &[])
                .contains("parport.enable_pin: pin 9 is already used by parport.dir_pins")
        );
        assert!(
            err("[parport]\nopen_pin = 10\n", &[]).contains("already used by parport.short_pin")
        );
        assert!(err("[parport]\nstep_length_ns = 0\n", &[]).contains("parport.step_length_ns"));
        // Axis count and timing only matter when the port is in use.
        let four_axes = [
            "machine.axes=[\"X\",\"Y\",\"Z\",\"A\",\"B\"]",
            "machine.step_mm=[0.001,0.001,0.001,0.001,0.001]",
        ];
        load("", &four_axes).unwrap();
        let e = err(PORT, &four_axes);
        assert!(
            e.contains("parport.step_pins: has 4 pins but machine.axes has 5 axes"),
            "{e}"
        );
        load("", &["fine.tick_us=10"]).unwrap();
        let e = err(PORT, &["fine.tick_us=40"]);
        assert!(e.contains("raise fine.tick_us to at least 45"), "{e}");
        let e = err(
            "[output]\nkind = \"parport\"\n[fine]\nvirtual_time = false\n[gap]\nkind = \"parport\"\n",
            &["parport.short_pin=0", "parport.open_pin=0"],
        );
        assert!(
            e.contains("needs parport.short_pin or parport.open_pin"),
            "{e}"
        );
    }

    #[test]
    fn line_col_counts_characters() {
        assert_eq!(line_col("ab\ncµd", 6), (2, 3));
        assert_eq!(line_col("ab\ncµd", 5), (2, 2)); // inside µ: rounds down, no panic
        assert_eq!(line_col("", 0), (1, 1));
    }
}
