//! `GET /api/jobs`: the job history as the page's table reads it; `GET /api/technology`: the
//! technology tables, and what a request selects, as the run dialog offers them.

use std::sync::Arc;

use axum::extract::{Query, State};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;

use super::{App, ask};
use crate::daemon::protocol::Request;

/// The job history, newest first (`?count=N`, 20 by default): what `edmd ctl jobs` lists.
pub(super) async fn list(State(app): State<Arc<App>>, Query(q): Query<JobsQuery>) -> Response {
    match ask(&app, Request::Jobs { count: q.count }).await {
        Ok(reply) => axum::Json(serde_json::json!({
            "ok": reply.ok,
            "jobs": reply.jobs.unwrap_or_default(),
        }))
        .into_response(),
        Err(e) => e,
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct JobsQuery {
    #[serde(default)]
    count: Option<usize>,
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
