//! What a machine knows about itself between runs: where it stands (machine coordinates, in
//! steps), which axes are homed, the work offset table and the active work system, kept in a
//! state file.
//!
//! **Write-ahead**, as for checkpoints: before anything leaves a standstill the file is
//! rewritten with `moving = true` (synced), and when motion stops it is rewritten with the
//! position where it stopped and `moving = false`. A state read back at a standstill is exact;
//! one that says it was moving (the daemon was killed, the power cut) has a position that is
//! only believed, so every axis is unhomed ([`MachineState::distrusted`]).
//!
//! The file names its axes and step sizes, so a state written for another machine
//! configuration is refused rather than misread.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::config::MachineConfig;
use crate::gcode::{WorkOffsets, WorkStart, WorkSystem};
use crate::geometry::Point;
use crate::vocab::{Axis, MAX_AXES, Steps, Trip};

/// Format version written into every state file.
pub const VERSION: u32 = 1;

/// The machine's own state.
#[derive(Debug, Clone, PartialEq)]
pub struct MachineState {
    pub axes: Vec<Axis>,
    pub step_mm: Vec<f64>,
    /// Machine position, steps per axis (machine order).
    pub position: Steps,
    pub homed: Vec<bool>,
    pub offsets: WorkOffsets,
    pub system: WorkSystem,
    /// `false` after an unclean stop (the file said moving): the position is only believed
    /// until every axis is homed again. A resume or a run from a line is refused meanwhile
    /// (unless forced): it would cut from wherever the machine really stands.
    pub position_trusted: bool,
    /// An E-stop or a limit switch stopped the machine and holds it: kept in the file, so a
    /// restart does not forget it.
    pub trip: Option<Trip>,
}

/// A state file that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum StateError {
    #[error("cannot read the machine state {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: not a machine state file: {message}")]
    Parse { path: PathBuf, message: String },
    #[error(
        "{path}: written for axes {found} with steps {found_steps} mm; this machine has {axes} \
         with {steps} mm (move the file away to start from machine zero, unhomed)"
    )]
    OtherMachine {
        path: PathBuf,
        found: String,
        found_steps: String,
        axes: String,
        steps: String,
    },
}

/// The file's JSON form: offsets by system name and axis letter, so it reads as a table.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct StateFile {
    version: u32,
    /// `true`: motion had left a standstill when this was written.
    moving: bool,
    axes: Vec<String>,
    step_mm: Vec<f64>,
    position_steps: Vec<i64>,
    homed: Vec<bool>,
    work_system: String,
    offsets_mm: BTreeMap<String, BTreeMap<String, f64>>,
    /// Absent in files of older edmds: trusted (their `moving` still distrusts).
    #[serde(default = "yes")]
    position_trusted: bool,
    /// `estop`, a limit switch (`X+`), or absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    tripped: Option<String>,
}

fn yes() -> bool {
    true
}

/// What a state file held, and whether it can be trusted.
#[derive(Debug, Clone, PartialEq)]
pub struct Loaded {
    pub state: MachineState,
    /// The file said the machine was moving: the position is only believed.
    pub was_moving: bool,
}

impl MachineState {
    /// At machine zero, unhomed, all offsets zero, in `G54`.
    pub fn new(machine: &MachineConfig) -> MachineState {
        MachineState {
            axes: machine.axes.clone(),
            step_mm: machine.step_mm.clone(),
            position: [0; MAX_AXES],
            homed: vec![false; machine.axes.len()],
            offsets: WorkOffsets::default(),
            system: WorkSystem::G54,
            position_trusted: true,
            trip: None,
        }
    }

    /// Machine position, mm.
    pub fn position_mm(&self) -> Point {
        let mut p = Point::zeros();
        for (i, mm) in self.step_mm.iter().enumerate() {
            p[i] = self.position[i] as f64 * mm;
        }
        p
    }

    /// Where a program starts from here.
    pub fn work_start(&self) -> WorkStart {
        WorkStart {
            position_mm: self.position_mm(),
            offsets: self.offsets.clone(),
            system: self.system,
            modes: Default::default(),
            unhomed: !self.all_homed(),
        }
    }

    /// Position in the active work system (no `G92`: that lives in a program), mm.
    pub fn position_work_mm(&self) -> Point {
        self.work_start().to_work(&self.position_mm())
    }

    /// Every axis is homed.
    fn all_homed(&self) -> bool {
        self.homed.iter().all(|&h| h)
    }

    /// The letters of the axes not homed (`"X, Y"`), or `None`.
    pub fn unhomed(&self) -> Option<String> {
        let names: Vec<String> = self
            .axes
            .iter()
            .zip(&self.homed)
            .filter(|(_, h)| !**h)
            .map(|(a, _)| a.letter().to_string())
            .collect();
        (!names.is_empty()).then(|| names.join(", "))
    }

