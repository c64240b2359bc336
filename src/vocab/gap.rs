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

/// What a machining condition sets the generator to: one fact for the configuration's
/// conditions, the technology tables, the status and the HAL component's `edmd.gen.*` pins.
/// A set point a condition does not give is 0 (the generator keeps its own).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct GeneratorSetPoints {
    /// Pulse on time, µs.
    pub on_time_us: f64,
    /// Pulse off (pause) time, µs.
    pub off_time_us: f64,
    /// Peak discharge current, A.
    pub peak_current_a: f64,
    /// Open-circuit voltage, V.
    pub open_voltage_v: f64,
    /// The servo's reference gap voltage (the voltage law's), V.
    pub servo_ref_v: f64,
    /// Wire tension, N (a wire machine's).
    pub wire_tension_n: f64,
    /// Wire speed, m/min (a wire machine's).
    pub wire_speed_m_per_min: f64,
    /// Flushing pressure, bar.
    pub flushing_bar: f64,
}

impl GeneratorSetPoints {
    /// Each set point with its name as a HAL pin says it (`on-time-us`, …), in one order.
    pub fn named(&self) -> [(&'static str, f64); 8] {
        [
            ("on-time-us", self.on_time_us),
            ("off-time-us", self.off_time_us),
            ("peak-current-a", self.peak_current_a),
            ("open-voltage-v", self.open_voltage_v),
            ("servo-ref-v", self.servo_ref_v),
            ("wire-tension-n", self.wire_tension_n),
            ("wire-speed-m-min", self.wire_speed_m_per_min),
            ("flushing-bar", self.flushing_bar),
        ]
    }

    /// `on 8 µs, off 8 µs, peak 10 A, …`: the set points given, for an operator.
    pub fn describe(&self) -> String {
        let units = ["µs", "µs", "A", "V", "V", "N", "m/min", "bar"];
        let names = [
            "on",
            "off",
            "peak",
            "open",
            "servo ref",
            "tension",
            "wire",
            "flushing",
        ];
        self.named()
            .iter()
            .zip(units.iter().zip(names))
            .filter(|((_, v), _)| *v != 0.0)
            .map(|((_, v), (unit, name))| format!("{name} {v} {unit}"))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// The generator's pulses of one tick, by class, as a discriminator counts them: normal
/// discharges (ignited after a delay), arcs (ignited at once on a contaminated gap), shorts
/// (current with no voltage: contact or a bridge) and open pulses (no breakdown within the
/// generator's wait), with the sum of the ignition delays of the ignited ones. One fact for the
/// simulator, HAL's `edmd.gap.pulses-*` pins, gap scripts, the servo and the adaptive law.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct PulseCounts {
    pub normal: u32,
    pub arc: u32,
    pub short: u32,
    pub open: u32,
    /// Sum of the ignition delays of the normal and arc pulses, µs.
    pub delay_sum_us: f64,
}

impl PulseCounts {
    /// Every pulse counted.
    #[inline]
    pub fn total(&self) -> u32 {
        self.normal + self.arc + self.short + self.open
    }

    /// The pulses that discharged (normal and arc).
    #[inline]
    pub fn ignited(&self) -> u32 {
        self.normal + self.arc
    }

    /// The mean ignition delay of the ignited pulses, µs (NaN with none).
    #[inline]
    pub fn mean_delay_us(&self) -> f64 {
        if self.ignited() == 0 {
            f64::NAN
        } else {
            self.delay_sum_us / self.ignited() as f64
        }
    }

    /// Adds `other`'s counts to these.
    #[inline]
    pub fn add(&mut self, other: &PulseCounts) {
        self.normal += other.normal;
        self.arc += other.arc;
        self.short += other.short;
        self.open += other.open;
        self.delay_sum_us += other.delay_sum_us;
    }

    /// The gap state the tick's pulses say: shorted when shorts are at least half of them,
    /// open when none discharged, sparking otherwise; `None` with no pulse.
    #[inline]
    pub fn state(&self) -> Option<GapState> {
        let total = self.total();
        if total == 0 {
            None
        } else if 2 * self.short >= total {
            Some(GapState::Short)
        } else if self.ignited() == 0 {
            Some(GapState::Open)
        } else {
            Some(GapState::Normal)
        }
    }
}
