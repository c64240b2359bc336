//! Outputs and gap inputs end to end: whole jobs through the parallel port's encoding (on
//! the recording fake), the port's startup errors through the real binary, the fault
//! injector and a real full disk, the tracer, and the closed-loop simulator.

use crate::common;

use std::path::{Path, PathBuf};

use common::repo;
use std::process::{Command, Output};
use std::sync::Arc;

use edmd::config::Config;
use edmd::gap::{GapError, GapSensor, GapState, ScriptGap};
use edmd::output::{OutputError, PulseOutput, read_pulse_log};
use edmd::parport::fake::{Bench, RecordingPort, VirtualClock};
use edmd::parport::{ParportOutput, PinMap, PortWriter, StepTiming};
use edmd::runtime::{self, Outcome};
use edmd::vocab::MAX_AXES;
use parking_lot::Mutex;

const PROGRAM: &str = "tests/data/runtime-path.nc";
/// The program's end in steps (1 µm).
const PROGRAM_END: [i64; 2] = [7500, 8250];

fn scratch(name: &str) -> PathBuf {
    common::scratch("io", name)
}

fn config(overrides: &[&str]) -> Config {
    // Jobs run in the test's own process: no SCHED_FIFO, no mlockall of the test harness.
    let overrides: Vec<String> = ["fine.rt_priority=0", "fine.lock_memory=false"]
        .iter()
        .chain(overrides)
        .map(|s| s.to_string())
        .collect();
    Config::load(None, &overrides).unwrap()
}

/// `edmd run PROGRAM --summary DIR/summary.json --set ...` in the repository.
/// The simulated gap's kinematic model: placed debris, erosion at a set rate.
const KINEMATIC: &str = "sim.model=\"kinematic\"";

