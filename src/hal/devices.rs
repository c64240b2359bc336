//! The component's three sides, one per trait the consumer's loop takes: the pulse output
//! (`pos-cmd`, the enables, the condition), the gap input and the machine inputs. All three
//! are used from the consumer's thread only; they share the pins.

use std::sync::Arc;

use super::{GapPins, HalSettings, Pins, State};
use crate::buffer::Activity;
use crate::gap::{GapError, GapSensor, GapState};
use crate::inputs::{InputError, InputReading, MachineInputs};
use crate::output::{OutputError, PulseOutput, StopReason};
use crate::vocab::{
    Axis, GapVolts, GeneratorSetPoints, HomeSwitch, LimitSet, LimitSwitch, MAX_AXES, ProbeReads,
    PulseCounts,
};

/// The pulse output: the ledger as `pos-cmd`, checked against `pos-fb`, with the two
/// heartbeats.
#[derive(Debug)]
pub struct HalOutput {
    pins: Arc<Pins>,
    /// Steps given each axis: the drives' position (from where their feedback stood when the
    /// first job began).
    ledger: [i64; MAX_AXES],
    /// The ledger was taken from the drives' feedback (at the first job: HAL nets the pins
    /// after the component is made, so at that moment `pos-fb` may read nothing yet).
    synced: bool,
    /// The feedback did not read 0 when the component was made.
    drives_moved: bool,
    step_mm: Vec<f64>,
    letters: Vec<char>,
    max_following_error_mm: Option<f64>,
    tick_ns: u64,
    /// edmd's heartbeat on `edmd.watchdog`: its level's period and how long it has stood.
    heartbeat_ns: u64,
    beat_for_ns: u64,
    /// HAL's heartbeat on `edmd.rt-beat-in`: the time allowed without a change, the last level
    /// read and how long it has stood.
    rt_beat_timeout_ns: Option<u64>,
    rt_beat: bool,
    rt_beat_for_ns: u64,
}

impl HalOutput {
    pub(super) fn new(pins: Arc<Pins>, settings: &HalSettings) -> HalOutput {
        let rt_beat = pins.rt_beat_in.get();
        let mut output = HalOutput {
            drives_moved: false,
            synced: false,
            pins,
            ledger: [0; MAX_AXES],
            step_mm: settings.step_mm.clone(),
            letters: settings.axes.iter().map(|a| a.letter()).collect(),
            max_following_error_mm: settings.max_following_error_mm,
            tick_ns: settings.tick_ns,
            heartbeat_ns: settings.heartbeat_ns.max(1),
            beat_for_ns: 0,
            rt_beat_timeout_ns: settings.rt_beat_timeout_ns,
            rt_beat,
            rt_beat_for_ns: 0,
        };
        output.sync_to_feedback();
        output.drives_moved = output.ledger.iter().any(|&l| l != 0);
        output
    }

    /// The ledger and `pos-cmd` where the drives' feedback stands (rounded to a step), so the
    /// next command is no jump.
    fn sync_to_feedback(&mut self) {
        for ((l, a), step) in self
            .ledger
            .iter_mut()
            .zip(&self.pins.axes)
            .zip(&self.step_mm)
        {
            let at = a.pos_fb.get() / step;
            *l = if at.is_finite() { at.round() as i64 } else { 0 };
            a.pos_cmd.set(*l as f64 * step);
        }
    }

    /// The drives' feedback did not read 0 when the component was made.
    pub(super) fn drives_moved(&self) -> bool {
        self.drives_moved
    }

    /// The first axis whose feedback is further from the command than the limit, or not a
    /// number at all (a NaN compares as nothing: it must not pass as "not further").
    fn following_error(&self) -> Option<(usize, f64)> {
        let max = self.max_following_error_mm?;
        self.pins.axes.iter().enumerate().find_map(|(i, a)| {
            let error = a.pos_cmd.get() - a.pos_fb.get();
            let within = error.abs().partial_cmp(&max).is_some_and(|o| o.is_le());
            (!within).then_some((i, error))
        })
    }

    /// `elapsed_ns` more of the fine thread's life: `edmd.watchdog` changes level when its
    /// period is up; HAL's heartbeat must have changed within its time-out.
    fn keep_time(&mut self, elapsed_ns: u64) -> Result<(), OutputError> {
        self.beat_for_ns += elapsed_ns;
        if self.beat_for_ns >= self.heartbeat_ns {
            self.beat_for_ns = 0;
            self.pins.watchdog.set(!self.pins.watchdog.get());
        }
        if let Some(timeout) = self.rt_beat_timeout_ns {
            let level = self.pins.rt_beat_in.get();
            if level != self.rt_beat {
                self.rt_beat = level;
                self.rt_beat_for_ns = 0;
            } else {
                self.rt_beat_for_ns += elapsed_ns;
                if self.rt_beat_for_ns > timeout {
                    self.pins.state.set(State::Alarm as i32);
                    return Err(OutputError::HalStopped {
                        still_ms: self.rt_beat_for_ns / 1_000_000,
                    });
                }
            }
        }
        Ok(())
    }

