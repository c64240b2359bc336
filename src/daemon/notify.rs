//! systemd's notify protocol (`sd_notify(3)`), without libsystemd: one datagram per message
//! to the socket named by `NOTIFY_SOCKET` (a path, or `@name` for the abstract namespace).
//!
//! - `READY=1` once the port is claimed, the fine thread runs and the socket listens;
//! - `STATUS=…` on every state change and with the periodic status line;
//! - `WATCHDOG=1` every half `WATCHDOG_USEC`, only while the fine thread makes progress;
//! - `STOPPING=1` when a controlled stop begins, `RELOADING=1`/`READY=1` around SIGHUP.
//!
//! Outside systemd (`NOTIFY_SOCKET` unset) every call is a no-op.

use std::os::unix::net::{SocketAddr, UnixDatagram};
use std::time::Duration;

/// The notify socket, if systemd gave one.
#[derive(Debug)]
pub struct Notifier {
    target: Option<(UnixDatagram, SocketAddr)>,
}

impl Notifier {
    /// From `NOTIFY_SOCKET`; a socket that cannot be used is logged and ignored.
    pub fn from_env() -> Notifier {
        let Some(name) = std::env::var_os("NOTIFY_SOCKET") else {
            return Notifier { target: None };
        };
        let name = name.to_string_lossy().into_owned();
        let addr = match name.strip_prefix('@') {
            Some(abstract_name) => {
                use std::os::linux::net::SocketAddrExt;
                SocketAddr::from_abstract_name(abstract_name.as_bytes())
            }
            None => SocketAddr::from_pathname(&name),
        };
        // Non-blocking: a notify socket nobody reads must never stall the control loop.
        let socket = UnixDatagram::unbound().and_then(|s| s.set_nonblocking(true).map(|()| s));
        match addr.and_then(|a| socket.map(|s| (s, a))) {
            Ok(target) => Notifier {
                target: Some(target),
            },
            Err(e) => {
                tracing::warn!("NOTIFY_SOCKET={name}: unusable ({e}); not notifying systemd");
                Notifier { target: None }
            }
        }
    }

    pub fn active(&self) -> bool {
        self.target.is_some()
    }

    /// Sends `message` (newline-separated `KEY=VALUE` lines) without waiting. Failures (a
    /// full queue included) are logged at debug level: systemd going away must not take the
    /// machine down.
    pub fn send(&self, message: &str) {
        if let Some((socket, addr)) = &self.target
            && let Err(e) = socket.send_to_addr(message.as_bytes(), addr)
        {
            tracing::debug!("sd_notify {message:?}: {e}");
        }
    }

    /// `STATUS=` with newlines flattened (one status per datagram line).
    pub fn status(&self, text: &str) {
        self.send(&format!("STATUS={}", text.replace('\n', "; ")));
    }
}

/// The watchdog period systemd asks for (`WATCHDOG_USEC`, for this process if
/// `WATCHDOG_PID` is set).
pub fn watchdog_period() -> Option<Duration> {
    if let Some(pid) = std::env::var_os("WATCHDOG_PID")
        && pid.to_string_lossy() != std::process::id().to_string()
    {
        return None;
    }
    let usec: u64 = std::env::var("WATCHDOG_USEC").ok()?.parse().ok()?;
    (usec > 0).then(|| Duration::from_micros(usec))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn datagrams_reach_a_path_socket() {
        let dir = std::env::temp_dir().join(format!("edmd-notify-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("notify");
        let listener = UnixDatagram::bind(&path).unwrap();
        let notifier = Notifier {
            target: Some((
                UnixDatagram::unbound().unwrap(),
                SocketAddr::from_pathname(&path).unwrap(),
            )),
        };
        notifier.send("READY=1");
        notifier.status("running\nline 3");
        let mut buf = [0u8; 256];
        let n = listener.recv(&mut buf).unwrap();
        assert_eq!(&buf[..n], b"READY=1");
        let n = listener.recv(&mut buf).unwrap();
        assert_eq!(&buf[..n], b"STATUS=running; line 3");
    }
}
