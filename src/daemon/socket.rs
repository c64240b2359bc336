//! The control socket: a Unix-domain stream socket speaking JSON lines ([`super::protocol`]).
//!
//! The clients are served by one thread (`edmd-listen`) running a single-threaded tokio
//! runtime: each connection is a task, so an idle client costs a descriptor and a few
//! hundred bytes, not a thread, and up to `daemon.max_clients` of them (256 by default, never
//! more than the descriptor limit allows) can stay connected at once. A task reads a line,
//! hands the request to the daemon's control loop and writes the reply. A request counts
//! only when its newline arrives: a client that vanishes mid-line has asked for nothing. A
//! client that asks nothing for [`CLIENT_IDLE`] is dropped; blank lines are not requests and
//! do not keep it.
//!
//! **The emergency path cannot be locked out.** Idle clients hold no thread, so however many
//! monitors and forgotten sessions stay connected, a new client's `hold` is read and sent
//! to the control loop at once. If the clients do reach `max_clients`, the one that has asked
//! nothing for the longest (never one whose request is with the control loop) is closed to
//! make room for the newcomer: the operator's client is always the newest, and the runtime
//! reads its request before it has accepted more than a few hundred others, so a client
//! flooding the socket with connections that reconnect the moment they are closed does not
//! starve it either (tested with a hundred of them). `edmd ctl` asks again when it was closed
//! before its request was read (it never reached the control loop, so that is safe).

use std::collections::HashMap;
use std::io::{BufRead, BufReader, Write};
use std::os::unix::fs::{FileTypeExt, PermissionsExt};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use parking_lot::Mutex;
use tokio::io::{AsyncBufReadExt, AsyncReadExt, AsyncWriteExt};
use tokio::sync::Notify;

use super::error::DaemonError;
use super::link::CoreLink;
use super::protocol::{MAX_REQUEST_BYTES, Reply, Request, Status};
use crate::config::DaemonConfig;

/// A client that sends no request for this long is disconnected (blank lines do not count).
pub const CLIENT_IDLE: Duration = Duration::from_secs(60);
/// Longest wait for the control loop's answer.
const REPLY_TIMEOUT: Duration = Duration::from_secs(30);
/// Longest a reply may take to be written to a client that does not read.
const WRITE_TIMEOUT: Duration = Duration::from_secs(5);

/// Binds the socket at `config.socket` with the configured mode and group. A stale socket
/// (nobody answers) is replaced; a live one means another daemon runs.
pub fn bind(config: &DaemonConfig) -> Result<UnixListener, DaemonError> {
    let path = &config.socket;
    let socket_error = |source| DaemonError::Socket {
        path: path.clone(),
        source,
    };
    match std::fs::symlink_metadata(path) {
        Ok(meta) if meta.file_type().is_socket() => {
            if UnixStream::connect(path).is_ok() {
                return Err(DaemonError::SocketInUse { path: path.clone() });
            }
            std::fs::remove_file(path).map_err(socket_error)?;
        }
        Ok(_) => return Err(DaemonError::NotASocket { path: path.clone() }),
        Err(_) => {}
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(socket_error)?;
    }
    let listener = UnixListener::bind(path).map_err(socket_error)?;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(config.socket_mode))
        .map_err(socket_error)?;
    if let Some(group) = &config.socket_group {
        let gid = crate::sys::group_id(group)
            .map_err(socket_error)?
            .ok_or_else(|| DaemonError::NoGroup {
                group: group.clone(),
            })?;
        std::os::unix::fs::chown(path, None, Some(gid)).map_err(socket_error)?;
    }
    Ok(listener)
}

/// Removes the socket file on the way out (only if it is still ours: a socket).
pub fn remove(path: &Path) {
    if std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_socket()) {
        let _ = std::fs::remove_file(path);
    }
}

/// One connected client, as the listener sees it.
struct Client {
    /// When it last asked something (or connected).
    last_request: Instant,
    /// Its request is with the control loop: never evicted.
    busy: bool,
    close: Arc<Notify>,
}

/// The clients connected.
#[derive(Default)]
struct Clients {
    next: u64,
    open: HashMap<u64, Client>,
}

