//! Machine inputs: the E-stop, the limit switches, the home switches, the probe and the
//! wire-break sensor, read at every tick in a phase of their own, whatever the gap input is.
//!
//! ```text
//!  consumer thread loop, each tick:
//!    inputs.sample(tick) ─► InputReading { safety, wire_broken, contact }   (this module)
//!    gap.sample(tick)    ─► GapState                                        (crate::gap)
//! ```
//!
//! LinuxCNC's motion controller reads its inputs (`process_inputs`) before it plans a cycle,
//! and the inputs are the machine's, not the spark generator's. So here: a machine whose
//! port carries an E-stop is read for it with a simulated gap, a script or an ADC as the gap
//! input just as with the port's own status pins. The sources are [`NoInputs`] (a machine
//! without wired inputs: the simulated drives, a pulse log), the parallel port's status
//! pins ([`crate::parport::ParportInputs`]) and the HAL component's input pins
//! ([`crate::hal::HalInputs`]). A simulated gap or a gap script still raises
//! the inputs of the machine it simulates through [`crate::gap::GapSensor::safety`]; the loop
//! merges both.

use crate::vocab::{ProbeReads, SafetyInputs};

/// What the inputs read at one tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct InputReading {
    pub safety: SafetyInputs,
    pub wire_broken: bool,
    /// What a probing move reads as its contact (the probe pin, or a homing job's switch
    /// pin), where a pin is wired for it; `None`: no pin, the gap input tells (its short is
    /// the contact). Read at every tick; the loop uses it only during probing moves.
    pub contact: Option<bool>,
}

/// The inputs could not be read (a device that stopped answering): the job stops where it
/// is, as for a gap input.
#[derive(Debug, thiserror::Error)]
pub enum InputError {
    #[error("{path}: cannot read the machine inputs: {source}")]
    Device {
        path: String,
        #[source]
        source: std::io::Error,
    },
}

/// A source of machine inputs, sampled once per tick.
pub trait MachineInputs {
    /// The inputs at tick `tick` (ticks come in increasing order).
    fn sample(&mut self, tick: u64) -> Result<InputReading, InputError>;

    /// Something is wired: `false` lets the loop skip [`sample`](Self::sample), which would
    /// read nothing, on every tick.
    fn wired(&self) -> bool {
        true
    }

    /// What the job's probing moves read as their contact (a homing job's switch, or the
    /// probe).
    fn probe_reads(&mut self, _what: ProbeReads) {}
}

/// No wired inputs: nothing is ever pressed, no contact pin.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoInputs;

impl MachineInputs for NoInputs {
    fn sample(&mut self, _tick: u64) -> Result<InputReading, InputError> {
        Ok(InputReading::default())
    }

    fn wired(&self) -> bool {
        false
    }
}

impl<I: MachineInputs + ?Sized> MachineInputs for Box<I> {
    fn sample(&mut self, tick: u64) -> Result<InputReading, InputError> {
        (**self).sample(tick)
    }

    fn wired(&self) -> bool {
        (**self).wired()
    }

    fn probe_reads(&mut self, what: ProbeReads) {
        (**self).probe_reads(what)
    }
}
