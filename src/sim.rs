//! The simulated EDM gap (`gap.kind = "sim"`): no hardware, a believable gap. (With
//! `output.kind = "sim"` the simulated drives take every step: the position is the pulse
//! ledger, so that output is [`crate::output::NullOutput`].)
//!
//! A one-dimensional model along the programmed path, the view the servo has of it:
//!
//! ```text
//!   electrode progress σ ──► gap g = φ − σ ◄── workpiece front φ
//!   (+ one event's length forward,              (+ erosion · dt while sparking)
//!    − one event's length on turn-back)
//!
//!   g < short_gap ─► short      short_gap ≤ g ≤ open_gap ─► normal (sparking)      g > open_gap ─► open
//! ```
//!
//! On top of the proximity states, debris bridges the gap at random (a Poisson process of
//! `debris_shorts_per_s` while sparking, from a seeded splitmix64): the gap reads short until
//! the electrode has turned back `debris_clear_um` from where it bridged. With the erosion
//! rate between the normal and the open feed, the servo alternates between normal and open
//! and the debris shorts exercise turn-back: a handful per program with the default config.
//!
//! The electrode learns its motion through [`GapSensor::observe`]: the length of each event
//! (from the steps and step sizes), signed by the event's direction along the program.

use crate::config::{Config, SimConfig};
use crate::gap::{GapSensor, GapState};
use crate::geometry::MAX_AXES;
use crate::rng::SplitMix64;

/// `gap.kind = "sim"`: the closed-loop gap model.
#[derive(Debug, Clone)]
pub struct SimGap {
    params: SimConfig,
    step_mm: [f64; MAX_AXES],
    dt: f64,
    rng: SplitMix64,
    /// Electrode progress along the path (mm).
    progress: f64,
    /// Workpiece front along the path (mm).
    front: f64,
    /// A debris bridge holds the gap shorted until progress falls to this (mm).
    debris_until: Option<f64>,
    /// Probability of a debris short in one sparking tick.
    debris_per_tick: f64,
    state: GapState,
    /// Debris shorts started.
    pub debris_shorts: u64,
}

impl SimGap {
    pub fn from_config(config: &Config) -> SimGap {
        let mut step_mm = [0.0; MAX_AXES];
        for (slot, s) in step_mm.iter_mut().zip(&config.machine.step_mm) {
            *slot = *s;
        }
        let dt = config.fine.tick_us as f64 * 1e-6;
        let params = config.sim.clone();
        SimGap {
            debris_per_tick: -(-params.debris_shorts_per_s * dt).exp_m1(),
            rng: SplitMix64::new(params.seed),
            front: params.initial_gap_mm,
            params,
            step_mm,
            dt,
            progress: 0.0,
            debris_until: None,
            state: GapState::Open,
            debris_shorts: 0,
        }
    }

    /// The gap distance (mm).
    pub fn gap_mm(&self) -> f64 {
        self.front - self.progress
    }
}

impl GapSensor for SimGap {
    fn sample(&mut self, _tick: u64) -> GapState {
        if let Some(until) = self.debris_until {
            if self.progress > until {
                self.state = GapState::Short;
                return self.state;
            }
            self.debris_until = None;
        }
        let gap = self.gap_mm();
        self.state = if gap < self.params.short_gap_mm {
            GapState::Short
        } else if gap > self.params.open_gap_mm {
            GapState::Open
        } else {
            GapState::Normal
        };
        if self.state == GapState::Normal {
            self.front += self.params.erosion_mm_per_s * self.dt;
            if self.debris_per_tick > 0.0 && self.rng.next_f64() < self.debris_per_tick {
                self.debris_until = Some(self.progress - self.params.debris_clear_mm);
                self.debris_shorts += 1;
                self.state = GapState::Short;
            }
        }
        self.state
    }

    fn observe(&mut self, steps: &[i8; MAX_AXES], dir: i8) {
        if dir == 0 {
            return;
        }
        let mut len2 = 0.0;
        for (s, mm) in steps.iter().zip(&self.step_mm) {
            let d = *s as f64 * mm;
            len2 += d * d;
        }
        self.progress += dir as f64 * len2.sqrt();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gap(overrides: &[&str]) -> SimGap {
        let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
        SimGap::from_config(&Config::load(None, &overrides).unwrap())
    }

    #[test]
    fn the_gap_closes_as_the_electrode_advances_and_erodes_while_sparking() {
        let mut g = gap(&["sim.debris_shorts_per_s=0"]);
        assert_eq!(g.sample(0), GapState::Open);
        let x = [1, 0, 0, 0, 0, 0];
        for _ in 0..12 {
            g.observe(&x, 1); // 12 µm: 8 µm left
        }
        assert_eq!(g.sample(1), GapState::Normal);
        let front = g.front;
        g.sample(2);
        assert!(g.front > front, "sparking erodes");
        for _ in 0..8 {
            g.observe(&x, 1);
        }
        assert_eq!(g.sample(3), GapState::Short);
        for _ in 0..3 {
            g.observe(&[-1, 0, 0, 0, 0, 0], -1); // turning back opens the gap again
        }
        assert_eq!(g.sample(4), GapState::Normal);
    }

    #[test]
    fn debris_shorts_are_seeded_and_clear_after_turning_back() {
        let run = |seed: u64| {
            let mut g = gap(&[
                // The gap opens after ~80 ticks of sparking without advancing: make them count.
                "sim.debris_shorts_per_s=2000",
                &format!("sim.seed={seed}"),
                "sim.initial_gap_um=5",
            ]);
            (0..2000u64)
                .filter(|&t| g.sample(t) == GapState::Short)
                .collect::<Vec<_>>()
        };
        let a = run(7);
        assert!(!a.is_empty());
        assert_eq!(a, run(7), "same seed, same shorts");
        assert_ne!(a, run(8));
        // A debris short holds until the electrode turns back debris_clear_um.
        let mut g = gap(&[
            "sim.debris_shorts_per_s=1e9",
            "sim.initial_gap_um=5",
            "sim.debris_clear_um=15",
        ]);
        assert_eq!(g.sample(0), GapState::Short);
        g.debris_per_tick = 0.0;
        for _ in 0..14 {
            g.observe(&[0, -1, 0, 0, 0, 0], -1);
        }
        assert_eq!(g.sample(1), GapState::Short);
        g.observe(&[0, -1, 0, 0, 0, 0], -1);
        assert_ne!(g.sample(2), GapState::Short);
    }
}
