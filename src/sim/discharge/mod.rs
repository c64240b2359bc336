//! The discharge-level gap (`sim.model = "discharge"`): what the generator's pulses do in
//! the gap, one cycle at a time, and what that does to the work, the debris and the wire.
//!
//! Each tick holds the generator's cycles of the condition in force. A cycle applies the open
//! voltage and waits for the gap to break down (an iso-energy generator: the on time counts
//! from ignition), discharges for the on time, then pauses for the off time:
//!
//! ```text
//!   ┌ wait t_d (open voltage) ┐┌ on time (U_d, I_p) ┐┌ off time ┐
//!   cycle class:  short  contact or a debris bridge: current, no voltage, no removal
//!                 arc    ignited at once (t_d < arc_delay) on a contaminated gap
//!                 normal ignited after t_d, drawn from the gap width's distribution
//!                 open   no breakdown within ignition_timeout: the generator gives up
//! ```
//!
//! **Ignition delay.** Exponential (a Poisson breakdown), its median a quadratic in the gap
//! width g (µm): `t50 = a·g² + b·g + c` µs (Esteves, Hensen, Kuffa, Wegener, *Ignition delay
//! time modeling in wire-EDM*, JMMP 2023 7(5) 177, as fitted in the WEDM Learning
//! Environment's ignition module: a = 0.48, b = −3.69, c = 14.05).
//!
//! **Removal.** A normal discharge removes `removal_mm3_per_j · U_d · I_p · t_on` (an arc
//! `arc_removal` of that): the front advances by the volume over the kerf and the part height,
//! so the cut speed follows from the condition, the height and the kerf.
//!
//! **Debris.** A contamination level `c` (dimensionless) grows with the volume removed per mm
//! of height (arcs' debris `arc_debris` times a normal's) and with random bursts (inclusions,
//! flow eddies: `debris_bursts_per_s`; with poor flushing more often, as its square, and
//! larger), and decays with the
//! flushing's time constant, longer for a thick part and a far nozzle. A pulse arcs with
//! probability `c · exp(−t_off / deionization)` (the off time lets the channel deionize and
//! the debris move) and bridges (a short) with `(c / short_contamination)²`.
//!
//! **The wire.** Two lumped temperatures above the dielectric's, per mm of wire: the body,
//! heated by the normal discharges spread over the height, and the spot where arcs
//! concentrate (`arc_spot_mm`; Sato et al.: wire breakage follows discharge concentration;
//! Liao and Yan 1997: excess arcs precede rupture). Both cool by convection, weaker deep in a
//! thick part and with a far nozzle (`flushing_depth_mm`), and by the wire's travel carrying
//! its heat out. The wire breaks when body + spot exceed `wire_break_rise_k`. The steady
//! limit is [`DischargeParams::breakage_limit_w`]: rising with the height, falling per mm,
//! lower with the nozzle far (the ordering of Sato et al.'s figures).
//!
//! **The gap voltage** it reports is the mean while the generator is energized (the waits at
//! the open voltage, the discharges at the burning voltage, a short at none), as a servo's
//! averaging circuit gated by the pulse sees it: a measure of the gap's width that the off
//! time does not shift.
//!
//! The model never allocates; a tick costs one draw and a logarithm per cycle.

use crate::rng::SplitMix64;
use crate::vocab::{GeneratorSetPoints, PulseCounts};

