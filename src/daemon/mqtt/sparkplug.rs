//! The edge node's Sparkplug B side, with no network: which metrics the machine has, what
//! NBIRTH, NDATA and NDEATH carry, the sequence numbers, and what an NCMD asks for.
//!
//! ```text
//! metric                          type      deadband          read from the status
//! bdSeq                           UInt64    (birth, death)    the session's number
//! Node Control/Rebirth|Hold|Abort Boolean   (writable)        false
//! Node Control/Last Command       String                      the last NCMD's answer
//! Node Info/Commands|Version|Dropped
//! Machine/State|Work System|Holds|Alarms|E-stop
//! Axes/<X>/Machine Position|Work Position (mm)|Homed
//! Channel/Feed (mm/min)|Feed Override|Rapid Override (%)
//! Generator/Condition|Gap|Gap Voltage (V)
//! Gap/Normal|Open|Short Share     Double    fraction          ticks over the last sample
//! Counters/Shorts|Turn-backs|Wire Breaks|Jobs, Counters/Machine Time|Spark Time (s)
//! Job/Active|Program|Line|Pass|Passes|Progress|Time To Go (s)|Technology
//! Job/Last Program|Last Outcome
//! ```
//!
//! **Sequence numbers, as the specification says.** `bdSeq` counts MQTT sessions (0 to 255
//! and round): the NDEATH registered as the will when a session connects and the NBIRTH that
//! follows carry the same number, so a host can pair a death with its birth. `seq` is 0 on
//! NBIRTH and counts every later message of the session (0 to 255 and round).
//!
//! **Aliases.** NBIRTH names every metric with its alias (its place in the table, from 1);
//! NDATA sends the alias and the value only, and only the metrics that moved past their
//! deadband since they were last sent.

use srad_types::payload::{DataType, Message, Metric, Payload, metric};

use crate::config::Deadbands;
use crate::daemon::protocol::{DaemonState, JobStatus, Status};

/// The Sparkplug namespace of every topic.
pub const NAMESPACE: &str = "spBv1.0";

/// The longest text a metric carries (bytes; longer is cut at a character and marked `…`):
/// a program's path, an outcome, a command's answer. With 64-byte names and every metric
/// bounded, a birth stays far below [`MAX_PACKET_BYTES`] whatever a host writes to the node.
pub const MAX_TEXT_BYTES: usize = 256;
/// How much of a metric's name an answer quotes.
const MAX_QUOTED_NAME: usize = 64;
/// The MQTT client's packet limit, both ways (rumqttc's default is 10 KiB, which a birth
/// carrying long texts once passed): a birth of the node is at most a few KiB.
pub const MAX_PACKET_BYTES: usize = 64 * 1024;

/// `text` cut to at most `max` bytes at a character boundary, `…` marking a cut.
pub fn bounded(text: &str, max: usize) -> String {
    if text.len() <= max {
        return text.to_string();
    }
    let mut end = max.saturating_sub('…'.len_utf8());
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    format!("{}…", &text[..end])
}

/// The node's topics.
#[derive(Debug, Clone)]
pub struct Topics {
    pub nbirth: String,
    pub ndata: String,
    pub ndeath: String,
    pub ncmd: String,
}

impl Topics {
    pub fn new(group: &str, node: &str) -> Topics {
        let topic = |kind: &str| format!("{NAMESPACE}/{group}/{kind}/{node}");
        Topics {
            nbirth: topic("NBIRTH"),
            ndata: topic("NDATA"),
            ndeath: topic("NDEATH"),
            ncmd: topic("NCMD"),
        }
    }
}

/// What one sample of the machine is: the status, and what the node adds of its own.
pub struct Sample<'a> {
    pub status: &'a Status,
    /// Normal, open and short gap readings over the last sample (fractions; 0 without any).
    pub shares: [f64; 3],
    /// Messages dropped so far because the broker did not take them.
    pub dropped: u64,
    /// The answer to the last NCMD ("" before any).
    pub answer: &'a str,
    /// Whether NCMD may hold and abort.
    pub commands: bool,
}

/// A metric's value.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    Text(String),
    Count(u64),
    Real(f64),
    Flag(bool),
}