fn edmd_run(program: &str, dir: &Path, sets: &[&str]) -> (Output, serde_json::Value) {
    let summary = dir.join("summary.json");
    let _ = std::fs::remove_file(&summary);
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_edmd"));
    cmd.args(["run", program, "--summary"])
        .arg(&summary)
        .current_dir(repo());
    for s in sets {
        cmd.args(["--set", s]);
    }
    let out = cmd.output().expect("edmd runs");
    let json = std::fs::read_to_string(&summary)
        .map(|t| serde_json::from_str(&t).expect("summary is JSON"))
        .unwrap_or(serde_json::Value::Null);
    (out, json)
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn end_steps(summary: &serde_json::Value) -> Vec<i64> {
    summary["end_steps"]
        .as_array()
        .expect("end_steps")
        .iter()
        .map(|v| v.as_i64().unwrap())
        .collect()
}

// ---- the parallel port's encoding under whole jobs ----------------------------------------

/// Puts the fake's clock at each tick's start before the port output runs, as the real-time
/// loop's wake-up would; with `press`, sets the status pins to its levels once the job's tick
/// reaches its tick (a switch pressed mid-job).
struct AtTickTime<O> {
    inner: O,
    bench: Bench,
    tick_ns: u64,
    press: Option<(u64, edmd::parport::PinLevels)>,
}

impl<O: PulseOutput> PulseOutput for AtTickTime<O> {
    fn write(
        &mut self,
        tick: u64,
        steps: &[i8; MAX_AXES],
        gap: GapState,
    ) -> Result<(), OutputError> {
        self.bench.set_now(tick * self.tick_ns);
        if let Some((at_tick, levels)) = self.press
            && tick + 1 >= at_tick
        {
            self.bench.set_inputs(levels);
        }
        self.inner.write(tick, steps, gap)
    }

    fn finish(&mut self, why: edmd::output::StopReason) -> Result<(), OutputError> {
        self.inner.finish(why)
    }
}

type FakePortOutput = AtTickTime<ParportOutput<RecordingPort, VirtualClock>>;

/// A parport output of `config`'s pin map and timing on a fresh recording fake.
fn fake_port(config: &Config) -> (FakePortOutput, Bench, PinMap, StepTiming) {
    let bench = Bench::new();
    let map = PinMap::from_config(config);
    let timing = StepTiming::from_config(config);
    let port: Arc<Mutex<PortWriter<RecordingPort>>> =
        Arc::new(Mutex::new(PortWriter::new(bench.port(), map.idle())));
    let output = ParportOutput::new(port, map.clone(), timing, bench.clock(), "fake-port").unwrap();
    let output = AtTickTime {
        inner: output,
        bench: bench.clone(),
        tick_ns: config.fine.tick.ns(),
        press: None,
    };
    (output, bench, map, timing)
}

/// Runs the test program in virtual time with this output and gap source.
fn job_on(
    config: &Config,
    output: impl PulseOutput + Send + 'static,
    gap: impl GapSensor + Send + 'static,
) -> runtime::JobSummary {
    job_with_inputs(config, output, gap, edmd::inputs::NoInputs)
}

/// [`job_on`] with these machine inputs.
fn job_with_inputs(
    config: &Config,
    output: impl PulseOutput + Send + 'static,
    gap: impl GapSensor + Send + 'static,
    inputs: impl edmd::inputs::MachineInputs + Send + 'static,
) -> runtime::JobSummary {
    let never = std::sync::atomic::AtomicBool::new(false);
    let published = Arc::new(runtime::Published::new(4096));
    job_steered(config, output, gap, inputs, published, &never).summary
}

/// The test program's job with these devices, steered through `published` and `stop` (as
/// the daemon steers one), in `config`'s time.
fn job_steered(
    config: &Config,
    output: impl PulseOutput + Send + 'static,
    gap: impl GapSensor + Send + 'static,
    inputs: impl edmd::inputs::MachineInputs + Send + 'static,
    published: Arc<runtime::Published>,
    stop: &std::sync::atomic::AtomicBool,
) -> runtime::JobEnd {
    let program = runtime::JobProgram::in_place(&repo().join(PROGRAM)).unwrap();
    let check = runtime::precheck(
        &program,
        config,
        &Default::default(),
        &edmd::path::CutPlan::default(),
        &runtime::Progress::new(),
    )
    .unwrap();
    let spec = runtime::JobSpec::from_config(config, false);
    let fine = runtime::FineThread::start(&spec.run_loop, None).unwrap();
    let io = runtime::JobIo {
        output: Some(Box::new(output)),
        gap: Some(Box::new(gap)),
        inputs: Some(Box::new(inputs)),
        gap_inputs: None,
        probe_reads: Default::default(),
        tracer: None,
        recording: None,
        progress: None,
    };
    let job = runtime::JobRun {
        program: &program,
        check: &check,
        spec: &spec,
        resume: None,
    };
    runtime::run(&fine, job, io, published, stop)
}

/// Runs the test program in virtual time through a parport output on the recording fake,
/// with a gap schedule; returns the summary, the bench, the map and the timing.
fn parport_job(
    overrides: &[&str],
    gap: ScriptGap,
) -> (runtime::JobSummary, Bench, PinMap, StepTiming) {
    let config = config(overrides);
    let (output, bench, map, timing) = fake_port(&config);
    (job_on(&config, output, gap), bench, map, timing)
}

fn sums(steps: &[Vec<i8>]) -> Vec<i64> {
    steps
        .iter()
        .map(|axis| axis.iter().map(|&s| s as i64).sum())
        .collect()
}

#[test]
fn a_whole_job_on_the_port_reaches_the_program_end_with_every_timing_rule() {
    // Shorts make the drives reverse: direction changes under the timing rules.
    let gap = ScriptGap::from_changes(vec![
        (100_000, GapState::Short),
        (103_000, GapState::Normal),
        (300_000, GapState::Short),
        (301_000, GapState::Normal),
    ]);
    let (summary, bench, map, timing) = parport_job(&["gap.kind=script"], gap);
    assert_eq!(summary.outcome, Outcome::Done, "{summary:?}");
    assert_eq!(summary.servo.shorts, 2);
    let seen = bench.drive_steps(&map, timing).unwrap();
    assert_eq!(sums(&seen), PROGRAM_END.to_vec(), "what the drives counted");
    assert_eq!(summary.end_steps, PROGRAM_END.to_vec(), "the ledger");
    let pulses: Vec<u64> = seen.iter().map(|a| a.len() as u64).collect();
    assert_eq!(
        pulses, summary.steps_per_axis,
        "every pulse reached a drive"
    );
    assert!(
        seen.iter().any(|a| a.contains(&-1)),
        "the turn-backs reversed an axis"
    );
}

#[test]
fn inverted_pins_and_other_pins_carry_the_same_job() {
    let gap = ScriptGap::from_changes(vec![
        (150_000, GapState::Short),
        (152_000, GapState::Normal),
    ]);
    let (summary, bench, map, timing) = parport_job(
        &[
            "gap.kind=script",
            "parport.step_pins=[14, 9]",
            "parport.dir_pins=[1, 16]",
            "parport.enable_pin=17",
            "parport.invert_pins=[14, 16, 17]",
            "parport.dir_setup_ns=1000",
            "parport.step_length_ns=2000",
        ],
        gap,
    );
    assert_eq!(summary.outcome, Outcome::Done);
    assert_eq!(map.step[..2], [14, 9]);
    assert!(
        map.idle().is_high(14) && map.idle().is_high(17),
        "active-low idles high"
    );
    let seen = bench.drive_steps(&map, timing).unwrap();
    assert_eq!(sums(&seen), PROGRAM_END.to_vec());
}

#[test]
fn a_port_write_error_mid_job_stops_and_the_ledger_is_what_the_drives_got() {
    // The fake port dies after 10,000 writes: somewhere in a tick, at some phase.
    for budget in [10_000u64, 10_001, 10_002] {
        let config = config(&["gap.kind=none"]);
        let (output, bench, map, _) = fake_port(&config);
        bench.fail_after_writes(budget);
        let summary = job_on(&config, output, edmd::gap::AlwaysNormal);
        assert_eq!(summary.outcome, Outcome::OutputError);
        let error = summary.error.clone().unwrap();
        assert!(
            error.starts_with("fake-port: write failed while"),
            "{error}"
        );
        // The drives' count from the pins that did change. A failed release leaves a pulse
        // open on the wire (the port died): count edges without the release check.
        let writes = bench.writes();
        assert_eq!(writes.len() as u64, budget);
        let wave = bench.waveform(map.idle());
        let mut seen = [0i64; 2];
        let mut prev = map.idle();
        for (_, levels) in wave {
            for (axis, count) in seen.iter_mut().enumerate() {
                let (sp, dp) = (map.step[axis], map.dir[axis]);
                if levels.is_high(sp) && !prev.is_high(sp) {
                    *count += if levels.is_high(dp) { 1 } else { -1 };
                }
            }
            prev = levels;
        }
        assert_eq!(summary.end_steps, seen.to_vec(), "{error}");
        assert_ne!(summary.end_steps, PROGRAM_END.to_vec());
    }
}

/// A gap input that dies at a given tick.
struct DyingGap(u64);

impl GapSensor for DyingGap {
    fn sample(&mut self, tick: u64) -> Result<GapState, GapError> {
        if tick >= self.0 {
            return Err(GapError::Device {
                path: "fake-status".to_string(),
                source: std::io::Error::from_raw_os_error(libc::EIO),
            });
        }
        Ok(GapState::Normal)
    }
}

#[test]
fn a_gap_input_error_stops_before_the_tick_moves() {
    let summary = job_on(
        &config(&["gap.kind=none"]),
        edmd::output::NullOutput,
        DyingGap(50_000),
    );
    assert_eq!(summary.outcome, Outcome::GapError);
    assert_eq!(summary.ticks, 50_000);
    assert!(summary.error.unwrap().contains("cannot read the gap input"));
    assert_eq!(
        summary.steps_per_axis.iter().sum::<u64>() as i64,
        summary.end_steps.iter().sum::<i64>(),
        "forward only: pulses are the position"
    );
}

// ---- the port's startup errors through the binary ------------------------------------------

/// `edmd run` on the parallel port (real time) with one more override.
fn run_on_port(name: &str, extra: &str) -> (Output, serde_json::Value) {
    let sets = [
        "output.kind=parport",
        "gap.kind=parport",
        "fine.virtual_time=false",
        extra,
    ];
    edmd_run(PROGRAM, &scratch(name), &sets)
}

#[test]
fn dev_null_is_refused_as_not_a_parallel_port_before_anything_moves() {
    let (out, summary) = run_on_port("devnull", "output.path=/dev/null");
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains("edmd: error: /dev/null: not a parallel port"),
        "{err}"
    );
    assert!(err.contains("/dev/parport0"), "{err}");
    assert!(summary.is_null(), "no job ran");
}