/// The model's constants (`[sim]`), each named with its unit; docs/process-model.md gives
/// each one's source.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DischargeParams {
    /// The part height where no `height` event says otherwise, mm.
    pub work_height_mm: f64,
    /// The kerf less the wire: twice the side gap, mm.
    pub side_gaps_mm: f64,
    /// Burning voltage of a discharge, V.
    pub discharge_voltage_v: f64,
    /// The median ignition delay's quadratic in the gap width (µm): [a, b, c], µs.
    pub ignition_median_us: [f64; 3],
    /// The generator gives up on a pulse that has not ignited within this, µs.
    pub ignition_timeout_us: f64,
    /// An ignition sooner than this is an arc, µs.
    pub arc_delay_us: f64,
    /// The off time's deionization constant, µs.
    pub deionization_us: f64,
    /// Work material removed per joule of discharge energy, mm³/J.
    pub removal_mm3_per_j: f64,
    /// An arc's removal as a fraction of a normal discharge's.
    pub arc_removal: f64,
    /// Contamination per mm³ removed per mm of height.
    pub debris_per_mm2: f64,
    /// An arc's debris as a multiple of a normal discharge's.
    pub arc_debris: f64,
    /// Flushing's time constant for a thin part at the nozzle, ms.
    pub flush_time_ms: f64,
    /// The depth flushing reaches into the slot with the nozzle at the part, mm.
    pub flushing_depth_mm: f64,
    /// Random debris bursts per second of cutting, with full flushing.
    pub debris_bursts_per_s: f64,
    /// A burst's contamination.
    pub debris_burst: f64,
    /// The contamination at which a pulse bridges with probability 1.
    pub short_contamination: f64,
    /// The fraction of a discharge's energy that heats the wire.
    pub wire_heat_fraction: f64,
    /// The dielectric's convection coefficient on the wire under full flushing, W/(m²·K).
    pub wire_convection_w_per_m2k: f64,
    /// The length of wire arcs concentrate on, mm.
    pub arc_spot_mm: f64,
    /// The wire breaks at this temperature rise, K.
    pub wire_break_rise_k: f64,
    /// The wire: diameter (mm), density (kg/m³), specific heat (J/(kg·K)).
    pub wire_diameter_mm: f64,
    pub wire_density_kg_m3: f64,
    pub wire_heat_capacity_j_kgk: f64,
    /// The generator's own set points, for those no condition gives.
    pub generator: GeneratorSetPoints,
}

impl DischargeParams {
    /// The median ignition delay at a gap of `gap_um`, µs.
    pub fn median_delay_us(&self, gap_um: f64) -> f64 {
        let gap_um = gap_um.max(0.0);
        let [a, b, c] = self.ignition_median_us;
        (a * gap_um * gap_um + b * gap_um + c).max(0.05)
    }

    /// An ignition delay drawn for a gap `gap_um` wide, µs: exponential with the median of
    /// [`median_delay_us`](Self::median_delay_us).
    #[inline]
    pub fn draw_delay_us(&self, gap_um: f64, rng: &mut SplitMix64) -> f64 {
        -self.median_delay_us(gap_um) / std::f64::consts::LN_2 * (1.0 - rng.next_f64()).ln()
    }

    /// The wire's heat capacity per mm of it, J/(K·mm).
    fn capacity_per_mm(&self) -> f64 {
        let d = self.wire_diameter_mm * 1e-3;
        self.wire_density_kg_m3 * self.wire_heat_capacity_j_kgk * std::f64::consts::PI * d * d / 4.0
            * 1e-3
    }

    /// Convection's conductance per mm of wire in a part `height_mm` high under `flushing`
    /// (1: the nozzle at the part), W/(K·mm).
    fn convection_per_mm(&self, height_mm: f64, flushing: f64) -> f64 {
        let reach = self.flushing_depth_mm * flushing.max(1e-3);
        self.wire_convection_w_per_m2k * std::f64::consts::PI * self.wire_diameter_mm * 1e-6
            / (1.0 + height_mm / reach)
    }

    /// The conductance per mm of wire carrying the heat of a `length_mm` stretch out as the
    /// wire travels at `wire_m_per_s`, W/(K·mm).
    fn travel_per_mm(&self, length_mm: f64, wire_m_per_s: f64) -> f64 {
        self.capacity_per_mm() * wire_m_per_s * 1e3 / length_mm
    }

    /// The steady breakage limit of the average discharge power of normal discharges, W, in
    /// a part `height_mm` high under `flushing` at a wire speed of `wire_m_per_min`.
    pub fn breakage_limit_w(&self, height_mm: f64, flushing: f64, wire_m_per_min: f64) -> f64 {
        let g = self.convection_per_mm(height_mm, flushing)
            + self.travel_per_mm(height_mm, wire_m_per_min / 60.0);
        self.wire_break_rise_k * g * height_mm / self.wire_heat_fraction
    }

