//! How a job ended and what it did: the [`Outcome`], the [`JobSummary`] that `edmd run`
//! prints and writes as JSON (and the daemon logs and reports), and the two decisions behind
//! them: which tick's steps the drives really received, and which failure names the end.

use serde::{Deserialize, Serialize};

use super::super::tick::consumer::LoopReport;
use super::super::tick::histogram::LatencySummary;
use super::producer::{ProducerError, ProducerReport};
use crate::fine::{FineCounters, Interpolator, SkipError};
use crate::output::OutputError;
use crate::servo::{ServoCounters, ServoState};
use crate::vocab::{Steps, Trip};

/// How a job ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Outcome {
    /// The whole program was executed.
    Done,
    /// Shorted after the whole reserved area: stopped, position kept.
    Alarm,
    /// The pulse output failed: stopped at once.
    OutputError,
    /// The gap input failed: stopped at once.
    GapError,
    /// The producer failed part-way (the program changed after the check, or a position out of
    /// range): the consumer executed what it had and stopped.
    ProducerError,
    /// Stopped on request.
    Stopped,
    /// A resumed job did not find its checkpoint on the program's path: nothing moved.
    ResumeRefused,
    /// The gap shorted during a rapid and no operator could release the hold (`edmd run`):
    /// stopped there, position kept.
    Collision,
    /// The wire broke and no operator could rethread it (`edmd run`): stopped there.
    WireBreak,
    /// A `G38.2`/`G38.4` reached its end point without contact: stopped there.
    ProbeMissed,
    /// The emergency stop: motion stopped in the tick it was seen, spark off, drives
    /// disabled.
    Estop,
    /// A limit switch: motion stopped in the tick it was seen.
    Limit,
}

impl Outcome {
    pub fn name(self) -> &'static str {
        match self {
            Outcome::Done => "done",
            Outcome::Alarm => "alarm",
            Outcome::OutputError => "output error",
            Outcome::GapError => "gap input error",
            Outcome::ProducerError => "producer error",
            Outcome::Stopped => "stopped",
            Outcome::ResumeRefused => "resume refused",
            Outcome::Collision => "collision",
            Outcome::Estop => "estop",
            Outcome::Limit => "limit",
            Outcome::WireBreak => "wire break",
            Outcome::ProbeMissed => "probe missed",
        }
    }
}

/// Where along the program a job that did not finish stopped (a standstill): what a checkpoint
/// needs to resume it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StopPoint {
    pub line: u64,
    pub segment: u64,
    pub step: i64,
    pub segment_steps: i64,
    pub parameter: Option<f64>,
    /// Seconds of a `G4` dwell still owed at the point (0 outside a dwell).
    #[serde(default)]
    pub dwell_s: f64,
    /// SHA-256 of the program's bytes the job ran.
    pub program_sha256: String,
}

/// Where the last probing move ended, per axis (mm), and whether it touched: the same fields
/// (flat) in the summary and the daemon's status.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LastProbe {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe_mm: Option<Vec<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe_contact: Option<bool>,
}

impl LastProbe {
    /// The last probe's result (`steps` times `step_mm`), if there was one.
    pub fn new(
        probe: Option<&super::super::tick::probe::ProbeResult>,
        step_mm: &[f64],
    ) -> LastProbe {
        LastProbe {
            probe_mm: probe.map(|p| {
                p.steps
                    .iter()
                    .zip(step_mm)
                    .map(|(s, mm)| *s as f64 * mm)
                    .collect()
            }),
            probe_contact: probe.map(|p| p.contact),
        }
    }
}

/// A limit switch in a summary's JSON: `"X+"`.
mod limit_text {
    use serde::{Deserialize, Deserializer, Serializer};

    use crate::vocab::{Axis, LimitSwitch};

