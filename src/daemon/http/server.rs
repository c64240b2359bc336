//! The HTTP connections: accepted, counted, timed out and evicted here; each served by
//! hyper's HTTP/1 connection with the router as its service.
//!
//! A client that connects and says nothing, or sends half a header and stops, holds a
//! descriptor for as long as the server lets it. With a thousand of them the daemon could not
//! open its checkpoint, so nothing here waits on a client without a limit:
//!
//! - **Header timeout**: a request's head must arrive within [`HEADER_TIMEOUT`] (hyper's
//!   timer), or the connection is closed.
//! - **Idle timeout**: a connection that moves no byte either way for [`IDLE_TIMEOUT`] is
//!   closed (a keep-alive connection between requests, a stalled upload). Event streams
//!   write at least every second, so they stay.
//! - **A cap with eviction**: at most `max_connections` at once, a number kept well below the
//!   descriptor limit (see [`connection_cap`]). When a new client comes while all are taken,
//!   the connection that has been quiet the longest is closed to make room: the operator
//!   pressing Hold is always the newest client, so however many connections an attacker
//!   holds open, the hold gets through.
//! - **Descriptor exhaustion**: if `accept` fails for want of descriptors (`EMFILE`), the
//!   quietest connection is closed too, and accepting resumes.

use std::collections::HashMap;
use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::task::{Context, Poll};
use std::time::{Duration, Instant};

use axum::Router;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use parking_lot::Mutex;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::TcpListener;
use tokio::sync::Notify;

/// A request's head must arrive within this.
pub const HEADER_TIMEOUT: Duration = Duration::from_secs(10);
/// A connection that moves no byte for this long is closed.
pub const IDLE_TIMEOUT: Duration = Duration::from_secs(60);
/// Descriptors kept free for everything but HTTP: the checkpoint and its directory, the
/// program copies, the control socket's clients, the log, the devices.
pub const DESCRIPTOR_RESERVE: u64 = 128;

/// How many HTTP connections may be open at once: the configured number, but never more
/// than the descriptor limit less [`DESCRIPTOR_RESERVE`] and the socket's clients.
pub fn connection_cap(configured: usize, descriptor_limit: u64, socket_clients: usize) -> usize {
    let room = descriptor_limit
        .saturating_sub(DESCRIPTOR_RESERVE)
        .saturating_sub(socket_clients as u64 + 2);
    configured.min(room as usize).max(1)
}

/// One open connection as the registry sees it.
struct Entry {
    /// Milliseconds since the server started, of the last byte moved.
    active: Arc<AtomicU64>,
    close: Arc<Notify>,
}

/// The open connections.
struct Registry {
    started: Instant,
    next: AtomicU64,
    open: Mutex<HashMap<u64, Entry>>,
}

impl Registry {
    fn now_ms(&self) -> u64 {
        self.started.elapsed().as_millis() as u64
    }

    /// Closes the connection quiet for the longest; `false` if there is none.
    fn evict_quietest(&self) -> bool {
        let mut open = self.open.lock();
        let quietest = open
            .iter()
            .min_by_key(|(_, e)| e.active.load(Ordering::Relaxed))
            .map(|(&id, _)| id);
        match quietest.and_then(|id| open.remove(&id)) {
            Some(entry) => {
                entry.close.notify_one();
                true
            }
            None => false,
        }
    }
}

/// Accepts and serves connections for ever.
pub async fn serve(listener: TcpListener, router: Router, max_connections: usize) {
    let registry = Arc::new(Registry {
        started: Instant::now(),
        next: AtomicU64::new(0),
        open: Mutex::new(HashMap::new()),
    });
    let mut refused_logged = false;
    loop {
        let stream = match listener.accept().await {
            Ok((stream, _)) => stream,
            Err(e) => {
                // Out of descriptors (or a connection reset before it was accepted): make
                // room and try again; never spin.
                if !refused_logged {
                    tracing::warn!("http: accept failed: {e}; closing the quietest connection");
                    refused_logged = true;
                }
                registry.evict_quietest();
                tokio::time::sleep(Duration::from_millis(20)).await;
                continue;
            }
        };
        refused_logged = false;
        while registry.open.lock().len() >= max_connections {
            if !registry.evict_quietest() {
                break;
            }
        }
        let id = registry.next.fetch_add(1, Ordering::Relaxed);
        let active = Arc::new(AtomicU64::new(registry.now_ms()));
        let close = Arc::new(Notify::new());
        registry.open.lock().insert(
            id,
            Entry {
                active: active.clone(),
                close: close.clone(),
            },
        );
        let registry = registry.clone();
        let service = TowerToHyperService::new(router.clone());
        tokio::spawn(async move {
            let io = Tracked {
                inner: stream,
                active: active.clone(),
                registry: registry.clone(),
            };
            let mut builder = hyper::server::conn::http1::Builder::new();
            builder
                .timer(TokioTimer::new())
                .header_read_timeout(HEADER_TIMEOUT)
                .max_buf_size(64 * 1024);
            let connection = builder.serve_connection(TokioIo::new(io), service);
            tokio::pin!(connection);
            let idle = async {
                loop {
                    let quiet = registry
                        .now_ms()
                        .saturating_sub(active.load(Ordering::Relaxed));
                    let left = IDLE_TIMEOUT.saturating_sub(Duration::from_millis(quiet));
                    if left.is_zero() {
                        return;
                    }
                    tokio::time::sleep(left).await;
                }
            };
            tokio::select! {
                _ = connection.as_mut() => {}
                _ = close.notified() => {}
                _ = idle => {}
            }
            registry.open.lock().remove(&id);
        });
    }
}

/// A TCP stream that notes when it last moved a byte.
struct Tracked {
    inner: tokio::net::TcpStream,
    active: Arc<AtomicU64>,
    registry: Arc<Registry>,
}

impl Tracked {
    fn touch(&self) {
        self.active.store(self.registry.now_ms(), Ordering::Relaxed);
    }
}

impl AsyncRead for Tracked {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let before = buf.filled().len();
        let polled = Pin::new(&mut self.inner).poll_read(cx, buf);
        if matches!(polled, Poll::Ready(Ok(()))) && buf.filled().len() > before {
            self.touch();
        }
        polled
    }
}

impl AsyncWrite for Tracked {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        data: &[u8],
    ) -> Poll<io::Result<usize>> {
        let polled = Pin::new(&mut self.inner).poll_write(cx, data);
        if matches!(polled, Poll::Ready(Ok(n)) if n > 0) {
            self.touch();
        }
        polled
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cap_stays_below_the_descriptor_limit() {
        assert_eq!(connection_cap(256, 1024, 8), 256);
        assert_eq!(connection_cap(1000, 1024, 8), 1024 - 128 - 10);
        assert_eq!(connection_cap(256, 100, 8), 1);
        assert_eq!(connection_cap(256, 524_288, 8), 256);
    }
}
