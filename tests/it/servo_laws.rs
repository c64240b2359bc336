//! The two servo laws closed around the simulated gap, through the public API in virtual time:
//! a straight 20 mm cut where the work erodes (40 mm/min) slower than the three-state law's
//! normal feed (60 mm/min). The three-state law closes in until the gap shorts, turns back and
//! does it again; the voltage law feeds `gain · (V − V_ref)` and settles where its feed equals
//! the erosion rate, a few volts above `V_ref`, with no shorts.

use edmd::buffer::{StepBlock, VecSource};
use edmd::config::Config;
use edmd::fine::{FineSettings, Interpolator};
use edmd::gap::{GapSensor, GapState};
use edmd::servo::{GapReading, Law, ServoState};
use edmd::sim::{SimMachine, SimScript, SimSettings};
use edmd::vocab::MAX_AXES;

/// 200 blocks of 0.1 mm along X, planned at up to 20 mm/s (the servo decides).
fn straight_cut() -> Vec<StepBlock> {
    crate::stepped::straight_blocks(200, 20.0, 1)
}

struct Run {
    shorts: u64,
    seconds: f64,
    /// Mean gap voltage (ratio law: open − short ratio) over the sparking ticks after the
    /// first 2 mm.
    mean_volts: f64,
}

fn run(law: &str) -> Run {
    let config = Config::load(
        None,
        &[
            format!("servo.law=\"{law}\""),
            "sim.debris_shorts_per_mm=0".into(),
            "sim.erosion_mm_per_min=40.0".into(),
            "sim.model=\"kinematic\"".into(),
        ],
    )
    .unwrap();
    let settings = FineSettings::from_config(&config);
    let mut sim = SimMachine::new(
        &SimSettings::from_config(&config),
        &[(0.0, 20.0)],
        SimScript::default(),
    )
    .gap;
    let mut source = VecSource::new(straight_cut(), 16);
    let mut fine = Interpolator::new(settings, [0; MAX_AXES]);
    let (mut sum, mut n) = (0.0, 0u64);
    let mut ticks = 0u64;
    while fine.state() != ServoState::Done {
        let gap = sim.sample(ticks).unwrap();
        let volts = sim.volts();
        let ratios = sim.ratios();
        let reading = GapReading {
            state: gap,
            volts,
            ratios,
            pulses: None,
            flushing: None,
        };
        let tick = fine.tick_measured(reading, &mut source);
        sim.observe(&tick.steps, tick.dir);
        if gap == GapState::Normal && fine.position()[0] > 2000 {
            sum += if law == "ratio" {
                let (open, short) = ratios.unwrap();
                open - short
            } else {
                volts.unwrap()
            };
            n += 1;
        }
        ticks += 1;
        assert!(ticks < 100_000_000, "stuck under the {law} law");
    }
    assert_eq!(fine.position()[0], 20_000);
    Run {
        shorts: fine.counters().servo.shorts,
        seconds: ticks as f64 * settings.dt,
        mean_volts: sum / n.max(1) as f64,
    }
}

#[test]
fn the_voltage_law_holds_the_gap_near_v_ref_without_the_shorts_of_the_three_state_law() {
    let three = run("three-state");
    let volt = run("voltage");
    eprintln!(
        "three-state: {} shorts, {:.1} s, mean {:.1} V; voltage: {} shorts, {:.1} s, mean {:.1} V",
        three.shorts, three.seconds, three.mean_volts, volt.shorts, volt.seconds, volt.mean_volts
    );
    assert!(
        three.shorts > 100,
        "the three-state law should short here: {}",
        three.shorts
    );
    assert!(
        volt.shorts <= 1,
        "{} shorts under the voltage law",
        volt.shorts
    );
    // Equilibrium: gain (10 mm/min per V) · (V − 25 V) = 40 mm/min, so V = 29 V.
    assert!(
        (27.0..31.0).contains(&volt.mean_volts),
        "mean {} V",
        volt.mean_volts
    );
    // Cutting at the erosion rate: 20 mm at 40 mm/min is 30 s.
    assert!((29.0..33.0).contains(&volt.seconds), "{} s", volt.seconds);
    assert!(volt.seconds < three.seconds);
}

/// The ratio law on the same cut: it keeps the open ratio where its feed equals the erosion
/// rate, `ratio_ref + erosion / gain` = 0.1 + 40/300, without the three-state law's shorts.
#[test]
fn the_ratio_law_holds_its_set_point_without_shorts() {
    let three = run("three-state");
    let ratio = run("ratio");
    eprintln!(
        "ratio: {} shorts, {:.1} s, mean open - short {:.3}",
        ratio.shorts, ratio.seconds, ratio.mean_volts
    );
    assert!(
        ratio.shorts <= 1,
        "{} shorts under the ratio law",
        ratio.shorts
    );
    assert!(three.shorts > 100);
    let set_point = 0.1 + 40.0 / 300.0;
    assert!(
        (ratio.mean_volts - set_point).abs() < 0.03,
        "mean {}",
        ratio.mean_volts
    );
    assert!((29.0..33.0).contains(&ratio.seconds), "{} s", ratio.seconds);
}

/// A steady 30 V gap advances, 20 V backs off, 0 V is a dead short, 80 V is open.
#[test]
fn the_voltage_law_at_fixed_voltages() {
    let config = Config::load(
        None,
        &["servo.law=\"voltage\"".into(), "gap.kind=\"sim\"".into()],
    )
    .unwrap();
    let settings = FineSettings::from_config(&config);
    assert!(matches!(settings.law, Law::Voltage { v_ref, .. } if v_ref == 25.0));
    for (volts, expect) in [(30.0, 1i8), (20.0, -1), (0.0, -1), (80.0, 1)] {
        let mut blocks = straight_cut();
        blocks.truncate(20);
        let mut source = VecSource::new(blocks, 16);
        let mut fine = Interpolator::new(settings, [0; MAX_AXES]);
        let mut dir_sum = 0i64;
        let mut state_short = false;
        let mut arrived = false;
        for _ in 0..200_000u64 {
            // Advance 1 mm at an open gap first, then hold the voltage under test.
            arrived |= fine.position()[0] >= 1000;
            let v = if arrived { volts } else { 80.0 };
            let reading = GapReading {
                state: GapState::Normal,
                volts: Some(v),
                ratios: None,
                pulses: None,
                flushing: None,
            };
            let tick = fine.tick_measured(reading, &mut source);
            if arrived {
                dir_sum += tick.dir as i64;
                state_short |= fine.state() == ServoState::TurnBack;
            }
        }
        assert_eq!(
            dir_sum.signum() as i8,
            expect,
            "{volts} V: net direction {dir_sum}"
        );
        assert_eq!(
            state_short,
            volts < 5.0,
            "{volts} V: turned back as a short"
        );
    }
}