impl Clients {
    /// Closes the idle client that asked nothing for the longest; `false` if every client
    /// is busy.
    fn evict_quietest(&mut self) -> bool {
        let quietest = self
            .open
            .iter()
            .filter(|(_, c)| !c.busy)
            .min_by_key(|(_, c)| c.last_request)
            .map(|(&id, _)| id);
        match quietest.and_then(|id| self.open.remove(&id)) {
            Some(client) => {
                client.close.notify_one();
                true
            }
            None => false,
        }
    }
}

/// A client's place in [`Clients`]; leaving frees it.
struct Seat {
    id: u64,
    clients: Arc<Mutex<Clients>>,
}

impl Seat {
    /// Its request is with the control loop (`true`) or answered (`false`).
    fn busy(&self, busy: bool) {
        if let Some(client) = self.clients.lock().open.get_mut(&self.id) {
            client.busy = busy;
            client.last_request = Instant::now();
        }
    }
}

impl Drop for Seat {
    fn drop(&mut self) {
        self.clients.lock().open.remove(&self.id);
    }
}

/// Accepts and serves clients for ever on a thread of its own (`edmd-listen`).
pub fn spawn_listener(
    listener: UnixListener,
    core: CoreLink,
    max_clients: Arc<AtomicUsize>,
) -> std::io::Result<()> {
    listener.set_nonblocking(true)?;
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    std::thread::Builder::new()
        .name("edmd-listen".to_string())
        .spawn(move || {
            runtime.block_on(async move {
                match tokio::net::UnixListener::from_std(listener) {
                    Ok(listener) => accept(listener, core, max_clients).await,
                    Err(e) => tracing::error!("control socket: {e}"),
                }
            })
        })?;
    Ok(())
}

async fn accept(listener: tokio::net::UnixListener, core: CoreLink, max_clients: Arc<AtomicUsize>) {
    let clients = Arc::new(Mutex::new(Clients::default()));
    loop {
        let stream = match listener.accept().await {
            Ok((stream, _)) => stream,
            Err(e) => {
                // Out of descriptors: make room rather than spin.
                tracing::warn!("control socket: accept failed: {e}");
                clients.lock().evict_quietest();
                tokio::time::sleep(Duration::from_millis(20)).await;
                continue;
            }
        };
        let close = Arc::new(Notify::new());
        let seat = {
            let mut all = clients.lock();
            let limit = max_clients.load(Ordering::Relaxed);
            // Every client busy: the newcomer is served all the same (their requests are
            // answered in microseconds), a little over the limit.
            while all.open.len() >= limit && all.evict_quietest() {}
            let id = all.next;
            all.next += 1;
            all.open.insert(
                id,
                Client {
                    last_request: Instant::now(),
                    busy: false,
                    close: close.clone(),
                },
            );
            Seat {
                id,
                clients: clients.clone(),
            }
        };
        tokio::spawn(serve_client(stream, core.clone(), seat, close));
    }
}

/// Reads one request line of at most [`MAX_REQUEST_BYTES`]. `Ok(None)`: the client is gone (or sent
/// a partial line and went).
pub async fn read_request_line<R: tokio::io::AsyncBufRead + Unpin>(
    reader: &mut R,
) -> std::io::Result<Option<Result<String, LineRefusal>>> {
    let mut line = Vec::new();
    reader
        .take(MAX_REQUEST_BYTES as u64 + 1)
        .read_until(b'\n', &mut line)
        .await?;
    Ok(request_line(line))
}

/// What the bytes read for one line (at most [`MAX_REQUEST_BYTES`] + 1, up to and with its
/// newline) are: `None` a partial line (the client went), `Err` a line too long or not
/// UTF-8, `Ok` the request's text.
pub fn request_line(mut line: Vec<u8>) -> Option<Result<String, LineRefusal>> {
    if line.last() != Some(&b'\n') {
        if line.len() > MAX_REQUEST_BYTES {
            return Some(Err(LineRefusal::TooLong));
        }
        return None;
    }
    line.pop();
    Some(String::from_utf8(line).map_err(|_| LineRefusal::NotUtf8))
}

/// A request line the daemon cannot read as text.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum LineRefusal {
    #[error("request longer than {MAX_REQUEST_BYTES} bytes; closing")]
    TooLong,
    #[error("request:1:1: not UTF-8")]
    NotUtf8,
}