    /// After an unclean stop: the position is kept as believed, but no axis is homed and
    /// the position is not trusted until they are.
    pub fn distrusted(mut self) -> MachineState {
        self.homed.iter_mut().for_each(|h| *h = false);
        self.position_trusted = false;
        self
    }

    /// Axis `i` is homed; once every axis is, the position is trusted again.
    pub fn set_homed(&mut self, i: usize) {
        if let Some(h) = self.homed.get_mut(i) {
            *h = true;
        }
        if self.all_homed() {
            self.position_trusted = true;
        }
    }

    /// Writes the state to `path` atomically; `moving` marks it as not a standstill.
    pub fn write(&self, path: &Path, moving: bool) -> std::io::Result<()> {
        let offsets_mm = offsets_table(&self.offsets, &self.axes);
        let file = StateFile {
            version: VERSION,
            moving,
            axes: self.axes.iter().map(|a| a.letter().to_string()).collect(),
            step_mm: self.step_mm.clone(),
            position_steps: self.position[..self.axes.len()].to_vec(),
            homed: self.homed.clone(),
            work_system: self.system.name().to_string(),
            offsets_mm,
            position_trusted: self.position_trusted,
            tripped: self.trip.map(Trip::name),
        };
        let mut json = serde_json::to_string_pretty(&file).map_err(std::io::Error::other)?;
        json.push('\n');
        // Bounded: a hung disk fails the write rather than stop the caller (the daemon's
        // control loop) for ever.
        crate::sys::write_atomic_bounded(path, json.as_bytes())
    }

    /// Reads the state at `path` for `machine`; `None` when there is no file.
    pub fn load(path: &Path, machine: &MachineConfig) -> Result<Option<Loaded>, StateError> {
        let text = match crate::sys::read_regular(path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(source) => {
                return Err(StateError::Read {
                    path: path.to_path_buf(),
                    source,
                });
            }
        };
        let parse = |message: String| StateError::Parse {
            path: path.to_path_buf(),
            message,
        };
        let file: StateFile = serde_json::from_str(&text).map_err(|e| parse(e.to_string()))?;
        if file.version != VERSION {
            return Err(parse(format!(
                "version {} (this edmd reads {VERSION})",
                file.version
            )));
        }
        let axes: Vec<String> = machine
            .axes
            .iter()
            .map(|a| a.letter().to_string())
            .collect();
        if file.axes != axes || file.step_mm != machine.step_mm {
            return Err(StateError::OtherMachine {
                path: path.to_path_buf(),
                found: file.axes.join(","),
                found_steps: format!("{:?}", file.step_mm),
                axes: axes.join(","),
                steps: format!("{:?}", machine.step_mm),
            });
        }
        let n = axes.len();
        if file.position_steps.len() != n || file.homed.len() != n {
            return Err(parse(format!(
                "position_steps and homed need {n} values, one per axis"
            )));
        }
        let system = WorkSystem::parse(&file.work_system).ok_or_else(|| {
            parse(format!(
                "work_system {:?} is not G54…G59.3",
                file.work_system
            ))
        })?;
        let offsets = offsets_from_table(&file.offsets_mm, &machine.axes).map_err(parse)?;
        let trip = match &file.tripped {
            None => None,
            Some(text) => Some(Trip::parse(text).ok_or_else(|| {
                parse(format!(
                    "tripped {text:?} is not \"estop\" or a limit switch (\"X+\")"
                ))
            })?),
        };
        if let Some(Trip::Limit(switch)) = trip
            && !machine.axes.contains(&switch.axis)
        {
            return Err(parse(format!(
                "tripped {:?}: axis {} is not on this machine",
                switch.to_string(),
                switch.axis
            )));
        }
        let mut position = [0; MAX_AXES];
        position[..n].copy_from_slice(&file.position_steps);
        Ok(Some(Loaded {
            state: MachineState {
                axes: machine.axes.clone(),
                step_mm: machine.step_mm.clone(),
                position,
                homed: file.homed,
                offsets,
                system,
                position_trusted: file.position_trusted,
                trip,
            },
            was_moving: file.moving,
        }))
    }

    /// The offset table as text, one system per line (`G55  X10.0000 Y-2.5000`), the active
    /// one marked.
    pub fn offsets_text(&self) -> String {
        WorkSystem::all()
            .map(|s| {
                let o = self.offsets.get(s);
                let values: Vec<String> = self
                    .axes
                    .iter()
                    .enumerate()
                    .map(|(i, a)| format!("{}{:.4}", a.letter(), o[i]))
                    .collect();
                format!(
                    "{}{:<6} {}",
                    if s == self.system { "*" } else { " " },
                    s.name(),
                    values.join(" ")
                )
            })
            .collect::<Vec<_>>()
            .join("\n")
    }
}

