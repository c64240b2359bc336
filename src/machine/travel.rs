//! The soft limits (`machine.travel_mm`), every decision about them in one place: a block's
//! path held to them before anything moves, a jog clamped at them, a touch cycle's search
//! held inside them, a work zero kept within them.

use crate::config::Travel;
use crate::gcode::Block;
use crate::vocab::Axis;

/// How far past a soft limit a path may reach before it is refused, mm: the extent of a curve
/// is found to this (a tenth of the finest step a configuration is likely to have).
pub const TRAVEL_TOLERANCE_MM: f64 = 1e-4;

/// A block whose path leaves the machine's travel.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "{program}:{line}:1: the path leaves the machine's travel: axis {axis} reaches {} mm \
     (machine coordinates), {} mm {} its {} limit {} mm (machine.travel_mm)",
    crate::vocab::Num(*.reach_mm),
    crate::vocab::Num((.reach_mm - .limit_mm).abs()),
    if *.above { "above" } else { "below" },
    if *.above { "upper" } else { "lower" },
    crate::vocab::Num(*.limit_mm)
)]
pub struct TravelError {
    pub program: String,
    pub line: u64,
    pub axis: Axis,
    /// The farthest point of the path on that axis, mm.
    pub reach_mm: f64,
    pub limit_mm: f64,
    pub above: bool,
}

/// Holds `block`'s path (machine coordinates) to the soft limits `travel` (one per axis of
/// `axes`): the control polygon settles most blocks at once (the curve lies in its hull);
/// a block whose polygon pokes out is measured to [`TRAVEL_TOLERANCE_MM`].
pub fn hold_to_travel(
    block: &Block,
    axes: &[Axis],
    travel: &[Option<Travel>],
    program: &str,
) -> Result<(), TravelError> {
    let curve = &block.curve;
    for (i, (axis, limits)) in axes.iter().zip(travel).enumerate() {
        let Some(t) = limits else { continue };
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for k in 0..curve.num_points() {
            let v = curve.control_point(k)[i];
            lo = lo.min(v);
            hi = hi.max(v);
        }
        if lo >= t.min_mm && hi <= t.max_mm {
            continue;
        }
        let (lo, hi) = curve.axis_extent(i, TRAVEL_TOLERANCE_MM);
        let fail = |reach_mm: f64, limit_mm: f64, above: bool| TravelError {
            program: program.to_string(),
            line: block.line,
            axis: *axis,
            reach_mm,
            limit_mm,
            above,
        };
        if hi > t.max_mm + TRAVEL_TOLERANCE_MM {
            return Err(fail(hi, t.max_mm, true));
        }
        if lo < t.min_mm - TRAVEL_TOLERANCE_MM {
            return Err(fail(lo, t.min_mm, false));
        }
    }
    Ok(())
}

/// Where a jog of `distance_mm` from `here` ends under the soft limit `travel`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum JogEnd {
    /// The whole distance.
    Full(f64),
    /// Clamped at the limit it would pass (mm).
    AtLimit(f64),
    /// The axis stands at or past that limit (mm) already: refused.
    Past(f64),
}

/// The end of a jog on one axis: the soft limit it would pass stops it, and an axis that
/// stands at or past that limit may only jog the other way.
pub fn jog_end(here: f64, distance_mm: f64, travel: Option<Travel>) -> JogEnd {
    let target = here + distance_mm;
    let Some(t) = travel else {
        return JogEnd::Full(target);
    };
    let clamped = target.clamp(t.min_mm, t.max_mm);
    if clamped == target {
        return JogEnd::Full(target);
    }
    let limit = if distance_mm > 0.0 {
        t.max_mm
    } else {
        t.min_mm
    };
    if (limit - here) * distance_mm <= 0.0 {
        JogEnd::Past(limit)
    } else {
        JogEnd::AtLimit(clamped)
    }
}

/// How far an axis may travel from `from` in one direction before its soft limit (infinite
/// without one).
pub fn room(travel: Option<[f64; 2]>, from: f64, positive: bool) -> f64 {
    match travel {
        Some([_, hi]) if positive => hi - from,
        Some([lo, _]) => from - lo,
        None => f64::INFINITY,
    }
}

/// Largest work offset on an axis without soft limits (mm): a 10 m machine.
pub const MAX_OFFSET_MM: f64 = 1.0e4;

/// The range a work zero must stay in on an axis: its travel, or ±[`MAX_OFFSET_MM`] without
/// one. `Err` holds the range an offset outside it (or not finite) missed.
pub fn offset_allowed(travel: Option<Travel>, offset_mm: f64) -> Result<(), (f64, f64)> {
    let (min, max) = travel.map_or((-MAX_OFFSET_MM, MAX_OFFSET_MM), |t| (t.min_mm, t.max_mm));
    if offset_mm.is_finite() && (min..=max).contains(&offset_mm) {
        Ok(())
    } else {
        Err((min, max))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const T: Option<Travel> = Some(Travel {
        min_mm: 0.0,
        max_mm: 100.0,
    });

    #[test]
    fn a_jog_stops_at_the_limit_and_only_leaves_it_the_other_way() {
        assert_eq!(jog_end(50.0, 10.0, T), JogEnd::Full(60.0));
        assert_eq!(jog_end(95.0, 10.0, T), JogEnd::AtLimit(100.0));
        assert_eq!(jog_end(100.0, 1.0, T), JogEnd::Past(100.0));
        assert_eq!(jog_end(100.0, -1.0, T), JogEnd::Full(99.0));
        assert_eq!(jog_end(-3.0, -1.0, T), JogEnd::Past(0.0));
        assert_eq!(jog_end(5.0, 1e9, None), JogEnd::Full(1e9 + 5.0));
    }

    #[test]
    fn room_and_offsets_keep_inside_the_travel() {
        assert_eq!(room(Some([0.0, 100.0]), 30.0, true), 70.0);
        assert_eq!(room(Some([0.0, 100.0]), 30.0, false), 30.0);
        assert_eq!(room(None, 30.0, true), f64::INFINITY);
        assert_eq!(offset_allowed(T, 50.0), Ok(()));
        assert_eq!(offset_allowed(T, 100.5), Err((0.0, 100.0)));
        assert_eq!(
            offset_allowed(None, 2e4),
            Err((-MAX_OFFSET_MM, MAX_OFFSET_MM))
        );
        assert_eq!(
            offset_allowed(None, f64::NAN),
            Err((-MAX_OFFSET_MM, MAX_OFFSET_MM))
        );
    }
}
