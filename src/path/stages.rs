//! The stages of a die-sinker's job: its orbital sinking moves, as the producer reads them
//! and `plan` and a run's summary list them.

use serde::{Deserialize, Serialize};

/// Most orbit stages a summary lists.
pub const MAX_STAGES: usize = 1000;

/// One orbital sinking move (a stage of a rough-to-finish sequence): where it sinks from and
/// to, in which condition, on which orbit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageRow {
    pub line: u64,
    pub condition: u32,
    pub shape: String,
    pub radius_mm: f64,
    pub from_z_mm: f64,
    pub to_z_mm: f64,
    pub turns: u32,
}

impl StageRow {
    /// The stage of `block`, when it is an orbital sinking move.
    pub fn of(block: &crate::gcode::Block) -> Option<StageRow> {
        block.orbit.map(|o| StageRow {
            line: block.line,
            condition: block.condition,
            shape: o.shape.name().to_string(),
            radius_mm: o.radius_mm,
            from_z_mm: o.from_z,
            to_z_mm: o.to_z,
            turns: o.turns,
        })
    }

    /// `line 4: Z 0.0000 -> -1.0000 mm in E3, circle of 0.3000 mm, 3 turns`.
    pub fn text(&self) -> String {
        format!(
            "line {}: Z {:.4} -> {:.4} mm in E{}, {} of {:.4} mm, {} turns",
            self.line,
            self.from_z_mm,
            self.to_z_mm,
            self.condition,
            self.shape,
            self.radius_mm,
            self.turns
        )
    }
}
