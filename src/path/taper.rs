//! The taper (`G51 A<deg>` left of the direction of travel, `G52 A<deg>` right, `G50` off):
//! the compensated contour in the program plane turned into the two guides' paths.
//!
//! X/Y move the lower guide, U/V are the upper guide relative to the lower one
//! ([`Guides`]). A wire through the contour point `P` tilted by `θ` towards the unit normal
//! `n` (left of travel for `G51`, `t = tan θ`; right for `G52`, `t < 0`) has its lower guide
//! at `P − L·t·n` and the upper one `H·t·n` above it, `L` the lower guide's distance below
//! the plane and `H` the guides' span: the wire then crosses the plane at
//! `P − L·t·n + H·t·n · L/H = P` at the angle `θ` from vertical.
//!
//! - **Lines**: `n` is constant, so both guides move on straight lines; the angle changes
//!   only on a line (as the controls do), ramped along it: `t` goes linearly from the last
//!   angle to the new one, and both guides still move straight.
//! - **Arcs**: `n` is the radial direction (towards the centre on a counter-clockwise arc),
//!   so both guide paths are arcs about the same centre: an affine image of the arc's own
//!   rational control points, exact. An arc keeps the angle in force. Leaning towards its
//!   centre, the wall's radius shrinks with height: an arc whose wall would vanish below the
//!   top of the work (`[wire] thickness_mm`) is refused.
//! - **Corners**, where the direction of travel turns, are cut one of two ways, by which
//!   side of the turn the wire leans to:
//!   - **leaning to the outside**, the wire pivots about the corner point `P` with its angle
//!     kept: `n` turns from the one before to the one after, so the lower guide describes an
//!     arc of radius `L·t` about `P` and the upper guide one of radius `(H − L)·t`. The walls
//!     above the plane get a round corner of radius `z·t` at height `z` (as a wire control's
//!     "arc" corner mode) and the wire keeps its programmed angle throughout;
//!   - **leaning into the turn**, that cone would cut past where the two walls meet (by
//!     `z·t·(1/cos(turn/2) − 1)`), so between two lines the corner is sharp: the wire there
//!     lies along the edge where the two walls' planes meet (the line through `P` whose lean
//!     `v` per unit of height satisfies `v·n₁ = v·n₂ = t`), and along each line both guides
//!     move straight from one corner's edge to the next. Both ends lie in the line's wall,
//!     so the whole move does: the walls are exact planes at the programmed draft and meet
//!     in a sharp edge at every height (the wire's angle from vertical grows towards such a
//!     corner, its draft across the wall does not). Where an arc or a curve meets a corner
//!     leaning into it, the walls are not planes and do not meet along a line: such a corner
//!     is refused unless pivoting stays within the tolerance at the top of the work
//!     (`[wire] thickness_mm`); a corner radius of `thickness·t` or more is always cut.
//! - **NURBS curves**: their normal is not rational, so each smooth piece (between knots of
//!   full multiplicity, where it pivots as at a corner) becomes a polyline of the guides'
//!   positions, halved until every chord's middle is within the tolerance of the curve's,
//!   the guides in four axes and the contour point in the plane alike.

use std::collections::VecDeque;

use nalgebra::Vector2;

use super::{Stage, StageError};
use crate::gcode::{Block, BlockKind, GcodeErrorKind, Plane};
use crate::geometry::{NurbsCurve, Point, circular_arc};
use crate::vocab::{Axis, Guides};

type V2 = Vector2<f64>;

/// Why a move cannot be cut with the taper in force (reported at its line).
#[derive(Debug)]
pub(super) struct TaperError {
    pub(super) line: u64,
    pub(super) message: String,
}

impl TaperError {
    /// The error as the path reports it: `kind` wraps the message.
    pub(super) fn at_move(self, kind: fn(String) -> GcodeErrorKind) -> StageError {
        StageError::Move {
            line: self.line,
            kind: kind(self.message),
        }
    }
}

#[derive(Debug)]
pub struct Taper {
    guides: Guides,
    /// X, Y, U and V's indices; `None`: the machine cannot tilt the wire (a `G51`/`G52` is
    /// refused before any block carries a tilt).
    axes: Option<[usize; 4]>,
    /// The tilt the wire has now, and the normal it leans along.
    tan: f64,
    normal: Option<V2>,
    tolerance: f64,
    /// The work's thickness above the program plane (mm): where the walls end.
    thickness_mm: f64,
    /// A tapered line held back until the next move says how its end corner is cut.
    held: Option<HeldLine>,
}

