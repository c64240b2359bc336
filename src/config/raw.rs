//! The raw layer: whatever serde can read from the merged TOML table, before any rule is
//! checked. One struct per section, `deny_unknown_fields` on each (the overlay already
//! refuses keys the shipped default lacks; this is the second lock). Numbers stay `i64`
//! here so that a negative or huge value reaches validation and gets a worded error.

use serde::Deserialize;

use super::{GapKind, LogFormat, LogLevel, OutputKind, ServoLaw};
use crate::vocab::{Predictor, Segmentation};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawConfig {
    pub(super) machine: RawMachine,
    pub(super) interpolation: RawInterpolation,
    pub(super) buffer: RawBuffer,
    pub(super) fine: RawFine,
    pub(super) output: RawOutput,
    pub(super) gap: RawGap,
    pub(super) parport: RawParport,
    pub(super) hal: RawHal,
    pub(super) servo: RawServo,
    pub(super) sim: RawSim,
    pub(super) daemon: RawDaemon,
    pub(super) log: RawLog,
    pub(super) program: RawProgram,
    pub(super) compensation: RawCompensation,
    pub(super) generator: RawGenerator,
    pub(super) homing: RawHoming,
    pub(super) wire: RawWire,
    pub(super) sinker: RawSinker,
    pub(super) technology: RawTechnology,
    pub(super) adaptive: RawAdaptive,
}