    /// `set` with the generator's own set points where it gives none.
    pub fn in_force(&self, set: &GeneratorSetPoints) -> GeneratorSetPoints {
        let or = |v: f64, own: f64| if v > 0.0 { v } else { own };
        let g = &self.generator;
        GeneratorSetPoints {
            on_time_us: or(set.on_time_us, g.on_time_us),
            off_time_us: or(set.off_time_us, g.off_time_us),
            peak_current_a: or(set.peak_current_a, g.peak_current_a),
            open_voltage_v: or(set.open_voltage_v, g.open_voltage_v),
            wire_speed_m_per_min: or(set.wire_speed_m_per_min, g.wire_speed_m_per_min),
            ..*set
        }
    }
}

/// What one tick of discharges did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TickDischarges {
    pub pulses: PulseCounts,
    /// How far the work's front moved, mm.
    pub removed_mm: f64,
    /// The mean gap voltage while the generator was energized (the ignition waits and the
    /// discharges of the tick's cycles, not their off times: a gap-width signal whatever the
    /// off time), V (NaN when no cycle started).
    pub volts: f64,
    /// The wire broke in this tick.
    pub wire_broke: bool,
}

/// The gap's process state: the cycle in progress, the debris and the wire's temperatures.
#[derive(Debug, Clone)]
pub struct Discharges {
    params: DischargeParams,
    /// When the next cycle starts, µs from the start of the next tick.
    next_cycle_us: f64,
    /// Contamination.
    debris: f64,
    /// Wire temperature rises, K: the body and the arc spot.
    body_k: f64,
    spot_k: f64,
    /// The part height and flushing where the wire is now.
    height_mm: f64,
    flushing: f64,
    /// The energy of the normal and the arc discharges of the last tick, J (what the wire
    /// took, before the heat fraction).
    last_energy_j: [f64; 2],
}

impl Discharges {
    pub fn new(params: DischargeParams) -> Discharges {
        Discharges {
            next_cycle_us: 0.0,
            debris: 0.0,
            body_k: 0.0,
            spot_k: 0.0,
            height_mm: params.work_height_mm,
            flushing: 1.0,
            last_energy_j: [0.0; 2],
            params,
        }
    }

    pub fn params(&self) -> &DischargeParams {
        &self.params
    }

    /// The part is this high where the wire is now, mm.
    pub fn set_height(&mut self, height_mm: f64) {
        self.height_mm = height_mm;
    }

    /// The flushing reaches the slot this well now (1: the nozzle at the part).
    pub fn set_flushing(&mut self, flushing: f64) {
        self.flushing = flushing;
    }

    pub fn height_mm(&self) -> f64 {
        self.height_mm
    }

    pub fn flushing(&self) -> f64 {
        self.flushing
    }

    pub fn debris(&self) -> f64 {
        self.debris
    }

    /// The wire's temperature rise at its hottest, K.
    pub fn wire_rise_k(&self) -> f64 {
        self.body_k + self.spot_k
    }

    /// The wire was replaced (a rethread): cold, and the slot flushed.
    pub fn rethreaded(&mut self) {
        self.body_k = 0.0;
        self.spot_k = 0.0;
        self.debris = 0.0;
    }

    /// The generator is off (a rapid, a jump, a hold): the wire cools and the slot flushes,
    /// the next cycle starts with the next sparking tick.
    pub fn idle(&mut self, dt_us: f64) {
        self.next_cycle_us = 0.0;
        self.last_energy_j = [0.0; 2];
        self.cool(dt_us, self.params.generator.wire_speed_m_per_min);
    }