/// A tapered line whose end waits for the next move: sharp where that move is a line the
/// wire leans into, else at the line's own tilt.
#[derive(Debug)]
struct HeldLine {
    block: Block,
    /// Where its guides start (the corner's edge, or its own tilt).
    start: Point,
    /// Its normal and the tilt at its end.
    n: V2,
    tan_end: f64,
}

impl Stage for Taper {
    fn push(&mut self, block: Block, out: &mut VecDeque<Block>) -> Result<(), StageError> {
        self.tilt(block, out)
            .map_err(|e| e.at_move(GcodeErrorKind::Taper))
    }

    /// Vertical and staying so, nothing held: as the first steps of `tilt` find.
    fn passes(&self, block: &Block) -> bool {
        let straight = matches!(block.kind, BlockKind::Line | BlockKind::Rapid);
        self.axes.is_none()
            || (self.held.is_none()
                && self.tan == 0.0
                && self.normal.is_none()
                && !(straight && block.taper != 0.0))
    }

    /// The line held back ends at its own tilt, with nothing after it.
    fn finish(&mut self, out: &mut VecDeque<Block>) -> Result<(), StageError> {
        self.end_held(out)
            .map_err(|e| e.at_move(GcodeErrorKind::Taper))
    }
}

impl Taper {
    pub fn new(axes: &[Axis], guides: Guides, thickness_mm: f64, tolerance: f64) -> Taper {
        let index = |a: Axis| axes.iter().position(|&x| x == a);
        let axes = (|| {
            Some([
                index(Axis::X)?,
                index(Axis::Y)?,
                index(Axis::U)?,
                index(Axis::V)?,
            ])
        })();
        Taper {
            guides,
            axes,
            tan: 0.0,
            normal: None,
            tolerance,
            thickness_mm,
            held: None,
        }
    }

    /// The line held back, ended at its own tilt: at the end of the program.
    fn end_held(&mut self, out: &mut VecDeque<Block>) -> Result<(), TaperError> {
        let Some(h) = self.held.take() else {
            return Ok(());
        };
        let Some(axes) = self.axes else {
            return Ok(());
        };
        let end = self.place(&h.block.end(), h.n * h.tan_end, axes);
        emit_line(h, end, out)
    }

    /// `block` as the guides cut it, after a corner move where the tilt turns.
    fn tilt(&mut self, block: Block, out: &mut VecDeque<Block>) -> Result<(), TaperError> {
        let Some(axes) = self.axes else {
            out.push_back(block);
            return Ok(());
        };
        let line = block.line;
        let fail = |message: String| TaperError { line, message };
        let straight = matches!(block.kind, BlockKind::Line | BlockKind::Rapid);
        let [ix, iy, ..] = axes;
        let xy = |p: &Point| V2::new(p[ix], p[iy]);
        let (p0, p1) = (block.start(), block.end());
        let travel = xy(&p1) - xy(&p0);
        // The held line's end: a sharp corner into this line, or its own tilt.
        let mut sharp_start = None;
        if let Some(h) = self.held.take() {
            let edge = (straight && travel.norm() > 1e-12)
                .then(|| self.sharp_edge(h.n, left(travel.normalize()), h.tan_end))
                .flatten()
                .transpose()
                .map_err(fail)?;
            let end = match edge {
                Some(v) => {
                    let end = self.place(&h.block.end(), v, axes);
                    sharp_start = Some(end);
                    end
                }
                None => self.place(&h.block.end(), h.n * h.tan_end, axes),
            };
            emit_line(h, end, out).map_err(|e| fail(e.message))?;
        }
        if self.tan == 0.0 && !(straight && block.taper != 0.0) {
            // Vertical, and staying so (an angle waits for a line).
            self.normal = None;
            out.push_back(block);
            return Ok(());
        }
        match block.kind.clone() {
            BlockKind::Probe(_) => Err(fail(
                "a probing move cannot be tapered: cancel the taper with G50 and a move first"
                    .into(),
            )),
            BlockKind::Nurbs { .. } => {
                // Between its corners (knots of full multiplicity) a curve's normal turns
                // smoothly: each smooth piece becomes a polyline, with a pivot at each corner.
                let mut rest = block;
                let corners: Vec<f64> = rest.curve.corner_knots().collect();
                for k in corners {
                    let Some((a, b)) = rest.curve.split_at(k) else {
                        continue;
                    };
                    self.smooth_piece(
                        Block {
                            curve: a,
                            ..rest.clone()
                        },
                        axes,
                        out,
                    )?;
                    rest = Block {
                        curve: b,
                        dwell_s: 0.0,
                        pause: None,
                        ..rest
                    };
                }
                self.smooth_piece(rest, axes, out)
            }
            BlockKind::Line | BlockKind::Rapid => {
                let n = if travel.norm() > 1e-12 {
                    left(travel.normalize())
                } else {
                    self.normal.ok_or_else(|| {
                        fail("the wire's tilt needs a direction of travel in X/Y".into())
                    })?
                };
                let (t0, t1) = (self.tan, block.taper);
                // A sharp corner is cut: no pivot.
                let (block, start) = match sharp_start {
                    Some(start) => (block, start),
                    None => (self.corner(block, n, out)?, self.place(&p0, n * t0, axes)),
                };
                self.held = Some(HeldLine {
                    block,
                    start,
                    n,
                    tan_end: t1,
                });
                self.tan = t1;
                self.normal = Some(n);
                Ok(())
            }
            BlockKind::Arc {
                center,
                radius,
                sweep,
                plane,
            } => self.arc(block, (center, radius, sweep, plane), axes, out),
        }
    }

