//! `edmd serve`: the daemon around the runtime.
//!
//! ```text
//!  signals (edmd-signals) ─┐
//!  clients (edmd-client) ──┼─► control loop (main thread) ──► job thread (edmd-job)
//!  job ends (edmd-job) ────┘     │ JobControl (job, check,        runtime::run: producer,
//!                                │ port, fine thread),            supervisor ─► FineThread
//!                                │ CheckpointKeeper, Clients,     (edmd-fine, started once)
//!                                │ watchdog, status line
//!                                └─ every PERIOD: periodic work
//! ```
//!
//! One thread owns every decision: the control loop. Clients, signals and finished jobs are
//! messages to it ([`CoreMsg`]), so there is no state shared between request handlers and no
//! order in which two commands could interleave. It never waits on the real-time thread: it
//! steers a job through the job's [`Published`] flags (hold, stop) and reads the job's
//! seqlocked [`Snapshot`](crate::runtime::Snapshot).
//!
//! **Startup** claims the parallel port (when configured), starts the fine thread (real-time
//! settings applied), binds the socket, then tells systemd `READY=1`. Anything that fails
//! before that is an exit 1 with an operator message.
//!
//! **Jobs**: a program's coordinates start where the electrode stands when the job starts
//! (the work origin is set there), and the job's ledger counts from zero. A job ends done,
//! stopped, aborted or in alarm; every end but "done" writes an exact checkpoint (at a
//! standstill), "done" removes it. `resume` with no job running continues the checkpoint's
//! job: same program bytes, same `[machine]`/`[interpolation]`, or it refuses.
//!
//! **Signals**: SIGTERM/SIGINT brake the job to a standstill, checkpoint it and exit 0 (a
//! second one stops at once, position kept). SIGHUP reloads the configuration (see
//! [`reload`]). SIGUSR1 writes the status into the log.

pub mod board;
mod checkpoints;
mod desk;
mod dispatch;
pub mod error;
pub mod history;
pub mod http;
mod jobs;
mod launch;
pub mod link;
mod machine;
pub mod mqtt;
pub mod names;
pub mod noise;
pub mod notify;
pub mod opcua;
mod overrides;
pub mod protocol;
pub mod refusal;
pub mod reload;
pub mod socket;
mod start;
mod status;
mod upkeep;

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use crossbeam::channel::{self, Receiver, RecvTimeoutError, Sender};

use crate::checkpoint::{Checkpoint, Reason};
use crate::config::{Config, KeyValues, OutputKind};
use crate::runtime::{self, FineThread, JobEnd, LoopSettings, ProgressTracker, Published};
use checkpoints::CheckpointKeeper;
pub use error::DaemonError;
use jobs::JobControl;
use link::CoreLink;
pub use names::{confine, has_control};
use notify::{Notifier, Watchdog, WatchdogGate};
use protocol::{Reply, Request};
pub use reload::ConfigSource;

/// How often the control loop does its periodic work when no message arrives.
const PERIOD: Duration = Duration::from_millis(250);
/// Overruns are reported at most this often (a loaded machine would flood the log).
const OVERRUN_REPORT: Duration = Duration::from_secs(5);
/// History pages read at once (`jobs`), each on a thread of its own.
const MAX_HISTORY_READERS: usize = 4;

/// Where a request's reply goes.
type ReplyTo = tokio::sync::oneshot::Sender<Reply>;

/// A message to the control loop.
pub enum CoreMsg {
    /// A client's request and where its reply goes: the client's task awaits it (a socket
    /// client's or an HTTP request's), holding no thread while it waits.
    Request(Request, tokio::sync::oneshot::Sender<Reply>),
    Signal(i32),
    JobDone(Box<JobEnd>),
    /// A check worker's verdict on check `id`.
    Checked {
        id: u64,
        result: Box<Result<launch::Checked, refusal::CheckRefusal>>,
    },
    /// The reload worker's reads (SIGHUP).
    Reloaded(Box<reload::ReadBack>),
}

