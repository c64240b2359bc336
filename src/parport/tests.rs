//! The port's byte-level behaviour through the recording fake: pin map, inversions, the
//! order and timing of direction, step and release, writes only on change, the safe state
//! on drop, and the gap input.

use proptest::prelude::*;

use super::fake::{Bench, RecordingPort, VirtualClock};
use super::pins::{OUTPUT_PINS, Pin, PinLevels, PinMap, StepTiming};
use super::*;

const TIMING: StepTiming = StepTiming {
    step_length_ns: 5_000,
    step_space_ns: 5_000,
    dir_setup_ns: 20_000,
    dir_hold_ns: 20_000,
};
const TICK_NS: u64 = 50_000;

fn stepconf_map(axes: usize, inverted: &[Pin]) -> PinMap {
    PinMap {
        axes,
        step: [2, 4, 6, 8, 0, 0],
        dir: [3, 5, 7, 9, 0, 0],
        enable: Some(14),
        flush: None,
        spark: None,
        condition: [0; crate::parport::CONDITION_BITS],
        condition_bits: 0,
        inverted: inverted.iter().fold(0, |m, &p| m | 1 << p),
        short: Some(10),
        open: Some(11),
        probe: None,
        wire_break: None,
        estop: None,
        limits: Vec::new(),
    }
}

type FakeOutput = ParportOutput<RecordingPort, VirtualClock>;

fn output(bench: &Bench, map: PinMap, timing: StepTiming) -> FakeOutput {
    let port = Arc::new(Mutex::new(PortWriter::new(bench.port(), map.idle())));
    ParportOutput::new(port, map, timing, bench.clock(), "fake").unwrap()
}

/// Runs `ticks` through a fresh output; returns the bench and the idle levels.
fn drive(map: &PinMap, timing: StepTiming, tick_ns: u64, ticks: &[[i8; MAX_AXES]]) -> Bench {
    let bench = Bench::new();
    let mut out = output(&bench, map.clone(), timing);
    for (k, steps) in ticks.iter().enumerate() {
        bench.set_now(k as u64 * tick_ns);
        out.write(k as u64, steps, GapState::Normal).unwrap();
    }
    bench.set_now(ticks.len() as u64 * tick_ns);
    drop(out);
    bench
}

fn check_waveform(
    map: &PinMap,
    timing: StepTiming,
    bench: &Bench,
) -> Result<Vec<Vec<i8>>, TestCaseError> {
    bench.drive_steps(map, timing).map_err(TestCaseError::fail)
}

#[test]
fn stepconf_pins_dir_before_step_high_then_low() {
    let map = stepconf_map(2, &[]);
    let bench = drive(
        &map,
        TIMING,
        TICK_NS,
        &[[1, 0, 0, 0, 0, 0], [1, -1, 0, 0, 0, 0], [0; MAX_AXES]],
    );
    let w = bench.writes();
    use fake::Register::*;
    let seq: Vec<(u64, fake::Register, u8)> =
        w.iter().map(|w| (w.at_ns, w.register, w.value)).collect();
    assert_eq!(
        seq,
        vec![
            // Enable (pin 14, C1: the hardware inverts it, so the bit clears).
            (0, Control, 0b1001),
            // Tick 0: X positive (pin 3 = D1), X step (pin 2 = D0) 20 µs later, released 5 µs after.
            (0, Data, 0b0000_0010),
            (20_000, Data, 0b0000_0011),
            (25_000, Data, 0b0000_0010),
            // Tick 1: Y negative is its idle level (pin 5 low): no direction write; X and Y step.
            (70_000, Data, 0b0000_0111),
            (75_000, Data, 0b0000_0010),
            // Drop: idle, drives disabled.
            (150_000, Data, 0),
            (150_000, Control, 0b1011),
        ]
    );
    check_waveform(&map, TIMING, &bench).unwrap();
}

