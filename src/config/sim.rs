//! Validation of `[sim]`: the gap model's distances and rates, and the part a wire-touch
//! cycle finds (`part_edge_mm`, `hole_center_mm`, `hole_diameter_mm`, `touch_bounce_mm`).

use std::path::PathBuf;

use super::raw::{RawAdaptive, RawSim};
use super::validate::{Invalid, at_most, in_range, non_negative, positive};
use super::{AdaptiveConfig, HomingConfig, MachineConfig, SimConfig};
use crate::process::AdaptiveSettings;
use crate::sim::{DischargeParams, SimHole, SimModel, SimPart};
use crate::vocab::GeneratorSetPoints;

/// Farthest a simulated part's coordinate may be from machine zero, mm.
const MAX_COORDINATE_MM: f64 = 1.0e6;

impl RawSim {
    /// `[sim]`, with its home switches on the machine's homed axes.
    pub(super) fn validate(
        self,
        machine: &MachineConfig,
        homing: &HomingConfig,
        wire_diameter_mm: f64,
    ) -> Result<SimConfig, Invalid> {
        sim(self, machine, homing, wire_diameter_mm)
    }
}

fn sim(
    m: RawSim,
    machine: &MachineConfig,
    homing: &HomingConfig,
    wire_diameter_mm: f64,
) -> Result<SimConfig, Invalid> {
    let short_gap = positive("sim.short_gap_um", m.short_gap_um, 1e4, "µm")?;
    let open_gap = positive("sim.open_gap_um", m.open_gap_um, 1e4, "µm")?;
    if open_gap <= short_gap {
        return Err((
            "sim.open_gap_um",
            format!("must be greater than sim.short_gap_um ({short_gap}), got {open_gap}"),
        ));
    }
    let home_switch_mm = m.home_switches(machine, homing)?;
    let part = part(&m)?;
    let model = model(&m, wire_diameter_mm)?;
    Ok(SimConfig {
        seed: in_range("sim.seed", m.seed, 0, i64::MAX)? as u64,
        initial_gap_mm: non_negative("sim.initial_gap_um", m.initial_gap_um)? / 1000.0,
        short_gap_mm: short_gap / 1000.0,
        open_gap_mm: open_gap / 1000.0,
        erosion_mm_per_s: positive(
            "sim.erosion_mm_per_min",
            m.erosion_mm_per_min,
            1e6,
            "mm/min",
        )? / 60.0,
        debris_per_mm: at_most(
            "sim.debris_shorts_per_mm",
            m.debris_shorts_per_mm,
            100.0,
            "per mm",
        )?,
        debris_shorts_per_s: non_negative("sim.debris_shorts_per_s", m.debris_shorts_per_s)?,
        debris_clear_mm: positive("sim.debris_clear_um", m.debris_clear_um, 1e6, "µm")? / 1000.0,
        wire_breaks_per_m: at_most("sim.wire_breaks_per_m", m.wire_breaks_per_m, 1e6, "per m")?,
        events: (!m.events.trim().is_empty()).then(|| PathBuf::from(m.events)),
        home_switch_mm,
        part,
        breakthrough_at_mm: match at_most(
            "sim.breakthrough_at_mm",
            m.breakthrough_at_mm,
            1e6,
            "mm",
        )? {
            0.0 => f64::INFINITY,
            mm => mm,
        },
        model,
    })
}

