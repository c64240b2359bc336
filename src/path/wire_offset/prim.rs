//! The offset path's primitives (segments and circular arcs) in the plane: evaluation,
//! intersections, cutting, and the join of two offset paths at a programmed corner.

/// Two closer than this (mm) are the same point.
pub(super) const SAME_MM: f64 = 1e-9;
/// Whether a corner from `prev` into `next` is concave (the offsets cross) rather than convex
/// (the wire goes round it), `toward` the signed turn towards the offset's side (radians,
/// the slight turns already taken out), `reverse` an exact reversal. LinuxCNC's rule
/// (`convert_straight_comp2`, `convert_arc_comp2`): a turn within [`SLIGHT_TURN`] of a
/// reversal is convex, either way, unless the offset is on the outside of the arc it turns
/// from (into a line) or into (an arc): the top of an "h" or an "m".
fn concave(prev: &Prim, next: &Prim, toward: f64, reverse: bool, side: f64) -> bool {
    let outside = |p: &Prim| matches!(p, Prim::Arc { sweep, .. } if side * sweep < 0.0);
    let near_reversal = reverse || std::f64::consts::PI - toward.abs() <= SLIGHT_TURN;
    if near_reversal {
        return match next {
            Prim::Line { .. } => outside(prev),
            Prim::Arc { .. } => outside(next),
        };
    }
    toward > 0.0
}

/// How many primitives on each side of a concave corner are searched for the intersection.
const TRIM_SEARCH: usize = 64;
/// A turn between two moves up to this (radians) is no corner: LinuxCNC's
/// `TOLERANCE_CONCAVE_CORNER`.
const SLIGHT_TURN: f64 = 0.05;
/// Deepest subdivision of a NURBS offset (2^30 chords at most per piece).
pub(super) const MAX_DEPTH: u32 = 30;

pub(super) type V2 = (f64, f64);

pub(super) fn sub(a: V2, b: V2) -> V2 {
    (a.0 - b.0, a.1 - b.1)
}
pub(super) fn add(a: V2, b: V2) -> V2 {
    (a.0 + b.0, a.1 + b.1)
}
pub(super) fn scale(a: V2, k: f64) -> V2 {
    (a.0 * k, a.1 * k)
}
pub(super) fn dot(a: V2, b: V2) -> f64 {
    a.0 * b.0 + a.1 * b.1
}
pub(super) fn cross(a: V2, b: V2) -> f64 {
    a.0 * b.1 - a.1 * b.0
}
pub(super) fn norm(a: V2) -> f64 {
    a.0.hypot(a.1)
}
pub(super) fn unit(a: V2) -> V2 {
    let n = norm(a);
    if n > 0.0 {
        scale(a, 1.0 / n)
    } else {
        (0.0, 0.0)
    }
}
/// Left normal of a unit tangent.
pub(super) fn left(t: V2) -> V2 {
    (-t.1, t.0)
}

/// One primitive of an offset path: a segment or a circular arc.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Prim {
    Line {
        a: V2,
        b: V2,
    },
    /// Centre, radius, start angle, signed sweep (positive counter-clockwise), radians.
    Arc {
        c: V2,
        r: f64,
        a0: f64,
        sweep: f64,
    },
}

impl Prim {
    pub(super) fn at(&self, s: f64) -> V2 {
        match *self {
            Prim::Line { a, b } => add(a, scale(sub(b, a), s)),
            Prim::Arc { c, r, a0, sweep } => {
                let ang = a0 + sweep * s;
                (c.0 + r * ang.cos(), c.1 + r * ang.sin())
            }
        }
    }

    pub(super) fn start(&self) -> V2 {
        self.at(0.0)
    }

    pub(super) fn end(&self) -> V2 {
        self.at(1.0)
    }

    /// Unit tangent at fraction `s`.
    pub(super) fn tangent(&self, s: f64) -> V2 {
        match *self {
            Prim::Line { a, b } => unit(sub(b, a)),
            Prim::Arc { a0, sweep, .. } => {
                let ang = a0 + sweep * s;
                let t = (-ang.sin(), ang.cos());
                if sweep >= 0.0 { t } else { scale(t, -1.0) }
            }
        }
    }

