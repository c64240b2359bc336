//! The layers of text under a configuration: the shipped default table, the user's file
//! overlaid on it key by key, then the `--set section.key=value` overrides, in order. Each
//! key's origin (`file:line:col` or the `--set` argument) is recorded on the way, so every
//! later error can say where its value came from.

use std::collections::HashMap;

use super::{ConfigError, DEFAULT_CONFIG_TOML};

#[derive(Default)]
pub(super) struct Origins {
    /// `section.key` (and `section`) to `line:col` in the user's file.
    file: HashMap<String, (usize, usize)>,
    /// `section.key` to the `--set` argument that last set it.
    overrides: HashMap<String, String>,
}

impl Origins {
    /// Where the value at `key` came from, for an error message. A path deeper than
    /// `section.key` (an array element) is traced back to its key.
    pub(super) fn describe(&self, key: &str, source: &str) -> String {
        let mut candidate = key.to_string();
        loop {
            if let Some(arg) = self.overrides.get(&candidate) {
                return format!("--set {arg}");
            }
            if let Some((line, col)) = self.file.get(&candidate) {
                return format!("{source}:{line}:{col}");
            }
            match candidate.rfind(['.', '[']) {
                Some(cut) => candidate.truncate(cut),
                None => return source.to_string(),
            }
        }
    }
}

/// 1-based line and column (in characters) of byte `offset` in `text`.
pub(super) fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..text.floor_char_boundary(offset)];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    (line, before[line_start..].chars().count() + 1)
}

pub(super) fn default_table() -> toml::Table {
    toml::from_str(DEFAULT_CONFIG_TOML).expect("the shipped default configuration parses")
}

/// Parses the user's text, records where each key stands, and returns it as a table.
pub(super) fn parse_user_table(
    text: &str,
    source: &str,
    origins: &mut Origins,
) -> Result<toml::Table, ConfigError> {
    let at = |offset: usize, message: &str| {
        let (line, col) = line_col(text, offset);
        ConfigError::Invalid {
            origin: format!("{source}:{line}:{col}"),
            message: message.to_string(),
        }
    };
    let spanned = toml::de::DeTable::parse(text)
        .map_err(|e| at(e.span().map_or(0, |s| s.start), e.message()))?;
    for (section, value) in spanned.get_ref() {
        let name = section.get_ref().to_string();
        origins
            .file
            .insert(name.clone(), line_col(text, section.span().start));
        if let Some(table) = value.get_ref().as_table() {
            for (key, inner) in table {
                let path = format!("{name}.{}", key.get_ref());
                // A table inside the section (`[daemon.mqtt]`, `[sinker.orbit]`): its keys.
                if let Some(inner) = inner.get_ref().as_table() {
                    for (sub, _) in inner {
                        origins.file.insert(
                            format!("{path}.{}", sub.get_ref()),
                            line_col(text, sub.span().start),
                        );
                    }
                }
                origins.file.insert(path, line_col(text, key.span().start));
            }
        }
    }
    toml::from_str(text).map_err(|e| at(e.span().map_or(0, |s| s.start), e.message()))
}

/// Puts the user's keys over the defaults; a section or key the default lacks is an error.
pub(super) fn overlay(
    merged: &mut toml::Table,
    user: toml::Table,
    source: &str,
    origins: &Origins,
) -> Result<(), ConfigError> {
    for (section, value) in user {
        let origin = origins.describe(&section, source);
        let Some(toml::Value::Table(defaults)) = merged.get_mut(&section) else {
            return Err(ConfigError::Invalid {
                origin,
                message: format!(
                    "unknown section [{section}]; the sections are {}",
                    section_names()
                ),
            });
        };
        let toml::Value::Table(keys) = value else {
            return Err(ConfigError::Invalid {
                origin,
                message: format!("{section} must be a table ([{section}])"),
            });
        };
        for (key, value) in keys {
            if !known(&section, &key, defaults) {
                return Err(ConfigError::Invalid {
                    origin: origins.describe(&format!("{section}.{key}"), source),
                    message: unknown_key_message(&section, &key, defaults),
                });
            }
            // A table of fixed keys (`[sinker.orbit]`) is overlaid key by key too; a free
            // map (empty by default: `sim.home_switch_mm`; or keyed by axis letter,
            // `machine.travel_mm`, whatever axes the default names) is replaced whole.
            if let (Some(toml::Value::Table(inner)), toml::Value::Table(user_inner)) =
                (defaults.get_mut(&key), &value)
                && !inner.is_empty()
                && !FREE_MAPS.contains(&(section.as_str(), key.as_str()))
            {
                let path = format!("{section}.{key}");
                for (sub, v) in user_inner {
                    if !inner.contains_key(sub) {
                        return Err(ConfigError::Invalid {
                            origin: origins.describe(&format!("{path}.{sub}"), source),
                            message: unknown_key_message(&path, sub, inner),
                        });
                    }
                    inner.insert(sub.clone(), v.clone());
                }
                continue;
            }
            defaults.insert(key, value);
        }
    }
    Ok(())
}

