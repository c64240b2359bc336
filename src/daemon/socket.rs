//! The control socket: a Unix-domain stream socket speaking JSON lines ([`super::protocol`]).
//!
//! One thread accepts; each client gets a thread of its own, at most `daemon.max_clients` at
//! once. A client thread reads a line, hands the request to the daemon's control loop and
//! writes the reply. A request counts only when its newline arrives: a client that vanishes
//! mid-line has asked for nothing. A client that asks nothing for [`CLIENT_IDLE`] is dropped;
//! blank lines are not requests and do not keep it.
//!
//! **The emergency path is reserved.** Past `max_clients`, one more connection is served on a
//! reserved slot that takes `status`, `hold` and `abort` only, one request, within
//! [`EMERGENCY_IDLE`]: however many idle clients hold the ordinary slots, an operator can
//! always stop the machine. Only past that is a client told "too many clients".

use std::io::{BufRead, BufReader, Read, Write};
use std::os::unix::fs::{FileTypeExt, PermissionsExt};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use crossbeam::channel::{self, Sender};

use super::protocol::{MAX_REQUEST_BYTES, Reply, Request};
use super::{CoreMsg, DaemonError};
use crate::config::DaemonConfig;

/// A client that sends no request for this long is disconnected (blank lines do not count).
pub const CLIENT_IDLE: Duration = Duration::from_secs(60);
/// The reserved slot's client must send its request within this.
pub const EMERGENCY_IDLE: Duration = Duration::from_secs(5);
/// Longest wait for the control loop's answer.
const REPLY_TIMEOUT: Duration = Duration::from_secs(30);

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

/// Accepts clients for ever on a thread of its own.
pub fn spawn_listener(
    listener: UnixListener,
    core: Sender<CoreMsg>,
    max_clients: Arc<AtomicUsize>,
) -> std::io::Result<()> {
    let active = Arc::new(AtomicUsize::new(0));
    let emergency = Arc::new(AtomicBool::new(false));
    std::thread::Builder::new()
        .name("edmd-listen".to_string())
        .spawn(move || {
            for stream in listener.incoming() {
                let Ok(mut stream) = stream else { continue };
                let busy = active.load(Ordering::Relaxed);
                tracing::debug!("control client connected ({busy} already served)");
                let slot = if busy < max_clients.load(Ordering::Relaxed) {
                    active.fetch_add(1, Ordering::Relaxed);
                    Slot::Ordinary(active.clone())
                } else if !emergency.swap(true, Ordering::AcqRel) {
                    Slot::Emergency(emergency.clone())
                } else {
                    let _ = stream.set_write_timeout(Some(Duration::from_secs(1)));
                    let limit = max_clients.load(Ordering::Relaxed);
                    let reply = Reply::error(
                        format!("too many clients (daemon.max_clients = {limit}); try again"),
                        None,
                    );
                    let _ = stream.write_all(reply.to_line().as_bytes());
                    continue;
                };
                let core = core.clone();
                let spawned = std::thread::Builder::new()
                    .name("edmd-client".to_string())
                    .spawn(move || {
                        serve_client(stream, &core, slot);
                    });
                if spawned.is_err() {
                    tracing::warn!("cannot start a thread for a control client; dropped");
                }
            }
        })?;
    Ok(())
}

/// The slot a client holds; dropping it frees the slot.
enum Slot {
    Ordinary(Arc<AtomicUsize>),
    Emergency(Arc<AtomicBool>),
}

impl Slot {
    fn is_emergency(&self) -> bool {
        matches!(self, Slot::Emergency(_))
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        match self {
            Slot::Ordinary(active) => {
                active.fetch_sub(1, Ordering::Relaxed);
            }
            Slot::Emergency(taken) => taken.store(false, Ordering::Release),
        }
    }
}

/// Reads one request line of at most [`MAX_REQUEST_BYTES`]. `Ok(None)`: the client is gone (or sent
/// a partial line and went).
pub fn read_request_line(
    reader: &mut impl BufRead,
) -> std::io::Result<Option<Result<String, String>>> {
    let mut line = Vec::new();
    reader
        .take(MAX_REQUEST_BYTES as u64 + 1)
        .read_until(b'\n', &mut line)?;
    if line.last() != Some(&b'\n') {
        if line.len() > MAX_REQUEST_BYTES {
            return Ok(Some(Err(format!(
                "request longer than {MAX_REQUEST_BYTES} bytes; closing"
            ))));
        }
        return Ok(None);
    }
    line.pop();
    Ok(Some(
        String::from_utf8(line).map_err(|_| "request:1:1: not UTF-8".to_string()),
    ))
}