/// Changes the log level at run time (SIGHUP); `Err` explains why it cannot.
pub type SetLogLevel =
    Box<dyn Fn(&str) -> Result<(), Box<dyn std::error::Error + Send + Sync>> + Send>;

/// Where a job's report goes, and the recording it is written from.
type JobRecording = Arc<parking_lot::Mutex<crate::record::Recording>>;

/// The running job as the control loop sees it.
struct Job {
    program: PathBuf,
    program_sha256: String,
    published: Arc<Published>,
    stop: Arc<AtomicBool>,
    /// Why the stop was asked for: abort or a signal.
    stop_reason: Option<Reason>,
    started: Instant,
    /// When it started, local time (the job history's).
    started_at: String,
    resumed: bool,
    /// A checkpoint has been written for the current hold.
    hold_checkpointed: bool,
    last_checkpoint: Instant,
    overruns_seen: u64,
    last_overrun_report: Instant,
    /// The config the job runs with (a reload may not change it under the job).
    config: Config,
    /// How far along the program, and the ETA.
    progress: ProgressTracker,
    /// Where the job's report goes, and the recording it is written from.
    report: Option<PathBuf>,
    /// What ran: the report's recording and the page's executed path.
    recording: JobRecording,
    /// The job's path-shaping settings (`machine.*`, `interpolation.*`) for its checkpoints.
    motion_settings: crate::config::KeyValues,
    /// A resumed job's checkpoint as it was before the write-ahead replaced it: put back if
    /// the resume is refused before anything moved.
    resumed_from: Option<Checkpoint>,
    /// Where the job started: machine position, work offsets, active system.
    start: crate::gcode::WorkStart,
    /// The work offsets and system the program leaves when it runs to its end.
    leaves: (crate::gcode::WorkOffsets, crate::gcode::WorkSystem),
    /// The work offsets and system it cuts in (at its first move): the DRO's and the
    /// backplot's while it runs.
    cuts_in: (crate::gcode::WorkOffsets, crate::gcode::WorkSystem),
    /// The units and distance mode it leaves (kept for the next MDI lines).
    modes: crate::gcode::StartModes,
    /// What the program tells the operator at its stops, by the line stopped before.
    pause_messages: Vec<(u64, String)>,
    kind: launch::JobKind,
    /// Run from a line, in passes (the checkpoint records them, so a resume replays the same
    /// approach and passes).
    cut: crate::path::CutPlan,
    /// The technology it cuts with.
    technology: Option<Arc<crate::technology::Selection>>,
}

/// The daemon's state, owned by the control loop.
struct Core {
    config: Config,
    keys: KeyValues,
    source: ConfigSource,
    set_log_level: SetLogLevel,
    jobs: JobControl,
    checkpoints: CheckpointKeeper,
    machine: crate::machine::Machine,
    /// The wire-touch cycle in progress and the last one, as the status shows it.
    touch: desk::touch::TouchCycles,
    clients: Clients,
    notifier: Notifier,
    watchdog: Option<WatchdogGate>,
    last_status_line: Instant,
    started: Instant,
    shutting_down: bool,
    /// A SIGHUP's reads in progress on the reload worker.
    reloading: Option<upkeep::Reloading>,
    /// The job history and the hour counters.
    history: history::History,
    /// The technology tables (`technology.dir`), read at start and on a reload.
    technology: Arc<crate::technology::Tables>,
    /// Where the status is posted for the transports, and when it last was.
    board: Arc<board::StatusBoard>,
    /// History pages being read off the loop.
    history_readers: Arc<AtomicUsize>,
    posted_at: Instant,
    /// Something other than a status request was handled since the last post.
    post_due: bool,
    /// Requests answered (the status reports it).
    control_requests: u64,
}

/// Who talks to the core: the senders handed to clients, the cap on socket clients, the web
/// side.
struct Clients {
    to_core: Sender<CoreMsg>,
    max_clients: Arc<AtomicUsize>,
    /// The web side, when `daemon.http` is on.
    http: Option<http::HttpServer>,
    /// The OPC UA server, when `daemon.opcua` is on.
    opcua: Option<opcua::OpcUaServer>,
    /// The Sparkplug B edge node, when `daemon.mqtt` is on.
    mqtt: Option<mqtt::MqttNode>,
}

