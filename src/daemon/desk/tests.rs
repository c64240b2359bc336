//! The desk's rules, from a configuration and a machine: no daemon, no threads.

use super::homing::{self, HomingEnd};
use super::manual;
use super::offsets;
use super::*;
use crate::config::Config;
use crate::machine::Machine;
use crate::runtime::{LastProbe, Outcome};
use crate::vocab::Trip;

fn config(overrides: &[&str]) -> Config {
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    Config::load(None, &overrides).expect("a valid configuration")
}

/// The machine of `config`, at machine zero, unhomed, with no state file.
fn machine(config: &Config) -> Machine {
    Machine::open(None, &config.machine).expect("a machine").0
}

fn at<'a>(config: &'a Config, machine: &'a Machine) -> Desk<'a> {
    Desk { config, machine }
}

fn text(order: &Order) -> &str {
    match &order.source {
        Source::Generated { text, .. } => text,
        _ => panic!("a command's job is generated"),
    }
}

fn refused(r: Result<impl Sized, Refusal>) -> String {
    match r {
        Ok(_) => panic!("refused expected"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn axes_are_named_by_one_letter_of_the_machine() {
    let c = config(&[]);
    let m = machine(&c);
    let desk = at(&c, &m);
    assert_eq!(desk.axis(" y ").unwrap(), (1, Axis::Y));
    assert!(refused(desk.axis("Z")).contains("not an axis of this machine (X, Y)"));
    assert!(refused(desk.axis("XY")).contains("not an axis"));
    assert_eq!(desk.axes(&[]).unwrap(), [(0, Axis::X), (1, Axis::Y)]);
}

#[test]
fn homing_by_switch_runs_in_sequence_order_whatever_the_order_named() {
    let c = config(&[]);
    let m = machine(&c);
    let desk = at(&c, &m);
    assert_eq!(homing::by_switch(desk, &[]).unwrap(), [0, 1]);
    let named = ["Y".to_string(), "X".to_string()];
    assert_eq!(homing::by_switch(desk, &named).unwrap(), [0, 1]);
    // An axis's job: the probing search towards its switch, then the latch.
    let job = homing::axis_job(desk, 1);
    assert!(matches!(job.launch.kind, JobKind::Home { switch, .. } if switch.axis == 1));
    let program = text(&job);
    assert!(program.contains("G38.2 Y"), "{program}");
    assert!(program.contains("G38.4 Y"), "{program}");
    // A machine that reads no switches says how to home it instead.
    let c = config(&["gap.kind=\"none\""]);
    let desk = at(&c, &m);
    assert!(refused(homing::by_switch(desk, &[])).contains("`home --here`"));
}

#[test]
fn home_here_refuses_an_axis_with_a_switch_unless_forced() {
    let c = config(&[]);
    let mut m = machine(&c);
    let e = refused(homing::here(&c, &mut m, &["X".to_string()], false));
    assert!(e.contains("X has a home switch"), "{e}");
    assert!(!m.state.homed[0]);
    m.state.position[0] = 1234;
    let said = homing::here(&c, &mut m, &["X".to_string()], true).unwrap();
    assert!(said.starts_with("homed here: X"), "{said}");
    assert!(m.state.homed[0] && !m.state.homed[1]);
    let home = c.homing.axis(0).unwrap().home_position_mm;
    assert_eq!(
        m.state.position[0],
        (home / c.machine.step_mm[0]).round() as i64
    );
}

#[test]
fn a_latch_sets_the_home_position_and_names_the_next_axis() {
    let c = config(&[]);
    let mut m = machine(&c);
    m.homing_queue = vec![1];
    m.state.position[0] = 5_000;
    let switch = match homing::axis_job(at(&c, &m), 0).launch.kind {
        JobKind::Home { switch, .. } => switch,
        _ => unreachable!(),
    };
    // The switch latched where the machine believed X = 4.9 mm.
    let probe = LastProbe {
        probe_mm: Some(vec![4.9, 0.0]),
        probe_contact: Some(true),
    };
    let end = HomingEnd {
        outcome: Outcome::Done,
        error: None,
        last_probe: &probe,
    };
    assert_eq!(homing::latched(&c, &mut m, &switch, end), Some(1));
    let home = c.homing.axis(0).unwrap().home_position_mm;
    let step = c.machine.step_mm[0];
    // The steps taken since the latch (0.1 mm) are kept on top of the home position.
    assert_eq!(
        m.state.position[0],
        5_000 + (home / step).round() as i64 - 4_900
    );
    assert!(m.state.homed[0]);
    assert!(m.homing_queue.is_empty());
    // No contact: the axis stays unhomed and the rest of the queue is dropped.
    m.homing_queue = vec![1];
    let none = LastProbe::default();
    let end = HomingEnd {
        outcome: Outcome::Done,
        error: None,
        last_probe: &none,
    };
    assert_eq!(homing::latched(&c, &mut m, &switch, end), None);
    assert!(m.homing_queue.is_empty());
}

#[test]
fn a_jog_stops_at_the_soft_limit_and_not_past_it() {
    let c = config(&[]);
    let mut m = machine(&c);
    let max = c.machine.travel[0].unwrap().max_mm;
    let desk = at(&c, &m);
    let order = manual::jog(desk, "x", 2.0 * max, Some(100.0)).unwrap();
    assert!(text(&order).contains(&format!("G53 G0 X{max:.6}")));
    assert!(
        order.said.contains("stops at the soft limit"),
        "{}",
        order.said
    );
    assert!(
        matches!(order.launch.kind, JobKind::Jog { feed_mm_per_min } if feed_mm_per_min == 100.0)
    );
    // At the limit, only the other way.
    m.state.position[0] = (max / c.machine.step_mm[0]).round() as i64;
    let desk = at(&c, &m);
    assert!(refused(manual::jog(desk, "X", 1.0, None)).contains("jog the other way"));
    assert!(manual::jog(desk, "X", -1.0, None).is_ok());
    // Less than a step, or a feed below the least, is refused.
    assert!(refused(manual::jog(desk, "X", 1e-4, None)).contains("at least one step"));
    assert!(refused(manual::jog(desk, "X", -1.0, Some(0.0))).contains("jog feed"));
}

#[test]
fn a_tripped_machine_refuses_motion_but_a_jog_away_from_the_switch() {
    let c = config(&[]);
    let mut m = machine(&c);
    m.state.trip = Some(Trip::EStop);
    let desk = at(&c, &m);
    assert!(manual::jog(desk, "X", 1.0, None).is_err());
    assert!(manual::mdi(desk, "G0 X1").is_err());
    assert!(manual::continuous(desk, 0, Axis::X, true, None).is_err());
    assert!(
        homing::by_switch(desk, &[]).is_ok(),
        "the loop refuses a trip before homing"
    );
}

#[test]
fn mdi_runs_in_the_modes_the_last_lines_left() {
    let c = config(&[]);
    let mut m = machine(&c);
    m.mdi_modes.inch = true;
    let desk = at(&c, &m);
    let order = manual::mdi(desk, "G0 X1\n\n").unwrap();
    assert_eq!(text(&order), "G0 X1\n");
    assert!(order.launch.start.modes.inch);
    assert_eq!(order.said, "mdi: checking");
    assert!(refused(manual::mdi(desk, "  \n")).contains("1 to 16384 bytes"));
}

#[test]
fn touch_off_makes_here_read_the_value_in_the_system_named() {
    let c = config(&[]);
    let mut m = machine(&c);
    m.state.position[0] = 12_500;
    let said = offsets::touch_off(&c, &mut m, "X", 2.5, Some("G55")).unwrap();
    assert_eq!(said, "G55 X offset is 10.0000 mm: here reads X2.5000");
    let g55 = crate::gcode::WorkSystem::parse("G55").unwrap();
    assert_eq!(m.state.offsets.get(g55)[0], 10.0);
    assert!(offsets::table(&m).contains("G55"));
    // A zero outside the axis's travel is a typing error: refused, nothing changed.
    let e = refused(offsets::touch_off(&c, &mut m, "X", -1.0e5, Some("G55")));
    assert!(e.contains("outside the axis's travel"), "{e}");
    assert_eq!(m.state.offsets.get(g55)[0], 10.0);
    assert!(refused(offsets::touch_off(&c, &mut m, "X", 1.0, Some("G60"))).contains("work system"));
    m.state.trip = Some(Trip::EStop);
    assert!(offsets::touch_off(&c, &mut m, "X", 1.0, None).is_err());
}

#[test]
fn the_pendant_renews_a_held_button_and_latches_a_jog_stopped_under_it() {
    use super::pendant::{LetGo, Pendant, Press};
    let dead_man = manual::DEAD_MAN.as_nanos() as u64;
    let mut p = Pendant::default();
    assert_eq!(p.press(0, true, 0, false), Press::New);
    p.started(0, true, 0);
    assert_eq!(p.deadline_ns(), Some(dead_man));
    // Renewed within the dead-man: the deadline moves on; another button is refused.
    assert_eq!(
        p.press(0, true, 100, false),
        Press::Renewed {
            deadline_ns: 100 + dead_man
        }
    );
    assert_eq!(
        p.press(1, false, 120, false),
        Press::Busy {
            axis: 0,
            positive: true
        }
    );
    assert!(!p.dead_man_due(99 + dead_man, false));
    assert!(p.dead_man_due(100 + dead_man, false));
    assert!(p.dead_man_due(200, true), "the job's thread held it first");
    // Its job stopped it (a hold): the press is the latch's to make.
    assert_eq!(p.press(0, true, 200, true), Press::StoppedInJob);
    assert!(p.stop(true, 200));
    assert!(!p.is_moving());
    // The same button, still held, is refused for as long as it is pressed again within the
    // dead-man; a pause longer than that is a new press.
    assert_eq!(p.press(0, true, 200 + dead_man, false), Press::Latched);
    assert_eq!(p.press(0, true, 200 + 2 * dead_man, false), Press::Latched);
    assert_eq!(p.press(0, true, 201 + 3 * dead_man, false), Press::New);
    // Let go (`jog-stop`) ends a latch at once; with nothing moving or latched it is refused.
    p.started(0, true, 0);
    p.stop(true, 10);
    assert_eq!(p.let_go(), LetGo::AlreadyStopped);
    assert_eq!(p.press(0, true, 11, false), Press::New);
    assert_eq!(p.let_go(), LetGo::Nothing);
    p.started(0, true, 20);
    assert_eq!(p.let_go(), LetGo::Stop);
    // A stop without a latch (`jog-stop`) leaves the next press free.
    assert!(p.stop(false, 30));
    assert_eq!(p.press(0, true, 31, false), Press::New);
    assert!(!p.stop(true, 40), "nothing was moving");
}

fn seen(estop_now: bool, estop_seen: bool, limits: &[&str]) -> crate::runtime::idle::IdleSeen {
    let mut set = crate::vocab::LimitSet::default();
    for s in limits {
        set.insert(crate::vocab::LimitSwitch::parse(s).unwrap());
    }
    crate::runtime::idle::IdleSeen {
        now: Some(crate::vocab::SafetyInputs {
            estop: estop_now,
            limits: set,
        }),
        seen: crate::vocab::SafetyInputs {
            estop: estop_seen,
            limits: set,
        },
        fault: None,
    }
}

#[test]
fn idle_inputs_trip_the_machine_and_only_a_released_estop_is_reset() {
    let c = config(&[]);
    let mut m = machine(&c);
    assert!(!super::trips::watch(&mut m, seen(false, false, &[])));
    assert!(refused(super::trips::reset(&mut m, false)).contains("nothing to reset"));
    // A pulse already released still trips (the fine thread latched it).
    assert!(super::trips::watch(&mut m, seen(false, true, &[])));
    assert_eq!(m.state.trip, Some(Trip::EStop));
    // While tripped by the E-stop, nothing new trips; a reset needs the input released.
    assert!(!super::trips::watch(&mut m, seen(true, true, &["X+"])));
    assert!(refused(super::trips::reset(&mut m, true)).contains("still reads pressed"));
    assert!(super::trips::reset(&mut m, false).is_ok());
    assert_eq!(m.state.trip, None);
    // A limit switch holds until it reads open; reset is not for it.
    assert!(super::trips::watch(&mut m, seen(false, false, &["X+"])));
    let switch = crate::vocab::LimitSwitch::parse("X+").unwrap();
    assert_eq!(m.state.trip, Some(Trip::Limit(switch)));
    assert!(refused(super::trips::reset(&mut m, false)).contains("jog away from it"));
    assert!(!super::trips::watch(&mut m, seen(false, false, &["X+"])));
    assert!(!super::trips::watch(&mut m, seen(false, false, &[])));
    assert_eq!(m.state.trip, None);
    // A device fault is an E-stop.
    let fault = crate::runtime::idle::IdleSeen {
        fault: Some("HAL's real-time side stopped".into()),
        ..Default::default()
    };
    super::trips::watch(&mut m, fault);
    assert_eq!(m.state.trip, Some(Trip::EStop));
}

/// A job of one tick that ended with `outcome` where it started.
fn ended(outcome: Outcome) -> crate::runtime::JobSummary {
    crate::runtime::JobSummary {
        program: "job".into(),
        outcome,
        error: None,
        limit_switch: None,
        limits_closed: Vec::new(),
        axes: vec!["X".into(), "Y".into()],
        blocks: 1,
        segments: 1,
        steps_per_axis: vec![0, 0],
        end_steps: vec![0, 0],
        program_end_steps: vec![0, 0],
        end_mm: vec![0.0, 0.0],
        events_forward: 0,
        events_backward: 0,
        servo: Default::default(),
        last_probe: Default::default(),
        overruns: 0,
        missed_deadlines: 0,
        latency_us: None,
        tick_us: 100,
        ticks: 1,
        virtual_time: true,
        virtual_time_s: 1e-4,
        wall_time_s: 0.0,
        producer_busy_s: 0.0,
        peak_rss_kib: 0,
        buffer_capacity: 1,
        buffer_high_water: 0,
        events_dropped: 0,
        trace_dropped: 0,
        rt_refused: Vec::new(),
        stopped_at: None,
        stages: Vec::new(),
    }
}

#[test]
fn a_job_ended_by_an_estop_trips_and_unhomes_the_machine() {
    let c = config(&["homing.lost_on_estop=true"]);
    let mut m = machine(&c);
    m.state.homed.iter_mut().for_each(|h| *h = true);
    let summary = ended(Outcome::Estop);
    super::trips::after_job(&c, &mut m, &summary);
    assert_eq!(m.state.trip, Some(Trip::EStop));
    assert!(m.state.homed.iter().all(|h| !h));
}

/// The checkpoint of `part.nc` stopped at `position_steps`, started at `start` (steps).
fn stopped_job(position_steps: Vec<i64>, start: Option<Vec<i64>>) -> crate::checkpoint::Checkpoint {
    crate::checkpoint::Checkpoint {
        version: 1,
        program: "part.nc".into(),
        program_sha256: "5ca1ab1e".into(),
        motion_sha256: String::new(),
        motion_settings: Default::default(),
        reason: crate::checkpoint::Reason::Abort,
        still: true,
        line: 7,
        segment: 0,
        step: 0,
        segment_steps: 0,
        parameter: None,
        dwell_s: 0.0,
        axes: vec!["X".into(), "Y".into()],
        position_mm: position_steps.iter().map(|&s| s as f64 * 0.001).collect(),
        position_steps,
        written_unix_s: 0,
        start: start.map(|position_steps| crate::checkpoint::StartRecord {
            position_steps,
            work_system: "G54".into(),
            offsets_mm: Default::default(),
        }),
        from_line: None,
        passes: Vec::new(),
        tab_mm: 0.0,
        kerf_end_mm: Vec::new(),
        technology: None,
    }
}

#[test]
fn a_run_from_a_line_asks_where_the_wire_stands_and_holds_it_to_the_stopped_job() {
    use crate::path::{Approach, FromLine, WireAt};
    let c = config(&[]);
    let mut m = machine(&c);
    let from = FromLine {
        line: 5,
        approach: Approach::Path,
        pass: None,
        wire_at: WireAt::StartHole,
    };
    let e = refused(at(&c, &m).recovery("part.nc", &from, None, None));
    assert!(e.contains("say where that is. --wire-at start-hole"), "{e}");
    // No stopped job: the operator's word, and the job starts here.
    let here = at(&c, &m)
        .recovery("part.nc", &from, Some(WireAt::StartHole), None)
        .unwrap();
    assert_eq!((here.kerf_end, here.sha256), (None, None));
    let e = refused(at(&c, &m).recovery("part.nc", &from, Some(WireAt::Stopped), None));
    assert!(e.contains("no stopped job of it is kept"), "{e}");

    // A job started at X1 Y1 and stopped at X4 Y1.5; the wire stands where it stopped.
    let cp = stopped_job(vec![4000, 1500], Some(vec![1000, 1000]));
    m.state.position[..2].copy_from_slice(&[4000, 1500]);
    let e = refused(at(&c, &m).recovery("part.nc", &from, Some(WireAt::StartHole), Some(&cp)));
    assert!(
        e.contains("stands at X4.0000 Y1.5000 (G54), not at the start hole X1.0000 Y1.0000")
            && e.contains("run with --wire-at stopped"),
        "{e}"
    );
    let back = at(&c, &m)
        .recovery("part.nc", &from, Some(WireAt::Stopped), Some(&cp))
        .unwrap();
    assert_eq!(
        back.start.position_mm.as_slice()[..2],
        [1.0, 1.0],
        "read from the start hole"
    );
    assert_eq!(
        back.kerf_end.unwrap().as_slice()[..2],
        [4.0, 1.5],
        "the wire is the kerf's end"
    );
    assert_eq!(back.sha256.as_deref(), Some("5ca1ab1e"));
    // Within 0.01 mm of where it stopped is there; 0.02 mm is not.
    m.state.position[0] = 4009;
    assert!(
        at(&c, &m)
            .recovery("part.nc", &from, Some(WireAt::Stopped), Some(&cp))
            .is_ok()
    );
    m.state.position[0] = 4020;
    let e = refused(at(&c, &m).recovery("part.nc", &from, Some(WireAt::Stopped), Some(&cp)));
    assert!(
        e.contains("not where its job stopped (X4.0000 Y1.5000 (G54), line 7)"),
        "{e}"
    );
    // At the start hole: the kerf ends where the job stopped.
    m.state.position[..2].copy_from_slice(&[1000, 1000]);
    let hole = at(&c, &m)
        .recovery("part.nc", &from, Some(WireAt::StartHole), Some(&cp))
        .unwrap();
    assert_eq!(hole.start.position_mm.as_slice()[..2], [1.0, 1.0]);
    assert_eq!(hole.kerf_end.unwrap().as_slice()[..2], [4.0, 1.5]);
    // A direct approach lifts out: nothing to say.
    let direct = FromLine {
        approach: Approach::Direct,
        ..from
    };
    assert!(
        at(&c, &m)
            .recovery("part.nc", &direct, None, Some(&cp))
            .is_ok()
    );
    assert!(
        refused(at(&c, &m).recovery("part.nc", &direct, Some(WireAt::Stopped), None))
            .contains("--wire-at is for the path approach")
    );
}

#[test]
fn a_resume_starts_only_where_its_checkpoint_stopped() {
    let c = config(&[]);
    let mut m = machine(&c);
    let cp = stopped_job(vec![100, 0], None);
    let e = refused(at(&c, &m).resume_start(&cp, false));
    assert!(
        e.contains("X0.0000 Y0.0000") && e.contains("X0.1000 Y0.0000"),
        "{e}"
    );
    assert!(at(&c, &m).resume_start(&cp, true).is_ok(), "forced");
    m.state.position[0] = 100;
    assert_eq!(
        at(&c, &m).resume_start(&cp, false).unwrap(),
        crate::gcode::WorkStart::default()
    );
}

#[test]
fn a_touch_cycle_orders_its_moves_and_fails_on_a_move_that_did_not_end() {
    let c = config(&[]);
    let mut m = machine(&c);
    let mut cycles = super::touch::TouchCycles::default();
    let e = refused(cycles.start(&c, &mut m, "edge X+", Some("G60")));
    assert!(e.contains("not a work system"), "{e}");
    let order = cycles.start(&c, &mut m, "edge X+", Some("G55")).unwrap();
    assert!(order.said.starts_with("find 1: "), "{}", order.said);
    assert!(matches!(order.launch.kind, JobKind::Touch { .. }));
    assert!(
        matches!(&order.source, Source::Generated { name, .. } if name == "find-approach-xplus")
    );
    assert_eq!(cycles.status().unwrap().state, "running");
    let aborted = ended(Outcome::Stopped);
    assert!(cycles.moved(&c, &mut m, &aborted).is_none());
    let status = cycles.status().unwrap();
    assert_eq!(status.state, "failed");
    assert!(
        status.message.contains("the move did not end"),
        "{}",
        status.message
    );
    // A moved job with no cycle in hand is none of the cycles' business.
    assert!(cycles.moved(&c, &mut m, &aborted).is_none());
}