/// A work offset table as files keep it: by system name, then axis letter, mm.
pub type OffsetTable = BTreeMap<String, BTreeMap<String, f64>>;

/// `offsets` as a file keeps them (every system, every axis of `axes`).
pub fn offsets_table(offsets: &WorkOffsets, axes: &[Axis]) -> OffsetTable {
    WorkSystem::all()
        .map(|s| {
            let o = offsets.get(s);
            let by_axis = axes
                .iter()
                .enumerate()
                .map(|(i, a)| (a.letter().to_string(), o[i]))
                .collect();
            (s.name().to_string(), by_axis)
        })
        .collect()
}

/// The offsets a file keeps, for a machine with `axes`; systems or axes not named are 0.
pub fn offsets_from_table(table: &OffsetTable, axes: &[Axis]) -> Result<WorkOffsets, String> {
    let mut offsets = WorkOffsets::default();
    for (name, by_axis) in table {
        let s = WorkSystem::parse(name)
            .ok_or_else(|| format!("offsets_mm: {name:?} is not G54…G59.3"))?;
        let mut o = Point::zeros();
        for (letter, &mm) in by_axis {
            let i = axes
                .iter()
                .position(|a| a.letter().to_string() == *letter)
                .ok_or_else(|| format!("offsets_mm.{name}: no axis {letter} on this machine"))?;
            if !mm.is_finite() {
                return Err(format!("offsets_mm.{name}.{letter} is not a number"));
            }
            o[i] = mm;
        }
        offsets.set(s, o);
    }
    Ok(offsets)
}

/// Where the state file goes by default: beside the checkpoint, named `machine-state.json`.
pub fn default_path(checkpoint: &Path) -> PathBuf {
    checkpoint
        .parent()
        .unwrap_or(Path::new("."))
        .join("machine-state.json")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_state_survives_the_file_and_a_moving_one_is_marked() {
        let dir = std::env::temp_dir().join(format!("edmd-machine-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("state.json");
        let m = super::super::xy_machine();
        assert_eq!(MachineState::load(&path, &m).unwrap(), None);
        let mut state = MachineState::new(&m);
        state.position[0] = 12_345;
        state.position[1] = -7;
        state.homed = vec![true, false];
        let mut o = Point::zeros();
        o[0] = 10.5;
        o[1] = -2.25;
        state.offsets.set(WorkSystem::parse("G59.3").unwrap(), o);
        state.system = WorkSystem::parse("G56").unwrap();
        state.write(&path, false).unwrap();
        let back = MachineState::load(&path, &m).unwrap().unwrap();
        assert_eq!(back.state, state);
        assert!(!back.was_moving);
        assert!((back.state.position_mm()[1] + 0.0035).abs() < 1e-12);
        state.write(&path, true).unwrap();
        let back = MachineState::load(&path, &m).unwrap().unwrap();
        assert!(back.was_moving);
        let distrusted = back.state.clone().distrusted();
        assert_eq!(distrusted.unhomed().as_deref(), Some("X, Y"));
        assert!(!distrusted.position_trusted);
        // The distrust and a trip survive the file; homing every axis ends the distrust.
        let mut kept = distrusted.clone();
        kept.trip = Some(Trip::Limit(crate::vocab::LimitSwitch::parse("Y-").unwrap()));
        kept.write(&path, false).unwrap();
        let back = MachineState::load(&path, &m).unwrap().unwrap();
        assert_eq!(back.state, kept);
        kept.set_homed(0);
        assert!(!kept.position_trusted, "one axis of two");
        kept.set_homed(1);
        assert!(kept.position_trusted);
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains("\"tripped\": \"Y-\""), "{text}");
        std::fs::write(&path, text.replace("\"Y-\"", "\"Z+\"")).unwrap();
        let e = MachineState::load(&path, &m).unwrap_err().to_string();
        assert!(e.contains("axis Z is not on this machine"), "{e}");
        assert!(state.offsets_text().contains("*G56"));

        let mut other = m.clone();
        other.step_mm = vec![0.001, 0.001];
        let e = MachineState::load(&path, &other).unwrap_err().to_string();
        assert!(e.contains("written for axes X,Y"), "{e}");
        std::fs::write(&path, "{\"version\": 1}").unwrap();
        let e = MachineState::load(&path, &m).unwrap_err().to_string();
        assert!(e.contains("not a machine state file"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
