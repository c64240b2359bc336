//! `daemon.opcua`: an OPC UA server for the shop floor's MES and SCADA.
//!
//! ```text
//!  MES / SCADA ──opc.tcp──► async-opcua server (its own thread, 2 tokio workers)
//!     browse, read, subscribe   ◄── the address space (space.rs), refreshed every POLL
//!                                    from CoreMsg::Request(Status): the snapshot /metrics reads
//!     events                    ◄── holds, shorts, alarms between two refreshes (events.rs)
//!     call Hold / Abort         ──► CoreMsg::Request(Hold | Abort): the control loop decides
//!                                    (a signed-in user on the encrypted endpoint only, auth.rs)
//! ```
//!
//! **Why the control loop again.** Like the socket and the web side, OPC UA reads the status
//! a client of the socket reads and asks for a hold as a client does, so no view of the
//! machine can disagree with another, and nothing here touches the real-time thread.
//!
//! **Two endpoints at one URL.** `None` (no signing, no encryption) takes anonymous clients
//! only: they browse, read and subscribe. `Basic256Sha256` with `SignAndEncrypt` also takes a
//! name and password of `daemon.opcua_users_file`, and only such a session may call Hold or
//! Abort. The server's key pair is made in `daemon.opcua_pki_dir` on first start
//! (self-signed); a client's certificate it does not know is put in `rejected/`, and the
//! encrypted endpoint takes that client once an administrator moves it to `trusted/`, the
//! usual OPC UA workflow.
//!
//! **What it is not.** Prometheus stays the place for metrics; this is the machine as the
//! shop floor's systems see it. The nodes follow OPC 40501's layout and names without being
//! instances of its types (see [`space`]).

mod auth;
mod desk;
mod events;
mod jobs;
mod space;
pub mod users;

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use opcua::nodes::{BaseEventType, Event};
use opcua::server::diagnostics::NamespaceMetadata;
use opcua::server::node_manager::memory::{SimpleNodeManager, simple_node_manager};
use opcua::server::{ANONYMOUS_USER_TOKEN_ID, ServerBuilder, ServerEndpoint, SubscriptionCache};
use opcua::types::{
    BuildInfo, ByteString, DataValue, DateTime, NodeId, ObjectId, StatusCode, UAString, Variant,
};

use super::link::CoreLink;
use super::protocol::{Reply, Request, Status};
use crate::config::OpcUaEndpoint;

/// How often the address space is refreshed from the status: the finest sampling a client
/// sees.
pub const POLL: Duration = Duration::from_millis(100);
/// Longest wait for the control loop's reply.
pub(super) const CORE_TIMEOUT: Duration = Duration::from_secs(10);

/// What the server is started with.
pub struct OpcUaSettings {
    pub endpoint: OpcUaEndpoint,
    pub users_file: PathBuf,
    pub pki_dir: PathBuf,
    /// Axis names, in order: one Axes/<name> object each.
    pub axes: Vec<String>,
    /// Where the programs a job order names are.
    pub program_dir: PathBuf,
}

/// Why the OPC UA server did not start.
#[derive(Debug, thiserror::Error)]
pub enum OpcUaError {
    #[error(transparent)]
    Users(#[from] users::UsersError),
    #[error("daemon.opcua = {url}: cannot listen there: {source}")]
    Listen { url: String, source: std::io::Error },
    #[error("{path}: cannot make the OPC UA certificate store (daemon.opcua_pki_dir): {source}")]
    Pki {
        path: String,
        source: std::io::Error,
    },
    #[error("daemon.opcua: the server cannot be set up: {0}")]
    Setup(String),
}

/// The running server: its URL, and the users in force (SIGHUP rereads them).
pub struct OpcUaServer {
    pub url: String,
    gatekeeper: Arc<auth::Gatekeeper>,
    /// Where job orders' programs are (SIGHUP may move it).
    program_dir: Arc<parking_lot::RwLock<PathBuf>>,
}

impl OpcUaServer {
    /// Puts `users` (read by the reload worker, [`users::load_or_create`]) in force; their
    /// number.
    pub fn set_users(&self, users: users::Users) -> usize {
        let n = users.len();
        self.gatekeeper.set_users(users);
        n
    }

