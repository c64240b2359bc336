//! SIGHUP: reload the configuration, key by key.
//!
//! The file (and the same `--set` overrides) is read and validated again, then every key is
//! compared with the one in force. Each changed key falls in one class:
//!
//! | class | keys | while a job runs | idle |
//! |---|---|---|---|
//! | live | `log.level`, `daemon.program_dir`, `daemon.status_interval_s`, `daemon.checkpoint_interval_s`, `daemon.report_dir`, `daemon.max_clients`, `daemon.http_token_file`, `daemon.http_allowed_hosts`, `daemon.opcua_users_file` | applied | applied |
//! | job | everything that shapes or times motion: `machine.*`, `interpolation.*`, `buffer.*`, `fine.tick_us`, `servo.*`, `gap.*`, `sim.*`, `output.path`, … | refused | applied (next job) |
//! | restart | what was set up at startup: `daemon.socket*`, `daemon.http`, `daemon.http_max_connections`, `daemon.opcua`, `daemon.opcua_pki_dir`, `[daemon.mqtt]`, `log.format`, `fine.virtual_time`, `fine.rt_priority`, `fine.lock_memory`, `fine.cpu`, `output.kind`, `parport.*`, and `output.path` when it names the port | refused | refused |
//!
//! A reload is all or nothing: if any change is refused, none is applied, and the log says
//! which keys and why. What changed is logged as `key: old -> new`.
//!
//! **Nothing is read on the control loop's thread.** A configuration path that blocks (a
//! FIFO, a hung network mount) must not stop status, hold or a jog's dead-man, so the files
//! (the configuration, the HTTP token, the OPC UA users) are read by a worker thread
//! ([`spawn_read`]) that hands its [`ReadBack`] to the control loop as a message. A read
//! that has not answered after [`READ_TIMEOUT`] is reported; the configuration in force
//! stays until one answers, and a SIGHUP meanwhile is read after it.

use std::path::PathBuf;
use std::time::Duration;

use crate::config::{Config, ConfigError, KeyValues, OutputKind};

/// Where the configuration came from, to reload it the same way.
#[derive(Debug, Clone)]
pub struct ConfigSource {
    pub path: Option<PathBuf>,
    pub overrides: Vec<String>,
}

/// How long a reload's reads may take before the log says so.
pub const READ_TIMEOUT: Duration = Duration::from_secs(10);

/// What the reload worker read.
pub struct ReadBack {
    pub config: Result<(Config, KeyValues), ConfigError>,
    /// The HTTP token (when the web side is on), from the file the new configuration names
    /// (the one in force if it did not load).
    pub token: Option<Result<String, super::http::token::TokenError>>,
    /// The OPC UA users (when OPC UA is on), likewise.
    pub users: Option<Result<super::opcua::users::Users, super::opcua::users::UsersError>>,
    /// The technology tables of the new configuration's `technology.dir` (the one in force
    /// if it did not load).
    pub technology: Result<crate::technology::Tables, crate::technology::TechError>,
}

/// The secrets' files in force: `None` for a side that is off.
pub struct SecretPaths {
    pub token: Option<PathBuf>,
    pub users: Option<PathBuf>,
    /// `technology.dir`.
    pub technology: PathBuf,
}

/// Reads the configuration (then the secrets) on a thread of its own and sends the result
/// through `done`.
pub fn spawn_read(
    source: ConfigSource,
    in_force: SecretPaths,
    done: impl FnOnce(ReadBack) + Send + 'static,
) -> std::io::Result<()> {
    std::thread::Builder::new()
        .name("edmd-reload".to_string())
        .spawn(move || {
            let config = Config::load_with_keys(source.path.as_deref(), &source.overrides);
            let (token_path, users_path) = match &config {
                Ok((c, _)) => (
                    in_force
                        .token
                        .as_ref()
                        .map(|_| c.daemon.http_token_file.clone()),
                    in_force
                        .users
                        .as_ref()
                        .map(|_| c.daemon.opcua_users_file.clone()),
                ),
                Err(_) => (in_force.token, in_force.users),
            };
            let technology = crate::technology::Tables::load(match &config {
                Ok((c, _)) => &c.technology.dir,
                Err(_) => &in_force.technology,
            });
            let token = token_path.map(|p| super::http::token::load_or_create(&p));
            let users = users_path.map(|p| super::opcua::users::load_or_create(&p));
            done(ReadBack {
                config,
                token,
                users,
                technology,
            });
        })
        .map(|_| ())
}

/// When a changed key may take effect.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KeyClass {
    Live,
    Job,
    Restart,
}

