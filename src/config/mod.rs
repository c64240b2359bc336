//! Configuration: TOML text and `--set` overrides in, a validated [`Config`] out.
//!
//! Two layers, as in ripgrep: a raw layer that is whatever serde can read (`raw.rs`), and the
//! validated [`Config`] that the rest of edmd trusts (positive step sizes, `reserved <
//! capacity`, ...; `validate.rs`). The text under them is layered in `overrides.rs`.
//!
//! `config` stands on floor 7, above the pipeline and the devices: it reads their settings
//! out of the configuration and hands them down as plain values (`settings.rs`), so no
//! lower floor ever sees a `Config`.
//!
//! The shipped `config/edmd.toml` is the single source of truth for which keys exist and what
//! their defaults are: it is embedded in the binary, a user's file is overlaid on it key by key,
//! and any key the default does not have is rejected with its line. Every error names where the
//! offending value came from: `file:line:col` for the file, the `--set` argument for an override.

mod condition;
pub use condition::{ConditionSpec, FeedRule};
mod corners;
pub use corners::CornerControl;
mod hal;
pub use hal::HalConfig;
mod homing;
mod mcode;
mod mqtt;
mod net;
mod opcua;
pub use mqtt::{Deadbands, MqttBroker, MqttConfig};
pub use opcua::OpcUaEndpoint;
mod overrides;
mod parport;
mod raw;
mod servo;
mod settings;
pub use settings::max_feed_warning;
mod sim;
mod sinker;
#[cfg(test)]
mod tests;
mod validate;
mod wire;
pub use wire::{Guides, TouchConfig, WireConfig, WirePass};

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::vocab::{Axis, Predictor, Segmentation, TickPeriod};
use overrides::{Origins, apply_override, default_table, overlay, parse_user_table};
use raw::RawConfig;

pub use crate::parport::ParportConfig;
pub use crate::sim::SimConfig;

/// The default configuration, exactly as shipped in `config/edmd.toml`.
pub const DEFAULT_CONFIG_TOML: &str = include_str!("../../config/edmd.toml");

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

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum OutputKind {
    Sim,
    File,
    Parport,
    Hal,
    Null,
}

impl OutputKind {
    /// The configuration's word for it.
    pub fn name(self) -> &'static str {
        match self {
            OutputKind::Sim => "sim",
            OutputKind::File => "file",
            OutputKind::Parport => "parport",
            OutputKind::Hal => "hal",
            OutputKind::Null => "null",
        }
    }

    /// Real hardware: claimed once by the daemon and lent to each job, never driven in
    /// virtual time, homed before use (`homing.required = "auto"`).
    pub fn hardware(self) -> bool {
        matches!(self, OutputKind::Parport | OutputKind::Hal)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GapKind {
    Sim,
    Script,
    Parport,
    Hal,
    Iio,
    None,
}

impl GapKind {
    /// The gap is read from the output's own device (the port's status pins, HAL's pins).
    pub fn from_output_device(self) -> bool {
        matches!(self, GapKind::Parport | GapKind::Hal)
    }
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
    /// The journal when systemd connected stderr to it, else human on a terminal, else plain.
    Auto,
    Human,
    Plain,
    Json,
    /// systemd's native journal protocol (priorities and `EDMD_*` fields); plain if there is
    /// no journal.
    Journal,
}

#[derive(Debug, Clone, PartialEq)]
pub struct MachineConfig {
    pub axes: Vec<Axis>,
    pub step_mm: Vec<f64>,
    pub max_feed_mm_per_min: f64,
    pub max_normal_accel_mm_per_s2: f64,
    pub max_tangential_accel_mm_per_s2: f64,
    /// Fastest jog, mm/min.
    pub max_jog_feed_mm_per_min: f64,
    /// A dry run's feed moves go at this feed, mm/min (rapids stay rapids).
    pub dry_run_feed_mm_per_min: f64,
    /// Jerk limit of positioning moves (rapids, jumps, rethread returns), mm/s³; 0: none.
    pub max_jerk_mm_per_s3: f64,
    /// Soft limits per axis (machine order); `None`: the axis has none.
    pub travel: Vec<Option<Travel>>,
    /// Machine Z (mm) a direct approach retracts to before it moves across the work (a job
    /// run from a line); `None`: the machine has no Z or no safe height is set.
    pub safe_z_mm: Option<f64>,
}

/// An axis's soft limits, machine coordinates, mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Travel {
    pub min_mm: f64,
    pub max_mm: f64,
}

impl MachineConfig {
    /// The axes with no soft limit, as letters (`"Z, A"`), or `None` when every axis has one.
    pub fn unlimited_axes(&self) -> Option<String> {
        let free: Vec<String> = self
            .axes
            .iter()
            .zip(&self.travel)
            .filter(|(_, t)| t.is_none())
            .map(|(a, _)| a.letter().to_string())
            .collect();
        (!free.is_empty()).then(|| free.join(", "))
    }