/// `sim.model`, with `sim.work_height_mm` and `[sim.discharge]` for the discharge model.
fn model(m: &RawSim, wire_diameter_mm: f64) -> Result<SimModel, Invalid> {
    let d = &m.discharge;
    let [a, b, c] = d.ignition_median_us;
    if ![a, b, c].iter().all(|v| v.is_finite()) || a < 0.0 || c <= 0.0 {
        return Err((
            "sim.discharge.ignition_median_us",
            format!("must be [a, b, c] with a >= 0 and c > 0, got [{a}, {b}, {c}]"),
        ));
    }
    let params = DischargeParams {
        work_height_mm: positive("sim.work_height_mm", m.work_height_mm, 1000.0, "mm")?,
        side_gaps_mm: at_most("sim.discharge.side_gaps_um", d.side_gaps_um, 1000.0, "µm")? / 1000.0,
        discharge_voltage_v: positive(
            "sim.discharge.discharge_voltage_v",
            d.discharge_voltage_v,
            1000.0,
            "V",
        )?,
        ignition_median_us: [a, b, c],
        ignition_timeout_us: positive(
            "sim.discharge.ignition_timeout_us",
            d.ignition_timeout_us,
            1e6,
            "µs",
        )?,
        arc_delay_us: at_most("sim.discharge.arc_delay_us", d.arc_delay_us, 1000.0, "µs")?,
        deionization_us: positive(
            "sim.discharge.deionization_us",
            d.deionization_us,
            1e6,
            "µs",
        )?,
        removal_mm3_per_j: positive(
            "sim.discharge.removal_mm3_per_j",
            d.removal_mm3_per_j,
            10.0,
            "mm³/J",
        )?,
        arc_removal: fraction("sim.discharge.arc_removal", d.arc_removal)?,
        debris_per_mm2: at_most("sim.discharge.debris_per_mm2", d.debris_per_mm2, 1e6, "")?,
        arc_debris: at_most("sim.discharge.arc_debris", d.arc_debris, 1000.0, "")?,
        flush_time_ms: positive("sim.discharge.flush_time_ms", d.flush_time_ms, 1e6, "ms")?,
        flushing_depth_mm: positive(
            "sim.discharge.flushing_depth_mm",
            d.flushing_depth_mm,
            1e4,
            "mm",
        )?,
        debris_bursts_per_s: at_most(
            "sim.discharge.debris_bursts_per_s",
            d.debris_bursts_per_s,
            1e4,
            "per s",
        )?,
        debris_burst: at_most("sim.discharge.debris_burst", d.debris_burst, 100.0, "")?,
        short_contamination: positive(
            "sim.discharge.short_contamination",
            d.short_contamination,
            1e3,
            "",
        )?,
        wire_heat_fraction: fraction("sim.discharge.wire_heat_fraction", d.wire_heat_fraction)?,
        wire_convection_w_per_m2k: positive(
            "sim.discharge.wire_convection_w_per_m2k",
            d.wire_convection_w_per_m2k,
            1e8,
            "W/(m²·K)",
        )?,
        arc_spot_mm: positive("sim.discharge.arc_spot_mm", d.arc_spot_mm, 1000.0, "mm")?,
        wire_break_rise_k: positive(
            "sim.discharge.wire_break_rise_k",
            d.wire_break_rise_k,
            1e4,
            "K",
        )?,
        wire_diameter_mm,
        wire_density_kg_m3: positive(
            "sim.discharge.wire_density_kg_m3",
            d.wire_density_kg_m3,
            1e5,
            "kg/m³",
        )?,
        wire_heat_capacity_j_kgk: positive(
            "sim.discharge.wire_heat_capacity_j_kgk",
            d.wire_heat_capacity_j_kgk,
            1e5,
            "J/(kg·K)",
        )?,
        generator: generator(d)?,
    };
    match m.model.trim().to_ascii_lowercase().as_str() {
        "discharge" => Ok(SimModel::Discharge(Box::new(params))),
        "kinematic" => Ok(SimModel::Kinematic),
        other => Err((
            "sim.model",
            format!("must be \"discharge\" or \"kinematic\", got \"{other}\""),
        )),
    }
}

/// `sim.part_edge_mm` (`{X = [MIN, MAX], Y = [MIN, MAX]}`), the hole and the bounce.
fn part(m: &RawSim) -> Result<SimPart, Invalid> {
    const EDGE_KEY: &str = "sim.part_edge_mm";
    let mut edges_mm = [None; 2];
    for (letter, &[lo, hi]) in &m.part_edge_mm {
        let i = match letter.trim().to_ascii_uppercase().as_str() {
            "X" => 0,
            "Y" => 1,
            _ => {
                return Err((
                    EDGE_KEY,
                    format!("\"{letter}\": the part's edges are on X and Y"),
                ));
            }
        };
        if !(lo.is_finite()
            && hi.is_finite()
            && lo < hi
            && lo.abs().max(hi.abs()) <= MAX_COORDINATE_MM)
        {
            return Err((
                EDGE_KEY,
                format!("{letter} = [{lo}, {hi}]: give [MIN, MAX] mm with MIN below MAX"),
            ));
        }
        edges_mm[i] = Some([lo, hi]);
    }
    let hole = match (&m.hole_center_mm[..], m.hole_diameter_mm) {
        ([], 0.0) => None,
        (&[x, y], d) if x.abs().max(y.abs()) <= MAX_COORDINATE_MM => Some(SimHole {
            center_mm: [x, y],
            diameter_mm: positive(
                "sim.hole_diameter_mm",
                d,
                1.0e4,
                "mm (with a hole_center_mm)",
            )?,
        }),
        ([], _) => {
            return Err((
                "sim.hole_center_mm",
                "a hole_diameter_mm needs its hole_center_mm = [X, Y]".to_string(),
            ));
        }
        (c, _) => {
            return Err((
                "sim.hole_center_mm",
                format!("{c:?}: give [X, Y] mm, or [] for no hole"),
            ));
        }
    };
    if let Some(h) = &hole {
        let r = h.diameter_mm / 2.0;
        for (i, edge) in edges_mm.iter().enumerate() {
            if let Some([lo, hi]) = edge
                && !(h.center_mm[i] - r > *lo && h.center_mm[i] + r < *hi)
            {
                return Err((
                    "sim.hole_center_mm",
                    format!(
                        "the hole ({:?}, diameter {}) must lie inside the part's edges \
                         (sim.part_edge_mm)",
                        h.center_mm, h.diameter_mm
                    ),
                ));
            }
        }
    }
    Ok(SimPart {
        edges_mm,
        hole,
        bounce_mm: at_most("sim.touch_bounce_mm", m.touch_bounce_mm, 100.0, "mm")?,
    })
}