    pub fn serialize<S: Serializer>(v: &Option<LimitSwitch>, s: S) -> Result<S::Ok, S::Error> {
        match v {
            Some(switch) => s.serialize_str(&switch.to_string()),
            None => s.serialize_none(),
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<LimitSwitch>, D::Error> {
        let text: Option<String> = Option::deserialize(d)?;
        Ok(text.and_then(|t| {
            let mut c = t.chars();
            let axis = Axis::from_letter(c.next()?)?;
            let positive = c.next()? == '+';
            Some(LimitSwitch { axis, positive })
        }))
    }
}

/// The end-of-job summary (`edmd run` prints it; `--summary FILE` writes it as JSON).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JobSummary {
    pub program: String,
    pub outcome: Outcome,
    pub error: Option<String>,
    /// The limit switch that stopped the job (outcome `limit`).
    #[serde(default, skip_serializing_if = "Option::is_none", with = "limit_text")]
    pub limit_switch: Option<crate::vocab::LimitSwitch>,
    /// The limit switches that read closed at the job's last tick (a trip is kept until its
    /// switch opens).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub limits_closed: Vec<String>,
    pub axes: Vec<String>,
    /// G-code blocks of the program.
    pub blocks: u64,
    /// Loop-buffer blocks (segments) produced.
    pub segments: u64,
    /// Pulses emitted per axis, both directions.
    pub steps_per_axis: Vec<u64>,
    /// The pulse ledger at the end, per axis (steps).
    pub end_steps: Vec<i64>,
    /// The program's end point, per axis (steps).
    pub program_end_steps: Vec<i64>,
    pub end_mm: Vec<f64>,
    pub events_forward: u64,
    pub events_backward: u64,
    /// Shorts, turn-backs, alarms, … (flat in the JSON).
    #[serde(flatten)]
    pub servo: ServoCounters,
    /// The last probe (flat in the JSON).
    #[serde(flatten)]
    pub last_probe: LastProbe,
    pub overruns: u64,
    pub missed_deadlines: u64,
    /// Real time only.
    pub latency_us: Option<LatencySummary>,
    pub tick_us: u32,
    pub ticks: u64,
    pub virtual_time: bool,
    /// Machine time: ticks × tick period (s).
    pub virtual_time_s: f64,
    pub wall_time_s: f64,
    /// Wall time the producer spent working (not waiting for buffer space), s. Machine time
    /// over this is how many times faster than real time the producer can feed the loop.
    #[serde(default)]
    pub producer_busy_s: f64,
    /// Peak resident set size of the process at the end of the job, KiB.
    #[serde(default)]
    pub peak_rss_kib: u64,
    pub buffer_capacity: u64,
    pub buffer_high_water: u64,
    pub events_dropped: u64,
    /// Trace records dropped because the logger fell behind (real time only).
    pub trace_dropped: u64,
    /// Real-time features the system refused.
    pub rt_refused: Vec<String>,
    /// Where a job that did not finish stopped (none when it was done).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stopped_at: Option<StopPoint>,
    /// A die-sinker's orbital sinking moves, in program order (at most
    /// [`crate::path::MAX_STAGES`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub stages: Vec<crate::path::StageRow>,
}

/// What a finished job leaves behind, for its summary.
pub(crate) struct JobFacts<'a> {
    pub program: &'a super::super::shaping::program::JobProgram,
    pub check: &'a super::precheck::Precheck,
    pub spec: &'a super::spec::JobSpec,
    pub resume: Option<&'a super::fine_thread::ResumePoint>,
    pub fine: &'a Interpolator,
    pub report: LoopReport,
    pub finished: &'a Result<(), OutputError>,
    pub skip: &'a Result<(), SkipError>,
    pub producer: Result<ProducerReport, ProducerError>,
    pub buffer_high_water: u64,
    pub events_dropped: u64,
    pub trace_dropped: u64,
}

impl JobSummary {
    /// The summary of a finished job, and the snapshot of where it stands (the checkpoint's
    /// point and ledger).
    pub(crate) fn of(facts: JobFacts<'_>) -> (JobSummary, super::super::tick::snapshot::Snapshot) {
        let JobFacts {
            program,
            check,
            spec,
            resume,
            fine,
            report,
            finished,
            skip,
            producer,
            buffer_high_water,
            events_dropped,
            trace_dropped,
        } = facts;
        let (counters, mut position) = delivered(fine, &report);
        if let (Err(_), Some(point)) = (skip, resume) {
            // Nothing moved: the walk towards the checkpoint emits nothing, so the machine
            // stands where the checkpoint says, whatever point the walk reached.
            for (p, s) in position.iter_mut().zip(&point.position) {
                *p = *s;
            }
        }
        let axes = spec.axes.len();
        let tick = spec.tick;
        let (outcome, error) = outcome(skip, &report, finished, fine.state(), &producer);
        let producer = producer.unwrap_or_default();
        let mut stopped_at = super::super::tick::snapshot::Snapshot::of(report.ticks, fine);
        if let Some((here, events)) = report.untaken_from {
            // The failed tick's step never reached the drives: the checkpoint's point is the
            // one before it (its ledger is taken back in `delivered`).
            stopped_at.here = here;
            stopped_at.events = events;
        }
        let summary = JobSummary {
            program: program.name.clone(),
            outcome,
            error,
            limit_switch: report.tripped.and_then(|(trip, _, _)| match trip {
                Trip::Limit(switch) => Some(switch),
                Trip::EStop => None,
            }),
            limits_closed: report.limits_at_end.iter().map(|s| s.to_string()).collect(),
            axes: spec.axis_names(),
            blocks: check.blocks,
            segments: producer.pushed,
            steps_per_axis: counters.pulses[..axes].to_vec(),
            end_steps: position[..axes].to_vec(),
            program_end_steps: check.end_steps[..axes].to_vec(),
            end_mm: position[..axes]
                .iter()
                .zip(&spec.step_mm)
                .map(|(p, s)| *p as f64 * s)
                .collect(),
            events_forward: counters.events_forward,
            events_backward: counters.events_backward,
            servo: counters.servo,
            last_probe: LastProbe::new(report.last_probe.as_ref(), &spec.step_mm),
            overruns: report.overruns,
            missed_deadlines: report.missed_deadlines,
            latency_us: report.latency.as_ref().map(|h| h.summary()),
            tick_us: tick.us(),
            ticks: report.ticks,
            virtual_time: spec.run_loop.virtual_time,
            virtual_time_s: tick.ticks_to_secs(report.ticks),
            wall_time_s: report.wall_ns as f64 * 1e-9,
            producer_busy_s: producer.busy_ns as f64 * 1e-9,
            peak_rss_kib: crate::sys::peak_rss_kib(),
            buffer_capacity: spec.buffer_capacity as u64,
            buffer_high_water,
            events_dropped,
            trace_dropped,
            rt_refused: report.rt_refused,
            stopped_at: (outcome != Outcome::Done && outcome != Outcome::ResumeRefused).then(
                || StopPoint {
                    line: stopped_at.line,
                    segment: stopped_at.here.seq,
                    step: stopped_at.here.event,
                    segment_steps: stopped_at.events,
                    parameter: stopped_at.u_end.is_finite().then_some(stopped_at.u_end),
                    dwell_s: tick.ticks_to_secs(stopped_at.dwell_left),
                    program_sha256: program.sha256.clone(),
                },
            ),
            stages: producer.stages.clone(),
        };
        (summary, stopped_at)
    }

