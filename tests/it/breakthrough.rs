//! Breakthrough on a drilling move (`[sinker] breakthrough`, issue [7/9]): the simulator's
//! work is 3 mm thick along the drill (`sim.breakthrough_at_mm`); from the pulse log, the
//! deepest the electrode went is the breakthrough plus `breakthrough_extra_mm` (within a
//! step), the rest of the plunge was dropped and the program's retract ran from there.

use crate::common;

use edmd::output::read_pulse_log;

const STEP: f64 = 0.001;
const EXTRA_MM: f64 = 0.5;

const DRILL: &str = "G21 G90\nG0 X0 Y0 Z0\nG1 Z-5 F30\nG0 Z5\nM2\n";

/// Drills through work `thickness` mm thick: the deepest Z (mm), the last position, stderr.
fn drill(name: &str, thickness: f64, on: bool) -> (f64, [i64; 3], String) {
    let dir = common::scratch("breakthrough", name);
    let program = dir.join("drill.ngc");
    std::fs::write(&program, DRILL).unwrap();
    let pulses = dir.join("drill.csv");
    let sets = [
        "machine.axes=[\"X\",\"Y\",\"Z\"]".to_string(),
        "machine.step_mm=[0.001,0.001,0.001]".to_string(),
        "gap.kind=\"sim\"".to_string(),
        format!("sim.breakthrough_at_mm={thickness}"),
        "sim.model=\"kinematic\"".to_string(),
        format!("sinker.breakthrough={on}"),
        format!("sinker.breakthrough_extra_mm={EXTRA_MM}"),
        "log.format=\"plain\"".to_string(),
    ];
    let mut args = Vec::new();
    for s in &sets {
        args.extend(["--set", s.as_str()]);
    }
    let out = common::run_to_pulse_log(&program, &pulses, &args);
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(out.status.success(), "{stderr}");
    let (_, rows) = read_pulse_log(&pulses).unwrap();
    let mut at = [0i64; 3];
    let mut deepest = 0i64;
    for r in &rows {
        for (a, s) in at.iter_mut().zip(&r.steps) {
            *a += i64::from(*s);
        }
        deepest = deepest.min(at[2]);
    }
    (deepest as f64 * STEP, at, stderr)
}

#[test]
fn a_breakthrough_stops_the_plunge_its_extra_past_the_work() {
    let (deepest, end, log) = drill("through", 3.0, true);
    let past = -deepest - 3.0;
    eprintln!("broke through 3.000 mm of work, went {past:.4} mm past it");
    assert!(
        (past - EXTRA_MM).abs() <= STEP + 1e-9,
        "{past} mm past the work: {log}"
    );
    // The rest of the plunge was dropped; the retract ran from where it stopped.
    assert_eq!(end, [0, 0, 5000]);
    assert!(
        log.contains("breakthrough at t=")
            && log.contains("the last spark at X0.0000 Y0.0000 Z-3.0"),
        "{log}"
    );
}

#[test]
fn a_drill_that_does_not_break_through_goes_to_its_end() {
    // Work thicker than the plunge: the whole move, and a warning.
    let (deepest, end, log) = drill("thick", 10.0, true);
    assert_eq!(deepest, -5.0);
    assert_eq!(end, [0, 0, 5000]);
    assert!(log.contains("without breaking through"), "{log}");
    // Off: the plunge goes on through the open to its end, as programmed.
    let (deepest, _, log) = drill("off", 3.0, false);
    assert_eq!(deepest, -5.0);
    assert!(!log.contains("breakthrough at"), "{log}");
}