    /// One tick of `dt_us` with the gap `gap_um` wide (≤ 0: contact), the generator at `set`.
    pub fn tick(
        &mut self,
        dt_us: f64,
        gap_um: f64,
        set: &GeneratorSetPoints,
        rng: &mut SplitMix64,
    ) -> TickDischarges {
        let p = self.params;
        let set = p.in_force(set);
        let on = set.on_time_us;
        let off = set.off_time_us;
        let pulse_j = p.discharge_voltage_v * set.peak_current_a * on * 1e-6;
        let deionized = (-off / p.deionization_us).exp();
        let mut out = TickDischarges::default();
        let mut volt_us = 0.0;
        let mut energized_us = 0.0;
        let mut energy = [0.0f64; 2];
        while self.next_cycle_us < dt_us {
            let p_short = if gap_um <= 0.0 {
                1.0
            } else {
                (self.debris / p.short_contamination).powi(2).min(1.0)
            };
            let p_arc = (self.debris * deionized).min(0.95) * (1.0 - p_short);
            let r = rng.next_f64();
            // An ignited pulse: its delay, whether the discriminator counts it an arc, and
            // whose energy it is (0: a discharge's, 1: an arc's on its spot).
            let (length, ignition) = if r < p_short {
                out.pulses.short += 1;
                (on + off, None)
            } else if r < p_short + p_arc {
                let delay = rng.next_f64() * p.arc_delay_us;
                (delay + on + off, Some((delay, true, 1)))
            } else {
                let delay = p.draw_delay_us(gap_um, rng);
                if delay >= p.ignition_timeout_us {
                    out.pulses.open += 1;
                    volt_us += set.open_voltage_v * p.ignition_timeout_us;
                    (p.ignition_timeout_us + off, None)
                } else {
                    // Ignited at once on a clean gap: a discharge all the same, but the
                    // discriminator cannot tell it from an arc.
                    (delay + on + off, Some((delay, delay < p.arc_delay_us, 0)))
                }
            };
            if let Some((delay, arc, source)) = ignition {
                if arc {
                    out.pulses.arc += 1;
                } else {
                    out.pulses.normal += 1;
                }
                out.pulses.delay_sum_us += delay;
                energy[source] += pulse_j;
                volt_us += set.open_voltage_v * delay + p.discharge_voltage_v * on;
            }
            energized_us += length - off;
            self.next_cycle_us += length;
        }
        self.next_cycle_us -= dt_us;
        out.volts = if energized_us > 0.0 {
            volt_us / energized_us
        } else {
            f64::NAN
        };
        let height = self.height_mm.max(0.1);
        let kerf = p.wire_diameter_mm + p.side_gaps_mm;
        let removed = p.removal_mm3_per_j * (energy[0] + p.arc_removal * energy[1]);
        out.removed_mm = removed / (kerf * height);
        let dt_s = dt_us * 1e-6;
        // Debris: made by the removal (arcs' more), brought by bursts, flushed out.
        self.debris += p.debris_per_mm2
            * p.removal_mm3_per_j
            * (energy[0] + p.arc_debris * p.arc_removal * energy[1])
            / height;
        let flushing = self.flushing.max(1e-3);
        let bursts = p.debris_bursts_per_s / (flushing * flushing) * dt_s;
        if bursts > 0.0 && rng.next_f64() < bursts {
            self.debris += p.debris_burst / flushing * rng.next_f64() * 2.0;
        }
        self.last_energy_j = energy;
        self.cool(dt_us, set.wire_speed_m_per_min);
        // Heat: the normal discharges over the height, the arcs on their spot.
        let c = p.capacity_per_mm();
        self.body_k += p.wire_heat_fraction * energy[0] / height / c;
        self.spot_k += p.wire_heat_fraction * energy[1] / p.arc_spot_mm / c;
        out.wire_broke = self.wire_rise_k() >= p.wire_break_rise_k;
        out
    }

    /// `dt_us` of cooling and flushing at a wire speed of `wire_m_per_min`.
    fn cool(&mut self, dt_us: f64, wire_m_per_min: f64) {
        let p = &self.params;
        let dt_s = dt_us * 1e-6;
        let height = self.height_mm.max(0.1);
        let c = p.capacity_per_mm();
        let conv = p.convection_per_mm(height, self.flushing);
        let wire = wire_m_per_min / 60.0;
        let body = (conv + p.travel_per_mm(height, wire)) / c;
        let spot = (conv + p.travel_per_mm(p.arc_spot_mm, wire)) / c;
        self.body_k *= (-body * dt_s).exp();
        self.spot_k *= (-spot * dt_s).exp();
        let reach = p.flushing_depth_mm * self.flushing.max(1e-3);
        let flush_s = p.flush_time_ms * 1e-3 * (1.0 + height / reach);
        self.debris *= (-dt_s / flush_s).exp();
    }
}

#[cfg(test)]
pub(crate) mod tests;
