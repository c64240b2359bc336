//! Orbiting (`[sinker.orbit]`, or a condition's `orbit_shape`/`orbit_radius_mm`): a sinking
//! move becomes an orbital path, as a die-sinker's planetary motion finishes the walls.
//!
//! A **sinking move** is a feed move (`G1`) straight down the tool axis (Z), every other axis
//! still. With an orbit in force for its condition, the electrode sinks with its offset from
//! the programmed axis turning around it: at progress `s` (0 at the top, 1 at the bottom)
//! the angle is `2π·N·s` and the radius `R·s` (`expand = true`: from nothing at the start to
//! the condition's undersize at the bottom) or `R` (held: a radial move out to it first).
//! `N`, whole turns, is what the orbit feed makes of the move: the time the sinking feed
//! takes over the depth, at `feed_mm_per_min` around the final circle. The shapes, for an
//! offset of radius `r` at angle `θ`:
//!
//! - `circle`: `r·(cos θ, sin θ)`;
//! - `square`: the square of half-side `r`, `r·(cos θ, sin θ)/max(|cos θ|, |sin θ|)`;
//! - `vector-x`, `vector-y`: back and forth along the axis, `r·tri(θ)` (a triangle wave:
//!   r, 0, −r, 0, r at the quarter turns, so a move ends at a full stroke);
//! - `sphere`: as `circle`, with the tool axis raised by `R − √(R² − r²)`, so the electrode's
//!   offset stays on a sphere of radius `R` and a rounded floor is finished.
//!
//! The path is a polyline through points of the exact orbit, halved until the middle and the
//! quarters of every chord lie within a quarter of the tolerance of the orbit (the step
//! lattice adds up to half a step on each axis across the path), with vertices at the
//! shape's corners; it ends at the bottom with a radial move back onto the programmed axis,
//! so the next move starts where the program says. The turn-back, the checkpoints and the
//! reports then treat it as any path.

use std::collections::VecDeque;

use super::taper::TaperError;
use super::{Stage, StageError};
use crate::gcode::{Block, GcodeErrorKind, OrbitOptions, OrbitStage};
use crate::geometry::{NurbsCurve, Point};
use crate::vocab::Axis;
use crate::vocab::OrbitShape;

/// Most whole turns of one sinking move (a bound on its polyline's size); more is refused at
/// the move's line.
const MAX_TURNS: f64 = 10_000.0;

#[derive(Debug)]
pub struct Orbiting {
    options: OrbitOptions,
    /// X, Y and Z's indices; `None`: the machine has no tool axis to orbit about.
    axes: Option<[usize; 3]>,
    tolerance: f64,
}

impl Stage for Orbiting {
    fn push(&mut self, block: Block, out: &mut VecDeque<Block>) -> Result<(), StageError> {
        self.orbit(block, out)
            .map_err(|e| e.at_move(GcodeErrorKind::Orbit))
    }

    /// Not a sinking move with an orbit in force: as `orbit` finds.
    fn passes(&self, block: &Block) -> bool {
        let Some([_, _, iz]) = self.axes else {
            return true;
        };
        let orbit = self.options.for_condition(block.condition);
        orbit.shape == OrbitShape::None || orbit.radius_mm <= 0.0 || !block.sinks(iz)
    }
}

impl Orbiting {
    pub fn new(axes: &[Axis], options: OrbitOptions, tolerance: f64) -> Orbiting {
        let index = |a: Axis| axes.iter().position(|&x| x == a);
        let axes = (|| Some([index(Axis::X)?, index(Axis::Y)?, index(Axis::Z)?]))();
        Orbiting {
            options,
            axes,
            tolerance,
        }
    }