    /// The human-readable summary.
    pub fn text(&self) -> String {
        use std::fmt::Write;
        let mut t = String::new();
        let list = |v: &[i64]| axis_list(v, &self.axes, |s| s.to_string());
        let _ = writeln!(t, "{}: {}", self.program, self.outcome.name());
        if let Some(e) = &self.error {
            let _ = writeln!(t, "  error:            {e}");
        }
        let _ = writeln!(
            t,
            "  blocks:           {} G-code blocks, {} segments",
            self.blocks, self.segments
        );
        let pulses: Vec<i64> = self.steps_per_axis.iter().map(|&p| p as i64).collect();
        let _ = writeln!(t, "  steps per axis:   {}", list(&pulses));
        let _ = writeln!(
            t,
            "  end position:     {} steps (program end {})",
            list(&self.end_steps),
            list(&self.program_end_steps)
        );
        let _ = writeln!(
            t,
            "  servo:            {} shorts, {} turn-backs (deepest {} blocks), {} alarms, {} starvations{}",
            self.servo.shorts,
            self.servo.turn_backs,
            self.servo.deepest_turn_back_blocks,
            self.servo.alarms,
            self.servo.starvations,
            if self.servo.collisions > 0 {
                format!(", {} collisions", self.servo.collisions)
            } else {
                String::new()
            }
        );
        let c = &self.servo;
        if c.jumps + c.wire_breaks + c.probes > 0 {
            let _ = writeln!(
                t,
                "  excursions:       {} jumps, {} wire breaks, {} probes",
                c.jumps, c.wire_breaks, c.probes
            );
        }
        for st in &self.stages {
            let _ = writeln!(t, "  orbit stage:      {}", st.text());
        }
        let x = &self.last_probe;
        if let Some(mm) = &x.probe_mm {
            let text = axis_list(mm, &self.axes, |v| format!("{v:.4}"));
            let _ = writeln!(
                t,
                "  last probe:       {text} mm ({})",
                if x.probe_contact == Some(true) {
                    "contact"
                } else {
                    "no contact"
                }
            );
        }
        let _ = writeln!(
            t,
            "  events:           {} forward, {} backward",
            self.events_forward, self.events_backward
        );
        match &self.latency_us {
            Some(l) => {
                let _ = writeln!(
                    t,
                    "  latency:          p50 {:.1} µs, p99 {:.1} µs, max {:.1} µs over {} ticks; {} overruns",
                    l.p50_us, l.p99_us, l.max_us, l.samples, self.overruns
                );
            }
            None => {
                let _ = writeln!(
                    t,
                    "  latency:          none measured (virtual time); {} overruns",
                    self.overruns
                );
            }
        }
        let _ = writeln!(
            t,
            "  time:             {:.3} s machine ({} ticks of {} µs), {:.3} s wall",
            self.virtual_time_s, self.ticks, self.tick_us, self.wall_time_s
        );
        let _ = writeln!(
            t,
            "  producer:         {:.3} s busy for {:.3} s of machine time ({:.0}x real time)",
            self.producer_busy_s,
            self.virtual_time_s,
            self.virtual_time_s / self.producer_busy_s.max(1e-9)
        );
        let _ = writeln!(
            t,
            "  loop buffer:      high water {} of {} blocks",
            self.buffer_high_water, self.buffer_capacity
        );
        let _ = writeln!(
            t,
            "  memory:           peak RSS {:.1} MiB",
            self.peak_rss_kib as f64 / 1024.0
        );
        for r in &self.rt_refused {
            let _ = writeln!(t, "  warning:          {r}");
        }
        t
    }
}

