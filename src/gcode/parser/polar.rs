//! Polar coordinates, LinuxCNC's way: `@` the radius and `^` the angle (degrees,
//! counter-clockwise from +X) of the end point about the program's origin in the XY plane.
//! One given alone keeps the other from where the machine stands; in `G91` each adds to
//! it (still about the origin, not the current point). Never with `X` or `Y`, nor `G53`.

use super::{Fail, Letters, Step};
use crate::gcode::error::GcodeErrorKind;
use crate::geometry::Point;
use crate::vocab::Axis;

/// Where a block's polar words are read: the machine's axes, the program's offset (program
/// point + this = machine point, mm), mm per program unit, `G91`, `G53`.
pub(super) struct PolarFrame<'a> {
    pub axes: &'a [Axis],
    pub offset: Point,
    pub scale: f64,
    pub incremental: bool,
    pub machine_move: bool,
}

/// The block's polar end point in the XY plane as machine X and Y (mm, with the indices of X
/// and Y in the axes), from `base` (machine, mm), or `None` without `@` or `^`.
pub(super) fn polar_end(
    frame: &PolarFrame,
    base: &Point,
    letters: &Letters,
) -> Step<Option<([usize; 2], [f64; 2])>> {
    let PolarFrame {
        axes,
        offset,
        scale: s,
        incremental,
        machine_move,
    } = *frame;
    let (radius, angle) = (letters.get('@'), letters.get('^'));
    let Some(first) = radius.or(angle) else {
        return Ok(None);
    };
    let fail = |what: &str| Fail::from((first.col, GcodeErrorKind::Polar(what.to_string())));
    if machine_move {
        return Err(fail("polar coordinates cannot be used with G53"));
    }
    if letters.get('X').is_some() || letters.get('Y').is_some() {
        return Err(fail("X or Y cannot be given with polar coordinates (@ ^)"));
    }
    let index = |axis| axes.iter().position(|&a| a == axis);
    let (Some(ix), Some(iy)) = (index(Axis::X), index(Axis::Y)) else {
        return Err(fail("polar coordinates need the axes X and Y"));
    };
    let here = base - offset;
    let (x, y) = (here[ix] / s, here[iy] / s);
    let (mut r, mut theta) = (x.hypot(y), y.atan2(x));
    let at_origin = x == 0.0 && y == 0.0;
    if incremental {
        if at_origin {
            return Err(fail(
                "incremental polar motion is indeterminate at the origin (G90 first)",
            ));
        }
        r += radius.map_or(0.0, |w| w.value);
        theta += angle.map_or(0.0, |w| w.value.to_radians());
    } else {
        if angle.is_none() && at_origin {
            return Err(fail("a polar move from the origin needs its angle ^"));
        }
        r = radius.map_or(r, |w| w.value);
        theta = angle.map_or(theta, |w| w.value.to_radians());
    }
    Ok(Some((
        [ix, iy],
        [
            r * theta.cos() * s + offset[ix],
            r * theta.sin() * s + offset[iy],
        ],
    )))
}