fn serve_client(stream: UnixStream, core: &Sender<CoreMsg>, slot: Slot) {
    let emergency = slot.is_emergency();
    let mut slot = Some(slot);
    let idle = if emergency {
        EMERGENCY_IDLE
    } else {
        CLIENT_IDLE
    };
    let _ = stream.set_write_timeout(Some(Duration::from_secs(5)));
    let Ok(read_half) = stream.try_clone() else {
        return;
    };
    let mut reader = BufReader::new(read_half);
    let mut writer = stream;
    let mut last_request = Instant::now();
    loop {
        // The idle clock runs from the last request, not the last byte: blank lines and
        // dribbled partial lines do not keep a slot.
        let left = idle.saturating_sub(last_request.elapsed());
        if left.is_zero() || writer.set_read_timeout(Some(left)).is_err() {
            return;
        }
        let line = match read_request_line(&mut reader) {
            Ok(Some(line)) => line,
            Ok(None) | Err(_) => return,
        };
        let (reply, close) = match line {
            Err(e) => (Reply::error(e, None), true),
            Ok(line) if line.trim().is_empty() => continue,
            Ok(line) => match Request::parse(&line) {
                Err(e) => (Reply::error(e, None), emergency),
                Ok(request)
                    if emergency
                        && !matches!(
                            request,
                            Request::Status {} | Request::Hold {} | Request::Abort {}
                        ) =>
                {
                    let reply = Reply::error(
                        "every client slot is taken (daemon.max_clients); the reserved one \
                         takes status, hold and abort only",
                        None,
                    );
                    (reply, true)
                }
                Ok(request) => {
                    last_request = Instant::now();
                    let (tx, rx) = channel::bounded(1);
                    if core.send(CoreMsg::Request(request, tx)).is_err() {
                        return;
                    }
                    match rx.recv_timeout(REPLY_TIMEOUT) {
                        Ok(reply) => (reply, emergency),
                        Err(_) => (Reply::error("the daemon did not answer", None), true),
                    }
                }
            },
        };
        if close {
            // Free the slot before the last reply goes out: an operator's next command may
            // connect the moment it has read this one.
            drop(slot.take());
        }
        if writer.write_all(reply.to_line().as_bytes()).is_err() || close {
            return;
        }
    }
}

/// How long `edmd ctl` keeps trying while the daemon says every slot is taken.
const BUSY_RETRY: Duration = Duration::from_secs(2);

/// The client side (`edmd ctl`): sends one request, returns the reply. A daemon whose slots
/// are all taken (the reserved one too, for a moment) is asked again for up to
/// [`BUSY_RETRY`].
pub fn request(socket: &Path, request: &Request) -> Result<Reply, ClientError> {
    let started = Instant::now();
    loop {
        let reply = request_once(socket, request)?;
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
        let reply = request(socket, &Request::Status {})?;
        let Some(status) = reply.status else {
            return Err(ClientError::Reply {
                path: socket.to_path_buf(),
                message: "a status reply without a status".to_string(),
            });
        };
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_are_bounded_and_partial_lines_are_nothing() {
        let mut r = BufReader::new(&b"{\"cmd\":\"status\"}\n{\"cmd\":\"ho"[..]);
        assert_eq!(
            read_request_line(&mut r).unwrap(),
            Some(Ok("{\"cmd\":\"status\"}".into()))
        );
        assert_eq!(
            read_request_line(&mut r).unwrap(),
            None,
            "a partial line is no request"
        );
        let long = vec![b'x'; MAX_REQUEST_BYTES + 10];
        let mut r = BufReader::new(&long[..]);
        assert!(matches!(read_request_line(&mut r).unwrap(), Some(Err(_))));
        let mut r = BufReader::new(&b"\xff\xfe\n"[..]);
        assert!(matches!(read_request_line(&mut r).unwrap(), Some(Err(_))));
    }
}
