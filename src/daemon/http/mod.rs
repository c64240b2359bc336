//! `daemon.http`: the machine's own web page, a JSON API and Prometheus metrics.
//!
//! ```text
//!  browser / curl / Prometheus ──► connections (server.rs: cap, timeouts, eviction)
//!     ──► guard (Host allow-list, security headers) ──► axum router on 1 tokio thread
//!        GET  /              the page (one self-contained document: no outside URLs)
//!        GET  /api/status    = `edmd ctl status --json`        ─┐ the status the loop posts
//!        GET  /api/events    Server-Sent Events: the same reply   │ (board), never a message
//!                            on every change, at least every 1 s  │ to it (status.rs)
//!        GET  /metrics       Prometheus text format, `edmd_` ────┘
//!        POST /api/run|hold|resume|abort|rethread (bearer token) ── CoreMsg::Request, exactly
//!                            as a socket client sends (one control loop decides)
//!        GET  /api/programs  the files under daemon.program_dir
//!        GET  /api/jobs      the job history, a page read from its file (jobs.rs)
//!        GET  /api/path      a program's path (X, Y), for the backplot (bounded work)
//! ```
//!
//! **Commands through the control loop, reading from its board.** Every command becomes the
//! [`Request`] a socket client sends and waits for the control loop's [`Reply`], so the
//! socket and HTTP can never disagree about what the daemon accepts; a handler awaits its
//! reply on a oneshot channel, never holding a thread. What is only read (the status, its
//! events, the metrics) is the status the loop posted on its board
//! ([`crate::daemon::board`]), so fifty pages polling cost the loop nothing, and the history
//! is read from its file: the loop stays free for the next hold. Nothing here touches the
//! real-time thread, whose only link to any of it is the job's `Published` atomics.
//!
//! **Work that is not the machine's waits its turn.** Drawing a program's path
//! ([`crate::report::programmed::programmed_path`]) and listing programs run on tokio's blocking threads, at most
//! [`MAX_PREVIEWS`] and [`MAX_LISTINGS`] at once (more get 503 at once), each drawing within
//! [`PREVIEW_TIME`] and [`crate::report::programmed::MAX_POINTS`]; the blocking pool is larger than both together.
//!
//! **Safety.** Reading is open (status, programs, metrics) to clients that name the machine
//! in `Host` ([`guard`]); every `POST` needs `Authorization: Bearer <token>` with the token
//! of `daemon.http_token_file` (at least 128 bits; reloaded on SIGHUP), compared in constant
//! time, or gets 401. Program names go through the same [`super::confine`] as on the socket:
//! a missing program and one outside the program directory get the same 404. Bodies above
//! [`MAX_BODY_BYTES`] are refused with 413; request heads are bounded by size and time
//! ([`server`]). Server-Sent Event streams are limited to [`MAX_EVENT_STREAMS`] at once.

// The handlers' helpers return the error response itself (`Result<T, Response>`): large, but
// built once per refused request, far from any hot path.
#![allow(clippy::result_large_err)]

pub mod executed;
mod guard;
mod jobs;
pub mod links;
mod metrics;
mod path;
mod programs;
mod server;
mod status;
pub mod token;

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Duration;

