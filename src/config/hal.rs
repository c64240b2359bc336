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
    /// `edmd.watchdog` changes level this often (ms).
    pub heartbeat_ms: f64,
    /// `edmd.rt-beat-in` standing still this long is HAL's real-time side gone (ms); `None`:
    /// not read.
    pub rt_beat_timeout_ms: Option<f64>,
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
        let beat = self.heartbeat_ms;
        if !(beat.is_finite() && (0.5..=1000.0).contains(&beat)) {
            return Err((
                "hal.heartbeat_ms",
                format!(
                    "must be 0.5 to 1000 ms (a level at least as long as the period of the HAL \
                     thread that runs the watchdog), got {beat}"
                ),
            ));
        }
        let rt = self.rt_beat_timeout_ms;
        if !(rt.is_finite() && (rt == 0.0 || (1.0..=60_000.0).contains(&rt))) {
            return Err((
                "hal.rt_beat_timeout_ms",
                format!("must be 0 (off) or 1 to 60000 ms, got {rt}"),
            ));
        }
        Ok(HalConfig {
            heartbeat_ms: beat,
            rt_beat_timeout_ms: (rt > 0.0).then_some(rt),
            library: self.library,
            component: self.component,
            max_following_error_mm: (e > 0.0).then_some(e),
            gap_input,
            probe_input: self.probe_input,
        })
    }
}