#[test]
fn a_missing_port_names_the_modules_to_load() {
    let (out, _) = run_on_port("missing", "output.path=/dev/parport-edmd-test-missing");
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(
        err.contains("/dev/parport-edmd-test-missing: no such parallel port"),
        "{err}"
    );
    assert!(err.contains("modprobe parport_pc ppdev"), "{err}");
}

#[test]
fn port_settings_that_cannot_work_are_config_errors() {
    let (out, _) = run_on_port("badport", "parport.dir_hold_ns=40000");
    let dir = scratch("badport");
    assert_eq!(out.status.code(), Some(2));
    let err = stderr(&out);
    assert!(err.contains("fine.tick_us"), "{err}");
    assert!(err.contains("raise fine.tick_us to at least 65"), "{err}");

    let (out, _) = edmd_run(PROGRAM, &dir, &["parport.dir_pins=[2, 5]"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains(
            "--set parport.dir_pins=[2, 5]: parport.dir_pins: pin 2 is already used by \
             parport.step_pins"
        ),
        "{}",
        stderr(&out)
    );
    let (out, _) = edmd_run(PROGRAM, &dir, &["parport.short_pin=3"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("3 is not an input pin"),
        "{}",
        stderr(&out)
    );
}

// ---- the fault injector and a real failing device ------------------------------------------

#[test]
fn an_injected_write_error_stops_keeps_the_position_and_exits_1() {
    let dir = scratch("fault");
    let log = dir.join("pulses.csv");
    let (out, summary) = edmd_run(
        PROGRAM,
        &dir,
        &[
            "output.kind=file",
            &format!("output.path={}", log.display()),
            "gap.kind=none",
            "output.fault_at_tick=200000",
        ],
    );
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains("edmd: error: output error: injected fault at tick 200000"),
        "{err}"
    );
    assert_eq!(summary["outcome"], "output-error");
    assert_eq!(summary["ticks"], 200_001);
    // The log has every tick before the fault and none after: its replay is the ledger.
    let (_, rows) = read_pulse_log(&log).unwrap();
    assert!(rows.iter().all(|r| r.tick < 200_000));
    let mut pos = [0i64; 2];
    for r in &rows {
        pos[0] += r.steps[0] as i64;
        pos[1] += r.steps[1] as i64;
    }
    assert_eq!(end_steps(&summary), pos.to_vec());
    assert!(
        pos != [0, 0] && pos != PROGRAM_END,
        "stopped mid-job: {pos:?}"
    );
}

#[test]
fn a_full_disk_under_the_pulse_log_is_an_output_error() {
    if !Path::new("/dev/full").exists() {
        return;
    }
    let dir = scratch("full");
    let (out, summary) = edmd_run(
        PROGRAM,
        &dir,
        &["output.kind=file", "output.path=/dev/full", "gap.kind=none"],
    );
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains("/dev/full: cannot write the pulse log"),
        "{err}"
    );
    assert_eq!(summary["outcome"], "output-error");
    assert!(end_steps(&summary)[0] > 0, "the failure came mid-job");
}