use axum::Router;
use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{DefaultBodyLimit, Query, Request as HttpRequest, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use parking_lot::RwLock;
use serde::Deserialize;
use tokio::sync::Semaphore;

use super::link::CoreLink;
use super::protocol::{Reply, Request};
use super::refusal::NameRefusal;
use crate::report::programmed;

pub use server::connection_cap;

/// Largest request body accepted (bytes): a `run` names a program, nothing more.
pub const MAX_BODY_BYTES: usize = 16 * 1024;
/// Server-Sent Event streams served at once.
pub const MAX_EVENT_STREAMS: usize = 16;
/// Path drawings and program listings computed at once.
pub const MAX_PREVIEWS: usize = 2;
pub const MAX_LISTINGS: usize = 2;
/// The longest a path drawing may take; it then returns what it has, marked partial.
pub const PREVIEW_TIME: Duration = Duration::from_secs(2);
/// How long a request waits for the control loop's reply.
const CORE_TIMEOUT: Duration = Duration::from_secs(10);
/// How often an event stream looks at the status, and the longest it stays silent.
const EVENT_POLL: Duration = Duration::from_millis(100);
const EVENT_HEARTBEAT: Duration = Duration::from_secs(1);

/// The operator's page: one document served whole (its style and script inline, so the
/// Content Security Policy can name their hashes), written in parts by what each holds.
const PAGE: &str = concat!(
    include_str!("page/head.html"),
    include_str!("page/style.css"),
    include_str!("page/body.html"),
    include_str!("page/status.js"),
    include_str!("page/drawing.js"),
    include_str!("page/controls.js"),
    include_str!("page/tail.html"),
);

/// What HTTP takes from the configuration; the part SIGHUP may change is [`Reloadable`].
#[derive(Debug, Clone)]
pub struct HttpSettings {
    pub addr: SocketAddr,
    /// Connections at once (already capped below the descriptor limit).
    pub max_connections: usize,
    pub reloadable: Reloadable,
}

/// What a reload (SIGHUP) changes under a running server.
#[derive(Debug, Clone, PartialEq)]
pub struct Reloadable {
    pub token: String,
    pub program_dir: PathBuf,
    /// Host names besides IP literals and `localhost` (`daemon.http_allowed_hosts`).
    pub allowed_hosts: Vec<String>,
}

/// What the handlers share.
struct App {
    to_core: CoreLink,
    live: RwLock<Reloadable>,
    axes: Vec<crate::vocab::Axis>,
    /// How the daemon's jobs read programs (conditions, `D` registers), for the backplot.
    options: crate::gcode::ProgramOptions,
    streams: AtomicUsize,
    previews: Semaphore,
    listings: Semaphore,
    /// The Content Security Policy of every response.
    csp: HeaderValue,
    /// The running or last job's recording.
    executed: executed::ExecutedSlot,
    /// One-time login codes (`edmd ctl web-link`).
    links: links::LoginLinks,
    /// The job history, read here page by page.
    history: crate::daemon::history::HistoryFile,
}

/// The running HTTP server (it lives as long as the daemon's process).
pub struct HttpServer {
    pub addr: SocketAddr,
    app: Arc<App>,
}

impl HttpServer {
    /// A one-time login link (`edmd ctl web-link`): see [`links`].
    pub fn login_link(&self) -> std::io::Result<String> {
        links::link(self.addr, &self.app.links)
    }

    /// Puts a reloaded token, program directory and host list in force for the next request.
    pub fn reload(&self, settings: Reloadable) {
        *self.app.live.write() = settings;
    }
}

/// Binds `addr` (so a taken port is an error at startup) and serves on a thread of its own.
pub fn spawn(
    settings: HttpSettings,
    axes: Vec<crate::vocab::Axis>,
    options: crate::gcode::ProgramOptions,
    to_core: CoreLink,
    executed: executed::ExecutedSlot,
    history: crate::daemon::history::HistoryFile,
) -> std::io::Result<HttpServer> {
    let listener = std::net::TcpListener::bind(settings.addr)?;
    listener.set_nonblocking(true)?;
    let bound = listener.local_addr()?;
    let csp = HeaderValue::from_str(&guard::content_security_policy(PAGE))
        .map_err(std::io::Error::other)?;
    let app = Arc::new(App {
        to_core,
        live: RwLock::new(settings.reloadable),
        axes,
        options,
        streams: AtomicUsize::new(0),
        previews: Semaphore::new(MAX_PREVIEWS),
        listings: Semaphore::new(MAX_LISTINGS),
        csp,
        executed,
        links: links::LoginLinks::default(),
        history,
    });
    let runtime = tokio::runtime::Builder::new_multi_thread()
        // One: reading the posted status is an Arc clone, so one thread answers tens of
        // thousands a second, and a second one only took CPU time the tick needed.
        .worker_threads(1)
        // Room for every preview and listing at once, and then some.
        .max_blocking_threads(MAX_PREVIEWS + MAX_LISTINGS + 4)
        // The blocking threads parse programs.
        .thread_stack_size(crate::gcode::PARSER_STACK_BYTES)
        .thread_name("edmd-http")
        .enable_all()
        .build()?;
    let router = router(app.clone());
    let max_connections = settings.max_connections;
    std::thread::Builder::new()
        .name("edmd-http".to_string())
        .spawn(move || {
            runtime.block_on(async move {
                match tokio::net::TcpListener::from_std(listener) {
                    Ok(listener) => server::serve(listener, router, max_connections).await,
                    Err(e) => tracing::error!("http: {e}"),
                }
            })
        })?;
    Ok(HttpServer { addr: bound, app })
}

fn router(app: Arc<App>) -> Router {
    Router::new()
        .route("/", get(page))
        .route("/api/status", get(status::status))
        .route("/api/jobs", get(jobs::list))
        .route("/api/technology", get(jobs::technology))
        .route("/api/events", get(status::events))
        .route(
            "/api/programs",
            get(programs)
                .post(programs::upload)
                .layer(DefaultBodyLimit::max(programs::MAX_UPLOAD_BYTES)),
        )
        .route("/api/program", get(programs::listing))
        .route("/api/path", get(planned_path))
        .route("/api/executed", get(executed::serve))
        .route("/metrics", get(status::metrics))
        .route("/api/run", post(run))
        .route("/api/login", post(links::login))
        .route("/api/hold", post(|s, h, b| control(s, h, b, "hold")))
        .route("/api/resume", post(|s, h, b| control(s, h, b, "resume")))
        .route("/api/abort", post(|s, h, b| control(s, h, b, "abort")))
        .route("/api/home", post(|s, h, b| machine(s, h, b, "home")))
        .route("/api/find", post(|s, h, b| machine(s, h, b, "find")))
        .route("/api/jog", post(|s, h, b| machine(s, h, b, "jog")))
        .route(
            "/api/jog-continuous",
            post(|s, h, b| machine(s, h, b, "jog-continuous")),
        )
        .route(
            "/api/jog-stop",
            post(|s, h, b| machine(s, h, b, "jog-stop")),
        )
        .route("/api/reset", post(|s, h, b| machine(s, h, b, "reset")))
        .route("/api/discard", post(|s, h, b| machine(s, h, b, "discard")))
        .route(
            "/api/override",
            post(|s, h, b| machine(s, h, b, "override")),
        )
        .route(
            "/api/single-block",
            post(|s, h, b| machine(s, h, b, "single-block")),
        )
        .route("/api/mdi", post(|s, h, b| machine(s, h, b, "mdi")))
        .route(
            "/api/touch-off",
            post(|s, h, b| machine(s, h, b, "touch-off")),
        )
        .route("/api/offsets", post(|s, h, b| machine(s, h, b, "offsets")))
        .route(
            "/api/rethread",
            post(|s, h, b| control(s, h, b, "rethread")),
        )
        .fallback(|| async { error(StatusCode::NOT_FOUND, "no such page") })
        // The limit makes an oversized body a `BytesRejection`, answered below as JSON.
        .layer(DefaultBodyLimit::max(MAX_BODY_BYTES))
        .layer(axum::middleware::from_fn_with_state(app.clone(), guarded))
        .with_state(app)
}

/// Every request: its `Host` must name this machine; every response: the security headers.
async fn guarded(State(app): State<Arc<App>>, request: HttpRequest, next: Next) -> Response {
    let allowed = {
        let live = app.live.read();
        guard::host_allowed(request.headers(), &live.allowed_hosts)
    };
    let mut response = if allowed {
        next.run(request).await
    } else {
        let host = guard::host_name(request.headers()).unwrap_or_default();
        static REFUSED_HOSTS: super::noise::Budget = super::noise::Budget::new();
        REFUSED_HOSTS.log(format_args!("http: refused a request for host {host:?}"));
        error(
            StatusCode::FORBIDDEN,
            format!(
                "the host {host:?} is not a name of this machine: use its address, or add the \
                 name to daemon.http_allowed_hosts"
            ),
        )
    };
    guard::secure(response.headers_mut(), &app.csp);
    response
}

/// A JSON error in the socket's shape: `{"ok": false, "error": "…"}`.
fn error(code: StatusCode, message: impl Into<String>) -> Response {
    let body = Reply::error(message, None);
    (code, axum::Json(body)).into_response()
}

/// Asks the control loop, as a socket client does, and awaits the reply without taking a
/// thread.
async fn ask(app: &App, request: Request) -> Result<Reply, Response> {
    let (tx, rx) = tokio::sync::oneshot::channel();
    if !app.to_core.ask(request, tx) {
        return Err(error(
            StatusCode::SERVICE_UNAVAILABLE,
            "the daemon is shutting down",
        ));
    }
    match tokio::time::timeout(CORE_TIMEOUT, rx).await {
        Ok(Ok(reply)) => Ok(reply),
        _ => Err(error(
            StatusCode::SERVICE_UNAVAILABLE,
            "the daemon did not answer",
        )),
    }
}

async fn page() -> Response {
    (
        [
            (header::CONTENT_TYPE, "text/html; charset=utf-8"),
            (header::CACHE_CONTROL, "no-store"),
        ],
        PAGE,
    )
        .into_response()
}

/// The files under the program directory (four levels deep at most, 2000 at most).
async fn programs(State(app): State<Arc<App>>) -> Response {
    let Ok(_turn) = app.listings.try_acquire() else {
        return busy("program listings");
    };
    let dir = app.live.read().program_dir.clone();
    let listed = tokio::task::spawn_blocking(move || path::list_programs(&dir)).await;
    match listed {
        Ok(Ok(list)) => axum::Json(serde_json::json!({ "programs": list })).into_response(),
        Ok(Err(e)) => error(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
        Err(e) => error(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    }
}

/// 503: the work of this kind already in progress is all there may be at once.
fn busy(what: &str) -> Response {
    let mut response = error(
        StatusCode::SERVICE_UNAVAILABLE,
        format!("busy: as many {what} as may run at once are running; try again shortly"),
    );
    response
        .headers_mut()
        .insert(header::RETRY_AFTER, HeaderValue::from_static("1"));
    response
}

#[derive(Deserialize)]
struct PathQuery {
    program: Option<String>,
}

/// The programmed path of `?program=` or of the running job, thinned, for the backplot:
/// at most [`MAX_PREVIEWS`] at once, each within [`PREVIEW_TIME`].
async fn planned_path(State(app): State<Arc<App>>, Query(q): Query<PathQuery>) -> Response {
    let name = match q.program {
        Some(name) => name,
        None => match app.to_core.status().status().and_then(|s| s.job.as_ref()) {
            Some(job) => job.program.clone(),
            None => return error(StatusCode::CONFLICT, "no job is running"),
        },
    };
    let file = match program_file(&app, &name) {
        Ok(file) => file,
        Err(e) => return e,
    };
    let Ok(_turn) = app.previews.try_acquire() else {
        return busy("path drawings");
    };
    let budget = programmed::Budget {
        cancel: Arc::new(AtomicBool::new(false)),
        max_blocks: programmed::MAX_BLOCKS,
    };
    let (axes, options, cancel) = (app.axes.clone(), app.options.clone(), budget.cancel.clone());
    let plot = move || programmed::programmed_path(&file, &name, &axes, options, None, &budget);
    let work = tokio::task::spawn_blocking(plot);
    tokio::pin!(work);
    let done = tokio::select! {
        done = &mut work => done,
        () = tokio::time::sleep(PREVIEW_TIME) => {
            // Out of time: the reader gives up at its next line, with what it drew.
            cancel.store(true, Ordering::Relaxed);
            work.await
        }
    };
    match done {
        Ok(Ok(path)) => axum::Json(path).into_response(),
        Ok(Err(e)) => error(StatusCode::BAD_REQUEST, e.to_string()),
        Err(e) => error(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    }
}

/// A program named by a client, confined as on the socket: 404 whether it is missing or
/// outside the program directory (the reply names no path), 400 for a name that is no name.
fn program_file(app: &App, name: &str) -> Result<PathBuf, Response> {
    let dir = app.live.read().program_dir.clone();
    super::names::confine(&dir, name).map_err(|e| {
        let code = match e {
            NameRefusal::Empty | NameRefusal::ControlCharacter { .. } => StatusCode::BAD_REQUEST,
            NameRefusal::NoSuchProgram { .. } | NameRefusal::ProgramDir { .. } => {
                StatusCode::NOT_FOUND
            }
        };
        error(code, e.to_string())
    })
}

/// `Authorization: Bearer <token>` (the scheme in any case), compared in constant time.
fn authorised(app: &App, headers: &HeaderMap) -> Result<(), Response> {
    let given = guard::bearer(headers);
    let ok = given.is_some_and(|t| token::same(t.as_bytes(), app.live.read().token.as_bytes()));
    if ok {
        return Ok(());
    }
    let mut response = error(
        StatusCode::UNAUTHORIZED,
        "control needs `Authorization: Bearer <token>` with the token of \
         daemon.http_token_file",
    );
    response.headers_mut().insert(
        header::WWW_AUTHENTICATE,
        header::HeaderValue::from_static("Bearer"),
    );
    Err(response)
}

/// A request body as JSON of `T` (an empty body is `{}`); 413 over the limit, 400 if bad.
fn body<T: serde::de::DeserializeOwned>(
    body: Result<Bytes, BytesRejection>,
) -> Result<T, Response> {
    let bytes = body.map_err(|e| {
        if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
            error(
                StatusCode::PAYLOAD_TOO_LARGE,
                format!("the request body is over {MAX_BODY_BYTES} bytes"),
            )
        } else {
            error(StatusCode::BAD_REQUEST, e.body_text())
        }
    })?;
    let text = if bytes.iter().all(u8::is_ascii_whitespace) {
        &b"{}"[..]
    } else {
        &bytes[..]
    };
    super::protocol::from_json(text).map_err(|e| {
        error(
            StatusCode::BAD_REQUEST,
            format!(
                "request body:{}:{}: {}",
                e.line(),
                e.column(),
                super::protocol::strip_location(&e)
            ),
        )
    })
}

/// The control loop's verdict: 200 with its reply, or 409 (the daemon's state does not allow
/// it) with the socket's message.
fn verdict(reply: Reply) -> Response {
    let code = if reply.ok {
        StatusCode::OK
    } else {
        StatusCode::CONFLICT
    };
    (code, axum::Json(reply)).into_response()
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RunBody {
    program: String,
    #[serde(default)]
    dry_run: bool,
    #[serde(default)]
    from_line: Option<u64>,
    #[serde(default)]
    approach: Option<crate::path::Approach>,
    #[serde(default)]
    wire_at: Option<crate::path::WireAt>,
    #[serde(default)]
    pass: Option<u8>,
    #[serde(default)]
    passes: Option<usize>,
    #[serde(default)]
    tab_mm: Option<f64>,
    technology: Option<String>,
    #[serde(default)]
    force: bool,
}

async fn run(
    State(app): State<Arc<App>>,
    headers: HeaderMap,
    raw: Result<Bytes, BytesRejection>,
) -> Response {
    if let Err(e) = authorised(&app, &headers) {
        return e;
    }
    let RunBody {
        program,
        dry_run,
        from_line,
        approach,
        wire_at,
        pass,
        passes,
        tab_mm,
        technology,
        force,
    } = match body(raw) {
        Ok(b) => b,
        Err(e) => return e,
    };
    if let Err(e) = program_file(&app, &program) {
        return e;
    }
    let run = Request::Run {
        program,
        dry_run,
        from_line,
        approach,
        wire_at,
        pass,
        passes,
        tab_mm,
        technology,
        force,
    };
    match ask(&app, run).await {
        Ok(reply) => verdict(reply),
        Err(e) => e,
    }
}

/// The machine's commands (`home`, `find`, `jog`, `mdi`, `touch-off`, `offsets`): the body holds the
/// socket request's fields (`{"axis":"X","distance_mm":0.5}`), checked as the socket checks
/// them.
async fn machine(
    State(app): State<Arc<App>>,
    headers: HeaderMap,
    raw: Result<Bytes, BytesRejection>,
    command: &'static str,
) -> Response {
    if let Err(e) = authorised(&app, &headers) {
        return e;
    }
    let mut fields: serde_json::Map<String, serde_json::Value> = match body(raw) {
        Ok(b) => b,
        Err(e) => return e,
    };
    if fields.contains_key("cmd") {
        return error(
            StatusCode::BAD_REQUEST,
            "request body: `cmd` is not a field: the path names the command".to_string(),
        );
    }
    fields.insert("cmd".into(), command.into());
    let request = match Request::parse(&serde_json::Value::Object(fields).to_string()) {
        Ok(r) => r,
        Err(e) => {
            return error(StatusCode::BAD_REQUEST, format!("request body: {}", e.what));
        }
    };
    match ask(&app, request).await {
        Ok(reply) => verdict(reply),
        Err(e) => e,
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct ControlBody {
    #[serde(default)]
    force: Option<bool>,
    #[serde(default)]
    here: Option<bool>,
}

async fn control(
    State(app): State<Arc<App>>,
    headers: HeaderMap,
    raw: Result<Bytes, BytesRejection>,
    command: &'static str,
) -> Response {
    if let Err(e) = authorised(&app, &headers) {
        return e;
    }
    let b: ControlBody = match body(raw) {
        Ok(b) => b,
        Err(e) => return e,
    };
    let misplaced = match command {
        "resume" => b.here.map(|_| "here"),
        "rethread" => b.force.map(|_| "force"),
        _ => b.force.map(|_| "force").or(b.here.map(|_| "here")),
    };
    if let Some(field) = misplaced {
        return error(
            StatusCode::BAD_REQUEST,
            format!("request body: `{field}` is not a field of {command}"),
        );
    }
    let request = match command {
        "hold" => Request::Hold {},
        "resume" => Request::Resume {
            force: b.force.unwrap_or(false),
        },
        "abort" => Request::Abort {},
        _ => Request::Rethread {
            here: b.here.unwrap_or(false),
        },
    };
    match ask(&app, request).await {
        Ok(reply) => verdict(reply),
        Err(e) => e,
    }
}
