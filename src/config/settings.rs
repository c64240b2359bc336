//! The hand-down: the validated configuration turned into each lower floor's own settings,
//! as plain values in the units that floor computes in (mm, s, mm/s, steps).
//!
//! The floors below `config` never see a [`Config`]: each defines the settings it takes
//! (`PlanSettings`, `FineSettings`, `SimSettings`, `PinMap`, `StepTiming`) and this module
//! is the only place they are read out of one. Their `from_config` constructors live here,
//! beside the keys they read, so a renamed key or a unit change is one edit in one file.

use super::Config;
use super::ServoLaw;
use crate::fine::FineSettings;
use crate::gcode::{ProgramOptions, WorkStart};
use crate::hal::HalSettings;
use crate::parport::{PinMap, StepTiming};
use crate::path::{CutPlan, PathSpec};
use crate::preprocess::PlanSettings;
use crate::preprocess::corners::CornerRule;
use crate::process::{Condition, ConditionTable, OffTimeBounds, ServoSetPoints};
use crate::servo::{Feeds, Law};
use crate::sim::SimSettings;
use crate::vocab::{Axis, MAX_AXES};

/// `machine.step_mm` as a fixed array, unused axes 0.
pub(super) fn step_mm(config: &Config) -> [f64; MAX_AXES] {
    let mut step_mm = [0.0; MAX_AXES];
    for (slot, &s) in step_mm.iter_mut().zip(&config.machine.step_mm) {
        *slot = s;
    }
    step_mm
}

/// The chord tolerance the segmenter holds in machine space. On a four-axis wire machine the
/// upper guide's path is X/Y plus U/V, whose chord error can be √2 times the four-axis one
/// (the X/Y and U/V errors side by side): the tolerance is held there too by holding
/// `tolerance / √2` in four axes.
fn chord_tolerance(config: &Config) -> f64 {
    let axes = &config.machine.axes;
    let wire = [Axis::X, Axis::Y, Axis::U, Axis::V]
        .iter()
        .all(|a| axes.contains(a));
    let tolerance = config.interpolation.chord_tolerance_mm;
    if wire {
        tolerance / std::f64::consts::SQRT_2
    } else {
        tolerance
    }
}

impl PlanSettings {
    /// The preprocessor's settings: `[interpolation]` and the machine's limits, per second.
    pub fn from_config(config: &Config) -> PlanSettings {
        let m = &config.machine;
        let i = &config.interpolation;
        PlanSettings {
            predictor: i.predictor,
            segmentation: i.segmentation,
            tolerance_mm: chord_tolerance(config),
            max_segment_mm: i.max_segment_mm,
            period_s: i.period_ms / 1000.0,
            max_feed_mm_per_s: m.max_feed_mm_per_min / 60.0,
            // One step per axis per tick: the coarsest axis along its own direction.
            rapid_feed_mm_per_s: (m.max_feed_mm_per_min / 60.0)
                .min(m.step_mm.iter().cloned().fold(0.0, f64::max) / config.fine.tick.secs()),
            max_normal_accel_mm_per_s2: m.max_normal_accel_mm_per_s2,
            max_tangential_accel_mm_per_s2: m.max_tangential_accel_mm_per_s2,
            lookahead: i.lookahead_segments,
            fluctuation_tolerance: i.fluctuation_tolerance,
            max_corrections: i.max_corrections,
            corners: config
                .conditions
                .iter()
                .filter_map(|c| {
                    c.corner.map(|k| CornerRule {
                        condition: c.number,
                        min_turn: (180.0 - k.angle_deg).to_radians(),
                        feed_factor: k.feed_factor,
                        distance: k.distance_mm,
                        dwell_s: k.dwell_ms / 1000.0,
                    })
                })
                .collect(),
            rapid_stops: m.max_jerk_mm_per_s3 > 0.0,
            axis_cap_mm_per_s: axis_cap(config),
        }
    }
}

