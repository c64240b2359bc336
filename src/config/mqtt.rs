//! Validation of `[daemon.mqtt]`: the Sparkplug B edge node's broker, identity, deadbands and
//! whether commands are taken.

use std::path::PathBuf;

use super::raw::RawMqtt;
use super::validate::{Invalid, in_range, positive};

/// Where the broker is: `mqtt://HOST:PORT`, or `mqtts://HOST:PORT` over TLS.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MqttBroker {
    pub host: String,
    pub port: u16,
    pub tls: bool,
}

impl std::fmt::Display for MqttBroker {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let scheme = if self.tls { "mqtts" } else { "mqtt" };
        write!(f, "{scheme}://{}:{}", self.host, self.port)
    }
}

/// How far a value must move before it is published again (NDATA), per kind of value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Deadbands {
    /// Positions (mm).
    pub mm: f64,
    /// Feeds (mm/min).
    pub mm_per_min: f64,
    /// Fractions: progress, gap shares (0 to 1).
    pub fraction: f64,
    /// Times: the time to go (s).
    pub s: f64,
}

/// The Sparkplug B edge node (`[daemon.mqtt]`, on when `broker` is set).
#[derive(Debug, Clone, PartialEq)]
pub struct MqttConfig {
    pub broker: MqttBroker,
    /// The Sparkplug group (`spBv1.0/<group>/…`).
    pub group_id: String,
    /// The edge node's id; by default the host's name.
    pub node_id: String,
    /// `name:password` on one line; `None`: connect without a user name.
    pub credentials_file: Option<PathBuf>,
    /// The certificate authorities (PEM) a `mqtts` broker is checked against; `None`: the
    /// system's.
    pub ca_file: Option<PathBuf>,
    /// The MQTT keep-alive (s): the broker sends the node's death this long (times 1.5)
    /// after it last heard from it.
    pub keep_alive_s: u16,
    /// How often the status is sampled for NDATA (s).
    pub interval_s: f64,
    pub deadbands: Deadbands,
    /// Messages waiting for the broker at most; past it they are dropped and counted.
    pub queue: usize,
    /// NCMD may hold and abort (rebirth is always taken).
    pub commands: bool,
}

/// A Sparkplug id (group or edge node): not empty, none of `/ + #`, no spaces.
fn sparkplug_id(key: &'static str, text: &str) -> Result<String, Invalid> {
    let ok = !text.is_empty()
        && text
            .chars()
            .all(|c| !matches!(c, '/' | '+' | '#') && !c.is_whitespace() && !c.is_control());
    if ok {
        Ok(text.to_string())
    } else {
        Err((
            key,
            format!(
                "{text:?} is not a Sparkplug id: it needs a character and none of `/ + #` or spaces"
            ),
        ))
    }
}

/// `text` as a broker; `""` is off.
fn broker(text: &str) -> Result<Option<MqttBroker>, Invalid> {
    let text = text.trim();
    if text.is_empty() {
        return Ok(None);
    }
    let wrong = |why: &str| {
        (
            "daemon.mqtt.broker",
            format!(
                "{text:?} {why}: write \"mqtt://HOST:PORT\" or \"mqtts://HOST:PORT\", e.g. \
                 \"mqtt://127.0.0.1:1883\" (\"\" turns the edge node off)"
            ),
        )
    };
    let (tls, rest) = if let Some(rest) = text.strip_prefix("mqtts://") {
        (true, rest)
    } else if let Some(rest) = text.strip_prefix("mqtt://") {
        (false, rest)
    } else {
        return Err(wrong("is not an mqtt or mqtts URL"));
    };
    let (host, port) = super::net::host_and_port(rest).map_err(wrong)?;
    Ok(Some(MqttBroker { host, port, tls }))
}

/// A deadband: 0 (every change) or more.
fn deadband(key: &'static str, value: f64) -> Result<f64, Invalid> {
    if value == 0.0 {
        Ok(0.0)
    } else {
        positive(key, value, 1e6, "")
    }
}

