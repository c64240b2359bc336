//! `edmd ctl find`: start a wire-touch cycle and wait for its result, which the daemon's
//! status carries (`machine.find`, under the cycle's id) once its last move has ended.

use std::path::Path;
use std::process::ExitCode;
use std::time::Duration;

use super::{EXIT_RUNTIME, write_stdout};
use crate::daemon::protocol::{FindStatus, Request};

/// How often the status is asked for while a cycle runs.
const POLL: Duration = Duration::from_millis(100);

/// Sends `request` (a `find`), then polls the status until the cycle it started has ended.
/// Exit 0 when it found its target, 1 when it failed or was refused.
pub(super) fn find_and_wait(socket: &Path, request: Request, json: bool) -> ExitCode {
    let refused = |error: &str| {
        eprintln!("edmd: error: {error}");
        ExitCode::from(EXIT_RUNTIME)
    };
    let reply = match crate::daemon::socket::request(socket, &request) {
        Ok(reply) => reply,
        Err(e) => return refused(&e.to_string()),
    };
    if !reply.ok {
        if json {
            out!("{}", reply.to_line());
        }
        return refused(reply.error.as_deref().unwrap_or("the daemon refused"));
    }
    let id = match reply.status.as_ref().and_then(|s| s.machine.find.as_ref()) {
        Some(f) => f.id,
        None => return refused("the daemon's reply names no find cycle"),
    };
    if !json {
        outln!("{}", reply.message.as_deref().unwrap_or_default());
    }
    loop {
        let status = match crate::daemon::socket::request(socket, &Request::Status {}) {
            Ok(reply) => reply.status,
            Err(e) => return refused(&format!("the daemon went away ({e})")),
        };
        let find: Option<FindStatus> = status.and_then(|s| s.machine.find);
        match find {
            Some(f) if f.id == id && f.state != "running" => {
                if json {
                    outln!(
                        "{}",
                        serde_json::to_string(&f).expect("a status serialises")
                    );
                } else if f.state == "found" {
                    outln!("{}", f.message);
                }
                return if f.state == "found" {
                    ExitCode::SUCCESS
                } else {
                    refused(&f.message)
                };
            }
            Some(f) if f.id == id => std::thread::sleep(POLL),
            _ => return refused("the daemon no longer knows the cycle (restarted?)"),
        }
    }
}
