//! Circular arcs (`G2`/`G3`) in the active plane, by centre offsets (`I J K`, absolute with
//! `G90.1`) or radius (`R`), full circles included: each becomes an exact rational quadratic
//! ([`circular_arc`]) whose last control point is the programmed end point. A helix is
//! refused (it is no rational quadratic), as are start and end radii further apart than
//! [`ARC_RADIUS_TOLERANCE_MM`] plus `1e-5` of the radius.

use std::io::{BufRead, Seek};

use super::{BlockReader, Fail, Letters, Step};
use crate::gcode::error::GcodeErrorKind;
use crate::gcode::lexer::Word;
use crate::gcode::{Block, BlockKind};
use crate::geometry::Point;
use crate::geometry::circular_arc;
use crate::vocab::Axis;

/// How far apart the start and end radii of an `I J K` arc may be, mm (plus [`ARC_RADIUS_REL`]
/// of the radius): CAM output rounded to 3 decimals in mm or 4 in inch stays inside.
pub const ARC_RADIUS_TOLERANCE_MM: f64 = 0.002;
const ARC_RADIUS_REL: f64 = 1e-5;
impl<R: BufRead + Seek> BlockReader<R> {
    pub(super) fn arc_block(
        &mut self,
        ccw: bool,
        line_no: u64,
        letters: &Letters,
        col: usize,
    ) -> Step<Option<Block>> {
        let plane = self.state.modal.plane;
        let [la, lb] = plane.axis_letters();
        let [oa, ob] = plane.offset_letters();
        self.check_letters_with(letters, true, &|c| [oa, ob, 'R', 'P'].contains(&c), &|| {
            format!("in {} ({}) arcs", plane.g_code(), plane.name())
        })?;
        if let Some(p) = letters.get('P') {
            return Err((
                p.col,
                GcodeErrorKind::UnexpectedWord {
                    letter: 'P',
                    context: "in arcs (multi-turn arcs are not supported)".into(),
                },
            )
                .into());
        }
        let index = |letter: char| {
            Axis::from_letter(letter).and_then(|a| self.axes.iter().position(|&m| m == a))
        };
        let (Some(ia), Some(ib)) = (index(la), index(lb)) else {
            return Err((
                col,
                GcodeErrorKind::ArcPlaneNotOnMachine {
                    plane: plane.g_code(),
                    a: la,
                    b: lb,
                    axes: self.axes_list(),
                },
            )
                .into());
        };
        let feed = self.feed_limit(col);
        let (end, _) = self.target(&self.state.position, letters, "")?;
        let start = self.state.position;
        for (i, axis) in self.axes.iter().enumerate() {
            if i != ia && i != ib && end[i] != start[i] {
                let w = letters.get(axis.letter()).map_or(col, |w| w.col);
                return Err((
                    w,
                    GcodeErrorKind::HelicalArc {
                        axis: axis.letter(),
                    },
                )
                    .into());
            }
        }
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
            let radius = r.value * self.state.scale();
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
            center = self.centre_of_offsets(off_a, off_b, [ia, ib], &start, &end, col)?;
        }
        let a0 = (start[ib] - center[ib]).atan2(start[ia] - center[ia]);
        let a1 = (end[ib] - center[ib]).atan2(end[ia] - center[ia]);
        let sweep = sweep_of(a0, a1, ccw, full_circle);
        let curve = circular_arc(self.axes.len(), [ia, ib], &center, &start, &end, sweep)
            .map_err(|e| Fail::from((col, e.into())))?;
        let radius = (start[ia] - center[ia]).hypot(start[ib] - center[ib]);
        self.state.position = end;
        Ok(Some(self.block(
            line_no,
            BlockKind::Arc {
                center,
                radius,
                sweep,
                plane,
            },
            curve,
            feed,
        )))
    }

    /// The centre of an `I J K` arc in the plane of axes `[ia, ib]` (the offsets relative to
    /// the start, or absolute under `G90.1`), its radius the same at both ends within the
    /// tolerance.
    fn centre_of_offsets(
        &self,
        off_a: Option<&Word>,
        off_b: Option<&Word>,
        [ia, ib]: [usize; 2],
        start: &Point,
        end: &Point,
        col: usize,
    ) -> Step<Point> {
        let mut center = *start;
        if off_a.is_none() && off_b.is_none() {
            return Err((col, GcodeErrorKind::ArcMissingCentre).into());
        }
        let s = self.state.scale();
        let va = off_a.map(|w| w.value * s);
        let vb = off_b.map(|w| w.value * s);
        if self.state.modal.arc_centre_absolute {
            let offset = self.state.offset();
            center[ia] = va.map_or(start[ia], |v| v + offset[ia]);
            center[ib] = vb.map_or(start[ib], |v| v + offset[ib]);
        } else {
            center[ia] = start[ia] + va.unwrap_or(0.0);
            center[ib] = start[ib] + vb.unwrap_or(0.0);
        }
        let r_start = (start[ia] - center[ia]).hypot(start[ib] - center[ib]);
        let r_end = (end[ia] - center[ia]).hypot(end[ib] - center[ib]);
        let offset_col = off_a.or(off_b).map_or(col, |w| w.col);
        if r_start < 1e-9 {
            return Err((offset_col, GcodeErrorKind::ArcZeroRadius).into());
        }
        if (r_start - r_end).abs() > ARC_RADIUS_TOLERANCE_MM + ARC_RADIUS_REL * r_start {
            return Err((
                offset_col,
                GcodeErrorKind::ArcRadiusMismatch {
                    start: r_start,
                    end: r_end,
                },
            )
                .into());
        }
        Ok(center)
    }
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
    let tol = ARC_RADIUS_TOLERANCE_MM + ARC_RADIUS_REL * radius.abs();
    let h_sq = radius * radius - half * half;
    if h_sq < 0.0 && half - radius.abs() > tol {
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
