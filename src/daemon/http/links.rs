//! One-time login links (`edmd ctl web-link`): a panel PC or a phone logs in by opening a
//! link instead of typing 64 hex digits.
//!
//! The daemon makes a code of 128 random bits (the kernel's), valid for [`LIFETIME`] and for
//! one use; the link is `http://ADDR/#login=CODE` (in the fragment, so it never reaches a
//! server log or a proxy). The page trades the code for the token at `POST /api/login` and
//! keeps the token as a typed one. Whoever may use the control socket (`edmd ctl`) may
//! already do everything the token allows, so a link gives nothing new to its holder.

use std::io::Read;
use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::body::Bytes;
use axum::extract::State;
use axum::extract::rejection::BytesRejection;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use parking_lot::Mutex;
use serde::Deserialize;

use super::{App, body, error};

/// How long a link stays valid.
pub const LIFETIME: Duration = Duration::from_secs(600);
/// Links outstanding at most (the oldest is dropped for a new one).
const MAX_OUTSTANDING: usize = 16;

/// The codes not yet used, with when each expires.
#[derive(Debug, Default)]
pub struct LoginLinks {
    codes: Mutex<Vec<(String, Instant)>>,
}

impl LoginLinks {
    /// A new code, valid from `now` for [`LIFETIME`].
    pub fn issue(&self, now: Instant) -> std::io::Result<String> {
        let mut bytes = [0u8; 16];
        std::fs::File::open("/dev/urandom")?.read_exact(&mut bytes)?;
        let code: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
        let mut codes = self.codes.lock();
        codes.retain(|(_, expires)| *expires > now);
        if codes.len() >= MAX_OUTSTANDING {
            codes.remove(0);
        }
        codes.push((code.clone(), now + LIFETIME));
        Ok(code)
    }

    /// Uses `code` up: true once, for a code issued and not expired at `now`.
    fn redeem(&self, code: &str, now: Instant) -> bool {
        let mut codes = self.codes.lock();
        codes.retain(|(_, expires)| *expires > now);
        match codes
            .iter()
            .position(|(c, _)| super::token::same(c.as_bytes(), code.as_bytes()))
        {
            Some(i) => {
                codes.remove(i);
                true
            }
            None => false,
        }
    }
}

/// `http://ADDR/#login=CODE` for a new code (an unspecified address is given as the
/// machine's host name).
pub(super) fn link(addr: std::net::SocketAddr, links: &LoginLinks) -> std::io::Result<String> {
    let code = links.issue(Instant::now())?;
    let host = if addr.ip().is_unspecified() {
        crate::sys::host_name()
    } else {
        match addr.ip() {
            std::net::IpAddr::V6(ip) => format!("[{ip}]"),
            std::net::IpAddr::V4(ip) => ip.to_string(),
        }
    };
    Ok(format!(
        "http://{host}:{}/#login={code} (one use, valid {} minutes)",
        addr.port(),
        LIFETIME.as_secs() / 60
    ))
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LoginBody {
    code: String,
}

/// A one-time code from `edmd ctl web-link` for the token (`{"ok":true,"token":…}`).
pub(super) async fn login(
    State(app): State<Arc<App>>,
    raw: Result<Bytes, BytesRejection>,
) -> Response {
    let LoginBody { code } = match body(raw) {
        Ok(b) => b,
        Err(e) => return e,
    };
    if app.links.redeem(&code, Instant::now()) {
        let token = app.live.read().token.clone();
        axum::Json(serde_json::json!({ "ok": true, "token": token })).into_response()
    } else {
        error(
            StatusCode::UNAUTHORIZED,
            "the login link is used up, expired or unknown: ask for a new one with \
             `edmd ctl web-link`",
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_code_logs_in_once_and_not_after_its_lifetime() {
        let links = LoginLinks::default();
        let now = Instant::now();
        let code = links.issue(now).unwrap();
        assert_eq!(code.len(), 32);
        assert!(!links.redeem("0123", now));
        assert!(links.redeem(&code, now));
        assert!(!links.redeem(&code, now), "a second use");
        let late = links.issue(now).unwrap();
        assert!(!links.redeem(&late, now + LIFETIME + Duration::from_secs(1)));
        let codes: Vec<String> = (0..20).map(|_| links.issue(now).unwrap()).collect();
        assert!(!links.redeem(&codes[0], now), "the oldest made way");
        assert!(links.redeem(&codes[19], now));
    }
}
