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