    /// Fractions along `self` and `other` where they cross (within both).
    fn intersections(&self, other: &Prim) -> Vec<(f64, f64)> {
        const E: f64 = 1e-9;
        let inside = |s: f64| (-E..=1.0 + E).contains(&s);
        let mut found = Vec::new();
        match (*self, *other) {
            (Prim::Line { a, b }, Prim::Line { a: c, b: d }) => {
                let (r, q) = (sub(b, a), sub(d, c));
                let den = cross(r, q);
                if den.abs() > 1e-15 {
                    let s = cross(sub(c, a), q) / den;
                    let t = cross(sub(c, a), r) / den;
                    if inside(s) && inside(t) {
                        found.push((s.clamp(0.0, 1.0), t.clamp(0.0, 1.0)));
                    }
                }
            }
            (Prim::Line { .. }, Prim::Arc { .. }) => {
                found = other
                    .intersections(self)
                    .into_iter()
                    .map(|(t, s)| (s, t))
                    .collect();
            }
            (Prim::Arc { c, r, .. }, Prim::Line { a, b }) => {
                // |a + t (b - a) - c| = r
                let d = sub(b, a);
                let f = sub(a, c);
                let (qa, qb, qc) = (dot(d, d), 2.0 * dot(f, d), dot(f, f) - r * r);
                let disc = qb * qb - 4.0 * qa * qc;
                if qa > 0.0 && disc >= -1e-12 {
                    let root = disc.max(0.0).sqrt();
                    for t in [(-qb - root) / (2.0 * qa), (-qb + root) / (2.0 * qa)] {
                        if inside(t)
                            && let Some(s) = self.fraction_of(add(a, scale(d, t)))
                        {
                            found.push((s, t.clamp(0.0, 1.0)));
                        }
                    }
                }
            }
            (Prim::Arc { c: c1, r: r1, .. }, Prim::Arc { c: c2, r: r2, .. }) => {
                let dv = sub(c2, c1);
                let dist = norm(dv);
                if dist > 1e-12 && dist <= r1 + r2 + 1e-9 && dist >= (r1 - r2).abs() - 1e-9 {
                    let x = (dist * dist + r1 * r1 - r2 * r2) / (2.0 * dist);
                    let h = (r1 * r1 - x * x).max(0.0).sqrt();
                    let base = add(c1, scale(dv, x / dist));
                    let off = scale(left(scale(dv, 1.0 / dist)), h);
                    for p in [add(base, off), sub(base, off)] {
                        if let (Some(s), Some(t)) = (self.fraction_of(p), other.fraction_of(p)) {
                            found.push((s, t));
                        }
                    }
                }
            }
        }
        found
    }

    /// For an arc: the fraction of the sweep at which it passes through `p` (on its circle).
    fn fraction_of(&self, p: V2) -> Option<f64> {
        let Prim::Arc { c, a0, sweep, .. } = *self else {
            return None;
        };
        let ang = (p.1 - c.1).atan2(p.0 - c.0);
        let tau = std::f64::consts::TAU;
        let along = if sweep >= 0.0 {
            (ang - a0).rem_euclid(tau)
        } else {
            (a0 - ang).rem_euclid(tau)
        };
        let s = along / sweep.abs();
        let e = 1e-9 / sweep.abs().max(1e-12);
        if s <= 1.0 + e {
            Some(s.min(1.0))
        } else if (tau - along) / sweep.abs() <= e {
            Some(0.0)
        } else {
            None
        }
    }

    /// The part from fraction `from` to `to`.
    fn cut(&self, from: f64, to: f64) -> Prim {
        match *self {
            Prim::Line { .. } => Prim::Line {
                a: self.at(from),
                b: self.at(to),
            },
            Prim::Arc { c, r, a0, sweep } => Prim::Arc {
                c,
                r,
                a0: a0 + sweep * from,
                sweep: sweep * (to - from),
            },
        }
    }

    pub(super) fn length(&self) -> f64 {
        match *self {
            Prim::Line { a, b } => norm(sub(b, a)),
            Prim::Arc { r, sweep, .. } => r * sweep.abs(),
        }
    }
}