/// `[adaptive]`: the off-time law.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawAdaptive {
    pub(super) enabled: bool,
    pub(super) window_ms: f64,
    pub(super) lengthen: f64,
    pub(super) shorten: f64,
    pub(super) margin: f64,
    pub(super) arc_limit: f64,
    pub(super) limit_w_at_20mm: f64,
    pub(super) limit_height_exponent: f64,
    pub(super) poor_flushing_factor: f64,
    pub(super) poor_flushing_arc_share: f64,
    pub(super) poor_flushing_below: f64,
    pub(super) discharge_voltage_v: f64,
    pub(super) height_mm2_per_as: f64,
    pub(super) height_window_mm: f64,
    pub(super) arc_charge_weight: f64,
    pub(super) initial_height_mm: f64,
    pub(super) off_time_min_us: f64,
    pub(super) off_time_max_us: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawTechnology {
    pub(super) dir: String,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawHoming {
    pub(super) required: RawRequired,
    pub(super) require_after_start: bool,
    pub(super) lost_on_estop: bool,
    pub(super) axis: Vec<RawHomingAxis>,
}

/// `homing.required`: `true`, `false` or `"auto"` (on with a parallel port).
#[derive(Debug, Deserialize)]
#[serde(untagged)]
pub(super) enum RawRequired {
    Flag(bool),
    Word(String),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawHomingAxis {
    pub(super) axis: String,
    #[serde(default)]
    pub(super) switch_pin: i64,
    pub(super) direction: String,
    pub(super) search_feed_mm_per_min: f64,
    pub(super) latch_feed_mm_per_min: f64,
    pub(super) home_position_mm: f64,
    #[serde(default)]
    pub(super) final_move_mm: f64,
    #[serde(default)]
    pub(super) sequence: i64,
    #[serde(default)]
    pub(super) search_distance_mm: Option<f64>,
    #[serde(default)]
    pub(super) latch_distance_mm: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawGenerator {
    pub(super) condition: Vec<RawCondition>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawCondition {
    pub(super) number: i64,
    #[serde(alias = "on_time_us")]
    pub(super) on_us: f64,
    #[serde(alias = "off_time_us")]
    pub(super) off_us: f64,
    #[serde(alias = "peak_current_a")]
    pub(super) current_a: f64,
    #[serde(alias = "servo_ref_v")]
    pub(super) v_ref: f64,
    #[serde(default)]
    pub(super) feed_mm_per_min: Option<f64>,
    #[serde(default)]
    pub(super) open_voltage_v: Option<f64>,
    #[serde(default)]
    pub(super) wire_tension_n: Option<f64>,
    #[serde(default)]
    pub(super) wire_speed_m_per_min: Option<f64>,
    #[serde(default)]
    pub(super) flushing_bar: Option<f64>,
    #[serde(default)]
    pub(super) jump_interval_s: Option<f64>,
    #[serde(default)]
    pub(super) jump_height_mm: Option<f64>,
    #[serde(default)]
    pub(super) jump_feed_mm_per_min: Option<f64>,
    /// Adapt this condition's off time (`[adaptive]`): true or false whatever
    /// `adaptive.enabled` says; absent: as it says.
    #[serde(default)]
    pub(super) adaptive: Option<bool>,
    /// The bounds the adaptive law keeps this condition's off time within, µs.
    #[serde(default)]
    pub(super) off_time_min_us: Option<f64>,
    #[serde(default)]
    pub(super) off_time_max_us: Option<f64>,
    #[serde(default)]
    pub(super) corner_angle_deg: Option<f64>,
    #[serde(default)]
    pub(super) corner_feed_factor: Option<f64>,
    #[serde(default)]
    pub(super) corner_distance_mm: Option<f64>,
    #[serde(default)]
    pub(super) corner_dwell_ms: Option<f64>,
    #[serde(default)]
    pub(super) orbit_shape: Option<String>,
    #[serde(default)]
    pub(super) orbit_radius_mm: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawCompensation {
    pub(super) d_mm: Vec<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawProgram {
    pub(super) block_delete: bool,
    pub(super) optional_stop: bool,
    pub(super) max_loop_iterations: i64,
    #[serde(default)]
    pub(super) mcode: Vec<RawMcode>,
}

/// `[[program.mcode]]`: a machine builder's M-code and its action.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawMcode {
    pub(super) number: i64,
    pub(super) action: String,
    #[serde(default)]
    pub(super) message: Option<String>,
    #[serde(default)]
    pub(super) condition: Option<i64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawMachine {
    pub(super) axes: Vec<String>,
    pub(super) step_mm: Vec<f64>,
    pub(super) max_feed_mm_per_min: f64,
    pub(super) max_normal_accel_mm_per_s2: f64,
    pub(super) max_tangential_accel_mm_per_s2: f64,
    pub(super) max_jog_feed_mm_per_min: f64,
    pub(super) dry_run_feed_mm_per_min: f64,
    pub(super) max_jerk_mm_per_s3: f64,
    pub(super) travel_mm: std::collections::BTreeMap<String, Vec<f64>>,
    #[serde(default)]
    pub(super) safe_z_mm: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawInterpolation {
    pub(super) predictor: Predictor,
    pub(super) segmentation: Segmentation,
    pub(super) chord_tolerance_mm: f64,
    pub(super) period_ms: f64,
    pub(super) max_segment_mm: f64,
    pub(super) lookahead_segments: i64,
    pub(super) fluctuation_tolerance: f64,
    pub(super) max_corrections: i64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawBuffer {
    pub(super) capacity: i64,
    pub(super) reserved: i64,
    pub(super) trail_blocks: i64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawFine {
    pub(super) tick_us: i64,
    pub(super) virtual_time: bool,
    pub(super) ticks_per_wake: i64,
    pub(super) rt_priority: i64,
    pub(super) lock_memory: bool,
    pub(super) cpu: i64,
}

/// `[hal]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawHal {
    pub(super) component: String,
    pub(super) max_following_error_mm: f64,
    pub(super) gap_input: String,
    pub(super) probe_input: bool,
    pub(super) library: String,
    pub(super) heartbeat_ms: f64,
    pub(super) rt_beat_timeout_ms: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawOutput {
    pub(super) kind: OutputKind,
    pub(super) path: String,
    pub(super) trace: bool,
    pub(super) fault_at_tick: i64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawGap {
    pub(super) kind: GapKind,
    pub(super) script: String,
    pub(super) trace: bool,
    pub(super) iio_device: String,
    pub(super) iio_channel: String,
    pub(super) iio_gain: f64,
    pub(super) iio_rate_hz: f64,
    pub(super) short_below_v: f64,
    pub(super) open_above_v: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawParport {
    pub(super) step_pins: Vec<i64>,
    pub(super) dir_pins: Vec<i64>,
    pub(super) enable_pin: i64,
    pub(super) flush_pin: i64,
    pub(super) spark_pin: i64,
    pub(super) condition_pins: Vec<i64>,
    pub(super) invert_pins: Vec<i64>,
    pub(super) step_length_ns: i64,
    pub(super) step_space_ns: i64,
    pub(super) dir_setup_ns: i64,
    pub(super) dir_hold_ns: i64,
    pub(super) short_pin: i64,
    pub(super) open_pin: i64,
    pub(super) probe_pin: i64,
    pub(super) wire_break_pin: i64,
    pub(super) estop_pin: i64,
    pub(super) limit_pins: std::collections::BTreeMap<String, i64>,
    pub(super) gap_filter_ticks: i64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawServo {
    pub(super) normal_feed_mm_per_min: f64,
    pub(super) open_feed_mm_per_min: f64,
    pub(super) retract_feed_mm_per_min: f64,
    pub(super) reverse_accel_mm_per_s2: f64,
    pub(super) short_confirm_ticks: i64,
    pub(super) min_retract_um: f64,
    pub(super) max_short_s: f64,
    pub(super) law: ServoLaw,
    pub(super) v_ref: f64,
    pub(super) voltage_gain_mm_per_min_per_v: f64,
    pub(super) voltage_filter_ms: f64,
    pub(super) ratio_ref: f64,
    pub(super) ratio_gain_mm_per_min: f64,
    pub(super) ratio_short_limit: f64,
    pub(super) ratio_open_limit: f64,
    pub(super) jump_interval_s: f64,
    pub(super) jump_height_mm: f64,
    pub(super) jump_feed_mm_per_min: f64,
    pub(super) max_open_mm: f64,
    pub(super) rethread_feed_mm_per_min: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSim {
    pub(super) seed: i64,
    pub(super) initial_gap_um: f64,
    pub(super) short_gap_um: f64,
    pub(super) open_gap_um: f64,
    pub(super) erosion_mm_per_min: f64,
    pub(super) debris_shorts_per_mm: f64,
    pub(super) debris_shorts_per_s: f64,
    pub(super) debris_clear_um: f64,
    pub(super) wire_breaks_per_m: f64,
    pub(super) events: String,
    pub(super) home_switch_mm: std::collections::BTreeMap<String, f64>,
    pub(super) part_edge_mm: std::collections::BTreeMap<String, [f64; 2]>,
    pub(super) hole_center_mm: Vec<f64>,
    pub(super) hole_diameter_mm: f64,
    pub(super) touch_bounce_mm: f64,
    pub(super) breakthrough_at_mm: f64,
    pub(super) model: String,
    pub(super) work_height_mm: f64,
    pub(super) discharge: RawDischarge,
}

/// `[sim.discharge]`: the discharge model's constants.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawDischarge {
    pub(super) side_gaps_um: f64,
    pub(super) discharge_voltage_v: f64,
    pub(super) ignition_median_us: [f64; 3],
    pub(super) ignition_timeout_us: f64,
    pub(super) arc_delay_us: f64,
    pub(super) deionization_us: f64,
    pub(super) removal_mm3_per_j: f64,
    pub(super) arc_removal: f64,
    pub(super) debris_per_mm2: f64,
    pub(super) arc_debris: f64,
    pub(super) flush_time_ms: f64,
    pub(super) flushing_depth_mm: f64,
    pub(super) debris_bursts_per_s: f64,
    pub(super) debris_burst: f64,
    pub(super) short_contamination: f64,
    pub(super) wire_heat_fraction: f64,
    pub(super) wire_convection_w_per_m2k: f64,
    pub(super) arc_spot_mm: f64,
    pub(super) wire_break_rise_k: f64,
    pub(super) wire_density_kg_m3: f64,
    pub(super) wire_heat_capacity_j_kgk: f64,
    pub(super) on_time_us: f64,
    pub(super) off_time_us: f64,
    pub(super) peak_current_a: f64,
    pub(super) open_voltage_v: f64,
    pub(super) wire_speed_m_per_min: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawDaemon {
    pub(super) socket: String,
    pub(super) socket_mode: String,
    pub(super) socket_group: String,
    pub(super) program_dir: String,
    pub(super) state_dir: String,
    pub(super) job_history: String,
    pub(super) checkpoint: String,
    pub(super) state_file: String,
    pub(super) checkpoint_interval_s: f64,
    pub(super) status_interval_s: f64,
    pub(super) max_clients: i64,
    pub(super) report_dir: String,
    pub(super) http: String,
    pub(super) http_token_file: String,
    pub(super) http_allowed_hosts: Vec<String>,
    pub(super) http_max_connections: i64,
    pub(super) opcua: String,
    pub(super) opcua_users_file: String,
    pub(super) opcua_pki_dir: String,
    pub(super) mqtt: RawMqtt,
}

/// `[daemon.mqtt]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawMqtt {
    pub(super) broker: String,
    pub(super) group_id: String,
    pub(super) node_id: String,
    pub(super) credentials_file: String,
    pub(super) ca_file: String,
    pub(super) keep_alive_s: i64,
    pub(super) interval_s: f64,
    pub(super) deadband_mm: f64,
    pub(super) deadband_mm_per_min: f64,
    pub(super) deadband_fraction: f64,
    pub(super) deadband_s: f64,
    pub(super) queue: i64,
    pub(super) commands: bool,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawLog {
    pub(super) level: LogLevel,
    pub(super) format: LogFormat,
}

/// `[sinker]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSinker {
    pub(super) breakthrough: bool,
    pub(super) breakthrough_extra_mm: f64,
    pub(super) breakthrough_open_ratio: f64,
    pub(super) breakthrough_window_ms: f64,
    pub(super) orbit: RawOrbit,
}

/// `[sinker.orbit]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawOrbit {
    pub(super) shape: String,
    pub(super) radius_mm: f64,
    pub(super) feed_mm_per_min: f64,
    pub(super) expand: bool,
}

/// `[wire]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawWire {
    pub(super) pass: Vec<RawPass>,
    pub(super) tab_mm: f64,
    pub(super) lower_guide_mm: f64,
    pub(super) upper_guide_mm: f64,
    pub(super) thickness_mm: f64,
    pub(super) diameter_mm: f64,
    pub(super) touch_condition: i64,
    pub(super) touch_feed_mm_per_min: f64,
    pub(super) touch_search_mm: f64,
    pub(super) touch_backoff_mm: f64,
    pub(super) touch_retries: i64,
    pub(super) touch_corner_clearance_mm: f64,
    pub(super) touch_center_rounds: i64,
}

/// `[[wire.pass]]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawPass {
    #[serde(default)]
    pub(super) offset_mm: Option<f64>,
    #[serde(default)]
    pub(super) d: Option<i64>,
    pub(super) condition: i64,
    #[serde(default)]
    pub(super) feed_mm_per_min: Option<f64>,
    #[serde(default)]
    pub(super) reverse: bool,
}
