//! The interpreter's own parameters, as LinuxCNC names them: what expressions read besides
//! the program's store (the position as `#<_x>`…`#<_w>` and `#5420`…`#5428`, the modes as
//! `#<_metric>`…, the feed, the line) and the parameters a program may not assign.

use super::{BlockReader, MM_PER_INCH};
use crate::gcode::expr::{Env, ParamRef};

/// Parameters as expressions see them: the store, plus read-only system values as LinuxCNC
/// names them (`#<_x>`…`#<_w>` and `#5420`…`#5428` the position in program units and
/// coordinates, `#<_metric>`, `#<_imperial>`, `#<_absolute>`, `#<_incremental>`, `#<_feed>`).
pub(super) struct ReaderEnv<'a, R> {
    pub(super) reader: &'a BlockReader<R>,
}

use super::params::PARAM_AXES as SYSTEM_AXES;

/// LinuxCNC's read-only numbered parameters: the tool's data (`#5400`…`#5413`) and the
/// position (`#5420`…`#5428`).
const READ_ONLY_NUMBERED: [std::ops::RangeInclusive<usize>; 2] = [5400..=5413, 5420..=5428];

/// LinuxCNC's read-only named parameters (its `interp_namedparams.cc`), `_x`…`_w` and
/// `_abs_x`…`_abs_w` aside: a program that assigns one is refused, as LinuxCNC refuses it,
/// whether or not edmd gives it a value.
const READ_ONLY_NAMED: [&str; 42] = [
    "_vmajor",
    "_vminor",
    "_metric_machine",
    "_line",
    "_motion_mode",
    "_plane",
    "_ccomp",
    "_metric",
    "_imperial",
    "_absolute",
    "_incremental",
    "_inverse_time",
    "_units_per_minute",
    "_units_per_rev",
    "_coord_system",
    "_tool_offset",
    "_retract_r_plane",
    "_retract_old_z",
    "_spindle_rpm_mode",
    "_spindle_css_mode",
    "_ijk_absolute_mode",
    "_lathe_diameter_mode",
    "_lathe_radius_mode",
    "_spindle_on",
    "_spindle_cw",
    "_mist",
    "_flood",
    "_speed_override",
    "_feed_override",
    "_adaptive_feed",
    "_feed_hold",
    "_feed",
    "_rpm",
    "_current_tool",
    "_current_pocket",
    "_selected_pocket",
    "_selected_tool",
    "_value",
    "_value_returned",
    "_task",
    "_call_level",
    "_remap_level",
];

/// `name` (lower case, no `#< >`) is one of LinuxCNC's read-only named parameters.
fn read_only_name(name: &str) -> bool {
    let axis = |s: &str| {
        let mut c = s.chars();
        matches!((c.next(), c.next()), (Some(a), None) if SYSTEM_AXES.contains(&a.to_ascii_uppercase()))
    };
    READ_ONLY_NAMED.contains(&name)
        || name.strip_prefix("_abs_").is_some_and(axis)
        || name.strip_prefix('_').is_some_and(axis)
}

impl<'a, R> ReaderEnv<'a, R> {
    /// What expressions read in `reader`: its parameters and its own values.
    pub(super) fn of(reader: &'a BlockReader<R>) -> Self {
        ReaderEnv { reader }
    }
}

impl<R> ReaderEnv<'_, R> {
    /// Position on the axis `letter` in program units and coordinates (0 if not on the machine).
    fn axis_position(&self, letter: char) -> f64 {
        let r = self.reader;
        let scale = if r.state.modal.inch { MM_PER_INCH } else { 1.0 };
        r.axes
            .iter()
            .position(|a| a.letter() == letter)
            .map_or(0.0, |i| r.state.program_point(&r.state.position)[i] / scale)
    }
}

impl<R> Env for ReaderEnv<'_, R> {
    fn read_only(&self, param: &ParamRef) -> bool {
        match param {
            ParamRef::Numbered(n) => READ_ONLY_NUMBERED.iter().any(|r| r.contains(n)),
            ParamRef::Named(name) => read_only_name(name),
        }
    }

    fn numbered(&self, n: usize) -> f64 {
        match n {
            5420..=5428 => self.axis_position(SYSTEM_AXES[n - 5420]),
            _ => self.reader.state.params.numbered(n),
        }
    }

    fn named(&self, name: &str) -> Option<f64> {
        let r = self.reader;
        let truth = |b: bool| Some(if b { 1.0 } else { 0.0 });
        match name {
            "_metric" => truth(!r.state.modal.inch),
            "_imperial" => truth(r.state.modal.inch),
            "_absolute" => truth(!r.state.modal.incremental),
            "_incremental" => truth(r.state.modal.incremental),
            "_feed" => Some(
                r.state.modal.feed.unwrap_or(0.0)
                    / if r.state.modal.inch { MM_PER_INCH } else { 1.0 },
            ),
            "_line" => Some(r.scratch.line_no as f64),
            "_coord_system" => Some(r.state.system.coord_system_value()),
            _ => {
                let mut chars = name.chars();
                if let (Some('_'), Some(c), None) = (chars.next(), chars.next(), chars.next()) {
                    let upper = c.to_ascii_uppercase();
                    if SYSTEM_AXES.contains(&upper) {
                        return Some(self.axis_position(upper));
                    }
                }
                r.state.params.named(name)
            }
        }
    }
}