// ---- signals ------------------------------------------------------------------------------

#[test]
fn sigint_stops_the_job_where_it_is_and_the_log_matches_the_ledger() {
    let dir = scratch("sigint");
    let log = dir.join("pulses.csv");
    let summary = dir.join("summary.json");
    // A slow feed: tens of seconds of wall time, interrupted after half a second.
    let child = Command::new(env!("CARGO_BIN_EXE_edmd"))
        .args(["run", "programs/jin-table1-g06_2.nc", "--summary"])
        .arg(&summary)
        .args([
            "--set",
            "output.kind=file",
            "--set",
            &format!("output.path={}", log.display()),
            "--set",
            "gap.kind=none",
            "--set",
            "servo.normal_feed_mm_per_min=3",
        ])
        .current_dir(repo())
        .stderr(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(500));
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("edmd: error: stopped: a stop was requested"),
        "{}",
        stderr(&out)
    );
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    assert_eq!(s["outcome"], "stopped");
    let (_, rows) = read_pulse_log(&log).unwrap();
    let mut pos = [0i64; 2];
    for r in &rows {
        pos[0] += r.steps[0] as i64;
        pos[1] += r.steps[1] as i64;
    }
    assert_eq!(end_steps(&s), pos.to_vec(), "the log has every step taken");
    assert_ne!(s["end_steps"], s["program_end_steps"], "stopped mid-job");
}

