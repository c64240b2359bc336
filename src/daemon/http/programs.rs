//! The program directory over HTTP, beside `GET /api/programs` (the list):
//!
//! - `POST /api/programs?name=NAME`: a program uploaded into `daemon.program_dir`. The body is
//!   the program's text (at most [`MAX_UPLOAD_BYTES`]); the name is one plain file name (no
//!   directory, no leading dot, no control character, at most 255 bytes). The file is written
//!   beside its place under a temporary name, synced and put in its place, so a reader sees
//!   the old program or the new one, never a part: with `replace` renamed over it, without
//!   linked to the name, which fails if the name exists at that moment (two uploads of one
//!   new name at once: one is saved, the other gets 409, never a silent overwrite). Nothing is
//!   checked here unless asked (`check`): `run` checks it.
//! - `GET /api/program?name=NAME`: its text as lines, for the page's listing (the first
//!   [`MAX_LISTING_LINES`] lines of at most [`MAX_LISTING_BYTES`], marked `truncated` past
//!   that), confined to the program directory as `run` is.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use axum::body::Body;
use axum::extract::{Query, State};
use axum::http::header::CONTENT_LENGTH;
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;

use super::{App, authorised, busy, error, program_file};

/// The longest listing served, in lines and bytes.
pub const MAX_LISTING_LINES: usize = 20_000;
pub const MAX_LISTING_BYTES: u64 = 2 * 1024 * 1024;

/// Largest program accepted by upload, bytes.
pub const MAX_UPLOAD_BYTES: usize = 16 * 1024 * 1024;
/// Longest file name accepted, bytes.
const MAX_NAME_BYTES: usize = 255;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct UploadQuery {
    name: String,
    /// A program of that name exists: write over it (else refused, 409).
    #[serde(default)]
    replace: bool,
    /// Read the whole program first (as `edmd check` reads it) and save it only if it reads:
    /// the page's editor.
    #[serde(default)]
    check: bool,
}

