//! Gap inputs: where the consumer learns whether the electrode is sparking, open or shorted.
//!
//! A [`GapSensor`] is sampled once per tick by the consumer's thread loop (never by the tick
//! core, which gets the state as a value). Sources: [`AlwaysNormal`] (`gap.kind = "none"`),
//! [`ScriptGap`] (`gap.kind = "script"`, a file of `TICK STATE` lines), the closed-loop
//! simulator ([`crate::sim::SimGap`], `"sim"`) and the parallel port's status pins
//! ([`crate::parport::ParportGap`], `"parport"`), an ADC's gap voltage through Linux IIO
//! ([`IioGap`], `"iio"`). The tracer
//! ([`crate::trace::TracedGap`]) wraps any of them.
//!
//! A gap input answers what the gap does, nothing else: a simulated machine's E-stop,
//! limits and wire come through its inputs side ([`crate::inputs::MachineInputs`]), as a
//! port's and HAL's do, so no wrapper here can drop one.

mod iio;
mod script;

use crate::vocab::MAX_AXES;

/// The gap state is shared vocabulary (the servo and the tick core read it too).
pub use crate::vocab::GapState;
pub use iio::{IioError, IioGap, IioSettings};
pub use script::{GapScript, ScriptError, ScriptGap, ScriptInputs};
pub(crate) use script::{read_script, words};

/// A gap input that failed mid-job (a device that stopped answering).
#[derive(Debug, thiserror::Error)]
pub enum GapError {
    #[error("{path}: cannot read the gap input: {source}")]
    Device {
        path: String,
        #[source]
        source: std::io::Error,
    },
    /// The IIO sampler has not delivered a value for this long.
    #[error("{path}: the gap voltage is stale: no sample for {ms} ms (the IIO sampler stopped)")]
    Stale { path: String, ms: u64 },
}

/// A source of gap states, sampled once per tick.
pub trait GapSensor {
    /// The gap state for tick `tick` (ticks come in increasing order). An error stops the
    /// job where it is.
    fn sample(&mut self, tick: u64) -> Result<GapState, GapError>;

    /// The steps the tick took (-1, 0, 1 per axis) and the direction of its event along the
    /// program (1 forward, -1 turn-back, 0 none). A simulated gap moves its electrode here;
    /// a real sensor ignores it.
    fn observe(&mut self, _steps: &[i8; MAX_AXES], _dir: i8) {}

    /// The kind of move in hand changed (`StepBlock` flags: rapid, flushing): a simulated gap
    /// knows the spark is off on a rapid; a real sensor ignores it.
    fn moving_in(&mut self, _now: crate::buffer::Activity) {}

    /// The gap voltage (V) at the last [`sample`](Self::sample), for inputs that measure one
    /// (the IIO ADC, the simulator); `None` for state-only inputs.
    fn volts(&self) -> Option<f64> {
        None
    }

    /// The open and short ratios (fractions of discharge pulses) of the last sampling window,
    /// for inputs that count them (the simulator); `None` otherwise.
    fn ratios(&self) -> Option<(f64, f64)> {
        None
    }

    /// The generator's pulses of the last [`sample`](Self::sample) by class, for inputs that
    /// count them (the simulator's discharge model, HAL's discriminator pins, a script that
    /// gives them); `None` otherwise.
    fn pulses(&self) -> Option<crate::vocab::PulseCounts> {
        None
    }

    /// How well the flushing reaches the slot (1: the nozzle at the part; less with the
    /// nozzle off it), as a nozzle-pressure sensor tells, for inputs that have one (the
    /// simulator, HAL's `edmd.gap.flushing`); `None` otherwise.
    fn flushing(&self) -> Option<f64> {
        None
    }

    /// The generator's set points changed (a new condition, an adaptation): a simulated gap
    /// discharges with them; a real one ignores it (its generator is told by the output).
    fn generator(&mut self, _set: &crate::vocab::GeneratorSetPoints) {}

    /// What the job's probing moves read as their contact (a homing job's switch, a touch
    /// cycle's part, or the probe). A wire's contact with the part is sensed through the
    /// gap (a short), so the simulator's gap answers a touch cycle from its part, and with
    /// its generator off through a homing job it answers the simulated switch too. A real
    /// gap input ignores it: its machine's switches are machine inputs.
    fn probe_reads(&mut self, _what: crate::vocab::ProbeReads) {}
}

/// `gap.kind = "none"`: the gap is always normal (a dry run).
#[derive(Debug, Clone, Copy, Default)]
pub struct AlwaysNormal;

impl GapSensor for AlwaysNormal {
    fn sample(&mut self, _tick: u64) -> Result<GapState, GapError> {
        Ok(GapState::Normal)
    }
}

impl<G: GapSensor + ?Sized> GapSensor for Box<G> {
    fn sample(&mut self, tick: u64) -> Result<GapState, GapError> {
        (**self).sample(tick)
    }

    fn observe(&mut self, steps: &[i8; MAX_AXES], dir: i8) {
        (**self).observe(steps, dir)
    }

    fn moving_in(&mut self, now: crate::buffer::Activity) {
        (**self).moving_in(now)
    }

    fn volts(&self) -> Option<f64> {
        (**self).volts()
    }

    fn ratios(&self) -> Option<(f64, f64)> {
        (**self).ratios()
    }

    fn probe_reads(&mut self, what: crate::vocab::ProbeReads) {
        (**self).probe_reads(what)
    }

    fn pulses(&self) -> Option<crate::vocab::PulseCounts> {
        (**self).pulses()
    }

    fn generator(&mut self, set: &crate::vocab::GeneratorSetPoints) {
        (**self).generator(set)
    }

    fn flushing(&self) -> Option<f64> {
        (**self).flushing()
    }
}
