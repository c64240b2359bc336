//! Validation of `[sim]`: the gap model's distances and rates, and the part a wire-touch
//! cycle finds (`part_edge_mm`, `hole_center_mm`, `hole_diameter_mm`, `touch_bounce_mm`).

use std::path::PathBuf;

use super::raw::RawSim;
use super::validate::{Invalid, at_most, in_range, non_negative, positive};
use super::{HomingConfig, MachineConfig, SimConfig};
use crate::sim::{SimHole, SimPart};

/// Farthest a simulated part's coordinate may be from machine zero, mm.
const MAX_COORDINATE_MM: f64 = 1.0e6;

impl RawSim {
    /// `[sim]`, with its home switches on the machine's homed axes.
    pub(super) fn validate(
        self,
        machine: &MachineConfig,
        homing: &HomingConfig,
    ) -> Result<SimConfig, Invalid> {
        sim(self, machine, homing)
    }
}

fn sim(m: RawSim, machine: &MachineConfig, homing: &HomingConfig) -> Result<SimConfig, Invalid> {
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
    })
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
