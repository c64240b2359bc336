//! Checkpoints: where a job stood, written atomically, so a restarted daemon resumes it
//! exactly.
//!
//! A checkpoint names the program (canonical path and SHA-256 of its bytes), the settings that
//! shape the path (a SHA-256 over `[machine]` and `[interpolation]`), and the electrode's
//! point on the program: source line, loop-buffer segment, Bresenham step within it, curve
//! parameter, and the pulse ledger in steps. Resuming replays the program through the same
//! producer, walks without emitting to that segment and step, checks the ledger there is the
//! checkpoint's, and carries on: every step before the point was emitted by the first run,
//! every step after it by the second, none twice.
//!
//! **Atomic write**: the JSON goes to `FILE.tmp`, is flushed to disk, renamed over `FILE` and
//! the directory is synced, so a power cut leaves either the old or the new checkpoint, never
//! a torn one; a write that fails removes its temporary file.
//!
//! **Still or moving**: checkpoints written at a standstill (hold, stop, abort, alarm, end of a
//! failed job) are exact. The periodic ones written while cutting lag the electrode by up to
//! a status period; after a crash the electrode is somewhere past them, so resuming from one
//! needs the operator's `--force`.
//!
//! **Write-ahead**: a standstill's checkpoint stays true only while the electrode stands, so
//! the daemon replaces it with a moving one ([`Reason::Moving`]), synced, *before* motion
//! leaves the standstill (a job's first step, a hold's release, a rethread), and does not
//! start the motion if that write fails. Whatever kills the daemon, the file on disk is either
//! exact (still) or says it is not (moving): a resume either continues from where the machine
//! is or asks for `--force`. A `G4` dwell stopped part-way keeps its remaining time
//! ([`Checkpoint::dwell_s`]).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::config::{Config, KeyValues};
use crate::runtime::Outcome;

/// Format version written into every checkpoint.
pub const VERSION: u32 = 1;

/// Why the checkpoint was written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Reason {
    /// The operator held the job (and it stands still).
    Hold,
    /// SIGTERM/SIGINT: a controlled stop.
    Stop,
    /// The operator aborted the job.
    Abort,
    /// Shorted after the whole reserved area.
    Alarm,
    /// The job ended on an error (device, gap input, producer).
    Error,
    /// Written while cutting, every `daemon.checkpoint_interval_s`.
    Periodic,
    /// Written just before motion left a standstill (a job's start, a hold's release, a
    /// rethread), replacing the standstill's checkpoint: the electrode is past it from then on.
    Moving,
}

impl Reason {
    /// Why a job that ended with `outcome` leaves a checkpoint, `None` for a job that leaves
    /// none (done, or a resume refused before anything moved). A stop is `asked` (an abort or
    /// a signal), a plain stop when nobody said which. The one mapping, for the daemon and
    /// `edmd run --checkpoint` alike.
    pub fn of_outcome(outcome: Outcome, asked: Option<Reason>) -> Option<Reason> {
        match outcome {
            Outcome::Done | Outcome::ResumeRefused => None,
            Outcome::Alarm
            | Outcome::Collision
            | Outcome::WireBreak
            | Outcome::Estop
            | Outcome::Limit => Some(Reason::Alarm),
            Outcome::Stopped => Some(asked.unwrap_or(Reason::Stop)),
            Outcome::OutputError
            | Outcome::GapError
            | Outcome::ProducerError
            | Outcome::ProbeMissed => Some(Reason::Error),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Reason::Hold => "hold",
            Reason::Stop => "stop",
            Reason::Abort => "abort",
            Reason::Alarm => "alarm",
            Reason::Error => "error",
            Reason::Periodic => "periodic",
            Reason::Moving => "moving",
        }
    }
}

