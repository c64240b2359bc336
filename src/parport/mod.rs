//! The PC parallel port: step/dir pulses out, gap state in, through Linux ppdev.
//!
//! ```text
//!  consumer thread loop                      one /dev/parportN, claimed exclusively
//!  tick steps ─► ParportOutput ─► StepEncoder: dir │ +setup: step │ +length: release
//!                   │ Clock: spin until each offset inside the tick
//!                   └─► PortWriter: data/control registers, written only when they change ─┐
//!  gap state ◄── ParportGap ◄── status register: short pin, open pin, filter ◄─────────────┤
//!  inputs ◄── ParportInputs ◄── status register: E-stop, limits, home, probe, wire break ◄─┘
//! ```
//!
//! Three layers, each testable alone:
//! - [`pins`]: the connector. Pin numbers to register bits with the hardware inversions,
//!   the user's pin map and inversions, and the timed writes of one tick. Pure.
//! - [`Port`] and [`Clock`]: the two things the hardware does for us, as small traits.
//!   [`ioctl::Ppdev`] and [`SpinClock`] are the real ones; [`fake`] records every write
//!   with its (virtual) time, so the tests check the byte-level encoding, pin by pin,
//!   against the drive's timing rules.
//! - [`ParportOutput`], [`ParportGap`] and [`ParportInputs`]: the [`PulseOutput`],
//!   [`GapSensor`] and [`MachineInputs`] the runtime uses. They share one port (one file,
//!   one claim) behind an uncontended mutex: they are used by the same thread. The inputs
//!   are read whenever the port is the output, whatever the gap input is.
//!
//! **Safety of the hardware.** The port is opened and claimed before the job starts, so a
//! missing device, a permission problem or a busy port is a startup error with a hint, never
//! a mid-job surprise. Every output is inactive from the moment the port is claimed; the
//! drives are enabled only while an output exists; [`ParportOutput`]'s `Drop` and the
//! port's own `Drop` ([`ioctl::Ppdev`]) drive every output inactive again and release the
//! port, whether the job ended, failed or panicked.
//!
//! **Timing.** Pulses shorter than a tick are timed inside the tick by spinning on
//! `CLOCK_MONOTONIC`: the waits are a few µs, far below what a sleep could hit. Every tick
//! that steps spends `dir_setup_ns + step_length_ns` in the output; the configuration
//! refuses timings that do not fit in a tick.

pub mod fake;
#[allow(unsafe_code)]
pub mod ioctl;
pub mod pins;

use crate::buffer::BlockFlags;
use std::io;
use std::path::Path;
use std::sync::Arc;

use parking_lot::Mutex;

use crate::gap::{GapError, GapSensor, GapState};
use crate::inputs::{InputError, InputReading, MachineInputs};
use crate::output::{OutputError, PulseOutput};
use crate::vocab::MAX_AXES;

pub use ioctl::Ppdev;
pub use pins::{CONDITION_BITS, PinLevels, PinMap, StepEncoder, StepTiming};

/// The port's settings (`[parport]`, validated by the configuration): pins are DB-25 pin
/// numbers, times in ns.
#[derive(Debug, Clone, PartialEq)]
pub struct ParportConfig {
    pub step_pins: Vec<u8>,
    pub dir_pins: Vec<u8>,
    pub enable_pin: Option<u8>,
    /// Flushing output, active while the program's flushing is on (`M7`/`M8`).
    pub flush_pin: Option<u8>,
    /// Spark-enable output, active while the generator may spark.
    pub spark_pin: Option<u8>,
    /// The machining condition's number in binary, least significant bit first.
    pub condition_pins: Vec<u8>,
    pub invert_pins: Vec<u8>,
    pub step_length_ns: u64,
    pub step_space_ns: u64,
    pub dir_setup_ns: u64,
    pub dir_hold_ns: u64,
    pub short_pin: Option<u8>,
    pub open_pin: Option<u8>,
    /// Probe input: contact during a probing move (read unfiltered, like a probe).
    pub probe_pin: Option<u8>,
    /// Wire-break sensor input.
    pub wire_break_pin: Option<u8>,
    /// Emergency-stop input (active: pressed).
    pub estop_pin: Option<u8>,
    /// Limit-switch inputs, each with the axis end it guards.
    pub limit_pins: Vec<(crate::vocab::LimitSwitch, u8)>,
    pub gap_filter_ticks: u32,
}

