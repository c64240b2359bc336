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

/// When to ping the watchdog: every half period, and only if the real-time side made
/// progress since the last ping. Time is passed in, so the rule is testable.
#[derive(Debug, Clone, Copy)]
pub struct WatchdogGate {
    period: Duration,
    last_ping: Duration,
    last_progress: Option<u64>,
    stalled: bool,
}

/// What the gate says at one check.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Watchdog {
    /// Not yet half a period since the last ping.
    Wait,
    /// Send `WATCHDOG=1`.
    Ping,
    /// Due, but nothing moved since the last ping: no ping. `first` once per stall.
    Stalled { first: bool },
}

impl WatchdogGate {
    pub fn new(period: Duration, now: Duration) -> WatchdogGate {
        WatchdogGate {
            period,
            last_ping: now,
            last_progress: None,
            stalled: false,
        }
    }

    /// `progress`: a counter that grows while the real-time side works; `alive`: its thread
    /// still exists.
    pub fn check(&mut self, now: Duration, progress: u64, alive: bool) -> Watchdog {
        if now.saturating_sub(self.last_ping) < self.period / 2 {
            return Watchdog::Wait;
        }
        if alive && self.last_progress != Some(progress) {
            self.last_progress = Some(progress);
            self.last_ping = now;
            self.stalled = false;
            return Watchdog::Ping;
        }
        let first = !self.stalled;
        self.stalled = true;
        Watchdog::Stalled { first }
    }

    /// Time since the last ping.
    pub fn since_ping(&self, now: Duration) -> Duration {
        now.saturating_sub(self.last_ping)
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_watchdog_is_pinged_only_on_progress() {
        use super::{Watchdog, WatchdogGate};
        let ms = std::time::Duration::from_millis;
        let mut gate = WatchdogGate::new(ms(1000), ms(0));
        assert_eq!(gate.check(ms(100), 1, true), Watchdog::Wait);
        assert_eq!(gate.check(ms(500), 1, true), Watchdog::Ping);
        assert_eq!(gate.check(ms(700), 2, true), Watchdog::Wait);
        assert_eq!(gate.check(ms(1000), 2, true), Watchdog::Ping);
        // The loop stops making progress: no more pings, one report.
        assert_eq!(
            gate.check(ms(1500), 2, true),
            Watchdog::Stalled { first: true }
        );
        assert_eq!(
            gate.check(ms(1750), 2, true),
            Watchdog::Stalled { first: false }
        );
        assert_eq!(gate.since_ping(ms(1750)), ms(750));
        // It moves again: pings resume.
        assert_eq!(gate.check(ms(1800), 3, true), Watchdog::Ping);
        // A dead thread is never pinged for, whatever the counter says.
        assert_eq!(
            gate.check(ms(2400), 4, false),
            Watchdog::Stalled { first: true }
        );
    }

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
