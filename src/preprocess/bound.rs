//! The time-optimal bound: the shortest time any planner could take along the path under the
//! same limits, by a dense forward/backward pass. A reference for `edmd plan`, not part of the
//! producer (it holds the whole path in memory).
//!
//! The path is sampled every ~`spacing` mm. At each sample the speed limit is the pointwise
//! minimum of the programmed feed, `sqrt(a_N rho)` and, in period mode, the chord-error speed
//! `2 sqrt(2 rho h - h²) / T`; corners between blocks get the planner's junction speed. The
//! forward pass caps `v²` growth at `2 a_T Δs`, the backward pass caps its fall the same way, the
//! path starts and ends at rest, and the time is `Σ 2 Δs / (v_k + v_k+1)` (exact for constant
//! acceleration between samples). With the samples dense enough this converges to the optimum
//! from below the planner's discretisation: a planner cannot beat it.

use super::chord::chord_length_limit;
use super::segmenter::unit;
use super::{PlanSettings, corner_speed};
use crate::gcode::Block;
use crate::geometry::Point;
use crate::vocab::Segmentation;

/// Time-optimal traversal time (s) of `blocks` in order, sampled about every `spacing` mm.
pub fn time_optimal_bound(blocks: &[&Block], settings: &PlanSettings, spacing: f64) -> f64 {
    let mut ds: Vec<f64> = vec![];
    let mut limit: Vec<f64> = vec![0.0];
    let mut prev_tangent: Option<Point> = None;
    for block in blocks {
        let curve = &block.curve;
        let feed = if block.kind == crate::gcode::BlockKind::Rapid {
            settings.rapid_feed
        } else {
            block
                .feed_mm_per_min
                .map_or(settings.max_feed, |f| (f / 60.0).min(settings.max_feed))
        };
        let n = (curve.length() / spacing).ceil().clamp(16.0, 4.0e6) as usize;
        let (u0, u1) = (curve.u_min(), curve.u_max());
        let first = curve.derivs(u0);
        if let Some(prev) = prev_tangent {
            let corner = corner_speed(&prev, &unit(&first.d1), settings);
            let last = limit.len() - 1;
            limit[last] = limit[last].min(corner);
        }
        let mut p = first.point;
        for k in 1..=n {
            let u = u0 + (u1 - u0) * k as f64 / n as f64;
            let d = if k == n {
                curve.derivs_from_left(u1)
            } else {
                curve.derivs(u)
            };
            let rho = d.curvature_radius();
            let mut v = feed.min((settings.max_normal_accel * rho).sqrt());
            if settings.segmentation == Segmentation::Period {
                v = v.min(chord_length_limit(rho, settings.tolerance) / settings.period);
            }
            let step = d.point - p;
            let length = step.norm();
            // The outputs' one step per tick, as the planner honours it.
            v = v.min(super::step_cap(&settings.axis_cap, &step, length));
            ds.push(length);
            limit.push(v);
            p = d.point;
            if k == n {
                prev_tangent = Some(unit(&d.d1));
            }
        }
    }
    let last = limit.len() - 1;
    limit[last] = 0.0;
    let a2 = 2.0 * settings.max_tangential_accel;
    let mut v = limit.clone();
    for k in 1..v.len() {
        v[k] = v[k].min((v[k - 1] * v[k - 1] + a2 * ds[k - 1]).sqrt());
    }
    for k in (0..v.len() - 1).rev() {
        v[k] = v[k].min((v[k + 1] * v[k + 1] + a2 * ds[k]).sqrt());
    }
    ds.iter()
        .enumerate()
        .map(|(k, &d)| {
            let sum = v[k] + v[k + 1];
            if d > 0.0 { 2.0 * d / sum } else { 0.0 }
        })
        .sum()
}
