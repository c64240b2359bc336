//! `[daemon.mqtt]`: a Sparkplug B edge node on the plant's MQTT broker.
//!
//! ```text
//!  status board ◄── read every interval_s ────────────── session task ── NBIRTH/NDATA ──┐
//!               ◄── Request::Hold | Abort (commands) ──┘    ▲  (try_publish: a bounded │
//!                                                           │   queue, drops counted)  ▼
//!                          Net::Connected { bd_seq } | Net::Command │   network task: rumqttc's
//!                                                           └─────── event loop ◄──► broker
//!                                                                     (will = NDEATH)
//! ```
//!
//! **Why it never stalls the machine.** Like OPC UA, the node reads the status a socket
//! client reads and asks for a hold as a client does: nothing here touches the real-time
//! thread, and the control loop answers a status in microseconds whatever the broker does.
//! What the node sends waits in rumqttc's request queue (`daemon.mqtt.queue` messages); a
//! message that finds it full is dropped and counted (`edmd_mqtt_dropped_total`, the
//! `Node Info/Dropped` metric), and the next sample is a whole NBIRTH again, so a host's
//! picture is never stale for longer than a sample once the broker takes messages again.
//!
//! **Two tasks, because rumqttc's event loop must not be cancelled.** The network task only
//! polls it: it reports a connection (with the session's bdSeq) and each NCMD, and on a lost
//! connection it drops what was queued for the old session (a new session begins with its
//! birth, so old data must not follow it), registers the next session's NDEATH as the will
//! and retries. The session task samples on a timer, builds the payloads ([`sparkplug`]),
//! answers commands and, on a clean stop, publishes NDEATH and disconnects.
//!
//! **Commands.** `Node Control/Rebirth` is always taken. `Node Control/Hold` and `Abort` go
//! to the control loop only with `daemon.mqtt.commands = true`; otherwise they are refused,
//! logged and counted, and `Node Control/Last Command` says why.

pub mod sparkplug;

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use rumqttc::{AsyncClient, Event, EventLoop, LastWill, MqttOptions, Packet, QoS};
use tokio::sync::{mpsc, oneshot, watch};

use super::link::CoreLink;
use super::protocol::{MqttStatus, Reply, Request, Status};
use crate::config::MqttConfig;
use sparkplug::{
    Command, EdgeNode, MAX_PACKET_BYTES, MAX_TEXT_BYTES, Sample, Topics, bounded, now_ms,
};

/// Longest wait for the control loop's reply.
const CORE_TIMEOUT: Duration = Duration::from_secs(10);
/// The wait before the next connection attempt after one failed or was lost.
const RETRY: Duration = Duration::from_secs(1);
/// The longest a clean stop waits for NDEATH to reach the broker.
const GOODBYE: Duration = Duration::from_secs(2);

/// Why the edge node did not start.
#[derive(Debug, thiserror::Error)]
pub enum MqttError {
    #[error("{path}: cannot read daemon.mqtt.credentials_file: {source}")]
    Credentials {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}:1:1: daemon.mqtt.credentials_file must hold `name:password` on one line")]
    CredentialsForm { path: PathBuf },
    #[error("{path}: cannot read daemon.mqtt.ca_file: {source}")]
    Ca {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("daemon.mqtt: cannot start the edge node's thread: {0}")]
    Thread(std::io::Error),
}

/// What the node counts, shared with the control loop's status.
#[derive(Debug, Default)]
pub struct MqttCounters {
    connected: AtomicBool,
    births: AtomicU64,
    published: AtomicU64,
    dropped: AtomicU64,
    refused: AtomicU64,
}

