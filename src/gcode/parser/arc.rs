//! Circular arcs (`G2`/`G3`) in the active plane, by centre offsets (`I J K`, absolute with
//! `G90.1`) or radius (`R`), full circles and `P` turns included, read as LinuxCNC's
//! interpreter reads them (`interp_arc.cc`):
//!
//! - an `I J K` arc whose end radius differs from its start radius is a spiral (the radius
//!   changes linearly with the angle), refused only when the two differ by more than 100×
//!   [`spiral_tolerance_mm`], or by more than that tolerance and [`SPIRAL_RELATIVE`] of the
//!   radius;
//! - an `R` arc is refused when half its chord exceeds the radius by more than
//!   [`ARC_RADIUS_TOLERANCE_MM`];
//! - an axis outside the plane that moves makes a helix (a sinker's helical plunge), refused
//!   under the wire offset and the taper, whose stages work in the plane.
//!
//! A plain arc is an exact rational quadratic ([`circular_arc`]); a spiral or a helix a C1
//! cubic within [`crate::geometry::SPIRAL_FIT_TOLERANCE_MM`] of it ([`spiral_arc`]). The
//! block's radius is the end radius, which LinuxCNC offsets an arc by.

use super::axes::MachineAxes;
use super::state::{BlockEnv, InterpState};
use super::{Fail, Letters, MM_PER_INCH, Step};
use crate::gcode::error::GcodeErrorKind;
use crate::gcode::lexer::Word;
use crate::gcode::{Block, BlockKind};
use crate::geometry::Point;
use crate::geometry::spiral_arc;
use crate::vocab::Axis;

/// How far half an `R` arc's chord may exceed its radius, and the least radius of an arc, mm
/// (LinuxCNC's `RADIUS_TOLERANCE_MM`, 0.00005 inch).
pub const ARC_RADIUS_TOLERANCE_MM: f64 = 0.000_05 * MM_PER_INCH;
/// The start and end radii of a centre arc may differ by this share of the larger one
/// (LinuxCNC's `SPIRAL_RELATIVE_TOLERANCE`)…
const SPIRAL_RELATIVE: f64 = 0.001;

/// …or by this much, mm, and never by 100 times it (LinuxCNC's
/// `CENTER_ARC_RADIUS_TOLERANCE_MM` and `_INCH`, by the program's units).
fn spiral_tolerance_mm(inch: bool) -> f64 {
    if inch {
        2.0 * 0.001 * std::f64::consts::SQRT_2 * MM_PER_INCH
    } else {
        2.0 * 0.01 * std::f64::consts::SQRT_2
    }
}

