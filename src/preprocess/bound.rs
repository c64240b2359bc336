//! The time-optimal bound: the shortest time any planner could take along the path under the
//! same limits, by a forward/backward pass over samples of the path. A reference for
//! `edmd plan`, not part of the producer.
//!
//! **Samples.** At each sample the speed limit is the pointwise minimum of the programmed feed,
//! `sqrt(a_N rho)`, the outputs' one step per tick along the tangent and, in period mode, the
//! chord-error speed `2 sqrt(2 rho h - h²) / T`; a junction between blocks also gets the
//! planner's corner speed and both blocks' limits. Between two samples of a block the speed may
//! reach the larger of their limits. A straight block's limits are the same all along it, so it
//! is one interval, exactly; a curved one is sampled at most [`MAX_TURN`] of tangent apart and
//! at most `spacing` mm apart (16 samples at least), which resolves the step cap's change with
//! direction and the curvature's along the curve. An interval's length is its chord lengthened
//! by the turn between its tangents (`θ²/24`, exact to fourth order on a circle).
//!
//! **Profile.** The forward pass caps `v²` growth at `2 a_T Δs`, the backward pass caps its fall
//! the same way, the path starts and ends at rest. Over each interval the fastest profile
//! under its cap is then exact: accelerate from one end, cruise at the cap or meet the
//! deceleration to the other end ([`interval_time`]). A planner cannot beat it by more than the
//! sampling misses of a limit's dips.
//!
//! **Streamed, in bounded memory.** The forward pass needs only the past, so it runs as the
//! samples come. The backward pass needs the future, but not much of it: no sample can be
//! slowed by a stop more than `v_max² / (2 a_T)` ahead, since from there even a stop allows
//! `v_max`, above every limit. [`TimeOptimalBound`] therefore keeps only the samples of the
//! last [`horizon`](TimeOptimalBound::horizon) mm (twice that distance, so rounding cannot
//! matter), runs the backward pass over them from the newest (whose speed is provisional: an
//! upper bound of its true one), and settles the samples farther back than the horizon: their
//! backward values are the whole path's. The memory is a few thousand samples whatever the
//! program's length, and the figure is, bit for bit, the one the whole path in memory gives
//! (a test holds it).

use std::collections::VecDeque;

use super::chord::chord_length_limit;
use super::segmenter::unit;
use super::{PlanSettings, corner_speed, step_cap};
use crate::gcode::{Block, BlockKind};
use crate::geometry::{CurveDerivs, NurbsCurve, Point, lanes, running_max, running_min};
use crate::vocab::{MAX_AXES, Segmentation};

/// Longest interval between two samples of a curved block (mm), as `plan` samples.
pub const MAX_SPACING_MM: f64 = 0.25;

/// Largest turn of the tangent between two samples of a curved block (rad): 5°.
pub const MAX_TURN: f64 = 5.0 * std::f64::consts::PI / 180.0;

/// One sample of the path.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Sample {
    /// Path length from the sample before (mm; zero for the first).
    ds: f64,
    /// The speed limit here (mm/s); after the forward pass, its value.
    v: f64,
    /// The speed the interval from the sample before may reach (mm/s).
    cap: f64,
}

/// What sampling a block gives the profile.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Step {
    /// A cap on the newest sample: the junction with the next block.
    Junction(f64),
    Sample(Sample),
}

/// Turns blocks into samples.
#[derive(Debug)]
struct Sampler {
    settings: PlanSettings,
    spacing: f64,
    /// The tangent the last block ended on, once there is one.
    prev_tangent: Option<Point>,
}

impl Sampler {
    fn block(&mut self, block: &Block, step: impl FnMut(Step)) {
        // Three coordinates for up to three axes, all of a `Point` beyond: the same numbers
        // ([`lanes`]), for half the arithmetic on a sample.
        if block.curve.dim() <= 3 {
            self.block_on::<3>(block, step);
        } else {
            self.block_on::<MAX_AXES>(block, step);
        }
    }