/// The running edge node.
pub struct MqttNode {
    broker: String,
    node: String,
    counters: Arc<MqttCounters>,
    /// `true` once the node is to stop.
    stop: Option<watch::Sender<bool>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl MqttNode {
    /// What the status and the metrics say of the node.
    pub fn status(&self) -> MqttStatus {
        let c = &self.counters;
        MqttStatus {
            broker: self.broker.clone(),
            node: self.node.clone(),
            connected: c.connected.load(Ordering::Relaxed),
            births: c.births.load(Ordering::Relaxed),
            published: c.published.load(Ordering::Relaxed),
            dropped: c.dropped.load(Ordering::Relaxed),
            commands_refused: c.refused.load(Ordering::Relaxed),
        }
    }

    /// Publishes NDEATH (when connected) and disconnects; waits [`GOODBYE`] at most.
    pub fn stop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(true);
        }
        if let Some(thread) = self.thread.take() {
            let deadline = std::time::Instant::now() + GOODBYE + Duration::from_millis(500);
            while !thread.is_finished() && std::time::Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(10));
            }
            if thread.is_finished() {
                let _ = thread.join();
            }
        }
    }
}

impl Drop for MqttNode {
    fn drop(&mut self) {
        self.stop();
    }
}

/// `name:password` from the credentials file (a regular file: a FIFO or a device is refused
/// at once, never waited on); one that others may read is used, with a warning.
fn credentials(path: &std::path::Path) -> Result<(String, String), MqttError> {
    let failed = |source| MqttError::Credentials {
        path: path.to_path_buf(),
        source,
    };
    let read = crate::sys::read_private(path)
        .map_err(failed)?
        .ok_or_else(|| failed(std::io::ErrorKind::NotFound.into()))?;
    if let Some(mode) = read.loose_mode {
        tracing::warn!(
            "{}: daemon.mqtt.credentials_file holds a password and is mode {mode:04o}: others \
             on this computer may read it (chmod 600)",
            path.display()
        );
    }
    let text = read.text;
    let line = text.lines().next().unwrap_or("").trim_end();
    match line.split_once(':') {
        Some((name, password)) if !name.is_empty() => Ok((name.into(), password.into())),
        _ => Err(MqttError::CredentialsForm {
            path: path.to_path_buf(),
        }),
    }
}

/// The MQTT options: a clean session (as Sparkplug requires of an edge node), the
/// keep-alive, the credentials, TLS, and the first session's NDEATH as the will.
fn options(config: &MqttConfig, topics: &Topics) -> Result<MqttOptions, MqttError> {
    let client_id = format!("edmd-{}-{}", config.group_id, config.node_id);
    let mut options = MqttOptions::new(client_id, &config.broker.host, config.broker.port);
    options
        .set_keep_alive(Duration::from_secs(u64::from(config.keep_alive_s)))
        .set_clean_session(true)
        .set_max_packet_size(MAX_PACKET_BYTES, MAX_PACKET_BYTES)
        .set_last_will(will(topics, 0));
    if let Some(path) = &config.credentials_file {
        let (name, password) = credentials(path)?;
        options.set_credentials(name, password);
    }
    if config.broker.tls {
        let tls = match &config.ca_file {
            Some(path) => rumqttc::TlsConfiguration::SimpleNative {
                ca: crate::sys::read_regular(path)
                    .map(String::into_bytes)
                    .map_err(|source| MqttError::Ca {
                        path: path.clone(),
                        source,
                    })?,
                client_auth: None,
            },
            None => rumqttc::TlsConfiguration::Native,
        };
        options.set_transport(rumqttc::Transport::tls_with_config(tls));
    }
    Ok(options)
}

/// The will of the session numbered `bd_seq`: its NDEATH, QoS 1, not retained.
fn will(topics: &Topics, bd_seq: u64) -> LastWill {
    LastWill::new(
        &topics.ndeath,
        sparkplug::death(bd_seq, now_ms()),
        QoS::AtLeastOnce,
        false,
    )
}

