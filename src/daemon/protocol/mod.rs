//! The control protocol: one JSON object per line each way.
//!
//! ```text
//! → {"cmd":"run","program":"part.nc"}          ← {"ok":true,"message":"…","status":{…}}
//! → {"cmd":"hold"} | {"cmd":"resume","force":false} | {"cmd":"abort"} | {"cmd":"status"}
//! → {"cmd":"rethread","here":false}
//! ← {"ok":false,"error":"request:1:9: unknown command \"fly\", expected one of …"}
//! ```
//!
//! Every reply carries the daemon's status after the command. A request that is not valid
//! JSON, names an unknown command or field, or lacks a field is answered with an error that
//! locates it (`request:LINE:COL: what`) and the connection stays usable.

mod console;
mod json;
mod text;

pub use console::{JobStatus, ProcessStatus, PulseClasses, WireOffsetStatus, WorkOffsetRow};
pub use json::from_json;
pub use text::duration_text;

use serde::{Deserialize, Serialize};

use crate::runtime::{JobSummary, axis_list};

pub(super) fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// Longest request line accepted (bytes).
pub const MAX_REQUEST_BYTES: usize = 64 * 1024;

/// A command from a client.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "cmd", rename_all = "lowercase", deny_unknown_fields)]
pub enum Request {
    /// Run a program from the program directory; `dry_run`: its moves with the spark off
    /// and the servo out of the loop, at the programmed feed (proving a program);
    /// `from_line`: cut from this source line, reached by `approach` (default: `direct` on a
    /// machine with `machine.safe_z_mm`, `path` otherwise).
    Run {
        program: String,
        #[serde(default)]
        dry_run: bool,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        from_line: Option<u64>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        approach: Option<crate::path::Approach>,
        /// A run from a line by the path: where the wire stands (the operator confirms it).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        wire_at: Option<crate::path::WireAt>,
        /// A run from a line in a job in passes: the pass (from 1) the line is cut in.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        pass: Option<u8>,
        /// Cut the program once per pass of `[wire] pass`, the first `passes` of them.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        passes: Option<usize>,
        /// In passes: the tab this job leaves (mm; 0: none), in place of `wire.tab_mm`.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        tab_mm: Option<f64>,
        /// Cut with a technology table: `material=steel,height=32,wire=0.25`.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        technology: Option<String>,
        /// A run from a line on a position not trusted (after an unclean stop): the operator
        /// checked it.
        #[serde(default, skip_serializing_if = "std::ops::Not::not")]
        force: bool,
    },
    /// Brake to a standstill and stay there. (Empty struct variants, not unit ones: serde
    /// checks unknown fields only on those.)
    Hold {},
    /// Release a hold, or resume the checkpoint's job when none is running.
    Resume {
        /// Resume from a checkpoint written while cutting.
        #[serde(default)]
        force: bool,
    },
    /// Brake to a standstill and end the job (checkpoint kept).
    Abort {},
    Status {},
    /// After a wire break: back along the path to the start hole (`here`: thread where the
    /// wire broke) and wait there for `resume`.
    Rethread {
        #[serde(default)]
        here: bool,
    },
    /// The work offset table.
    Offsets {},
    /// The job history, newest first: the last `count` jobs (20 by default).
    Jobs {
        #[serde(default)]
        count: Option<usize>,
        /// The newest jobs to pass over (a page further back).
        #[serde(default)]
        skip: Option<usize>,
    },
    /// The technology tables, and what `request` (`material=steel,height=32,wire=0.25`)
    /// selects, explained.
    Technology {
        #[serde(default)]
        request: Option<String>,
    },
    /// A one-time login link to the web page (valid 10 minutes, for one use).
    #[serde(rename = "web-link")]
    WebLink {},
    /// `G10 L20` for where the machine stands: `axis` reads `value` (mm) in `system`
    /// (default: the active one).
    #[serde(rename = "touch-off")]
    TouchOff {
        axis: String,
        value: f64,
        #[serde(default)]
        system: Option<String>,
    },
    /// Move `axis` by `distance_mm` (spark off), at `feed_mm_per_min` or the jog maximum;
    /// stops at the soft limits.
    Jog {
        axis: String,
        distance_mm: f64,
        #[serde(default)]
        feed_mm_per_min: Option<f64>,
    },
    /// Jog `axis` towards its soft limit (`positive`: upwards) until the request stops being
    /// renewed: the same request again within 250 ms keeps it going (a dead-man).
    #[serde(rename = "jog-continuous")]
    JogContinuous {
        axis: String,
        positive: bool,
        #[serde(default)]
        feed_mm_per_min: Option<f64>,
    },
    /// Clear an E-stop once its input is released.
    Reset {},
    /// Remove the checkpoint (a stopped job the operator will not resume); `confirm`: the
    /// operator confirmed it (it cannot be undone). A checkpoint kept aside is the
    /// checkpoint again.
    Discard {
        #[serde(default)]
        confirm: bool,
    },
    /// Stop a continuous jog now.
    #[serde(rename = "jog-stop")]
    JogStop {},
    /// Set the feed (0–200 %) or rapid (0–100 %) override, in force at once and for the
    /// jobs after.
    Override {
        kind: OverrideKind,
        percent: f64,
    },
    /// Single block on or off: while on, a job pauses before every program block (a
    /// standstill, checkpointed); `resume` runs the next one.
    #[serde(rename = "single-block")]
    SingleBlock {
        on: bool,
    },
    /// Run G-code lines as a job, in the modes the last MDI lines left.
    Mdi {
        line: String,
    },
    /// A wire-touch cycle: `target` is `edge X+|X-|Y+|Y-`, `corner X±Y±` or `center`;
    /// `system` (`G54` … `G59.3`): the result written into that work offset (`G10 L20`).
    Find {
        target: String,
        #[serde(default)]
        system: Option<String>,
    },
    /// Home `axes` by their switches (all with one when empty); `here`: where they stand is
    /// their home position (axes without a switch; `force`: those with one too).
    Home {
        #[serde(default)]
        axes: Vec<String>,
        #[serde(default)]
        here: bool,
        #[serde(default)]
        force: bool,
    },
}

