//! What the simulated probe touches when a job's probing moves do not read the gap: a homing
//! job's switch, or the part a wire-touch cycle finds (`edmd ctl find`).
//!
//! The part is geometry in the program plane, in the machine coordinates the machine
//! believes: a block (`sim.part_edge_mm`, the extent of the stock on X and on Y, an axis
//! without one unbounded) with a round hole through it (`sim.hole_center_mm`,
//! `sim.hole_diameter_mm`, a start hole). The wire is a disk of the machine's wire radius
//! around its lower guide's X/Y; it touches when that disk reaches the material, so the
//! contact a cycle reads is exact to the step and its wire-radius correction is checked
//! against the part's true edges.
//!
//! ```text
//!      y ▲        part_edge_mm Y max
//!        │   ┌───────────────────────┐
//!        │   │        ╭────╮          │   hole: center, diameter
//!        │ o─┼→ X+    │ o→ │ X+       │   o: the wire; its disk (radius r) touches
//!        │   │        ╰────╯          │      when clearance(p, r) <= 0
//!        │   └───────────────────────┘ part_edge_mm Y min
//!        └────────────────────────────────► x
//! ```

use crate::vocab::{GapState, HomeSwitch, MAX_AXES, Steps};

/// The simulated part (`[sim]`), machine coordinates in mm.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SimPart {
    /// The block's extent on X and on Y, `[min, max]` (`None`: unbounded that way). With
    /// neither and no hole there is no part.
    pub edges_mm: [Option<[f64; 2]>; 2],
    /// A round hole through the block (the block is everywhere when no edge is given).
    pub hole: Option<SimHole>,
    /// The first approach of a find cycle reads one false contact (a bounce: a water film, a
    /// vibrating wire) when its wire comes this close to the material (mm; 0: never).
    pub bounce_mm: f64,
}

/// A round hole through the simulated part.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimHole {
    pub center_mm: [f64; 2],
    pub diameter_mm: f64,
}

impl SimPart {
    /// There is material to touch.
    pub fn exists(&self) -> bool {
        self.hole.is_some() || self.edges_mm.iter().any(Option::is_some)
    }

    /// How far the surface of a wire of radius `r` at `p` (X, Y) is from the material, mm:
    /// at or below 0 it touches. Inside the hole that is the hole's wall; elsewhere the
    /// block's (inside the block: touching).
    pub fn clearance(&self, p: [f64; 2], r: f64) -> f64 {
        if !self.exists() {
            return f64::INFINITY;
        }
        if let Some(h) = &self.hole {
            let d = (p[0] - h.center_mm[0]).hypot(p[1] - h.center_mm[1]);
            let radius = h.diameter_mm / 2.0;
            if d < radius || self.edges_mm.iter().all(Option::is_none) {
                return radius - d - r;
            }
        }
        let outside =
            |i: usize| self.edges_mm[i].map_or(0.0, |[lo, hi]| (lo - p[i]).max(p[i] - hi).max(0.0));
        outside(0).hypot(outside(1)) - r
    }
}

/// What a job's probing moves read in the simulator, with what it tracks of the motion.
#[derive(Debug, Clone, Copy, Default)]
pub(super) enum Target {
    /// The gap model's own distance (a program's `G38`).
    #[default]
    Gap,
    /// A homing job's switch and the steps taken on its axis since the job started.
    Switch { switch: HomeSwitch, moved: i64 },
    /// A find cycle's part, with the wire's position in steps.
    Part(Touching),
}

/// A touch job in the simulator: where the wire is, and whether a bounce is still to come.
#[derive(Debug, Clone, Copy)]
pub(super) struct Touching {
    at: Steps,
    bounce_left: bool,
}

/// The part and the wire as the simulator knows them: the X and Y axes' indices and step
/// sizes, the wire's radius.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(super) struct SimWire {
    pub part: SimPart,
    /// Indices of X and Y in `machine.axes` (`None`: the machine has no program plane).
    pub plane: Option<[usize; 2]>,
    pub radius_mm: f64,
}

impl Target {
    /// The target of `what` (see [`crate::vocab::ProbeReads`]).
    pub(super) fn new(what: crate::vocab::ProbeReads) -> Target {
        use crate::vocab::ProbeReads;
        match what {
            ProbeReads::Probe => Target::Gap,
            ProbeReads::Switch(switch) => Target::Switch { switch, moved: 0 },
            ProbeReads::Touch { start, bounce } => Target::Part(Touching {
                at: start,
                bounce_left: bounce,
            }),
        }
    }