    /// The indices of X and Y in `axes` (the program plane), when the machine has both.
    pub fn plane_axes(&self) -> Option<[usize; 2]> {
        let index = |a: Axis| self.axes.iter().position(|&x| x == a);
        Some([index(Axis::X)?, index(Axis::Y)?])
    }

    /// The indices of U and V in `axes` (a four-axis wire machine's upper guide), when the
    /// machine has X, Y, U and V.
    pub fn upper_guide_axes(&self) -> Option<[usize; 2]> {
        let index = |a: Axis| self.axes.iter().position(|&x| x == a);
        self.plane_axes()?;
        Some([index(Axis::U)?, index(Axis::V)?])
    }

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
    /// Executed blocks kept beyond the reserved area, back to the start of the cut: the way
    /// back to the start hole after a wire break (0: only the reserved area).
    pub trail_blocks: usize,
}

#[derive(Debug, Clone, PartialEq)]
pub struct FineConfig {
    /// `fine.tick_us`.
    pub tick: TickPeriod,
    pub virtual_time: bool,
    /// `fine.ticks_per_wake`: ticks run back to back per wake-up in real time (1 on a
    /// machine).
    pub ticks_per_wake: u32,
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
    /// The voltages that separate the gap's states (the ADC input, the voltage law and the
    /// simulator read them).
    pub volts: crate::vocab::GapVolts,
    /// `gap.kind = "iio"`: the ADC channel.
    pub iio: crate::gap::IioSettings,
}

#[derive(Debug, Clone, PartialEq)]
pub struct ServoConfig {
    pub normal_feed_mm_per_min: f64,
    pub open_feed_mm_per_min: f64,
    pub retract_feed_mm_per_min: f64,
    /// Braking into a turn-back, the reversal, the turn-back and the re-advance (mm/s²; the
    /// machine's largest acceleration where the file says 0).
    pub reverse_accel_mm_per_s2: f64,
    /// A short is believed after this many ticks in a row.
    pub short_confirm_ticks: u32,
    /// The least a turn-back backs off, mm.
    pub min_retract_mm: f64,
    /// 0: off.
    pub max_short_s: f64,
    pub law: ServoLaw,
    pub v_ref: f64,
    pub voltage_gain_mm_per_min_per_v: f64,
    pub voltage_filter_ms: f64,
    pub ratio_ref: f64,
    pub ratio_gain_mm_per_min: f64,
    pub ratio_short_limit: f64,
    pub ratio_open_limit: f64,
    /// Sinker jumps: every so many seconds of cutting (0: off), this high along the path, at
    /// this feed.
    pub jumps: Jumps,
    /// Cutting travel through an open gap that counts as a wire break, mm (0: off).
    pub max_open_mm: f64,
    /// Feed back to the start hole after a wire break and back to the break point, mm/min.
    pub rethread_feed_mm_per_min: f64,
}

/// Jump settings (`[servo]`, or a machining condition's where it gives them).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Jumps {
    /// Seconds of cutting between jumps; 0: no jumps.
    pub interval_s: f64,
    pub height_mm: f64,
    pub feed_mm_per_min: f64,
}

/// `servo.law`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ServoLaw {
    /// `"three-state"`, also spelled `"state"`.
    #[serde(alias = "state")]
    ThreeState,
    Voltage,
    Ratio,
}

#[derive(Debug, Clone, PartialEq)]
pub struct DaemonConfig {
    pub socket: PathBuf,
    /// Permission bits of the socket.
    pub socket_mode: u32,
    /// Group owning the socket (`None`: the daemon's own).
    pub socket_group: Option<String>,
    pub program_dir: PathBuf,
    /// Where the daemon keeps its files unless one is given its own path: the checkpoint,
    /// the machine state, the job history and hour counters, reports, the HTTP token, the
    /// OPC UA users and certificates.
    pub state_dir: PathBuf,
    /// The job history (one JSON line a job); the hour counters are `counters.json` beside it.
    pub job_history: PathBuf,
    pub checkpoint: PathBuf,
    /// The machine state (position, homed axes, work offsets); by default beside the
    /// checkpoint, `machine-state.json`.
    pub state_file: PathBuf,
    /// Checkpoint period while cutting (s); `None`: only at standstills.
    pub checkpoint_interval_s: Option<f64>,
    /// Period of the status line in the log (s); `None`: no periodic line.
    pub status_interval_s: Option<f64>,
    /// Control connections served at once; more are refused with an error reply.
    pub max_clients: usize,
    /// Where each job's report of what ran goes (`<dir>/<job>/`); `None`: no reports.
    pub report_dir: Option<PathBuf>,
    /// Where the web page, API and metrics listen; `None`: off.
    pub http: Option<std::net::SocketAddr>,
    /// The bearer token every control request over HTTP needs (created when missing).
    pub http_token_file: PathBuf,
    /// Host names the web side answers to besides IP addresses and `localhost`.
    pub http_allowed_hosts: Vec<String>,
    /// HTTP connections at once (the daemon keeps it below its descriptor limit too).
    pub http_max_connections: usize,
    /// Where the OPC UA server listens; `None`: off.
    pub opcua: Option<OpcUaEndpoint>,
    /// The OPC UA users (`name:password` lines) allowed to call Hold and Abort.
    pub opcua_users_file: PathBuf,
    /// The OPC UA server's certificate store: its own key pair, trusted and rejected clients.
    pub opcua_pki_dir: PathBuf,
    /// The Sparkplug B edge node on the plant's broker; `None`: off.
    pub mqtt: Option<MqttConfig>,
}