/// A request line that is not a request: where in it, and what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("request:{line}:{col}: {what}")]
pub struct RequestError {
    pub line: usize,
    pub col: usize,
    pub what: String,
}

impl Request {
    /// Parses one request line; errors are `request:LINE:COL: what`.
    pub fn parse(line: &str) -> Result<Request, RequestError> {
        from_json(line.as_bytes()).map_err(|e| RequestError {
            line: e.line(),
            col: e.column(),
            what: strip_location(&e),
        })
    }
}

/// serde_json appends " at line L column C" to its messages; the prefix says it already.
pub fn strip_location(e: &serde_json::Error) -> String {
    let text = e.to_string();
    match text.rfind(" at line ") {
        Some(i) => text[..i].to_string(),
        None => text,
    }
}

/// A reply.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Reply {
    pub ok: bool,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub message: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub status: Option<Status>,
    /// The job history (`jobs`), newest first.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub jobs: Option<Vec<crate::daemon::history::JobRecord>>,
    /// The technology tables (`technology`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub technology: Option<Vec<crate::technology::TableSummary>>,
}

impl Reply {
    pub fn ok(message: impl Into<String>, status: Status) -> Reply {
        Reply {
            ok: true,
            message: Some(message.into()),
            error: None,
            status: Some(status),
            jobs: None,
            technology: None,
        }
    }

    pub fn error(error: impl Into<String>, status: Option<Status>) -> Reply {
        Reply {
            ok: false,
            message: None,
            error: Some(error.into()),
            status,
            jobs: None,
            technology: None,
        }
    }

    pub fn to_line(&self) -> String {
        let mut line = serde_json::to_string(self).expect("replies serialise");
        line.push('\n');
        line
    }
}

/// Which override.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum OverrideKind {
    Feed,
    Rapid,
}

/// The operator's overrides in force, percent.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct OverrideStatus {
    pub feed_pct: u32,
    pub rapid_pct: u32,
}

impl Default for OverrideStatus {
    fn default() -> Self {
        OverrideStatus {
            feed_pct: 100,
            rapid_pct: 100,
        }
    }
}