    /// An arc under the tilt in force: both guides on arcs about its centre.
    fn arc(
        &mut self,
        block: Block,
        (center, radius, sweep, plane): (Point, f64, f64, Plane),
        axes: [usize; 4],
        out: &mut VecDeque<Block>,
    ) -> Result<(), TaperError> {
        let line = block.line;
        let fail = |message: String| TaperError { line, message };
        let [ix, iy, ..] = axes;
        let xy = |p: &Point| V2::new(p[ix], p[iy]);
        let (p0, p1) = (block.start(), block.end());
        if plane != Plane::XY {
            return Err(fail(
                "a taper tilts the wire over arcs in G17 (XY) only".into(),
            ));
        }
        let (c, r) = (xy(&center), radius);
        // Left of a counter-clockwise arc is towards its centre.
        let ccw = sweep.signum();
        let normal_at = |p: &Point| -(xy(p) - c).normalize() * ccw;
        let t = self.tan;
        let (l, h) = (self.guides.lower_mm, self.guides.span_mm());
        let lower = r + ccw * l * t;
        // The wall's radius at the top of the work: smaller where the wire leans inwards.
        let top = r - ccw * t * self.thickness_mm;
        if top <= self.tolerance {
            return Err(fail(format!(
                "the wire leans into this arc (radius {r:.4} mm): at the top of the work \
                 ({} mm up) its radius would be {top:.4} mm; at this angle it needs a radius of \
                 at least {:.4} mm",
                self.thickness_mm,
                (t * self.thickness_mm).abs()
            )));
        }
        let block = self.corner(block, normal_at(&p0), out)?;
        let curve = &block.curve;
        let points: Vec<Point> = (0..curve.num_points())
            .map(|i| {
                // Affine in the control point, so the rational arc maps exactly.
                let q = curve.control_point(i);
                let radial = (xy(&q) - c) / r;
                let mut p = q;
                let lower_xy = c + radial * lower;
                let uv = -radial * (ccw * h * t);
                let [ix, iy, iu, iv] = axes;
                (p[ix], p[iy], p[iu], p[iv]) = (lower_xy.x, lower_xy.y, uv.x, uv.y);
                p
            })
            .collect();
        let weights: Vec<f64> = (0..curve.num_points()).map(|i| curve.weight(i)).collect();
        let mapped = NurbsCurve::new(
            curve.degree(),
            curve.dim(),
            &points,
            &weights,
            curve.knots().to_vec(),
        )
        .map_err(|e| fail(format!("the tapered arc: {e}")))?;
        self.normal = Some(normal_at(&p1));
        out.push_back(Block {
            kind: BlockKind::Arc {
                center,
                radius: lower.abs(),
                sweep,
                plane: Plane::XY,
            },
            curve: mapped,
            ..block
        });
        Ok(())
    }