/// Runs the daemon until a signal stops it. `Ok` is exit 0.
pub fn serve(
    config: Config,
    keys: KeyValues,
    source: ConfigSource,
    set_log_level: SetLogLevel,
) -> Result<(), DaemonError> {
    let started = Instant::now();
    // Every file the daemon keeps is under it unless given a path of its own.
    if let Err(e) = std::fs::create_dir_all(&config.daemon.state_dir) {
        tracing::warn!(
            "daemon.state_dir {}: cannot make it ({e}); files kept there will fail to write",
            config.daemon.state_dir.display()
        );
    }
    let checkpoints = CheckpointKeeper::open(&config.daemon.checkpoint);
    let history = history::History::open(
        &config.daemon.job_history,
        &config.daemon.job_history.with_file_name("counters.json"),
    );
    let mut machine = machine::open_machine(&config, checkpoints.current.as_ref())?;
    let technology = Arc::new(crate::technology::Tables::of(&config)?);
    upkeep::technology_read(&technology);
    let (claimed, ready) = claim_device(&config, &mut machine)?;
    let fine = Arc::new(
        FineThread::start(&LoopSettings::from_config(&config), claimed)
            .map_err(DaemonError::Thread)?,
    );
    let listener = socket::bind(&config.daemon)?;
    let (to_core, inbox) = channel::unbounded();
    let max_clients = Arc::new(AtomicUsize::new(config.daemon.max_clients));
    let board = Arc::new(board::StatusBoard::default());
    let link = core_link(&to_core, &board);
    socket::spawn_listener(listener, link.clone(), max_clients.clone())
        .map_err(DaemonError::Thread)?;
    spawn_signal_thread(to_core.clone()).map_err(DaemonError::Thread)?;
    // Network clients are served: the soft descriptor limit goes up to the hard one, and
    // HTTP stays well below it (checkpoints and the socket keep their reserve).
    let descriptors = descriptor_limit();
    let executed = http::executed::ExecutedSlot::default();
    let http = start_http(&config, descriptors, &link, &executed, &history.file())?;
    let opcua = start_opcua(&config, &link)?;
    let mqtt = start_mqtt(&config, &link)?;
    let notifier = Notifier::from_env();
    let watchdog = notify::watchdog_period();
    let socket_path = config.daemon.socket.clone();
    tracing::info!(
        "listening on {} (programs from {}); {} time, tick {} µs",
        socket_path.display(),
        config.daemon.program_dir.display(),
        if config.fine.virtual_time {
            "virtual"
        } else {
            "real"
        },
        config.fine.tick.us()
    );
    let mut core = Core {
        config,
        keys,
        source,
        set_log_level,
        jobs: JobControl {
            fine,
            job: None,
            check: None,
            last_check: None,
            pendant: Default::default(),
            next_check_id: 0,
            last: None,
            finished: protocol::Counters::default(),
            controls: Default::default(),
            executed,
        },
        checkpoints,
        machine,
        touch: Default::default(),
        clients: Clients {
            to_core,
            max_clients,
            http,
            opcua,
            mqtt,
        },
        notifier,
        watchdog: watchdog.map(|period| WatchdogGate::new(period, started.elapsed())),
        last_status_line: Instant::now(),
        started,
        shutting_down: false,
        reloading: None,
        history,
        technology,
        board,
        history_readers: Arc::new(AtomicUsize::new(0)),
        posted_at: Instant::now(),
        post_due: true,
        control_requests: 0,
    };

    core.jobs
        .prune_copies(&core.checkpoints, &core.config.daemon.checkpoint, None);
    core.post_status();
    // HAL's `loadusr -W` returns now, so a `ctl` on the HAL file's next line finds the socket.
    if let Some(ready) = ready {
        ready
            .send()
            .map_err(|e| DaemonError::Job(Box::new(e.into())))?;
    }
    core.notifier.send("READY=1");
    core.notify_status();
    core.run(&inbox);
    core.stopped(&socket_path);
    Ok(())
}

