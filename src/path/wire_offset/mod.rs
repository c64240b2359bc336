//! Wire offset (`G41`/`G42` with `D`, `G40`): the programmed contour in, the path of the wire's
//! centre out, in the XY plane (`G17`), streamed with one move of look-ahead.
//!
//! Each programmed move is offset by `d` to the left (`G41`) or right (`G42`) of its travel:
//! a line stays a line, an arc keeps its centre with radius `r ∓ d`, and a NURBS curve, whose
//! offset is no NURBS, becomes a polyline through points `p(u) ± d·n(u)` placed so that the
//! true offset curve never leaves a chord by more than the tolerance (each chord is split
//! until its midpoint and quarter points are within half the tolerance of it; the offset is
//! smooth between the curve's corner knots, so a chord that passes at its probes passes
//! between them to within the tolerance). Where two offset moves meet:
//!
//! - **convex corner** (the offset side is outside the turn): an arc of radius `d` about the
//!   programmed corner joins them, so every point of it is exactly `d` from the contour (the
//!   wire-EDM convention; a sharp corner would leave the corner's distance larger);
//! - **concave corner**: both moves are trimmed at their intersection; none found (the offset
//!   would cut into the part) is an error naming the line. Between two programmed lines or
//!   arcs the point is placed by LinuxCNC's construction, which is that intersection unless
//!   an arc is a slight spiral (its `I J` rounded): then it is where LinuxCNC puts it, up to
//!   tens of µm along the path from the exact crossing at a near-tangent junction, off the
//!   exact offset by no more than the spiral's own mismatch;
//! - **tangent junction**: nothing to add.
//!
//! **Entry and exit** as LinuxCNC's interpreter does them (`tests/it/wire_offset_linuxcnc.rs`
//! compares every end point with `rs274`'s): the first move after `G41`/`G42` starts at the
//! uncompensated point and must be longer than the offset; a line ends offset perpendicular
//! to itself at its end, an arc at its end moved along the radius, about a centre moved so the
//! arc passes through both ends (then the corner with the next move is handled as above).
//! The first move after `G40` must be a line: the move before it ends at its own offset end
//! point, with no corner processing, and the exit goes straight from there to the programmed
//! point (so a die program may leave back along its entry line).
//!
//! An arc whose offset radius would be 0 or less, or a curve whose radius of curvature on the
//! offset side is smaller than `d`, cannot be cut: an error naming the line. So is a move of
//! any axis outside the plane while the offset is on.

mod prim;

use crate::vocab::Num;
use std::collections::VecDeque;

use super::{Stage, StageError};
use crate::gcode::{Block, BlockKind, GcodeErrorKind, NurbsForm, Plane, WireOffset};
use crate::geometry::{NurbsCurve, Point, spiral_arc};
use prim::{
    MAX_DEPTH, Prim, SAME_MM, V2, add, cross, dot, join_prims, left, norm, scale, sub, unit,
};

/// The offset of one programmed move, with what its blocks carry.
#[derive(Debug, Clone)]
struct Piece {
    prims: Vec<Prim>,
    template: Block,
    /// A straight entry move: where the wire really starts (the uncompensated point). Its
    /// prims are then the programmed move's offset line, which its corner with the next move
    /// is worked out on (as LinuxCNC does: the corner point moves along the offset line, not
    /// along the slanted entry); the move emitted runs from here to that line's end. And for
    /// an arc after a corner: where the last move (or the corner's arc) ended, which the arc
    /// runs from to its own end (LinuxCNC's arc from the last compensated point: a spiral
    /// where the programmed arc's radii differ).
    entry_from: Option<V2>,
}

