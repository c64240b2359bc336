//! How the machine gets to where a cut starts, spark off: along the programmed path, direct
//! over the safe height, or back along a kerf from where the wire stands. The moves are made
//! here; which one a run takes is the gate's ([`super::from_line`]) and the tab planner's
//! ([`super::tabs`]).

use crate::gcode::{Block, BlockKind, Travel};
use crate::geometry::{NurbsCurve, Point};
use crate::vocab::Axis;

/// How far (mm) where the wire stands may lie from a block and still be on it: the executed
/// path is the lattice's, within a step and the chord tolerance of the programmed curve,
/// while passes lie tens of micrometres apart and a kerf is a few hundred wide.
pub const ON_PATH_MM: f64 = 0.01;

/// The parameter of `curve` at the point `at`, if `at` lies on it within [`ON_PATH_MM`].
/// The curve lies in its control points' hull (the box is cheap and rules most blocks out);
/// samples find the nearest stretch, a golden-section search the point in it.
pub fn locate(curve: &NurbsCurve, at: &Point) -> Option<f64> {
    let n = curve.num_points();
    let outside = (0..curve.dim()).any(|i| {
        let (lo, hi) = (0..n)
            .map(|k| curve.control_point(k)[i])
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), c| {
                (lo.min(c), hi.max(c))
            });
        at[i] < lo - ON_PATH_MM || at[i] > hi + ON_PATH_MM
    });
    if outside {
        return None;
    }
    let (a, b) = (curve.u_min(), curve.u_max());
    let distance = |u: f64| (curve.point(u) - at).norm();
    let samples = 32 * n;
    let u_of = |k: usize| a + (b - a) * k as f64 / samples as f64;
    let nearest = (0..=samples)
        .min_by(|&i, &j| distance(u_of(i)).total_cmp(&distance(u_of(j))))
        .expect("samples");
    let (mut lo, mut hi) = (
        u_of(nearest.saturating_sub(1)),
        u_of((nearest + 1).min(samples)),
    );
    const PHI: f64 = 0.618_033_988_749_895;
    for _ in 0..60 {
        let (m1, m2) = (hi - PHI * (hi - lo), lo + PHI * (hi - lo));
        if distance(m1) < distance(m2) {
            hi = m2;
        } else {
            lo = m1;
        }
    }
    let u = 0.5 * (lo + hi);
    (distance(u) <= ON_PATH_MM).then_some(u)
}

/// The way back along `held` (the cut's blocks from the line's start, the wire on the last
/// at parameter `u`): the last up to `u`, then the others, each reversed, last first, as the
/// path approach moves them.
pub(super) fn retrace(held: &[Block], u: f64, feed_mm_per_min: f64) -> Vec<Block> {
    let Some((last, before)) = held.split_last() else {
        return Vec::new();
    };
    let mm = last.curve.length_between(last.curve.u_min(), u);
    // Within the tolerance of either end the wire stands at that end.
    let cut_of_last = if mm <= ON_PATH_MM {
        None
    } else if last.curve.length() - mm <= ON_PATH_MM {
        Some(last.clone())
    } else {
        last.split_at_length(mm).map(|(cut, _)| cut)
    };
    cut_of_last
        .iter()
        .chain(before.iter().rev())
        .map(|b| {
            let mut back = b.reversed();
            if matches!(back.kind, BlockKind::Probe(_)) {
                back.kind = BlockKind::Line;
            }
            path_approach(back, feed_mm_per_min)
        })
        .collect()
}

/// A block before the line as the path approach moves it: the same geometry, spark off, at
/// most `feed_mm_per_min` (a rapid too: the wire is in the work).
pub fn path_approach(mut block: Block, feed_mm_per_min: f64) -> Block {
    if block.kind == BlockKind::Rapid {
        block.kind = BlockKind::Line;
    }
    block.feed_mm_per_min = Some(
        block
            .feed_mm_per_min
            .map_or(feed_mm_per_min, |f| f.min(feed_mm_per_min)),
    );
    block.spark_off = Some(Travel::Kerf);
    block.pause = None;
    block.dwell_s = 0.0;
    block
}

/// The direct approach from `origin` to the start of `first` (machine mm): up to `safe_z`
/// (if the machine has Z and it is set, and Z stands below it) and across as rapids, then
/// down to the start at `feed_mm_per_min`; without a safe height, one straight move at that
/// feed. Every move has the spark off and carries `first`'s line and condition.
pub(super) fn direct_approach(
    origin: &Point,
    first: &Block,
    axes: &[Axis],
    safe_z: Option<f64>,
    feed_mm_per_min: f64,
) -> Vec<Block> {
    let target = first.start();
    let dim = axes.len();
    let z = axes.iter().position(|&a| a == Axis::Z);
    let mut corners = vec![*origin];
    let mut rapid_legs = 0;
    if let (Some(z), Some(safe)) = (z, safe_z) {
        let high = origin[z].max(safe).max(target[z]);
        let mut up = *origin;
        up[z] = high;
        let mut across = target;
        across[z] = high;
        corners.push(up);
        corners.push(across);
        rapid_legs = 2;
    }
    corners.push(target);
    let mut moves = Vec::new();
    for (leg, pair) in corners.windows(2).enumerate() {
        let (a, b) = (pair[0], pair[1]);
        if (0..dim).all(|i| (a[i] - b[i]).abs() < 1e-9) {
            continue;
        }
        let Ok(curve) = NurbsCurve::line(dim, &a, &b) else {
            continue;
        };
        let (kind, feed) = if leg < rapid_legs {
            (BlockKind::Rapid, None)
        } else {
            (BlockKind::Line, Some(feed_mm_per_min))
        };
        let mut block = Block::new(first.line, kind, curve, feed);
        block.spark_off = Some(Travel::Open);
        block.condition = first.condition;
        moves.push(block);
    }
    moves
}