// ---- the tracer ----------------------------------------------------------------------------

#[test]
fn the_tracer_logs_gap_and_direction_changes() {
    let dir = scratch("trace");
    let script = dir.join("gap.txt");
    std::fs::write(&script, "100000 short\n103000 normal\n").unwrap();
    let (out, summary) = edmd_run(
        PROGRAM,
        &dir,
        &[
            "output.kind=null",
            "gap.kind=script",
            &format!("gap.script={}", script.display()),
            "gap.trace=true",
            "output.trace=true",
        ],
    );
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let err = stderr(&out);
    let traces: Vec<&str> = err.lines().filter(|l| l.contains("edmd::trace")).collect();
    let has = |needle: &str| traces.iter().any(|l| l.contains(needle));
    assert!(
        has("(tick 0): gap (first reading) -> normal"),
        "{traces:#?}"
    );
    assert!(has("(tick 100000): gap normal -> short"), "{traces:#?}");
    assert!(has("(tick 103000): gap short -> normal"), "{traces:#?}");
    assert!(has("axis X now steps +"), "{traces:#?}");
    assert!(has("axis X now steps -"), "{traces:#?}");
    assert_eq!(summary["trace_dropped"], 0);
}

// ---- the closed-loop simulator -------------------------------------------------------------

/// The summary without what the host measures (wall time, producer time, memory).
fn without_timing(mut summary: serde_json::Value) -> serde_json::Value {
    for key in ["wall_time_s", "producer_busy_s", "peak_rss_kib"] {
        summary[key] = serde_json::Value::Null;
    }
    summary
}

#[test]
fn the_kinematic_sim_places_debris_by_the_mm_on_both_papers_curves_deterministically() {
    let dir = scratch("sim");
    // sim.debris_shorts_per_mm = 0.1 over the cutting past its first 0.3 mm: Huang's curve
    // is 49.0 mm, Jin's 1151.3 mm.
    for (program, shorts) in [
        ("programs/huang-table1-g38.nc", 5),
        ("programs/jin-table1-g06_2.nc", 115),
    ] {
        let (out, a) = edmd_run(program, &dir, &[KINEMATIC]);
        assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
        assert_eq!(a["shorts"], shorts, "{program}");
        assert_eq!(a["turn_backs"], shorts, "{program}");
        assert_eq!(a["end_steps"], a["program_end_steps"], "{program}");
        let (_, b) = edmd_run(program, &dir, &[KINEMATIC]);
        assert_eq!(
            without_timing(a.clone()),
            without_timing(b),
            "same seed, same job"
        );
        let (_, c) = edmd_run(program, &dir, &["sim.seed=2", KINEMATIC]);
        assert_ne!(a["ticks"], c["ticks"], "another seed, other shorts");
        assert_eq!(c["end_steps"], c["program_end_steps"]);
    }
}

