//! The status board: the control loop's latest status, posted for every transport to read
//! without asking the loop.
//!
//! ```text
//!  control loop ── after every message, and every POST_EVERY while a job runs ──► post
//!  HTTP status, events, metrics · OPC UA · Sparkplug ──► current() (an Arc, no lock held)
//! ```
//!
//! **Why.** A status is what most clients ask for, and most often: a page polls it, fifty
//! pages poll it fifty times, Prometheus scrapes it, OPC UA and Sparkplug sample it. Asked of
//! the control loop, every one of them is a message it must build a status for (and the
//! transport must serialise), and under load the loop and the HTTP threads took the CPU the
//! tick needed. Posted, the loop builds one status (and its JSON) per change or per
//! [`POST_EVERY`], whoever reads it; a read is an `Arc` clone. Commands still go through the
//! loop: a reply carries the status the command left.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use parking_lot::RwLock;

use super::protocol::{Reply, Status};

/// While a job runs (or a check), the loop posts at least this often: the position and the
/// counts a page draws move on meanwhile.
pub const POST_EVERY: Duration = Duration::from_millis(50);

/// One posted status.
#[derive(Debug)]
pub struct Posted {
    /// The status reply, as `edmd ctl status --json` and `GET /api/status` give it.
    pub reply: Reply,
    /// The same, serialised once.
    pub json: String,
    /// Counts the posts: a reader tells a new one from the one it has.
    pub seq: u64,
    pub at: Instant,
}

impl Posted {
    pub fn status(&self) -> Option<&Status> {
        self.reply.status.as_ref()
    }
}

/// The board, shared by the loop (which posts) and the transports (which read).
#[derive(Debug)]
pub struct StatusBoard {
    current: RwLock<Arc<Posted>>,
    posts: AtomicU64,
}

impl Default for StatusBoard {
    fn default() -> Self {
        StatusBoard {
            current: RwLock::new(Arc::new(Posted {
                reply: Reply::error("the daemon is starting", None),
                json: String::from(r#"{"ok":false,"error":"the daemon is starting"}"#),
                seq: 0,
                at: Instant::now(),
            })),
            posts: AtomicU64::new(0),
        }
    }
}

impl StatusBoard {
    /// Posts `status` (the control loop only).
    pub fn post(&self, status: Status) {
        let reply = Reply::ok("status", status);
        let json = serde_json::to_string(&reply).unwrap_or_default();
        let seq = self.posts.fetch_add(1, Ordering::Relaxed) + 1;
        let posted = Arc::new(Posted {
            reply,
            json,
            seq,
            at: Instant::now(),
        });
        *self.current.write() = posted;
    }

    /// The latest post.
    pub fn current(&self) -> Arc<Posted> {
        self.current.read().clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_post_replaces_the_last_and_readers_keep_theirs() {
        let board = StatusBoard::default();
        let first = board.current();
        assert_eq!(first.seq, 0);
        assert!(first.status().is_none(), "nothing posted yet");
        board.post(Status::bare(crate::daemon::protocol::DaemonState::Idle));
        let second = board.current();
        assert_eq!(second.seq, 1);
        assert!(second.status().is_some());
        assert!(second.json.starts_with(r#"{"ok":true"#), "{}", second.json);
        assert_eq!(first.seq, 0, "a reader's post stays as it was");
    }
}
