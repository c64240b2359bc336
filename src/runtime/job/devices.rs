//! The machine's two sides, opened from the configuration: the pulse output
//! (`output.kind`: simulated drives, pulse log, parallel port, LinuxCNC's HAL, null) with the
//! machine inputs that come with it (the port's status pins, the HAL component's input pins;
//! none otherwise), and the gap source (`gap.kind`: simulator, script, the port's status
//! pins, the HAL component's gap pins, an ADC, none), each wrapped in the fault injector and
//! the tracer when configured. A simulated gap (the simulator, a script) is a device with
//! two sides: its gap and the inputs of the machine it simulates, read beside the output
//! device's inputs.
//!
//! Everything that can fail at startup fails here, before anything moves. This is the only
//! place that knows which device a kind names; the job runner takes boxed traits.

use std::sync::Arc;

use super::error::JobError;
use super::precheck::Precheck;
use crate::config::{Config, GapKind, OutputKind};
use crate::gap::{AlwaysNormal, GapScript, GapSensor, IioGap};
use crate::inputs::{MachineInputs, NoInputs};
use crate::output::{FaultInjector, NullOutput, PulseLog, PulseLogHeader, PulseOutput};
use crate::sim::{SimMachine, SimSettings};
use crate::trace::{TracedGap, TracedOutput, Tracer};

pub type BoxedOutput = Box<dyn PulseOutput + Send>;
pub type BoxedGap = Box<dyn GapSensor + Send>;
pub type BoxedInputs = Box<dyn MachineInputs + Send>;

/// An opened output, with what comes with it.
pub struct OpenedOutput {
    pub output: BoxedOutput,
    /// The device's own gap input: the port's status pins (`gap.kind = "parport"`), the HAL
    /// component's gap pins (`"hal"`).
    pub port_gap: Option<BoxedGap>,
    /// The machine inputs wired to the output's device: read whatever the gap input is.
    pub inputs: BoxedInputs,
    /// The device's host is to be told it is ready (HAL's `loadusr -W` waits for it): the
    /// daemon sends it once it serves, `edmd run` at once.
    pub ready: Option<crate::hal::ReadySignal>,
    /// Why the machine position is not to be trusted (HAL kept running after an earlier
    /// edmd): [`crate::hal::Opened::distrust`].
    pub distrust: Option<String>,
}

/// An opened gap source, with the inputs side of the machine it simulates.
pub struct OpenedGap {
    pub gap: BoxedGap,
    /// A simulator's or a gap script's E-stop, limits and wire, read beside the machine's
    /// own inputs; `None` for a real gap input.
    pub inputs: Option<BoxedInputs>,
}

/// A job's devices, opened.
pub struct OpenedIo {
    pub output: BoxedOutput,
    pub gap: BoxedGap,
    pub inputs: BoxedInputs,
    /// See [`OpenedGap::inputs`].
    pub gap_inputs: Option<BoxedInputs>,
}

/// Opens the output, the machine inputs and the gap source of `config`, with the fault
/// injector and the tracer when configured: everything that can fail at startup fails here,
/// before anything moves.
pub fn open_io(
    config: &Config,
    check: &Precheck,
    start: &[i64],
    tracer: Option<&Arc<Tracer>>,
) -> Result<OpenedIo, JobError> {
    let opened = open_output(config, start)?;
    if let Some(ready) = opened.ready {
        ready.send()?;
    }
    let gap = open_gap(config, check, opened.port_gap)?;
    let (output, sensor) = wrap_io(config, opened.output, gap.gap, tracer);
    Ok(OpenedIo {
        output,
        gap: sensor,
        inputs: opened.inputs,
        gap_inputs: gap.inputs,
    })
}

