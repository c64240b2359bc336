//! The parts of the status the console adds to the machine's: the work offset table's rows
//! and the wire offset in force.

use serde::{Deserialize, Serialize};

/// One system of the work offset table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WorkOffsetRow {
    pub system: String,
    pub offset_mm: Vec<f64>,
}

/// The wire offset a job cuts with now.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WireOffsetStatus {
    /// `"G41"` (left of travel) or `"G42"` (right).
    pub side: String,
    pub mm: f64,
}

impl WireOffsetStatus {
    /// From a signed offset (+ left, − right; 0: none).
    pub fn of(signed_mm: f64) -> Option<WireOffsetStatus> {
        (signed_mm != 0.0).then(|| WireOffsetStatus {
            side: if signed_mm > 0.0 { "G41" } else { "G42" }.to_string(),
            // The ring carries it as f32: shown to the micron it was given in.
            mm: (signed_mm.abs() * 1e6).round() / 1e6,
        })
    }
}
