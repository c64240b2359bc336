//! Work coordinate systems as LinuxCNC has them: nine systems (`G54`…`G59.3`), each an offset
//! from machine coordinates, and where a program starts (the machine position, the table and
//! the active system).
//!
//! A program point is a machine point minus the active system's offset minus the `G92`
//! offset. The interpreter keeps the table where LinuxCNC keeps it, in the numbered
//! parameters (`#5221`… for `G54`, twenty per system, `#5220` the active one), in millimetres
//! (LinuxCNC's "user units", the machine's: edmd's machine is metric). [`WorkOffsets`] is the
//! same table as a value, for whoever keeps it between programs (the daemon's state file).

use crate::geometry::Point;

/// How many work coordinate systems there are (`G54`…`G59.3`).
pub const WORK_SYSTEMS: usize = 9;

/// The names of the nine systems, in LinuxCNC's order (`#5220` = 1 is `G54`).
const NAMES: [&str; WORK_SYSTEMS] = [
    "G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3",
];

/// One of the nine work coordinate systems.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct WorkSystem(u8);

impl Default for WorkSystem {
    fn default() -> Self {
        WorkSystem::G54
    }
}

impl WorkSystem {
    /// `G54`, the system a machine starts in and a program end returns to.
    pub const G54: WorkSystem = WorkSystem(1);

    /// The system LinuxCNC numbers `n` (`#5220`, `G10`'s `P`): 1 is `G54`, 9 is `G59.3`.
    pub fn from_number(n: u8) -> Option<WorkSystem> {
        (1..=WORK_SYSTEMS as u8)
            .contains(&n)
            .then_some(WorkSystem(n))
    }

    /// Its number, 1 (`G54`) to 9 (`G59.3`).
    pub fn number(self) -> u8 {
        self.0
    }

    /// Its place in the table, 0 to 8.
    pub fn index(self) -> usize {
        usize::from(self.0 - 1)
    }

    /// `G54`…`G59.3`.
    pub fn name(self) -> &'static str {
        NAMES[self.index()]
    }

    /// A system by its name (`G55`, `g59.1`, `55`, `59.3`).
    pub fn parse(text: &str) -> Option<WorkSystem> {
        let t = text.trim();
        let t = t
            .strip_prefix('G')
            .or_else(|| t.strip_prefix('g'))
            .unwrap_or(t);
        NAMES
            .iter()
            .position(|n| &n[1..] == t)
            .and_then(|i| WorkSystem::from_number(i as u8 + 1))
    }

    /// The system a `G` code selects, in tenths (`G55` is 550, `G59.1` is 591).
    pub(crate) fn from_g_tenths(tenths: u32) -> Option<WorkSystem> {
        let n = match tenths {
            540 | 550 | 560 | 570 | 580 | 590 => (tenths - 530) / 10,
            591..=593 => tenths - 584,
            _ => return None,
        };
        WorkSystem::from_number(n as u8)
    }

    /// LinuxCNC's `#<_coord_system>`: 540 for `G54` … 590, then 591 … 593.
    pub(crate) fn coord_system_value(self) -> f64 {
        let n = f64::from(self.0);
        if self.0 < 7 {
            530.0 + 10.0 * n
        } else {
            584.0 + n
        }
    }

    /// All nine, `G54` first.
    pub fn all() -> impl Iterator<Item = WorkSystem> {
        (1..=WORK_SYSTEMS as u8).map(WorkSystem)
    }
}

impl std::fmt::Display for WorkSystem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The nine systems' offsets from machine coordinates, mm, in machine axis order.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct WorkOffsets {
    systems: [Point; WORK_SYSTEMS],
}

impl WorkOffsets {
    pub fn get(&self, system: WorkSystem) -> &Point {
        &self.systems[system.index()]
    }

    pub fn set(&mut self, system: WorkSystem, offset: Point) {
        self.systems[system.index()] = offset;
    }
}

/// Where a program starts: the machine position, the work offsets and the active system.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct WorkStart {
    /// Machine coordinates, mm, machine axis order.
    pub position_mm: Point,
    pub offsets: WorkOffsets,
    pub system: WorkSystem,
    /// The modes the program starts in: `G20` (else `G21`), `G91` (else `G90`). A program
    /// file starts in G21 G90; MDI lines go on in the modes the previous ones left.
    pub modes: StartModes,
    /// An axis is not homed: machine coordinates mean nothing yet, so `G28`/`G30` (to a
    /// stored machine position) are refused. A program read without a machine (`check`,
    /// `plan`) reads as on a homed one.
    pub unhomed: bool,
}

/// Units and distance mode at a program's start.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StartModes {
    pub inch: bool,
    pub incremental: bool,
}

impl WorkStart {
    /// The machine point `machine` in the active system's coordinates (no `G92`), mm.
    pub fn to_work(&self, machine: &Point) -> Point {
        machine - self.offsets.get(self.system)
    }

    /// `X1.2000 Y-3.0000 (G54)`: the machine point `machine` as the program reads it in the
    /// active system, for a machine with `axes`.
    pub fn text_of(&self, machine: &Point, axes: &[crate::vocab::Axis]) -> String {
        let work = self.to_work(machine);
        let axes: Vec<String> = axes
            .iter()
            .enumerate()
            .map(|(i, a)| format!("{}{:.4}", a.letter(), work[i]))
            .collect();
        format!("{} ({})", axes.join(" "), self.system.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn systems_are_named_and_numbered_as_linuxcnc_does() {
        let names: Vec<&str> = WorkSystem::all().map(|s| s.name()).collect();
        assert_eq!(names, NAMES);
        assert_eq!(WorkSystem::from_g_tenths(540), Some(WorkSystem::G54));
        assert_eq!(WorkSystem::from_g_tenths(593).unwrap().name(), "G59.3");
        assert_eq!(WorkSystem::from_g_tenths(590).unwrap().number(), 6);
        assert_eq!(WorkSystem::from_g_tenths(591).unwrap().number(), 7);
        assert_eq!(WorkSystem::from_g_tenths(594), None);
        assert_eq!(WorkSystem::from_g_tenths(530), None);
        assert_eq!(WorkSystem::parse("g59.1").unwrap().number(), 7);
        assert_eq!(WorkSystem::parse("55").unwrap().name(), "G55");
        assert_eq!(WorkSystem::parse("G60"), None);
        assert_eq!(WorkSystem::from_number(0), None);
        let coded: Vec<f64> = WorkSystem::all().map(|s| s.coord_system_value()).collect();
        assert_eq!(
            coded,
            [
                540.0, 550.0, 560.0, 570.0, 580.0, 590.0, 591.0, 592.0, 593.0
            ]
        );
    }
}