/// `X 1, Y 2`: one value per axis, each after its letter.
pub fn axis_list<T>(values: &[T], axes: &[String], format: impl Fn(&T) -> String) -> String {
    values
        .iter()
        .zip(axes)
        .map(|(v, a)| format!("{a} {}", format(v)))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The counters and the pulse ledger as the drives received them: a tick whose write failed
/// before its step edge never reached them, so its steps are taken back.
fn delivered(fine: &Interpolator, report: &LoopReport) -> (FineCounters, Steps) {
    let mut counters = fine.counters();
    let mut position = fine.position();
    if let Some((steps, dir)) = report.untaken {
        for (axis, &s) in steps.iter().enumerate() {
            position[axis] -= s as i64;
            counters.pulses[axis] -= s.unsigned_abs() as u64;
        }
        if dir > 0 {
            counters.events_forward -= 1;
        } else {
            counters.events_backward -= 1;
        }
    }
    (counters, position)
}

/// How the job ended and why, the first cause winning: a refused resume, then a failed gap
/// input, a failed output (mid-job, then on finishing), an alarm, a failed producer, a
/// requested stop.
fn outcome(
    skip: &Result<(), SkipError>,
    report: &LoopReport,
    finished: &Result<(), OutputError>,
    state: ServoState,
    producer: &Result<ProducerReport, ProducerError>,
) -> (Outcome, Option<String>) {
    if let Err(e) = skip {
        (Outcome::ResumeRefused, Some(e.to_string()))
    } else if let Some(e) = report.input_error.as_ref() {
        (Outcome::GapError, Some(e.to_string()))
    } else if let Some(e) = report.gap_error.as_ref() {
        (Outcome::GapError, Some(e.to_string()))
    } else if let Some(e) = report.output_error.as_ref() {
        (Outcome::OutputError, Some(e.to_string()))
    } else if let Err(e) = finished {
        (Outcome::OutputError, Some(e.to_string()))
    } else if let Some((trip, at, line)) = report.tripped {
        let stopped = format!(
            "motion stopped in the tick it was seen (segment {}, step {}), spark off, drives \
             disabled",
            at.seq, at.event
        );
        match trip {
            Trip::Limit(switch) => (
                Outcome::Limit,
                Some(format!(
                    "line {line}: limit switch {switch} ({} end of axis {}): {stopped}; only a \
                     jog away from it moves",
                    if switch.positive { "upper" } else { "lower" },
                    switch.axis
                )),
            ),
            Trip::EStop => (
                Outcome::Estop,
                Some(format!(
                    "line {line}: E-stop: {stopped}; release it, then `edmd ctl reset`"
                )),
            ),
        }
    } else if let Some((at, line)) = report.collision {
        (
            Outcome::Collision,
            Some(format!(
                "line {line}: the gap shorted during a rapid (segment {}, step {}): motion \
                 stopped, position kept",
                at.seq, at.event
            )),
        )
    } else if let Some((at, line, open)) = report.wire_break {
        (
            Outcome::WireBreak,
            Some(format!(
                "line {line}: the wire broke ({}; segment {}, step {}): motion stopped, position \
                 kept; `edmd serve` holds such a job for a rethread",
                if open {
                    "the gap stayed open over servo.max_open_mm of cutting"
                } else {
                    "the wire-break input"
                },
                at.seq,
                at.event
            )),
        )
    } else if let Some((at, line)) = report.probe_missed {
        (
            Outcome::ProbeMissed,
            Some(format!(
                "line {line}: the probing move reached its end point without contact (segment \
                 {}, step {}): the program cannot go on",
                at.seq, at.event
            )),
        )
    } else if state == ServoState::Alarm {
        (
            Outcome::Alarm,
            Some(
                "a short outlasted the reserved history or servo.max_short_s: motion stopped, \
                 position kept"
                    .to_string(),
            ),
        )
    } else if let Err(e) = producer {
        (Outcome::ProducerError, Some(e.to_string()))
    } else if report.stopped {
        (
            Outcome::Stopped,
            Some("a stop was requested: motion stopped where it was, position kept".to_string()),
        )
    } else if state != ServoState::Done {
        (Outcome::Stopped, None)
    } else {
        (Outcome::Done, None)
    }
}