/// A `G2` (`ccw` false) or `G3` block's arc, from `state`'s position, which moves to its
/// end.
pub(super) fn arc_block(
    state: &mut InterpState,
    env: &mut BlockEnv,
    ccw: bool,
    line_no: u64,
    letters: &Letters,
    col: usize,
) -> Step<Block> {
    let plane = state.modal.plane;
    let [la, lb] = plane.axis_letters();
    let [oa, ob] = plane.offset_letters();
    env.axes
        .check_letters_with(letters, true, &|c| [oa, ob, 'R', 'P'].contains(&c), &|| {
            format!("in {} ({}) arcs", plane.g_code(), plane.name())
        })?;
    let turns = match letters.get('P') {
        Some(p) => arc_turns(p)?,
        None => 1,
    };
    let index = |letter: char| {
        Axis::from_letter(letter).and_then(|a| env.axes.iter().position(|&m| m == a))
    };
    let (Some(ia), Some(ib)) = (index(la), index(lb)) else {
        return Err((
            col,
            GcodeErrorKind::ArcPlaneNotOnMachine {
                plane: plane.g_code(),
                a: la,
                b: lb,
                axes: env.axes.list(),
            },
        )
            .into());
    };
    let feed = env.feed_limit(state, col);
    let (end, _) = env.target_here(state, letters)?;
    let start = state.position;
    check_helix(state, env.axes, letters, [ia, ib], &start, &end, col)?;
    let radius_word = letters.get('R');
    let (off_a, off_b) = (letters.get(oa), letters.get(ob));
    if let (Some(r), Some(o)) = (radius_word, off_a.or(off_b)) {
        return Err((r.col.max(o.col), GcodeErrorKind::ArcRAndCentre).into());
    }
    let chord_a = end[ia] - start[ia];
    let chord_b = end[ib] - start[ib];
    let chord = chord_a.hypot(chord_b);
    let full_circle = chord < 1e-9;
    let mut center = start;
    if let Some(r) = radius_word {
        if full_circle {
            return Err((r.col, GcodeErrorKind::ArcFullCircleWithR).into());
        }
        let radius = r.value * state.scale();
        let [ca, cb] = centre_of_radius(
            r.col,
            radius,
            ccw,
            [start[ia], start[ib]],
            [chord_a, chord_b],
            chord,
        )?;
        center[ia] = ca;
        center[ib] = cb;
    } else {
        center = centre_of_offsets(state, off_a, off_b, [ia, ib], &start, &end, col)?;
    }
    let a0 = (start[ib] - center[ib]).atan2(start[ia] - center[ia]);
    let a1 = (end[ib] - center[ib]).atan2(end[ia] - center[ia]);
    let extra_turns = std::f64::consts::TAU * f64::from(turns - 1);
    let sweep = sweep_of(a0, a1, ccw, full_circle);
    let sweep = sweep + extra_turns.copysign(sweep);
    let curve = spiral_arc(env.axes.len(), [ia, ib], &center, &start, &end, sweep)
        .map_err(|e| Fail::from((col, e.into())))?;
    // The end radius: what LinuxCNC offsets an arc by (`convert_arc_comp2`).
    let radius = (end[ia] - center[ia]).hypot(end[ib] - center[ib]);
    state.position = end;
    Ok(state.block(
        line_no,
        BlockKind::Arc {
            center,
            radius,
            sweep,
            plane,
        },
        curve,
        feed,
    ))
}

/// An axis outside the arc's plane `[ia, ib]` that moves makes a helix: refused where a
/// stage works in the plane (the wire offset, the taper).
fn check_helix(
    state: &InterpState,
    axes: &MachineAxes,
    letters: &Letters,
    [ia, ib]: [usize; 2],
    start: &Point,
    end: &Point,
    col: usize,
) -> Step<()> {
    let why = if state.modal.wire_offset.engaged() {
        "under the wire offset (G41/G42 offset the path in the plane: cut the helix after G40)"
    } else if state.modal.taper != 0.0 {
        "under a taper (G51/G52 tilt the wire along a path in the plane: G50 first)"
    } else {
        return Ok(());
    };
    for (i, axis) in axes.iter().enumerate() {
        if i != ia && i != ib && end[i] != start[i] {
            let w = letters.get(axis.letter()).map_or(col, |w| w.col);
            return Err((
                w,
                GcodeErrorKind::HelicalArc {
                    axis: axis.letter(),
                    why,
                },
            )
                .into());
        }
    }
    Ok(())
}