/// Joins two offset paths meeting at the programmed `corner`: trims both at their
/// intersection (concave) or returns the arc about `corner` that links them (convex).
///
/// `programmed`: `a` ends and `b` starts with the offset of a programmed line or arc (not a
/// chord of a curve's offset), whose concave corner is placed as LinuxCNC places it.
pub(super) fn join_prims(
    a: &mut Vec<Prim>,
    b: &mut Vec<Prim>,
    corner: V2,
    side: f64,
    d: f64,
    programmed: bool,
) -> Result<Vec<Prim>, String> {
    let (ea, sb) = (a[a.len() - 1].end(), b[0].start());
    if norm(sub(ea, sb)) <= 1e-7 {
        // Tangent (or as good as): the offsets meet.
        return Ok(Vec::new());
    }
    let (ta, tb) = (a[a.len() - 1].tangent(1.0), b[0].tangent(0.0));
    let turn = cross(ta, tb);
    let reverse = dot(ta, tb) < 0.0 && turn.abs() < 1e-9;
    if !reverse && turn.atan2(dot(ta, tb)).abs() <= SLIGHT_TURN {
        // As LinuxCNC: a corner this slight, convex or concave, gets neither an arc nor a
        // trim; the next move starts where the last one ended (a line from there; an arc
        // from there to its own end, which the emitted move spirals to where the distance
        // from its centre differs).
        match &mut b[0] {
            Prim::Line { a: start, .. } => *start = ea,
            Prim::Arc { c, a0, sweep, .. } => {
                // The arc starts at the angle of the last end about its centre, its end kept.
                let start = (ea.1 - c.1).atan2(ea.0 - c.0);
                let moved = (start - *a0 + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                    - std::f64::consts::PI;
                *a0 += moved;
                *sweep -= moved;
            }
        }
        return Ok(Vec::new());
    }
    if !concave(
        &a[a.len() - 1],
        &b[0],
        side * turn.atan2(dot(ta, tb)),
        reverse,
        side,
    ) {
        // Convex: around the corner at distance d, turning away from the offset's side (the
        // long way round a tip within the band of a reversal).
        let (v1, v2) = (sub(ea, corner), sub(sb, corner));
        let mut sweep = cross(v1, v2).atan2(dot(v1, v2));
        if reverse || (sweep.abs() - std::f64::consts::PI).abs() < 1e-9 {
            sweep = -side * std::f64::consts::PI;
        } else if side * sweep > 0.0 {
            sweep -= side * std::f64::consts::TAU;
        }
        return Ok(vec![Prim::Arc {
            c: corner,
            r: d,
            a0: v1.1.atan2(v1.0),
            sweep,
        }]);
    }
    if programmed
        && let Some(meet) = concave_as_linuxcnc(&a[a.len() - 1], &b[0], corner, side, d)
        && let (Some(ta), Some(tb)) = (a[a.len() - 1].ending_at(meet), b[0].starting_at(meet))
    {
        let last = a.len() - 1;
        a[last] = ta;
        b[0] = tb;
        return Ok(Vec::new());
    }
    // Concave: the nearest crossing, searching back along `a` and forward along `b`.
    let na = a.len();
    for i in (na.saturating_sub(TRIM_SEARCH)..na).rev() {
        for j in 0..b.len().min(TRIM_SEARCH) {
            let hits = a[i].intersections(&b[j]);
            if let Some(&(s, t)) = hits
                .iter()
                .max_by(|x, y| (x.0 - x.1).total_cmp(&(y.0 - y.1)))
            {
                a.truncate(i + 1);
                a[i] = a[i].cut(0.0, s);
                b.drain(..j);
                b[0] = b[0].cut(t, 1.0);
                // Meet exactly (the cut points agree to rounding).
                if let Prim::Line { a: start, .. } = &mut b[0] {
                    *start = a[i].end();
                }
                return Ok(Vec::new());
            }
        }
    }
    Err(format!(
        "the wire offset of {} mm cuts into the part at this corner (the offset paths do not \
         meet): the offset is larger than the contour allows",
        crate::vocab::Num(d)
    ))
}

/// Where LinuxCNC's interpreter ends `a` and starts `b` at a concave corner of two
/// programmed moves (`convert_straight_comp2`, `convert_arc_comp2`), `corner` the programmed
/// corner, `side` +1 left, `d` the offset; `None` where it finds no point (it refuses the
/// corner as gouging; the general search then says why).
///
/// Its constructions are the offsets' intersection wherever an arc's start and end radii
/// agree. Where they differ (an `I J` arc rounded to four decimals of an inch is a slight
/// spiral), a line into an arc is met on the circle of the arc's end radius at the distance
/// from its centre that the end radius, not the start radius, gives the line; and the
/// crossing of two arcs is taken wherever it lies, not only within their sweeps. Near a
/// tangent junction the point moves far along the path for a micrometre of spiral: edmd
/// places it where LinuxCNC does, so the two read such a program to the same cut.
fn concave_as_linuxcnc(a: &Prim, b: &Prim, corner: V2, side: f64, d: f64) -> Option<V2> {
    use std::f64::consts::{FRAC_PI_2, PI};
    let angle = |v: V2| v.1.atan2(v.0);
    let at = |c: V2, r: f64, ang: f64| (c.0 + r * ang.cos(), c.1 + r * ang.sin());
    let unit_range = |l: f64| (-1.0..=1.0).contains(&l).then_some(l);
    // The wire inside the arc: left of a counter-clockwise one, right of a clockwise one.
    let inside = |sweep: f64| (side > 0.0) == (sweep > 0.0);
    match (*a, *b) {
        (Prim::Line { .. }, Prim::Line { .. }) => None,
        (Prim::Line { .. }, Prim::Arc { c, r, sweep, .. }) => {
            let theta = angle(a.tangent(1.0));
            let delta = angle(sub(c, corner));
            let alpha = if sweep > 0.0 {
                delta - FRAC_PI_2
            } else {
                delta + FRAC_PI_2
            };
            let beta = if side > 0.0 {
                theta - alpha
            } else {
                alpha - theta
            };
            let end_radius = if inside(sweep) { r + d } else { r - d };
            let toward = end_radius * (beta - FRAC_PI_2).sin();
            let ang = if inside(sweep) {
                let l = unit_range((toward + d) / r)?;
                if sweep > 0.0 {
                    theta + l.asin()
                } else {
                    theta - l.asin()
                }
            } else {
                let l = unit_range((toward - d) / r)?;
                if sweep > 0.0 {
                    theta + PI - l.asin()
                } else {
                    theta + PI + l.asin()
                }
            };
            Some(at(c, r, ang))
        }
        (Prim::Arc { c, r, sweep, .. }, Prim::Line { .. }) => {
            let base = angle(b.tangent(0.0));
            let theta = if sweep > 0.0 {
                base + FRAC_PI_2
            } else {
                base - FRAC_PI_2
            };
            let phi = angle(sub(c, corner));
            let programmed_radius = if inside(sweep) { r + d } else { r - d };
            let across = programmed_radius * (theta - phi).cos();
            let toward = if inside(sweep) {
                across - d
            } else {
                across + d
            };
            let turn_back = unit_range(toward / r)?.acos();
            let ang = if inside(sweep) == (sweep > 0.0) {
                theta + PI - turn_back
            } else {
                theta + PI + turn_back
            };
            Some(at(c, r, ang))
        }
        (
            Prim::Arc {
                c: ca,
                r: ra,
                sweep: sa,
                ..
            },
            Prim::Arc {
                c: cb,
                r: rb,
                sweep: sb,
                ..
            },
        ) => {
            let between = norm(sub(cb, ca));
            if ra == 0.0 || between == 0.0 {
                return None;
            }
            let cos_back = (ra * ra + between * between - rb * rb) / (2.0 * ra * between);
            let pullback = unit_range(cos_back)?.acos();
            let toward = angle(sub(cb, ca));
            let ang = if inside(sa) == (sb > 0.0) {
                toward + pullback
            } else {
                toward - pullback
            };
            Some(at(ca, ra, ang))
        }
    }
}

impl Prim {
    /// `self` ended at `p` (a line's end moved there; an arc's end moved to `p`'s angle about
    /// its centre, by less than half a turn), or `None` if that would turn it round.
    fn ending_at(&self, p: V2) -> Option<Prim> {
        match *self {
            Prim::Line { a, b } => {
                (dot(sub(p, a), sub(b, a)) > 0.0).then_some(Prim::Line { a, b: p })
            }
            Prim::Arc { c, r, a0, sweep } => {
                let moved = wrapped(sub(p, c).1.atan2(sub(p, c).0) - (a0 + sweep));
                let sweep2 = sweep + moved;
                (sweep2 * sweep > 0.0).then_some(Prim::Arc {
                    c,
                    r,
                    a0,
                    sweep: sweep2,
                })
            }
        }
    }

    /// `self` started at `p`, as [`Prim::ending_at`] ends it.
    fn starting_at(&self, p: V2) -> Option<Prim> {
        match *self {
            Prim::Line { a, b } => {
                (dot(sub(b, p), sub(b, a)) > 0.0).then_some(Prim::Line { a: p, b })
            }
            Prim::Arc { c, r, a0, sweep } => {
                let moved = wrapped(sub(p, c).1.atan2(sub(p, c).0) - a0);
                let sweep2 = sweep - moved;
                (sweep2 * sweep > 0.0).then_some(Prim::Arc {
                    c,
                    r,
                    a0: a0 + moved,
                    sweep: sweep2,
                })
            }
        }
    }
}

/// An angle in (-π, π].
fn wrapped(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    let w = (a + PI).rem_euclid(TAU) - PI;
    if w <= -PI { w + TAU } else { w }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The offset (`side` +1 left, `d`) of a programmed move through the corner at the
    /// origin with tangent `heading` there: a line of length 10, or an arc of radius 5 turning
    /// `turn` (±1) for 1 radian; `into` the corner (ending there) or out of it.
    fn offset_move(heading: f64, turn: Option<f64>, into: bool, side: f64, d: f64) -> Prim {
        let t = (heading.cos(), heading.sin());
        let Some(turn) = turn else {
            let n = scale(left(t), side * d);
            let far = scale(t, if into { -10.0 } else { 10.0 });
            let (a, b) = if into {
                (far, (0.0, 0.0))
            } else {
                ((0.0, 0.0), far)
            };
            return Prim::Line {
                a: add(a, n),
                b: add(b, n),
            };
        };
        let c = scale(left(t), 5.0 * turn);
        let at_corner = (-c.1).atan2(-c.0);
        let sweep = turn * 1.0;
        Prim::Arc {
            c,
            r: 5.0 - side * d * turn,
            a0: if into { at_corner - sweep } else { at_corner },
            sweep,
        }
    }

    #[test]
    fn where_an_arcs_radii_agree_linuxcncs_concave_corner_is_the_offsets_crossing() {
        let d = 0.3;
        let mut checked = 0;
        for side in [1.0, -1.0] {
            for into in [None, Some(1.0), Some(-1.0)] {
                for out in [None, Some(1.0), Some(-1.0)] {
                    if into.is_none() && out.is_none() {
                        continue; // Two lines: the general crossing, no construction.
                    }
                    // Turned 0.7 rad towards the offset's side: a concave corner.
                    let a = offset_move(0.0, into, true, side, d);
                    let b = offset_move(side * 0.7, out, false, side, d);
                    let meet = concave_as_linuxcnc(&a, &b, (0.0, 0.0), side, d)
                        .unwrap_or_else(|| panic!("no point: {a:?} {b:?}"));
                    let off = |p: &Prim| match *p {
                        Prim::Line { a, b } => cross(unit(sub(b, a)), sub(meet, a)).abs(),
                        Prim::Arc { c, r, .. } => (norm(sub(meet, c)) - r).abs(),
                    };
                    assert!(
                        off(&a) < 1e-12 && off(&b) < 1e-12,
                        "{a:?} {b:?} meet {meet:?}"
                    );
                    // The crossing near the corner, where the search finds it too.
                    let crossing = a.intersections(&b);
                    assert!(
                        crossing
                            .iter()
                            .any(|&(s, _)| norm(sub(a.at(s), meet)) < 1e-9),
                        "{a:?} {b:?}: {meet:?} is not among {crossing:?}"
                    );
                    checked += 1;
                }
            }
        }
        assert_eq!(checked, 16);
    }

    #[test]
    fn ending_and_starting_at_a_point_keep_the_direction_of_travel() {
        let arc = Prim::Arc {
            c: (0.0, 0.0),
            r: 1.0,
            a0: 0.0,
            sweep: 1.0,
        };
        let p = (0.9_f64.cos(), 0.9_f64.sin());
        let Some(Prim::Arc { sweep, .. }) = arc.ending_at(p) else {
            panic!()
        };
        assert!((sweep - 0.9).abs() < 1e-12);
        let Some(Prim::Arc { a0, sweep, .. }) = arc.starting_at(p) else {
            panic!()
        };
        assert!((a0 - 0.9).abs() < 1e-12 && (sweep - 0.1).abs() < 1e-12);
        // Past the start of a line, or behind an arc's start, turns the move round: refused.
        let line = Prim::Line {
            a: (0.0, 0.0),
            b: (1.0, 0.0),
        };
        assert!(line.ending_at((-0.5, 0.0)).is_none());
        assert!(arc.starting_at((1.5_f64.cos(), 1.5_f64.sin())).is_none());
        assert!((wrapped(3.0 * std::f64::consts::PI) - std::f64::consts::PI).abs() < 1e-12);
    }
}