fn file(value: &str) -> Option<PathBuf> {
    let value = value.trim();
    (!value.is_empty()).then(|| PathBuf::from(value))
}

impl RawMqtt {
    /// `[daemon.mqtt]` checked (every key, also while the node is off); `None` when `broker`
    /// is `""`. `host` is the default node id.
    pub(super) fn validate(self, host: &str) -> Result<Option<MqttConfig>, Invalid> {
        let broker = broker(&self.broker)?;
        // The host's name is the default id only where the node is on: a host name Sparkplug
        // cannot take must not stop a daemon that does not publish.
        let node_id = match (self.node_id.trim(), &broker) {
            ("", Some(_)) => host,
            ("", None) => "edmd",
            (id, _) => id,
        };
        let ca_file = file(&self.ca_file);
        let config = |broker: MqttBroker| -> Result<MqttConfig, Invalid> {
            if ca_file.is_some() && !broker.tls {
                return Err((
                    "daemon.mqtt.ca_file",
                    format!(
                        "is for a TLS broker; daemon.mqtt.broker {broker} is not one (mqtts://)"
                    ),
                ));
            }
            Ok(MqttConfig {
                group_id: sparkplug_id("daemon.mqtt.group_id", self.group_id.trim())?,
                node_id: sparkplug_id("daemon.mqtt.node_id", node_id)?,
                broker,
                credentials_file: file(&self.credentials_file),
                ca_file: ca_file.clone(),
                keep_alive_s: in_range("daemon.mqtt.keep_alive_s", self.keep_alive_s, 5, 3600)?
                    as u16,
                interval_s: positive("daemon.mqtt.interval_s", self.interval_s, 3600.0, "s")?,
                deadbands: Deadbands {
                    mm: deadband("daemon.mqtt.deadband_mm", self.deadband_mm)?,
                    mm_per_min: deadband(
                        "daemon.mqtt.deadband_mm_per_min",
                        self.deadband_mm_per_min,
                    )?,
                    fraction: deadband("daemon.mqtt.deadband_fraction", self.deadband_fraction)?,
                    s: deadband("daemon.mqtt.deadband_s", self.deadband_s)?,
                },
                queue: in_range("daemon.mqtt.queue", self.queue, 4, 100_000)? as usize,
                commands: self.commands,
            })
        };
        match broker {
            Some(broker) => config(broker).map(Some),
            // Off: the other keys are checked all the same, against a stand-in broker, so a
            // mistake is found before the node is turned on.
            None => config(MqttBroker {
                host: "localhost".into(),
                port: 8883,
                tls: true,
            })
            .map(|_| None),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn brokers_are_read_or_refused_with_the_form_to_write() {
        let b = broker("mqtt://127.0.0.1:1883").unwrap().unwrap();
        assert_eq!((b.host.as_str(), b.port, b.tls), ("127.0.0.1", 1883, false));
        let b = broker("mqtts://broker.plant.lan:8883").unwrap().unwrap();
        assert!(b.tls);
        assert_eq!(b.to_string(), "mqtts://broker.plant.lan:8883");
        assert_eq!(broker("mqtt://[::1]:1883").unwrap().unwrap().host, "::1");
        assert!(broker("").unwrap().is_none());
        for bad in ["tcp://h:1883", "mqtt://h", "mqtt://h:0", "mqtt://a b:1883"] {
            let (key, why) = broker(bad).unwrap_err();
            assert_eq!(key, "daemon.mqtt.broker");
            assert!(why.contains("mqtt://HOST:PORT"), "{why}");
        }
    }

    #[test]
    fn sparkplug_ids_refuse_topic_characters() {
        assert!(sparkplug_id("k", "edm-7").is_ok());
        for bad in ["", "a/b", "a+", "#", "a b"] {
            assert!(sparkplug_id("k", bad).is_err(), "{bad:?}");
        }
    }
}
