//! The machine: where it stands (machine coordinates, in steps), which axes are homed, its
//! work offsets and active system, whether its position is trusted and what tripped it, kept
//! in a state file ([`state`]); its soft limits ([`travel`]); and the decisions that follow
//! from them, as pure functions of the machine and the request ([`Machine::admit`]).
//!
//! **One write-ahead path** for the daemon and `edmd run --state`: [`Machine::open`] reads the
//! file (a state that says moving is distrusted: every axis unhomed) and writes back what is
//! now believed; [`Machine::save`] with `moving = true` before anything leaves a standstill;
//! [`Machine::stopped`] and [`Machine::standstill`] where motion ends.

pub mod state;
pub mod travel;

use std::path::{Path, PathBuf};

pub use state::{
    Loaded, MachineState, OffsetTable, StateError, default_path, offsets_from_table, offsets_table,
};

use crate::config::MachineConfig;
use crate::gcode::{StartModes, WorkOffsets, WorkSystem};
use crate::vocab::{Axis, LimitSwitch, Steps, Trip};

/// The machine's state with its file (none: nothing is kept, as `edmd run` without `--state`).
#[derive(Debug)]
pub struct Machine {
    pub state: MachineState,
    path: Option<PathBuf>,
    /// Why the last write of the state file failed; `None` once one succeeds.
    pub write_error: Option<String>,
    /// The units and distance mode the last MDI lines left (LinuxCNC's MDI keeps them).
    pub mdi_modes: StartModes,
    /// The axes still to home after the one homing now (indices, in order).
    pub homing_queue: Vec<usize>,
}

/// What [`Machine::open`] found in the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Found {
    /// No file (or no path): the machine at machine zero, unhomed.
    Nothing,
    /// A clean standstill: the position is exact.
    Standstill,
    /// The file said moving (the last writer was killed, the power cut): the position is only
    /// believed and every axis is unhomed.
    Moving,
}

/// A state file that could not be written.
#[derive(Debug, thiserror::Error)]
#[error("{}: cannot write the machine state: {source}", path.display())]
pub struct WriteError {
    pub path: PathBuf,
    #[source]
    pub source: std::io::Error,
}

/// What the operator asks of the machine, for [`Machine::admit`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Admission {
    /// Any motion; a jog names its axis and direction (the only motion a closed limit switch
    /// allows is a jog away from it).
    Motion { jog: Option<(Axis, bool)> },
    /// A program run, on a machine that may have to be homed first.
    Run { homing_required: bool },
    /// A cut continued where the machine is believed to stand (resume, run from a line).
    Continue { homing_required: bool },
}

/// Why the machine refuses an [`Admission`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Denial {
    EStop,
    Limit {
        switch: LimitSwitch,
    },
    /// Axes still to home (`"X, Y"`).
    Unhomed {
        axes: String,
    },
    /// The position is only believed after an unclean stop.
    Distrusted,
}

impl Machine {
    /// Reads the state at `path` for `config` (none: machine zero, unhomed, nothing kept), a
    /// moving one distrusted, and writes back what is now believed, so that a second crash
    /// finds the distrust and a file that cannot be written is known before any motion.
    pub fn open(
        path: Option<&Path>,
        config: &MachineConfig,
    ) -> Result<(Machine, Found), OpenError> {
        let loaded = match path {
            Some(p) => MachineState::load(p, config)?,
            None => None,
        };
        let (state, found) = match loaded {
            None => (MachineState::new(config), Found::Nothing),
            Some(l) if l.was_moving => (l.state.distrusted(), Found::Moving),
            Some(l) => (l.state, Found::Standstill),
        };
        let mut machine = Machine {
            state,
            path: path.map(Path::to_path_buf),
            write_error: None,
            mdi_modes: StartModes::default(),
            homing_queue: Vec::new(),
        };
        machine.save(false)?;
        Ok((machine, found))
    }

    /// Writes the state (nothing without a file); `moving` before motion leaves a standstill.
    pub fn save(&mut self, moving: bool) -> Result<(), WriteError> {
        let Some(path) = &self.path else {
            return Ok(());
        };
        match self.state.write(path, moving) {
            Ok(()) => {
                self.write_error = None;
                Ok(())
            }
            Err(source) => {
                let e = WriteError {
                    path: path.clone(),
                    source,
                };
                self.write_error = Some(e.to_string());
                Err(e)
            }
        }
    }

    /// Motion stopped at `position`; with `left` the work offsets and system a program that
    /// ran to its end left.
    pub fn stopped(
        &mut self,
        position: &Steps,
        left: Option<(WorkOffsets, WorkSystem)>,
    ) -> Result<(), WriteError> {
        self.state.position = *position;
        if let Some((offsets, system)) = left {
            self.state.offsets = offsets;
            self.state.system = system;
        }
        self.save(false)
    }