    /// The motion of one event.
    pub(super) fn observe(&mut self, steps: &[i8; MAX_AXES]) {
        match self {
            Target::Gap => {}
            Target::Switch { switch, moved } => *moved += steps[switch.axis] as i64,
            Target::Part(t) => {
                for (a, s) in t.at.iter_mut().zip(steps) {
                    *a += *s as i64;
                }
            }
        }
    }

    /// The gap state of a tick: `None` for the gap model's own; else contact (short) while a
    /// probing move touches, open otherwise (the generator is off, nothing erodes).
    pub(super) fn state(
        &mut self,
        probing: bool,
        wire: &SimWire,
        step_mm: &[f64; MAX_AXES],
    ) -> Option<GapState> {
        let touching = match self {
            Target::Gap => return None,
            Target::Switch { switch, moved } => {
                if switch.positive {
                    *moved >= switch.at_steps
                } else {
                    *moved <= switch.at_steps
                }
            }
            Target::Part(t) => match wire.plane {
                None => false,
                Some([x, y]) => {
                    let p = [t.at[x] as f64 * step_mm[x], t.at[y] as f64 * step_mm[y]];
                    let clearance = wire.part.clearance(p, wire.radius_mm);
                    let bounce = probing
                        && t.bounce_left
                        && clearance > 0.0
                        && clearance <= wire.part.bounce_mm;
                    if bounce {
                        t.bounce_left = false;
                    }
                    bounce || clearance <= 0.0
                }
            },
        };
        Some(if probing && touching {
            GapState::Short
        } else {
            GapState::Open
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wire_touches_a_block_edge_and_a_hole_wall_at_its_radius() {
        let part = SimPart {
            edges_mm: [Some([10.0, 60.0]), Some([-40.0, 20.0])],
            hole: Some(SimHole {
                center_mm: [30.0, 0.0],
                diameter_mm: 10.0,
            }),
            bounce_mm: 0.0,
        };
        let r = 0.125;
        // Left of the block, level with it: the X min face.
        assert!((part.clearance([9.0, 0.0], r) - 0.875).abs() < 1e-12);
        assert!(part.clearance([9.875, 0.0], r) <= 0.0);
        // Off the corner: the distance to the corner.
        assert!((part.clearance([7.0, -44.0], r) - (5.0 - r)).abs() < 1e-12);
        // In the hole: the wall; in the block: touching.
        assert!((part.clearance([30.0, 0.0], r) - (5.0 - r)).abs() < 1e-12);
        assert!((part.clearance([34.875, 0.0], r)).abs() < 1e-12);
        assert!(part.clearance([40.0, 0.0], r) < 0.0);
        // A hole alone: material all around it.
        let hole = SimPart {
            edges_mm: [None, None],
            ..part
        };
        assert!(hole.clearance([100.0, 0.0], r) < 0.0);
        assert_eq!(SimPart::default().clearance([0.0, 0.0], r), f64::INFINITY);
    }

    #[test]
    fn a_touch_job_reads_contact_only_while_probing_and_bounces_once() {
        let wire = SimWire {
            part: SimPart {
                edges_mm: [Some([1.0, 5.0]), None],
                hole: None,
                bounce_mm: 0.5,
            },
            plane: Some([0, 1]),
            radius_mm: 0.0,
        };
        let step_mm = [0.1, 0.1, 0.0, 0.0, 0.0, 0.0];
        let mut t = Target::new(crate::vocab::ProbeReads::Touch {
            start: [0; MAX_AXES],
            bounce: true,
        });
        let x_plus = [1, 0, 0, 0, 0, 0];
        let mut states = Vec::new();
        for _ in 0..12 {
            states.push(t.state(true, &wire, &step_mm).unwrap());
            t.observe(&x_plus);
        }
        use GapState::{Open, Short};
        // x = 0.5 reads the bounce (one tick), x = 1.0 the face, and on.
        assert_eq!(
            states,
            [
                Open, Open, Open, Open, Open, Short, Open, Open, Open, Open, Short, Short
            ]
        );
        assert_eq!(t.state(false, &wire, &step_mm), Some(Open), "not probing");
        assert_eq!(Target::Gap.state(true, &wire, &step_mm), None);
    }
}