    /// A NURBS curve without corners under the tilt in force, as a polyline of the guides'
    /// positions: halved until the middle of every chord is within the tolerance of the
    /// curve's, both the guides' point in four axes and the contour's in the plane.
    fn smooth_piece(
        &mut self,
        block: Block,
        axes: [usize; 4],
        out: &mut VecDeque<Block>,
    ) -> Result<(), TaperError> {
        let [ix, iy, ..] = axes;
        let line = block.line;
        let fail = |message: String| TaperError { line, message };
        let curve = block.curve.clone();
        let normal = |u: f64| -> Option<V2> {
            let d1 = curve.derivs(u).d1;
            let t = V2::new(d1[ix], d1[iy]);
            (t.norm() > 1e-12).then(|| left(t.normalize()))
        };
        let t = self.tan;
        let at = |u: f64| -> Option<(Point, Point)> {
            let p = curve.point(u);
            Some((self.place(&p, normal(u)? * t, axes), p))
        };
        let no_direction =
            || fail("the tapered curve has no direction of travel in X/Y somewhere".into());
        let (u0, u1) = (curve.u_min(), curve.u_max());
        let mut points = vec![at(u0).ok_or_else(no_direction)?];
        let mut stack = vec![(u1, at(u1).ok_or_else(no_direction)?, 0u32)];
        let mut from = u0;
        while let Some((to, end, depth)) = stack.pop() {
            let start = *points.last().expect("a point");
            let mid_u = 0.5 * (from + to);
            let mid = at(mid_u).ok_or_else(no_direction)?;
            // How far the curve's middle lies from the chord.
            let off = |m: &Point, a: &Point, b: &Point| {
                let ab = b - a;
                let along = (m - a).dot(&ab) / ab.norm_squared().max(f64::MIN_POSITIVE);
                (m - (a + ab * along.clamp(0.0, 1.0))).norm()
            };
            // The middle and the quarters, so an S between two points is not taken for a
            // straight chord.
            let mut fine = true;
            for k in [0.25, 0.5, 0.75] {
                let m = if k == 0.5 {
                    mid
                } else {
                    at(from + k * (to - from)).ok_or_else(no_direction)?
                };
                fine &= off(&m.0, &start.0, &end.0) <= self.tolerance
                    && off(&m.1, &start.1, &end.1) <= self.tolerance;
            }
            if fine || depth >= 24 {
                points.push(end);
                from = to;
            } else {
                stack.push((to, end, depth + 1));
                stack.push((mid_u, mid, depth + 1));
            }
        }
        let start_normal = normal(u0).ok_or_else(no_direction)?;
        let block = self.corner(block, start_normal, out)?;
        let n = points.len();
        let mut knots = vec![0.0, 0.0];
        knots.extend((1..n - 1).map(|i| i as f64));
        knots.extend([(n - 1) as f64, (n - 1) as f64]);
        let guides: Vec<Point> = points.into_iter().map(|(g, _)| g).collect();
        let polyline = NurbsCurve::new(1, curve.dim(), &guides, &vec![1.0; n], knots)
            .map_err(|e| fail(format!("the tapered curve: {e}")))?;
        self.normal = Some(normal(u1).ok_or_else(no_direction)?);
        out.push_back(Block {
            curve: polyline,
            ..block
        });
        Ok(())
    }

    /// The guides' positions for the contour point `p` with the wire leaning `v` per unit
    /// of height (`t·n` for a tilt `t` along `n`); the other axes as at `p`.
    fn place(&self, p: &Point, v: V2, [ix, iy, iu, iv]: [usize; 4]) -> Point {
        let (l, h) = (self.guides.lower_mm, self.guides.span_mm());
        let mut q = *p;
        q[ix] = p[ix] - l * v.x;
        q[iy] = p[iy] - l * v.y;
        q[iu] = h * v.x;
        q[iv] = h * v.y;
        q
    }

    /// The lean (per unit of height) of the edge where two walls meet, when the wire leans
    /// into the turn from `n1` to `n2` at tilt `t`: `Some(Ok(v))` with `v·n1 = v·n2 = t`;
    /// `None` for a corner that is pivoted instead (leaning out, or no turn); an error for a
    /// turn so sharp that edge would lie flatter than 45°.
    fn sharp_edge(&self, n1: V2, n2: V2, t: f64) -> Option<Result<V2, String>> {
        let turn = n1.perp(&n2).atan2(n1.dot(&n2));
        if t == 0.0 || turn.abs() < 1e-9 || t * turn < 0.0 {
            return None;
        }
        let det = n1.perp(&n2);
        let v = V2::new(n2.y - n1.y, n1.x - n2.x) * (t / det);
        Some(if v.norm() <= 1.0 {
            Ok(v)
        } else {
            Err(format!(
                "the wire leans into this corner ({:.1}° turn): the walls would meet along an \
                 edge {:.1}° from vertical; round the corner or lean the other way",
                turn.to_degrees().abs(),
                v.norm().atan().to_degrees()
            ))
        })
    }