/// Connects to the broker and publishes on a thread of its own.
pub fn spawn(
    config: &MqttConfig,
    axes: &[String],
    to_core: CoreLink,
) -> Result<MqttNode, MqttError> {
    let topics = Topics::new(&config.group_id, &config.node_id);
    let options = options(config, &topics)?;
    let (client, eventloop) = AsyncClient::new(options, config.queue);
    let counters = Arc::new(MqttCounters::default());
    let (stop, stopped) = watch::channel(false);
    let session = Session {
        node: EdgeNode::new(axes, config.deadbands),
        topics: topics.clone(),
        client,
        to_core,
        counters: counters.clone(),
        commands: config.commands,
        answer: String::new(),
        connected: false,
        birth_due: false,
        last_birth: Vec::new(),
        commands_off: false,
        since: None,
        stop: stopped,
    };
    let interval = Duration::from_secs_f64(config.interval_s);
    let thread = std::thread::Builder::new()
        .name("edmd-mqtt".to_string())
        .spawn(move || {
            let runtime = match tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
            {
                Ok(runtime) => runtime,
                Err(e) => return tracing::error!("mqtt: cannot start: {e}"),
            };
            runtime.block_on(async move {
                let (net_tx, net_rx) = mpsc::channel(16);
                let stopping = Arc::new(AtomicBool::new(false));
                let network = tokio::spawn(network(eventloop, topics, net_tx, stopping.clone()));
                session.run(net_rx, interval, stopping).await;
                let _ = tokio::time::timeout(GOODBYE, network).await;
            })
        })
        .map_err(MqttError::Thread)?;
    Ok(MqttNode {
        broker: config.broker.to_string(),
        node: format!("{}/{}", config.group_id, config.node_id),
        counters,
        stop: Some(stop),
        thread: Some(thread),
    })
}

/// What the network task tells the session task.
enum Net {
    /// A session began (CONNACK), its will carrying `bd_seq`.
    Connected { bd_seq: u64 },
    /// An NCMD's payload.
    Command(Vec<u8>),
    /// An NBIRTH on the node's own topic (its own, echoed, or another node's).
    Birth(Vec<u8>),
    /// The connection was lost (or could not be made): why; `oversized`: a message larger
    /// than the client takes came in (a retained one comes again at every subscription).
    Lost { why: String, oversized: bool },
}

/// Retained commands and oversized ones are said at most this often.
static IGNORED: crate::daemon::noise::Budget = crate::daemon::noise::Budget::new();

/// Polls rumqttc's event loop, never cancelled: connections, NCMDs, and after a lost
/// connection the next session's will and a retry.
async fn network(
    mut eventloop: EventLoop,
    topics: Topics,
    to_session: mpsc::Sender<Net>,
    stopping: Arc<AtomicBool>,
) {
    let mut bd_seq = 0u64;
    loop {
        let told = match eventloop.poll().await {
            Ok(Event::Incoming(Packet::ConnAck(_))) => Net::Connected { bd_seq },
            // A retained command would act again at every reconnection (and on every node
            // that ever subscribes): a command is for the moment it is sent, never kept.
            Ok(Event::Incoming(Packet::Publish(p))) if p.topic == topics.ncmd && p.retain => {
                IGNORED.log(format_args!(
                    "mqtt: a retained NCMD ({} bytes) ignored: commands are taken only as they \
                     are sent; clear it on the broker (an empty retained message on {})",
                    p.payload.len(),
                    topics.ncmd
                ));
                continue;
            }
            Ok(Event::Incoming(Packet::Publish(p))) if p.topic == topics.ncmd => {
                Net::Command(p.payload.to_vec())
            }
            Ok(Event::Incoming(Packet::Publish(p))) if p.topic == topics.nbirth => {
                Net::Birth(p.payload.to_vec())
            }
            Ok(Event::Outgoing(rumqttc::Outgoing::Disconnect)) => return,
            Ok(_) => continue,
            Err(e) => {
                if stopping.load(Ordering::Relaxed) {
                    return;
                }
                // What waited for the old session is not for the new one: it begins with
                // its birth.
                eventloop.clean();
                eventloop.pending.clear();
                bd_seq = (bd_seq + 1) % 256;
                eventloop.mqtt_options.set_last_will(will(&topics, bd_seq));
                let oversized = matches!(
                    e,
                    rumqttc::ConnectionError::MqttState(rumqttc::StateError::Deserialization(
                        rumqttc::mqttbytes::Error::PayloadSizeLimitExceeded(_)
                    ))
                );
                let lost = Net::Lost {
                    why: e.to_string(),
                    oversized,
                };
                let _ = to_session.send(lost).await;
                tokio::time::sleep(RETRY).await;
                continue;
            }
        };
        if to_session.send(told).await.is_err() {
            return;
        }
    }
}

