//! The proportional servo laws' inputs: the gap voltage and the pulse ratios, turned into a
//! gap state and a filtered signal before the tick proper.

use super::{Interpolator, Tick};
use crate::buffer::BlockSource;
use crate::servo::Law;
use crate::vocab::GapState;

impl Interpolator {
    /// One tick with what the gap input measured beside its state: the voltage (voltage
    /// law) or the open and short ratios of its last window (ratio law). Each law takes what
    /// it reads; the three-state law takes the state alone.
    #[inline]
    pub fn tick_measured<S: BlockSource + ?Sized>(
        &mut self,
        gap: GapState,
        volts: Option<f64>,
        ratios: Option<(f64, f64)>,
        source: &mut S,
    ) -> Tick {
        if let (
            Law::Ratio {
                short_limit,
                open_limit,
                ..
            },
            Some((open, short)),
        ) = (self.settings.law, ratios)
        {
            // The proportional signal is open − short, kept where the voltage law keeps its
            // filtered voltage.
            self.volts = open - short;
            let gap = if short >= short_limit {
                GapState::Short
            } else if open >= open_limit {
                GapState::Open
            } else {
                GapState::Normal
            };
            return self.tick(gap, source);
        }
        self.tick_volts(gap, volts, source)
    }

    /// One tick with the gap's voltage (V, when the input measures one) and the state the
    /// input reports. Under the voltage law the state comes from the filtered voltage and the
    /// feed is proportional; under the three-state law the voltage is ignored.
    #[inline]
    pub fn tick_volts<S: BlockSource + ?Sized>(
        &mut self,
        gap: GapState,
        volts: Option<f64>,
        source: &mut S,
    ) -> Tick {
        let gap = match (self.settings.law, volts) {
            (
                Law::Voltage {
                    short_v,
                    open_v,
                    tau,
                    ..
                },
                Some(v),
            ) => {
                self.volts = if !self.volts.is_finite() || tau <= 0.0 {
                    v
                } else {
                    self.volts + (v - self.volts) * (self.settings.dt / tau).min(1.0)
                };
                if self.volts < short_v {
                    GapState::Short
                } else if self.volts > open_v {
                    GapState::Open
                } else {
                    GapState::Normal
                }
            }
            _ => gap,
        };
        self.tick(gap, source)
    }
}