/// Opening the port failed. Each variant is what an operator needs to fix it.
#[derive(Debug, thiserror::Error)]
pub enum ParportError {
    #[error(
        "{path}: no such parallel port. Load the drivers (`modprobe parport_pc ppdev`, or \
         list them in /etc/modules-load.d) and check `ls /dev/parport*` for the port's name"
    )]
    Missing { path: String },
    #[error(
        "{path}: permission denied. Add the user to group `lp` (`usermod -aG lp USER`, then \
         log in again) or run edmd as its systemd service (SupplementaryGroups=lp); the \
         modules `parport_pc` and `ppdev` must be loaded"
    )]
    PermissionDenied { path: String },
    #[error(
        "{path}: port busy: another driver or program holds it, usually the printer driver \
         `lp` (`rmmod lp`, and blacklist it in /etc/modprobe.d) or another edmd"
    )]
    Busy { path: String },
    #[error(
        "{path}: not a parallel port (the ppdev ioctls fail: {source}); use a ppdev device \
         such as /dev/parport0"
    )]
    NotAParport {
        path: String,
        #[source]
        source: io::Error,
    },
    #[error("{path}: cannot open the parallel port ({step}): {source}")]
    Io {
        path: String,
        step: &'static str,
        #[source]
        source: io::Error,
    },
    /// The port was claimed, but writing the drives' enable level to it failed.
    #[error(transparent)]
    Enable(#[from] OutputError),
}

/// The port's registers, as the ppdev ioctls reach them.
pub trait Port {
    fn write_data(&mut self, value: u8) -> io::Result<()>;
    fn write_control(&mut self, value: u8) -> io::Result<()>;
    fn read_status(&mut self) -> io::Result<u8>;
}

/// Time inside a tick, for the pulse timing.
pub trait Clock {
    fn now_ns(&mut self) -> u64;
    /// Returns once `now_ns() >= deadline_ns`.
    fn wait_until_ns(&mut self, deadline_ns: u64);
}

/// `CLOCK_MONOTONIC`, waiting by spinning.
#[derive(Debug, Clone, Copy, Default)]
pub struct SpinClock;

impl Clock for SpinClock {
    fn now_ns(&mut self) -> u64 {
        crate::sys::monotonic_ns()
    }

    fn wait_until_ns(&mut self, deadline_ns: u64) {
        while crate::sys::monotonic_ns() < deadline_ns {
            std::hint::spin_loop();
        }
    }
}

/// A port with a shadow of its output registers: a register is written only when its value
/// changes, and the shadow only follows a write that succeeded.
#[derive(Debug)]
pub struct PortWriter<P: Port> {
    port: P,
    data: u8,
    control: u8,
}

impl<P: Port> PortWriter<P> {
    /// `port` must hold `levels` already (the safe state written at open).
    pub fn new(port: P, levels: PinLevels) -> PortWriter<P> {
        PortWriter {
            port,
            data: levels.data_register(),
            control: levels.control_register(),
        }
    }

    pub fn apply(&mut self, levels: PinLevels) -> io::Result<()> {
        let data = levels.data_register();
        if data != self.data {
            self.port.write_data(data)?;
            self.data = data;
        }
        let control = levels.control_register();
        if control != self.control {
            self.port.write_control(control)?;
            self.control = control;
        }
        Ok(())
    }

    pub fn read_status(&mut self) -> io::Result<u8> {
        self.port.read_status()
    }

    /// The levels the port holds.
    pub fn levels(&self) -> PinLevels {
        PinLevels::from_registers(self.data, self.control)
    }
}

/// A port shared by the output and the gap input.
pub type SharedPort<P> = Arc<Mutex<PortWriter<P>>>;

/// `output.kind = "parport"`: step/dir pulses on the port's pins.
#[derive(Debug)]
pub struct ParportOutput<P: Port, C: Clock> {
    port: SharedPort<P>,
    clock: C,
    encoder: StepEncoder,
    path: String,
}

impl<P: Port, C: Clock> ParportOutput<P, C> {
    /// Enables the drives (the enable pin, if any) and returns the output.
    pub fn new(
        port: SharedPort<P>,
        map: PinMap,
        timing: StepTiming,
        clock: C,
        path: &str,
    ) -> Result<ParportOutput<P, C>, OutputError> {
        let encoder = StepEncoder::new(map, timing);
        port.lock()
            .apply(encoder.levels())
            .map_err(|source| OutputError::Device {
                path: path.to_string(),
                phase: "enabling the drives",
                step_taken: false,
                source,
            })?;
        Ok(ParportOutput {
            port,
            clock,
            encoder,
            path: path.to_string(),
        })
    }
}