    fn block_on<const N: usize>(&mut self, block: &Block, mut step: impl FnMut(Step)) {
        let s = &self.settings;
        let curve = &block.curve;
        let feed = if block.kind == BlockKind::Rapid {
            s.rapid_feed_mm_per_s
        } else {
            block
                .feed_mm_per_min
                .map_or(s.max_feed_mm_per_s, |f| (f / 60.0).min(s.max_feed_mm_per_s))
        };
        let n = if curve.degree() == 1 && curve.num_points() == 2 {
            1
        } else {
            let by_length = (curve.length() / self.spacing).ceil();
            let by_turn = (polygon_turn(curve) / MAX_TURN).ceil();
            by_length.max(by_turn).clamp(16.0, 4.0e6) as usize
        };
        let (u0, u1) = (curve.u_min(), curve.u_max());
        let first = curve.derivs(u0);
        let mut limit = self.limit::<N>(feed, &first);
        let mut tangent = lanes::unit::<N>(&first.d1);
        match self.prev_tangent {
            Some(prev) => step(Step::Junction(limit.min(corner_speed(&prev, &tangent, s)))),
            // The path starts at rest.
            None => step(Step::Sample(Sample {
                ds: 0.0,
                v: 0.0,
                cap: 0.0,
            })),
        }
        let mut p = first.point;
        for k in 1..=n {
            let u = u0 + (u1 - u0) * k as f64 / n as f64;
            let d = if k == n {
                curve.derivs_from_left(u1)
            } else {
                curve.derivs_inlined(u)
            };
            let here = self.limit::<N>(feed, &d);
            let next_tangent = lanes::unit::<N>(&d.d1);
            // The arc over its chord: 1 + θ²/24 for a turn of θ between the tangents.
            let gap = lanes::norm::<N>(&lanes::sub::<N>(&next_tangent, &tangent));
            let turn = 2.0 * (gap / 2.0).min(1.0).asin();
            step(Step::Sample(Sample {
                ds: lanes::norm::<N>(&lanes::sub::<N>(&d.point, &p)) * (1.0 + turn * turn / 24.0),
                v: here,
                cap: running_max(limit, here),
            }));
            (p, limit, tangent) = (d.point, here, next_tangent);
        }
        self.prev_tangent = Some(tangent);
    }

    /// The speed limit at a point of a block programmed at `feed` (mm/s).
    #[inline]
    fn limit<const N: usize>(&self, feed: f64, d: &CurveDerivs) -> f64 {
        let s = &self.settings;
        let rho = lanes::curvature_radius::<N>(d);
        // Running minima from the feed, a number: `f64::min`'s results, in fewer
        // instructions, on every sample.
        let mut v = running_min(feed, (s.max_normal_accel_mm_per_s2 * rho).sqrt());
        if s.segmentation == Segmentation::Period {
            v = running_min(v, chord_length_limit(rho, s.tolerance_mm) / s.period_s);
        }
        // The outputs' one step per tick, as the planner honours it.
        running_min(
            v,
            step_cap::<N>(&s.axis_cap_mm_per_s, &d.d1, lanes::norm::<N>(&d.d1)),
        )
    }
}

/// The turn of `curve`'s control polygon (rad): the sum of the angles between its edges,
/// which bounds the turn of the curve's tangent.
fn polygon_turn(curve: &NurbsCurve) -> f64 {
    let mut turn = 0.0;
    let mut prev: Option<Point> = None;
    for i in 1..curve.num_points() {
        let edge = curve.control_point(i) - curve.control_point(i - 1);
        if edge.norm() == 0.0 {
            continue;
        }
        let edge = unit(&edge);
        if let Some(before) = prev {
            turn += 2.0 * ((edge - before).norm() / 2.0).min(1.0).asin();
        }
        prev = Some(edge);
    }
    turn
}

/// The least time (s) over an interval of `ds` mm entered at `a` and left at `b` (mm/s),
/// at most `cap` inside, at most `accel` (mm/s²) of acceleration either way: up from `a`, on
/// at the peak, down to `b`. `a` and `b` are at most `cap` and within reach of each other.
fn interval_time(a: f64, b: f64, cap: f64, ds: f64, accel: f64) -> f64 {
    if ds <= 0.0 {
        return 0.0;
    }
    let peak_sq = running_min(cap * cap, (a * a + b * b + 2.0 * accel * ds) / 2.0);
    let peak = peak_sq.sqrt();
    let ramps = (peak_sq - a * a + peak_sq - b * b) / (2.0 * accel);
    let cruise = (ds - ramps).max(0.0);
    (peak - a) / accel + (peak - b) / accel + cruise / peak
}

/// The time-optimal bound over a path given block by block, in bounded memory.
#[derive(Debug)]
pub struct TimeOptimalBound {
    sampler: Sampler,
    profile: Profile,
}