pub(super) async fn upload(
    State(app): State<Arc<App>>,
    headers: HeaderMap,
    query: Result<Query<UploadQuery>, axum::extract::rejection::QueryRejection>,
    body: Body,
) -> Response {
    if let Err(e) = authorised(&app, &headers) {
        return e;
    }
    let too_large = || {
        error(
            StatusCode::PAYLOAD_TOO_LARGE,
            format!("a program of over {MAX_UPLOAD_BYTES} bytes is not uploaded"),
        )
    };
    // Refused from its declared length before a byte of it is read (the body is read only
    // for an authorised request, and never past the limit).
    let declared = headers
        .get(CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    if declared.is_some_and(|n| n > MAX_UPLOAD_BYTES as u64) {
        return too_large();
    }
    let Ok(Query(UploadQuery {
        name,
        replace,
        check,
    })) = query
    else {
        return error(
            StatusCode::BAD_REQUEST,
            "name the program: POST /api/programs?name=part.nc",
        );
    };
    if let Err(why) = plain_name(&name) {
        return error(StatusCode::BAD_REQUEST, format!("{name:?}: {why}"));
    }
    let bytes = match axum::body::to_bytes(body, MAX_UPLOAD_BYTES).await {
        Ok(b) => b,
        Err(e) if is_length_limit(&e) => return too_large(),
        Err(e) => return error(StatusCode::BAD_REQUEST, format!("the upload: {e}")),
    };
    let dir = app.live.read().program_dir.clone();
    let target = dir.join(&name);
    if replace && let Some(refused) = running_program(&app, &name, &target) {
        return refused;
    }
    if !replace && target.exists() {
        return error(
            StatusCode::CONFLICT,
            format!("{name} exists: upload it with replace to write over it"),
        );
    }
    let mut blocks = None;
    if check {
        let (axes, options, text) = (app.axes.clone(), app.options.clone(), bytes.clone());
        let named = name.clone();
        let read =
            tokio::task::spawn_blocking(move || check_text(&text, &named, &axes, options)).await;
        match read {
            Ok(Ok(n)) => blocks = Some(n),
            Ok(Err(e)) => {
                return error(StatusCode::UNPROCESSABLE_ENTITY, format!("not saved: {e}"));
            }
            Err(e) => return error(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
        }
    }
    let written =
        tokio::task::spawn_blocking(move || write_atomically(&dir, &target, &bytes, replace))
            .await
            .map_err(std::io::Error::other)
            .and_then(|r| r);
    match written {
        Ok(replaced) => {
            tracing::info!(
                edmd_event = "upload",
                "program {name} uploaded{}",
                if replaced {
                    " (replacing the old one)"
                } else {
                    ""
                }
            );
            let message = format!(
                "{name} {}{}{}",
                if check {
                    "checked and saved"
                } else {
                    "uploaded"
                },
                blocks.map(|n| format!(" ({n} moves)")).unwrap_or_default(),
                if replaced {
                    ", replacing the old one"
                } else {
                    ""
                }
            );
            axum::Json(serde_json::json!({ "ok": true, "message": message })).into_response()
        }
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => error(
            StatusCode::CONFLICT,
            format!("{name} exists (saved meanwhile): upload it with replace to write over it"),
        ),
        Err(e) => {
            tracing::error!("upload of {name}: {e}");
            error(
                StatusCode::INTERNAL_SERVER_ERROR,
                format!("{name}: cannot write it into the program directory: {e}"),
            )
        }
    }
}

/// The running job's program stays as it was run while it runs: what the operator reads
/// beside the cut, and what its history names. Another one is edited meanwhile.
fn running_program(app: &App, name: &str, target: &Path) -> Option<Response> {
    let running = app.to_core.status().status().and_then(|s| s.job.clone())?;
    (Path::new(&running.program) == target).then(|| {
        error(
            StatusCode::CONFLICT,
            format!(
                "{name} is the running job's program: it is not replaced while it runs (save \
                 the edit under another name, or after the job)"
            ),
        )
    })
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ListingQuery {
    name: String,
}

pub(super) async fn listing(
    State(app): State<Arc<App>>,
    query: Result<Query<ListingQuery>, axum::extract::rejection::QueryRejection>,
) -> Response {
    let Ok(Query(ListingQuery { name })) = query else {
        return error(
            StatusCode::BAD_REQUEST,
            "name the program: GET /api/program?name=part.nc",
        );
    };
    let path = match program_file(&app, &name) {
        Ok(p) => p,
        Err(e) => return e,
    };
    let Ok(_turn) = app.listings.try_acquire() else {
        return busy("program listings");
    };
    let read = tokio::task::spawn_blocking(move || read_lines(&path)).await;
    match read {
        Ok(Ok((lines, truncated))) => axum::Json(serde_json::json!({
            "name": name, "lines": lines, "truncated": truncated
        }))
        .into_response(),
        Ok(Err(e)) => error(StatusCode::INTERNAL_SERVER_ERROR, format!("{name}: {e}")),
        Err(e) => error(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    }
}

/// The first lines of a program (invalid UTF-8 replaced), and whether there were more.
fn read_lines(path: &Path) -> std::io::Result<(Vec<String>, bool)> {
    use std::io::{BufRead, Read};
    let file = crate::sys::open_regular(path)?;
    let size = file.metadata()?.len();
    let mut reader = std::io::BufReader::new(file.take(MAX_LISTING_BYTES));
    let mut lines = Vec::new();
    let mut buf = Vec::new();
    while lines.len() < MAX_LISTING_LINES {
        buf.clear();
        if reader.read_until(b'\n', &mut buf)? == 0 {
            return Ok((lines, size > MAX_LISTING_BYTES));
        }
        let text = String::from_utf8_lossy(&buf);
        lines.push(text.trim_end_matches(['\n', '\r']).to_string());
    }
    Ok((lines, true))
}

/// A name an upload may have: one plain file name.
/// Reads a program's text through the reader and the path's stages, as a job's check
/// does (without a machine: no travel limits): the number of moves, or the first error
/// with its `name:line:col`.
fn check_text(
    bytes: &[u8],
    name: &str,
    axes: &[crate::vocab::Axis],
    options: crate::gcode::ProgramOptions,
) -> Result<u64, String> {
    let reader =
        crate::gcode::BlockReader::with_options(std::io::Cursor::new(bytes), name, axes, options);
    let mut moves = 0;
    for item in crate::path::Pipeline::new(reader) {
        item.map_err(|e| e.to_string())?;
        moves += 1;
    }
    Ok(moves)
}

fn plain_name(name: &str) -> Result<(), &'static str> {
    if name.is_empty() || name.len() > MAX_NAME_BYTES {
        return Err("a program name has 1 to 255 bytes");
    }
    if name.chars().any(|c| c.is_control()) {
        return Err("a program name has no control characters");
    }
    if name.contains('/') || name.contains('\\') {
        return Err("a program name is a file name, with no directory");
    }
    if name.starts_with('.') {
        return Err("a program name does not start with a dot");
    }
    Ok(())
}

/// Writes `bytes` to `target` in `dir` through a synced temporary file, then renamed over
/// it (`replace`) or linked to its name, which fails with `AlreadyExists` if the name exists
/// by then (the check before the upload was read is only a courtesy: two uploads of one new
/// name race past it). `true` when it replaced a file.
fn write_atomically(
    dir: &Path,
    target: &PathBuf,
    bytes: &[u8],
    replace: bool,
) -> std::io::Result<bool> {
    let replaced = replace && target.exists();
    let tmp = dir.join(format!(
        ".upload-{}-{}-{}",
        std::process::id(),
        crate::sys::monotonic_ns(),
        crate::sys::random_hex(4)?
    ));
    let result = (|| {
        let mut file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)?;
        file.write_all(bytes)?;
        file.sync_all()?;
        if replace {
            std::fs::rename(&tmp, target)?;
        } else {
            std::fs::hard_link(&tmp, target)?;
            std::fs::remove_file(&tmp)?;
        }
        std::fs::File::open(dir)?.sync_all()
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.map(|()| replaced)
}

/// The body ran past the limit `to_bytes` was given.
fn is_length_limit(e: &axum::Error) -> bool {
    let mut source: Option<&(dyn std::error::Error + 'static)> = Some(e);
    while let Some(err) = source {
        if err.is::<http_body_util::LengthLimitError>() {
            return true;
        }
        source = err.source();
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_plain_file_names() {
        assert!(plain_name("part.nc").is_ok());
        assert!(plain_name("die 7 (rough).ngc").is_ok());
        for bad in ["", "../x.nc", "a/b.nc", ".hidden", "a\nb", "a\\b"] {
            assert!(plain_name(bad).is_err(), "{bad:?}");
        }
        assert!(plain_name(&"x".repeat(256)).is_err());
    }

    #[test]
    fn of_two_writes_of_one_new_name_one_is_kept_and_the_other_refused() {
        let dir = std::env::temp_dir().join(format!("edmd-upload-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let target = dir.join("part.nc");
        let barrier = std::sync::Barrier::new(8);
        let results: Vec<_> = std::thread::scope(|s| {
            let writers: Vec<_> = (0..8)
                .map(|i| {
                    let (dir, target, barrier) = (&dir, &target, &barrier);
                    s.spawn(move || {
                        barrier.wait();
                        write_atomically(dir, target, format!("G1 X{i}\n").as_bytes(), false)
                    })
                })
                .collect();
            writers.into_iter().map(|w| w.join().unwrap()).collect()
        });
        let kept = results.iter().filter(|r| r.is_ok()).count();
        assert_eq!(kept, 1, "{results:?}");
        assert!(results.iter().all(|r| match r {
            Ok(replaced) => !replaced,
            Err(e) => e.kind() == std::io::ErrorKind::AlreadyExists,
        }));
        // Nothing left behind but the program.
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        assert!(write_atomically(&dir, &target, b"G1 X9\n", true).unwrap());
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "G1 X9\n");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
