//! The component's three sides, one per trait the consumer's loop takes: the pulse output
//! (`pos-cmd`, the enables, the condition), the gap input and the machine inputs. All three
//! are used from the consumer's thread only; they share the pins.

use std::sync::Arc;

use super::{GapPins, HalSettings, Pins, State};
use crate::buffer::Activity;
use crate::gap::{GapError, GapSensor, GapState};
use crate::inputs::{InputError, InputReading, MachineInputs};
use crate::output::{OutputError, PulseOutput};
use crate::vocab::{
    Axis, GapVolts, GeneratorSetPoints, HomeSwitch, LimitSet, LimitSwitch, MAX_AXES, ProbeReads,
};

/// The pulse output: the ledger as `pos-cmd`, checked against `pos-fb`.
#[derive(Debug)]
pub struct HalOutput {
    pins: Arc<Pins>,
    /// Steps given each axis since the component started: the drives' position.
    ledger: [i64; MAX_AXES],
    step_mm: Vec<f64>,
    letters: Vec<char>,
    max_following_error_mm: Option<f64>,
    /// The job's conditions' set points, and the condition whose are on the pins.
    generator: Vec<(u32, GeneratorSetPoints)>,
    set_points_of: Option<u16>,
}

impl HalOutput {
    pub(super) fn new(pins: Arc<Pins>, settings: &HalSettings) -> HalOutput {
        HalOutput {
            pins,
            ledger: [0; MAX_AXES],
            step_mm: settings.step_mm.clone(),
            letters: settings.axes.iter().map(|a| a.letter()).collect(),
            max_following_error_mm: settings.max_following_error_mm,
            generator: Vec::new(),
            set_points_of: None,
        }
    }

    /// The set points of `condition` on the `edmd.gen.*` pins (a lookup in the job's short
    /// table, no allocation: called from the tick's thread).
    fn write_set_points(&mut self, condition: u16) {
        if self.set_points_of == Some(condition) {
            return;
        }
        let set = self
            .generator
            .iter()
            .find(|(n, _)| *n == u32::from(condition))
            .map_or_else(GeneratorSetPoints::default, |(_, s)| *s);
        for (pin, (_, value)) in self.pins.generator.iter().zip(set.named()) {
            pin.set(value);
        }
        self.set_points_of = Some(condition);
    }

    /// The first axis whose feedback is further from the command than the limit.
    fn following_error(&self) -> Option<(usize, f64)> {
        let max = self.max_following_error_mm?;
        self.pins.axes.iter().enumerate().find_map(|(i, a)| {
            let error = a.pos_cmd.get() - a.pos_fb.get();
            (error.abs() > max).then_some((i, error))
        })
    }
}

impl PulseOutput for HalOutput {
    fn write(
        &mut self,
        _tick: u64,
        steps: &[i8; MAX_AXES],
        _gap: GapState,
    ) -> Result<(), OutputError> {
        // The drives have not reached the last command: this tick's step is not given.
        if let Some((axis, error_mm)) = self.following_error() {
            self.pins.state.set(State::Alarm as i32);
            return Err(OutputError::FollowingError {
                axis: self.letters[axis],
                error_mm,
                max_mm: self.max_following_error_mm.unwrap_or_default(),
            });
        }
        self.pins.enable_out.set(true);
        for (i, a) in self.pins.axes.iter().enumerate() {
            if steps[i] != 0 {
                self.ledger[i] += i64::from(steps[i]);
                a.pos_cmd.set(self.ledger[i] as f64 * self.step_mm[i]);
            }
        }
        Ok(())
    }

    fn moving_in(&mut self, now: Activity) {
        self.pins.state.set(State::Running as i32);
        self.pins.enable_out.set(true);
        self.pins.spark_on.set(now.spark);
        self.pins
            .flush_on
            .set(now.flags.contains(crate::buffer::BlockFlags::FLUSH));
        self.pins.condition.set(i32::from(now.condition));
        self.write_set_points(now.condition);
    }