    /// `block`, or its orbital path when it is a sinking move with an orbit in force.
    fn orbit(&self, block: Block, out: &mut VecDeque<Block>) -> Result<(), TaperError> {
        let Some(axes) = self.axes else {
            out.push_back(block);
            return Ok(());
        };
        let orbit = self.options.for_condition(block.condition);
        let (p0, p1) = (block.start(), block.end());
        let [ix, iy, iz] = axes;
        if orbit.shape == OrbitShape::None || orbit.radius_mm <= 0.0 || !block.sinks(iz) {
            out.push_back(block);
            return Ok(());
        }
        let fail = |message: String| TaperError {
            line: block.line,
            message,
        };
        let depth = p0[iz] - p1[iz];
        let r = orbit.radius_mm;
        // Whole turns: the sinking feed's time over the depth, around the final circle at
        // the orbit feed.
        let sink_feed = block
            .feed_mm_per_min
            .unwrap_or(self.options.feed_mm_per_min);
        let turns = (depth / sink_feed * self.options.feed_mm_per_min
            / (2.0 * std::f64::consts::PI * r))
            .ceil()
            .max(1.0);
        if turns.is_nan() || turns > MAX_TURNS {
            return Err(fail(format!(
                "the orbit would make {turns:.0} turns on this {depth:.4} mm sinking move (at \
                 most {MAX_TURNS:.0}: the path is held whole): sink it in shorter moves, or \
                 raise its feed against sinker.orbit.feed_mm_per_min"
            )));
        }
        let expand = self.options.expand;
        let offset = |s: f64| -> [f64; 3] {
            let radius = if expand { r * s } else { r };
            orbit_offset(
                orbit.shape,
                radius,
                r,
                2.0 * std::f64::consts::PI * turns * s,
            )
        };
        let at = |s: f64| -> Point {
            let o = offset(s);
            let mut p = p0;
            p[ix] += o[0];
            p[iy] += o[1];
            p[iz] = p0[iz] - depth * s + o[2];
            p
        };
        // The shape's corners (square corners, vector reversals) are vertices.
        let per_turn: &[f64] = match orbit.shape {
            OrbitShape::Square => &[0.125, 0.375, 0.625, 0.875],
            OrbitShape::VectorX | OrbitShape::VectorY => &[0.5],
            _ => &[0.25, 0.5, 0.75],
        };
        let mut breaks = vec![0.0];
        for k in 0..turns as u64 {
            for f in per_turn {
                breaks.push((k as f64 + f) / turns);
            }
            breaks.push((k + 1) as f64 / turns);
        }
        let mut points = Vec::new();
        if !expand {
            // Out from the axis to the radius first.
            points.push(p0);
        }
        points.push(at(0.0));
        for w in breaks.windows(2) {
            self.refine(&at, w[0], w[1], &mut points, 0);
        }
        // Back onto the programmed axis at the bottom.
        points.push(p1);
        points.dedup_by(|a, b| (*a - *b).norm() < 1e-12);
        let n = points.len();
        let mut knots = vec![0.0, 0.0];
        knots.extend((1..n - 1).map(|i| i as f64));
        knots.extend([(n - 1) as f64, (n - 1) as f64]);
        let curve = NurbsCurve::new(1, block.curve.dim(), &points, &vec![1.0; n], knots)
            .map_err(|e| fail(format!("the orbital path: {e}")))?;
        out.push_back(Block {
            curve,
            orbit: Some(OrbitStage {
                shape: orbit.shape,
                radius_mm: r,
                from_z: p0[iz],
                to_z: p1[iz],
                turns: turns as u32,
            }),
            ..block
        });
        Ok(())
    }

    /// Appends the points after `at(from)` up to `at(to)`, halving until the middle and the
    /// quarters of each chord lie within the tolerance of the orbit.
    fn refine(
        &self,
        at: &impl Fn(f64) -> Point,
        from: f64,
        to: f64,
        points: &mut Vec<Point>,
        depth: u32,
    ) {
        let (a, b) = (at(from), at(to));
        let fine = [0.25, 0.5, 0.75].iter().all(|k| {
            let m = at(from + k * (to - from));
            let ab = b - a;
            let along = (m - a).dot(&ab) / ab.norm_squared().max(f64::MIN_POSITIVE);
            // A quarter of the tolerance: the step lattice adds up to √½ step across the path.
            (m - (a + ab * along.clamp(0.0, 1.0))).norm() <= self.tolerance / 4.0
        });
        if fine || depth >= 30 {
            points.push(b);
        } else {
            let mid = 0.5 * (from + to);
            self.refine(at, from, mid, points, depth + 1);
            self.refine(at, mid, to, points, depth + 1);
        }
    }
}