pub fn classify(key: &str) -> KeyClass {
    match key {
        "log.level"
        | "daemon.program_dir"
        | "daemon.status_interval_s"
        | "daemon.checkpoint_interval_s"
        | "daemon.report_dir"
        | "daemon.max_clients"
        | "daemon.http_token_file"
        | "daemon.http_allowed_hosts"
        | "daemon.opcua_users_file" => KeyClass::Live,
        "daemon.socket"
        | "daemon.socket_mode"
        | "daemon.socket_group"
        | "daemon.http"
        | "daemon.http_max_connections"
        | "daemon.opcua"
        | "daemon.opcua_pki_dir"
        | "log.format"
        | "fine.virtual_time"
        | "fine.rt_priority"
        | "fine.lock_memory"
        | "fine.cpu"
        | "output.kind" => KeyClass::Restart,
        k if k.starts_with("parport.") || k == "daemon.mqtt" => KeyClass::Restart,
        _ => KeyClass::Job,
    }
}

/// The keys whose values differ, as `key: old -> new` lines.
pub fn diff(old: &KeyValues, new: &KeyValues) -> Vec<(String, String, String)> {
    let mut changes = Vec::new();
    for (key, value) in new {
        let before = old.get(key).cloned().unwrap_or_default();
        if &before != value {
            changes.push((key.clone(), before, value.clone()));
        }
    }
    changes
}

/// A changed key that may not change now.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RefusedKey {
    pub key: String,
    /// `Restart`, or `Job` while a job runs.
    pub class: KeyClass,
}

impl std::fmt::Display for RefusedKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.class {
            KeyClass::Restart => write!(f, "{} needs a restart", self.key),
            _ => write!(f, "{} cannot change while a job runs", self.key),
        }
    }
}

/// Why a reload applied nothing.
#[derive(Debug, thiserror::Error)]
pub enum ReloadRefusal {
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    #[error("{}", .0.iter().map(ToString::to_string).collect::<Vec<_>>().join("; "))]
    Keys(Vec<RefusedKey>),
}

/// Decides on the configuration the worker read. `Ok(None)`: nothing changed; `Ok(Some)`:
/// the new configuration with the change lines; `Err`: refused, with the reasons.
pub fn decide(
    keys: &KeyValues,
    config: Config,
    new_keys: KeyValues,
    job_running: bool,
) -> Result<Option<(Config, KeyValues, Vec<String>)>, ReloadRefusal> {
    let changes = diff(keys, &new_keys);
    if changes.is_empty() {
        return Ok(None);
    }
    let mut refused = Vec::new();
    for (key, _, _) in &changes {
        // The port's device path was opened at startup.
        let parport_device = key == "output.path" && config.output.kind == OutputKind::Parport;
        let class = if parport_device {
            KeyClass::Restart
        } else {
            classify(key)
        };
        let refuse = class == KeyClass::Restart || (class == KeyClass::Job && job_running);
        if refuse {
            refused.push(RefusedKey {
                key: key.clone(),
                class,
            });
        }
    }
    if !refused.is_empty() {
        return Err(ReloadRefusal::Keys(refused));
    }
    let lines = changes
        .iter()
        .map(|(k, a, b)| format!("{k}: {a} -> {b}"))
        .collect();
    Ok(Some((config, new_keys, lines)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(sets: &[&str]) -> (Config, KeyValues) {
        let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
        Config::load_with_keys(None, &sets).unwrap()
    }

    #[test]
    fn live_keys_apply_job_keys_wait_restart_keys_never() {
        let (_, keys) = load(&[]);
        let (c, k) = load(&["log.level=\"debug\"", "daemon.max_clients=3"]);
        let (_, _, lines) = decide(&keys, c, k, true).unwrap().unwrap();
        assert_eq!(
            lines,
            vec![
                "daemon.max_clients: 256 -> 3".to_string(),
                "log.level: \"info\" -> \"debug\"".to_string()
            ]
        );

        let (c, k) = load(&["servo.normal_feed_mm_per_min=9.0"]);
        let e = decide(&keys, c.clone(), k.clone(), true)
            .unwrap_err()
            .to_string();
        assert!(e.contains("servo.normal_feed_mm_per_min cannot change while a job runs"));
        assert!(decide(&keys, c, k, false).unwrap().is_some());

        let (c, k) = load(&["daemon.socket=\"/tmp/x.sock\"", "log.level=\"debug\""]);
        let e = decide(&keys, c, k, false).unwrap_err().to_string();
        assert_eq!(e, "daemon.socket needs a restart");
        let (c, k) = load(&["daemon.mqtt.commands=true"]);
        let e = decide(&keys, c, k, false).unwrap_err().to_string();
        assert_eq!(e, "daemon.mqtt needs a restart");

        let (c, k) = load(&[]);
        assert!(decide(&keys, c, k, true).unwrap().is_none());
    }
}
