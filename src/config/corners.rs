//! A condition's corner control (`corner_angle_deg`, `corner_feed_factor`,
//! `corner_distance_mm`, `corner_dwell_ms` of a `[[generator.condition]]`): checked here, used
//! by the preprocessor ([`crate::preprocess::corners`]).

use super::raw::RawCondition;
use super::validate::{Invalid, positive};

/// Corner control of one condition, as configured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CornerControl {
    /// Corners whose included angle is below this count (degrees; 180 is straight on).
    pub angle_deg: f64,
    /// The feed ceiling around such a corner, as a fraction of the planned one.
    pub feed_factor: f64,
    /// How far before and after the corner, mm of path.
    pub distance_mm: f64,
    /// A stop at the corner, ms (0: none).
    pub dwell_ms: f64,
}

impl RawCondition {
    /// The condition's corner control: none without `corner_angle_deg`; with it, the factor
    /// and the distance are needed too.
    pub(super) fn corner_control(&self) -> Result<Option<CornerControl>, Invalid> {
        CornerControl::from_keys(
            self.number,
            [
                self.corner_angle_deg,
                self.corner_feed_factor,
                self.corner_distance_mm,
                self.corner_dwell_ms,
            ],
        )
    }
}

impl CornerControl {
    /// Corner control from its four keys (`corner_angle_deg`, `corner_feed_factor`,
    /// `corner_distance_mm`, `corner_dwell_ms`) as condition `number` (or a technology
    /// table's pass in it) gives them: none without the angle; with it, the factor and the
    /// distance are needed too.
    pub fn from_keys(
        number: i64,
        keys: [Option<f64>; 4],
    ) -> Result<Option<CornerControl>, Invalid> {
        corner_control(number, keys)
    }
}

fn corner_control(number: i64, keys: [Option<f64>; 4]) -> Result<Option<CornerControl>, Invalid> {
    const KEY: &str = "generator.condition";
    let [angle, factor, distance, dwell] = keys;
    let Some(angle) = angle else {
        if factor.is_some() || distance.is_some() || dwell.is_some() {
            return Err((
                KEY,
                format!(
                    "E{}: corner_feed_factor, corner_distance_mm and corner_dwell_ms need \
                     corner_angle_deg (which corners count)",
                    number
                ),
            ));
        }
        return Ok(None);
    };
    if !(angle > 0.0 && angle < 180.0) {
        return Err((
            KEY,
            format!(
                "E{}: corner_angle_deg = {angle}: an included angle between 0 and 180 degrees \
                 (corners sharper than it slow down; 180 is a straight continuation)",
                number
            ),
        ));
    }
    let (Some(factor), Some(distance)) = (factor, distance) else {
        return Err((
            KEY,
            format!(
                "E{}: corner_angle_deg needs corner_feed_factor (how slow, 0 to 1) and \
                 corner_distance_mm (how far before and after the corner)",
                number
            ),
        ));
    };
    if !(factor > 0.0 && factor <= 1.0) {
        return Err((
            KEY,
            format!(
                "E{}: corner_feed_factor = {factor}: above 0, at most 1",
                number
            ),
        ));
    }
    let dwell_ms = dwell.unwrap_or(0.0);
    if !(0.0..=60_000.0).contains(&dwell_ms) {
        return Err((
            KEY,
            format!("E{}: corner_dwell_ms = {dwell_ms}: 0 to 60000 ms", number),
        ));
    }
    Ok(Some(CornerControl {
        angle_deg: angle,
        feed_factor: factor,
        distance_mm: positive(KEY, distance, 100.0, "mm (corner_distance_mm)")?,
        dwell_ms,
    }))
}
