//! What `M70`–`M73` save of the modal state, and what a line's save codes carry from before
//! its G codes to after its F (the reader's `modal_state_first` and `modal_state_last`).

use super::super::Letters;

/// The modal state `M70` saves and `M72` restores (LinuxCNC's list, as far as edmd has the
/// modes): units, distance modes, plane, feed, flushing, the condition, the retract mode,
/// the work system, whether the `G92` offset is applied and whether the wire offset is off.
#[derive(Debug, Clone)]
pub(in crate::gcode::parser) struct SavedModes {
    pub(in crate::gcode::parser) g92_applied: bool,
    /// The wire offset was off (`G40`): `M72` ends one begun since.
    pub(in crate::gcode::parser) offset_off: bool,
    pub(in crate::gcode::parser) inch: bool,
    pub(in crate::gcode::parser) incremental: bool,
    pub(in crate::gcode::parser) arc_centre_absolute: bool,
    pub(in crate::gcode::parser) plane: crate::gcode::Plane,
    pub(in crate::gcode::parser) feed: Option<f64>,
    pub(in crate::gcode::parser) flushing: bool,
    pub(in crate::gcode::parser) condition: u32,
    pub(in crate::gcode::parser) retract_to_initial: bool,
    pub(in crate::gcode::parser) system: crate::gcode::work::WorkSystem,
}

/// A line's `M70`–`M73` (code, column), the modes before its G codes, and whether an `M72`
/// restored them (then its F and E, which came before, are overruled).
pub(in crate::gcode::parser) struct StateCodes {
    pub(in crate::gcode::parser) codes: Vec<(u32, usize)>,
    pub(in crate::gcode::parser) before: SavedModes,
    pub(in crate::gcode::parser) restored: bool,
}

impl StateCodes {
    /// The line's words as its F and E act: without them after an `M72`, which acted after
    /// them and restored the feed and condition saved.
    pub(in crate::gcode::parser) fn feed_words<'w>(&self, letters: &Letters<'w>) -> Letters<'w> {
        if self.restored {
            letters.without(&['F', 'E'])
        } else {
            *letters
        }
    }
}