impl<P: Port, C: Clock> PulseOutput for ParportOutput<P, C> {
    fn write(
        &mut self,
        _tick: u64,
        steps: &[i8; MAX_AXES],
        _gap: GapState,
    ) -> Result<(), OutputError> {
        let writes = self.encoder.tick(steps);
        let mut writes = writes.iter().peekable();
        if writes.peek().is_none() {
            return Ok(());
        }
        let start = self.clock.now_ns();
        let mut port = self.port.lock();
        for w in writes {
            self.clock.wait_until_ns(start + w.offset_ns);
            port.apply(w.levels).map_err(|source| OutputError::Device {
                path: self.path.clone(),
                phase: w.phase.name(),
                // The drives step on the edge: once it is out, the step is taken.
                step_taken: w.phase == pins::Phase::StepRelease,
                source,
            })?;
        }
        Ok(())
    }

    fn moving_in(&mut self, now: crate::output::Activity) {
        self.encoder.set_process(
            now.flags.contains(BlockFlags::FLUSH),
            now.spark,
            now.condition,
        );
    }

    /// Every output inactive whatever the reason (the port's enable pin included: a port's
    /// drives are enabled only while a job steps them).
    fn finish(&mut self, _why: crate::output::StopReason) -> Result<(), OutputError> {
        let idle = self.encoder.map().idle();
        self.port
            .lock()
            .apply(idle)
            .map_err(|source| OutputError::Device {
                path: self.path.clone(),
                phase: "driving the outputs inactive",
                step_taken: false,
                source,
            })
    }
}

impl<P: Port, C: Clock> Drop for ParportOutput<P, C> {
    fn drop(&mut self) {
        let idle = self.encoder.map().idle();
        let _ = self.port.lock().apply(idle);
    }
}

/// `gap.kind = "parport"`: the gap state from two status pins.
#[derive(Debug)]
pub struct ParportGap<P: Port> {
    port: SharedPort<P>,
    map: PinMap,
    filter_ticks: u32,
    /// The reading being confirmed, and for how many ticks it has read so.
    candidate: GapState,
    seen: u32,
    /// The believed state; `None` before the first reading.
    state: Option<GapState>,
    path: String,
}

impl<P: Port> ParportGap<P> {
    pub fn new(port: SharedPort<P>, map: PinMap, filter_ticks: u32, path: &str) -> ParportGap<P> {
        ParportGap {
            port,
            map,
            filter_ticks: filter_ticks.max(1),
            candidate: GapState::Normal,
            seen: 0,
            state: None,
            path: path.to_string(),
        }
    }

    /// The gap state a status register value shows (short wins over open).
    pub fn decode(&self, status: u8) -> GapState {
        let active = |pin: Option<u8>| pin.is_some_and(|p| self.map.input_active(status, p));
        if active(self.map.short) {
            GapState::Short
        } else if active(self.map.open) {
            GapState::Open
        } else {
            GapState::Normal
        }
    }
}

impl<P: Port> GapSensor for ParportGap<P> {
    fn sample(&mut self, _tick: u64) -> Result<GapState, GapError> {
        let status = self
            .port
            .lock()
            .read_status()
            .map_err(|source| GapError::Device {
                path: self.path.clone(),
                source,
            })?;
        let reading = self.decode(status);
        if reading == self.candidate {
            self.seen = self.seen.saturating_add(1);
        } else {
            self.candidate = reading;
            self.seen = 1;
        }
        // The first reading is believed at once: there is no earlier state to hold.
        if self.state.is_none() || self.seen >= self.filter_ticks {
            self.state = Some(reading);
        }
        Ok(self.state.unwrap_or(reading))
    }
}

/// The port's machine inputs (E-stop, limit switches, home switches, probe, wire break):
/// read whenever the port is the output, whatever `gap.kind` is.
#[derive(Debug)]
pub struct ParportInputs<P: Port> {
    port: SharedPort<P>,
    map: PinMap,
    /// A homing job's switch: its probing moves read its pin instead of the probe pin.
    home: Option<crate::vocab::HomeSwitch>,
    path: String,
}

impl<P: Port> ParportInputs<P> {
    pub fn new(port: SharedPort<P>, map: PinMap, path: &str) -> ParportInputs<P> {
        ParportInputs {
            port,
            map,
            home: None,
            path: path.to_string(),
        }
    }

