//! Who holds the component's name in HAL: a small record in `daemon.state_dir`
//! (`hal-<component>.json`) written once the component is made, and removed only by a clean
//! stop of the daemon.
//!
//! HAL keeps a userspace component until its process leaves HAL (`hal_exit`). A process that
//! is killed never leaves: its component, pins and all, stays in HAL's shared memory, so
//! `waitusr` waits for ever and the name is refused to the next edmd ("is the name free?").
//! HAL records the owner's pid but offers no call to read it back, so edmd keeps its own
//! record: the component's id in HAL, and the process (its pid and start time, which a
//! reused pid does not share). With it,
//!
//! - a restarted edmd that finds the name taken by a dead owner removes the dead component
//!   and takes the name ([`super::open`]);
//! - `edmd hal-wait`, the service's last HAL command, waits for the owner to end and fails
//!   (so `halrun`, and systemd, see a failure) when the record outlives it: edmd did not stop
//!   cleanly ([`wait_for_end`]).

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::{Deserialize, Serialize};

/// The record of the process holding a component.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Owner {
    pub component: String,
    /// The component's id in HAL (`hal_init`'s answer).
    pub comp_id: i32,
    pub pid: u32,
    /// When the process started (clock ticks after boot): with the pid, one process for good.
    pub start_ticks: u64,
}

/// How often [`wait_for_end`] looks at the owner.
const POLL: Duration = Duration::from_millis(50);

impl Owner {
    /// This process, holding component `comp_id` named `component`.
    pub fn this_process(component: &str, comp_id: i32) -> Owner {
        Owner {
            component: component.to_string(),
            comp_id,
            pid: std::process::id(),
            start_ticks: crate::sys::own_start_ticks(),
        }
    }

    /// The owning process still runs (a zombie has ended: it only waits for its parent).
    pub fn alive(&self) -> bool {
        crate::sys::process_stat(self.pid)
            .is_some_and(|s| s.start_ticks == self.start_ticks && !s.ended())
    }

    /// The record at `path`; `None` when there is none or it does not read (a FIFO, a device
    /// or a torn file is no record: nothing is removed on its word).
    pub fn read(path: &Path) -> Option<Owner> {
        let text = crate::sys::read_regular(path).ok()?;
        serde_json::from_str(&text).ok()
    }

    /// Writes the record atomically.
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir)?;
        }
        let text = serde_json::to_vec_pretty(self).map_err(std::io::Error::other)?;
        crate::sys::write_atomic(path, &text)
    }
}

/// The record's path for component `component` under `state_dir`.
pub fn record_path(state_dir: &Path, component: &str) -> PathBuf {
    state_dir.join(format!("hal-{component}.json"))
}

/// A clean stop: the record goes, so `edmd hal-wait` ends with success.
pub fn remove_record(path: &Path) {
    match std::fs::remove_file(path) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => tracing::warn!(
            "{}: cannot remove the HAL owner record: {e}",
            path.display()
        ),
    }
}

/// How the owner of the record at `path` ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum End {
    /// It stopped cleanly (removed its record): or there was no record to wait on.
    Clean,
    /// It ended without a clean stop (killed, crashed, an error): its record is left.
    Unclean(Owner),
}

/// Waits until the owner recorded at `path` ends (its process gone, or a zombie), then says
/// how. A record that is not there at once is waited for up to `settle` (the service's HAL
/// file runs this right after `loadusr -W`, when edmd has written it).
pub fn wait_for_end(path: &Path, settle: Duration) -> End {
    let started = std::time::Instant::now();
    let owner = loop {
        match Owner::read(path) {
            Some(owner) => break owner,
            None if started.elapsed() >= settle => return End::Clean,
            None => std::thread::sleep(POLL),
        }
    };
    while owner.alive() {
        std::thread::sleep(POLL);
    }
    // A clean stop removes the record before the process ends.
    match Owner::read(path) {
        Some(left) if left == owner => End::Unclean(owner),
        _ => End::Clean,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_record_names_this_process_while_it_lives_and_a_stranger_is_dead() {
        let dir = std::env::temp_dir().join(format!("edmd-hal-owner-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let path = record_path(&dir, "edmd");
        assert_eq!(path.file_name().unwrap(), "hal-edmd.json");
        assert_eq!(Owner::read(&path), None);
        let me = Owner::this_process("edmd", 7);
        assert!(me.alive());
        me.write(&path).unwrap();
        assert_eq!(Owner::read(&path), Some(me.clone()));
        // The same pid started at another time is another process: dead to us.
        let reused = Owner {
            start_ticks: me.start_ticks + 1,
            ..me.clone()
        };
        assert!(!reused.alive());

        // A child that exits leaves its record behind: an unclean end, seen once it is gone.
        let mut child = std::process::Command::new("sleep")
            .arg("0.2")
            .spawn()
            .unwrap();
        let child_owner = Owner {
            component: "edmd".into(),
            comp_id: 9,
            pid: child.id(),
            start_ticks: crate::sys::process_stat(child.id()).unwrap().start_ticks,
        };
        child_owner.write(&path).unwrap();
        // The zombie (not yet reaped) already counts as ended.
        assert_eq!(
            wait_for_end(&path, Duration::ZERO),
            End::Unclean(child_owner.clone())
        );
        let _ = child.wait();
        remove_record(&path);
        assert_eq!(wait_for_end(&path, Duration::ZERO), End::Clean);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