/// The session task's state.
struct Session {
    node: EdgeNode,
    topics: Topics,
    client: AsyncClient,
    to_core: CoreLink,
    counters: Arc<MqttCounters>,
    commands: bool,
    /// The answer to the last NCMD.
    answer: String,
    connected: bool,
    /// The next sample is a whole NBIRTH (a rebirth was asked for, or a message was dropped).
    birth_due: bool,
    /// The last NBIRTH this node sent: an NBIRTH on its topic that differs is another node's.
    last_birth: Vec<u8>,
    /// A message too large for the client knocked a session off: commands are no longer
    /// subscribed to (the message, retained, would come again at every subscription).
    commands_off: bool,
    /// When the current session began.
    since: Option<std::time::Instant>,
    /// `true` once the node is to stop.
    stop: watch::Receiver<bool>,
}

/// Asks the control loop and waits for its reply; `None` at once when the node is told to
/// stop (the daemon's control loop no longer answers then).
async fn ask(to_core: &CoreLink, request: Request, stop: &watch::Receiver<bool>) -> Option<Reply> {
    let (tx, rx) = oneshot::channel();
    if !to_core.ask(request, tx) {
        return None;
    }
    let mut stop = stop.clone();
    tokio::select! {
        reply = tokio::time::timeout(CORE_TIMEOUT, rx) => reply.ok()?.ok(),
        _ = stop.wait_for(|s| *s) => None,
    }
}

impl Session {
    async fn run(
        mut self,
        mut from_network: mpsc::Receiver<Net>,
        interval: Duration,
        stopping: Arc<AtomicBool>,
    ) {
        let mut stop = self.stop.clone();
        let mut tick = tokio::time::interval(interval);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let mut lost_before = false;
        loop {
            tokio::select! {
                _ = stop.wait_for(|s| *s) => break,
                told = from_network.recv() => match told {
                    Some(Net::Connected { bd_seq }) => {
                        lost_before = false;
                        self.begin(bd_seq).await;
                    }
                    Some(Net::Command(payload)) => self.command(&payload).await,
                    Some(Net::Birth(payload)) => self.birth_seen(&payload),
                    Some(Net::Lost { why, oversized }) => {
                        if oversized && !self.commands_off {
                            self.commands_off = true;
                            tracing::error!(
                                "mqtt: a message larger than {} KiB came on {} ({why}): NCMD is \
                                 no longer subscribed to, so the node stays on the broker; clear \
                                 a retained one (an empty retained message on the topic) and \
                                 restart edmd to take commands again",
                                MAX_PACKET_BYTES / 1024,
                                self.topics.ncmd
                            );
                        }
                        // A session the broker ends soon after it began, again and again, is
                        // what two clients with one id do to each other.
                        let short = self
                            .since
                            .take()
                            .is_some_and(|t| t.elapsed() < Duration::from_secs(10));
                        // Said once per outage, not at every retry.
                        if self.connected || !lost_before {
                            tracing::warn!(
                                "mqtt: no session with the broker ({why}); retrying every {} s{}",
                                RETRY.as_secs(),
                                if short {
                                    " (it ended within seconds of starting: does another \
                                     client use this node's id?)"
                                } else {
                                    ""
                                }
                            );
                        }
                        lost_before = true;
                        self.connected = false;
                        self.counters.connected.store(false, Ordering::Relaxed);
                    }
                    None => return,
                },
                _ = tick.tick() => {
                    if self.connected {
                        let birth = self.birth_due;
                        self.sample(birth).await;
                    }
                }
            }
        }
        stopping.store(true, Ordering::Relaxed);
        if self.connected {
            // A clean stop: the will is not published on DISCONNECT, so NDEATH goes first.
            let death = sparkplug::death(self.node.bd_seq(), now_ms());
            let _ = self
                .client
                .try_publish(&self.topics.ndeath, QoS::AtLeastOnce, false, death);
            let _ = self.client.try_disconnect();
            tracing::info!("mqtt: NDEATH published; disconnected");
        }
    }

