//! Logging into the systemd journal through its native protocol, so entries keep their
//! priority and their fields.
//!
//! Under systemd, stderr reaches journald as plain lines stored at priority 6 (info) whatever
//! they say: `journalctl -p warning` would show no alarm, and nothing would tell a short from a
//! status line. So when systemd connected stderr to the journal (`$JOURNAL_STREAM`), or when
//! `log.format = "journal"`, each event goes to journald's datagram socket as one entry
//! (<https://systemd.io/JOURNAL_NATIVE_PROTOCOL/>): `PRIORITY` from the level (error 3, warn 4,
//! info 6, debug and trace 7), `MESSAGE`, `SYSLOG_IDENTIFIER=edmd`, `TARGET`, and every field
//! of the event whose name starts with `edmd_`, upper-cased: `EDMD_EVENT` (job_start, job_end,
//! short, turn_back, alarm, hold, checkpoint, refusal), `EDMD_LINE`, `EDMD_PROGRAM`. So
//! `journalctl -u edmd -p warning` and `journalctl EDMD_EVENT=alarm` work.
//!
//! The socket is `/run/systemd/journal/socket`, or `$EDMD_JOURNAL_SOCKET` (tests point it at a
//! socket of their own). A send waits at most 50 ms for room in journald's queue: an entry that
//! cannot be sent in that time (the journal is gone, or stalled) is written to stderr instead.

use std::fmt::Write as _;
use std::os::unix::net::UnixDatagram;
use std::path::PathBuf;

use tracing::field::{Field, Visit};
use tracing::{Event, Level, Subscriber};
use tracing_subscriber::Layer;
use tracing_subscriber::layer::Context;

/// The longest an entry waits for room in journald's queue.
const SEND_TIMEOUT: std::time::Duration = std::time::Duration::from_millis(50);

/// Where journald listens for native entries.
const JOURNAL_SOCKET: &str = "/run/systemd/journal/socket";

/// Fields with this prefix are the journal's structured fields (`EDMD_…`); the text formats
/// leave them out.
pub const FIELD_PREFIX: &str = "edmd_";

/// Sends each event to journald as one entry.
pub struct JournalLayer {
    socket: UnixDatagram,
    path: PathBuf,
}

impl JournalLayer {
    /// The journal's socket: `$EDMD_JOURNAL_SOCKET` or the standard one. `None` when nothing
    /// listens there.
    pub fn connect() -> Option<JournalLayer> {
        let path = std::env::var_os("EDMD_JOURNAL_SOCKET")
            .filter(|p| !p.is_empty())
            .map_or_else(|| PathBuf::from(JOURNAL_SOCKET), PathBuf::from);
        let socket = UnixDatagram::unbound().ok()?;
        socket.connect(&path).ok()?;
        // Wait for journald briefly, never long: the kernel queues only a few datagrams per
        // socket (`net.unix.max_dgram_qlen`, often 10), so a burst must be able to wait for
        // the journal to read, but a stalled journal must not stall the control loop or a
        // job's supervisor. An entry it cannot take in time goes to stderr instead.
        socket.set_write_timeout(Some(SEND_TIMEOUT)).ok()?;
        Some(JournalLayer { socket, path })
    }
}

/// Whether systemd connected our stderr to the journal (`$JOURNAL_STREAM` is set).
pub fn stderr_is_journal() -> bool {
    std::env::var_os("JOURNAL_STREAM").is_some_and(|v| !v.is_empty())
}

fn priority(level: &Level) -> u8 {
    match *level {
        Level::ERROR => 3,
        Level::WARN => 4,
        Level::INFO => 6,
        Level::DEBUG | Level::TRACE => 7,
    }
}

/// Appends one field in the native format: `KEY=value\n`, or the binary form when the value
/// holds a line break.
fn push_field(entry: &mut Vec<u8>, key: &str, value: &str) {
    entry.extend_from_slice(key.as_bytes());
    if value.contains('\n') {
        entry.push(b'\n');
        entry.extend_from_slice(&(value.len() as u64).to_le_bytes());
    } else {
        entry.push(b'=');
    }
    entry.extend_from_slice(value.as_bytes());
    entry.push(b'\n');
}

#[derive(Default)]
struct Fields {
    message: String,
    structured: Vec<(String, String)>,
    other: String,
}

impl Visit for Fields {
    fn record_str(&mut self, field: &Field, value: &str) {
        self.record(field, value.to_string());
    }

    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        self.record(field, format!("{value:?}"));
    }
}

impl Fields {
    fn record(&mut self, field: &Field, value: String) {
        let name = field.name();
        if name == "message" {
            self.message = value;
        } else if name.starts_with(FIELD_PREFIX) {
            self.structured.push((name.to_ascii_uppercase(), value));
        } else {
            let _ = write!(self.other, " {name}={value}");
        }
    }
}

impl<S: Subscriber> Layer<S> for JournalLayer {
    fn on_event(&self, event: &Event<'_>, _: Context<'_, S>) {
        let meta = event.metadata();
        let mut fields = Fields::default();
        event.record(&mut fields);
        let mut entry = Vec::with_capacity(256);
        push_field(&mut entry, "PRIORITY", &priority(meta.level()).to_string());
        push_field(&mut entry, "SYSLOG_IDENTIFIER", "edmd");
        push_field(&mut entry, "TARGET", meta.target());
        push_field(&mut entry, "MESSAGE", &(fields.message + &fields.other));
        for (key, value) in &fields.structured {
            push_field(&mut entry, key, value);
        }
        if self.socket.send(&entry).is_err() {
            eprintln!(
                "edmd: {} (journal {} unreachable): {}",
                meta.level(),
                self.path.display(),
                String::from_utf8_lossy(&entry)
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_are_written_in_the_native_format() {
        let mut entry = Vec::new();
        push_field(&mut entry, "MESSAGE", "short circuit");
        push_field(&mut entry, "EDMD_TEXT", "two\nlines");
        let mut want = b"MESSAGE=short circuit\nEDMD_TEXT\n".to_vec();
        want.extend_from_slice(&9u64.to_le_bytes());
        want.extend_from_slice(b"two\nlines\n");
        assert_eq!(entry, want);
        assert_eq!(priority(&Level::ERROR), 3);
        assert_eq!(priority(&Level::WARN), 4);
        assert_eq!(priority(&Level::INFO), 6);
    }
}