/// The checkpoint file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Checkpoint {
    pub version: u32,
    /// Canonical path of the program.
    pub program: PathBuf,
    /// SHA-256 of the program's bytes (hex).
    pub program_sha256: String,
    /// SHA-256 of the settings that shape the path (hex): see [`motion_hash`].
    pub motion_sha256: String,
    /// Those settings as `section.key = value`, so a refusal can name what changed.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub motion_settings: KeyValues,
    pub reason: Reason,
    /// Written at a standstill: the electrode is exactly here.
    pub still: bool,
    /// Source line of the segment in hand.
    pub line: u64,
    /// Loop-buffer segment (0-based sequence number along the program).
    pub segment: u64,
    /// Bresenham step within the segment (0 = its start).
    pub step: i64,
    /// Steps of the segment.
    pub segment_steps: i64,
    /// Curve parameter at the end of the segment (NURBS blocks only).
    pub parameter: Option<f64>,
    /// Seconds of a `G4` dwell still owed at the point: the resumed job dwells them before
    /// it moves on (absent: none).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub dwell_s: f64,
    pub axes: Vec<String>,
    /// The pulse ledger (steps from the job's start), per axis.
    pub position_steps: Vec<i64>,
    pub position_mm: Vec<f64>,
    /// Seconds since the Unix epoch.
    pub written_unix_s: u64,
    /// Where the job started and in which work system, with which offsets: a resume replays
    /// the program from there. Absent (older checkpoints): machine zero, `G54`, no offsets.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub start: Option<StartRecord>,
    /// The job ran from a line: a resume replays the same approach (and never cuts it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub from_line: Option<crate::path::FromLine>,
    /// The job ran in passes: a resume replays the same ones, whatever the table says now.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub passes: Vec<crate::config::WirePass>,
    /// The tab those passes left (mm; 0: none).
    #[serde(default, skip_serializing_if = "no_tab")]
    pub tab_mm: f64,
    /// A run from a line that recovered a stopped job: where that job stopped (machine mm,
    /// per axis), so a resume replays the same approach along its kerf. Empty: none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub kerf_end_mm: Vec<f64>,
    /// The technology it was cut with (the request, `material=steel height=32 wire=0.25`):
    /// a resume selects it again, and is refused if the table no longer gives its passes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub technology: Option<String>,
}

/// [`Checkpoint::kerf_end_mm`] of a job that cuts `cut` on a machine of `axes` axes.
pub fn kerf_end_record(cut: &crate::path::CutPlan, axes: usize) -> Vec<f64> {
    cut.kerf_end
        .map(|p| p.iter().take(axes).copied().collect())
        .unwrap_or_default()
}

fn no_tab(tab_mm: &f64) -> bool {
    *tab_mm == 0.0
}

/// A job's start as a checkpoint keeps it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StartRecord {
    /// Machine position, steps per axis.
    pub position_steps: Vec<i64>,
    pub work_system: String,
    pub offsets_mm: crate::machine::OffsetTable,
}

impl StartRecord {
    pub fn new(
        start: &crate::gcode::WorkStart,
        axes: &[crate::vocab::Axis],
        step_mm: &[f64],
    ) -> Self {
        StartRecord {
            position_steps: crate::runtime::start_steps(start, step_mm)[..step_mm.len()].to_vec(),
            work_system: start.system.name().to_string(),
            offsets_mm: crate::machine::offsets_table(&start.offsets, axes),
        }
    }

    /// The start it records, for a machine with `axes` and `step_mm`.
    pub fn work_start(
        &self,
        axes: &[crate::vocab::Axis],
        step_mm: &[f64],
    ) -> Result<crate::gcode::WorkStart, String> {
        let mut start = crate::gcode::WorkStart {
            offsets: crate::machine::offsets_from_table(&self.offsets_mm, axes)?,
            system: crate::gcode::WorkSystem::parse(&self.work_system)
                .ok_or_else(|| format!("start.work_system {:?}", self.work_system))?,
            ..Default::default()
        };
        for (i, (s, mm)) in self.position_steps.iter().zip(step_mm).enumerate() {
            start.position_mm[i] = *s as f64 * mm;
        }
        Ok(start)
    }
}

