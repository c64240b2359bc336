//! Network addresses as the configuration writes them: `HOST:PORT`, `[V6]:PORT`.

/// The host and port of `authority` (`host:port`, `[v6]:port`), or why it is neither: a
/// name of letters, digits, `-` and `.`, or an IP address; a port from 1 to 65535.
pub(super) fn host_and_port(authority: &str) -> Result<(String, u16), &'static str> {
    let (host, port) = match authority.strip_prefix('[') {
        Some(v6) => v6.split_once("]:").ok_or("has no port")?,
        None => authority.rsplit_once(':').ok_or("has no port")?,
    };
    let host_ok = !host.is_empty()
        && (host.parse::<std::net::IpAddr>().is_ok()
            || host
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '.'));
    if !host_ok {
        return Err("does not name a host");
    }
    let port: u16 = port
        .parse()
        .ok()
        .filter(|p| *p > 0)
        .ok_or("has no port from 1 to 65535")?;
    Ok((host.to_string(), port))
}