/// The process pins follow the machine: flushing (M7/M8), spark enable and the condition
/// number in binary; they change in a tick without steps too, and are inactive again when the
/// port is let go.
#[test]
fn the_process_pins_follow_the_machine_and_idle_off() {
    let mut map = stepconf_map(1, &[16]);
    map.flush = Some(16); // C2, active low here
    map.spark = Some(4);
    map.condition = [5, 6, 7, 0, 0, 0, 0, 0, 0, 0];
    map.condition_bits = 3;
    let bench = Bench::new();
    let mut out = output(&bench, map.clone(), TIMING);
    out.moving_in(crate::output::Activity {
        flags: crate::buffer::BlockFlags::FLUSH,
        spark: true,
        condition: 5,
        ..Default::default()
    });
    bench.set_now(TICK_NS);
    out.write(1, &[0; MAX_AXES], GapState::Normal).unwrap();
    bench.set_now(2 * TICK_NS);
    out.write(2, &[1, 0, 0, 0, 0, 0], GapState::Normal).unwrap();
    out.moving_in(crate::output::Activity {
        condition: 2,
        ..Default::default()
    });
    bench.set_now(3 * TICK_NS);
    out.write(3, &[1, 0, 0, 0, 0, 0], GapState::Normal).unwrap();
    drop(out);
    let wave = bench.waveform(map.idle());
    let at = |t: u64| wave.iter().rev().find(|(at, _)| *at <= t).unwrap().1;
    let state = |t: u64| {
        let l = at(t);
        let condition =
            (l.is_high(5) as u8) | (l.is_high(6) as u8) << 1 | (l.is_high(7) as u8) << 2;
        (!l.is_high(16), l.is_high(4), condition)
    };
    assert_eq!(
        state(0),
        (false, false, 0),
        "all off before the program asks"
    );
    assert_eq!(
        state(TICK_NS),
        (true, true, 5),
        "on in a tick without steps"
    );
    assert_eq!(
        state(2 * TICK_NS + TIMING.dir_setup_ns),
        (true, true, 5),
        "held through steps"
    );
    assert_eq!(state(3 * TICK_NS + TIMING.dir_setup_ns), (false, false, 2));
    let last = wave.last().unwrap().1;
    assert!(last.is_high(16) && !last.is_high(4) && !last.is_high(5) && !last.is_high(6));
}

#[test]
fn inverted_pins_step_low_going_and_idle_high() {
    // X step and Y direction active low, enable active low.
    let map = stepconf_map(2, &[2, 5, 14]);
    let bench = drive(&map, TIMING, TICK_NS, &[[1, 1, 0, 0, 0, 0]]);
    let wave = bench.waveform(map.idle());
    let idle = map.idle();
    assert!(idle.is_high(2) && idle.is_high(5) && idle.is_high(14));
    // Enable: pin 14 goes low.
    assert!(!wave[0].1.is_high(14));
    // Direction write: X positive (pin 3 high), Y positive = pin 5 low.
    assert_eq!(wave[1].0, 0);
    assert!(wave[1].1.is_high(3) && !wave[1].1.is_high(5));
    // Step edge: pin 2 falls, pin 4 rises.
    assert_eq!(wave[2].0, TIMING.dir_setup_ns);
    assert!(!wave[2].1.is_high(2) && wave[2].1.is_high(4));
    let traces = check_waveform(&map, TIMING, &bench).unwrap();
    assert_eq!(traces, [[1], [1]]);
}

#[test]
fn write_failures_say_whether_the_step_was_taken() {
    let map = stepconf_map(1, &[]);
    for (writes_ok, phase, taken) in [
        (1, "setting the direction pins", false),
        (2, "raising the step pins", false),
        (3, "releasing the step pins", true),
    ] {
        let bench = Bench::new();
        let mut out = output(&bench, map.clone(), TIMING);
        bench.fail_after_writes(writes_ok - 1);
        let err = out
            .write(0, &[1, 0, 0, 0, 0, 0], GapState::Normal)
            .unwrap_err();
        match &err {
            OutputError::Device {
                phase: p,
                step_taken,
                ..
            } => {
                assert_eq!((*p, *step_taken), (phase, taken), "{err}");
            }
            other => panic!("unexpected {other}"),
        }
        assert!(
            err.to_string().starts_with("fake: write failed while"),
            "{err}"
        );
    }
}