/// What the daemon is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DaemonState {
    /// No job.
    Idle,
    /// A program is being copied and checked; nothing moves yet.
    Checking,
    /// A job is cutting (or turning back, or starved).
    Running,
    /// A hold was asked for; still braking.
    Holding,
    /// Held at a standstill.
    Held,
    /// Held at a standstill by a programmed stop (`M0`, or `M1` with the optional stop on):
    /// `resume` continues.
    Paused,
    /// Braking to end the job (abort, SIGTERM).
    Stopping,
    /// The wire broke: held where it broke until `rethread`.
    WireBreak,
    /// Going back along the path to the start hole for a rethread.
    Rethreading,
    /// An MDI job is running.
    Mdi,
    /// Stopped by the E-stop: nothing moves until `reset`.
    Estop,
    /// Stopped by a limit switch: only a jog away from it moves.
    Limit,
    /// A jog is moving.
    Jogging,
    /// An axis is finding its home switch.
    Homing,
    /// Parked for threading (at the start hole or where the wire broke) until `resume`.
    Threading,
    /// A wire-touch cycle (`find`) is touching the part.
    Finding,
}

impl DaemonState {
    /// Every state, once (the metrics' `edmd_state` gauges list them all).
    pub const ALL: [DaemonState; 16] = [
        DaemonState::Idle,
        DaemonState::Checking,
        DaemonState::Running,
        DaemonState::Holding,
        DaemonState::Held,
        DaemonState::Paused,
        DaemonState::Stopping,
        DaemonState::WireBreak,
        DaemonState::Rethreading,
        DaemonState::Mdi,
        DaemonState::Estop,
        DaemonState::Limit,
        DaemonState::Jogging,
        DaemonState::Homing,
        DaemonState::Threading,
        DaemonState::Finding,
    ];

    pub fn name(self) -> &'static str {
        match self {
            DaemonState::Idle => "idle",
            DaemonState::Checking => "checking",
            DaemonState::Running => "running",
            DaemonState::Holding => "holding",
            DaemonState::Held => "held",
            DaemonState::Paused => "paused",
            DaemonState::Stopping => "stopping",
            DaemonState::WireBreak => "wire-break",
            DaemonState::Rethreading => "rethreading",
            DaemonState::Mdi => "mdi",
            DaemonState::Estop => "estop",
            DaemonState::Limit => "limit",
            DaemonState::Jogging => "jogging",
            DaemonState::Homing => "homing",
            DaemonState::Threading => "threading",
            DaemonState::Finding => "finding",
        }
    }
}

/// The status report (`status`, and every reply).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Status {
    pub state: DaemonState,
    pub version: String,
    pub uptime_s: f64,
    pub axes: Vec<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub job: Option<JobStatus>,
    /// The last job that ended.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub last_job: Option<JobSummary>,
    /// The checkpoint on disk: what `resume` would continue.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub checkpoint: Option<CheckpointStatus>,
    /// A stopped job's checkpoint kept aside while another program job runs or stopped: the
    /// checkpoint again once none is (`discard` the current one, or let its job end done).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kept_checkpoint: Option<CheckpointStatus>,
    /// Why the last checkpoint write failed; absent once a write succeeds again.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub checkpoint_write_error: Option<String>,
    /// The check in progress, or the verdict of the last one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub check: Option<CheckStatus>,
    /// Real-time features the system refused.
    pub rt_refused: Vec<String>,
    /// Counts over the daemon's life: the jobs that ended plus the running one.
    #[serde(default)]
    pub counters: Counters,
    /// The machine's hour counters over its life (kept across restarts, with the job
    /// history): jobs ended before the running one.
    #[serde(default)]
    pub hours: crate::daemon::history::HourCounters,
    /// The job history's last write failed: why.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub history_write_error: Option<String>,
    /// Requests the control loop has answered since the daemon started (commands, and the
    /// socket's status requests; the web side, OPC UA and Sparkplug read the posted status
    /// without asking).
    #[serde(default)]
    pub control_requests: u64,
    /// Where the machine stands, in machine and work coordinates, homed axes, soft limits.
    pub machine: MachineStatus,
    /// The feed and rapid overrides in force.
    #[serde(default)]
    pub overrides: OverrideStatus,
    /// Single block is on.
    #[serde(default)]
    pub single_block: bool,
    /// The Sparkplug B edge node, when `daemon.mqtt` is on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mqtt: Option<MqttStatus>,
}

/// The Sparkplug B edge node: its broker, whether it is connected, what it sent and dropped.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MqttStatus {
    pub broker: String,
    /// `group/node`.
    pub node: String,
    pub connected: bool,
    /// NBIRTHs published (the first, each reconnect, each rebirth).
    pub births: u64,
    /// Messages handed to the broker's queue.
    pub published: u64,
    /// Messages dropped because the queue was full (the broker slow or away).
    pub dropped: u64,
    /// NCMD holds and aborts refused because `daemon.mqtt.commands` is false.
    pub commands_refused: u64,
}