impl FineSettings {
    /// The tick core's settings: the tick, `a_T`, the servo's feeds per second, step sizes.
    pub fn from_config(config: &Config) -> FineSettings {
        let servo = &config.servo;
        FineSettings {
            dt: config.fine.tick.secs(),
            accel: config.machine.max_tangential_accel_mm_per_s2,
            reverse_accel: servo.reverse_accel_mm_per_s2,
            feeds: Feeds {
                normal: servo.normal_feed_mm_per_min / 60.0,
                open: servo.open_feed_mm_per_min / 60.0,
                retract: servo.retract_feed_mm_per_min / 60.0,
            },
            shorts: crate::servo::ShortRules {
                confirm_ticks: servo.short_confirm_ticks,
                min_retract_mm: servo.min_retract_mm,
            },
            step_mm: step_mm(config),
            dry_run: false,
            jerk: config.machine.max_jerk_mm_per_s3,
            lift_axis: config
                .machine
                .axes
                .iter()
                .position(|&a| a == crate::vocab::Axis::Z),
            breakthrough: {
                let s = &config.sinker;
                crate::fine::BreakthroughSettings {
                    enabled: s.breakthrough,
                    window_ticks: (s.breakthrough_window_s / config.fine.tick.secs())
                        .round()
                        .max(1.0) as u32,
                    open_ratio: s.breakthrough_open_ratio,
                    extra_mm: s.breakthrough_extra_mm,
                }
            },
            excursions: crate::fine::ExcursionSettings {
                jump_interval_ticks: (servo.jumps.interval_s / config.fine.tick.secs()).round()
                    as u64,
                jump_height_mm: servo.jumps.height_mm,
                jump_feed: servo.jumps.feed_mm_per_min / 60.0,
                max_open_mm: servo.max_open_mm,
                rethread_feed: servo.rethread_feed_mm_per_min / 60.0,
            },
            max_short_ticks: (servo.max_short_s / config.fine.tick.secs()).round() as u64,
            law: match servo.law {
                ServoLaw::ThreeState => Law::ThreeState,
                ServoLaw::Voltage => Law::Voltage {
                    v_ref: servo.v_ref,
                    gain: servo.voltage_gain_mm_per_min_per_v / 60.0,
                    volts: config.gap.volts,
                    tau: servo.voltage_filter_ms / 1000.0,
                },
                ServoLaw::Ratio => Law::Ratio {
                    r_ref: servo.ratio_ref,
                    gain: servo.ratio_gain_mm_per_min / 60.0,
                    short_limit: servo.ratio_short_limit,
                    open_limit: servo.ratio_open_limit,
                },
            },
        }
    }
}

impl ConditionTable {
    /// `[generator] condition`s (the technology table's, once merged): the sparking feed in
    /// mm/s, the jumps in s, mm and mm/s, NaN where the `[servo]` setting stays.
    pub fn from_config(config: &Config) -> ConditionTable {
        let or_keep = |v: Option<f64>| v.map_or(f32::NAN, |v| v as f32);
        ConditionTable::new(
            config
                .conditions
                .iter()
                .map(|c| Condition {
                    number: c.number as u16,
                    servo: ServoSetPoints {
                        feed_mm_per_s: (c.feed_mm_per_min / 60.0) as f32,
                        v_ref: c.generator.servo_ref_v as f32,
                        jump: [
                            or_keep(c.jump_interval_s),
                            or_keep(c.jump_height_mm),
                            or_keep(c.jump_feed_mm_per_min.map(|v| v / 60.0)),
                        ],
                    },
                    generator: c.generator,
                    adaptive: c.adaptive.unwrap_or(config.adaptive.enabled).then(|| {
                        let [min_us, max_us] = c
                            .off_time_bounds_us
                            .unwrap_or(config.adaptive.off_time_bounds_us);
                        OffTimeBounds { min_us, max_us }
                    }),
                })
                .collect(),
        )
        .with_adaptive(config.adaptive.law)
    }
}

impl SimSettings {
    /// The simulated gap's settings: `[sim]`, the step sizes and the tick.
    pub fn from_config(config: &Config) -> SimSettings {
        SimSettings {
            params: config.sim.clone(),
            step_mm: step_mm(config),
            tick: config.fine.tick,
            volts: config.gap.volts,
            plane: config.machine.plane_axes(),
            wire_radius_mm: config.wire.diameter_mm / 2.0,
        }
    }
}