#[test]
fn gap_pins_decode_with_inversion_priority_and_filter() {
    let bench = Bench::new();
    let map = stepconf_map(2, &[11]);
    let port = Arc::new(Mutex::new(PortWriter::new(bench.port(), map.idle())));
    let mut gap = ParportGap::new(port, map, 3, "fake");
    let levels = |high: &[Pin]| PinLevels(high.iter().fold(0, |m, &p| m | 1 << p));
    // Pin 11 is the open input, inverted: high means "not open".
    bench.set_inputs(levels(&[11]));
    assert_eq!(
        gap.sample(0).unwrap(),
        GapState::Normal,
        "first reading believed"
    );
    bench.set_inputs(levels(&[]));
    assert_eq!(gap.sample(1).unwrap(), GapState::Normal, "open, 1 of 3");
    assert_eq!(gap.sample(2).unwrap(), GapState::Normal, "open, 2 of 3");
    assert_eq!(gap.sample(3).unwrap(), GapState::Open, "open, confirmed");
    bench.set_inputs(levels(&[10]));
    for t in 4..6 {
        assert_eq!(gap.sample(t).unwrap(), GapState::Open);
    }
    assert_eq!(
        gap.sample(6).unwrap(),
        GapState::Short,
        "short wins over open"
    );
}

/// The probe pin is the contact during probing moves only, read at once; the wire-break pin
/// is read whatever the move.
#[test]
fn probe_and_wire_break_pins() {
    let bench = Bench::new();
    let mut map = stepconf_map(2, &[]);
    map.probe = Some(12);
    map.wire_break = Some(13);
    let port = Arc::new(Mutex::new(PortWriter::new(bench.port(), map.idle())));
    let mut inputs = ParportInputs::new(port, map, "fake");
    let levels = |high: &[Pin]| PinLevels(high.iter().fold(0, |m, &p| m | 1 << p));
    bench.set_inputs(levels(&[12]));
    let r = inputs.sample(0).unwrap();
    assert_eq!(r.contact, Some(true), "contact, unfiltered");
    assert!(!r.wire_broken);
    bench.set_inputs(levels(&[]));
    assert_eq!(inputs.sample(1).unwrap().contact, Some(false), "no contact");
    bench.set_inputs(levels(&[13]));
    assert!(inputs.sample(2).unwrap().wire_broken);
    bench.set_inputs(levels(&[]));
    assert!(!inputs.sample(3).unwrap().wire_broken);
    // Without a probe pin the gap input tells the contact.
    let mut map = stepconf_map(2, &[]);
    map.probe = None;
    let port = Arc::new(Mutex::new(PortWriter::new(bench.port(), map.idle())));
    assert_eq!(
        ParportInputs::new(port, map, "fake")
            .sample(4)
            .unwrap()
            .contact,
        None
    );
}

#[test]
fn a_homing_job_reads_its_switch_pin_not_the_probe() {
    let bench = Bench::new();
    let mut map = stepconf_map(2, &[]);
    map.probe = Some(12);
    let port = Arc::new(Mutex::new(PortWriter::new(bench.port(), map.idle())));
    let mut inputs = ParportInputs::new(port, map, "fake");
    let levels = |high: &[Pin]| PinLevels(high.iter().fold(0, |m, &p| m | 1 << p));
    inputs.probe_reads(crate::vocab::ProbeReads::Switch(crate::vocab::HomeSwitch {
        axis: 0,
        positive: true,
        pin: Some(15),
        at_steps: 0,
    }));
    bench.set_inputs(levels(&[12]));
    assert_eq!(
        inputs.sample(0).unwrap().contact,
        Some(false),
        "the probe is not the switch"
    );
    bench.set_inputs(levels(&[15]));
    assert_eq!(
        inputs.sample(1).unwrap().contact,
        Some(true),
        "the switch is"
    );
    inputs.probe_reads(crate::vocab::ProbeReads::Probe);
    assert_eq!(
        inputs.sample(2).unwrap().contact,
        Some(false),
        "the probe again"
    );
    bench.set_inputs(levels(&[12]));
    assert_eq!(inputs.sample(3).unwrap().contact, Some(true));
}

