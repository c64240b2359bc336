//! What every request passes before a handler sees it, and what every response carries.
//!
//! - **Host allow-list** (DNS rebinding): a page on another site can make the browser send
//!   requests to the machine under the attacker's host name, and read the answers. A browser
//!   always sends the name it connected to in `Host`, so only names the machine answers to
//!   are served: IP literals (a rebinding attack never produces one), `localhost`, and
//!   `daemon.http_allowed_hosts`. Anything else is 403.
//! - **Security headers** on every response: a Content Security Policy that allows the
//!   page's own script and style (by their SHA-256) and connections to itself, nothing from
//!   elsewhere and no framing; `X-Frame-Options: DENY` for older browsers (clickjacking a
//!   page whose token sits in its storage); `X-Content-Type-Options: nosniff`; no referrer.
//! - **Bearer tokens**: `Authorization: Bearer <token>`, the scheme in any case (RFC 7235).

use std::net::IpAddr;

use axum::http::{HeaderMap, HeaderValue, header};
use base64_sha256::digest_b64;

/// The `Host` header's name part, lower case (the port and IPv6 brackets taken off).
pub fn host_name(headers: &HeaderMap) -> Option<String> {
    let host = headers.get(header::HOST)?.to_str().ok()?.trim();
    let name = if let Some(rest) = host.strip_prefix('[') {
        rest.split(']').next()?
    } else {
        host.rsplit_once(':')
            .filter(|(_, port)| port.bytes().all(|b| b.is_ascii_digit()))
            .map_or(host, |(name, _)| name)
    };
    Some(name.trim_end_matches('.').to_ascii_lowercase())
}

/// The request's `Host` names this machine: an IP literal, `localhost`, or one of `allowed`.
pub fn host_allowed(headers: &HeaderMap, allowed: &[String]) -> bool {
    let Some(name) = host_name(headers) else {
        return false;
    };
    name.parse::<IpAddr>().is_ok()
        || name == "localhost"
        || allowed.iter().any(|a| a.eq_ignore_ascii_case(&name))
}

/// The token of `Authorization: Bearer <token>`, the scheme's case ignored.
pub fn bearer(headers: &HeaderMap) -> Option<&str> {
    let value = headers.get(header::AUTHORIZATION)?.to_str().ok()?.trim();
    let (scheme, token) = value.split_once(' ')?;
    scheme
        .eq_ignore_ascii_case("bearer")
        .then(|| token.trim())
        .filter(|t| !t.is_empty())
}

/// The Content Security Policy for `page`: its inline `<script>` and `<style>` allowed by
/// hash, connections to the page's own origin, nothing else.
pub fn content_security_policy(page: &str) -> String {
    let inline = |open: &str, close: &str| -> Vec<String> {
        let mut hashes = Vec::new();
        let mut rest = page;
        while let Some(start) = rest.find(open) {
            let body = &rest[start + open.len()..];
            let Some(end) = body.find(close) else { break };
            hashes.push(format!("'sha256-{}'", digest_b64(&body[..end])));
            rest = &body[end..];
        }
        hashes
    };
    format!(
        "default-src 'none'; script-src {}; style-src {}; connect-src 'self'; img-src 'self' \
         data:; base-uri 'none'; form-action 'none'; frame-ancestors 'none'",
        inline("<script>", "</script>").join(" "),
        inline("<style>", "</style>").join(" ")
    )
}

/// Adds the security headers to a response's headers.
pub fn secure(headers: &mut HeaderMap, csp: &HeaderValue) {
    headers.insert(header::CONTENT_SECURITY_POLICY, csp.clone());
    headers.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    headers.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    headers.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static("no-referrer"),
    );
}

/// SHA-256 in base64, as CSP hashes are written.
mod base64_sha256 {
    use sha2::{Digest, Sha256};

    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

    pub(super) fn digest_b64(text: &str) -> String {
        encode(&Sha256::digest(text.as_bytes()))
    }

    /// Standard base64 with padding (RFC 4648 §4).
    pub fn encode(bytes: &[u8]) -> String {
        let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
        for chunk in bytes.chunks(3) {
            let b = [
                chunk[0],
                *chunk.get(1).unwrap_or(&0),
                *chunk.get(2).unwrap_or(&0),
            ];
            let n = u32::from(b[0]) << 16 | u32::from(b[1]) << 8 | u32::from(b[2]);
            for i in 0..4 {
                if i <= chunk.len() {
                    out.push(ALPHABET[(n >> (18 - 6 * i) & 63) as usize] as char);
                } else {
                    out.push('=');
                }
            }
        }
        out
    }

    #[cfg(test)]
    mod tests {
        #[test]
        fn rfc_4648_vectors() {
            for (plain, coded) in [
                ("", ""),
                ("f", "Zg=="),
                ("fo", "Zm8="),
                ("foo", "Zm9v"),
                ("foob", "Zm9vYg=="),
                ("fooba", "Zm9vYmE="),
                ("foobar", "Zm9vYmFy"),
            ] {
                assert_eq!(super::encode(plain.as_bytes()), coded);
            }
            // `echo -n 'alert(1)' | openssl dgst -sha256 -binary | base64`
            assert_eq!(
                super::digest_b64("alert(1)"),
                "bhHHL3z2vDgxUt0W3dWQOrprscmda2Y5pLsLg4GF+pI="
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with(name: &str, value: &str) -> HeaderMap {
        let mut h = HeaderMap::new();
        h.insert(
            axum::http::HeaderName::from_bytes(name.as_bytes()).unwrap(),
            HeaderValue::from_str(value).unwrap(),
        );
        h
    }

    #[test]
    fn hosts_the_machine_answers_to() {
        let allowed = vec!["edm-7.shop.lan".to_string()];
        for ok in [
            "127.0.0.1:8080",
            "localhost:8080",
            "LOCALHOST",
            "[::1]:8080",
            "192.168.1.20",
            "edm-7.shop.lan:80",
            "EDM-7.shop.lan.",
        ] {
            assert!(host_allowed(&with("host", ok), &allowed), "{ok}");
        }
        for bad in [
            "evil.example:8080",
            "127.0.0.1.nip.io",
            "localhost.evil.example",
            "",
        ] {
            assert!(!host_allowed(&with("host", bad), &allowed), "{bad}");
        }
        assert!(!host_allowed(&HeaderMap::new(), &allowed), "no Host at all");
    }

    #[test]
    fn the_bearer_scheme_in_any_case() {
        let t = |v: &str| bearer(&with("authorization", v)).map(str::to_string);
        assert_eq!(t("Bearer abc").as_deref(), Some("abc"));
        assert_eq!(t("bearer abc").as_deref(), Some("abc"));
        assert_eq!(t("BEARER  abc ").as_deref(), Some("abc"));
        assert_eq!(t("Basic abc"), None);
        assert_eq!(t("Bearer"), None);
        assert_eq!(t("Bearer "), None);
    }

    #[test]
    fn the_policy_allows_the_pages_own_script_and_style_only() {
        let page = "<style>b{}</style><script>alert(1)</script>";
        let csp = content_security_policy(page);
        assert!(
            csp.contains("script-src 'sha256-bhHHL3z2vDgxUt0W3dWQOrprscmda2Y5pLsLg4GF+pI='"),
            "{csp}"
        );
        assert!(csp.contains("frame-ancestors 'none'"));
        assert!(!csp.contains("unsafe"));
    }
}