/// The device first (the parallel port, the HAL component): if it cannot be claimed, nothing
/// else should start. The fine thread keeps it from here on, and watches it between jobs
/// (heartbeat, E-stop) from before HAL's threads start; HAL is told it is ready once the
/// daemon serves.
fn claim_device(
    config: &Config,
    machine: &mut crate::machine::Machine,
) -> Result<(Option<runtime::Claimed>, Option<crate::hal::ReadySignal>), DaemonError> {
    if !config.output.kind.hardware() {
        return Ok((None, None));
    }
    let opened = runtime::open_output(config, &[]).map_err(|e| DaemonError::Job(Box::new(e)))?;
    if config.output.kind == OutputKind::Parport {
        tracing::info!("{}: parallel port claimed", config.output.path.display());
    }
    if let Some(why) = &opened.distrust {
        machine::distrust_moved_drives(machine, why);
    }
    let claimed = runtime::Claimed {
        output: opened.output,
        gap: opened.port_gap,
        inputs: opened.inputs,
    };
    Ok((Some(claimed), opened.ready))
}

/// The descriptor limit, raised to the hard one (network clients are served).
fn descriptor_limit() -> u64 {
    match crate::sys::raise_descriptor_limit() {
        Ok(n) => n,
        Err(e) => {
            tracing::warn!("cannot read the descriptor limit ({e}); assuming 1024");
            1024
        }
    }
}

/// The web side, when `daemon.http` is on: the page, the API and the metrics, with its
/// token and a connection cap below the descriptor limit.
fn start_http(
    config: &Config,
    descriptors: u64,
    to_core: &CoreLink,
    executed: &http::executed::ExecutedSlot,
    history: &history::HistoryFile,
) -> Result<Option<http::HttpServer>, DaemonError> {
    match config.daemon.http {
        Some(addr) => {
            let token = http::token::load_or_create(&config.daemon.http_token_file)?;
            let max_connections = http::connection_cap(
                config.daemon.http_max_connections,
                descriptors,
                config.daemon.max_clients,
            );
            let settings = http::HttpSettings {
                addr,
                max_connections,
                reloadable: http::Reloadable {
                    token,
                    program_dir: config.daemon.program_dir.clone(),
                    allowed_hosts: config.daemon.http_allowed_hosts.clone(),
                },
            };
            let server = http::spawn(
                settings,
                config.machine.axes.clone(),
                crate::gcode::ProgramOptions::from_config(config),
                to_core.clone(),
                executed.clone(),
                history.clone(),
            )
            .map_err(|source| DaemonError::Http { addr, source })?;
            tracing::info!(
                "http: the page, API and metrics on http://{} (control needs the token in {}; \
                 {max_connections} connections at most, descriptor limit {descriptors})",
                server.addr,
                config.daemon.http_token_file.display()
            );
            Ok(Some(server))
        }
        None => Ok(None),
    }
}

/// The OPC UA server, when `daemon.opcua` is on.
fn start_opcua(
    config: &Config,
    to_core: &CoreLink,
) -> Result<Option<opcua::OpcUaServer>, DaemonError> {
    let Some(endpoint) = config.daemon.opcua.clone() else {
        return Ok(None);
    };
    let settings = opcua::OpcUaSettings {
        endpoint,
        users_file: config.daemon.opcua_users_file.clone(),
        pki_dir: config.daemon.opcua_pki_dir.clone(),
        axes: config.machine.axes.iter().map(|a| a.to_string()).collect(),
        program_dir: config.daemon.program_dir.clone(),
    };
    let server = opcua::spawn(settings, to_core.clone())?;
    tracing::info!(
        "opcua: the machine on {} (Hold and Abort need a user of {} on the encrypted endpoint; \
         certificates in {})",
        server.url,
        config.daemon.opcua_users_file.display(),
        config.daemon.opcua_pki_dir.display()
    );
    Ok(Some(server))
}