    /// Where the tilted wire meets a move leaning along `n`: a pivot about the corner point
    /// (the block's programmed start) from the normal before, the angle kept. The block's
    /// stops (dwell, pause) come before its motion, so they go with the pivot; the block is
    /// handed back for its own move.
    fn corner(
        &self,
        mut block: Block,
        n: V2,
        out: &mut VecDeque<Block>,
    ) -> Result<Block, TaperError> {
        let (Some(before), Some(axes)) = (self.normal, self.axes) else {
            return Ok(block);
        };
        let turn = before.perp(&n).atan2(before.dot(&n));
        if self.tan == 0.0 || turn.abs() < 1e-9 {
            return Ok(block);
        }
        let fail = |message: String| TaperError {
            line: block.line,
            message,
        };
        // Leaning into the turn (left of a left turn), the cone about the corner point cuts
        // past where the two walls meet: at the top of the work by `h·(1/cos(turn/2) − 1)`,
        // `h` the lean there.
        let lean_top = (self.tan * self.thickness_mm).abs();
        let overcut = lean_top * (1.0 / (turn / 2.0).cos() - 1.0);
        if self.tan * turn > 0.0 && overcut > self.tolerance {
            return Err(fail(format!(
                "the wire leans into this corner ({:.1}° turn) where an arc or a curve meets \
                 it: pivoting about it would cut {overcut:.4} mm into the walls at the top of \
                 the work (a corner between two lines is cut sharp); give the corner a radius \
                 of at least {lean_top:.4} mm (the lean at the top), or lean the other way",
                turn.to_degrees().abs()
            )));
        }
        let at = |v: V2| crate::geometry::point(&[v.x, v.y]);
        let unit = circular_arc(2, [0, 1], &Point::zeros(), &at(before), &at(n), turn)
            .map_err(|e| fail(format!("the tapered corner: {e}")))?;
        let p = block.start();
        let points: Vec<Point> = (0..unit.num_points())
            .map(|i| {
                let q = unit.control_point(i);
                self.place(&p, V2::new(q[0], q[1]) * self.tan, axes)
            })
            .collect();
        let weights: Vec<f64> = (0..unit.num_points()).map(|i| unit.weight(i)).collect();
        let curve = NurbsCurve::new(
            unit.degree(),
            block.curve.dim(),
            &points,
            &weights,
            unit.knots().to_vec(),
        )
        .map_err(|e| fail(format!("the tapered corner: {e}")))?;
        let mut corner = block.clone();
        corner.kind = BlockKind::Arc {
            center: p,
            radius: (self.guides.lower_mm * self.tan).abs(),
            sweep: turn,
            plane: Plane::XY,
        };
        corner.curve = curve;
        out.push_back(corner);
        block.dwell_s = 0.0;
        block.pause = None;
        Ok(block)
    }
}

/// A held line's move, from its start to `end` (both guides straight).
fn emit_line(h: HeldLine, end: Point, out: &mut VecDeque<Block>) -> Result<(), TaperError> {
    let curve = NurbsCurve::line(h.block.curve.dim(), &h.start, &end).map_err(|e| TaperError {
        line: h.block.line,
        message: format!("the tapered move: {e}"),
    })?;
    out.push_back(Block { curve, ..h.block });
    Ok(())
}

/// The unit normal to the left of the unit direction `d`.
fn left(d: V2) -> V2 {
    V2::new(-d.y, d.x)
}

#[cfg(test)]
mod tests {
    use crate::gcode::{Block, BlockKind, BlockReader};
    use crate::vocab::Axis;
    use std::io::Cursor;

    fn read(text: &str) -> Vec<Block> {
        let axes = [Axis::X, Axis::Y, Axis::U, Axis::V];
        crate::path::Pipeline::new(BlockReader::new(
            Cursor::new(text.to_string()),
            "t.ngc",
            &axes,
        ))
        .collect::<Result<Vec<_>, _>>()
        .unwrap()
    }

    /// The shipped guides: 10 mm below the plane, 50 mm apart.
    const L: f64 = 10.0;
    const H: f64 = 50.0;

