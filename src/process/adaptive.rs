//! Adaptive control of the off time (`[adaptive]`): cut as fast as the wire survives.
//!
//! After Sato, Sato, Miyake, Hattori and Tokura (Mitsubishi Electric), *Wire-break prevention
//! on wire EDM*: the generator's pulses are counted by class over a window (normal, arc,
//! short, open); the average machining power of the normal pulses is held under a breakage
//! limit that rises with the part height and falls with poor flushing, by lengthening the off
//! time when it is over (or when arcs and shorts crowd the window: Liao and Yan 1997, excess
//! arcs precede rupture) and shortening it, a little at a time, when it is under:
//!
//! ```text
//!   every window:  P = N_normal · U_d · I_p · t_on / T_w
//!                  poor flushing  ⇐  the sensed flushing under poor_flushing_below (a nozzle
//!                                    pressure sensor), or the arc share, averaged, above
//!                                    poor_flushing_arc_share
//!                  over = max(P / (margin · P_limit(Ĥ, flushing)), (arcs + shorts) / pulses / arc_limit)
//!                  over > 1  ─► off ·= 1 + lengthen · over      else ─► off ·= 1 − shorten
//!                  off clamped to the condition's bounds (a technology row's), never past them
//! ```
//!
//! **The height, on line** (Sato after Yafuku: the kerf is constant, so the removal rate per
//! mm of travel tells the height): Ĥ = `height_mm2_per_as` · Q / d, the charge of the
//! discharges (arcs weighted by `arc_charge_weight`) over the net travel, both forgotten
//! exponentially over `height_window_mm` of travel. The constant is calibrated by cutting a
//! part of known height (docs/process-model.md).
//!
//! The law runs in the tick core: no allocation, a handful of operations per tick and one
//! decision per window.

use crate::vocab::{GeneratorSetPoints, PulseCounts};

/// The law's settings (`[adaptive]`), in the units it computes in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdaptiveSettings {
    /// Ticks per decision window.
    pub window_ticks: u32,
    /// The tick period, s.
    pub dt_s: f64,
    /// The off time's factors per window: over the limit, and under it.
    pub lengthen: f64,
    pub shorten: f64,
    /// The share of the limit the law cuts at.
    pub margin: f64,
    /// The arc-and-short share of a window's pulses that lengthens the off time whatever the
    /// power.
    pub arc_limit: f64,
    /// The breakage limit of the normal pulses' power: at a 20 mm part (W), its exponent of
    /// the height, and its factor under poor flushing.
    pub limit_w_at_20mm: f64,
    pub limit_height_exponent: f64,
    pub poor_flushing_factor: f64,
    /// The averaged arc share that means poor flushing, and the sensed flushing below which
    /// it is poor.
    pub poor_flushing_arc_share: f64,
    pub poor_flushing_below: f64,
    /// A discharge's burning voltage, V (the power's).
    pub discharge_voltage_v: f64,
    /// Height per charge per travel, mm² per A·s: Ĥ = this · Q / d.
    pub height_mm2_per_as: f64,
    /// The height estimate's travel window, mm.
    pub height_window_mm: f64,
    /// An arc's charge in the height estimate, as a fraction of a normal pulse's.
    pub arc_charge_weight: f64,
    /// The height the estimate starts from, mm (the technology row's).
    pub initial_height_mm: f64,
}

/// The bounds a condition's off time is adapted within, µs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OffTimeBounds {
    pub min_us: f64,
    pub max_us: f64,
}

/// What the law measured in its last window, for the operator.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AdaptiveView {
    /// Pulses per second by class: normal, arc, short, open.
    pub rates_hz: [f64; 4],
    /// The mean ignition delay, µs (NaN with no discharge).
    pub mean_delay_us: f64,
    /// The estimated part height, mm (NaN before the first estimate).
    pub height_mm: f64,
    /// The normal pulses' power and the limit it is held under, W.
    pub power_w: f64,
    pub limit_w: f64,
    /// The law judged the flushing poor.
    pub poor_flushing: bool,
}

/// The law at work: its settings and what it keeps between windows.
#[derive(Debug, Clone, Copy)]
pub struct AdaptiveLaw {
    settings: AdaptiveSettings,
    window: PulseCounts,
    ticks: u32,
    /// Net travel in the window, mm.
    travel_mm: f64,
    /// The height estimate's forgetting sums: charge (A·s) and travel (mm).
    charge: f64,
    distance: f64,
    /// The averaged arc share, and the flushing last sensed (1 with no sensor).
    arc_share: f64,
    flushing: f64,
    view: AdaptiveView,
}

impl AdaptiveLaw {
    pub fn new(settings: AdaptiveSettings) -> AdaptiveLaw {
        AdaptiveLaw {
            settings,
            window: PulseCounts::default(),
            ticks: 0,
            travel_mm: 0.0,
            charge: 0.0,
            distance: 0.0,
            arc_share: 0.0,
            flushing: 1.0,
            view: AdaptiveView {
                height_mm: settings.initial_height_mm,
                mean_delay_us: f64::NAN,
                ..AdaptiveView::default()
            },
        }
    }

    pub fn view(&self) -> &AdaptiveView {
        &self.view
    }

    /// The estimated part height, mm.
    pub fn height_mm(&self) -> f64 {
        self.view.height_mm
    }

    /// One tick's pulses and net travel along the path (mm, negative backing off), under
    /// the set points `set`; at the end of a window, the off time the law asks for (within
    /// `bounds`), or `None` between windows.
    #[inline]
    pub fn observe(
        &mut self,
        pulses: &PulseCounts,
        travel_mm: f64,
        flushing: Option<f64>,
        set: &GeneratorSetPoints,
        bounds: OffTimeBounds,
    ) -> Option<f64> {
        self.window.add(pulses);
        self.travel_mm += travel_mm;
        self.ticks += 1;
        if let Some(f) = flushing {
            self.flushing = f;
        }
        if self.ticks < self.settings.window_ticks {
            return None;
        }
        let off = self.decide(set, bounds);
        self.window = PulseCounts::default();
        self.ticks = 0;
        self.travel_mm = 0.0;
        Some(off)
    }