impl RawAdaptive {
    /// `[adaptive]`, every value in range, for ticks of `tick`.
    pub(super) fn validate(
        self,
        tick: crate::vocab::TickPeriod,
    ) -> Result<AdaptiveConfig, Invalid> {
        adaptive(self, tick)
    }
}

fn adaptive(a: RawAdaptive, tick: crate::vocab::TickPeriod) -> Result<AdaptiveConfig, Invalid> {
    let lo = positive("adaptive.off_time_min_us", a.off_time_min_us, 1e6, "µs")?;
    let hi = positive("adaptive.off_time_max_us", a.off_time_max_us, 1e6, "µs")?;
    if hi < lo {
        return Err((
            "adaptive.off_time_max_us",
            format!("must be at least adaptive.off_time_min_us ({lo}), got {hi}"),
        ));
    }
    let dt_s = tick.secs();
    let window_ms = positive("adaptive.window_ms", a.window_ms, 10_000.0, "ms")?;
    Ok(AdaptiveConfig {
        enabled: a.enabled,
        law: AdaptiveSettings {
            window_ticks: ((window_ms * 1e-3 / dt_s).round() as u32).max(1),
            dt_s,
            lengthen: positive("adaptive.lengthen", a.lengthen, 10.0, "")?,
            shorten: fraction("adaptive.shorten", a.shorten)?,
            margin: fraction("adaptive.margin", a.margin)?,
            arc_limit: fraction("adaptive.arc_limit", a.arc_limit)?,
            limit_w_at_20mm: positive("adaptive.limit_w_at_20mm", a.limit_w_at_20mm, 1e6, "W")?,
            limit_height_exponent: at_most(
                "adaptive.limit_height_exponent",
                a.limit_height_exponent,
                2.0,
                "",
            )?,
            poor_flushing_factor: fraction(
                "adaptive.poor_flushing_factor",
                a.poor_flushing_factor,
            )?,
            poor_flushing_arc_share: fraction(
                "adaptive.poor_flushing_arc_share",
                a.poor_flushing_arc_share,
            )?,
            poor_flushing_below: at_most(
                "adaptive.poor_flushing_below",
                a.poor_flushing_below,
                1.0,
                "",
            )?,
            discharge_voltage_v: positive(
                "adaptive.discharge_voltage_v",
                a.discharge_voltage_v,
                1000.0,
                "V",
            )?,
            height_mm2_per_as: positive(
                "adaptive.height_mm2_per_as",
                a.height_mm2_per_as,
                1e6,
                "mm² per A·s",
            )?,
            height_window_mm: positive("adaptive.height_window_mm", a.height_window_mm, 1e3, "mm")?,
            arc_charge_weight: at_most("adaptive.arc_charge_weight", a.arc_charge_weight, 1.0, "")?,
            initial_height_mm: positive(
                "adaptive.initial_height_mm",
                a.initial_height_mm,
                1000.0,
                "mm",
            )?,
        },
        off_time_bounds_us: [lo, hi],
    })
}

/// A fraction: above 0, at most 1.
fn fraction(key: &'static str, v: f64) -> Result<f64, Invalid> {
    if v.is_finite() && v > 0.0 && v <= 1.0 {
        Ok(v)
    } else {
        Err((key, format!("must be above 0 and at most 1, got {v}")))
    }
}

/// `[sim.discharge]`'s generator set points, for what no condition gives.
fn generator(d: &super::raw::RawDischarge) -> Result<GeneratorSetPoints, Invalid> {
    Ok(GeneratorSetPoints {
        on_time_us: positive("sim.discharge.on_time_us", d.on_time_us, 1e5, "µs")?,
        off_time_us: positive("sim.discharge.off_time_us", d.off_time_us, 1e5, "µs")?,
        peak_current_a: positive("sim.discharge.peak_current_a", d.peak_current_a, 1e4, "A")?,
        open_voltage_v: positive("sim.discharge.open_voltage_v", d.open_voltage_v, 1e4, "V")?,
        wire_speed_m_per_min: positive(
            "sim.discharge.wire_speed_m_per_min",
            d.wire_speed_m_per_min,
            1000.0,
            "m/min",
        )?,
        ..GeneratorSetPoints::default()
    })
}