#[cfg(test)]
impl Status {
    /// A status for tests: `state`, axes X and Y, no job, nothing counted.
    pub fn bare(state: DaemonState) -> Status {
        Status {
            machine: Default::default(),
            overrides: Default::default(),
            single_block: false,
            mqtt: None,
            state,
            version: "0".into(),
            uptime_s: 0.0,
            axes: vec!["X".into(), "Y".into()],
            job: None,
            last_job: None,
            checkpoint: None,
            kept_checkpoint: None,
            checkpoint_write_error: None,
            check: None,
            rt_refused: Vec::new(),
            counters: Counters::default(),
            hours: Default::default(),
            history_write_error: None,
            control_requests: 0,
        }
    }
}

fn yes() -> bool {
    true
}

/// The machine, always (idle, held, running).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MachineStatus {
    /// Machine coordinates, mm per axis.
    pub position_machine_mm: Vec<f64>,
    /// In the active work system (without a program's `G92`), mm per axis.
    pub position_work_mm: Vec<f64>,
    /// `G54` … `G59.3`.
    pub work_system: String,
    /// The work offset table: every system's zero in machine coordinates (mm, per axis),
    /// `G54` first.
    #[serde(default)]
    pub work_offsets: Vec<WorkOffsetRow>,
    pub homed: Vec<bool>,
    /// The position is believed, not known (after an unclean stop, or drives found moved):
    /// runs from a line and resumes need the operator's word until it is homed or confirmed.
    #[serde(default = "yes")]
    pub position_trusted: bool,
    /// Soft limits `[lowest, highest]` per axis (`null`: none).
    pub travel_mm: Vec<Option<[f64; 2]>>,
    /// Why the last write of the machine state failed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub state_write_error: Option<String>,
    /// The wire-touch cycle running, or the last one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub find: Option<FindStatus>,
}

/// A wire-touch cycle (`find`) as the status shows it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FindStatus {
    /// Counts the daemon's cycles: the reply to `find` names its own.
    pub id: u64,
    /// `edge X+`, `corner X+Y-`, `center`.
    pub target: String,
    /// `running`, `found` or `failed`.
    pub state: String,
    /// What it found (or why not), as the log says it.
    pub message: String,
    /// The edge, corner or centre found, X and Y in machine coordinates, mm (`null`: the
    /// axis an edge does not measure).
    #[serde(default)]
    pub point_mm: Vec<Option<f64>>,
    /// A hole's diameter on X and on Y, mm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub diameter_mm: Option<[f64; 2]>,
    /// The work system the result was written into.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub system: Option<String>,
}

/// Counts over the daemon's life (the jobs that ended plus the running one), only ever
/// growing: what Prometheus counters and the histogram of `/metrics` are made of.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Counters {
    /// Jobs started.
    pub jobs: u64,
    /// The servo's counts over all jobs (flat in the JSON; the deepest turn-back the deepest
    /// of any job).
    #[serde(flatten)]
    pub servo: crate::servo::ServoCounters,
    pub holds: u64,
    pub overruns: u64,
    pub ticks: u64,
    /// Checkpoint writes that failed.
    #[serde(default)]
    pub checkpoint_failures: u64,
    /// Ticks by the gap state read: normal, open, short.
    pub gap_ticks: [u64; 3],
    /// Real time: wake-up latency counts per bucket of `runtime::consumer::LATENCY_BUCKETS_US`,
    /// the last above them all; and the sum (µs).
    pub latency_buckets: Vec<u64>,
    pub latency_sum_us: f64,
}

impl Counters {
    /// These counts plus `other`'s.
    pub fn plus(&self, other: &Counters) -> Counters {
        let n = self.latency_buckets.len().max(other.latency_buckets.len());
        let bucket = |v: &Vec<u64>, i: usize| v.get(i).copied().unwrap_or(0);
        Counters {
            jobs: self.jobs + other.jobs,
            servo: self.servo.plus(&other.servo),
            holds: self.holds + other.holds,
            overruns: self.overruns + other.overruns,
            ticks: self.ticks + other.ticks,
            checkpoint_failures: self.checkpoint_failures + other.checkpoint_failures,
            gap_ticks: std::array::from_fn(|i| self.gap_ticks[i] + other.gap_ticks[i]),
            latency_buckets: (0..n)
                .map(|i| bucket(&self.latency_buckets, i) + bucket(&other.latency_buckets, i))
                .collect(),
            latency_sum_us: self.latency_sum_us + other.latency_sum_us,
        }
    }
}

