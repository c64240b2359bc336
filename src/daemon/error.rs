//! Why the daemon could not start: the socket, the HTTP and OPC UA listeners, a thread, the
//! machine state file.

use std::path::PathBuf;

use super::{http, mqtt, opcua};
use crate::runtime::JobError;

/// Why the daemon could not start.
#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    #[error("{path}: another edmd answers on this socket; stop it first (systemctl stop edmd)")]
    SocketInUse { path: PathBuf },
    #[error("{path}: exists and is not a socket; refusing to replace it (daemon.socket)")]
    NotASocket { path: PathBuf },
    #[error("{path}: cannot set up the control socket: {source}")]
    Socket {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("daemon.socket_group = {group:?}: no such group")]
    NoGroup { group: String },
    #[error(transparent)]
    Job(Box<JobError>),
    #[error("cannot start a daemon thread: {0}")]
    Thread(std::io::Error),
    #[error(
        "daemon.http = {addr}: cannot listen there: {source}{}",
        unit_hint(source)
    )]
    Http {
        addr: std::net::SocketAddr,
        source: std::io::Error,
    },
    #[error(transparent)]
    Token(#[from] http::token::TokenError),
    #[error(transparent)]
    OpcUa(#[from] opcua::OpcUaError),
    #[error(transparent)]
    Mqtt(#[from] mqtt::MqttError),
    #[error("{0}")]
    MachineState(String),
    #[error("technology.dir: {0}")]
    Technology(#[from] crate::technology::TechError),
}

/// What to add to a listening error that a service manager's sandbox causes.
fn unit_hint(e: &std::io::Error) -> &'static str {
    match e.raw_os_error() {
        Some(libc::EAFNOSUPPORT) => {
            " (under systemd, the unit's RestrictAddressFamilies= must allow AF_INET and \
             AF_INET6 for daemon.http; the shipped unit does: see docs/operator-guide.md, \"Running as a service\")"
        }
        Some(libc::EACCES) => {
            " (a port below 1024 needs CAP_NET_BIND_SERVICE: use a port such as 8080)"
        }
        _ => "",
    }
}
