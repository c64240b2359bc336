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
//! ([`crate::hal::HalInputs`]), and the inputs side of a simulated machine or a gap script
//! ([`crate::sim::SimInputs`], [`crate::gap::ScriptInputs`]): the E-stop, the limit
//! switches and the wire the script or the model raises. [`Both`] reads two sources as one
//! (the port's pins beside a simulated gap's machine), so the loop reads one reading.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

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

    /// The operator rethreaded the wire: a simulated wire is whole again. A real wire-break
    /// sensor reads the new wire by itself.
    fn rethreaded(&mut self) {}
}

/// A simulated wire, shared by the two sides of a simulated machine: its gap side breaks
/// it (a model) or reads it (a script: the gap reads open while it is broken), its inputs
/// side reports it as the wire-break input and mends it on a rethread. Both sides run on
/// the consumer's thread; the flag is atomic only because each side is its own `Send` box.
#[derive(Debug, Clone, Default)]
pub struct SimulatedWire(Arc<AtomicBool>);

impl SimulatedWire {
    pub fn is_broken(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }

    pub fn set_broken(&self, broken: bool) {
        self.0.store(broken, Ordering::Relaxed);
    }

    /// What a simulated machine's inputs read: its `safety` and this wire. No contact pin:
    /// a simulated contact is sensed through the gap.
    pub fn reading(&self, safety: SafetyInputs) -> InputReading {
        InputReading {
            safety,
            wire_broken: self.is_broken(),
            contact: None,
        }
    }
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

    fn rethreaded(&mut self) {
        (**self).rethreaded()
    }
}

/// Two sources read as one machine: what either reads active is active, and the first's
/// contact pin wins over the second's (a wired probe over a simulated one).
pub struct Both<A, B> {
    pub first: A,
    pub second: B,
}

impl<A, B> MachineInputs for Both<&mut A, &mut B>
where
    A: MachineInputs + ?Sized,
    B: MachineInputs + ?Sized,
{
    fn sample(&mut self, tick: u64) -> Result<InputReading, InputError> {
        let first = if self.first.wired() {
            self.first.sample(tick)?
        } else {
            InputReading::default()
        };
        let second = self.second.sample(tick)?;
        Ok(InputReading {
            safety: first.safety.merged(second.safety),
            wire_broken: first.wire_broken || second.wire_broken,
            contact: first.contact.or(second.contact),
        })
    }

    fn wired(&self) -> bool {
        self.first.wired() || self.second.wired()
    }

    fn probe_reads(&mut self, what: ProbeReads) {
        self.first.probe_reads(what);
        self.second.probe_reads(what);
    }

    fn rethreaded(&mut self) {
        self.first.rethreaded();
        self.second.rethreaded();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vocab::{LimitSet, LimitSwitch};

    /// A source that reads what it is given.
    struct Reads(InputReading, bool, u32);

    impl MachineInputs for Reads {
        fn sample(&mut self, _tick: u64) -> Result<InputReading, InputError> {
            Ok(self.0)
        }
        fn wired(&self) -> bool {
            self.1
        }
        fn rethreaded(&mut self) {
            self.2 += 1;
        }
    }

    #[test]
    fn both_sources_read_as_one_machine() {
        let mut limits = LimitSet::default();
        limits.insert(LimitSwitch::parse("X+").unwrap());
        let mut pins = Reads(
            InputReading {
                contact: Some(false),
                ..InputReading::default()
            },
            true,
            0,
        );
        let mut sim = Reads(
            InputReading {
                safety: SafetyInputs {
                    estop: true,
                    limits,
                },
                wire_broken: true,
                contact: Some(true),
            },
            true,
            0,
        );
        let mut both = Both {
            first: &mut pins,
            second: &mut sim,
        };
        let r = both.sample(3).unwrap();
        assert!(r.safety.estop && r.wire_broken);
        assert_eq!(r.safety.limits, limits);
        assert_eq!(r.contact, Some(false), "the wired pin wins");
        both.rethreaded();
        assert_eq!((pins.2, sim.2), (1, 1), "both are told of a rethread");
    }

    #[test]
    fn an_unwired_first_source_is_not_read() {
        struct Fails;
        impl MachineInputs for Fails {
            fn sample(&mut self, _tick: u64) -> Result<InputReading, InputError> {
                Err(InputError::Device {
                    path: "x".into(),
                    source: std::io::Error::other("read"),
                })
            }
            fn wired(&self) -> bool {
                false
            }
        }
        let mut sim = Reads(InputReading::default(), true, 0);
        let mut both = Both {
            first: &mut Fails,
            second: &mut sim,
        };
        assert!(both.wired());
        assert!(both.sample(0).is_ok());
    }
}
