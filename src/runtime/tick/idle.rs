//! Between jobs the fine thread keeps watch over the machine's claimed device (the parallel
//! port, the HAL component): every [`IDLE_POLL`] it reads the machine inputs and lets the
//! output prove it is alive ([`PulseOutput::idle`]: HAL's heartbeat pins).
//!
//! ```text
//!  fine thread, idle:  every 1 ms ─► inputs.sample ─► IdleWatch (reading; latched trips)
//!                                 ─► E-stop pressed? output.finish(EStop): drives off now
//!                                 ─► output.idle(elapsed) ─► a fault? latched, drives off
//!  control loop:       IdleWatch::take ─► the trip, the alarm, in the machine state
//! ```
//!
//! **Why here, not in the control loop.** The control loop looks at the machine every
//! 250 ms at most and may be busy: an E-stop pulse shorter than that would never be seen, and
//! a run sent right after it would move. The fine thread is the one thread that touches the
//! device in a job; between jobs it polls at a millisecond, latches what it saw until the
//! control loop takes it, and drops the drives' enable itself the moment the E-stop reads
//! pressed, whatever the control loop is doing. LinuxCNC's motion controller likewise reads
//! its inputs in every servo period, machine on or not.

use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::time::Duration;

use crate::inputs::MachineInputs;
use crate::output::{PulseOutput, StopReason};
use crate::vocab::{LimitSet, SafetyInputs};

/// How often the fine thread reads the claimed device between jobs.
pub const IDLE_POLL: Duration = Duration::from_millis(1);

/// The E-stop's bit in the words below; the limit switches' bits above it.
const ESTOP: u32 = 1;

fn word(s: SafetyInputs) -> u32 {
    (u32::from(s.limits.bits()) << 1) | u32::from(s.estop)
}

fn safety(word: u32) -> SafetyInputs {
    SafetyInputs {
        estop: word & ESTOP != 0,
        limits: LimitSet::from_bits((word >> 1) as u16),
    }
}

/// What the fine thread saw between jobs, for the control loop.
#[derive(Debug, Default)]
pub struct IdleWatch {
    /// The last reading (E-stop, limit switches).
    now: AtomicU32,
    /// Every E-stop and limit switch read active since the control loop last took them.
    seen: AtomicU32,
    /// A reading has been made (a claimed device with inputs is watched).
    watched: AtomicBool,
    /// The device failed between jobs since the control loop last looked (its message in
    /// `fault_text`).
    faulted: AtomicBool,
    fault_text: parking_lot::Mutex<String>,
    /// Polls made: the idle thread's proof of life.
    polls: AtomicU64,
}

/// What the control loop takes from the watch.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct IdleSeen {
    /// The inputs as last read; `None` when no device is watched.
    pub now: Option<SafetyInputs>,
    /// Everything read active since the last take (a pulse already gone included).
    pub seen: SafetyInputs,
    /// A device fault since the last take.
    pub fault: Option<String>,
}

impl IdleWatch {
    /// The inputs as last read (`None`: no device is watched).
    pub fn reading(&self) -> Option<SafetyInputs> {
        self.watched
            .load(Ordering::Acquire)
            .then(|| safety(self.now.load(Ordering::Acquire)))
    }

    /// What was seen since the last call, and the reading now.
    pub fn take(&self) -> IdleSeen {
        let fault = self
            .faulted
            .swap(false, Ordering::AcqRel)
            .then(|| std::mem::take(&mut *self.fault_text.lock()));
        IdleSeen {
            now: self.reading(),
            seen: safety(self.seen.swap(0, Ordering::AcqRel)),
            fault,
        }
    }

    pub fn polls(&self) -> u64 {
        self.polls.load(Ordering::Relaxed)
    }

    /// One reading: kept as the one now, and latched.
    fn store(&self, reading: SafetyInputs) {
        let w = word(reading);
        self.now.store(w, Ordering::Release);
        self.seen.fetch_or(w, Ordering::AcqRel);
        self.watched.store(true, Ordering::Release);
    }

    fn fault(&self, text: String) {
        *self.fault_text.lock() = text;
        self.faulted.store(true, Ordering::Release);
    }
}

/// The fine thread's device between jobs, and what it already did to it.
pub struct Parked<O: ?Sized, I: ?Sized> {
    /// The device was made safe for an E-stop or a fault (nothing to repeat until a job
    /// runs again).
    safe: bool,
    pub output: Box<O>,
    pub inputs: Box<I>,
}

impl<O: PulseOutput + ?Sized, I: MachineInputs + ?Sized> Parked<O, I> {
    pub fn new(output: Box<O>, inputs: Box<I>) -> Self {
        Parked {
            safe: false,
            output,
            inputs,
        }
    }

    /// A job ran on the device: it may be enabled again.
    pub fn used(&mut self) {
        self.safe = false;
    }