/// Opens the pulse output of `config`; a parallel port comes with its status pins (the gap
/// input and the machine inputs), opened together under one claim. `start`: the ledger the
/// job starts from (steps per axis; empty for zero), for the pulse log's header.
pub fn open_output(config: &Config, start: &[i64]) -> Result<OpenedOutput, JobError> {
    let axes = config.machine.axes.len();
    let mut ready = None;
    let mut distrust = None;
    let (output, port_gap, inputs): (BoxedOutput, Option<BoxedGap>, BoxedInputs) =
        match config.output.kind {
            // The simulated drives take every step and report nothing: the ledger is their position.
            OutputKind::Null | OutputKind::Sim => (Box::new(NullOutput), None, Box::new(NoInputs)),
            OutputKind::File => (
                Box::new(PulseLog::create(
                    &config.output.path,
                    &PulseLogHeader {
                        axes: config.machine.axes.clone(),
                        step_mm: config.machine.step_mm.clone(),
                        tick_us: config.fine.tick.us(),
                        start: (0..axes)
                            .map(|i| start.get(i).copied().unwrap_or(0))
                            .collect(),
                    },
                )?),
                None,
                Box::new(NoInputs),
            ),
            OutputKind::Parport => {
                let port = crate::parport::open(&config.output.path, axes, &config.parport)?;
                (
                    Box::new(port.output),
                    Some(Box::new(port.gap)),
                    Box::new(port.inputs),
                )
            }
            OutputKind::Hal => {
                let hal = crate::hal::open(&crate::hal::HalSettings::from_config(config))?;
                ready = Some(hal.ready);
                distrust = hal.distrust;
                (
                    Box::new(hal.output),
                    Some(Box::new(hal.gap)),
                    Box::new(hal.inputs),
                )
            }
        };
    Ok(OpenedOutput {
        output,
        port_gap,
        inputs,
        ready,
        distrust,
    })
}

/// Opens the gap source of `config`; `port_gap` is the parallel port's status pins when the
/// port is open.
pub fn open_gap(
    config: &Config,
    check: &Precheck,
    port_gap: Option<BoxedGap>,
) -> Result<OpenedGap, JobError> {
    let real = |gap: BoxedGap| OpenedGap { gap, inputs: None };
    Ok(match (config.gap.kind, port_gap) {
        (GapKind::Parport | GapKind::Hal, Some(gap)) => real(gap),
        // Validation refuses this combination; a hand-built `Config` gets an error, not a panic.
        (GapKind::Parport | GapKind::Hal, None) => {
            return Err(JobError::Config(
                "gap.kind = \"parport\" or \"hal\" reads the output device's own inputs and \
                 needs output.kind to name that device"
                    .to_string(),
            ));
        }
        (GapKind::None, _) => real(Box::new(AlwaysNormal)),
        (GapKind::Script, _) => {
            let script = GapScript::load(&config.gap.script)?;
            OpenedGap {
                gap: Box::new(script.gap),
                inputs: Some(Box::new(script.inputs)),
            }
        }
        (GapKind::Iio, _) => real(Box::new(IioGap::open(&config.gap.iio, config.gap.volts)?)),
        (GapKind::Sim, _) => {
            let sim = SimMachine::load(&SimSettings::from_config(config), &check.cutting_spans)?;
            OpenedGap {
                gap: Box::new(sim.gap),
                inputs: Some(Box::new(sim.inputs)),
            }
        }
    })
}

/// Wraps the output and the gap source in the fault injector and the tracer, as configured.
pub fn wrap_io(
    config: &Config,
    mut output: BoxedOutput,
    mut gap: BoxedGap,
    tracer: Option<&Arc<Tracer>>,
) -> (BoxedOutput, BoxedGap) {
    if let Some(tick) = config.output.fault_at_tick {
        tracing::warn!("output.fault_at_tick = {tick}: the output will fail at that tick");
        output = Box::new(FaultInjector::new(output, tick));
    }
    if let Some(tracer) = tracer {
        if config.output.trace {
            output = Box::new(TracedOutput::new(output, tracer.clone()));
        }
        if config.gap.trace {
            gap = Box::new(TracedGap::new(gap, tracer.clone()));
        }
    }
    (output, gap)
}