impl Value {
    fn datatype(&self) -> DataType {
        match self {
            Value::Text(_) => DataType::String,
            Value::Count(_) => DataType::UInt64,
            Value::Real(_) => DataType::Double,
            Value::Flag(_) => DataType::Boolean,
        }
    }

    fn wire(&self) -> metric::Value {
        match self {
            Value::Text(s) => metric::Value::StringValue(bounded(s, MAX_TEXT_BYTES)),
            Value::Count(n) => metric::Value::LongValue(*n),
            Value::Real(x) => metric::Value::DoubleValue(*x),
            Value::Flag(b) => metric::Value::BooleanValue(*b),
        }
    }
}

/// Which deadband a metric's value has.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Band {
    /// Every change.
    Exact,
    Mm,
    MmPerMin,
    Fraction,
    Seconds,
}

type ReadWhole = fn(&Sample) -> Value;
type ReadAxis = fn(&Sample, usize) -> Value;

enum Read {
    Whole(ReadWhole),
    Axis(usize, ReadAxis),
}

struct Def {
    name: String,
    band: Band,
    read: Read,
}

fn job<'a, T>(s: &Sample<'a>, f: impl Fn(&'a JobStatus) -> T) -> Option<T> {
    s.status.job.as_ref().map(f)
}

/// A figure of the job's process (none without a job, or from an input that counts no
/// pulses).
fn process(
    s: &Sample<'_>,
    f: impl Fn(&crate::daemon::protocol::ProcessStatus) -> Option<f64>,
) -> Option<f64> {
    s.status.job.as_ref()?.process.as_ref().and_then(f)
}

/// One class's share of the job's pulses so far (0 with none counted).
fn pulse_share(
    s: &Sample<'_>,
    class: fn(&crate::daemon::protocol::PulseClasses<u64>) -> u64,
) -> f64 {
    process(s, |p| {
        let c = &p.pulses;
        let total = c.normal + c.arc + c.short + c.open;
        (total > 0).then(|| class(c) as f64 / total as f64)
    })
    .unwrap_or(0.0)
}

fn text(t: &str) -> Value {
    Value::Text(t.to_string())
}

/// The node control metrics a host writes to (NCMD), by name.
pub const REBIRTH: &str = "Node Control/Rebirth";
pub const HOLD: &str = "Node Control/Hold";
pub const ABORT: &str = "Node Control/Abort";