/// The Sparkplug B edge node, when `daemon.mqtt` is on. The broker need not be there: the
/// node connects when it can.
fn start_mqtt(config: &Config, to_core: &CoreLink) -> Result<Option<mqtt::MqttNode>, DaemonError> {
    let Some(settings) = &config.daemon.mqtt else {
        return Ok(None);
    };
    let node = mqtt::spawn(settings, &config.machine.axis_names(), to_core.clone())?;
    tracing::info!(
        "mqtt: Sparkplug B edge node {}/{} on {} (NCMD hold and abort {})",
        settings.group_id,
        settings.node_id,
        settings.broker,
        if settings.commands {
            "taken"
        } else {
            "refused: daemon.mqtt.commands is false"
        }
    );
    Ok(Some(node))
}

/// The transports' link to the control loop: their requests onto its inbox, and its board.
fn core_link(to_core: &Sender<CoreMsg>, board: &Arc<board::StatusBoard>) -> CoreLink {
    let (submit, idle) = (to_core.clone(), to_core.clone());
    CoreLink::new(
        move |request, reply| submit.send(CoreMsg::Request(request, reply)).is_ok(),
        move || idle.is_empty(),
        board.clone(),
    )
}

fn spawn_signal_thread(to_core: Sender<CoreMsg>) -> std::io::Result<()> {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM, SIGUSR1};
    let mut signals = signal_hook::iterator::Signals::new([SIGTERM, SIGINT, SIGHUP, SIGUSR1])?;
    std::thread::Builder::new()
        .name("edmd-signals".to_string())
        .spawn(move || {
            for signal in signals.forever() {
                if to_core.send(CoreMsg::Signal(signal)).is_err() {
                    return;
                }
            }
        })?;
    Ok(())
}

fn unix_now() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn confine_keeps_programs_inside_the_directory() {
        let root = std::env::temp_dir().join(format!("edmd-confine-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let dir = root.join("programs");
        std::fs::create_dir_all(dir.join("sub")).unwrap();
        std::fs::write(dir.join("a.nc"), "G1 X1 F60\n").unwrap();
        std::fs::write(dir.join("sub/b.nc"), "G1 X1 F60\n").unwrap();
        std::fs::write(root.join("secret.nc"), "G1 X1 F60\n").unwrap();
        std::os::unix::fs::symlink(root.join("secret.nc"), dir.join("escape.nc")).unwrap();
        std::os::unix::fs::symlink(dir.join("a.nc"), dir.join("inside.nc")).unwrap();

        let real = dir.canonicalize().unwrap();
        assert_eq!(confine(&dir, "a.nc").unwrap(), real.join("a.nc"));
        assert_eq!(confine(&dir, "sub/b.nc").unwrap(), real.join("sub/b.nc"));
        assert_eq!(confine(&dir, "inside.nc").unwrap(), real.join("a.nc"));
        let abs = real.join("a.nc").display().to_string();
        assert_eq!(confine(&dir, &abs).unwrap(), real.join("a.nc"));

        // Missing, outside, `..` and not-a-file: one answer, no path in it.
        for bad in [
            "../secret.nc",
            "sub/../../secret.nc",
            "escape.nc",
            "missing.nc",
            "sub",
        ] {
            let e = confine(&dir, bad).unwrap_err().to_string();
            assert_eq!(
                e,
                format!("{bad}: no such program in the program directory")
            );
        }
        let outside = root.join("secret.nc").display().to_string();
        assert_eq!(
            confine(&dir, &outside).unwrap_err().to_string(),
            format!("{outside}: no such program in the program directory")
        );
        assert!(confine(&dir, "").unwrap_err().to_string().contains("empty"));
        let forged = "a.nc\n2026-11-23T00:00:00Z INFO edmd: job end: done";
        assert!(
            confine(&dir, forged)
                .unwrap_err()
                .to_string()
                .contains("no control characters")
        );
    }
}