    /// Job orders name programs of `dir` from now on (a reload's `daemon.program_dir`).
    pub fn set_program_dir(&self, dir: PathBuf) {
        *self.program_dir.write() = dir;
    }
}

/// The certificate store's folders, private to the daemon's user (the private key is in it).
fn make_pki_dir(dir: &std::path::Path) -> Result<(), OpcUaError> {
    use std::os::unix::fs::PermissionsExt;
    let fail = |source| OpcUaError::Pki {
        path: dir.display().to_string(),
        source,
    };
    std::fs::create_dir_all(dir).map_err(fail)?;
    std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o700)).map_err(fail)
}

/// The server with its two endpoints, its certificate store and edmd's namespace.
fn build_server(
    settings: &OpcUaSettings,
    url: &str,
    host: &str,
    gatekeeper: Arc<auth::Gatekeeper>,
) -> Result<(opcua::server::Server, opcua::server::ServerHandle), OpcUaError> {
    let version = env!("CARGO_PKG_VERSION");
    ServerBuilder::new()
        .application_name("edmd")
        .application_uri(format!("urn:edmd:{host}"))
        .product_uri("urn:edmd")
        .build_info(BuildInfo {
            product_uri: "urn:edmd".into(),
            manufacturer_name: "edmd".into(),
            product_name: "edmd EDM controller".into(),
            software_version: version.into(),
            build_number: version.into(),
            build_date: DateTime::now(),
        })
        .host(settings.endpoint.host.clone())
        .port(settings.endpoint.port)
        .pki_dir(&settings.pki_dir)
        .create_sample_keypair(true)
        .trust_client_certs(false)
        .add_endpoint(
            "none",
            ServerEndpoint::new_none("/", &[ANONYMOUS_USER_TOKEN_ID.to_string()]),
        )
        .add_endpoint(
            "basic256sha256_sign_encrypt",
            ServerEndpoint::new_basic256sha256_sign_encrypt(
                "/",
                &[ANONYMOUS_USER_TOKEN_ID.to_string()],
            ),
        )
        .discovery_urls(vec![url.to_string()])
        .with_authenticator(gatekeeper)
        .with_node_manager(simple_node_manager(
            NamespaceMetadata {
                namespace_uri: space::NAMESPACE.to_owned(),
                ..Default::default()
            },
            "edmd",
        ))
        .build()
        .map_err(OpcUaError::Setup)
}

