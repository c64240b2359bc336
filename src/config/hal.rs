//! `[hal]`: edmd as a LinuxCNC HAL component (`output.kind = "hal"`).

use super::raw::RawHal;
use super::validate::Invalid;
use super::{GapKind, OutputKind};

/// `[hal]`, validated.
#[derive(Debug, Clone, PartialEq)]
pub struct HalConfig {
    /// The component's name: every pin's prefix.
    pub component: String,
    /// `None`: `pos-fb` is not read.
    pub max_following_error_mm: Option<f64>,
    pub gap_input: crate::hal::GapPins,
    pub probe_input: bool,
    /// The HAL library to load: a name the dynamic loader finds, or a path (a run-in-place
    /// LinuxCNC build).
    pub library: String,
}

impl RawHal {
    /// The gap is read as a voltage.
    pub(super) fn reads_voltage(&self) -> bool {
        self.gap_input == "voltage"
    }

    pub(super) fn validate(self, output: OutputKind, gap: GapKind) -> Result<HalConfig, Invalid> {
        let name_ok = !self.component.is_empty()
            && self.component.len() <= 20
            && self
                .component
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
        if !name_ok {
            return Err((
                "hal.component",
                format!(
                    "{:?} is not a HAL component name: 1 to 20 letters, digits, '-' or '_' \
                     (every pin's name starts with it and HAL keeps names under 48 bytes)",
                    self.component
                ),
            ));
        }
        let e = self.max_following_error_mm;
        if !(e.is_finite() && (0.0..=100.0).contains(&e)) {
            return Err((
                "hal.max_following_error_mm",
                format!("must be 0 (off) to 100 mm, got {e}"),
            ));
        }
        let gap_input = match self.gap_input.as_str() {
            "bits" => crate::hal::GapPins::Bits,
            "voltage" => crate::hal::GapPins::Voltage,
            other => {
                return Err((
                    "hal.gap_input",
                    format!("must be \"bits\" or \"voltage\", got {other:?}"),
                ));
            }
        };
        if gap == GapKind::Hal && output != OutputKind::Hal {
            return Err((
                "gap.kind",
                "\"hal\" reads the gap pins of edmd's HAL component and needs output.kind = \"hal\""
                    .to_string(),
            ));
        }
        if self.library.trim().is_empty() {
            return Err((
                "hal.library",
                "must name the HAL library (Debian's is \"liblinuxcnchal.so.0\")".to_string(),
            ));
        }
        Ok(HalConfig {
            library: self.library,
            component: self.component,
            max_following_error_mm: (e > 0.0).then_some(e),
            gap_input,
            probe_input: self.probe_input,
        })
    }
}