/// The speed profile over the samples: the passes, and the time of what is settled.
#[derive(Debug)]
struct Profile {
    accel: f64,
    /// How far back from the newest sample a sample is settled (mm): twice the longest stop.
    horizon: f64,
    /// Samples not yet settled, oldest first, and their path length after the oldest.
    open: VecDeque<Sample>,
    open_length: f64,
    /// The backward pass's values over `open`, reused.
    backward: Vec<f64>,
    /// The speed of the last settled sample.
    settled: Option<f64>,
    time: f64,
    /// The most samples held at once.
    peak_open: usize,
}

impl TimeOptimalBound {
    /// A bound sampling curved blocks at most `spacing` mm apart.
    pub fn new(settings: &PlanSettings, spacing: f64) -> TimeOptimalBound {
        let accel = settings.max_tangential_accel_mm_per_s2;
        let v_max = settings.max_feed_mm_per_s.max(settings.rapid_feed_mm_per_s);
        TimeOptimalBound {
            sampler: Sampler {
                settings: settings.clone(),
                spacing,
                prev_tangent: None,
            },
            profile: Profile {
                accel,
                horizon: v_max * v_max / accel,
                open: VecDeque::new(),
                open_length: 0.0,
                backward: Vec::new(),
                settled: None,
                time: 0.0,
                peak_open: 0,
            },
        }
    }

    /// The distance behind the newest sample beyond which samples are settled (mm).
    pub fn horizon(&self) -> f64 {
        self.profile.horizon
    }

    /// The most samples held at once so far.
    #[cfg(test)]
    fn peak_samples(&self) -> usize {
        self.profile.peak_open
    }

    /// Samples `block`, the next along the path.
    pub fn push_block(&mut self, block: &Block) {
        let profile = &mut self.profile;
        self.sampler.block(block, |step| profile.step(step));
    }

    /// The bound (s), the path ending at rest; `None` for a path of no blocks.
    pub fn finish(mut self) -> Option<f64> {
        let last = self.profile.open.back_mut()?;
        last.v = 0.0;
        self.profile.settle(true);
        Some(self.profile.time)
    }
}

impl Profile {
    fn step(&mut self, step: Step) {
        match step {
            // The newest sample is never settled before the end: it is open.
            Step::Junction(limit) => {
                if let Some(last) = self.open.back_mut() {
                    last.v = last.v.min(limit);
                }
            }
            Step::Sample(sample) => self.push_sample(sample),
        }
    }

    /// The forward pass over a new sample.
    fn push_sample(&mut self, mut sample: Sample) {
        if let Some(prev) = self.open.back() {
            let reach = (prev.v * prev.v + 2.0 * self.accel * sample.ds).sqrt();
            sample.v = running_min(sample.v, reach);
            self.open_length += sample.ds;
        }
        self.open.push_back(sample);
        self.peak_open = self.peak_open.max(self.open.len());
        if self.open_length > 2.0 * self.horizon {
            self.settle(false);
        }
    }

    /// The backward pass over the open samples from the newest; settles those at least a
    /// horizon behind it (all of them at the path's end), adding their time.
    fn settle(&mut self, all: bool) {
        let len = self.open.len();
        let (front, back) = self.open.as_slices();
        backward_pass([front, back], self.accel, &mut self.backward);
        // Settle while the next sample is a horizon or more behind the newest; the newest
        // stays open before the end, for the junction the next block may put on it.
        let mut behind = self.open_length;
        let mut count = 0;
        while count < len && (all || (count + 1 < len && behind >= self.horizon)) {
            if count + 1 < len {
                behind -= self.open[count + 1].ds;
            }
            count += 1;
        }
        for &v in &self.backward[..count] {
            let sample = self.open.pop_front().expect("counted among the open");
            if let Some(prev) = self.settled {
                self.time += interval_time(prev, v, sample.cap, sample.ds, self.accel);
            }
            self.settled = Some(v);
        }
        self.open_length = self.open.iter().skip(1).map(|s| s.ds).sum();
    }
}

/// The backward pass over the samples from the last: each speed capped by what a stop at the
/// next allows, into `out`. The samples come in path order in two runs (a ring buffer's two
/// slices), walked as slices: through the ring's own iterator the walk cost twice as much.
fn backward_pass(runs: [&[Sample]; 2], accel: f64, out: &mut Vec<f64>) {
    let [front, back] = runs;
    let len = front.len() + back.len();
    // Every slot is written below: only the slots past the vector's present length are
    // zeroed first, not the whole of it on every settle.
    out.truncate(len);
    out.resize(len, 0.0);
    let (out_front, out_back) = out.split_at_mut(front.len());
    // What a stop after the last sample allows: an infinite speed, which caps nothing (the
    // running minimum of a speed and infinity is the speed), so the last keeps its own.
    let (mut v_next, mut ds_next) = (f64::INFINITY, 0.0);
    for (samples, out) in [(back, out_back), (front, out_front)] {
        for (slot, sample) in out.iter_mut().zip(samples).rev() {
            let v = running_min(sample.v, (v_next * v_next + 2.0 * accel * ds_next).sqrt());
            *slot = v;
            (v_next, ds_next) = (v, sample.ds);
        }
    }
}