#[test]
fn a_servo_feed_above_the_erosion_rate_gives_proximity_shorts_and_still_ends_exactly() {
    let dir = scratch("proximity");
    let (out, s) = edmd_run(
        "programs/huang-table1-g38.nc",
        &dir,
        &[
            "sim.debris_shorts_per_mm=0",
            "sim.model=\"kinematic\"",
            "servo.normal_feed_mm_per_min=90",
        ],
    );
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(s["shorts"].as_u64().unwrap() > 10, "{s}");
    assert_eq!(s["end_steps"], s["program_end_steps"]);
    let (_, none) = edmd_run(
        "programs/huang-table1-g38.nc",
        &dir,
        &["sim.debris_shorts_per_mm=0", "sim.model=\"kinematic\""],
    );
    assert_eq!(none["shorts"], 0, "erosion outpaces the default feed");
}

#[test]
fn scripted_sim_events_reach_the_job_and_bad_ones_are_located() {
    let dir = scratch("events");
    let events = dir.join("events.txt");
    // A debris bridge that needs a 2 mm turn-back, then a welded short: an alarm.
    std::fs::write(&events, "200000 debris 2000\n400000 short 100000000\n").unwrap();
    let (out, s) = edmd_run(
        "programs/huang-table1-g38.nc",
        &dir,
        &[
            "sim.debris_shorts_per_mm=0",
            "sim.model=\"kinematic\"",
            &format!("sim.events={}", events.display()),
            "buffer.reserved=64",
        ],
    );
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert_eq!(s["outcome"], "alarm");
    assert_eq!(s["shorts"], 2);
    assert!(s["deepest_turn_back_blocks"].as_u64().unwrap() >= 1);

    std::fs::write(&events, "10 debris\n20 erode 5\n").unwrap();
    let (out, s) = edmd_run(
        "programs/huang-table1-g38.nc",
        &dir,
        &[&format!("sim.events={}", events.display())],
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains(&format!(
            "{}:2:4: \"erode\" is not an event",
            events.display()
        )),
        "{}",
        stderr(&out)
    );
    assert!(s.is_null());
}

/// A job whose output fails at `fault_tick`, then the same program resumed from the point and
/// ledger its end reports (what the daemon's checkpoint holds): it must finish exactly.
fn fault_then_resume(
    config: &Config,
    fault_tick: u64,
) -> (runtime::JobSummary, runtime::JobSummary) {
    let program = runtime::JobProgram::in_place(&repo().join(PROGRAM)).unwrap();
    let check = runtime::precheck(
        &program,
        config,
        &Default::default(),
        &edmd::path::CutPlan::default(),
        &runtime::Progress::new(),
    )
    .unwrap();
    let spec = runtime::JobSpec::from_config(config, true);
    let fine = runtime::FineThread::start(&spec.run_loop, None).unwrap();
    let never = std::sync::atomic::AtomicBool::new(false);
    let job = |output: runtime::BoxedOutput, resume| {
        let io = runtime::JobIo {
            output: Some(output),
            gap: Some(Box::new(edmd::gap::AlwaysNormal)),
            inputs: Some(Box::new(edmd::inputs::NoInputs)),
            gap_inputs: None,
            probe_reads: Default::default(),
            tracer: None,
            recording: None,
            progress: None,
        };
        let published = Arc::new(runtime::Published::new(64));
        let job = runtime::JobRun {
            program: &program,
            check: &check,
            spec: &spec,
            resume,
        };
        runtime::run(&fine, job, io, published, &never)
    };
    let failing = edmd::output::FaultInjector::new(edmd::output::NullOutput, fault_tick);
    let first = job(Box::new(failing), None);
    let point = runtime::ResumePoint {
        here: first.stopped_at.here,
        position: first.summary.end_steps.clone(),
        dwell_s: 0.0,
        line: first.stopped_at.line,
    };
    let second = job(Box::new(edmd::output::NullOutput), Some(point));
    (first.summary, second.summary)
}

