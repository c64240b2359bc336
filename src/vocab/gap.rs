//! The spark gap's state and the voltages that separate its states.

use serde::{Deserialize, Serialize};

/// The gap voltages that separate its states: below `short_below` (V) a short, above
/// `open_above` open, sparking in between. One fact for the ADC input, the voltage law and the
/// simulator's voltage (`gap.short_below_v`, `gap.open_above_v`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GapVolts {
    pub short_below: f64,
    pub open_above: f64,
}

impl GapVolts {
    /// The gap state of a gap voltage.
    #[inline]
    pub fn state_of(&self, volts: f64) -> GapState {
        if volts < self.short_below {
            GapState::Short
        } else if volts > self.open_above {
            GapState::Open
        } else {
            GapState::Normal
        }
    }
}

/// The state of the spark gap.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GapState {
    /// Discharging: machine at the normal servo feed.
    Normal,
    /// No discharge: the electrode is too far; close in at the open feed.
    Open,
    /// Short circuit: turn back along the executed path.
    Short,
}

impl GapState {
    /// In the order of the counts by gap state (`gap_ticks`): [`GapState::index`].
    pub const ALL: [GapState; 3] = [GapState::Normal, GapState::Open, GapState::Short];

    /// Where this state stands in [`GapState::ALL`].
    pub fn index(self) -> usize {
        match self {
            GapState::Normal => 0,
            GapState::Open => 1,
            GapState::Short => 2,
        }
    }

    /// `normal`, `open` or `short`, as in the pulse log and gap scripts.
    pub fn name(self) -> &'static str {
        match self {
            GapState::Normal => "normal",
            GapState::Open => "open",
            GapState::Short => "short",
        }
    }

    pub fn from_name(name: &str) -> Option<GapState> {
        match name.to_ascii_lowercase().as_str() {
            "normal" => Some(GapState::Normal),
            "open" => Some(GapState::Open),
            "short" => Some(GapState::Short),
            _ => None,
        }
    }
}