    /// A job holds at a standstill at `position`: the file says so.
    pub fn standstill(&mut self, position: &Steps) -> Result<(), WriteError> {
        self.state.position = *position;
        self.save(false)
    }

    /// Whether the machine allows `what`: a trip refuses motion (but a jog away from the
    /// closed switch), an unhomed machine refuses a run where homing is required, and a cut
    /// continued from a believed position is refused while distrusted.
    pub fn admit(&self, what: Admission) -> Result<(), Denial> {
        let state = &self.state;
        match what {
            Admission::Motion { jog } => match state.trip {
                None => Ok(()),
                Some(Trip::EStop) => Err(Denial::EStop),
                Some(Trip::Limit(switch)) => match jog {
                    Some((axis, positive))
                        if axis == switch.axis && positive != switch.positive =>
                    {
                        Ok(())
                    }
                    _ => Err(Denial::Limit { switch }),
                },
            },
            Admission::Run { homing_required } => match state.unhomed() {
                Some(axes) if homing_required => Err(Denial::Unhomed { axes }),
                _ => Ok(()),
            },
            Admission::Continue { homing_required } => match state.unhomed() {
                Some(axes) if homing_required => Err(Denial::Unhomed { axes }),
                _ if !state.position_trusted => Err(Denial::Distrusted),
                _ => Ok(()),
            },
        }
    }
}

/// A state file that could not be read, or not written back.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    #[error(transparent)]
    Read(#[from] StateError),
    #[error(transparent)]
    Write(#[from] WriteError),
}

/// A two-axis machine without soft limits, for the tests of the model and of its file.
#[cfg(test)]
fn xy_machine() -> MachineConfig {
    MachineConfig {
        axes: vec![Axis::X, Axis::Y],
        step_mm: vec![0.001, 0.0005],
        max_feed_mm_per_min: 1000.0,
        max_normal_accel_mm_per_s2: 1000.0,
        max_tangential_accel_mm_per_s2: 1000.0,
        max_jog_feed_mm_per_min: 600.0,
        dry_run_feed_mm_per_min: 600.0,
        max_jerk_mm_per_s3: 0.0,
        travel: vec![None, None],
        safe_z_mm: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_write_ahead_path_distrusts_a_state_left_moving() {
        let dir = std::env::temp_dir().join(format!("edmd-machine-model-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("state.json");
        let (mut m, found) = Machine::open(Some(&path), &xy_machine()).unwrap();
        assert_eq!(found, Found::Nothing);
        m.state.set_homed(0);
        m.state.set_homed(1);
        m.save(true).unwrap();
        let mut moved = m.state.position;
        moved[0] = 5_000;
        // Killed while moving: the next open believes the last position, distrusted.
        let (m2, found) = Machine::open(Some(&path), &xy_machine()).unwrap();
        assert_eq!(found, Found::Moving);
        assert!(!m2.state.position_trusted);
        assert_eq!(
            m2.admit(Admission::Continue {
                homing_required: false
            }),
            Err(Denial::Distrusted)
        );
        assert_eq!(
            m2.admit(Admission::Run {
                homing_required: true
            }),
            Err(Denial::Unhomed {
                axes: "X, Y".into()
            })
        );
        // The distrust was written back: a second open still distrusts.
        let (mut m3, found) = Machine::open(Some(&path), &xy_machine()).unwrap();
        assert_eq!(found, Found::Standstill);
        assert!(!m3.state.position_trusted);
        m3.stopped(&moved, None).unwrap();
        let (m4, _) = Machine::open(Some(&path), &xy_machine()).unwrap();
        assert_eq!(m4.state.position[0], 5_000);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_trip_refuses_motion_but_a_jog_away_from_the_switch() {
        let (mut m, _) = Machine::open(None, &xy_machine()).unwrap();
        assert_eq!(m.admit(Admission::Motion { jog: None }), Ok(()));
        m.state.trip = Some(Trip::EStop);
        assert_eq!(
            m.admit(Admission::Motion {
                jog: Some((Axis::X, false))
            }),
            Err(Denial::EStop)
        );
        let switch = LimitSwitch::parse("X+").unwrap();
        m.state.trip = Some(Trip::Limit(switch));
        assert_eq!(
            m.admit(Admission::Motion {
                jog: Some((Axis::X, false))
            }),
            Ok(())
        );
        assert_eq!(
            m.admit(Admission::Motion {
                jog: Some((Axis::X, true))
            }),
            Err(Denial::Limit { switch })
        );
        assert_eq!(
            m.admit(Admission::Motion { jog: None }),
            Err(Denial::Limit { switch })
        );
    }
}