async fn serve_client(
    stream: tokio::net::UnixStream,
    core: CoreLink,
    seat: Seat,
    close: Arc<Notify>,
) {
    let (read_half, mut writer) = stream.into_split();
    let mut reader = tokio::io::BufReader::new(read_half);
    let mut last_request = Instant::now();
    loop {
        // The idle clock runs from the last request, not the last byte: blank lines and
        // dribbled partial lines do not keep a client.
        let left = CLIENT_IDLE.saturating_sub(last_request.elapsed());
        let line = tokio::select! {
            line = read_request_line(&mut reader) => line,
            () = tokio::time::sleep(left) => return,
            () = close.notified() => return,
        };
        let line = match line {
            Ok(Some(line)) => line,
            Ok(None) | Err(_) => return,
        };
        let (reply, close_after) = match line {
            Err(e) => (Reply::error(e.to_string(), None), true),
            Ok(line) if line.trim().is_empty() => continue,
            Ok(line) => match Request::parse(&line) {
                Err(e) => (Reply::error(e.to_string(), None), false),
                Ok(request) => {
                    last_request = Instant::now();
                    seat.busy(true);
                    let (tx, rx) = tokio::sync::oneshot::channel();
                    if !core.ask(request, tx) {
                        return;
                    }
                    let answer = match tokio::time::timeout(REPLY_TIMEOUT, rx).await {
                        Ok(Ok(reply)) => (reply, false),
                        _ => (Reply::error("the daemon did not answer", None), true),
                    };
                    seat.busy(false);
                    answer
                }
            },
        };
        let written =
            tokio::time::timeout(WRITE_TIMEOUT, writer.write_all(reply.to_line().as_bytes())).await;
        if !matches!(written, Ok(Ok(()))) || close_after {
            return;
        }
    }
}

/// How long `edmd ctl` keeps trying while the daemon says every slot is taken, or closes the
/// connection before reading the request.
const BUSY_RETRY: Duration = Duration::from_secs(2);

