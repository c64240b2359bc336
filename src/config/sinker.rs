//! Validation of `[sinker]`: the orbit sinking moves make (`[sinker.orbit]`), and a
//! machining condition's own orbit (`orbit_shape`, `orbit_radius_mm`: the undersize of its
//! stage).

use super::raw::{RawCondition, RawSinker};
use super::validate::{Invalid, at_most, positive};
use super::{Condition, SinkerConfig};
use crate::gcode::{Orbit, OrbitOptions};
use crate::vocab::OrbitShape;

/// Largest orbit radius accepted, mm.
const MAX_RADIUS_MM: f64 = 50.0;

fn shape(key: &'static str, text: &str) -> Result<OrbitShape, Invalid> {
    OrbitShape::parse(text).ok_or_else(|| {
        (
            key,
            format!(
                "{text:?} is not an orbit shape: {}",
                OrbitShape::ALL.map(|s| s.name()).join(", ")
            ),
        )
    })
}

impl RawCondition {
    /// The condition's own orbit: its shape and radius, each `None` where it keeps
    /// `[sinker.orbit]`'s.
    pub(super) fn orbit(&self) -> Result<(Option<OrbitShape>, Option<f64>), Invalid> {
        const KEY: &str = "generator.condition";
        let shape = self
            .orbit_shape
            .as_deref()
            .map(|t| shape(KEY, t))
            .transpose()?;
        let radius = self
            .orbit_radius_mm
            .map(|r| at_most(KEY, r, MAX_RADIUS_MM, "mm (orbit_radius_mm)"))
            .transpose()?;
        Ok((shape, radius))
    }
}

impl RawSinker {
    /// `[sinker]`, with the conditions' own orbits.
    pub(super) fn validate(self, conditions: &[Condition]) -> Result<SinkerConfig, Invalid> {
        let o = self.orbit;
        let default = Orbit {
            shape: shape("sinker.orbit.shape", &o.shape)?,
            radius_mm: at_most("sinker.orbit.radius_mm", o.radius_mm, MAX_RADIUS_MM, "mm")?,
        };
        let by_condition = conditions
            .iter()
            .filter(|c| c.orbit_shape.is_some() || c.orbit_radius_mm.is_some())
            .map(|c| {
                (
                    c.number,
                    Orbit {
                        shape: c.orbit_shape.unwrap_or(default.shape),
                        radius_mm: c.orbit_radius_mm.unwrap_or(default.radius_mm),
                    },
                )
            })
            .collect();
        Ok(SinkerConfig {
            breakthrough: self.breakthrough,
            breakthrough_extra_mm: at_most(
                "sinker.breakthrough_extra_mm",
                self.breakthrough_extra_mm,
                100.0,
                "mm",
            )?,
            breakthrough_open_ratio: positive(
                "sinker.breakthrough_open_ratio",
                self.breakthrough_open_ratio,
                1.0,
                "(a share of the window)",
            )?,
            breakthrough_window_s: positive(
                "sinker.breakthrough_window_ms",
                self.breakthrough_window_ms,
                1e4,
                "ms",
            )? / 1000.0,
            orbit: OrbitOptions {
                default,
                feed_mm_per_min: positive(
                    "sinker.orbit.feed_mm_per_min",
                    o.feed_mm_per_min,
                    1e5,
                    "mm/min",
                )?,
                expand: o.expand,
                by_condition,
            },
        })
    }
}