/// Binds the endpoint (so a taken port is an error at startup) and serves on a thread of
/// its own.
pub fn spawn(settings: OpcUaSettings, to_core: CoreLink) -> Result<OpcUaServer, OpcUaError> {
    let url = settings.endpoint.url();
    let listen_error = |source| OpcUaError::Listen {
        url: url.clone(),
        source,
    };
    let users = users::load_or_create(&settings.users_file)?;
    make_pki_dir(&settings.pki_dir)?;
    let listener =
        std::net::TcpListener::bind((settings.endpoint.host.as_str(), settings.endpoint.port))
            .map_err(listen_error)?;
    listener.set_nonblocking(true).map_err(listen_error)?;
    let host = crate::sys::host_name();
    let version = env!("CARGO_PKG_VERSION");
    let gatekeeper = Arc::new(auth::Gatekeeper::new(users));
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .thread_name("edmd-opcua")
        .enable_all()
        .build()
        .map_err(listen_error)?;
    // The server starts tasks of its own as it is built: in this runtime.
    let entered = runtime.enter();
    let (server, handle) = build_server(&settings, &url, &host, gatekeeper.clone())?;
    let ns = handle
        .get_namespace_index(space::NAMESPACE)
        .ok_or_else(|| OpcUaError::Setup("edmd's namespace was not registered".into()))?;
    let manager = handle
        .node_managers()
        .get_of_type::<SimpleNodeManager>()
        .ok_or_else(|| OpcUaError::Setup("no node manager".into()))?;
    let identity = space::Identity {
        manufacturer: "edmd".into(),
        model: "edmd EDM controller".into(),
        product_instance_uri: format!("urn:edmd:{host}"),
        software_revision: version.into(),
    };
    let space = Arc::new(space::Space::build(
        &mut manager.address_space().write(),
        ns,
        &settings.axes,
        &identity,
    ));
    let job_nodes = Arc::new(jobs::JobNodes::build(
        &mut manager.address_space().write(),
        ns,
    ));
    let mut guarded = vec![space.hold.clone(), space.abort.clone()];
    guarded.extend(job_nodes.guarded());
    gatekeeper.guard(guarded);
    let desk = desk::Desk {
        orders: Arc::default(),
        to_core: to_core.clone(),
        program_dir: Arc::new(parking_lot::RwLock::new(settings.program_dir.clone())),
    };
    let program_dir = desk.program_dir.clone();
    add_methods(&manager, &space, &job_nodes, &desk);
    drop(entered);
    let subscriptions = handle.subscriptions().clone();
    // Event ids are unique for the server's life: its start time and a count.
    let epoch = DateTime::now().ticks();
    std::thread::Builder::new()
        .name("edmd-opcua".to_string())
        .spawn(move || {
            runtime.block_on(async move {
                let views = Views {
                    space,
                    jobs: job_nodes,
                    desk,
                };
                tokio::spawn(refresh(views, manager, subscriptions, to_core, epoch));
                let listener = match tokio::net::TcpListener::from_std(listener) {
                    Ok(listener) => listener,
                    Err(e) => return tracing::error!("opcua: {e}"),
                };
                if let Err(e) = server.run_with(listener).await {
                    tracing::error!("opcua: the server stopped: {e}");
                }
            })
        })
        .map_err(listen_error)?;
    Ok(OpcUaServer {
        url,
        gatekeeper,
        program_dir,
    })
}

/// The methods' callbacks: Hold and Abort of the machine, and the job methods.
fn add_methods(
    manager: &SimpleNodeManager,
    space: &space::Space,
    nodes: &jobs::JobNodes,
    desk: &desk::Desk,
) {
    for (method, request, what) in [
        (space.hold.clone(), Request::Hold {}, "Hold"),
        (space.abort.clone(), Request::Abort {}, "Abort"),
    ] {
        let to_core = desk.to_core.clone();
        manager
            .inner()
            .add_method_callback(method, move |_| call(&to_core, request.clone(), what));
    }
    type Handler = fn(&desk::Desk, &[Variant]) -> Result<Vec<Variant>, StatusCode>;
    let handlers: [(&NodeId, Handler); 8] = [
        (&nodes.store, |d, a| d.store(a, false)),
        (&nodes.store_and_start, |d, a| d.store(a, true)),
        (&nodes.start, |d, a| d.start(a)),
        (&nodes.pause, |d, a| d.machine(a, "Pause", Request::Hold {})),
        (&nodes.resume, |d, a| {
            d.machine(a, "Resume", Request::Resume { force: false })
        }),
        (&nodes.abort, |d, a| {
            d.machine(a, "Abort", Request::Abort {})
        }),
        (&nodes.clear, |d, a| d.clear(a)),
        (&nodes.result, |d, a| d.result(a)),
    ];
    for (method, handler) in handlers {
        let desk = desk.clone();
        manager
            .inner()
            .add_method_callback(method.clone(), move |args| handler(&desk, args));
    }
}

/// Asks the control loop and waits for its reply, from a method call (which the server
/// makes synchronously on one of its workers: the loop answers in microseconds).
pub(super) fn ask_blocking(to_core: &CoreLink, request: Request) -> Result<Reply, StatusCode> {
    let (tx, rx) = tokio::sync::oneshot::channel();
    if !to_core.ask(request, tx) {
        return Err(StatusCode::BadShutdown);
    }
    tokio::task::block_in_place(|| {
        tokio::runtime::Handle::current().block_on(tokio::time::timeout(CORE_TIMEOUT, rx))
    })
    .map_err(|_| StatusCode::BadTimeout)?
    .map_err(|_| StatusCode::BadShutdown)
}

