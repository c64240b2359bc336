//! One machining condition, validated: `[generator] condition` entries and the conditions of
//! the technology tables (`crate::technology`) are the same table, read by one rule.

use super::Condition;
use super::raw::RawCondition;
use super::validate::{Invalid, at_most, in_range, positive};
use crate::vocab::GeneratorSetPoints;

/// Where a condition's sparking feed comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FeedRule {
    /// The condition gives it (`feed_mm_per_min`): `[generator]`, a sinker table.
    Given,
    /// Its pass gives it, per height (a wire table): a feed of its own is refused.
    FromPass,
}

/// `[generator] condition`'s entry shape, as other tables write it too.
pub type ConditionSpec = RawCondition;

impl RawCondition {
    /// The condition, every value in range; `key` names the table in a message.
    pub fn validate(self, key: &'static str, feed: FeedRule) -> Result<Condition, Invalid> {
        let number = in_range(key, self.number, 1, 999)? as u32;
        let corner = self.corner_control()?;
        let (orbit_shape, orbit_radius_mm) = self.orbit()?;
        let optional = |v: Option<f64>, max: f64, unit: &str| {
            v.map_or(Ok(0.0), |v| positive(key, v, max, unit))
        };
        let feed_mm_per_min = match (feed, self.feed_mm_per_min) {
            (FeedRule::Given, Some(f)) => positive(key, f, 1e6, "mm/min (feed_mm_per_min)")?,
            (FeedRule::Given, None) => {
                return Err((key, format!("E{number}: feed_mm_per_min is missing")));
            }
            (FeedRule::FromPass, None) => 0.0,
            (FeedRule::FromPass, Some(_)) => {
                return Err((
                    key,
                    format!(
                        "E{number}: a wire table's feeds are its passes' (they change with \
                         the height): give feed_mm_per_min in each pass, not here"
                    ),
                ));
            }
        };
        let bound = |v: Option<f64>, what: &str| {
            v.map(|v| positive(key, v, 1e6, &format!("µs ({what})")))
                .transpose()
        };
        let off_time_bounds_us = match (
            bound(self.off_time_min_us, "off_time_min_us")?,
            bound(self.off_time_max_us, "off_time_max_us")?,
        ) {
            (None, None) => None,
            (Some(lo), Some(hi)) if lo <= hi => Some([lo, hi]),
            (Some(lo), Some(hi)) => {
                return Err((
                    key,
                    format!("E{number}: off_time_min_us ({lo}) is above off_time_max_us ({hi})"),
                ));
            }
            _ => {
                return Err((
                    key,
                    format!("E{number}: give both off_time_min_us and off_time_max_us, or neither"),
                ));
            }
        };
        Ok(Condition {
            number,
            adaptive: self.adaptive,
            off_time_bounds_us,
            corner,
            orbit_shape,
            orbit_radius_mm,
            generator: GeneratorSetPoints {
                on_time_us: positive(key, self.on_us, 1e6, "µs (on_us)")?,
                off_time_us: positive(key, self.off_us, 1e6, "µs (off_us)")?,
                peak_current_a: positive(key, self.current_a, 1e4, "A (current_a)")?,
                servo_ref_v: positive(key, self.v_ref, 1e4, "V (v_ref)")?,
                open_voltage_v: optional(self.open_voltage_v, 1e4, "V (open_voltage_v)")?,
                wire_tension_n: optional(self.wire_tension_n, 1e3, "N (wire_tension_n)")?,
                wire_speed_m_per_min: optional(
                    self.wire_speed_m_per_min,
                    1e3,
                    "m/min (wire_speed_m_per_min)",
                )?,
                flushing_bar: optional(self.flushing_bar, 1e3, "bar (flushing_bar)")?,
            },
            feed_mm_per_min,
            jump_interval_s: self
                .jump_interval_s
                .map(|v| at_most(key, v, 86_400.0, "s (jump_interval_s)"))
                .transpose()?,
            jump_height_mm: self
                .jump_height_mm
                .map(|v| at_most(key, v, 1000.0, "mm (jump_height_mm)"))
                .transpose()?,
            jump_feed_mm_per_min: self
                .jump_feed_mm_per_min
                .map(|v| positive(key, v, 1e6, "mm/min (jump_feed_mm_per_min)"))
                .transpose()?,
        })
    }
}