/// What stops a checkpoint from being read or resumed.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    #[error("{path}: cannot read the checkpoint: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}:{line}:{col}: not a checkpoint: {message}")]
    Parse {
        path: PathBuf,
        line: usize,
        col: usize,
        message: String,
    },
    #[error("{path}: checkpoint format {found}, this edmd reads {VERSION}")]
    Version { path: PathBuf, found: u32 },
    #[error(
        "{program}: the program changed since the checkpoint (SHA-256 {found:.12}…, the \
         checkpoint has {expected:.12}…); refusing to resume a different program"
    )]
    ProgramChanged {
        program: PathBuf,
        expected: String,
        found: String,
    },
    #[error(
        "the [machine] or [interpolation] settings changed since the checkpoint ({changed}); \
         the path would not be the same, refusing to resume"
    )]
    MotionChanged { changed: String },
    #[error(
        "the checkpoint was written while cutting ({reason}), so the electrode may be past it; \
         check the position and resume with --force"
    )]
    Moving { reason: &'static str },
}

impl Checkpoint {
    /// [`Self::kerf_end_mm`] as a point, `None` where the job recovered none.
    pub fn kerf_end(&self) -> Option<crate::geometry::Point> {
        (!self.kerf_end_mm.is_empty()).then(|| {
            crate::geometry::Point::from_fn(|i, _| self.kerf_end_mm.get(i).copied().unwrap_or(0.0))
        })
    }

    /// Where the job stopped, as a point (machine mm).
    pub fn stopped_at(&self) -> crate::geometry::Point {
        crate::geometry::Point::from_fn(|i, _| self.position_mm.get(i).copied().unwrap_or(0.0))
    }

    /// Writes the checkpoint atomically (temporary file, fsync, rename, directory fsync).
    pub fn write_atomic(&self, path: &Path) -> std::io::Result<()> {
        let mut json = serde_json::to_string_pretty(self).map_err(std::io::Error::other)?;
        json.push('\n');
        // Bounded: a hung disk fails the write rather than stop the caller (the daemon's
        // control loop) for ever.
        crate::sys::write_atomic_bounded(path, json.as_bytes())
    }

    /// Removes a temporary file a write interrupted by a crash left beside `path`; `true`
    /// if there was one.
    pub fn remove_leftover(path: &Path) -> bool {
        std::fs::remove_file(crate::sys::temporary_path(path)).is_ok()
    }

    /// Reads the checkpoint at `path`; `None` when there is none.
    pub fn load(path: &Path) -> Result<Option<Checkpoint>, CheckpointError> {
        let text = match crate::sys::read_regular(path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(source) => {
                return Err(CheckpointError::Read {
                    path: path.to_path_buf(),
                    source,
                });
            }
        };
        let checkpoint: Checkpoint =
            serde_json::from_str(&text).map_err(|e| CheckpointError::Parse {
                path: path.to_path_buf(),
                line: e.line(),
                col: e.column(),
                message: e.to_string(),
            })?;
        if checkpoint.version != VERSION {
            return Err(CheckpointError::Version {
                path: path.to_path_buf(),
                found: checkpoint.version,
            });
        }
        Ok(Some(checkpoint))
    }

    /// Removes the checkpoint (the job it described is finished or replaced).
    pub fn remove(path: &Path) -> std::io::Result<()> {
        match std::fs::remove_file(path) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(e),
            _ => Ok(()),
        }
    }

    /// Checks a program's bytes (their SHA-256, `found`) are the checkpoint's.
    #[cfg(test)]
    fn check_program(&self, found: &str) -> Result<(), CheckpointError> {
        if found != self.program_sha256 {
            return Err(CheckpointError::ProgramChanged {
                program: self.program.clone(),
                expected: self.program_sha256.clone(),
                found: found.to_string(),
            });
        }
        Ok(())
    }

    /// Checks the settings are those of the checkpoint, and (without `force`) that it was
    /// written at a standstill. The program is checked where it is read
    /// (`check_program`).
    pub fn check_resumable(
        &self,
        config: &Config,
        keys: &KeyValues,
        force: bool,
    ) -> Result<(), CheckpointError> {
        if motion_hash(config) != self.motion_sha256 {
            return Err(CheckpointError::MotionChanged {
                changed: self.changed_settings(keys),
            });
        }
        if !self.still && !force {
            return Err(CheckpointError::Moving {
                reason: self.reason.name(),
            });
        }
        Ok(())
    }
}