    fn conditions(&mut self, table: &[(u32, GeneratorSetPoints)]) {
        self.generator = table.to_vec();
        self.set_points_of = None;
    }

    /// The spark and flushing go off. The drives stay enabled (the machine is on, as in
    /// LinuxCNC: a position-mode `stepgen` still reaching the last command finishes it) but
    /// on an E-stop or an alarm, where they go off at once.
    fn finish(&mut self) -> Result<(), OutputError> {
        let alarm = self.pins.state.get() == State::Alarm as i32;
        if alarm || !self.pins.estop_ok_in.get() {
            self.pins.enable_out.set(false);
        }
        self.pins.spark_on.set(false);
        self.pins.flush_on.set(false);
        if !alarm {
            self.pins.state.set(State::Idle as i32);
        }
        Ok(())
    }
}

/// The gap input: the generator's detection bits, or its gap voltage by the thresholds.
#[derive(Debug)]
pub struct HalGap {
    pins: Arc<Pins>,
    mode: GapPins,
    volts: GapVolts,
    last_volts: f64,
}

impl HalGap {
    pub(super) fn new(pins: Arc<Pins>, settings: &HalSettings) -> HalGap {
        HalGap {
            pins,
            mode: settings.gap,
            volts: settings.volts,
            last_volts: 0.0,
        }
    }
}

impl GapSensor for HalGap {
    fn sample(&mut self, _tick: u64) -> Result<GapState, GapError> {
        Ok(match self.mode {
            GapPins::Bits if self.pins.gap_short.get() => GapState::Short,
            GapPins::Bits if self.pins.gap_open.get() => GapState::Open,
            GapPins::Bits => GapState::Normal,
            GapPins::Voltage => {
                self.last_volts = self.pins.gap_voltage.get();
                self.volts.state_of(self.last_volts)
            }
        })
    }

    fn volts(&self) -> Option<f64> {
        (self.mode == GapPins::Voltage).then_some(self.last_volts)
    }
}

/// The machine inputs: E-stop, limit and home switches, probe, wire break.
#[derive(Debug)]
pub struct HalInputs {
    pins: Arc<Pins>,
    axes: Vec<Axis>,
    /// `probe-in` is wired: probing moves read it (else the gap's short is the contact).
    probe_input: bool,
    /// A homing job's switch: its probing moves read that axis's `home-sw`.
    home: Option<HomeSwitch>,
}

impl HalInputs {
    pub(super) fn new(pins: Arc<Pins>, settings: &HalSettings) -> HalInputs {
        HalInputs {
            pins,
            axes: settings.axes.clone(),
            probe_input: settings.probe_input,
            home: None,
        }
    }
}

impl MachineInputs for HalInputs {
    fn sample(&mut self, _tick: u64) -> Result<InputReading, InputError> {
        let pins = &self.pins;
        let mut limits = LimitSet::EMPTY;
        for (&axis, a) in self.axes.iter().zip(&pins.axes) {
            for (positive, pin) in [(true, &a.pos_lim_sw), (false, &a.neg_lim_sw)] {
                if pin.get() {
                    limits.insert(LimitSwitch { axis, positive });
                }
            }
        }
        // A switch or the probe is believed at once, unfiltered: the move stops in the tick.
        let contact = match self.home {
            Some(switch) => pins.axes.get(switch.axis).map(|a| a.home_sw.get()),
            None => self.probe_input.then(|| pins.probe_in.get()),
        };
        Ok(InputReading {
            safety: crate::vocab::SafetyInputs {
                estop: !pins.estop_ok_in.get(),
                limits,
            },
            wire_broken: pins.wire_break_in.get(),
            contact,
        })
    }

    fn probe_reads(&mut self, what: ProbeReads) {
        self.home = match what {
            ProbeReads::Switch(switch) => Some(switch),
            _ => None,
        };
    }
}