    fn following_error_alarm(&self) -> Result<(), OutputError> {
        match self.following_error() {
            Some((axis, error_mm)) => {
                self.pins.state.set(State::Alarm as i32);
                Err(OutputError::FollowingError {
                    axis: self.letters[axis],
                    error_mm,
                    max_mm: self.max_following_error_mm.unwrap_or_default(),
                })
            }
            None => Ok(()),
        }
    }
}

impl PulseOutput for HalOutput {
    fn write(
        &mut self,
        _tick: u64,
        steps: &[i8; MAX_AXES],
        _gap: GapState,
    ) -> Result<(), OutputError> {
        self.keep_time(self.tick_ns)?;
        // The drives have not reached the last command: this tick's step is not given.
        self.following_error_alarm()?;
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
    }

    /// The first job after the component was made takes up where the drives stand: HAL's
    /// file nets `pos-fb` after `loadusr`, so only now does it read them (a HAL that kept
    /// running after an earlier edmd: stepgen's counts, not 0). The drives are still disabled
    /// here; from now on the ledger is theirs.
    fn prepare(&mut self) {
        if !self.synced {
            self.sync_to_feedback();
            self.synced = true;
        }
    }

    /// The set points on the `edmd.gen.*` pins (no allocation: called from the tick's
    /// thread).
    fn set_points(&mut self, _condition: u16, set: &GeneratorSetPoints) {
        for (pin, (_, value)) in self.pins.generator.iter().zip(set.named()) {
            pin.set(value);
        }
    }

    /// The spark and the flushing go off. The drives stay enabled after a job that ended (the
    /// machine is on, as in LinuxCNC: a position-mode `stepgen` still reaching the last
    /// command finishes it), and go off at once on an E-stop or an alarm.
    fn finish(&mut self, why: StopReason) -> Result<(), OutputError> {
        if why.drives_off() {
            self.pins.enable_out.set(false);
        }
        self.pins.spark_on.set(false);
        self.pins.flush_on.set(false);
        self.pins.state.set(match why {
            StopReason::Alarm => State::Alarm,
            // An alarm's state stays until the next job.
            _ if self.pins.state.get() == State::Alarm as i32 => State::Alarm,
            _ => State::Idle,
        } as i32);
        Ok(())
    }

    /// Between jobs: the heartbeats, and while the drives are enabled the following error
    /// (a drive that faulted or was pushed at a standstill).
    fn idle(&mut self, elapsed_ns: u64) -> Result<(), OutputError> {
        self.keep_time(elapsed_ns)?;
        if self.pins.enable_out.get() {
            self.following_error_alarm()?;
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
    /// The discriminator's counters as last read, and the pulses they gained in the last
    /// tick; `counting` once any counter has moved (an unconnected discriminator counts
    /// nothing, and then the input has no pulses to give).
    counters: Option<[i32; 4]>,
    pulses: PulseCounts,
    counting: bool,
}

impl HalGap {
    pub(super) fn new(pins: Arc<Pins>, settings: &HalSettings) -> HalGap {
        HalGap {
            pins,
            mode: settings.gap,
            volts: settings.volts,
            last_volts: 0.0,
            counters: None,
            pulses: PulseCounts::default(),
            counting: false,
        }
    }

    /// What the discriminator's counters gained since the last tick (wrapping; the first
    /// reading is where they stand, whatever they counted before edmd was there).
    fn count_pulses(&mut self) {
        let now: [i32; 4] = std::array::from_fn(|i| self.pins.gap_pulses[i].get());
        let last = self.counters.replace(now).unwrap_or(now);
        let gained: [u32; 4] = std::array::from_fn(|i| now[i].wrapping_sub(last[i]) as u32);
        let [normal, arc, short, open] = gained;
        self.counting |= gained.iter().any(|&g| g != 0);
        let delay = self.pins.gap_ignition_delay_us.get();
        self.pulses = PulseCounts {
            normal,
            arc,
            short,
            open,
            delay_sum_us: if delay.is_finite() && delay > 0.0 {
                delay * f64::from(normal + arc)
            } else {
                0.0
            },
        };
    }
}

impl GapSensor for HalGap {
    fn sample(&mut self, _tick: u64) -> Result<GapState, GapError> {
        self.count_pulses();
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

    fn pulses(&self) -> Option<PulseCounts> {
        self.counting.then_some(self.pulses)
    }

    fn flushing(&self) -> Option<f64> {
        let f = self.pins.gap_flushing.get();
        (f.is_finite() && f > 0.0).then(|| f.min(1.0))
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
