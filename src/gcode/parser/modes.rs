//! The interpreter's modal groups: what a block leaves in force for the next (units, distance
//! mode, arc centres, plane, motion, feed, taper) and the wire offset's progress through its
//! entry, its moves and its exit.

use super::codes::Motion;
use crate::gcode::{Plane, WireOffset};

/// The modal groups in force (LinuxCNC's `setup` fields of the same names).
#[derive(Debug, Clone)]
pub(super) struct Modal {
    pub(super) inch: bool,
    pub(super) incremental: bool,
    pub(super) arc_centre_absolute: bool,
    pub(super) plane: Plane,
    pub(super) motion: Option<Motion>,
    /// mm/min
    pub(super) feed: Option<f64>,
    /// The wire's tilt (`G51`/`G52`): the tangent of its angle from vertical, + to the left
    /// of the direction of travel; 0: vertical (`G50`).
    pub(super) taper: f64,
    /// `G41`/`G42`/`G40`.
    pub(super) wire_offset: WireOffsetMode,
}

/// The wire offset as the program set it (`G41`/`G42`, `G40`) and where its moves stand. The
/// reader refuses what cannot happen under it (changing offsets, probing, a second `G41`);
/// every move carries the offset it is cut with ([`crate::gcode::Block::wire_offset`]) and
/// the path's wire-offset stage does the geometry.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(super) enum WireOffsetMode {
    #[default]
    Off,
    /// `G41`/`G42` given: the next move is the entry.
    Entry(WireOffset),
    On(WireOffset),
    /// `G40` given while on: the next move is the exit.
    Exit,
}

impl WireOffsetMode {
    /// The offset is on, or about to be, or its exit move is still to come.
    pub(super) fn engaged(self) -> bool {
        self != WireOffsetMode::Off
    }

    /// `G41` (`left`) or `G42` with offset `d_mm`, in `plane`, on a machine that has X and Y
    /// (`has_xy`). Errors are messages for the G word.
    pub(super) fn start(
        &mut self,
        left: bool,
        d_mm: f64,
        plane: Plane,
        has_xy: bool,
    ) -> Result<(), String> {
        if plane != Plane::XY {
            return Err("the wire offset works in the XY plane (G17) only".into());
        }
        if !has_xy {
            return Err("the wire offset needs axes X and Y on the machine".into());
        }
        if matches!(self, WireOffsetMode::On(_) | WireOffsetMode::Exit) {
            return Err("the wire offset is already on: cancel it with G40 first".into());
        }
        *self = if d_mm == 0.0 {
            WireOffsetMode::Off
        } else {
            WireOffsetMode::Entry(WireOffset { left, d_mm })
        };
        Ok(())
    }

    /// `G40`.
    pub(super) fn cancel(&mut self) {
        *self = match *self {
            WireOffsetMode::Off | WireOffsetMode::Entry(_) => WireOffsetMode::Off,
            WireOffsetMode::On(_) | WireOffsetMode::Exit => WireOffsetMode::Exit,
        };
    }

    /// A move was read: the offset it is cut with; the entry and the exit move the mode on.
    pub(super) fn stamp_move(&mut self) -> Option<WireOffset> {
        match *self {
            WireOffsetMode::Off => None,
            WireOffsetMode::Entry(w) | WireOffsetMode::On(w) => {
                *self = WireOffsetMode::On(w);
                Some(w)
            }
            WireOffsetMode::Exit => {
                *self = WireOffsetMode::Off;
                None
            }
        }
    }
}