impl Piece {
    /// A straight move from `a` to `b` (the exit move).
    fn line(a: V2, b: V2, template: Block) -> Piece {
        Piece {
            prims: vec![Prim::Line { a, b }],
            template,
            entry_from: None,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    Off,
    On,
}

/// The wire-offset stage: the programmed contour in, the wire centre's path out.
#[derive(Debug, Clone)]
pub struct WireOffsetStage {
    phase: Phase,
    /// +1 left (G41), -1 right (G42).
    side: f64,
    d: f64,
    tolerance: f64,
    /// Axis indices of X and Y (the reader refuses `G41`/`G42` without them).
    plane: Option<[usize; 2]>,
    /// The last offset move, held until the next one shows its corner.
    pending: Option<Piece>,
}

impl WireOffsetStage {
    /// The stage for a machine with `axes`; `tolerance`: how far a curve's offset polyline
    /// may stray from the true offset, mm.
    pub fn new(axes: &[crate::vocab::Axis], tolerance: f64) -> WireOffsetStage {
        use crate::vocab::Axis;
        let index = |a: Axis| axes.iter().position(|&x| x == a);
        WireOffsetStage {
            phase: Phase::Off,
            side: 1.0,
            d: 0.0,
            tolerance,
            plane: index(Axis::X).zip(index(Axis::Y)).map(|(x, y)| [x, y]),
            pending: None,
        }
    }

    /// The entry: the first move carrying an offset ([`Block::wire_offset`]).
    fn entry(
        &mut self,
        offset: WireOffset,
        block: Block,
        (p0, p1): (V2, V2),
        [ix, iy]: [usize; 2],
    ) -> Result<(), String> {
        self.side = if offset.left { 1.0 } else { -1.0 };
        self.d = offset.d_mm;
        if norm(sub(p1, p0)) <= self.d {
            return Err(format!(
                "the entry move (the first move after G41/G42) is {} mm long, not longer than \
                 the wire offset {} mm",
                Num(norm(sub(p1, p0))),
                Num(self.d)
            ));
        }
        let (prim, entry_from) = match &block.kind {
            BlockKind::Line | BlockKind::Rapid => {
                let n = scale(left(unit(sub(p1, p0))), self.side * self.d);
                let offset_line = Prim::Line {
                    a: add(p0, n),
                    b: add(p1, n),
                };
                (offset_line, Some(p0))
            }
            BlockKind::Arc { center, sweep, .. } => {
                let arc = self.entry_arc(p0, p1, (center[ix], center[iy]), *sweep)?;
                (arc, None)
            }
            _ => {
                return Err(
                    "the first move after G41/G42 (the entry) must be a line or an arc".into(),
                );
            }
        };
        self.pending = Some(Piece {
            prims: vec![prim],
            template: block,
            entry_from,
        });
        self.phase = Phase::On;
        Ok(())
    }

    /// The exit: the first move without an offset after the offset path.
    fn exit(
        &mut self,
        block: Block,
        (p0, p1): (V2, V2),
        out: &mut VecDeque<Block>,
    ) -> Result<(), StageError> {
        let line = block.line;
        if !matches!(block.kind, BlockKind::Line | BlockKind::Rapid) {
            return Err(fail(
                line,
                "the first move after G40 (the exit) must be a straight move".into(),
            ));
        }
        // The last offset move keeps its own offset end (no corner with the exit); the
        // exit goes straight from there to the programmed point.
        let from = match self.pending.take() {
            Some(last) => {
                let end = last.prims.last().map_or(p0, Prim::end);
                let last_line = last.template.line;
                self.emit(last, out).map_err(|m| fail(last_line, m))?;
                end
            }
            None => p0,
        };
        self.emit(Piece::line(from, p1, block), out)
            .map_err(|m| fail(line, m))?;
        self.phase = Phase::Off;
        Ok(())
    }
}

/// A wire-offset error about the move at `line`.
fn fail(line: u64, message: String) -> StageError {
    StageError::Move {
        line,
        kind: GcodeErrorKind::WireOffset(message),
    }
}

impl Stage for WireOffsetStage {
    /// Takes a programmed move; hands the offset moves that are final to `out`.
    fn push(&mut self, block: Block, out: &mut VecDeque<Block>) -> Result<(), StageError> {
        let line = block.line;
        if self.phase == Phase::Off && block.wire_offset.is_none() {
            out.push_back(block);
            return Ok(());
        }
        let Some([ix, iy]) = self.plane else {
            // The reader refuses G41/G42 on a machine without X and Y.
            out.push_back(block);
            return Ok(());
        };
        let (s, e) = (block.start(), block.end());
        for i in 0..s.len() {
            if i != ix && i != iy && (e[i] - s[i]).abs() > SAME_MM {
                return Err(fail(
                    line,
                    "only X and Y may move while the wire offset is on (G41/G42)".into(),
                ));
            }
        }
        let ends = ((s[ix], s[iy]), (e[ix], e[iy]));
        match (self.phase, block.wire_offset) {
            (Phase::Off, Some(offset)) => self
                .entry(offset, block, ends, [ix, iy])
                .map_err(|m| fail(line, m)),
            (Phase::On, Some(_)) => {
                let piece = self.offset(block).map_err(|m| fail(line, m))?;
                self.join(piece, out)
            }
            (Phase::On, None) => self.exit(block, ends, out),
            (Phase::Off, None) => unreachable!("handled above"),
        }
    }

    fn passes(&self, block: &Block) -> bool {
        self.phase == Phase::Off && block.wire_offset.is_none()
    }

    /// At the end of the program: the held move goes out as it is.
    fn finish(&mut self, out: &mut VecDeque<Block>) -> Result<(), StageError> {
        if let Some(last) = self.pending.take() {
            let line = last.template.line;
            self.emit(last, out).map_err(|m| fail(line, m))?;
        }
        self.phase = Phase::Off;
        Ok(())
    }
}

impl WireOffsetStage {
    /// An arc as the entry move, as LinuxCNC's interpreter makes it: from the uncompensated
    /// start `p0` to the programmed end `p1` moved by the offset along the end's radius
    /// (towards the centre `c` where the wire is inside the arc), about the point of the line
    /// through `c` and that end which is as far from both ends; the turn is the programmed one.
    fn entry_arc(&self, p0: V2, p1: V2, c: V2, sweep: f64) -> Result<Prim, String> {
        let ccw = sweep > 0.0;
        // Left of a counter-clockwise arc is its inside.
        let inside = (self.side > 0.0) == ccw;
        let radial = unit(if inside { sub(c, p1) } else { sub(p1, c) });
        let end = add(p1, scale(radial, self.d));
        let toward = unit(sub(c, end));
        let chord = sub(p0, end);
        let cos_a = dot(unit(chord), toward);
        if cos_a.abs() < 1e-12 {
            return Err(
                "the entry arc cannot reach the offset path: the wire offset is not smaller \
                 than the arc's radius"
                    .into(),
            );
        }
        let centre = add(end, scale(toward, norm(chord) / 2.0 / cos_a));
        let r = norm(sub(end, centre));
        let a0 = (p0.1 - centre.1).atan2(p0.0 - centre.0);
        let a1 = (end.1 - centre.1).atan2(end.0 - centre.0);
        let tau = std::f64::consts::TAU;
        let turn = if ccw {
            (a1 - a0).rem_euclid(tau)
        } else {
            -(a0 - a1).rem_euclid(tau)
        };
        Ok(Prim::Arc {
            c: centre,
            r,
            a0,
            sweep: turn,
        })
    }

    /// The offset of a programmed move (not the entry or exit).
    fn offset(&self, block: Block) -> Result<Piece, String> {
        let [ix, iy] = self.plane.expect("no offset without X and Y");
        let sd = self.side * self.d;
        let (s, e) = (block.start(), block.end());
        let (p0, p1) = ((s[ix], s[iy]), (e[ix], e[iy]));
        let prims = match &block.kind {
            // Probing refuses a wire offset before it gets here.
            BlockKind::Line | BlockKind::Rapid | BlockKind::Probe(_) => {
                let n = scale(left(unit(sub(p1, p0))), sd);
                vec![Prim::Line {
                    a: add(p0, n),
                    b: add(p1, n),
                }]
            }
            BlockKind::Arc {
                center,
                radius,
                sweep,
                ..
            } => {
                let c = (center[ix], center[iy]);
                // Left of a counter-clockwise arc is towards its centre.
                let r = radius - sd * sweep.signum();
                if r <= self.tolerance {
                    return Err(format!(
                        "the wire offset {} mm is not smaller than the arc's radius {} mm on \
                         the inside of the turn: it cannot be cut",
                        Num(self.d),
                        Num(*radius)
                    ));
                }
                vec![Prim::Arc {
                    c,
                    r,
                    a0: (p0.1 - c.1).atan2(p0.0 - c.0),
                    sweep: *sweep,
                }]
            }
            BlockKind::Nurbs { .. } => self.offset_curve(&block.curve)?,
        };
        Ok(Piece {
            prims,
            template: block,
            entry_from: None,
        })
    }

    /// A NURBS curve's offset as chords within the tolerance, piece by piece between corner
    /// knots; the corners inside the curve are joined like corners between moves.
    fn offset_curve(&self, curve: &NurbsCurve) -> Result<Vec<Prim>, String> {
        let [ix, iy] = self.plane.expect("no offset without X and Y");
        let sd = self.side * self.d;
        let offset_at = |u: f64, from_left: bool| -> Result<V2, String> {
            let d = if from_left {
                curve.derivs_from_left(u)
            } else {
                curve.derivs(u)
            };
            let t = (d.d1[ix], d.d1[iy]);
            let speed = norm(t);
            if speed == 0.0 {
                return Err(
                    "the curve has a point without a direction: it cannot be offset".into(),
                );
            }
            // Signed curvature: positive turning left.
            let k = cross(t, (d.d2[ix], d.d2[iy])) / (speed * speed * speed);
            if self.side * k > 0.0 && 1.0 / k.abs() < self.d {
                return Err(format!(
                    "the curve turns tighter (radius {} mm) than the wire offset {} mm on its \
                     inner side: it cannot be cut",
                    Num(1.0 / k.abs()),
                    Num(self.d)
                ));
            }
            let n = left(scale(t, 1.0 / speed));
            Ok(add((d.point[ix], d.point[iy]), scale(n, sd)))
        };
        let mut bounds: Vec<f64> = vec![curve.u_min()];
        bounds.extend(curve.corner_knots());
        bounds.push(curve.u_max());
        let mut pieces: Vec<(f64, Vec<Prim>)> = Vec::new();
        for w in bounds.windows(2) {
            let (u0, u1) = (w[0], w[1]);
            if u1 <= u0 {
                continue;
            }
            let mut prims = Vec::new();
            let q0 = offset_at(u0, false)?;
            let q1 = offset_at(u1, true)?;
            self.chords(&offset_at, u0, q0, u1, q1, 0, &mut prims)?;
            if !prims.is_empty() {
                pieces.push((u0, prims));
            }
        }
        let mut all: Vec<Prim> = Vec::new();
        for (u0, prims) in pieces {
            if all.is_empty() {
                all = prims;
                continue;
            }
            // A corner of the curve: joined as between two moves.
            let p = curve.point(u0);
            let corner_point = (p[ix], p[iy]);
            let mut b = prims;
            let extra = join_prims(&mut all, &mut b, corner_point, self.side, self.d, false)?;
            all.extend(extra);
            all.extend(b);
        }
        Ok(all)
    }

    #[allow(clippy::too_many_arguments)]
    fn chords(
        &self,
        offset_at: &dyn Fn(f64, bool) -> Result<V2, String>,
        u0: f64,
        q0: V2,
        u1: f64,
        q1: V2,
        depth: u32,
        out: &mut Vec<Prim>,
    ) -> Result<(), String> {
        let um = 0.5 * (u0 + u1);
        let qm = offset_at(um, false)?;
        let probes = [0.25, 0.75].map(|f| u0 + f * (u1 - u0));
        let chord = sub(q1, q0);
        let len = norm(chord);
        let off_chord = |q: V2| -> f64 {
            if len == 0.0 {
                norm(sub(q, q0))
            } else {
                let s = (dot(sub(q, q0), chord) / (len * len)).clamp(0.0, 1.0);
                norm(sub(q, add(q0, scale(chord, s))))
            }
        };
        let mut worst = off_chord(qm);
        for &u in &probes {
            worst = worst.max(off_chord(offset_at(u, false)?));
        }
        if depth < 4 || (worst > 0.5 * self.tolerance && depth < MAX_DEPTH) {
            self.chords(offset_at, u0, q0, um, qm, depth + 1, out)?;
            self.chords(offset_at, um, qm, u1, q1, depth + 1, out)?;
            return Ok(());
        }
        if worst > 0.5 * self.tolerance {
            return Err("the curve's offset could not be approximated within the tolerance".into());
        }
        if len > SAME_MM {
            out.push(Prim::Line { a: q0, b: q1 });
        }
        Ok(())
    }

    /// Joins the held move and `next` at their corner, sends the held one out, holds `next`.
    fn join(&mut self, mut next: Piece, out: &mut VecDeque<Block>) -> Result<(), StageError> {
        let Some(mut prev) = self.pending.take() else {
            self.pending = Some(next);
            return Ok(());
        };
        let [ix, iy] = self.plane.expect("no offset without X and Y");
        let corner = next.template.start();
        let corner = (corner[ix], corner[iy]);
        let programmed = |p: &Piece| !matches!(p.template.kind, BlockKind::Nurbs { .. });
        let both_programmed = programmed(&prev) && programmed(&next);
        let extra = join_prims(
            &mut prev.prims,
            &mut next.prims,
            corner,
            self.side,
            self.d,
            both_programmed,
        )
        .map_err(|m| fail(next.template.line, m))?;
        let joined_at = extra.last().or(prev.prims.last()).map(Prim::end);
        if let (Some(Prim::Arc { .. }), Some(end)) = (next.prims.first(), joined_at) {
            next.entry_from = Some(end);
        }
        let line = prev.template.line;
        self.emit(prev, out).map_err(|m| fail(line, m))?;
        if !extra.is_empty() {
            // The corner arc: a move of its own, on the next move's line, carrying its stops.
            let mut template = next.template.clone();
            template.kind = BlockKind::Arc {
                center: Point::zeros(),
                radius: self.d,
                sweep: 0.0,
                plane: Plane::XY,
            };
            next.template.dwell_s = 0.0;
            next.template.pause = None;
            let corner = Piece {
                prims: extra,
                template,
                entry_from: None,
            };
            let line = corner.template.line;
            self.emit(corner, out).map_err(|m| fail(line, m))?;
        }
        self.pending = Some(next);
        Ok(())
    }

    /// Turns a piece into blocks: one per line or arc; a NURBS offset's chords as one
    /// polyline block.
    fn emit(&self, piece: Piece, out: &mut VecDeque<Block>) -> Result<(), String> {
        let [ix, iy] = self.plane.expect("no offset without X and Y");
        let t = &piece.template;
        let base = t.start();
        let dim = t.curve.dim();
        let point = |v: V2| {
            let mut p = base;
            p[ix] = v.0;
            p[iy] = v.1;
            p
        };
        let mut prims: Vec<Prim> = piece.prims.clone();
        let mut arc_from = None;
        match (piece.entry_from, prims.first_mut()) {
            (Some(from), Some(Prim::Line { a, .. })) => *a = from,
            (Some(from), Some(Prim::Arc { .. })) => arc_from = Some(from),
            _ => {}
        }
        prims.retain(|p| p.length() > SAME_MM);
        let mut first = true;
        let mut push = |kind: BlockKind, curve: NurbsCurve| {
            let mut b = Block::new(t.line, kind, curve, t.feed_mm_per_min);
            b.flushing = t.flushing;
            b.condition = t.condition;
            b.taper = t.taper;
            b.wire_offset = t.wire_offset;
            if std::mem::take(&mut first) {
                b.dwell_s = t.dwell_s;
                b.pause = t.pause;
            }
            out.push_back(b);
        };
        let polyline = matches!(t.kind, BlockKind::Nurbs { .. }) && prims.len() > 1;
        if polyline {
            let points: Vec<Point> = std::iter::once(point(prims[0].start()))
                .chain(prims.iter().map(|p| point(p.end())))
                .collect();
            let n = points.len();
            let mut knots = vec![0.0, 0.0];
            knots.extend((1..n - 1).map(|i| i as f64));
            knots.extend([(n - 1) as f64, (n - 1) as f64]);
            let curve = NurbsCurve::new(1, dim, &points, &vec![1.0; n], knots)
                .map_err(|e| e.to_string())?;
            let form = match t.kind {
                BlockKind::Nurbs { form } => form,
                _ => NurbsForm::LinuxCnc,
            };
            push(BlockKind::Nurbs { form }, curve);
            return Ok(());
        }
        for prim in prims {
            match prim {
                Prim::Line { a, b } => {
                    let kind = if t.kind == BlockKind::Rapid {
                        BlockKind::Rapid
                    } else {
                        BlockKind::Line
                    };
                    let curve =
                        NurbsCurve::line(dim, &point(a), &point(b)).map_err(|e| e.to_string())?;
                    push(kind, curve);
                }
                Prim::Arc { c, r, sweep, .. } => {
                    let center = point(c);
                    let start = arc_from.take().unwrap_or(prim.start());
                    let curve = spiral_arc(
                        dim,
                        [ix, iy],
                        &center,
                        &point(start),
                        &point(prim.end()),
                        sweep,
                    )
                    .map_err(|e| e.to_string())?;
                    push(
                        BlockKind::Arc {
                            center,
                            radius: r,
                            sweep,
                            plane: Plane::XY,
                        },
                        curve,
                    );
                }
            }
        }
        Ok(())
    }
}