/// Time-optimal traversal time (s) of `blocks` in order, curved blocks sampled at most
/// `spacing` mm apart (zero for no blocks).
pub fn time_optimal_bound(blocks: &[&Block], settings: &PlanSettings, spacing: f64) -> f64 {
    let mut bound = TimeOptimalBound::new(settings, spacing);
    for block in blocks {
        bound.push_block(block);
    }
    bound.finish().unwrap_or(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gcode::BlockReader;
    use crate::rng::SplitMix64;
    use crate::vocab::Axis;
    use std::io::Cursor;

    const SPACING: f64 = MAX_SPACING_MM;

    /// The default machine's limits (`config/edmd.toml`): 1 µm steps every 50 µs cap each
    /// axis at 20 mm/s. This module stands below `config`, so they are written out.
    fn settings() -> PlanSettings {
        let mut axis_cap = [f64::INFINITY; crate::vocab::MAX_AXES];
        axis_cap[0] = 20.0;
        axis_cap[1] = 20.0;
        PlanSettings {
            predictor: crate::vocab::Predictor::Taylor,
            segmentation: Segmentation::Chord,
            tolerance_mm: 0.001,
            max_segment_mm: 1.0,
            period_s: 0.001,
            max_feed_mm_per_s: 300.0,
            rapid_feed_mm_per_s: 20.0,
            max_normal_accel_mm_per_s2: 4900.0,
            max_tangential_accel_mm_per_s2: 2400.0,
            lookahead: 1024,
            fluctuation_tolerance: 1e-6,
            max_corrections: 8,
            corners: vec![],
            rapid_stops: false,
            axis_cap_mm_per_s: axis_cap,
        }
    }

    fn read(text: &str) -> Vec<Block> {
        BlockReader::new(Cursor::new(text.to_string()), "b.ngc", &[Axis::X, Axis::Y])
            .collect::<Result<Vec<_>, _>>()
            .unwrap()
    }

    /// The bound with the whole path in memory: every sample first, then the forward pass,
    /// the backward pass and the sum over all.
    fn whole_path(blocks: &[Block], settings: &PlanSettings, spacing: f64) -> (f64, usize) {
        let mut sampler = Sampler {
            settings: settings.clone(),
            spacing,
            prev_tangent: None,
        };
        let mut samples: Vec<Sample> = vec![];
        for block in blocks {
            sampler.block(block, |step| match step {
                Step::Junction(limit) => {
                    let last = samples.last_mut().unwrap();
                    last.v = last.v.min(limit);
                }
                Step::Sample(sample) => samples.push(sample),
            });
        }
        samples.last_mut().unwrap().v = 0.0;
        let accel = settings.max_tangential_accel_mm_per_s2;
        for k in 1..samples.len() {
            let reach = (samples[k - 1].v.powi(2) + 2.0 * accel * samples[k].ds).sqrt();
            samples[k].v = samples[k].v.min(reach);
        }
        // The backward pass written plainly, against which the streamed one (over a ring's
        // two slices, wrapping as samples settle) is held.
        let mut v = vec![0.0; samples.len()];
        let mut next: Option<(f64, f64)> = None;
        for k in (0..samples.len()).rev() {
            v[k] = match next {
                Some((v_next, ds_next)) => samples[k]
                    .v
                    .min((v_next * v_next + 2.0 * accel * ds_next).sqrt()),
                None => samples[k].v,
            };
            next = Some((v[k], samples[k].ds));
        }
        let time = (1..samples.len())
            .map(|k| interval_time(v[k - 1], v[k], samples[k].cap, samples[k].ds, accel))
            .sum();
        (time, samples.len())
    }

    /// A seeded program of lines, arcs, rapids and feed changes, some moves far longer than
    /// the horizon and some far shorter.
    fn program(seed: u64, moves: usize) -> String {
        let mut rng = SplitMix64::new(seed);
        let mut text = String::from("G21 G90 G17\nF300\n");
        let (mut x, mut y) = (0.0, 0.0);
        for i in 0..moves {
            let length = [0.02, 0.3, 2.0, 12.0][rng.below(4)];
            let angle = rng.uniform(0.0, std::f64::consts::TAU);
            let (nx, ny) = (x + length * angle.cos(), y + length * angle.sin());
            match rng.below(6) {
                0 => text += &format!("G0 X{nx:.4} Y{ny:.4}\n"),
                1 | 2 => {
                    // A half circle on the chord: centre at its middle.
                    let (i_, j_) = ((nx - x) / 2.0, (ny - y) / 2.0);
                    let g = if i % 2 == 0 { 2 } else { 3 };
                    text += &format!("G{g} X{nx:.4} Y{ny:.4} I{i_:.4} J{j_:.4}\n");
                    // The end the reader computes differs in the last digit at most.
                }
                3 => text += &format!("G1 X{nx:.4} Y{ny:.4} F{}\n", 60 + rng.below(1500)),
                _ => text += &format!("G1 X{nx:.4} Y{ny:.4}\n"),
            }
            (x, y) = ((nx * 1e4).round() / 1e4, (ny * 1e4).round() / 1e4);
        }
        text + "M2\n"
    }

    #[test]
    fn streamed_bound_is_the_whole_paths_bit_for_bit_in_bounded_memory() {
        let mut period = settings();
        period.segmentation = Segmentation::Period;
        let mut papers = settings();
        papers.axis_cap_mm_per_s = [f64::INFINITY; crate::vocab::MAX_AXES];
        for (seed, settings) in [(1, settings()), (2, period), (3, papers)] {
            let blocks = read(&program(seed, 300));
            let mut streamed = TimeOptimalBound::new(&settings, SPACING);
            for block in &blocks {
                streamed.push_block(block);
            }
            let peak = streamed.peak_samples();
            let horizon = streamed.horizon();
            let got = streamed.finish().unwrap();
            let (want, samples) = whole_path(&blocks, &settings, SPACING);
            assert_eq!(
                got.to_bits(),
                want.to_bits(),
                "seed {seed}: {got} against {want}"
            );
            // What is held is about two horizons of samples, not the path.
            assert!(
                peak < samples / 4,
                "seed {seed}: {peak} of {samples} samples held (horizon {horizon} mm)"
            );
        }
    }

    #[test]
    fn the_backward_pass_over_two_runs_is_the_plain_one_at_every_split() {
        // Fast samples close together ending near rest: the stop binds all the way back,
        // so a run walked in the wrong order or a lost carry between the runs shows.
        let mut rng = SplitMix64::new(7);
        let accel = 100.0;
        for len in [1, 2, 3, 17, 64] {
            let samples: Vec<Sample> = (0..len)
                .map(|k| Sample {
                    ds: rng.uniform(0.0, 0.01),
                    v: if k + 1 == len {
                        0.0
                    } else {
                        rng.uniform(30.0, 50.0)
                    },
                    cap: 50.0,
                })
                .collect();
            let mut want = vec![0.0; len];
            let mut next: Option<(f64, f64)> = None;
            for k in (0..len).rev() {
                want[k] = match next {
                    Some((v, ds)) => samples[k].v.min((v * v + 2.0 * accel * ds).sqrt()),
                    None => samples[k].v,
                };
                next = Some((want[k], samples[k].ds));
            }
            assert!(
                want[0] < samples[0].v || len < 3,
                "the stop binds back to the first"
            );
            let mut got = vec![1.0; 3];
            for split in 0..=len {
                let (front, back) = samples.split_at(split);
                backward_pass([front, back], accel, &mut got);
                assert_eq!(got, want, "{len} samples split at {split}");
            }
        }
    }

    #[test]
    fn an_empty_path_has_no_bound_and_one_block_ends_at_rest() {
        let settings = settings();
        assert_eq!(TimeOptimalBound::new(&settings, SPACING).finish(), None);
        // 10 mm at 600 mm/min: 1 s at speed plus the ramps at either end.
        let blocks = read("G1 X10 F600\n");
        let t = time_optimal_bound(&blocks.iter().collect::<Vec<_>>(), &settings, SPACING);
        let a = settings.max_tangential_accel_mm_per_s2;
        let v = 10.0f64.min(settings.axis_cap_mm_per_s[0]);
        let exact = 10.0 / v + v / a;
        assert!((t - exact).abs() < 1e-3 * exact, "{t} against {exact}");
    }
}