#[test]
fn a_job_cut_short_by_an_output_fault_resumes_exactly_at_any_tick() {
    // Segments of two steps, so about every other step finishes one: a fault on a step that
    // finished a segment once left the checkpoint one step ahead of the ledger.
    let config = config(&["gap.kind=\"none\"", "interpolation.max_segment_mm=0.002"]);
    // The ticks that step, from a run into a pulse log.
    let dir = scratch("fault-ticks");
    let log = dir.join("pulses.csv");
    let mut with_log = config.clone();
    with_log.output.kind = edmd::config::OutputKind::File;
    with_log.output.path = log.clone();
    let never = std::sync::atomic::AtomicBool::new(false);
    runtime::run_file(
        &repo().join(PROGRAM),
        &with_log,
        &never,
        runtime::Observers::default(),
    )
    .unwrap();
    let (_, rows) = read_pulse_log(&log).unwrap();
    let stepping: Vec<u64> = rows
        .iter()
        .filter(|r| r.steps.iter().any(|&s| s != 0))
        .map(|r| r.tick)
        .collect();
    let middle = stepping.len() / 2;
    for &tick in &stepping[middle..middle + 24] {
        let (first, second) = fault_then_resume(&config, tick);
        assert_eq!(first.outcome, Outcome::OutputError, "fault at {tick}");
        assert_eq!(
            second.outcome,
            Outcome::Done,
            "fault at {tick}: {:?}",
            second.error
        );
        assert_eq!(second.end_steps, PROGRAM_END.to_vec(), "fault at {tick}");
    }
}

// ---- machine inputs whatever the gap input is --------------------------------------------

/// The port's E-stop is read with every gap input: the port as the output, the gap from
/// nothing, a script, the simulator, an IIO ADC (a fake sysfs directory) or the port's own
/// status pins. Pressed at tick 20,000, the job stops in that tick with outcome `estop`, no
/// step after it reaches the drives, and the port is left with its outputs inactive.
#[test]
fn the_estop_pin_stops_the_job_whatever_the_gap_input() {
    let mut config = config(&[
        "output.kind=\"parport\"",
        "fine.virtual_time=false",
        "parport.estop_pin=12",
        "fine.tick_us=50",
    ]);
    // The port is the recording fake: its time is virtual.
    config.fine.virtual_time = true;
    const PRESS: u64 = 20_000;
    // 30 V at the gap (sparking): 1500 counts of 1 mV behind a 1:20 divider.
    let dev = common::scratch("io", "estop-iio").join("iio:device0");
    std::fs::create_dir_all(&dev).unwrap();
    std::fs::write(dev.join("in_voltage0_raw"), "1500\n").unwrap();
    std::fs::write(dev.join("in_voltage_scale"), "1.000000\n").unwrap();
    let iio = edmd::gap::IioSettings {
        device: dev,
        channel: "voltage0".into(),
        gain: 20.0,
        rate_hz: 10_000.0,
    };
    let gaps: Vec<(&str, Box<dyn GapSensor + Send>)> = vec![
        ("none", Box::new(edmd::gap::AlwaysNormal)),
        (
            "script",
            Box::new(
                edmd::gap::GapScript::parse("0 normal\n", "gap.txt")
                    .unwrap()
                    .gap,
            ),
        ),
        ("sim", {
            let check = runtime::precheck(
                &runtime::JobProgram::in_place(&repo().join(PROGRAM)).unwrap(),
                &config,
                &Default::default(),
                &edmd::path::CutPlan::default(),
                &runtime::Progress::new(),
            )
            .unwrap();
            runtime::open_gap(&config, &check, None).unwrap().gap
        }),
        (
            "iio",
            Box::new(edmd::gap::IioGap::open(&iio, config.gap.volts).unwrap()),
        ),
        ("parport", Box::new(edmd::gap::AlwaysNormal)),
    ];
    for (kind, gap) in gaps {
        let (mut output, bench, map, _) = fake_port(&config);
        // The port's own status pins as the gap input, on the same fake.
        let gap: Box<dyn GapSensor + Send> = if kind == "parport" {
            Box::new(edmd::parport::ParportGap::new(
                Arc::new(Mutex::new(PortWriter::new(bench.port(), map.idle()))),
                map.clone(),
                1,
                "fake-port",
            ))
        } else {
            gap
        };
        let inputs = edmd::parport::ParportInputs::new(
            Arc::new(Mutex::new(PortWriter::new(bench.port(), map.idle()))),
            map.clone(),
            "fake-port",
        );
        output.press = Some((PRESS, edmd::parport::PinLevels(1 << 12)));
        let summary = job_with_inputs(&config, output, gap, inputs);
        assert_eq!(
            summary.outcome,
            Outcome::Estop,
            "gap.kind {kind}: {summary:?}"
        );
        assert_eq!(
            summary.ticks, PRESS,
            "gap.kind {kind}: stopped in the tick it was seen"
        );
        let last_step = bench
            .writes()
            .iter()
            .filter(|w| w.register == edmd::parport::fake::Register::Data)
            .map(|w| w.at_ns)
            .max()
            .unwrap();
        assert!(
            last_step < PRESS * config.fine.tick.ns(),
            "gap.kind {kind}: a write at {last_step} ns after the press"
        );
        let (_, last) = *bench.waveform(map.idle()).last().unwrap();
        assert_eq!(last, map.idle(), "gap.kind {kind}: every output inactive");
    }
}