/// The machine-wide metrics: (name, deadband, read).
const WHOLE: &[(&str, Band, ReadWhole)] = &[
    (REBIRTH, Band::Exact, |_| Value::Flag(false)),
    (HOLD, Band::Exact, |_| Value::Flag(false)),
    (ABORT, Band::Exact, |_| Value::Flag(false)),
    ("Node Control/Last Command", Band::Exact, |s| text(s.answer)),
    ("Node Info/Commands", Band::Exact, |s| {
        Value::Flag(s.commands)
    }),
    ("Node Info/Version", Band::Exact, |s| {
        text(&s.status.version)
    }),
    ("Node Info/Dropped", Band::Exact, |s| {
        Value::Count(s.dropped)
    }),
    ("Machine/State", Band::Exact, |s| {
        text(s.status.state.name())
    }),
    ("Machine/E-stop", Band::Exact, |s| {
        Value::Flag(s.status.state == DaemonState::Estop)
    }),
    ("Machine/Work System", Band::Exact, |s| {
        text(&s.status.machine.work_system)
    }),
    ("Machine/Holds", Band::Exact, |s| {
        Value::Count(s.status.counters.holds)
    }),
    ("Machine/Alarms", Band::Exact, |s| {
        Value::Count(s.status.counters.servo.alarms)
    }),
    ("Channel/Feed", Band::MmPerMin, |s| {
        Value::Real(job(s, |j| j.feed_mm_per_min).unwrap_or(0.0))
    }),
    ("Channel/Feed Override", Band::Exact, |s| {
        Value::Real(f64::from(s.status.overrides.feed_pct))
    }),
    ("Channel/Rapid Override", Band::Exact, |s| {
        Value::Real(f64::from(s.status.overrides.rapid_pct))
    }),
    ("Generator/Condition", Band::Exact, |s| {
        Value::Count(job(s, |j| j.condition).flatten().unwrap_or(0))
    }),
    ("Generator/Gap", Band::Exact, |s| {
        text(job(s, |j| j.gap.map_or("", |g| g.name())).unwrap_or(""))
    }),
    ("Generator/Gap Voltage", Band::Exact, |s| {
        Value::Real(job(s, |j| j.gap_volts).flatten().unwrap_or(0.0).round())
    }),
    ("Gap/Normal Pulses Share", Band::Fraction, |s| {
        Value::Real(pulse_share(s, |p| p.normal))
    }),
    ("Gap/Arc Pulses Share", Band::Fraction, |s| {
        Value::Real(pulse_share(s, |p| p.arc))
    }),
    ("Gap/Short Pulses Share", Band::Fraction, |s| {
        Value::Real(pulse_share(s, |p| p.short))
    }),
    ("Gap/Open Pulses Share", Band::Fraction, |s| {
        Value::Real(pulse_share(s, |p| p.open))
    }),
    ("Gap/Ignition Delay", Band::MmPerMin, |s| {
        Value::Real(process(s, |p| p.mean_ignition_delay_us).unwrap_or(0.0))
    }),
    ("Generator/Off Time", Band::Exact, |s| {
        Value::Real(process(s, |p| Some(p.off_time_us)).unwrap_or(0.0))
    }),
    ("Process/Height Estimate", Band::Mm, |s| {
        Value::Real(process(s, |p| p.height_estimate_mm).unwrap_or(0.0))
    }),
    ("Process/Cut Rate", Band::MmPerMin, |s| {
        Value::Real(process(s, |p| p.cut_rate_mm2_per_min).unwrap_or(0.0))
    }),
    ("Gap/Normal Share", Band::Fraction, |s| {
        Value::Real(s.shares[0])
    }),
    ("Gap/Open Share", Band::Fraction, |s| {
        Value::Real(s.shares[1])
    }),
    ("Gap/Short Share", Band::Fraction, |s| {
        Value::Real(s.shares[2])
    }),
    ("Counters/Shorts", Band::Exact, |s| {
        Value::Count(s.status.counters.servo.shorts)
    }),
    ("Counters/Turn-backs", Band::Exact, |s| {
        Value::Count(s.status.counters.servo.turn_backs)
    }),
    ("Counters/Wire Breaks", Band::Exact, |s| {
        Value::Count(s.status.counters.servo.wire_breaks)
    }),
    ("Counters/Jobs", Band::Exact, |s| {
        Value::Count(s.status.hours.jobs)
    }),
    ("Counters/Machine Time", Band::Seconds, |s| {
        Value::Real(s.status.hours.machine_s)
    }),
    ("Counters/Spark Time", Band::Seconds, |s| {
        Value::Real(s.status.hours.spark_s)
    }),
    ("Job/Active", Band::Exact, |s| {
        Value::Flag(s.status.job.is_some())
    }),
    ("Job/Program", Band::Exact, |s| {
        text(job(s, |j| j.program.as_str()).unwrap_or(""))
    }),
    ("Job/Line", Band::Exact, |s| {
        Value::Count(job(s, |j| j.line).unwrap_or(0))
    }),
    ("Job/Pass", Band::Exact, |s| {
        Value::Count(job(s, |j| j.pass).flatten().unwrap_or(0))
    }),
    ("Job/Passes", Band::Exact, |s| {
        Value::Count(job(s, |j| j.passes as u64).unwrap_or(0))
    }),
    ("Job/Progress", Band::Fraction, |s| {
        Value::Real(job(s, |j| j.progress).unwrap_or(0.0))
    }),
    ("Job/Time To Go", Band::Seconds, |s| {
        Value::Real(job(s, |j| j.eta_s).flatten().unwrap_or(0.0))
    }),
    ("Job/Technology", Band::Exact, |s| {
        text(job(s, |j| j.technology.as_deref()).flatten().unwrap_or(""))
    }),
    ("Job/Last Program", Band::Exact, |s| {
        text(
            s.status
                .last_job
                .as_ref()
                .map_or("", |j| j.program.as_str()),
        )
    }),
    ("Job/Last Outcome", Band::Exact, |s| {
        text(s.status.last_job.as_ref().map_or("", |j| j.outcome.name()))
    }),
];

