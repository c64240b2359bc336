//! The cycles move by move, against a lattice executor of their programs: each `G0` moves
//! the wire, each `G38.3` walks it step by step until the simulated part's clearance reaches
//! zero. The part and its clearance are the simulator's (`crate::sim::SimPart`).

use super::*;
use crate::sim::{SimHole, SimPart};

const STEP: f64 = 0.001;
const R: f64 = 0.125;

fn settings() -> FindSettings {
    FindSettings {
        touch: TouchConfig {
            condition: 9,
            feed_mm_per_min: 300.0,
            search_mm: 20.0,
            backoff_mm: 0.1,
            retries: 2,
            corner_clearance_mm: 5.0,
            center_rounds: 5,
        },
        wire_radius_mm: R,
        step_mm: [STEP; 2],
        travel: [None, None],
    }
}

fn block() -> SimPart {
    SimPart {
        edges_mm: [Some([10.0, 60.0]), Some([-40.0, 20.0])],
        hole: Some(SimHole {
            center_mm: [12.345 + 20.0, -6.789],
            diameter_mm: 10.0,
        }),
        bounce_mm: 0.0,
    }
}

fn hole() -> SimPart {
    SimPart {
        edges_mm: [None, None],
        hole: Some(SimHole {
            center_mm: [12.345, -6.789],
            diameter_mm: 10.0,
        }),
        bounce_mm: 0.0,
    }
}

/// Runs a cycle's programs against `part` from `at`: the result, the wire's end, the moves.
struct Executor {
    part: SimPart,
    at: [i64; 2],
    bounce_left: bool,
    programs: Vec<String>,
}

impl Executor {
    fn new(part: SimPart, at: [f64; 2]) -> Executor {
        Executor {
            part,
            at: at.map(|v| (v / STEP).round() as i64),
            bounce_left: false,
            programs: Vec::new(),
        }
    }

    fn mm(&self) -> [f64; 2] {
        self.at.map(|s| s as f64 * STEP)
    }

    /// Runs one move's program; where it ended and the last probe's contact.
    fn run(&mut self, m: &Move) -> MoveEnd {
        self.programs.push(m.program.clone());
        if m.first {
            self.bounce_left = self.part.bounce_mm > 0.0;
        }
        let mut contact_mm = None;
        for line in m.program.lines() {
            let code = line.split('(').next().unwrap();
            let words: Vec<&str> = code.split_whitespace().collect();
            let probe = match words.first() {
                Some(&"G0") => false,
                Some(&"G38.3") => true,
                _ => continue,
            };
            let mut d = [0i64; 2];
            for w in &words[1..] {
                let axis = match w.chars().next() {
                    Some('X') => 0,
                    Some('Y') => 1,
                    _ => continue,
                };
                d[axis] = (w[1..].parse::<f64>().unwrap() / STEP).round() as i64;
            }
            if !probe {
                self.at = [self.at[0] + d[0], self.at[1] + d[1]];
                continue;
            }
            contact_mm = None;
            let from = self.at;
            let n = d[0].abs().max(d[1].abs());
            for k in 1..=n {
                self.at =
                    [0, 1].map(|i| from[i] + (d[i] as f64 * k as f64 / n as f64).round() as i64);
                let c = self.part.clearance(self.mm(), R);
                let bounce = self.bounce_left && c > 0.0 && c <= self.part.bounce_mm;
                if bounce {
                    self.bounce_left = false;
                }
                if c <= 0.0 || bounce {
                    contact_mm = Some(self.mm());
                    break;
                }
            }
        }
        MoveEnd {
            at_mm: self.mm(),
            contact_mm,
        }
    }

    fn find(&mut self, target: Target, s: FindSettings) -> Result<Found, FindError> {
        let mut cycle = FindCycle::new(target, s, self.mm());
        let mut next = cycle.begin()?;
        loop {
            match next {
                Next::Done(found) => return Ok(found),
                Next::Run(m) => {
                    assert!(self.programs.len() < 200, "a cycle that does not end");
                    let end = self.run(&m);
                    next = cycle.moved(end)?;
                }
            }
        }
    }
}

#[test]
fn targets_parse_and_name_themselves() {
    assert_eq!(Target::parse("edge X+"), Ok(Target::Edge(Side::X_PLUS)));
    assert_eq!(Target::parse(" EDGE  y- "), Ok(Target::Edge(Side::Y_MINUS)));
    assert_eq!(
        Target::parse("corner Y+X-"),
        Ok(Target::Corner(Side::X_MINUS, Side::Y_PLUS))
    );
    assert_eq!(Target::parse("centre"), Ok(Target::Center));
    for bad in [
        "edge",
        "edge Z+",
        "edge X",
        "corner X+X+",
        "corner X+Y",
        "middle",
    ] {
        let e = Target::parse(bad).unwrap_err();
        assert!(e.to_string().contains("edge X+|X-|Y+|Y-"), "{bad}: {e}");
    }
    assert_eq!(
        Target::Corner(Side::X_MINUS, Side::Y_PLUS).name(),
        "corner X-Y+"
    );
}