/// The centre of an `I J K` arc in the plane of axes `[ia, ib]` (the offsets relative to
/// the start, or absolute under `G90.1`, where both are needed), its start and end radii
/// within LinuxCNC's spiral tolerance.
fn centre_of_offsets(
    state: &InterpState,
    off_a: Option<&Word>,
    off_b: Option<&Word>,
    [ia, ib]: [usize; 2],
    start: &Point,
    end: &Point,
    col: usize,
) -> Step<Point> {
    let mut center = *start;
    let (va, vb) = match (off_a, off_b) {
        (None, None) => return Err((col, GcodeErrorKind::ArcMissingCentre).into()),
        (a, b) if state.modal.arc_centre_absolute && (a.is_none() || b.is_none()) => {
            let [la, lb] = state.modal.plane.offset_letters();
            let letter = if a.is_none() { la } else { lb };
            let at = a.or(b).map_or(col, |w| w.col);
            return Err((at, GcodeErrorKind::ArcCentreWordMissing { letter }).into());
        }
        (a, b) => (a, b),
    };
    let s = state.scale();
    let va = va.map_or(0.0, |w| w.value * s);
    let vb = vb.map_or(0.0, |w| w.value * s);
    if state.modal.arc_centre_absolute {
        let offset = state.offset();
        center[ia] = va + offset[ia];
        center[ib] = vb + offset[ib];
    } else {
        center[ia] = start[ia] + va;
        center[ib] = start[ib] + vb;
    }
    let r_start = (start[ia] - center[ia]).hypot(start[ib] - center[ib]);
    let r_end = (end[ia] - center[ia]).hypot(end[ib] - center[ib]);
    let offset_col = off_a.or(off_b).map_or(col, |w| w.col);
    if r_start < ARC_RADIUS_TOLERANCE_MM || r_end < ARC_RADIUS_TOLERANCE_MM {
        return Err((offset_col, GcodeErrorKind::ArcZeroRadius).into());
    }
    let tolerance = spiral_tolerance_mm(state.modal.inch);
    let apart = (r_start - r_end).abs();
    let relative = apart / r_start.max(r_end);
    if apart > 100.0 * tolerance || (relative > SPIRAL_RELATIVE && apart > tolerance) {
        let limit = (100.0 * tolerance).min(tolerance.max(SPIRAL_RELATIVE * r_start.max(r_end)));
        return Err((
            offset_col,
            GcodeErrorKind::ArcSpiralTooFar {
                start: r_start,
                end: r_end,
                limit,
            },
        )
            .into());
    }
    Ok(center)
}

/// An arc's `P`: how many times it goes round (1: as far as its end point, as without `P`).
fn arc_turns(p: &Word) -> Step<u32> {
    let turns = p.value.round();
    if (turns - p.value).abs() > 0.001 || !(1.0..=1e6).contains(&turns) {
        return Err((
            p.col,
            GcodeErrorKind::ArcTurns {
                text: p.text.to_string(),
            },
        )
            .into());
    }
    Ok(turns as u32)
}

/// The centre of an `R` arc (`radius` in mm, negative for the major arc) from `start` along
/// `chord` (its components and length), in the arc's plane; the radius is refused if it
/// cannot span the chord (`col`: the `R` word's column).
fn centre_of_radius(
    col: usize,
    radius: f64,
    ccw: bool,
    start: [f64; 2],
    [chord_a, chord_b]: [f64; 2],
    chord: f64,
) -> Result<[f64; 2], Fail> {
    let half = chord / 2.0;
    let h_sq = radius * radius - half * half;
    if h_sq < 0.0 && half - radius.abs() > ARC_RADIUS_TOLERANCE_MM {
        return Err((
            col,
            GcodeErrorKind::ArcRadiusTooSmall {
                radius: radius.abs(),
                half_chord: half,
            },
        )
            .into());
    }
    let h = h_sq.max(0.0).sqrt();
    // Centre to the left of the chord for a counter-clockwise minor arc; R < 0 asks for
    // the major arc, which puts it on the other side.
    let side = if ccw == (radius > 0.0) { 1.0 } else { -1.0 };
    Ok([
        start[0] + chord_a / 2.0 - side * h * chord_b / chord,
        start[1] + chord_b / 2.0 + side * h * chord_a / chord,
    ])
}

/// The signed sweep (rad) from angle `a0` to `a1`: counter-clockwise positive, a whole turn
/// for a full circle or equal angles.
fn sweep_of(a0: f64, a1: f64, ccw: bool, full_circle: bool) -> f64 {
    let tau = std::f64::consts::TAU;
    if full_circle {
        if ccw { tau } else { -tau }
    } else if ccw {
        let s = (a1 - a0).rem_euclid(tau);
        if s == 0.0 { tau } else { s }
    } else {
        let s = (a0 - a1).rem_euclid(tau);
        -(if s == 0.0 { tau } else { s })
    }
}
