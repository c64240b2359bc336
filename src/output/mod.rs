//! Pulse outputs: where the consumer's steps go.
//!
//! A [`PulseOutput`] receives every tick's signed steps (at most one per axis) with the gap
//! state of that tick, from the consumer's thread loop. Outputs: [`PulseLog`]
//! (`output.kind = "file"`, the CSV pulse log of `design.md`), [`NullOutput`] (`"null"`, and
//! `"sim"`: the simulated drives take every step, so the pulse ledger is their position), the
//! parallel port ([`crate::parport::ParportOutput`]) and LinuxCNC's HAL
//! ([`crate::hal::HalOutput`]).
//!
//! Wrappers that work around any output: [`FaultInjector`] (`output.fault_at_tick`, a device
//! that dies mid-job) and the tracer ([`crate::trace::TracedOutput`]).
//!
//! **The contract of a failed write.** A write that returns an error has not taken the tick's
//! steps, unless the error says so ([`OutputError::step_taken`]): a port that fails after
//! the step edge went out has moved the drives. The runtime keeps its position ledger equal
//! to what the drives received on that basis.

mod fault;
mod pulse_log;

pub use fault::FaultInjector;
pub use pulse_log::{PulseLog, PulseLogHeader, PulseLogRow, read_pulse_log};

use crate::gap::GapState;
use crate::vocab::MAX_AXES;

/// An output that failed: which one and why.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("{path}: cannot write the pulse log: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    /// A hardware output failed; `phase` says during which write of the tick.
    #[error("{path}: write failed while {phase}: {source}")]
    Device {
        path: String,
        phase: &'static str,
        /// The step edge went out before the failure: the drives took the tick's steps.
        step_taken: bool,
        #[source]
        source: std::io::Error,
    },
    #[error(
        "injected fault at tick {tick} (output.fault_at_tick): the output refuses every write from here on"
    )]
    Injected { tick: u64 },
    /// The drives' feedback is further from the command than allowed (HAL's `pos-fb`).
    #[error(
        "following error on {axis}: the feedback is {error_mm:.4} mm from the command, more \
         than hal.max_following_error_mm = {max_mm} (a drive that stalled, lost steps or is \
         not connected)"
    )]
    FollowingError {
        axis: char,
        error_mm: f64,
        max_mm: f64,
    },
    /// HAL's real-time heartbeat (`rt-beat-in`) stood still: its threads no longer run.
    #[error(
        "HAL's real-time side stopped: rt-beat-in has not changed for {still_ms} ms (more than \
         hal.rt_beat_timeout_ms); its threads no longer run, nothing reaches the drives"
    )]
    HalStopped { still_ms: u64 },
}

impl OutputError {
    /// Whether the drives took the failed tick's steps anyway.
    pub fn step_taken(&self) -> bool {
        matches!(
            self,
            OutputError::Device {
                step_taken: true,
                ..
            }
        )
    }
}

/// A destination for step pulses.
pub trait PulseOutput {
    /// The steps of tick `tick` (-1, 0 or 1 per axis, axes in machine order) and the gap state
    /// sampled for it. Called once per tick, in tick order.
    fn write(
        &mut self,
        tick: u64,
        steps: &[i8; MAX_AXES],
        gap: GapState,
    ) -> Result<(), OutputError>;

    /// The job is over, or the idle machine is made safe: everything written reaches its
    /// destination, the spark and the flushing go off, and the drives too where `why` says
    /// so ([`StopReason::drives_off`]).
    fn finish(&mut self, why: StopReason) -> Result<(), OutputError>;

    /// Between jobs, about every millisecond (the fine thread's idle watch), `elapsed_ns`
    /// after the last call or the job's last tick: a device proves it is alive (HAL's
    /// heartbeat pin) and checks what it stands on (HAL's real-time side). An error is an
    /// alarm: the device is made safe and the machine held as in an E-stop.
    fn idle(&mut self, _elapsed_ns: u64) -> Result<(), OutputError> {
        Ok(())
    }