fn section_names() -> String {
    default_table()
        .keys()
        .map(|k| format!("[{k}]"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Keys with no default value (TOML has no null): absent from the shipped file, which
/// describes them in a comment, and still known.
const OPTIONAL_KEYS: &[(&str, &str)] = &[("machine", "safe_z_mm")];

/// Tables keyed by the user's own names (axis letters) that have a default: a file's table
/// replaces the default whole, as the shipped file says, rather than key by key.
const FREE_MAPS: &[(&str, &str)] = &[("machine", "travel_mm")];

fn known(section: &str, key: &str, defaults: &toml::Table) -> bool {
    defaults.contains_key(key) || OPTIONAL_KEYS.contains(&(section, key))
}

fn unknown_key_message(section: &str, key: &str, known: &toml::Table) -> String {
    let mut names: Vec<&str> = known.keys().map(String::as_str).collect();
    names.extend(
        OPTIONAL_KEYS
            .iter()
            .filter(|(s, _)| *s == section)
            .map(|(_, k)| *k),
    );
    names.sort_unstable();
    format!(
        "unknown key `{key}` in [{section}]; the keys are {}",
        names.join(", ")
    )
}

/// Applies one `section.key=value` override.
pub(super) fn apply_override(
    merged: &mut toml::Table,
    arg: &str,
    origins: &mut Origins,
) -> Result<(), ConfigError> {
    let fail = |message: String| ConfigError::Invalid {
        origin: format!("--set {arg}"),
        message,
    };
    let (path, value_text) = arg
        .split_once('=')
        .ok_or_else(|| fail("expected section.key=value".to_string()))?;
    let path = path.trim();
    let (section, key) = path
        .split_once('.')
        .ok_or_else(|| fail(format!("`{path}` is not of the form section.key")))?;
    let Some(toml::Value::Table(keys)) = merged.get_mut(section) else {
        return Err(fail(format!(
            "unknown section [{section}]; the sections are {}",
            section_names()
        )));
    };
    let value = parse_override_value(value_text.trim())
        .ok_or_else(|| fail(format!("`{value_text}` is not a TOML value")))?;
    // `section.table.key` sets one key of a table of fixed keys (`sinker.orbit.shape`).
    if let Some((table, sub)) = key.split_once('.') {
        let inner = match keys.get_mut(table) {
            Some(toml::Value::Table(inner)) if !inner.is_empty() => inner,
            _ => return Err(fail(unknown_key_message(section, key, keys))),
        };
        if !inner.contains_key(sub) {
            return Err(fail(unknown_key_message(
                &format!("{section}.{table}"),
                sub,
                inner,
            )));
        }
        inner.insert(sub.to_string(), value);
        origins.overrides.insert(path.to_string(), arg.to_string());
        return Ok(());
    }
    if !known(section, key, keys) {
        return Err(fail(unknown_key_message(section, key, keys)));
    }
    keys.insert(key.to_string(), value);
    origins.overrides.insert(path.to_string(), arg.to_string());
    Ok(())
}

/// A TOML value, or a bare word taken as a string (`--set output.kind=file`).
fn parse_override_value(text: &str) -> Option<toml::Value> {
    if let Ok(mut table) = toml::from_str::<toml::Table>(&format!("v = {text}")) {
        return table.remove("v");
    }
    let bare = !text.is_empty()
        && text
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "_./:+-@".contains(c));
    bare.then(|| toml::Value::String(text.to_string()))
}