    #[test]
    fn a_line_ramps_the_tilt_a_corner_pivots_and_g50_ramps_back() {
        // G52: right of travel, so the left turn below leans to its outside.
        let t = -(3f64.to_radians().tan());
        let blocks = read("G21 G90\nG52 A3\nG1 X10 F100\nG1 Y10\nG50 G1 Y20\nM2\n");
        // The ramp: vertical at the start, tilted right of +X (towards -Y) at the end.
        let ramp = &blocks[0];
        assert_eq!(
            ramp.start().iter().take(4).copied().collect::<Vec<_>>(),
            [0.0; 4]
        );
        let e = ramp.end();
        assert!((e[0] - 10.0).abs() < 1e-12 && (e[1] + L * t).abs() < 1e-12);
        assert!(e[2].abs() < 1e-12 && (e[3] - H * t).abs() < 1e-12);
        // The corner: a quarter turn about (10, 0), the lean from -Y to +X.
        assert!(matches!(blocks[1].kind, BlockKind::Arc { .. }));
        let c = blocks[1].end();
        assert!((c[0] - (10.0 + L * t)).abs() < 1e-12 && c[1].abs() < 1e-12);
        assert!((c[2] + H * t).abs() < 1e-12 && c[3].abs() < 1e-12);
        // Along +Y at the tilt, then back to vertical over the last line.
        assert!((blocks[2].end()[0] - (10.0 + L * t)).abs() < 1e-12);
        let last = blocks[3].end();
        assert_eq!(
            last.iter().take(4).copied().collect::<Vec<_>>(),
            [10.0, 20.0, 0.0, 0.0]
        );
        // The wire meets the plane on the programmed path at every block end.
        for b in &blocks {
            let p = b.end();
            let plane = (p[0] + p[2] * L / H, p[1] + p[3] * L / H);
            assert!(
                plane.0.abs() < 1e-9 || (plane.0 - 10.0).abs() < 1e-9,
                "{plane:?}"
            );
        }
        // Leaning into that turn instead (G51), the corner is sharp: no pivot, the first line
        // ends with the wire along the edge where the two walls meet (lean (−t, t) per mm of
        // height), where the second starts.
        let t = 3f64.to_radians().tan();
        let blocks = read("G21 G90\nG51 A3\nG1 X10 F100\nG1 Y10\nM2\n");
        assert_eq!(blocks.len(), 2, "no pivot");
        let edge = [10.0 + L * t, -L * t, -H * t, H * t];
        for (p, name) in [(blocks[0].end(), "end"), (blocks[1].start(), "start")] {
            for k in 0..4 {
                assert!((p[k] - edge[k]).abs() < 1e-12, "{name} {k}: {p:?}");
            }
        }
        let e = blocks[1].end();
        let own = [10.0 + L * t, 10.0, -H * t, 0.0];
        assert!((0..4).all(|k| (e[k] - own[k]).abs() < 1e-12), "{e:?}");
        // An arc meeting such a corner: refused (the walls do not meet along a line).
        let axes = [Axis::X, Axis::Y, Axis::U, Axis::V];
        let text = "G21 G90\nG51 A3\nG1 X10 F100\nG3 X0 Y10 I-10 J0\nM2\n";
        let err = crate::path::Pipeline::new(BlockReader::new(
            Cursor::new(text.to_string()),
            "t.ngc",
            &axes,
        ))
        .collect::<Result<Vec<_>, _>>()
        .unwrap_err();
        assert!(
            matches!(&err, crate::path::PathError::Program(e) if e.line == 4),
            "{err}"
        );
        assert!(
            err.to_string().contains("where an arc or a curve meets it"),
            "{err}"
        );
    }

    #[test]
    fn an_arc_maps_to_arcs_about_its_centre_at_both_guides() {
        let t = 2f64.to_radians().tan();
        // Tilt on a line along +Y, then on tangentially (no corner) into a counter-clockwise
        // half circle about the origin from (5, 0): left of it is the centre.
        let blocks = read("G21 G90\nG0 X5 Y-5\nG52 A2\nG1 Y0 F100\nG3 X-5 Y0 I-5 J0\nM2\n");
        assert_eq!(blocks.len(), 3, "a rapid, the ramp and the arc: no pivot");
        let arc = &blocks[2];
        for k in 0..=20 {
            let u = arc.curve.u_min() + (arc.curve.u_max() - arc.curve.u_min()) * k as f64 / 20.0;
            let p = arc.curve.point(u);
            // G52 (right of counter-clockwise travel: outwards) on a radius of 5.
            let lower = p[0].hypot(p[1]);
            let upper = (p[0] + p[2]).hypot(p[1] + p[3]);
            assert!((lower - (5.0 - L * t)).abs() < 1e-9, "lower {lower}");
            assert!((upper - (5.0 + (H - L) * t)).abs() < 1e-9, "upper {upper}");
        }
    }
}