/// A port pin that nothing would read does not validate: the E-stop, a limit switch, the
/// probe and the wire break need the port as the output.
#[test]
fn a_machine_input_pin_without_the_port_is_a_configuration_error() {
    for set in [
        "parport.estop_pin=12",
        "parport.limit_pins={\"X+\"=13}",
        "parport.probe_pin=15",
        "parport.wire_break_pin=13",
    ] {
        let overrides = vec![set.to_string()];
        let e = Config::load(None, &overrides).unwrap_err().to_string();
        assert!(
            e.contains("nothing reads the parallel port's inputs with output.kind = \"sim\""),
            "{set}: {e}"
        );
    }
}

/// The dead-man of a continuous jog is kept by the job's own thread: with nobody renewing
/// (the control loop frozen, here: nothing runs it at all), the job holds within a tick of
/// its deadline and moves no more.
#[test]
fn the_job_thread_holds_at_the_dead_man_deadline_by_itself() {
    let config = config(&[
        "fine.virtual_time=false",
        "output.kind=\"null\"",
        "gap.kind=\"none\"",
        "servo.normal_feed_mm_per_min=300.0",
    ]);
    let published = Arc::new(runtime::Published::new(4096));
    let deadline = edmd::sys::monotonic_ns() + 150_000_000;
    published
        .dead_man_ns
        .store(deadline, std::sync::atomic::Ordering::Release);
    let stop = std::sync::atomic::AtomicBool::new(false);
    std::thread::scope(|s| {
        let job = s.spawn(|| {
            job_steered(
                &config,
                edmd::output::NullOutput,
                edmd::gap::AlwaysNormal,
                edmd::inputs::NoInputs,
                published.clone(),
                &stop,
            )
        });
        std::thread::sleep(std::time::Duration::from_millis(100));
        let moving = published.position();
        assert!(
            moving[0] != 0 || moving[1] != 0,
            "moving before the deadline"
        );
        assert!(
            !published
                .dead_man_tripped
                .load(std::sync::atomic::Ordering::Acquire)
        );
        std::thread::sleep(std::time::Duration::from_millis(250));
        assert!(
            published
                .dead_man_tripped
                .load(std::sync::atomic::Ordering::Acquire)
        );
        assert!(published.hold.load(std::sync::atomic::Ordering::Acquire));
        let held = published.snapshot();
        assert!(held.still, "braked to a standstill: {held:?}");
        std::thread::sleep(std::time::Duration::from_millis(200));
        assert_eq!(
            published.position(),
            held.position,
            "no motion after the dead-man"
        );
        stop.store(true, std::sync::atomic::Ordering::Relaxed);
        let end = job.join().unwrap();
        assert_eq!(end.summary.outcome, Outcome::Stopped);
    });
}