/// The settings of `keys` that shape the path: `machine.*` and `interpolation.*`.
pub fn motion_settings(keys: &KeyValues) -> KeyValues {
    keys.iter()
        .filter(|(k, _)| {
            ["machine.", "interpolation.", "program.", "compensation."]
                .iter()
                .any(|s| k.starts_with(s))
        })
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect()
}

impl Checkpoint {
    /// `key: then -> now` for each path-shaping setting that differs from the checkpoint's.
    fn changed_settings(&self, keys: &KeyValues) -> String {
        if self.motion_settings.is_empty() {
            return "this checkpoint does not list them".to_string();
        }
        let now = motion_settings(keys);
        let names: std::collections::BTreeSet<&String> =
            self.motion_settings.keys().chain(now.keys()).collect();
        let changes: Vec<String> = names
            .into_iter()
            .filter_map(|k| {
                let (then, now) = (self.motion_settings.get(k), now.get(k));
                (then != now).then(|| {
                    let show = |v: Option<&String>| v.map_or("(unset)", |s| s.as_str()).to_string();
                    format!("{k}: {} -> {}", show(then), show(now))
                })
            })
            .collect();
        if changes.is_empty() {
            "no key differs; the defaults of this edmd do".to_string()
        } else {
            changes.join(", ")
        }
    }
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

fn hex(bytes: &[u8]) -> String {
    use std::fmt::Write;
    bytes.iter().fold(String::new(), |mut s, b| {
        let _ = write!(s, "{b:02x}");
        s
    })
}

pub use crate::runtime::program::sha256_file;

/// SHA-256 over the settings that decide the step path of a program: the machine (axes, step
/// sizes, limits) and the interpolation (tolerance, predictor, segmentation). The loop
/// buffer, the tick, the servo feeds and the outputs change when things happen, never where.
pub fn motion_hash(config: &Config) -> String {
    let mut text = format!("{:?}\n{:?}", config.machine, config.interpolation);
    // `[program]` shapes the path too (block delete); hashed only when it differs from the
    // default, so checkpoints written before the section existed still resume.
    let default_program = crate::config::ProgramConfig {
        block_delete: false,
        optional_stop: false,
        max_loop_iterations: 1_000_000,
        mcodes: Vec::new(),
    };
    if config.program != default_program {
        text.push_str(&format!("\n{:?}", config.program));
    }
    if config.compensation.d_mm != [0.0] {
        text.push_str(&format!("\n{:?}", config.compensation));
    }
    hex(&Sha256::digest(text.as_bytes()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(program: PathBuf, config: &Config) -> Checkpoint {
        Checkpoint {
            version: VERSION,
            program_sha256: sha256_file(&program).unwrap(),
            program,
            motion_sha256: motion_hash(config),
            motion_settings: KeyValues::new(),
            reason: Reason::Stop,
            still: true,
            line: 12,
            segment: 40,
            step: 3,
            segment_steps: 9,
            parameter: Some(0.25),
            dwell_s: 1.25,
            axes: vec!["X".into(), "Y".into()],
            position_steps: vec![100, -7],
            position_mm: vec![0.1, -0.007],
            written_unix_s: 1,
            start: None,
            from_line: None,
            passes: Vec::new(),
            tab_mm: 0.0,
            kerf_end_mm: Vec::new(),
            technology: None,
        }
    }

    fn scratch(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("edmd-checkpoint-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn round_trip_and_resumable_checks() {
        let dir = scratch("trip");
        let program = dir.join("p.nc");
        std::fs::write(&program, "G1 X1 F60\n").unwrap();
        let config = Config::default();
        let cp = sample(program.clone(), &config);
        let path = dir.join("checkpoint.json");
        cp.write_atomic(&path).unwrap();
        assert!(!dir.join("checkpoint.json.tmp").exists());
        let back = Checkpoint::load(&path).unwrap().unwrap();
        assert_eq!(back, cp);
        back.check_resumable(&config, &KeyValues::new(), false)
            .unwrap();

        // A different tolerance gives a different path.
        let mut other = config.clone();
        other.interpolation.chord_tolerance_mm *= 2.0;
        assert!(matches!(
            back.check_resumable(&other, &KeyValues::new(), false),
            Err(CheckpointError::MotionChanged { .. })
        ));
        // A servo feed does not.
        let mut feeds = config.clone();
        feeds.servo.normal_feed_mm_per_min *= 2.0;
        back.check_resumable(&feeds, &KeyValues::new(), false)
            .unwrap();

        back.check_program(&sha256_file(&program).unwrap()).unwrap();
        std::fs::write(&program, "G1 X2 F60\n").unwrap();
        let err = back
            .check_program(&sha256_file(&program).unwrap())
            .unwrap_err();
        assert!(
            err.to_string().contains("changed since the checkpoint"),
            "{err}"
        );

        Checkpoint::remove(&path).unwrap();
        assert!(Checkpoint::load(&path).unwrap().is_none());
        Checkpoint::remove(&path).unwrap();
    }

    #[test]
    fn a_refusal_names_the_settings_that_changed() {
        let (config, keys) = Config::load_with_keys(None, &[]).unwrap();
        let dir = scratch("named");
        let program = dir.join("p.nc");
        std::fs::write(&program, "G1 X1 F60\n").unwrap();
        let mut cp = sample(program, &config);
        cp.motion_settings = motion_settings(&keys);
        assert!(
            cp.motion_settings
                .contains_key("interpolation.chord_tolerance_mm")
        );
        assert!(!cp.motion_settings.keys().any(|k| k.starts_with("servo.")));
        let set = ["interpolation.chord_tolerance_mm=0.002".to_string()];
        let (other, other_keys) = Config::load_with_keys(None, &set).unwrap();
        let err = cp.check_resumable(&other, &other_keys, false).unwrap_err();
        assert!(
            err.to_string()
                .contains("(interpolation.chord_tolerance_mm: 0.001 -> 0.002)"),
            "{err}"
        );
    }

    /// A full disk (the temporary file is `/dev/full`, through a symlink): the write fails
    /// with the kernel's ENOSPC, the old checkpoint stays, no temporary file is left.
    #[test]
    fn a_write_on_a_full_disk_fails_cleanly() {
        let dir = scratch("full");
        let program = dir.join("p.nc");
        std::fs::write(&program, "G1 X1 F60\n").unwrap();
        let config = Config::default();
        let path = dir.join("checkpoint.json");
        let old = sample(program.clone(), &config);
        old.write_atomic(&path).unwrap();
        let tmp = dir.join("checkpoint.json.tmp");
        std::os::unix::fs::symlink("/dev/full", &tmp).unwrap();
        let mut new = old.clone();
        new.still = false;
        new.reason = Reason::Moving;
        let err = new.write_atomic(&path).unwrap_err();
        assert_eq!(err.raw_os_error(), Some(libc::ENOSPC), "{err}");
        assert!(
            std::fs::symlink_metadata(&tmp).is_err(),
            "the temporary file is gone"
        );
        assert_eq!(Checkpoint::load(&path).unwrap().unwrap(), old);
        // A leftover of a crash mid-write is found and removed at startup.
        std::fs::write(&tmp, "").unwrap();
        assert!(Checkpoint::remove_leftover(&path));
        assert!(!Checkpoint::remove_leftover(&path));
    }

    #[test]
    fn a_moving_checkpoint_needs_force_and_a_bad_file_is_located() {
        let dir = scratch("moving");
        let program = dir.join("p.nc");
        std::fs::write(&program, "G1 X1 F60\n").unwrap();
        let config = Config::default();
        let mut cp = sample(program, &config);
        cp.still = false;
        cp.reason = Reason::Periodic;
        assert!(matches!(
            cp.check_resumable(&config, &KeyValues::new(), false),
            Err(CheckpointError::Moving { .. })
        ));
        cp.check_resumable(&config, &KeyValues::new(), true)
            .unwrap();

        let path = dir.join("bad.json");
        std::fs::write(&path, "{\n  \"version\": 1,\n  \"nonsense\": true\n}\n").unwrap();
        let err = Checkpoint::load(&path).unwrap_err().to_string();
        assert!(err.contains("bad.json:3:"), "{err}");
    }
}