/// A `run` (or `resume`) is answered at once; its program is then copied and checked on a
/// worker, and the verdict lands here.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CheckStatus {
    /// Counts the checks of this daemon; the `run` reply carries the one it started.
    pub id: u64,
    pub program: String,
    /// `copying`, `checking`, then `started` or `refused`.
    pub phase: String,
    pub bytes_done: u64,
    pub bytes_total: u64,
    /// Why the job was refused (the program's `file:line:col` error, a cancel, …).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// What the job's start said (`running X: N blocks`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub message: Option<String>,
    pub resume: bool,
}

impl CheckStatus {
    /// The verdict is in: the job started or was refused.
    pub fn decided(&self) -> bool {
        self.phase == "started" || self.phase == "refused"
    }
}

/// The checkpoint on disk, in short.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CheckpointStatus {
    pub program: String,
    pub line: u64,
    pub reason: String,
    pub still: bool,
    pub position_steps: Vec<i64>,
    /// `resume` would continue it now: no job runs or is being checked (while one runs, the
    /// checkpoint is that job's own).
    #[serde(default)]
    pub resumable: bool,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_parse_and_errors_are_located() {
        assert_eq!(
            Request::parse(r#"{"cmd":"run","program":"a.nc"}"#).unwrap(),
            Request::Run {
                program: "a.nc".into(),
                dry_run: false,
                from_line: None,
                approach: None,
                wire_at: None,
                pass: None,
                passes: None,
                tab_mm: None,
                technology: None,
                force: false,
            }
        );
        assert_eq!(
            Request::parse(r#"{"cmd":"run","program":"a.nc","from_line":12,"approach":"path","wire_at":"stopped","technology":"material=x"}"#).unwrap(),
            Request::Run {
                program: "a.nc".into(),
                dry_run: false,
                from_line: Some(12),
                approach: Some(crate::path::Approach::Path),
                wire_at: Some(crate::path::WireAt::Stopped),
                pass: None,
                passes: None,
                tab_mm: None,
                technology: Some("material=x".into()),
                force: false,
            }
        );
        assert_eq!(
            Request::parse(r#"{"cmd":"resume"}"#).unwrap(),
            Request::Resume { force: false }
        );
        assert_eq!(
            Request::parse(r#"{"cmd":"status"}"#).unwrap(),
            Request::Status {}
        );
        let e = Request::parse(r#"{"cmd":"fly"}"#).unwrap_err().to_string();
        assert!(
            e.starts_with("request:1:") && e.contains("unknown variant"),
            "{e}"
        );
        let e = Request::parse(r#"{"cmd":"run"}"#).unwrap_err().to_string();
        assert!(e.contains("missing field `program`"), "{e}");
        let e = Request::parse("{\"cmd\":\n\"hold\",}")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("request:2:"), "{e}");
        let e = Request::parse(r#"{"cmd":"hold","extra":1}"#)
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown field"), "{e}");
        assert!(!e.contains(" at line "), "{e}");
    }

    /// A key named twice is refused at its second place, whichever key and however deep;
    /// the same keys once each still parse.
    #[test]
    fn a_key_named_twice_is_refused() {
        for (line, col) in [
            (r#"{"cmd":"jog","axis":"X","axis":"Y","distance_mm":1}"#, 30),
            (r#"{"cmd":"hold","cmd":"abort"}"#, 19),
            (r#"{"cmd":"resume","force":false,"force":true}"#, 37),
        ] {
            let e = Request::parse(line).unwrap_err();
            assert!(e.what.contains("duplicate key"), "{line}: {e}");
            assert_eq!((e.line, e.col), (1, col), "{line}: {e}");
        }
        let nested: Result<serde_json::Value, _> = from_json(br#"{"a":[{"b":1,"b":2}]}"#);
        assert!(
            nested
                .unwrap_err()
                .to_string()
                .contains("duplicate key \"b\"")
        );
        assert_eq!(
            Request::parse(r#"{"cmd":"jog","axis":"X","distance_mm":1}"#).unwrap(),
            Request::Jog {
                axis: "X".into(),
                distance_mm: 1.0,
                feed_mm_per_min: None
            }
        );
    }
}
