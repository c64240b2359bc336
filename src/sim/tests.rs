//! The simulated gap's model, tick by tick.

use super::*;

/// The shipped defaults (`config/edmd.toml`, on two 1 µm axes at 50 µs; the
/// configuration's tests check they are what the shipped file gives), with `sim.KEY=VALUE`
/// overrides in the file's units.
pub(crate) fn settings(overrides: &[&str]) -> SimSettings {
    let mut params = SimConfig {
        seed: 1,
        initial_gap_mm: 20.0 / 1000.0,
        short_gap_mm: 1.0 / 1000.0,
        open_gap_mm: 10.0 / 1000.0,
        erosion_mm_per_s: 75.0 / 60.0,
        debris_per_mm: 0.1,
        debris_shorts_per_s: 0.0,
        debris_clear_mm: 300.0 / 1000.0,
        wire_breaks_per_m: 0.0,
        events: None,
        home_switch_mm: vec![None, None],
        part: SimPart::default(),
        breakthrough_at_mm: f64::INFINITY,
        model: SimModel::Kinematic,
    };
    for o in overrides {
        let (key, value) = o.split_once('=').expect("sim.KEY=VALUE");
        let v: f64 = value.parse().expect("a number");
        match key {
            "sim.seed" => params.seed = v as u64,
            "sim.initial_gap_um" => params.initial_gap_mm = v / 1000.0,
            "sim.debris_shorts_per_mm" => params.debris_per_mm = v,
            "sim.debris_shorts_per_s" => params.debris_shorts_per_s = v,
            "sim.debris_clear_um" => params.debris_clear_mm = v / 1000.0,
            "sim.wire_breaks_per_m" => params.wire_breaks_per_m = v,
            other => panic!("no test override for {other}"),
        }
    }
    SimSettings {
        params,
        step_mm: [0.001, 0.001, 0.0, 0.0, 0.0, 0.0],
        tick: TickPeriod::from_us(50).unwrap(),
        volts: GapVolts {
            short_below: 5.0,
            open_above: 60.0,
        },
        plane: Some([0, 1]),
        wire_radius_mm: 0.125,
    }
}

fn gap(overrides: &[&str]) -> SimGap {
    SimMachine::new(&settings(overrides), &[(0.0, 10.0)], SimScript::default()).gap
}

fn sample(g: &mut SimGap, tick: u64) -> GapState {
    g.sample(tick).unwrap()
}

const X: [i8; MAX_AXES] = [1, 0, 0, 0, 0, 0];
const BACK: [i8; MAX_AXES] = [-1, 0, 0, 0, 0, 0];

#[test]
fn the_gap_closes_as_the_electrode_advances_and_erodes_while_sparking() {
    let mut g = gap(&["sim.debris_shorts_per_mm=0"]);
    assert_eq!(sample(&mut g, 0), GapState::Open);
    for _ in 0..12 {
        g.observe(&X, 1); // 12 µm: 8 µm left
    }
    assert_eq!(sample(&mut g, 1), GapState::Normal);
    let front = g.front;
    sample(&mut g, 2);
    assert!(g.front > front, "sparking erodes");
    for _ in 0..8 {
        g.observe(&X, 1);
    }
    assert_eq!(sample(&mut g, 3), GapState::Short);
    assert_eq!(g.counters().proximity_shorts, 1);
    for _ in 0..3 {
        g.observe(&BACK, -1); // turning back opens the gap again
    }
    assert_eq!(sample(&mut g, 4), GapState::Normal);
}

#[test]
fn random_debris_is_seeded_and_clears_after_turning_back() {
    let run = |seed: u64| {
        let mut g = gap(&[
            "sim.debris_shorts_per_mm=0",
            // The gap opens after ~80 ticks of sparking without advancing: make them count.
            "sim.debris_shorts_per_s=2000",
            &format!("sim.seed={seed}"),
            "sim.initial_gap_um=6",
            "sim.debris_clear_um=1",
        ]);
        g.observe(&X, 1); // past the first debris_clear of cutting
        (0..2000u64)
            .filter(|&t| sample(&mut g, t) == GapState::Short)
            .collect::<Vec<_>>()
    };
    let a = run(7);
    assert!(!a.is_empty());
    assert_eq!(a, run(7), "same seed, same shorts");
    assert_ne!(a, run(8));
    let mut g = gap(&[
        "sim.debris_shorts_per_mm=0",
        "sim.debris_shorts_per_s=1e9",
        "sim.initial_gap_um=20",
        "sim.debris_clear_um=15",
    ]);
    // Nothing forms in the first debris_clear of cutting, whatever the rate.
    for _ in 0..14 {
        g.observe(&X, 1);
        assert_ne!(sample(&mut g, 0), GapState::Short);
    }
    g.observe(&X, 1);
    assert_eq!(sample(&mut g, 0), GapState::Short);
    g.debris_per_tick = 0.0;
    for _ in 0..14 {
        g.observe(&BACK, -1);
    }
    assert_eq!(sample(&mut g, 1), GapState::Short);
    g.observe(&BACK, -1);
    assert_ne!(sample(&mut g, 2), GapState::Short);
    assert_eq!(g.counters().debris_shorts, 1);
}