/// One machining condition of the generator (`[generator] condition`), selected by `E<number>`.
#[derive(Debug, Clone, PartialEq)]
pub struct Condition {
    pub number: u32,
    /// What it sets the generator to; `servo_ref_v` is the voltage law's reference while
    /// it runs.
    pub generator: crate::vocab::GeneratorSetPoints,
    /// The advance feed while sparking (three-state law), mm/min.
    pub feed_mm_per_min: f64,
    /// Jumps while this condition runs: each `None` keeps the `[servo]` setting.
    pub jump_interval_s: Option<f64>,
    pub jump_height_mm: Option<f64>,
    pub jump_feed_mm_per_min: Option<f64>,
    /// Corner control while this condition cuts.
    pub corner: Option<CornerControl>,
    /// This condition's own orbit (its stage's undersize): each `None` keeps
    /// `[sinker.orbit]`'s.
    pub orbit_shape: Option<crate::vocab::OrbitShape>,
    pub orbit_radius_mm: Option<f64>,
    /// Adapted by `[adaptive]` (`None`: as `adaptive.enabled` says), and the bounds of its
    /// off time (`None`: `[adaptive]`'s), µs.
    pub adaptive: Option<bool>,
    pub off_time_bounds_us: Option<[f64; 2]>,
}

/// `[adaptive]`: the off-time law, and which conditions it adapts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdaptiveConfig {
    /// Adapt every condition that does not say otherwise.
    pub enabled: bool,
    /// The law's settings, for ticks of `fine.tick_us`.
    pub law: crate::process::AdaptiveSettings,
    /// The off time's bounds for a condition that gives none, µs.
    pub off_time_bounds_us: [f64; 2],
}

/// `[sinker]`: how a die-sinker's sinking moves orbit.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SinkerConfig {
    pub orbit: crate::gcode::OrbitOptions,
    /// Breakthrough on drilling moves: on or off, the extra travel past it (mm), the open
    /// ratio that tells it and the window it is judged over (s of cutting).
    pub breakthrough: bool,
    pub breakthrough_extra_mm: f64,
    pub breakthrough_open_ratio: f64,
    pub breakthrough_window_s: f64,
}

/// `[compensation]`: the wire offset registers.
#[derive(Debug, Clone, PartialEq)]
pub struct CompensationConfig {
    /// `d_mm[k]` is register `Dk` (mm); `d_mm[0]` is 0.
    pub d_mm: Vec<f64>,
}

/// `[program]`: switches that change how a program reads.
#[derive(Debug, Clone, PartialEq)]
pub struct ProgramConfig {
    pub block_delete: bool,
    pub optional_stop: bool,
    pub max_loop_iterations: u64,
    /// `[[program.mcode]]`: the machine builder's M-codes.
    pub mcodes: Vec<crate::gcode::VendorM>,
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
    pub hal: HalConfig,
    pub servo: ServoConfig,
    pub sim: SimConfig,
    pub daemon: DaemonConfig,
    pub log: LogConfig,
    pub program: ProgramConfig,
    pub compensation: CompensationConfig,
    /// `[generator] condition`, by number.
    pub conditions: Vec<Condition>,
    pub homing: HomingConfig,
    /// `[wire]`: the technology table of passes.
    pub wire: WireConfig,
    /// `[sinker]`: orbiting.
    pub sinker: SinkerConfig,
    /// `[technology]`: where the technology tables are.
    pub technology: TechnologyConfig,
    pub adaptive: AdaptiveConfig,
}

/// `[technology]`: the technology tables (`crate::technology`), one TOML file each.
#[derive(Debug, Clone, PartialEq)]
pub struct TechnologyConfig {
    /// The folder of the tables (every `*.toml` in it).
    pub dir: PathBuf,
}

