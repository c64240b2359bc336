//! How a transport (the socket, HTTP, OPC UA) reaches the control loop: a request and where
//! its reply goes, put on the loop's inbox. The transports know this link and the protocol,
//! nothing of the loop's own messages, so they stand below the module that starts them.

use std::sync::Arc;

use tokio::sync::oneshot;

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
}

impl CoreLink {
    /// The link over `submit` (a request onto the inbox) and `idle` (the inbox is empty).
    pub fn new(
        submit: impl Fn(Request, oneshot::Sender<Reply>) -> bool + Send + Sync + 'static,
        idle: impl Fn() -> bool + Send + Sync + 'static,
    ) -> CoreLink {
        CoreLink {
            submit: Arc::new(submit),
            idle: Arc::new(idle),
        }
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