/// The orbit's offset (x, y, tool axis) at radius `r` (of the full `full`) and angle `theta`.
fn orbit_offset(shape: OrbitShape, r: f64, full: f64, theta: f64) -> [f64; 3] {
    let (s, c) = theta.sin_cos();
    // The triangle wave 1, 0, −1, 0, 1 over a turn (a cosine's corners: every move ends,
    // and a held one starts, at a full stroke).
    let tri = || {
        let q = (theta / (2.0 * std::f64::consts::PI)).rem_euclid(1.0) * 4.0;
        match q {
            q if q < 2.0 => 1.0 - q,
            q => q - 3.0,
        }
    };
    match shape {
        OrbitShape::None => [0.0; 3],
        OrbitShape::Circle => [r * c, r * s, 0.0],
        OrbitShape::Square => {
            let k = r / c.abs().max(s.abs());
            [k * c, k * s, 0.0]
        }
        OrbitShape::VectorX => [r * tri(), 0.0, 0.0],
        OrbitShape::VectorY => [0.0, r * tri(), 0.0],
        OrbitShape::Sphere => [r * c, r * s, full - (full * full - r * r).max(0.0).sqrt()],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gcode::{BlockReader, ProgramOptions};
    use std::io::Cursor;

    fn read(text: &str, orbit: OrbitOptions) -> Vec<Block> {
        let axes = [Axis::X, Axis::Y, Axis::Z];
        let options = ProgramOptions {
            orbit,
            ..ProgramOptions::default()
        };
        crate::path::Pipeline::new(BlockReader::with_options(
            Cursor::new(text.to_string()),
            "t.ngc",
            &axes,
            options,
        ))
        .collect::<Result<Vec<_>, _>>()
        .unwrap()
    }

    fn circle(expand: bool) -> OrbitOptions {
        OrbitOptions {
            default: crate::gcode::Orbit {
                shape: OrbitShape::Circle,
                radius_mm: 0.2,
            },
            feed_mm_per_min: 60.0,
            expand,
            by_condition: Vec::new(),
        }
    }

    #[test]
    fn a_sinking_move_becomes_an_expanding_orbit_back_on_its_axis() {
        let blocks = read(
            "G21 G90\nG1 X5 Y5 F100\nG1 Z-2 F10\nG1 Z0\nM2\n",
            circle(true),
        );
        assert_eq!(blocks.len(), 3);
        assert!(
            blocks[0].orbit.is_none() && blocks[2].orbit.is_none(),
            "not sinking"
        );
        let orbit = &blocks[1];
        let stage = orbit.orbit.unwrap();
        // 2 mm at 10 mm/min: 12 s; at 60 mm/min around a 0.2 mm circle: 9.55 turns -> 10.
        assert_eq!(stage.turns, 10);
        assert_eq!((stage.from_z, stage.to_z), (0.0, -2.0));
        let c = &orbit.curve;
        assert_eq!(orbit.start(), blocks[0].end());
        assert_eq!(
            orbit.end().iter().take(3).copied().collect::<Vec<_>>(),
            [5.0, 5.0, -2.0]
        );
        // Every vertex (the last, back on the axis, aside) on the ideal orbit: radius
        // 0.2·depth/2 about (5, 5).
        for i in 0..c.num_points() - 1 {
            let p = c.control_point(i);
            let s = -p[2] / 2.0;
            let r = (p[0] - 5.0).hypot(p[1] - 5.0);
            assert!((r - 0.2 * s).abs() < 1e-12, "vertex {i}: r {r} at s {s}");
        }
    }

    #[test]
    fn each_shape_follows_its_definition() {
        let full = 1.0;
        let quarter = std::f64::consts::FRAC_PI_2;
        let at = |shape, k: f64| orbit_offset(shape, full, full, k * quarter);
        let corner = at(OrbitShape::Square, 0.5);
        assert!((corner[0] - 1.0).abs() < 1e-12 && (corner[1] - 1.0).abs() < 1e-12);
        // Halfway along a side: on the side.
        let side = orbit_offset(OrbitShape::Square, full, full, 0.3);
        assert!((side[0] - 1.0).abs() < 1e-12 && (side[1] - 0.3f64.tan()).abs() < 1e-12);
        let v = at(OrbitShape::VectorX, 2.0);
        assert!((v[0] + 1.0).abs() < 1e-12 && v[1] == 0.0);
        let v = at(OrbitShape::VectorY, 3.0);
        assert!(v[1].abs() < 1e-12 && v[0] == 0.0);
        let v = at(OrbitShape::VectorY, 4.0);
        assert!((v[1] - 1.0).abs() < 1e-12);
        // The sphere: at half the radius, raised by R − √(R² − r²).
        let p = orbit_offset(OrbitShape::Sphere, 0.5, 1.0, 0.0);
        assert!((p[2] - (1.0 - 0.75f64.sqrt())).abs() < 1e-12);
    }

    #[test]
    fn an_orbit_of_too_many_turns_is_refused_at_its_line() {
        let axes = [Axis::X, Axis::Y, Axis::Z];
        let options = ProgramOptions {
            orbit: circle(true),
            ..ProgramOptions::default()
        };
        // 50 mm at 0.01 mm/min: 5000 min around a 0.2 mm circle at 60 mm/min.
        let text = "G21 G90\nG1 Z-50 F0.01\nM2\n";
        let err = crate::path::Pipeline::new(BlockReader::with_options(
            Cursor::new(text.to_string()),
            "t.ngc",
            &axes,
            options,
        ))
        .collect::<Result<Vec<_>, _>>()
        .unwrap_err();
        assert!(
            matches!(&err, crate::path::PathError::Program(e) if e.line == 2),
            "{err}"
        );
        assert!(
            err.to_string()
                .contains("turns on this 50.0000 mm sinking move"),
            "{err}"
        );
    }

    #[test]
    fn a_held_orbit_moves_out_first_and_other_moves_are_left_alone() {
        let blocks = read(
            "G21 G90\nG1 Z-1 F10\nG1 X1 Z-2\nG0 Z-3\nM2\n",
            circle(false),
        );
        let first = blocks[0].curve.control_point(1);
        assert!(
            (first[0] - 0.2).abs() < 1e-12 && first[2] == 0.0,
            "{first:?}"
        );
        assert!(blocks[1].orbit.is_none(), "not straight down the axis");
        assert!(blocks[2].orbit.is_none(), "a rapid");
    }
}
