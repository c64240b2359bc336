//! How a transport (the socket, HTTP, OPC UA, Sparkplug) reaches the control loop: a request
//! and where its reply goes, put on the loop's inbox; and the status the loop last posted
//! ([`super::board`]), read without asking. The transports know this link and the protocol,
//! nothing of the loop's own messages, so they stand below the module that starts them.

use std::sync::Arc;

use tokio::sync::oneshot;

use super::board::{Posted, StatusBoard};
use super::protocol::{Reply, Request};

/// Puts a request on the loop's inbox; `false` when the loop is gone.
type Submit = dyn Fn(Request, oneshot::Sender<Reply>) -> bool + Send + Sync;
/// Whether the inbox is empty (nothing waits for the loop).
type Idle = dyn Fn() -> bool + Send + Sync;

/// A transport's way into the control loop (cheap to clone: one per client task).
#[derive(Clone)]
pub struct CoreLink {
    submit: Arc<Submit>,
    idle: Arc<Idle>,
    board: Arc<StatusBoard>,
}

impl CoreLink {
    /// The link over `submit` (a request onto the inbox), `idle` (the inbox is empty) and
    /// the loop's status board.
    pub fn new(
        submit: impl Fn(Request, oneshot::Sender<Reply>) -> bool + Send + Sync + 'static,
        idle: impl Fn() -> bool + Send + Sync + 'static,
        board: Arc<StatusBoard>,
    ) -> CoreLink {
        CoreLink {
            submit: Arc::new(submit),
            idle: Arc::new(idle),
            board,
        }
    }

    /// The status the loop last posted (at most [`super::board::POST_EVERY`] old while a job
    /// runs, and after every command).
    pub fn status(&self) -> Arc<Posted> {
        self.board.current()
    }

    /// Hands `request` to the loop, its reply to come on `reply`; `false`: the loop is gone
    /// (the daemon is shutting down).
    pub fn ask(&self, request: Request, reply: oneshot::Sender<Reply>) -> bool {
        (self.submit)(request, reply)
    }

    /// Nothing waits on the loop's inbox.
    pub fn inbox_empty(&self) -> bool {
        (self.idle)()
    }
}