fn arb_map() -> impl Strategy<Value = PinMap> {
    (
        1usize..=4,
        Just(OUTPUT_PINS.to_vec()).prop_shuffle(),
        any::<u32>(),
        any::<bool>(),
    )
        .prop_map(|(axes, pins, invert_bits, enable)| {
            let mut step = [0; MAX_AXES];
            let mut dir = [0; MAX_AXES];
            for a in 0..axes {
                step[a] = pins[2 * a];
                dir[a] = pins[2 * a + 1];
            }
            PinMap {
                axes,
                step,
                dir,
                enable: enable.then_some(pins[8]),
                flush: None,
                spark: None,
                condition: [0; crate::parport::CONDITION_BITS],
                condition_bits: 0,
                inverted: invert_bits & 0x3_43fe,
                short: None,
                open: None,
                probe: None,
                wire_break: None,
                estop: None,
                limits: Vec::new(),
            }
        })
}

fn arb_timing() -> impl Strategy<Value = (StepTiming, u64)> {
    (
        1u64..20_000,
        0u64..20_000,
        0u64..30_000,
        0u64..30_000,
        0u64..5_000,
    )
        .prop_map(|(len, space, setup, hold, slack)| {
            let timing = StepTiming {
                step_length_ns: len,
                step_space_ns: space,
                dir_setup_ns: setup,
                dir_hold_ns: hold,
            };
            (timing, timing.min_tick_ns() + slack)
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, rng_seed: proptest::test_runner::RngSeed::Fixed(5), ..ProptestConfig::default() })]

    /// Any pin map, inversions and timing that fit a tick: the drives see exactly the steps
    /// given, in order, with every timing rule honoured, and the port ends idle.
    #[test]
    fn drives_see_exactly_the_steps_with_every_timing_rule(
        map in arb_map(),
        (timing, tick_ns) in arb_timing(),
        ticks in proptest::collection::vec(proptest::array::uniform6(-1i8..=1), 1..120),
    ) {
        let bench = drive(&map, timing, tick_ns, &ticks);
        let traces = check_waveform(&map, timing, &bench)?;
        for (axis, trace) in traces.iter().enumerate() {
            let expected: Vec<i8> = ticks.iter().map(|t| t[axis]).filter(|&s| s != 0).collect();
            prop_assert_eq!(trace, &expected, "axis {}", axis);
        }
    }
}

/// The E-stop and limit-switch pins are read every tick; when the consumer stops
/// on them the output's finish leaves the port with the spark off and the drives disabled.
#[test]
fn estop_and_limit_pins_and_the_port_they_leave() {
    let bench = Bench::new();
    let mut map = stepconf_map(2, &[]);
    map.spark = Some(4);
    map.estop = Some(15);
    map.limits = vec![(
        crate::vocab::LimitSwitch {
            axis: crate::vocab::Axis::X,
            positive: true,
        },
        12,
    )];
    let port = Arc::new(Mutex::new(PortWriter::new(bench.port(), map.idle())));
    let mut inputs = ParportInputs::new(port.clone(), map.clone(), "fake");
    let mut out = ParportOutput::new(port, map.clone(), TIMING, bench.clock(), "fake").unwrap();
    let levels = |high: &[Pin]| PinLevels(high.iter().fold(0, |m, &p| m | 1 << p));
    out.moving_in(crate::output::Activity {
        spark: true,
        ..Default::default()
    });
    assert!(!inputs.sample(0).unwrap().safety.tripped());
    bench.set_now(TICK_NS);
    out.write(1, &[1, 0, 0, 0, 0, 0], GapState::Normal).unwrap();
    bench.set_inputs(levels(&[12]));
    assert_eq!(inputs.sample(2).unwrap().safety.limits.to_string(), "X+");
    bench.set_inputs(levels(&[15]));
    let safety = inputs.sample(3).unwrap().safety;
    assert!(safety.estop && safety.limits.is_empty());
    // The consumer stops here: no write for tick 3, the output finishes.
    let before = bench.waveform(map.idle()).last().unwrap().1;
    assert!(before.is_high(4), "sparking while it moved");
    assert_ne!(
        before.is_high(14),
        map.idle().is_high(14),
        "the drives were enabled while it moved"
    );
    bench.set_now(3 * TICK_NS);
    out.finish(crate::output::StopReason::Ended).unwrap();
    let last = bench.waveform(map.idle()).last().unwrap().1;
    assert!(!last.is_high(4), "spark off");
    assert_eq!(
        last,
        map.idle(),
        "every output inactive: the drives' enable dropped"
    );
}