    /// A session began (CONNACK) with its will carrying `bd_seq`: subscribe, and be born.
    async fn begin(&mut self, bd_seq: u64) {
        tracing::info!("mqtt: connected as {} (bdSeq {bd_seq})", self.topics.nbirth);
        self.connected = true;
        self.since = Some(std::time::Instant::now());
        self.counters.connected.store(true, Ordering::Relaxed);
        self.node.set_session(bd_seq);
        self.subscribe();
        // Due until it is published: a session that begins before the control loop has
        // posted its first status (a daemon starting on a loaded machine) is born at the
        // first sample that has one.
        self.birth_due = true;
        self.sample(true).await;
    }

    /// NCMD (unless a message too large turned commands off), and the node's own NBIRTH
    /// topic, where another node's birth tells a duplicate `node_id`.
    fn subscribe(&self) {
        let mut topics = vec![&self.topics.nbirth];
        if !self.commands_off {
            topics.push(&self.topics.ncmd);
        }
        for topic in topics {
            if let Err(e) = self.client.try_subscribe(topic, QoS::AtLeastOnce) {
                tracing::warn!("mqtt: cannot subscribe to {topic}: {e}");
            }
        }
    }

    /// An NBIRTH on the node's own topic that is not the one it sent last: another node
    /// publishes as this one.
    fn birth_seen(&mut self, payload: &[u8]) {
        if payload != self.last_birth.as_slice() {
            static DUPLICATE: crate::daemon::noise::Budget = crate::daemon::noise::Budget::new();
            DUPLICATE.log(format_args!(
                "mqtt: another edge node publishes as {}: two machines with one \
                 daemon.mqtt.node_id (and client id) take each other's sessions; give each its \
                 own",
                self.topics.nbirth
            ));
        }
    }

    /// Queues one message; a full queue drops it, counts it and makes the next sample a
    /// birth.
    fn publish(&mut self, topic: &str, payload: Vec<u8>) -> bool {
        match self
            .client
            .try_publish(topic, QoS::AtMostOnce, false, payload)
        {
            Ok(()) => {
                self.counters.published.fetch_add(1, Ordering::Relaxed);
                true
            }
            Err(_) => {
                let dropped = self.counters.dropped.fetch_add(1, Ordering::Relaxed) + 1;
                if dropped.is_power_of_two() {
                    tracing::warn!(
                        "mqtt: the broker does not keep up: {dropped} message(s) dropped so far"
                    );
                }
                self.birth_due = true;
                false
            }
        }
    }

    /// A status sample (the one the control loop last posted): NBIRTH when `birth`, else
    /// NDATA with what moved. Nothing before the loop's first status (a birth stays due).
    async fn sample(&mut self, birth: bool) {
        let posted = self.to_core.status();
        let Some(status) = posted.status() else {
            return;
        };
        self.publish_sample(status, birth);
    }

    fn publish_sample(&mut self, status: &Status, birth: bool) {
        let shares = self.node.shares(status);
        let sample = Sample {
            status,
            shares,
            dropped: self.counters.dropped.load(Ordering::Relaxed),
            answer: &self.answer,
            commands: self.commands,
        };
        let now = now_ms();
        if birth {
            let payload = self.node.birth(&sample, now);
            self.birth_due = false;
            self.last_birth = payload.clone();
            let topic = self.topics.nbirth.clone();
            if self.publish(&topic, payload) {
                self.counters.births.fetch_add(1, Ordering::Relaxed);
            }
        } else if let Some(payload) = self.node.data(&sample, now) {
            let topic = self.topics.ndata.clone();
            self.publish(&topic, payload);
        }
    }