/// The client side (`edmd ctl`): sends one request, returns the reply. A daemon whose slots
/// are all taken (the reserved one too, for a moment) is asked again for up to
/// [`BUSY_RETRY`].
pub fn request(socket: &Path, request: &Request) -> Result<Reply, ClientError> {
    let started = Instant::now();
    loop {
        // A connection closed with no answer was closed before its request was read (the
        // daemon made room for a newer client; it never closes one whose request is with the
        // control loop): the request never arrived, so asking again is safe.
        let reply = match request_once(socket, request) {
            Err(e) if e.closed_unread() && started.elapsed() < BUSY_RETRY => {
                std::thread::sleep(Duration::from_millis(10));
                continue;
            }
            other => other?,
        };
        let busy = !reply.ok
            && reply.status.is_none()
            && reply
                .error
                .as_deref()
                .is_some_and(|e| e.starts_with("too many clients"));
        if !busy || started.elapsed() >= BUSY_RETRY {
            return Ok(reply);
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn request_once(socket: &Path, request: &Request) -> Result<Reply, ClientError> {
    let connect_error = |source| ClientError::Connect {
        path: socket.to_path_buf(),
        source,
    };
    let mut stream = UnixStream::connect(socket).map_err(connect_error)?;
    stream
        .set_read_timeout(Some(REPLY_TIMEOUT + Duration::from_secs(5)))
        .map_err(connect_error)?;
    let mut line = serde_json::to_string(request).expect("requests serialise");
    line.push('\n');
    // A daemon that turned the connection away has written why before closing: a failed
    // write (a broken pipe) must not hide that reply, so read whatever came back first.
    let written = stream.write_all(line.as_bytes());
    let mut reader = BufReader::new(stream);
    let mut answer = String::new();
    let read = reader.read_line(&mut answer);
    if answer.is_empty() {
        let source = match (written, read) {
            (Err(e), _) | (Ok(()), Err(e)) => e,
            (Ok(()), Ok(_)) => {
                return Err(ClientError::Closed {
                    path: socket.to_path_buf(),
                });
            }
        };
        return Err(ClientError::Io {
            path: socket.to_path_buf(),
            source,
        });
    }
    serde_json::from_str(&answer).map_err(|e| ClientError::Reply {
        path: socket.to_path_buf(),
        message: e.to_string(),
    })
}

/// How often `edmd ctl run` asks for the verdict of its check.
const VERDICT_POLL: Duration = Duration::from_millis(200);

/// The client side of a `run` or `resume` that waits: polls the status until check `id` is
/// decided, showing its progress on standard error when `show` is set. The reply is the
/// verdict: `ok` with the job's start message, or the refusal.
pub fn wait_for_verdict(socket: &Path, id: u64, show: bool) -> Result<Reply, ClientError> {
    let mut shown = None;
    loop {
        let status = status_of(socket)?;
        let check = status.check.clone().filter(|c| c.id == id);
        let Some(check) = check else {
            return Err(ClientError::Reply {
                path: socket.to_path_buf(),
                message: format!("check {id} is no longer reported (another run replaced it)"),
            });
        };
        if check.decided() {
            return Ok(match (check.message, check.error) {
                (Some(message), None) => Reply::ok(message, status),
                (_, error) => Reply::error(
                    error.unwrap_or_else(|| "the job was refused".to_string()),
                    Some(status),
                ),
            });
        }
        let percent = (check.bytes_done * 100)
            .checked_div(check.bytes_total)
            .unwrap_or(0);
        let now = (check.phase.clone(), percent / 10);
        if show && shown.as_ref() != Some(&now) {
            eprintln!("{} {}: {percent} %", check.phase, check.program);
            shown = Some(now);
        }
        std::thread::sleep(VERDICT_POLL);
    }
}

/// Waits for the running job to end (`edmd ctl run --wait-end`): the reply is ok when it
/// ended done, an error with its outcome otherwise. A held or paused job is waited for: the
/// operator resumes it. `program` is the job's, to tell its end from an earlier job's.
pub fn wait_for_end(socket: &Path, program: &str) -> Result<Reply, ClientError> {
    loop {
        let status = status_of(socket)?;
        if status.job.is_none() {
            let Some(last) = status
                .last_job
                .clone()
                .filter(|j| j.program.ends_with(program))
            else {
                return Err(ClientError::Reply {
                    path: socket.to_path_buf(),
                    message: format!("{program}: no job of it ended (another replaced it?)"),
                });
            };
            let outcome = last.outcome.name();
            let said = format!(
                "{}: {outcome} after {:.1} s of machine time",
                last.program, last.virtual_time_s
            );
            return Ok(if last.outcome == crate::runtime::Outcome::Done {
                Reply::ok(said, status)
            } else {
                let why = last.error.map(|e| format!(": {e}")).unwrap_or_default();
                Reply::error(format!("{said}{why}"), Some(status))
            });
        }
        std::thread::sleep(VERDICT_POLL);
    }
}

/// The daemon's status, asked for once.
fn status_of(socket: &Path) -> Result<Status, ClientError> {
    request(socket, &Request::Status {})?
        .status
        .ok_or_else(|| ClientError::Reply {
            path: socket.to_path_buf(),
            message: "a status reply without a status".to_string(),
        })
}

/// Why `edmd ctl` got no answer.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    #[error(
        "{path}: cannot connect to the daemon ({source}); is `edmd serve` running, and may \
         this user use its socket (daemon.socket_group)?"
    )]
    Connect {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: the daemon closed the connection without answering")]
    Closed { path: PathBuf },
    #[error("{path}: the daemon's reply is not understood: {message}")]
    Reply { path: PathBuf, message: String },
}

impl ClientError {
    /// The daemon closed the connection without a reply (cleanly or with a reset): it did
    /// so before the request was read.
    fn closed_unread(&self) -> bool {
        match self {
            ClientError::Closed { .. } => true,
            ClientError::Io { source, .. } => matches!(
                source.kind(),
                std::io::ErrorKind::ConnectionReset | std::io::ErrorKind::BrokenPipe
            ),
            _ => false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_are_bounded_and_partial_lines_are_nothing() {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .build()
            .unwrap();
        runtime.block_on(async {
            let mut r = tokio::io::BufReader::new(&b"{\"cmd\":\"status\"}\n{\"cmd\":\"ho"[..]);
            assert_eq!(
                read_request_line(&mut r).await.unwrap(),
                Some(Ok("{\"cmd\":\"status\"}".into()))
            );
            assert_eq!(
                read_request_line(&mut r).await.unwrap(),
                None,
                "a partial line is no request"
            );
            let long = vec![b'x'; MAX_REQUEST_BYTES + 10];
            let mut r = tokio::io::BufReader::new(&long[..]);
            assert!(matches!(
                read_request_line(&mut r).await.unwrap(),
                Some(Err(_))
            ));
            let mut r = tokio::io::BufReader::new(&b"\xff\xfe\n"[..]);
            assert!(matches!(
                read_request_line(&mut r).await.unwrap(),
                Some(Err(_))
            ));
        });
    }
}