    /// The inputs a status register value shows.
    pub fn decode(&self, status: u8) -> InputReading {
        let active = |pin: Option<u8>| pin.is_some_and(|p| self.map.input_active(status, p));
        let mut limits = crate::vocab::LimitSet::EMPTY;
        for &(switch, pin) in &self.map.limits {
            if self.map.input_active(status, pin) {
                limits.insert(switch);
            }
        }
        let contact_pin = match self.home {
            Some(switch) => switch.pin,
            None => self.map.probe,
        };
        InputReading {
            safety: crate::vocab::SafetyInputs {
                estop: active(self.map.estop),
                limits,
            },
            wire_broken: active(self.map.wire_break),
            // A probe's contact (or a home switch) is believed at once, unfiltered: the move
            // stops within the tick.
            contact: contact_pin.map(|p| self.map.input_active(status, p)),
        }
    }
}

impl<P: Port> MachineInputs for ParportInputs<P> {
    fn sample(&mut self, _tick: u64) -> Result<InputReading, InputError> {
        let status = self
            .port
            .lock()
            .read_status()
            .map_err(|source| InputError::Device {
                path: self.path.clone(),
                source,
            })?;
        Ok(self.decode(status))
    }

    fn probe_reads(&mut self, what: crate::vocab::ProbeReads) {
        self.home = match what {
            crate::vocab::ProbeReads::Switch(switch) => Some(switch),
            _ => None,
        };
    }
}

impl PinMap {
    /// The pin map of a machine with `axes` axes on the port of `settings` (validated by the
    /// configuration: pins exist, are of the right kind and carry one signal each).
    pub fn new(axes: usize, settings: &ParportConfig) -> PinMap {
        let p = settings;
        let mut step = [0; MAX_AXES];
        let mut dir = [0; MAX_AXES];
        let used = axes.min(p.step_pins.len()).min(p.dir_pins.len());
        step[..used].copy_from_slice(&p.step_pins[..used]);
        dir[..used].copy_from_slice(&p.dir_pins[..used]);
        PinMap {
            axes,
            step,
            dir,
            enable: p.enable_pin,
            flush: p.flush_pin,
            spark: p.spark_pin,
            condition: {
                let mut pins = [0; CONDITION_BITS];
                for (slot, &pin) in pins.iter_mut().zip(&p.condition_pins) {
                    *slot = pin;
                }
                pins
            },
            condition_bits: p.condition_pins.len().min(CONDITION_BITS) as u8,
            inverted: p.invert_pins.iter().fold(0, |m, &pin| m | 1 << pin),
            short: p.short_pin,
            open: p.open_pin,
            probe: p.probe_pin,
            wire_break: p.wire_break_pin,
            estop: p.estop_pin,
            limits: p.limit_pins.clone(),
        }
    }
}

impl StepTiming {
    /// The drives' timing of `settings`.
    pub fn new(settings: &ParportConfig) -> StepTiming {
        StepTiming {
            step_length_ns: settings.step_length_ns,
            step_space_ns: settings.step_space_ns,
            dir_setup_ns: settings.dir_setup_ns,
            dir_hold_ns: settings.dir_hold_ns,
        }
    }
}

/// The port's three sides, sharing one claim.
pub struct OpenedPort {
    pub output: ParportOutput<Ppdev, SpinClock>,
    /// Used when `gap.kind = "parport"`; dropping it is harmless.
    pub gap: ParportGap<Ppdev>,
    pub inputs: ParportInputs<Ppdev>,
}

/// Opens the port at `path` for a machine with `axes` axes: its output, its gap input and
/// its machine inputs.
pub fn open(
    path: &Path,
    axes: usize,
    settings: &ParportConfig,
) -> Result<OpenedPort, ParportError> {
    let name = path.display().to_string();
    let map = PinMap::new(axes, settings);
    let idle = map.idle();
    let port = Ppdev::open(path, idle.data_register(), idle.control_register())?;
    let shared = Arc::new(Mutex::new(PortWriter::new(port, idle)));
    let gap = ParportGap::new(
        shared.clone(),
        map.clone(),
        settings.gap_filter_ticks,
        &name,
    );
    let inputs = ParportInputs::new(shared.clone(), map.clone(), &name);
    let output = ParportOutput::new(shared, map, StepTiming::new(settings), SpinClock, &name)?;
    tracing::info!(
        "{name}: claimed; {axes} axes, step length {} ns, dir setup {} ns",
        settings.step_length_ns,
        settings.dir_setup_ns
    );
    Ok(OpenedPort {
        output,
        gap,
        inputs,
    })
}

#[cfg(test)]
mod tests;
