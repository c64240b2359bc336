//! The control socket: a Unix-domain stream socket speaking JSON lines ([`super::protocol`]).
//!
//! One thread accepts; each client gets a thread of its own, at most `daemon.max_clients` at
//! once (the next is answered with an error and closed). A client thread reads a line, hands
//! the request to the daemon's control loop and writes the reply. A request counts only when
//! its newline arrives: a client that vanishes mid-line has asked for nothing. Idle clients
//! are dropped after [`CLIENT_IDLE`].

use std::io::{BufRead, BufReader, Read, Write};
use std::os::unix::fs::{FileTypeExt, PermissionsExt};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use crossbeam::channel::{self, Sender};

use super::protocol::{MAX_REQUEST_BYTES, Reply, Request};
use super::{CoreMsg, DaemonError};
use crate::config::DaemonConfig;

/// A client that sends nothing for this long is disconnected.
pub const CLIENT_IDLE: Duration = Duration::from_secs(60);
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
    std::thread::Builder::new()
        .name("edmd-listen".to_string())
        .spawn(move || {
            for stream in listener.incoming() {
                let Ok(mut stream) = stream else { continue };
                let busy = active.load(Ordering::Relaxed);
                tracing::debug!("control client connected ({busy} already served)");
                if busy >= max_clients.load(Ordering::Relaxed) {
                    let _ = stream.set_write_timeout(Some(Duration::from_secs(1)));
                    let limit = max_clients.load(Ordering::Relaxed);
                    let reply = Reply::error(
                        format!("too many clients (daemon.max_clients = {limit}); try again"),
                        None,
                    );
                    let _ = stream.write_all(reply.to_line().as_bytes());
                    continue;
                }
                active.fetch_add(1, Ordering::Relaxed);
                let active = active.clone();
                let core = core.clone();
                let spawned = std::thread::Builder::new()
                    .name("edmd-client".to_string())
                    .spawn(move || {
                        serve_client(stream, &core);
                        active.fetch_sub(1, Ordering::Relaxed);
                    });
                if spawned.is_err() {
                    tracing::warn!("cannot start a thread for a control client; dropped");
                }
            }
        })?;
    Ok(())
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

fn serve_client(stream: UnixStream, core: &Sender<CoreMsg>) {
    let _ = stream.set_read_timeout(Some(CLIENT_IDLE));
    let _ = stream.set_write_timeout(Some(Duration::from_secs(5)));
    let Ok(read_half) = stream.try_clone() else {
        return;
    };
    let mut reader = BufReader::new(read_half);
    let mut writer = stream;
    loop {
        let line = match read_request_line(&mut reader) {
            Ok(Some(line)) => line,
            Ok(None) | Err(_) => return,
        };
        let (reply, close) = match line {
            Err(e) => (Reply::error(e, None), true),
            Ok(line) if line.trim().is_empty() => continue,
            Ok(line) => match Request::parse(&line) {
                Err(e) => (Reply::error(e, None), false),
                Ok(request) => {
                    let (tx, rx) = channel::bounded(1);
                    if core.send(CoreMsg::Request(request, tx)).is_err() {
                        return;
                    }
                    match rx.recv_timeout(REPLY_TIMEOUT) {
                        Ok(reply) => (reply, false),
                        Err(_) => (Reply::error("the daemon did not answer", None), true),
                    }
                }
            },
        };
        if writer.write_all(reply.to_line().as_bytes()).is_err() || close {
            return;
        }
    }
}

/// The client side (`edmd ctl`): sends one request, returns the reply.
pub fn request(socket: &Path, request: &Request) -> Result<Reply, ClientError> {
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
    stream
        .write_all(line.as_bytes())
        .map_err(|source| ClientError::Io {
            path: socket.to_path_buf(),
            source,
        })?;
    let mut reader = BufReader::new(stream);
    let mut answer = String::new();
    reader
        .read_line(&mut answer)
        .map_err(|source| ClientError::Io {
            path: socket.to_path_buf(),
            source,
        })?;
    if answer.is_empty() {
        return Err(ClientError::Closed {
            path: socket.to_path_buf(),
        });
    }
    serde_json::from_str(&answer).map_err(|e| ClientError::Reply {
        path: socket.to_path_buf(),
        message: e.to_string(),
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