/// Each axis's metrics, under `Axes/<name>/`.
const PER_AXIS: &[(&str, Band, ReadAxis)] = &[
    ("Machine Position", Band::Mm, |s, i| {
        Value::Real(
            s.status
                .machine
                .position_machine_mm
                .get(i)
                .copied()
                .unwrap_or(0.0),
        )
    }),
    ("Work Position", Band::Mm, |s, i| {
        Value::Real(
            s.status
                .machine
                .position_work_mm
                .get(i)
                .copied()
                .unwrap_or(0.0),
        )
    }),
    ("Homed", Band::Exact, |s, i| {
        Value::Flag(s.status.machine.homed.get(i).copied().unwrap_or(false))
    }),
];

/// What a host asked for in an NCMD.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    Rebirth,
    Hold,
    Abort,
}

impl Command {
    pub fn name(self) -> &'static str {
        match self {
            Command::Rebirth => "Rebirth",
            Command::Hold => "Hold",
            Command::Abort => "Abort",
        }
    }
}

/// The edge node's Sparkplug state: its metrics, the session and message counts, and what
/// each metric last said.
pub struct EdgeNode {
    defs: Vec<Def>,
    bands: Deadbands,
    bd_seq: u64,
    seq: u64,
    /// What each metric last said in this session (empty before its birth).
    sent: Vec<Value>,
    /// The gap readings counted at the last sample.
    gap_ticks: Option<[u64; 3]>,
}

fn bd_seq_metric(bd_seq: u64) -> Metric {
    let mut m = Metric::new();
    m.name = Some("bdSeq".into());
    m.datatype = Some(DataType::UInt64 as u32);
    m.value = Some(metric::Value::LongValue(bd_seq));
    m
}

/// NDEATH of the session numbered `bd_seq`: the will registered with it, and what a clean
/// stop publishes.
pub fn death(bd_seq: u64, now_ms: u64) -> Vec<u8> {
    Payload {
        timestamp: Some(now_ms),
        metrics: vec![bd_seq_metric(bd_seq)],
        seq: None,
        uuid: None,
        body: None,
    }
    .encode_to_vec()
}

/// Milliseconds since the epoch, as Sparkplug stamps messages.
pub fn now_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

impl EdgeNode {
    /// The node of a machine with `axes`, before its first session (bdSeq 0).
    pub fn new(axes: &[String], bands: Deadbands) -> EdgeNode {
        let mut defs: Vec<Def> = WHOLE
            .iter()
            .map(|&(name, band, read)| Def {
                name: name.to_string(),
                band,
                read: Read::Whole(read),
            })
            .collect();
        for (i, axis) in axes.iter().enumerate() {
            defs.extend(PER_AXIS.iter().map(|&(name, band, read)| Def {
                name: format!("Axes/{axis}/{name}"),
                band,
                read: Read::Axis(i, read),
            }));
        }
        EdgeNode {
            defs,
            bands,
            bd_seq: 0,
            seq: 0,
            sent: Vec::new(),
            gap_ticks: None,
        }
    }

    /// The session's birth-death number.
    pub fn bd_seq(&self) -> u64 {
        self.bd_seq
    }

    /// A session numbered `bd_seq` began (its will carries that number): nothing of the
    /// last one was sent in it.
    pub fn set_session(&mut self, bd_seq: u64) {
        self.bd_seq = bd_seq;
        self.sent.clear();
    }

    fn value(def: &Def, sample: &Sample) -> Value {
        match def.read {
            Read::Whole(read) => read(sample),
            Read::Axis(i, read) => read(sample, i),
        }
    }

    /// The gap readings' shares since the last sample, from the counts in `status`.
    pub fn shares(&mut self, status: &Status) -> [f64; 3] {
        let now = status.counters.gap_ticks;
        let before = self.gap_ticks.replace(now).unwrap_or(now);
        let delta: Vec<u64> = (0..3).map(|i| now[i].saturating_sub(before[i])).collect();
        let total: u64 = delta.iter().sum();
        if total == 0 {
            return [0.0; 3];
        }
        // Status counts normal, open, short.
        std::array::from_fn(|i| delta[i] as f64 / total as f64)
    }