    /// One idle poll, `elapsed_ns` after the last (or the job's end).
    pub fn watch(&mut self, watch: &IdleWatch, elapsed_ns: u64) {
        watch.polls.fetch_add(1, Ordering::Relaxed);
        if self.inputs.wired() {
            match self.inputs.sample(0) {
                Ok(reading) => {
                    watch.store(reading.safety);
                    if reading.safety.estop {
                        self.make_safe(StopReason::EStop);
                    }
                }
                Err(e) => {
                    // A device that stopped answering reads as pressed: nothing may move.
                    watch.store(SafetyInputs {
                        estop: true,
                        limits: LimitSet::EMPTY,
                    });
                    if !self.safe {
                        watch.fault(e.to_string());
                    }
                    self.make_safe(StopReason::Alarm);
                }
            }
        }
        if let Err(e) = self.output.idle(elapsed_ns) {
            if !self.safe {
                watch.fault(e.to_string());
            }
            self.make_safe(StopReason::Alarm);
        }
    }

    fn make_safe(&mut self, why: StopReason) {
        if !self.safe {
            // The output's own failure to go quiet changes nothing more we could do here.
            let _ = self.output.finish(why);
            self.safe = true;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::GapState;
    use crate::inputs::{InputError, InputReading};
    use crate::output::OutputError;
    use crate::vocab::{Axis, LimitSwitch, MAX_AXES};

    #[derive(Default)]
    struct Drives {
        finished: Vec<StopReason>,
        fail_idle: bool,
    }
    impl PulseOutput for Drives {
        fn write(&mut self, _: u64, _: &[i8; MAX_AXES], _: GapState) -> Result<(), OutputError> {
            Ok(())
        }
        fn finish(&mut self, why: StopReason) -> Result<(), OutputError> {
            self.finished.push(why);
            Ok(())
        }
        fn idle(&mut self, _: u64) -> Result<(), OutputError> {
            if self.fail_idle {
                return Err(OutputError::HalStopped { still_ms: 50 });
            }
            Ok(())
        }
    }

    struct Script(Vec<Result<SafetyInputs, ()>>);
    impl MachineInputs for Script {
        fn sample(&mut self, _: u64) -> Result<InputReading, InputError> {
            match self.0.remove(0) {
                Ok(safety) => Ok(InputReading {
                    safety,
                    ..Default::default()
                }),
                Err(()) => Err(InputError::Device {
                    path: "port".into(),
                    source: std::io::Error::other("gone"),
                }),
            }
        }
    }

    fn pressed() -> SafetyInputs {
        SafetyInputs {
            estop: true,
            limits: LimitSet::EMPTY,
        }
    }

    #[test]
    fn a_pulse_between_two_takes_is_latched_and_the_drives_go_off_once() {
        let mut limits = LimitSet::EMPTY;
        limits.insert(LimitSwitch {
            axis: Axis::Y,
            positive: false,
        });
        let free = SafetyInputs::default();
        let mut parked = Parked::new(
            Box::new(Drives::default()),
            Box::new(Script(vec![
                Ok(free),
                Ok(pressed()),
                Ok(pressed()),
                Ok(free),
                Ok(SafetyInputs {
                    estop: false,
                    limits,
                }),
                Ok(free),
            ])),
        );
        let watch = IdleWatch::default();
        assert_eq!(watch.reading(), None, "nothing read yet");
        for _ in 0..4 {
            parked.watch(&watch, 1_000_000);
        }
        let taken = watch.take();
        assert_eq!(taken.now, Some(free), "released again");
        assert!(taken.seen.estop, "the pulse is latched");
        assert_eq!(taken.fault, None);
        assert_eq!(parked.output.finished, [StopReason::EStop], "once");
        assert_eq!(watch.take().seen, free, "taken: the latch is clear");
        parked.used();
        parked.watch(&watch, 1_000_000);
        parked.watch(&watch, 1_000_000);
        let taken = watch.take();
        assert_eq!(taken.seen.limits, limits);
        assert_eq!(taken.now, Some(free));
        assert_eq!(watch.polls(), 6);
    }

    #[test]
    fn a_device_that_fails_between_jobs_is_a_fault_said_once_and_reads_as_pressed() {
        let mut parked = Parked::new(
            Box::new(Drives {
                fail_idle: true,
                ..Default::default()
            }),
            Box::new(Script(vec![Ok(SafetyInputs::default()), Err(())])),
        );
        let watch = IdleWatch::default();
        parked.watch(&watch, 1_000_000);
        let taken = watch.take();
        assert!(taken.fault.unwrap().contains("real-time side stopped"));
        assert_eq!(parked.output.finished, [StopReason::Alarm]);
        parked.watch(&watch, 1_000_000);
        let taken = watch.take();
        assert_eq!(taken.fault, None, "said once while it stays safe");
        assert_eq!(taken.now, Some(pressed()));
    }
}
