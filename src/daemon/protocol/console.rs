//! The parts of the status the console adds to the machine's: the running job (what it
//! cuts with, where it is), the work offset table's rows and the wire offset in force.

use serde::{Deserialize, Serialize};

use super::is_zero;

/// One system of the work offset table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WorkOffsetRow {
    pub system: String,
    pub offset_mm: Vec<f64>,
}

/// The wire offset a job cuts with now.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WireOffsetStatus {
    /// `"G41"` (left of travel) or `"G42"` (right).
    pub side: String,
    pub mm: f64,
}

impl WireOffsetStatus {
    /// From a signed offset (+ left, − right; 0: none).
    pub fn of(signed_mm: f64) -> Option<WireOffsetStatus> {
        (signed_mm != 0.0).then(|| WireOffsetStatus {
            side: if signed_mm > 0.0 { "G41" } else { "G42" }.to_string(),
            // The ring carries it as f32: shown to the micron it was given in.
            mm: (signed_mm.abs() * 1e6).round() / 1e6,
        })
    }
}

/// The running job.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JobStatus {
    pub program: String,
    /// A dry run: spark off, the servo out of the loop, no checkpoint.
    #[serde(default)]
    pub dry_run: bool,
    /// Run from a line: where the cut starts and how the machine approached it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub from_line: Option<crate::path::FromLine>,
    /// Passes of the technology table the job cuts (0: the program as written).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub passes: usize,
    /// The pass being cut (1 to `passes`; none outside passes).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pass: Option<u64>,
    /// The machining condition in force (`E`; none before any).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub condition: Option<u64>,
    /// What that condition sets the generator to.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub generator: Option<crate::vocab::GeneratorSetPoints>,
    /// The technology it cuts with (`material=steel height=32 wire=0.25 (steel with 0.25 mm
    /// brass wire)`), and the table's file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub technology: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub technology_table: Option<String>,
    /// The program reads in inches (`G20`): the page shows its positions so as well.
    #[serde(default)]
    pub inch: bool,
    /// The wire offset in force: `"G41"`/`"G42"` and its distance, mm (none without one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wire_offset: Option<WireOffsetStatus>,
    /// Source line of the segment in hand.
    pub line: u64,
    pub segment: u64,
    pub step: i64,
    pub parameter: Option<f64>,
    /// The servo's state: forward, turn-back, re-advance, hold (starved), alarm, done.
    pub servo: crate::servo::ServoState,
    /// The gap state read in the last tick (none before the first).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gap: Option<crate::vocab::GapState>,
    /// The gap voltage the input measured in the last tick, V (none for an input that reads
    /// states only: a parallel port's pins, a script).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gap_volts: Option<f64>,
    /// What the generator's pulses did, from a gap input that counts them (the simulator's
    /// discharge model, HAL's discriminator pins).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub process: Option<ProcessStatus>,
    pub position_steps: Vec<i64>,
    pub position_mm: Vec<f64>,
    pub feed_mm_per_min: f64,
    pub buffer_unprocessed: u64,
    pub buffer_reserved: u64,
    pub buffer_capacity: u64,
    /// Shorts, turn-backs, alarms, jumps, … so far (flat in the JSON).
    #[serde(flatten)]
    pub servo_counters: crate::servo::ServoCounters,
    /// The last probe (flat in the JSON).
    #[serde(flatten)]
    pub last_probe: crate::runtime::LastProbe,
    pub overruns: u64,
    pub pulses: Vec<u64>,
    pub ticks: u64,
    pub machine_time_s: f64,
    pub elapsed_s: f64,
    /// Real time only: wake-up latency so far.
    pub latency_mean_us: Option<f64>,
    pub latency_max_us: Option<f64>,
    /// Started from a checkpoint.
    pub resumed: bool,
    /// Fraction of the program's path done (0 to 1): the farthest point reached, so a
    /// turn-back does not move it back and the re-advance does not count twice.
    pub progress: f64,
    /// Path length done and in all (mm).
    pub path_done_mm: f64,
    pub path_total_mm: f64,
    /// Seconds to the end at the recent average forward feed (none until a second of motion
    /// is known, or while nothing advances).
    pub eta_s: Option<f64>,
    /// That recent average forward feed (mm/min).
    pub recent_feed_mm_per_min: Option<f64>,
    /// Held by a programmed stop (`M0`/`M1`), single block or a tab's slug before this
    /// source line.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub paused_before_line: Option<u64>,
    /// Why it is paused there: "program stop (M0/M1)", "single block", "secure the slug".
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pause: Option<String>,
    /// What the program tells the operator at this stop: its `(MSG, …)` or its pause
    /// M-code's message ("M60: thread the wire (M60), then resume").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pause_message: Option<String>,
}

/// The process as the pulses tell it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProcessStatus {
    /// Pulses so far by class.
    pub pulses: PulseClasses<u64>,
    /// Pulses per second by class, over the job so far.
    pub rates_hz: PulseClasses<f64>,
    /// The mean ignition delay of the normal and arc pulses, µs.
    pub mean_ignition_delay_us: Option<f64>,
    /// The generator's off time in force (adapted or as set), µs.
    pub off_time_us: f64,
    /// The adaptive law's estimate of the part height, mm.
    pub height_estimate_mm: Option<f64>,
    /// The cut rate: the recent feed times the part height (the estimate, else the
    /// technology row's), mm²/min.
    pub cut_rate_mm2_per_min: Option<f64>,
}

/// One figure per pulse class.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PulseClasses<T> {
    pub normal: T,
    pub arc: T,
    pub short: T,
    pub open: T,
}
