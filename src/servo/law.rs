//! The servo laws: each takes what the gap input read ([`GapReading`]), decides the gap
//! state from it ([`GapLaw::classify`]) and keeps what it needs between ticks (the filtered
//! voltage, the ratio signal), and asks for a feed along the path
//! ([`Servo::law_motion`](super::Servo::law_motion)).
//!
//! - **Three states**: the input's state as it is; sparking at `Feeds::normal`, open at
//!   `Feeds::open`, shorted: turn back.
//! - **Voltage**: the gap voltage, filtered (first order, `tau`), against two thresholds (the
//!   gap's [`GapVolts`]: below the first a short, above the second open); in between the feed is
//!   `gain · (V − v_ref)`, negative backing off along the path at up to `Feeds::retract`. A
//!   machining condition may set its own `v_ref`.
//! - **Ratio**: the open and short ratios of the input's last window: a short ratio from
//!   `short_limit` up is a short, an open ratio from `open_limit` up is open; in between the
//!   feed is `gain · (open − short − r_ref)`.

use crate::vocab::{GapState, GapVolts, PulseCounts};

/// How the servo turns the gap into a feed, as configured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Law {
    ThreeState,
    Voltage {
        v_ref: f64,
        gain: f64,
        /// The voltages that separate the gap's states.
        volts: GapVolts,
        /// Filter time constant (s); 0 for none.
        tau: f64,
    },
    Ratio {
        r_ref: f64,
        gain: f64,
        short_limit: f64,
        open_limit: f64,
    },
}

/// What a law reads from the gap input beside its state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LawInput {
    /// The state alone (the three-state law).
    State,
    /// The gap voltage (the voltage law).
    Volts,
    /// The open and short ratios of the last window (the ratio law).
    Ratios,
}

impl Law {
    /// What this law reads: the consumer's loop asks the input for that and nothing else.
    pub fn input(&self) -> LawInput {
        match self {
            Law::ThreeState => LawInput::State,
            Law::Voltage { .. } => LawInput::Volts,
            Law::Ratio { .. } => LawInput::Ratios,
        }
    }
}

/// What the gap input read this tick: its state, and what it measured beside it (the gap
/// voltage, V; the open and short ratios of its last window; the tick's pulses).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GapReading {
    pub state: GapState,
    pub volts: Option<f64>,
    pub ratios: Option<(f64, f64)>,
    /// The tick's pulses by class, from an input that counts them (whatever the law: the
    /// adaptive control reads them too).
    pub pulses: Option<PulseCounts>,
    /// The flushing as the input senses it (1: the nozzle at the part).
    pub flushing: Option<f64>,
}

impl GapReading {
    /// A reading of the state alone.
    pub fn state(state: GapState) -> GapReading {
        GapReading {
            state,
            volts: None,
            ratios: None,
            pulses: None,
            flushing: None,
        }
    }
}

/// A law at work: its settings and what it keeps between ticks.
#[derive(Debug, Clone, Copy)]
pub(crate) enum GapLaw {
    ThreeState,
    Voltage {
        law: VoltageLaw,
        /// The filtered voltage (V); NaN before the first reading.
        filtered: f64,
    },
    Ratio {
        law: RatioLaw,
        /// `open − short` of the last window; NaN before the first.
        signal: f64,
    },
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct VoltageLaw {
    pub v_ref: f64,
    pub gain: f64,
    pub volts: GapVolts,
    /// Filter time constant (s); 0 for none.
    pub tau: f64,
    /// Tick period (s).
    pub dt: f64,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct RatioLaw {
    pub r_ref: f64,
    pub gain: f64,
    pub short_limit: f64,
    pub open_limit: f64,
}

impl GapLaw {
    /// The law of `law` for ticks of `dt` seconds, nothing read yet.
    pub(crate) fn new(law: Law, dt: f64) -> GapLaw {
        match law {
            Law::ThreeState => GapLaw::ThreeState,
            Law::Voltage {
                v_ref,
                gain,
                volts,
                tau,
            } => GapLaw::Voltage {
                law: VoltageLaw {
                    v_ref,
                    gain,
                    volts,
                    tau,
                    dt,
                },
                filtered: f64::NAN,
            },
            Law::Ratio {
                r_ref,
                gain,
                short_limit,
                open_limit,
            } => GapLaw::Ratio {
                law: RatioLaw {
                    r_ref,
                    gain,
                    short_limit,
                    open_limit,
                },
                signal: f64::NAN,
            },
        }
    }

    /// The gap state of this tick's reading; the law keeps what it measured. A reading
    /// without what the law measures keeps the input's state (and the law's last value).
    #[inline]
    pub(crate) fn classify(&mut self, reading: &GapReading) -> GapState {
        match self {
            GapLaw::ThreeState => reading.state,
            GapLaw::Voltage { law, filtered } => match reading.volts {
                Some(v) => {
                    *filtered = if !filtered.is_finite() || law.tau <= 0.0 {
                        v
                    } else {
                        *filtered + (v - *filtered) * (law.dt / law.tau).min(1.0)
                    };
                    law.volts.state_of(*filtered)
                }
                None => reading.state,
            },
            GapLaw::Ratio { law, signal } => match reading.ratios {
                Some((open, short)) => {
                    *signal = open - short;
                    if short >= law.short_limit {
                        GapState::Short
                    } else if open >= law.open_limit {
                        GapState::Open
                    } else {
                        GapState::Normal
                    }
                }
                None => reading.state,
            },
        }
    }

    /// The proportional law's signal, reference and gain, once it has a signal (`v_ref`:
    /// a machining condition's reference voltage, 0 for the law's own); `None` for the
    /// three-state law or before the first measurement.
    #[inline]
    pub(crate) fn proportional(&self, v_ref: f32) -> Option<(f64, f64, f64)> {
        match *self {
            GapLaw::ThreeState => None,
            GapLaw::Voltage { law, filtered } => filtered.is_finite().then(|| {
                let reference = if v_ref > 0.0 { v_ref as f64 } else { law.v_ref };
                (filtered, reference, law.gain)
            }),
            GapLaw::Ratio { law, signal } => {
                signal.is_finite().then_some((signal, law.r_ref, law.gain))
            }
        }
    }

    pub(crate) fn is_three_state(&self) -> bool {
        matches!(self, GapLaw::ThreeState)
    }
}