#[test]
fn placed_debris_spreads_over_the_path_and_forms_where_placed() {
    // 0.5 per mm over the 9.7 mm of a 10 mm cut past its first 0.3 mm (debris_clear_um).
    let g = gap(&["sim.debris_shorts_per_mm=0.5", "sim.seed=3"]);
    let at = g.debris_positions().to_vec();
    assert_eq!(at.len(), 5);
    for (k, p) in at.iter().enumerate() {
        let stretch = 9.7 / 5.0;
        assert!(
            *p >= 0.3 + stretch * (k as f64 + 0.1) && *p <= 0.3 + stretch * (k as f64 + 0.9),
            "{at:?}"
        );
    }
    assert_ne!(
        at,
        gap(&["sim.debris_shorts_per_mm=0.5", "sim.seed=4"]).debris_positions()
    );
    // The number goes with the cutting: none on a move of a few mm at the default rate.
    let short = SimMachine::new(&settings(&[]), &[(0.0, 4.0)], SimScript::default()).gap;
    assert!(short.debris_positions().is_empty());
    assert_eq!(gap(&[]).debris_positions().len(), 1, "0.1 per mm of 9.7 mm");
    // Only on cutting moves: a 10 mm rapid, 2 mm cut, 5 mm rapid, 2 mm cut.
    let spans = [(10.0, 12.0), (17.0, 19.0)];
    let g = SimMachine::new(
        &settings(&["sim.debris_shorts_per_mm=10", "sim.debris_clear_um=0.001"]),
        &spans,
        SimScript::default(),
    )
    .gap;
    for p in g.debris_positions() {
        assert!(spans.iter().any(|(a, b)| p >= a && p <= b), "{p}");
    }
    assert_eq!(
        g.debris_positions().iter().filter(|&&p| p < 15.0).count(),
        20
    );
    // Walk the electrode along, keeping the gap sparking: a short exactly past each one.
    let mut g = gap(&[
        "sim.debris_shorts_per_mm=0.5",
        "sim.seed=3",
        "sim.initial_gap_um=5",
    ]);
    let mut formed = Vec::new();
    for tick in 0..12_000u64 {
        if sample(&mut g, tick) == GapState::Short {
            formed.push(g.progress);
            while sample(&mut g, tick) == GapState::Short {
                g.observe(&BACK, -1);
            }
        } else {
            g.observe(&X, 1);
            g.front = g.progress + 0.005;
        }
    }
    assert_eq!(formed.len(), 5, "{formed:?}");
    for (f, p) in formed.iter().zip(&at) {
        assert!(f >= p && f - p < 0.0011, "formed at {f}, placed at {p}");
    }
}

#[test]
fn scripted_events_hold_erode_and_bridge() {
    let events = events::parse(
        "0 open 3\n5 erosion 6000\n10 debris 2000\n20 short 4\n",
        "ev",
    )
    .unwrap();
    let mut g = SimMachine::new(
        &settings(&["sim.debris_shorts_per_mm=0", "sim.initial_gap_um=5"]),
        &[(0.0, 10.0)],
        events,
    )
    .gap;
    let states: Vec<GapState> = (0..3).map(|t| sample(&mut g, t)).collect();
    assert_eq!(
        states,
        [GapState::Open; 3],
        "held open although the gap is 5 µm"
    );
    assert_eq!(sample(&mut g, 3), GapState::Normal);
    let front = g.front;
    sample(&mut g, 5);
    assert!(
        (g.front - front - 100.0 * g.dt).abs() < 1e-12,
        "6000 mm/min"
    );
    g.front = g.progress + 0.005;
    assert_eq!(sample(&mut g, 10), GapState::Short, "scripted debris");
    for _ in 0..1999 {
        g.observe(&BACK, -1);
    }
    assert_eq!(sample(&mut g, 11), GapState::Short, "clears after 2 mm");
    g.observe(&BACK, -1);
    g.observe(&BACK, -1);
    g.front = g.progress + 0.005;
    assert_eq!(sample(&mut g, 12), GapState::Normal);
    for t in 20..24 {
        assert_eq!(sample(&mut g, t), GapState::Short, "welded");
        g.observe(&BACK, -1);
    }
    g.front = g.progress + 0.005;
    assert_eq!(sample(&mut g, 24), GapState::Normal);
}

#[test]
fn the_machine_s_inputs_side_reads_its_e_stop_limits_and_wire() {
    use crate::inputs::MachineInputs;
    let events = events::parse("3 estop\n5 limit X+\n", "ev").unwrap();
    let SimMachine {
        gap: mut g,
        mut inputs,
    } = SimMachine::new(
        &settings(&[
            "sim.debris_shorts_per_mm=0",
            "sim.initial_gap_um=5",
            "sim.wire_breaks_per_m=1000",
        ]),
        &[(0.0, 10.0)],
        events,
    );
    // The loop's order in a tick: the inputs, the gap, then the steps.
    let tick = |t: u64, g: &mut SimGap, inputs: &mut SimInputs| {
        let read = inputs.sample(t).unwrap();
        let state = sample(g, t);
        g.observe(&X, 1);
        g.front = g.progress + 0.005;
        (read, state)
    };
    let (r, _) = tick(2, &mut g, &mut inputs);
    assert!(!r.safety.estop && r.safety.limits.is_empty());
    let (r, _) = tick(3, &mut g, &mut inputs);
    assert!(r.safety.estop, "pressed in its own tick");
    let (r, _) = tick(5, &mut g, &mut inputs);
    assert_eq!(r.safety.limits.iter().count(), 1);
    // 1000 breaks per m: one within a few mm of cutting.
    let mut t = 6;
    let broke = loop {
        let (r, state) = tick(t, &mut g, &mut inputs);
        if r.wire_broken {
            assert_eq!(state, GapState::Open, "no wire, no discharge");
            break t;
        }
        t += 1;
        assert!(t < 100_000, "the wire never broke");
    };
    assert_eq!(g.counters().wire_breaks, 1);
    inputs.rethreaded();
    let (r, state) = tick(broke + 1, &mut g, &mut inputs);
    assert!(!r.wire_broken);
    assert_eq!(state, GapState::Normal, "sparking again on the new wire");
}
