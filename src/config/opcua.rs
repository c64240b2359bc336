//! Validation of `daemon.opcua`: the OPC UA endpoint URL, `opc.tcp://HOST:PORT`.

/// Where the OPC UA server listens: the host (a name or an IP address, as clients will
/// write it in their URLs) and the TCP port.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OpcUaEndpoint {
    pub host: String,
    pub port: u16,
}

impl OpcUaEndpoint {
    /// The URL clients connect to.
    pub fn url(&self) -> String {
        if self.host.contains(':') {
            format!("opc.tcp://[{}]:{}/", self.host, self.port)
        } else {
            format!("opc.tcp://{}:{}/", self.host, self.port)
        }
    }
}

/// `text` as an endpoint; `""` is off. The error says what is wrong with it.
pub(super) fn endpoint(text: &str) -> Result<Option<OpcUaEndpoint>, String> {
    let text = text.trim();
    if text.is_empty() {
        return Ok(None);
    }
    let wrong = |why: &str| {
        format!(
            "{text:?} {why}: write \"opc.tcp://HOST:PORT\", e.g. \"opc.tcp://127.0.0.1:4840\" \
             (\"\" turns OPC UA off)"
        )
    };
    let rest = text
        .strip_prefix("opc.tcp://")
        .ok_or_else(|| wrong("is not an opc.tcp URL"))?;
    let authority = rest.strip_suffix('/').unwrap_or(rest);
    if authority.contains('/') {
        return Err(wrong(
            "has a path; edmd serves its one endpoint at the root",
        ));
    }
    let (host, port) = super::net::host_and_port(authority).map_err(wrong)?;
    Ok(Some(OpcUaEndpoint { host, port }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn endpoints() {
        assert_eq!(endpoint("  ").unwrap(), None);
        let e = endpoint("opc.tcp://127.0.0.1:4840").unwrap().unwrap();
        assert_eq!((e.host.as_str(), e.port), ("127.0.0.1", 4840));
        assert_eq!(e.url(), "opc.tcp://127.0.0.1:4840/");
        let e = endpoint("opc.tcp://edm-7.shop.lan:48010/")
            .unwrap()
            .unwrap();
        assert_eq!((e.host.as_str(), e.port), ("edm-7.shop.lan", 48010));
        let e = endpoint("opc.tcp://[::1]:4840").unwrap().unwrap();
        assert_eq!(e.url(), "opc.tcp://[::1]:4840/");
        for (text, why) in [
            ("127.0.0.1:4840", "not an opc.tcp URL"),
            ("opc.tcp://127.0.0.1", "no port"),
            ("opc.tcp://127.0.0.1:0", "no port from 1"),
            ("opc.tcp://127.0.0.1:99999", "no port from 1"),
            ("opc.tcp://:4840", "does not name a host"),
            ("opc.tcp://a b:4840", "does not name a host"),
            ("opc.tcp://127.0.0.1:4840/edmd", "has a path"),
        ] {
            let e = endpoint(text).unwrap_err();
            assert!(e.contains(why), "{text}: {e}");
        }
    }
}