    /// The window's decision.
    fn decide(&mut self, set: &GeneratorSetPoints, bounds: OffTimeBounds) -> f64 {
        let s = &self.settings;
        let w = self.window;
        let span_s = self.ticks as f64 * s.dt_s;
        let total = w.total();
        let pulse_as = set.peak_current_a * set.on_time_us * 1e-6;
        // The height: charge over travel, forgotten over the travel window.
        let keep = (-self.travel_mm.abs() / s.height_window_mm).exp();
        self.charge =
            self.charge * keep + pulse_as * (w.normal as f64 + s.arc_charge_weight * w.arc as f64);
        self.distance = self.distance * keep + self.travel_mm;
        if self.distance > 0.2 * s.height_window_mm {
            self.view.height_mm = s.height_mm2_per_as * self.charge / self.distance;
        }
        let arcs = if total > 0 {
            (w.arc + w.short) as f64 / total as f64
        } else {
            0.0
        };
        if w.ignited() > 0 {
            self.arc_share += (w.arc as f64 / w.ignited() as f64 - self.arc_share) * 0.05;
        }
        let poor =
            self.flushing < s.poor_flushing_below || self.arc_share > s.poor_flushing_arc_share;
        let height = self.view.height_mm.clamp(1.0, 1000.0);
        let limit = s.limit_w_at_20mm
            * (height / 20.0).powf(s.limit_height_exponent)
            * if poor { s.poor_flushing_factor } else { 1.0 };
        let power = w.normal as f64 * s.discharge_voltage_v * pulse_as / span_s;
        // How far over: the power against its limit, the arcs against theirs; the step
        // grows with it, so a burst of arcs is met at once.
        let over = (power / (s.margin * limit)).max(arcs / s.arc_limit);
        let off = if total == 0 {
            set.off_time_us
        } else if over > 1.0 {
            set.off_time_us * (1.0 + s.lengthen * over)
        } else {
            set.off_time_us * (1.0 - s.shorten)
        };
        self.view.rates_hz = [w.normal, w.arc, w.short, w.open].map(|n| n as f64 / span_s);
        self.view.mean_delay_us = w.mean_delay_us();
        self.view.power_w = power;
        self.view.limit_w = limit;
        self.view.poor_flushing = poor;
        off.clamp(bounds.min_us, bounds.max_us)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn settings() -> AdaptiveSettings {
        AdaptiveSettings {
            window_ticks: 40,
            dt_s: 50e-6,
            lengthen: 0.3,
            shorten: 0.03,
            margin: 0.9,
            arc_limit: 0.25,
            limit_w_at_20mm: 100.0,
            limit_height_exponent: 0.5,
            poor_flushing_factor: 0.6,
            poor_flushing_arc_share: 0.15,
            poor_flushing_below: 0.6,
            discharge_voltage_v: 25.0,
            height_mm2_per_as: 0.735,
            height_window_mm: 0.5,
            arc_charge_weight: 0.3,
            initial_height_mm: 20.0,
        }
    }

    fn set(off: f64) -> GeneratorSetPoints {
        GeneratorSetPoints {
            on_time_us: 8.0,
            off_time_us: off,
            peak_current_a: 12.0,
            ..GeneratorSetPoints::default()
        }
    }

    const BOUNDS: OffTimeBounds = OffTimeBounds {
        min_us: 2.0,
        max_us: 60.0,
    };

    /// Runs windows of `normal` normal and `arc` arc pulses per tick; the off time after.
    fn run(law: &mut AdaptiveLaw, mut off: f64, normal: u32, arc: u32, windows: u32) -> f64 {
        let pulses = PulseCounts {
            normal,
            arc,
            delay_sum_us: 10.0 * (normal + arc) as f64,
            ..PulseCounts::default()
        };
        for _ in 0..windows * 40 {
            if let Some(next) = law.observe(&pulses, 3.5e-6, None, &set(off), BOUNDS) {
                off = next;
            }
        }
        off
    }

    #[test]
    fn under_the_limit_the_off_time_shortens_to_its_bound() {
        let mut law = AdaptiveLaw::new(settings());
        // One normal pulse per tick: 20 kHz · 2.4 mJ = 48 W, under 90 W (the height stays
        // at its start until 0.1 mm of travel).
        let off = run(&mut law, 10.0, 1, 0, 200);
        assert_eq!(off, 2.0);
        assert!((law.view().power_w - 48.0).abs() < 1e-9);
    }

    #[test]
    fn over_the_limit_or_among_arcs_the_off_time_lengthens_to_its_bound() {
        let mut law = AdaptiveLaw::new(settings());
        // Three per tick: 144 W, over.
        assert_eq!(run(&mut law, 10.0, 3, 0, 50), 60.0);
        let mut law = AdaptiveLaw::new(settings());
        // Few normal pulses, but half of them arcs.
        assert_eq!(run(&mut law, 10.0, 1, 1, 50), 60.0);
    }

    #[test]
    fn the_height_is_estimated_from_charge_over_travel() {
        let mut law = AdaptiveLaw::new(settings());
        // 1 pulse of 96 µA·s per tick over 3.5 nm per tick: 0.735 · 96e-6 / 3.5e-6 mm.
        run(&mut law, 10.0, 1, 0, 1000);
        assert!(
            (law.height_mm() - 20.16).abs() < 0.01,
            "{}",
            law.height_mm()
        );
    }
}
