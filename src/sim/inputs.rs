//! The simulated machine's inputs side: what its E-stop, limit switches and wire-break
//! sensor read, under the same trait as the port's status pins and HAL's input pins.
//!
//! The scripted `estop` and `limit X+` events (`sim.events`) press them at their tick; the
//! wire is the one the gap side breaks (the model's wire-break process) and a rethread
//! mends. The loop reads this side before the gap side in every tick, so an event is seen
//! in its own tick, and the gap side learns of a rethread in the same tick it happens.

use super::SimEvent;
use crate::inputs::{InputError, InputReading, MachineInputs, SimulatedWire};
use crate::vocab::SafetyInputs;

/// `gap.kind = "sim"`: the inputs of the machine the simulator simulates.
#[derive(Debug, Clone)]
pub struct SimInputs {
    /// The scripted events that press inputs, by tick; the next one to apply.
    events: Vec<(u64, SimEvent)>,
    next_event: usize,
    /// The E-stop and limit switches the events have raised.
    safety: SafetyInputs,
    wire: SimulatedWire,
}

impl SimInputs {
    /// The inputs side for `events` (only [`SimEvent::presses_an_input`] ones) and the
    /// gap side's `wire`.
    pub(super) fn new(events: Vec<(u64, SimEvent)>, wire: SimulatedWire) -> SimInputs {
        debug_assert!(events.iter().all(|(_, e)| e.presses_an_input()));
        SimInputs {
            events,
            next_event: 0,
            safety: SafetyInputs::default(),
            wire,
        }
    }
}

impl MachineInputs for SimInputs {
    fn sample(&mut self, tick: u64) -> Result<InputReading, InputError> {
        while let Some(&(at, event)) = self.events.get(self.next_event) {
            if at > tick {
                break;
            }
            self.next_event += 1;
            match event {
                SimEvent::Estop => self.safety.estop = true,
                SimEvent::Limit(switch) => self.safety.limits.insert(switch),
                _ => {}
            }
        }
        Ok(self.wire.reading(self.safety))
    }

    fn rethreaded(&mut self) {
        self.wire.set_broken(false);
    }
}
