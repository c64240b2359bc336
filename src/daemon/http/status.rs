//! What the page, Prometheus and scripts read of the machine: `GET /api/status`, the
//! Server-Sent Events that carry it on every change, and `GET /metrics`, all from the status
//! the control loop posts ([`crate::daemon::board`]): however many clients read, the loop is
//! not asked.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Instant;

use axum::extract::State;
use axum::http::{StatusCode, header};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};

use super::{App, EVENT_HEARTBEAT, EVENT_POLL, MAX_EVENT_STREAMS, ask, error, metrics};
use crate::daemon::protocol::Request;

/// The status the control loop last posted ([`crate::daemon::board`]), serialised by it
/// (before its first post, in the daemon's first moments, the loop is asked).
pub(super) async fn status(State(app): State<Arc<App>>) -> Response {
    let posted = app.to_core.status();
    if posted.seq == 0 {
        return match ask(&app, Request::Status {}).await {
            Ok(reply) => axum::Json(reply).into_response(),
            Err(e) => e,
        };
    }
    (
        [(header::CONTENT_TYPE, "application/json")],
        posted.json.clone(),
    )
        .into_response()
}

pub(super) async fn metrics(State(app): State<Arc<App>>) -> Response {
    let posted = app.to_core.status();
    match posted.status() {
        Some(status) => (
            [(
                header::CONTENT_TYPE,
                "text/plain; version=0.0.4; charset=utf-8",
            )],
            metrics::render(status),
        )
            .into_response(),
        None => error(StatusCode::SERVICE_UNAVAILABLE, "the daemon is starting"),
    }
}

/// The status reply on every change (position, state, counters: anything but the clocks)
/// and at least every second.
pub(super) async fn events(State(app): State<Arc<App>>) -> Response {
    if app.streams.fetch_add(1, Ordering::AcqRel) >= MAX_EVENT_STREAMS {
        app.streams.fetch_sub(1, Ordering::AcqRel);
        return error(
            StatusCode::SERVICE_UNAVAILABLE,
            format!("{MAX_EVENT_STREAMS} event streams are open already"),
        );
    }
    let stream = EventStream {
        app: app.clone(),
        last: None,
        last_seq: 0,
        sent_at: Instant::now(),
    };
    let events = futures_util::stream::unfold(stream, |mut s| async move {
        let event = s.next().await?;
        Some((Ok::<_, std::convert::Infallible>(event), s))
    });
    Sse::new(events)
        .keep_alive(KeepAlive::default())
        .into_response()
}

/// One client's stream; counts itself out when the client goes.
struct EventStream {
    app: Arc<App>,
    /// The last reply sent, without its clocks, and the post it came from.
    last: Option<serde_json::Value>,
    last_seq: u64,
    sent_at: Instant,
}

impl EventStream {
    async fn next(&mut self) -> Option<Event> {
        loop {
            // At most one event per poll period, however fast the status changes.
            if self.last.is_some() {
                tokio::time::sleep(EVENT_POLL).await;
            }
            let posted = self.app.to_core.status();
            if self.last.is_some()
                && posted.seq == self.last_seq
                && self.sent_at.elapsed() < EVENT_HEARTBEAT
            {
                continue;
            }
            self.last_seq = posted.seq;
            let mut json = serde_json::to_value(&posted.reply).ok()?;
            let mut key = json.clone();
            if let Some(s) = key.get_mut("status").and_then(|s| s.as_object_mut()) {
                s.remove("uptime_s");
                if let Some(j) = s.get_mut("job").and_then(|j| j.as_object_mut()) {
                    j.remove("elapsed_s");
                }
            }
            let changed = self.last.as_ref() != Some(&key);
            if changed || self.last.is_none() || self.sent_at.elapsed() >= EVENT_HEARTBEAT {
                self.last = Some(key);
                self.sent_at = Instant::now();
                let data = std::mem::take(&mut json).to_string();
                return Some(Event::default().event("status").data(data));
            }
        }
    }
}

impl Drop for EventStream {
    fn drop(&mut self) {
        self.app.streams.fetch_sub(1, Ordering::AcqRel);
    }
}