/// `[homing]`: when the machine position must be known.
#[derive(Debug, Clone, PartialEq)]
pub struct HomingConfig {
    /// `run` is refused while an axis is not homed.
    pub required: bool,
    /// A daemon start unhomes every axis, even after a clean stop.
    pub require_after_start: bool,
    /// An E-stop unhomes every axis.
    pub lost_on_estop: bool,
    /// The axes homed by a switch (`[[homing.axis]]`), in the order they home: by
    /// `sequence`, then as listed.
    pub axes: Vec<HomingAxis>,
}

/// `[[homing.axis]]`: how one axis finds its home switch. Search towards the switch at the
/// search feed, back off until it releases, approach again at the latch feed: where it
/// closes is `home_position_mm`; then move `final_move_mm` (away from the switch).
#[derive(Debug, Clone, PartialEq)]
pub struct HomingAxis {
    /// Index in `machine.axes`.
    pub index: usize,
    pub axis: Axis,
    /// The parallel port's status pin of the switch (`None`: the simulator's switch only).
    pub switch_pin: Option<u8>,
    /// The search runs towards +.
    pub positive: bool,
    pub search_feed_mm_per_min: f64,
    pub latch_feed_mm_per_min: f64,
    /// The machine coordinate of the switch's latch point.
    pub home_position_mm: f64,
    /// The move after latching, mm (0 or away from the switch).
    pub final_move_mm: f64,
    pub sequence: u32,
    /// The longest search before homing gives up, mm.
    pub search_distance_mm: f64,
    /// The longest back-off and latch approach, mm.
    pub latch_distance_mm: f64,
}

impl HomingConfig {
    /// The homing settings of machine axis `index`, if it homes by a switch.
    pub fn axis(&self, index: usize) -> Option<&HomingAxis> {
        self.axes.iter().find(|a| a.index == index)
    }
}

impl Default for Config {
    /// The shipped default (`config/edmd.toml`).
    fn default() -> Self {
        Config::from_toml_str(DEFAULT_CONFIG_TOML, "<built-in default>", &[])
            .expect("the shipped default configuration is valid")
    }
}

/// The nominal cutting feed of each condition: the feed a cut advances at when the gap
/// behaves (the condition's sparking feed where it sets one, else
/// `servo.normal_feed_mm_per_min`). The plan's estimate and a job's ETA time cuts by it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SparkingFeeds {
    /// Without a condition of its own (mm/s).
    normal: f64,
    /// `(number, mm/s)`.
    conditions: Vec<(u32, f64)>,
}

impl SparkingFeeds {
    pub fn new(config: &Config) -> SparkingFeeds {
        SparkingFeeds {
            normal: config.servo.normal_feed_mm_per_min / 60.0,
            conditions: config
                .conditions
                .iter()
                .map(|c| (c.number, c.feed_mm_per_min / 60.0))
                .collect(),
        }
    }

    /// A cut's nominal feed in condition `n` (mm/s; 0: none in force).
    pub fn mm_per_s(&self, n: u32) -> f64 {
        self.conditions
            .iter()
            .find(|(c, _)| *c == n)
            .map_or(self.normal, |(_, f)| *f)
    }
}

impl Config {
    /// The E numbers `[generator] condition` defines.
    pub fn condition_numbers(&self) -> Vec<u32> {
        self.conditions.iter().map(|c| c.number).collect()
    }

    /// A wire break can be told on this machine (an open-gap limit, a wire-break input, the
    /// simulator's breaks, or a gap script, which may script one): only then does a job keep
    /// the trail a rethread walks back along (`buffer.trail_blocks`), so a machine that never
    /// rethreads runs in flat memory.
    pub fn wire_can_break(&self) -> bool {
        self.servo.max_open_mm > 0.0
            // HAL's wire-break-in pin is read whatever the gap input is.
            || self.output.kind == OutputKind::Hal
            || match self.gap.kind {
                GapKind::Parport => self.parport.wire_break_pin.is_some(),
                GapKind::Hal => true,
                GapKind::Sim => self.sim.wire_breaks_per_m > 0.0 || self.sim.events.is_some(),
                GapKind::Script => true,
                GapKind::Iio | GapKind::None => false,
            }
    }

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
                // A regular file only, opened without waiting: a FIFO in its place is an
                // error at once, not a thread waiting for a writer.
                let text = crate::sys::read_regular(path).map_err(|source| ConfigError::Io {
                    path: path.to_path_buf(),
                    source,
                })?;
                let (mut config, keys) =
                    Config::parse(&text, &path.display().to_string(), overrides)?;
                // The tables beside the file that names them (unless `--set` named them).
                let set = overrides
                    .iter()
                    .any(|o| o.trim_start().starts_with("technology.dir"));
                if config.technology.dir.is_relative() && !set {
                    let base = path.parent().unwrap_or(Path::new(""));
                    config.technology.dir = base.join(&config.technology.dir);
                }
                Ok((config, keys))
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
        let text = crate::vocab::without_bom(text);
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