    /// Everything written so far reaches its destination, durably where there is a disk (a
    /// pulse log): called at a standstill, before a checkpoint is written there, so after a
    /// crash the record and the checkpoint agree to the step. Devices with nothing buffered
    /// have nothing to do.
    fn sync(&mut self) -> Result<(), OutputError> {
        Ok(())
    }

    /// What the machine is doing changed (the move in hand's `StepBlock` flags, the spark,
    /// the machining condition); the steps written from now on belong to it. A pulse log
    /// writes it down, the port drives its flushing pin, a recorder notes rapids.
    fn moving_in(&mut self, _now: Activity) {}

    /// A job is about to step the device (before its set points and its first tick): a
    /// device that takes up where its drives stand does so now (HAL's `pos-cmd` from
    /// `pos-fb`, the first time after it was made, once HAL has netted its pins).
    fn prepare(&mut self) {}

    /// The generator's set points in force (of `condition`, as the job's process holds them):
    /// before the first tick, and whenever they change during the job (another condition,
    /// or one adapted). A device with set-point outputs (HAL's `edmd.gen.*`) writes them.
    fn set_points(&mut self, _condition: u16, _set: &crate::vocab::GeneratorSetPoints) {}
}

pub use crate::buffer::Activity;

/// Why the outputs go quiet: what a device may keep on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// The job ended (done, stopped, a limit switch, a missed probe): the machine stays on,
    /// as in LinuxCNC, and a position-mode drive finishes reaching its last command.
    Ended,
    /// The E-stop: the drives go off.
    EStop,
    /// An alarm (a following error, a device that failed, HAL's real-time side gone): the
    /// drives go off.
    Alarm,
}

impl StopReason {
    /// The drives' enable goes off.
    pub fn drives_off(self) -> bool {
        self != StopReason::Ended
    }
}

/// `output.kind = "null"`: discards everything.
#[derive(Debug, Clone, Copy, Default)]
pub struct NullOutput;

impl PulseOutput for NullOutput {
    fn write(&mut self, _: u64, _: &[i8; MAX_AXES], _: GapState) -> Result<(), OutputError> {
        Ok(())
    }

    fn finish(&mut self, _why: StopReason) -> Result<(), OutputError> {
        Ok(())
    }
}

/// An output lent for one job (the fine thread's claimed device, wrapped in the job's
/// recorder).
impl<O: PulseOutput + ?Sized> PulseOutput for &mut O {
    fn write(
        &mut self,
        tick: u64,
        steps: &[i8; MAX_AXES],
        gap: GapState,
    ) -> Result<(), OutputError> {
        (**self).write(tick, steps, gap)
    }

    fn finish(&mut self, why: StopReason) -> Result<(), OutputError> {
        (**self).finish(why)
    }

    fn idle(&mut self, elapsed_ns: u64) -> Result<(), OutputError> {
        (**self).idle(elapsed_ns)
    }

    fn sync(&mut self) -> Result<(), OutputError> {
        (**self).sync()
    }

    fn moving_in(&mut self, now: Activity) {
        (**self).moving_in(now)
    }

    fn prepare(&mut self) {
        (**self).prepare()
    }

    fn set_points(&mut self, condition: u16, set: &crate::vocab::GeneratorSetPoints) {
        (**self).set_points(condition, set)
    }
}

impl<O: PulseOutput + ?Sized> PulseOutput for Box<O> {
    fn write(
        &mut self,
        tick: u64,
        steps: &[i8; MAX_AXES],
        gap: GapState,
    ) -> Result<(), OutputError> {
        (**self).write(tick, steps, gap)
    }

    fn finish(&mut self, why: StopReason) -> Result<(), OutputError> {
        (**self).finish(why)
    }

    fn idle(&mut self, elapsed_ns: u64) -> Result<(), OutputError> {
        (**self).idle(elapsed_ns)
    }

    fn sync(&mut self) -> Result<(), OutputError> {
        (**self).sync()
    }

    fn moving_in(&mut self, now: Activity) {
        (**self).moving_in(now)
    }

    fn prepare(&mut self) {
        (**self).prepare()
    }

    fn set_points(&mut self, condition: u16, set: &crate::vocab::GeneratorSetPoints) {
        (**self).set_points(condition, set)
    }
}