#[test]
fn an_edge_is_the_contact_plus_the_wire_radius_and_the_wire_backs_off() {
    let mut ex = Executor::new(block(), [0.0, 0.0]);
    let found = ex.find(Target::Edge(Side::X_PLUS), settings()).unwrap();
    let edge = found.point_mm[0].unwrap();
    assert!((10.0..10.0 + STEP).contains(&edge), "{edge}");
    let wire = found.wire_mm[0].unwrap();
    assert!((wire - (10.0 - R)).abs() <= STEP, "{wire}");
    assert_eq!(found.point_mm[1], None);
    assert_eq!((found.touches, found.retries), (1, 0));
    // Approach, retouch, back off.
    assert_eq!(ex.programs.len(), 3);
    assert_eq!(
        ex.programs[0],
        "G21 G91 E9 (find edge X+: wire touch, spark off)\n\
         G38.3 X20 F300 (approach X+)\nM2\n"
    );
    assert_eq!(
        ex.programs[1],
        "G21 G91 E9 (find edge X+: wire touch, spark off)\nG0 X-0.1 (back off)\n\
         G38.3 X0.2 F30 (retouch X+ at a tenth of the feed)\nM2\n"
    );
    assert!((ex.mm()[0] - (wire - 0.1)).abs() < 1e-9, "backed off");
    // The other way: the block's X max face.
    let mut ex = Executor::new(block(), [70.0, 0.0]);
    let found = ex.find(Target::Edge(Side::X_MINUS), settings()).unwrap();
    let edge = found.point_mm[0].unwrap();
    assert!((60.0 - STEP..=60.0).contains(&edge), "{edge}");
}

#[test]
fn a_hole_centre_settles_within_a_step_and_measures_the_diameter() {
    let mut ex = Executor::new(hole(), [11.0, -5.0]);
    let found = ex.find(Target::Center, settings()).unwrap();
    let [x, y] = found.point_mm.map(Option::unwrap);
    assert!((x - 12.345).abs() <= STEP, "{x}");
    assert!((y + 6.789).abs() <= STEP, "{y}");
    let [dx, dy] = found.diameter_mm.unwrap();
    assert!(
        (dx - 10.0).abs() <= 2.0 * STEP && (dy - 10.0).abs() <= 2.0 * STEP,
        "{dx} {dy}"
    );
    assert!(found.rounds >= 2, "two rounds must agree");
    assert_eq!(found.touches, 4 * found.rounds);
    // The wire ends at the centre.
    assert!((ex.mm()[0] - x).abs() <= STEP && (ex.mm()[1] - y).abs() <= STEP);
}

#[test]
fn a_corner_is_found_from_off_the_corner_in_each_direction() {
    let cases = [
        (
            Target::Corner(Side::X_PLUS, Side::Y_PLUS),
            [7.0, -43.0],
            [10.0, -40.0],
        ),
        (
            Target::Corner(Side::X_MINUS, Side::Y_MINUS),
            [63.0, 23.0],
            [60.0, 20.0],
        ),
    ];
    for (target, start, corner) in cases {
        let mut ex = Executor::new(block(), start);
        let found = ex.find(target, settings()).unwrap();
        for (i, (v, want)) in found.point_mm.iter().zip(corner).enumerate() {
            let v = v.unwrap();
            assert!((v - want).abs() <= STEP, "{target:?} {i}: {v}");
        }
        assert_eq!(
            ex.mm(),
            start.map(|v| (v / STEP).round() * STEP),
            "back at the start"
        );
    }
}

#[test]
fn a_false_first_contact_is_retouched_away_and_approached_again() {
    let part = SimPart {
        bounce_mm: 0.5,
        ..block()
    };
    let mut ex = Executor::new(part, [0.0, 0.0]);
    let found = ex.find(Target::Edge(Side::X_PLUS), settings()).unwrap();
    assert_eq!(found.retries, 1);
    let edge = found.point_mm[0].unwrap();
    assert!((10.0..10.0 + STEP).contains(&edge), "{edge}");
    // With no retries allowed the same bounce fails the cycle.
    let mut s = settings();
    s.touch.retries = 0;
    let mut ex = Executor::new(part, [0.0, 0.0]);
    let e = ex.find(Target::Edge(Side::X_PLUS), s).unwrap_err();
    assert_eq!(
        e,
        FindError::Unsteady {
            side: "X+".into(),
            tries: 1
        }
    );
}

#[test]
fn failures_say_where() {
    // Nothing within the search.
    let mut ex = Executor::new(block(), [-30.0, 0.0]);
    let e = ex.find(Target::Edge(Side::X_PLUS), settings()).unwrap_err();
    assert_eq!(e.to_string(), "X+: no contact within 20.000 mm");
    // The soft limit bounds the search.
    let mut s = settings();
    s.travel = [Some([-100.0, 5.0]), None];
    let mut ex = Executor::new(block(), [0.0, 0.0]);
    assert!(ex.programs.is_empty());
    ex.find(Target::Edge(Side::X_PLUS), s).unwrap_err();
    assert!(
        ex.programs[0].contains("G38.3 X5 F300"),
        "{}",
        ex.programs[0]
    );
    s.travel = [Some([-100.0, 0.0]), None];
    let mut ex = Executor::new(block(), [0.0, 0.0]);
    assert_eq!(
        ex.find(Target::Edge(Side::X_PLUS), s).unwrap_err(),
        FindError::NoRoom { side: "X+".into() }
    );
    // A corner whose clearance runs into the part: the positioning move touches it.
    let mut ex = Executor::new(block(), [12.0, -43.0]);
    let e = ex
        .find(Target::Corner(Side::X_PLUS, Side::Y_PLUS), settings())
        .unwrap_err();
    assert!(matches!(e, FindError::Collided { .. }), "{e}");
}

#[test]
fn numbers_in_programs_are_short_and_exact() {
    assert_eq!(num(20.0), "20");
    assert_eq!(num(-0.1), "-0.1");
    assert_eq!(num(1.0e-7), "0");
    assert_eq!(num(-1.0e-7), "0");
    assert_eq!(num(12.3456789), "12.345679");
}