/// Hold or Abort of the machine: the loop's answer as the method's.
fn call(to_core: &CoreLink, request: Request, what: &str) -> Result<Vec<Variant>, StatusCode> {
    let reply = ask_blocking(to_core, request)?;
    if reply.ok {
        let message = reply.message.unwrap_or_default();
        tracing::info!("opcua: {what}: {message}");
        Ok(vec![Variant::from(message)])
    } else {
        tracing::info!(
            "opcua: {what} refused: {}",
            reply.error.as_deref().unwrap_or("")
        );
        Err(StatusCode::BadInvalidState)
    }
}

/// The status the control loop last posted, as `/metrics` reads it.
async fn status(to_core: &CoreLink) -> Option<Status> {
    to_core.status().status().cloned()
}

/// What the refresh fills: the machine's nodes and the job list.
struct Views {
    space: Arc<space::Space>,
    jobs: Arc<jobs::JobNodes>,
    desk: desk::Desk,
}

/// The job orders follow the status; an order that ended gets its line of the job history.
async fn follow_orders(views: &Views, to_core: &CoreLink, now: &Status) -> [(NodeId, Variant); 3] {
    let ended = views.desk.orders.lock().observe(now);
    if let Some(id) = ended {
        let (tx, rx) = tokio::sync::oneshot::channel();
        if to_core.ask(
            Request::Jobs {
                count: Some(20),
                skip: None,
            },
            tx,
        ) && let Ok(Ok(reply)) = tokio::time::timeout(CORE_TIMEOUT, rx).await
        {
            let records = reply.jobs.unwrap_or_default();
            views.desk.orders.lock().attach_result(&id, &records);
        }
    }
    views.jobs.values(&views.desk.orders.lock())
}

/// Every [`POLL`]: the variables from a fresh status, and the events since the last one.
async fn refresh(
    views: Views,
    manager: Arc<SimpleNodeManager>,
    subscriptions: Arc<SubscriptionCache>,
    to_core: CoreLink,
    epoch: i64,
) {
    let mut interval = tokio::time::interval(POLL);
    interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut before: Option<Status> = None;
    let mut next_event: u64 = 0;
    loop {
        interval.tick().await;
        let Some(now) = status(&to_core).await else {
            if to_core.inbox_empty() && before.is_some() {
                tracing::debug!("opcua: no status this time");
            }
            continue;
        };
        let space = &views.space;
        let lists = follow_orders(&views, &to_core, &now).await;
        let mut values: Vec<(&NodeId, Variant)> = space.values(&now).collect();
        values.extend(lists.iter().map(|(id, v)| (id, v.clone())));
        if let Err(e) = manager.set_values(
            &subscriptions,
            values
                .iter()
                .map(|(id, value)| (*id, None, DataValue::new_now(value.clone()))),
        ) {
            tracing::warn!("opcua: cannot set the values: {e}");
        }
        if let Some(before) = &before {
            for happened in events::between(before, &now) {
                next_event += 1;
                raise(
                    space,
                    &subscriptions,
                    &happened,
                    format!("{epoch}-{next_event}"),
                );
            }
        }
        before = Some(now);
    }
}

/// Raises one event on the machine, its Notification object and the Server object.
fn raise(
    space: &space::Space,
    subscriptions: &SubscriptionCache,
    happened: &events::Happened,
    id: String,
) {
    let kind = match happened.kind {
        events::EventKind::Hold => &space.events.hold,
        events::EventKind::Short => &space.events.short,
        events::EventKind::Alarm => &space.events.alarm,
    };
    let event = BaseEventType::new(
        kind.clone(),
        ByteString::from(id.into_bytes()),
        happened.message.as_str(),
        DateTime::now(),
    )
    .set_source_node(space.machine.clone())
    .set_source_name(UAString::from("edmd"))
    .set_severity(happened.kind.severity());
    let server: NodeId = ObjectId::Server.into();
    let emitters = [&space.machine, &space.notification, &server];
    subscriptions.notify_events(emitters.into_iter().map(|e| (&event as &dyn Event, e)));
}
