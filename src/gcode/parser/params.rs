//! LinuxCNC's numbered parameters that the reader keeps (`#5061`…, `#5161`…, `#5181`…,
//! `#5210`…, `#5220`…): where the work systems' table, the `G92` offset, the stored `G28`/`G30`
//! positions and the probe's result stand, axis by axis (`X Y Z A B C U V W`), as LinuxCNC
//! numbers them, so that a program reads them where it would there.

use crate::gcode::work::WorkSystem;
use crate::vocab::Axis;

/// LinuxCNC's axis order in its parameter blocks (`#5061`…, `#5211`…, `#5221`…).
pub(super) const PARAM_AXES: [char; 9] = ['X', 'Y', 'Z', 'A', 'B', 'C', 'U', 'V', 'W'];

/// `#5210`: the `G92` offset is on; `#5211`… its value per axis.
pub(super) const G92_ENABLED: usize = 5210;
/// LinuxCNC's probe result: `#5061`… per axis (`X Y Z A B C U V W`), `#5070` success.
pub(super) const PROBE_PARAMS: usize = 5061;
/// `#5161`: `G28`'s stored position on the first parameter axis (`#5181` for `G30`).
pub(super) const G28_PARAMS: usize = 5161;
pub(super) const G30_PARAMS: usize = 5181;

/// `#5220`: the active work system (1 = `G54`).
pub(super) const ACTIVE_SYSTEM: usize = 5220;

/// The slot of `axis` in LinuxCNC's parameter blocks.
pub(super) fn param_slot(axis: Axis) -> usize {
    PARAM_AXES
        .iter()
        .position(|&l| l == axis.letter())
        .expect("every machine axis has a parameter slot")
}

/// The parameter that holds `system`'s offset on the axis in slot `k`.
pub(super) fn table_param(system: WorkSystem, k: usize) -> usize {
    ACTIVE_SYSTEM + 1 + 20 * system.index() + k
}