impl PinMap {
    /// The pin map of `config` (`[parport]` for `machine.axes`).
    pub fn from_config(config: &Config) -> PinMap {
        PinMap::new(config.machine.axes.len(), &config.parport)
    }
}

impl StepTiming {
    /// The drives' step timing of `config` (`[parport]`).
    pub fn from_config(config: &Config) -> StepTiming {
        StepTiming::new(&config.parport)
    }
}

impl ProgramOptions {
    /// The reader's switches: `[program]`.
    pub fn from_config(config: &Config) -> ProgramOptions {
        let p = &config.program;
        ProgramOptions {
            block_delete: p.block_delete,
            optional_stop: p.optional_stop,
            max_loop_iterations: p.max_loop_iterations,
            d_mm: config.compensation.d_mm.clone(),
            offset_tolerance_mm: config.interpolation.chord_tolerance_mm,
            conditions: config.conditions.iter().map(|c| c.number).collect(),
            guides: config.wire.guides,
            thickness_mm: config.wire.thickness_mm,
            orbit: config.sinker.orbit.clone(),
            mcodes: p.mcodes.clone(),
        }
    }
}

impl HalSettings {
    /// The HAL component of `config` (`[hal]`, the machine's axes, `[gap]`'s thresholds).
    pub fn from_config(config: &Config) -> HalSettings {
        HalSettings {
            component: config.hal.component.clone(),
            axes: config.machine.axes.clone(),
            step_mm: config.machine.step_mm.clone(),
            max_following_error_mm: config.hal.max_following_error_mm,
            gap: config.hal.gap_input,
            probe_input: config.hal.probe_input,
            volts: config.gap.volts,
            library: config.hal.library.clone(),
            tick_ns: config.fine.tick.ns(),
            heartbeat_ns: (config.hal.heartbeat_ms * 1e6) as u64,
            rt_beat_timeout_ns: config.hal.rt_beat_timeout_ms.map(|ms| (ms * 1e6) as u64),
            owner_file: crate::hal::owner::record_path(
                &config.daemon.state_dir,
                &config.hal.component,
            ),
        }
    }
}

impl PathSpec {
    /// A job's path under `config`: the program read with its options from `work`, cut as
    /// `cut` says, approaches at the rethread feed and the machine's safe height.
    pub fn from_config(config: &Config, work: &WorkStart, cut: &CutPlan) -> PathSpec {
        PathSpec {
            axes: config.machine.axes.clone(),
            program: ProgramOptions::from_config(config),
            work: work.clone(),
            cut: cut.clone(),
            approach_feed_mm_per_min: config.servo.rethread_feed_mm_per_min,
            safe_z_mm: config.machine.safe_z_mm,
        }
    }
}

/// The fastest each axis of `config`'s machine can be stepped (mm/s): a step per tick.
pub fn axis_cap(config: &Config) -> [f64; MAX_AXES] {
    let mut cap = [f64::INFINITY; MAX_AXES];
    for (c, s) in cap.iter_mut().zip(&config.machine.step_mm) {
        *c = s / config.fine.tick.secs();
    }
    cap
}

/// The warning for a machine whose `max_feed_mm_per_min` is above what its outputs can step
/// (one step per tick on the slowest axis): the planner plans with the real limit.
pub fn max_feed_warning(config: &Config) -> Option<String> {
    let m = &config.machine;
    let cap = axis_cap(config);
    let (i, slowest) = cap
        .iter()
        .take(m.axes.len())
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    let real = (slowest * 60.0 * 1e6).round() / 1e6;
    (m.max_feed_mm_per_min > real).then(|| {
        format!(
            "machine.max_feed_mm_per_min = {} is more than the outputs can step: one step of {} mm \
             per {} µs tick is {real} mm/min on {} (faster along a diagonal); moves are planned \
             at that",
            m.max_feed_mm_per_min,
            m.step_mm[i],
            (config.fine.tick.secs() * 1e6).round(),
            m.axes[i].letter(),
        )
    })
}
