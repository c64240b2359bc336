//! `GET /api/jobs`: the job history as the page's table reads it; `GET /api/technology`: the
//! technology tables, and what a request selects, as the run dialog offers them.

use std::sync::Arc;

use axum::extract::{Query, State};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;

use axum::http::StatusCode;

use super::{App, ask};
use crate::daemon::history::MAX_LISTED;
use crate::daemon::protocol::Request;

/// The job history, newest first (`?count=N`, 20 by default, `&skip=M` for a page further
/// back): what `edmd ctl jobs` lists. Read from the file on a blocking thread, never through
/// the control loop; at most [`super::MAX_LISTINGS`] at once (it shares the listings' turn).
pub(super) async fn list(State(app): State<Arc<App>>, Query(q): Query<JobsQuery>) -> Response {
    let Ok(_turn) = app.listings.try_acquire() else {
        return super::busy("history reads");
    };
    let file = app.history.clone();
    let count = q.count.unwrap_or(20).clamp(1, MAX_LISTED);
    let skip = q.skip.unwrap_or(0);
    match tokio::task::spawn_blocking(move || file.page(skip, count)).await {
        Ok(Ok(page)) => axum::Json(serde_json::json!({
            "ok": true,
            "jobs": page.jobs,
            "unreadable": page.unreadable,
            "more": page.more,
        }))
        .into_response(),
        Ok(Err(e)) => super::error(
            StatusCode::INTERNAL_SERVER_ERROR,
            format!("cannot read the job history: {e}"),
        ),
        Err(e) => super::error(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct JobsQuery {
    #[serde(default)]
    count: Option<usize>,
    #[serde(default)]
    skip: Option<usize>,
}

/// The technology tables; with `?request=material=steel,height=32,wire=0.25`, what it
/// selects explained (`explain`), or why nothing (`error`).
pub(super) async fn technology(
    State(app): State<Arc<App>>,
    Query(q): Query<TechnologyQuery>,
) -> Response {
    match ask(&app, Request::Technology { request: q.request }).await {
        Ok(reply) => axum::Json(serde_json::json!({
            "ok": reply.ok,
            "tables": reply.technology.unwrap_or_default(),
            "explain": if reply.ok { reply.message } else { None },
            "error": reply.error,
        }))
        .into_response(),
        Err(e) => e,
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct TechnologyQuery {
    #[serde(default)]
    request: Option<String>,
}