    /// An NCMD: each node control asked for, then a sample so the host sees the answer.
    async fn command(&mut self, payload: &[u8]) {
        let asked = match self.node.commands(payload) {
            Ok(asked) => asked,
            Err(why) => {
                tracing::warn!("mqtt: NCMD refused: {why}");
                self.answer = bounded(&format!("refused: {why}"), MAX_TEXT_BYTES);
                self.sample(false).await;
                return;
            }
        };
        let mut rebirth = false;
        for command in asked {
            let request = match command {
                Command::Rebirth => {
                    tracing::info!("mqtt: rebirth asked for");
                    rebirth = true;
                    continue;
                }
                Command::Hold => Request::Hold {},
                Command::Abort => Request::Abort {},
            };
            self.answer = if self.commands {
                match ask(&self.to_core, request, &self.stop).await {
                    Some(r) if r.ok => {
                        format!("{}: {}", command.name(), r.message.unwrap_or_default())
                    }
                    Some(r) => format!(
                        "{} refused: {}",
                        command.name(),
                        r.error.unwrap_or_default()
                    ),
                    None => format!("{} refused: the daemon is stopping", command.name()),
                }
            } else {
                self.counters.refused.fetch_add(1, Ordering::Relaxed);
                format!("{} refused: daemon.mqtt.commands is false", command.name())
            };
            self.answer = bounded(&self.answer, MAX_TEXT_BYTES);
            tracing::info!("mqtt: NCMD {}", self.answer);
        }
        self.sample(rebirth).await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Deadbands;
    use crate::daemon::board::StatusBoard;
    use crate::daemon::protocol::DaemonState;

    /// A session whose network task never runs: its queue of `cap` fills and stays full.
    fn stuck_session(cap: usize) -> Session {
        let topics = Topics::new("g", "n");
        let (client, eventloop) = AsyncClient::new(MqttOptions::new("test", "127.0.0.1", 1), cap);
        // The event loop is kept but never polled: nothing takes from the queue.
        std::mem::forget(eventloop);
        Session {
            node: EdgeNode::new(
                &["X".into()],
                Deadbands {
                    mm: 0.0,
                    mm_per_min: 0.0,
                    fraction: 0.0,
                    s: 0.0,
                },
            ),
            topics,
            client,
            to_core: CoreLink::new(|_, _| false, || true, Default::default()),
            counters: Arc::new(MqttCounters::default()),
            commands: false,
            answer: String::new(),
            connected: true,
            birth_due: false,
            last_birth: Vec::new(),
            commands_off: false,
            since: None,
            stop: watch::channel(false).1,
        }
    }

    /// A session that connects before the control loop has posted a status is born at the
    /// first tick after the status comes, and sends no NDATA before its birth. (On a loaded
    /// machine the broker's CONNACK can come first; the birth was lost, and the node stayed
    /// unborn for good.)
    #[test]
    fn a_session_begun_before_the_first_status_is_born_when_it_comes() {
        let mut session = stuck_session(16);
        let board = Arc::new(StatusBoard::default());
        session.to_core = CoreLink::new(|_, _| false, || true, board.clone());
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        // CONNACK, then two ticks, as `run` takes them.
        runtime.block_on(session.begin(0));
        assert_eq!(session.counters.births.load(Ordering::Relaxed), 0);
        assert_eq!(session.counters.published.load(Ordering::Relaxed), 0);
        assert!(session.birth_due, "no status yet: the birth is still due");
        board.post(Status::bare(DaemonState::Idle));
        let due = session.birth_due;
        runtime.block_on(session.sample(due));
        assert_eq!(session.counters.births.load(Ordering::Relaxed), 1);
        assert_eq!(session.counters.published.load(Ordering::Relaxed), 1);
        assert!(!session.birth_due);
        let due = session.birth_due;
        runtime.block_on(session.sample(due));
        assert_eq!(
            session.counters.births.load(Ordering::Relaxed),
            1,
            "born once"
        );
    }

    #[test]
    fn a_full_queue_drops_counts_and_makes_the_next_sample_a_birth() {
        let mut session = stuck_session(4);
        let mut status = Status::bare(DaemonState::Running);
        session.publish_sample(&status, true);
        for n in 1..=10u64 {
            status.counters.holds = n;
            session.publish_sample(&status, false);
        }
        let c = &session.counters;
        assert_eq!(c.published.load(Ordering::Relaxed), 4, "the queue holds 4");
        assert_eq!(c.dropped.load(Ordering::Relaxed), 7);
        assert_eq!(c.births.load(Ordering::Relaxed), 1);
        assert!(
            session.birth_due,
            "the host's picture is made whole by a birth"
        );
    }
}