    /// NBIRTH: every metric named, typed and aliased, seq 0.
    pub fn birth(&mut self, sample: &Sample, now_ms: u64) -> Vec<u8> {
        self.seq = 0;
        self.sent = self.defs.iter().map(|d| Self::value(d, sample)).collect();
        let mut metrics = vec![bd_seq_metric(self.bd_seq)];
        for (i, (def, value)) in self.defs.iter().zip(&self.sent).enumerate() {
            let mut m = Metric::new();
            m.name = Some(def.name.clone());
            m.alias = Some(i as u64 + 1);
            m.timestamp = Some(now_ms);
            m.datatype = Some(value.datatype() as u32);
            m.value = Some(value.wire());
            metrics.push(m);
        }
        Payload {
            timestamp: Some(now_ms),
            metrics,
            seq: Some(0),
            uuid: None,
            body: None,
        }
        .encode_to_vec()
    }

    fn band(&self, band: Band) -> Option<f64> {
        match band {
            Band::Exact => None,
            Band::Mm => Some(self.bands.mm),
            Band::MmPerMin => Some(self.bands.mm_per_min),
            Band::Fraction => Some(self.bands.fraction),
            Band::Seconds => Some(self.bands.s),
        }
    }

    /// Whether `new` is to be sent after `old` was.
    fn moved(&self, def: &Def, old: &Value, new: &Value) -> bool {
        match (old, new, self.band(def.band)) {
            (Value::Real(a), Value::Real(b), Some(band)) => {
                // Zero is always told exactly: a job's end, an axis at home.
                (b - a).abs() > band || (*b == 0.0 && *a != 0.0) || a.is_nan() != b.is_nan()
            }
            _ => old != new,
        }
    }

    /// NDATA with what moved past its deadband, by alias; `None` when nothing did (or
    /// before the birth).
    pub fn data(&mut self, sample: &Sample, now_ms: u64) -> Option<Vec<u8>> {
        if self.sent.is_empty() {
            return None;
        }
        let mut metrics = Vec::new();
        for i in 0..self.defs.len() {
            let value = Self::value(&self.defs[i], sample);
            if self.moved(&self.defs[i], &self.sent[i], &value) {
                let mut m = Metric::new();
                m.alias = Some(i as u64 + 1);
                m.timestamp = Some(now_ms);
                m.value = Some(value.wire());
                metrics.push(m);
                self.sent[i] = value;
            }
        }
        if metrics.is_empty() {
            return None;
        }
        self.seq = (self.seq + 1) % 256;
        Some(
            Payload {
                timestamp: Some(now_ms),
                metrics,
                seq: Some(self.seq),
                uuid: None,
                body: None,
            }
            .encode_to_vec(),
        )
    }

    /// What an NCMD asks for: each node control metric written `true`, by name or alias.
    /// Anything else is an error naming it (the node's other metrics are read-only).
    pub fn commands(&self, bytes: &[u8]) -> Result<Vec<Command>, String> {
        let payload =
            Payload::decode(bytes).map_err(|e| format!("not a Sparkplug B payload: {e}"))?;
        let mut asked = Vec::new();
        for m in &payload.metrics {
            let name = match (&m.name, m.alias) {
                (Some(name), _) => bounded(name, MAX_QUOTED_NAME),
                (None, Some(alias)) => alias
                    .checked_sub(1)
                    .and_then(|i| self.defs.get(i as usize))
                    .map(|d| d.name.clone())
                    .ok_or_else(|| format!("alias {alias} names no metric"))?,
                (None, None) => return Err("a metric without a name or alias".into()),
            };
            let command = match name.as_str() {
                REBIRTH => Command::Rebirth,
                HOLD => Command::Hold,
                ABORT => Command::Abort,
                other => return Err(format!("{other:?} cannot be written")),
            };
            match m.value {
                Some(metric::Value::BooleanValue(true)) => asked.push(command),
                Some(metric::Value::BooleanValue(false)) => {}
                _ => return Err(format!("{name:?} takes a Boolean true")),
            }
        }
        Ok(asked)
    }
}

#[cfg(test)]
mod tests;
