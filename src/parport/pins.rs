//! The DB-25 connector of the PC parallel port, as registers see it, and the step/dir
//! encoding of one tick. Pure: no I/O, no clock.
//!
//! ```text
//!  data register    D0..D7  ─► pins 2..9                     (as written)
//!  control register C0 ─► pin 1 (nStrobe)   C1 ─► pin 14 (nAutoFeed)
//!                   C2 ─► pin 16 (nInit)    C3 ─► pin 17 (nSelectIn)
//!                   the port's hardware inverts C0, C1 and C3: a 1 bit is a low pin
//!  status register  S3 ◄─ pin 15 (nError)   S4 ◄─ pin 13 (Select)   S5 ◄─ pin 12 (PaperOut)
//!                   S6 ◄─ pin 10 (nAck)     S7 ◄─ pin 11 (Busy, inverted: a 1 bit is a low pin)
//! ```
//!
//! Everything above this module speaks in pin levels ([`PinLevels`], bit `p` = pin `p` high),
//! so a pin map never needs to know which register a pin lives in or which of them the
//! hardware inverts. The user's own inversions (`parport.invert_pins`, for drives that want
//! active-low steps) are a second, separate layer: [`PinMap::level`] turns a logical signal
//! (step active, direction positive, short present) into a pin level.

use crate::vocab::MAX_AXES;

/// A DB-25 pin number.
pub type Pin = u8;

/// Output pins: the data pins 2–9 and the control pins 1, 14, 16, 17.
pub const OUTPUT_PINS: [Pin; 12] = [1, 2, 3, 4, 5, 6, 7, 8, 9, 14, 16, 17];
/// Input pins: the status pins.
pub const INPUT_PINS: [Pin; 5] = [10, 11, 12, 13, 15];

/// Control register bits the port hardware inverts (C0, C1, C3).
pub const CONTROL_HW_INVERTED: u8 = 0b1011;
/// Status register bits the port hardware inverts (S7, Busy).
pub const STATUS_HW_INVERTED: u8 = 0b1000_0000;

pub fn is_output_pin(pin: i64) -> bool {
    OUTPUT_PINS.iter().any(|&p| p as i64 == pin)
}

pub fn is_input_pin(pin: i64) -> bool {
    INPUT_PINS.iter().any(|&p| p as i64 == pin)
}

/// The control register bit of a control pin.
fn control_bit(pin: Pin) -> Option<u8> {
    match pin {
        1 => Some(0),
        14 => Some(1),
        16 => Some(2),
        17 => Some(3),
        _ => None,
    }
}

/// The status register bit of a status pin.
fn status_bit(pin: Pin) -> Option<u8> {
    match pin {
        15 => Some(3),
        13 => Some(4),
        12 => Some(5),
        10 => Some(6),
        11 => Some(7),
        _ => None,
    }
}

/// Levels of the output pins: bit `p` set means pin `p` is high.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct PinLevels(pub u32);

impl PinLevels {
    pub fn is_high(self, pin: Pin) -> bool {
        self.0 >> pin & 1 == 1
    }

    pub fn set(&mut self, pin: Pin, high: bool) {
        if high {
            self.0 |= 1 << pin;
        } else {
            self.0 &= !(1 << pin);
        }
    }

    /// The data register value that puts pins 2–9 at these levels.
    pub fn data_register(self) -> u8 {
        (self.0 >> 2) as u8
    }

    /// The control register value that puts pins 1, 14, 16 and 17 at these levels (the
    /// hardware inversions undone).
    pub fn control_register(self) -> u8 {
        let mut reg = 0u8;
        for pin in [1, 14, 16, 17] {
            if self.is_high(pin) {
                reg |= 1 << control_bit(pin).unwrap_or(0);
            }
        }
        reg ^ CONTROL_HW_INVERTED
    }

    /// The output pin levels that register values produce (the inverse of
    /// [`data_register`](Self::data_register) and [`control_register`](Self::control_register)).
    pub fn from_registers(data: u8, control: u8) -> PinLevels {
        let mut levels = PinLevels((data as u32) << 2);
        let control = (control ^ CONTROL_HW_INVERTED) & 0x0f;
        for pin in [1, 14, 16, 17] {
            levels.set(pin, control >> control_bit(pin).unwrap_or(0) & 1 == 1);
        }
        levels
    }
}

/// The level of status pin `pin` in a status register value (`None` for a pin that is not a
/// status pin).
fn status_pin_high(status: u8, pin: Pin) -> Option<bool> {
    let bit = status_bit(pin)?;
    Some((status ^ STATUS_HW_INVERTED) >> bit & 1 == 1)
}

/// The status register value that shows input pins at these levels (bit `p` = pin `p` high):
/// what a port reads back; for fakes and tests.
pub fn status_register(levels: PinLevels) -> u8 {
    let mut reg = 0u8;
    for pin in INPUT_PINS {
        if levels.is_high(pin) {
            reg |= 1 << status_bit(pin).unwrap_or(0);
        }
    }
    // Bits 0-2 are reserved and read back as 1 on most ports; keep the fake honest.
    (reg ^ STATUS_HW_INVERTED) | 0b111
}

/// Most condition-select pins.
pub const CONDITION_BITS: usize = 10;

/// Which pin carries which signal, and which pins are active low. Validated by the
/// configuration: every pin exists, outputs are outputs, no pin is used twice.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PinMap {
    /// Axes in use (the first `axes` entries of `step` and `dir`).
    pub axes: usize,
    pub step: [Pin; MAX_AXES],
    pub dir: [Pin; MAX_AXES],
    pub enable: Option<Pin>,
    /// Flushing on (`M7`/`M8`) while active; inactive when idle.
    pub flush: Option<Pin>,
    /// Spark enable while active; inactive when idle.
    pub spark: Option<Pin>,
    /// Condition-select pins, least significant bit first (the first `condition_bits`).
    pub condition: [Pin; CONDITION_BITS],
    pub condition_bits: u8,
    /// Bit `p` set: pin `p` is active low.
    pub inverted: u32,
    pub short: Option<Pin>,
    pub open: Option<Pin>,
    pub probe: Option<Pin>,
    pub wire_break: Option<Pin>,
    pub estop: Option<Pin>,
    /// Limit switches and their pins (a port has five inputs, so a short list).
    pub limits: Vec<(crate::vocab::LimitSwitch, Pin)>,
}

impl PinMap {
    pub fn condition_pins(&self) -> &[Pin] {
        &self.condition[..self.condition_bits as usize]
    }

    fn is_inverted(&self, pin: Pin) -> bool {
        self.inverted >> pin & 1 == 1
    }

    /// The pin level that makes the signal on `pin` logically `active`.
    pub fn level(&self, pin: Pin, active: bool) -> bool {
        active != self.is_inverted(pin)
    }

    /// Every output inactive: steps released, directions at their inactive level, enable
    /// off, unused pins low. What the port shows before a job and after it, whatever
    /// happened.
    pub fn idle(&self) -> PinLevels {
        let mut levels = PinLevels::default();
        for axis in 0..self.axes {
            levels.set(self.step[axis], self.level(self.step[axis], false));
            levels.set(self.dir[axis], self.level(self.dir[axis], false));
        }
        for pin in [self.enable, self.flush, self.spark].into_iter().flatten() {
            levels.set(pin, self.level(pin, false));
        }
        for &pin in self.condition_pins() {
            levels.set(pin, self.level(pin, false));
        }
        levels
    }

    /// [`idle`](Self::idle) with the drives enabled: the state while a job runs.
    pub fn ready(&self) -> PinLevels {
        let mut levels = self.idle();
        if let Some(pin) = self.enable {
            levels.set(pin, self.level(pin, true));
        }
        levels
    }

    /// Whether the logical signal on input `pin` is active in `status`.
    pub fn input_active(&self, status: u8, pin: Pin) -> bool {
        status_pin_high(status, pin).is_some_and(|high| high != self.is_inverted(pin))
    }
}

/// Step timing of the drives, ns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StepTiming {
    pub step_length_ns: u64,
    pub step_space_ns: u64,
    pub dir_setup_ns: u64,
    pub dir_hold_ns: u64,
}

impl StepTiming {
    /// The shortest tick that honours every constraint with a step in every tick and a
    /// direction change in any of them (see [`StepEncoder`]).
    pub fn min_tick_ns(&self) -> u64 {
        (self.dir_setup_ns + self.step_length_ns + self.dir_hold_ns)
            .max(self.step_length_ns + self.step_space_ns)
    }
}

/// Which write of a tick: an output that fails says which, because a failure after the step
/// edge means the step was taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// The process pins (flushing, spark, condition) change in a tick without steps.
    Flush,
    Direction,
    StepEdge,
    StepRelease,
}

impl Phase {
    pub fn name(self) -> &'static str {
        match self {
            Phase::Flush => "setting the process pins (flushing, spark, condition)",
            Phase::Direction => "setting the direction pins",
            Phase::StepEdge => "raising the step pins",
            Phase::StepRelease => "releasing the step pins",
        }
    }
}

/// One write of a tick: at `offset_ns` after the tick starts, put the pins at `levels`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TimedWrite {
    pub offset_ns: u64,
    pub levels: PinLevels,
    pub phase: Phase,
}

/// A tick's writes, in time order (at most three; no allocation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TickWrites {
    writes: [Option<TimedWrite>; 3],
}

impl TickWrites {
    pub fn iter(&self) -> impl Iterator<Item = &TimedWrite> {
        self.writes.iter().flatten()
    }

    fn push(&mut self, write: TimedWrite) {
        if let Some(slot) = self.writes.iter_mut().find(|w| w.is_none()) {
            *slot = Some(write);
        }
    }
}

/// Turns each tick's signed steps into timed pin writes.
///
/// Every tick that steps has the same shape, so step edges are exactly one tick apart at
/// steady speed (no jitter from whether the direction changed):
///
/// ```text
///  tick start      +dir_setup            +dir_setup+step_length                next tick
///  │ dir pins       │ step pins active    │ step pins released                  │
///  ▼ (if changed)   ▼                     ▼                                     ▼
///  ├─ dir_setup ────┼── step_length ──────┼── ≥ dir_hold, ≥ step_space ─────────┤
/// ```
///
/// With `dir_setup + step_length + dir_hold ≤ tick` and `step_length + step_space ≤ tick`
/// (checked by the configuration), a direction change at the next tick's start is at least
/// `dir_hold` after this release and the next step edge at least `step_space` after it, and
/// every pulse ends inside its own tick: nothing spills into the next one.
#[derive(Debug, Clone)]
pub struct StepEncoder {
    map: PinMap,
    timing: StepTiming,
    levels: PinLevels,
    /// The direction each dir pin shows: 1 positive, -1 negative, 0 never driven.
    dir: [i8; MAX_AXES],
    /// A process pin (flushing, spark, condition) changed since the last write.
    process_changed: bool,
}

impl StepEncoder {
    pub fn new(map: PinMap, timing: StepTiming) -> StepEncoder {
        StepEncoder {
            levels: map.ready(),
            map,
            timing,
            dir: [0; MAX_AXES],
            process_changed: false,
        }
    }

    /// The process outputs from the next tick on: flushing, spark enable, and the condition
    /// number on the condition-select pins (pins the map does not have are skipped).
    pub fn set_process(&mut self, flush: bool, spark: bool, condition: u16) {
        let mut wanted: [(Option<Pin>, bool); 2 + CONDITION_BITS] =
            [(None, false); 2 + CONDITION_BITS];
        wanted[0] = (self.map.flush, flush);
        wanted[1] = (self.map.spark, spark);
        for (bit, &pin) in self.map.condition_pins().iter().enumerate() {
            wanted[2 + bit] = (Some(pin), condition >> bit & 1 == 1);
        }
        for (pin, active) in wanted {
            if let Some(pin) = pin {
                let level = self.map.level(pin, active);
                if self.levels.is_high(pin) != level {
                    self.levels.set(pin, level);
                    self.process_changed = true;
                }
            }
        }
    }

    pub fn map(&self) -> &PinMap {
        &self.map
    }

    /// The levels the pins are at between ticks.
    pub fn levels(&self) -> PinLevels {
        self.levels
    }

    /// The writes for a tick with these steps (-1, 0, 1 per axis); empty when nothing steps.
    pub fn tick(&mut self, steps: &[i8; MAX_AXES]) -> TickWrites {
        let mut out = TickWrites::default();
        let process_changed = std::mem::take(&mut self.process_changed);
        if steps[..self.map.axes].iter().all(|&s| s == 0) {
            if process_changed {
                out.push(TimedWrite {
                    offset_ns: 0,
                    levels: self.levels,
                    phase: Phase::Flush,
                });
            }
            return out;
        }
        let mut levels = self.levels;
        let mut dir_changed = false;
        for (axis, &s) in steps[..self.map.axes].iter().enumerate() {
            if s != 0 && s != self.dir[axis] {
                levels.set(
                    self.map.dir[axis],
                    self.map.level(self.map.dir[axis], s > 0),
                );
                self.dir[axis] = s;
                dir_changed = true;
            }
        }
        if dir_changed {
            out.push(TimedWrite {
                offset_ns: 0,
                levels,
                phase: Phase::Direction,
            });
        }
        let released = levels;
        for (axis, &s) in steps[..self.map.axes].iter().enumerate() {
            if s != 0 {
                levels.set(
                    self.map.step[axis],
                    self.map.level(self.map.step[axis], true),
                );
            }
        }
        out.push(TimedWrite {
            offset_ns: self.timing.dir_setup_ns,
            levels,
            phase: Phase::StepEdge,
        });
        out.push(TimedWrite {
            offset_ns: self.timing.dir_setup_ns + self.timing.step_length_ns,
            levels: released,
            phase: Phase::StepRelease,
        });
        self.levels = released;
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn registers_and_levels_round_trip_with_the_hardware_inversions() {
        for raw in [0u32, 0x3fe, 0x2_4002, 0x3_43fe, 0x1_4000] {
            let mut levels = PinLevels::default();
            for pin in OUTPUT_PINS {
                levels.set(pin, raw >> pin & 1 == 1);
            }
            let back = PinLevels::from_registers(levels.data_register(), levels.control_register());
            assert_eq!(back, levels);
        }
        // All pins low: data 0; control bits of the inverted pins 1, 14, 17 set, pin 16's clear.
        assert_eq!(PinLevels::default().control_register(), 0b1011);
        // Pin 1 high alone: C0 cleared (inverted), the others still at their low setting.
        let mut one = PinLevels::default();
        one.set(1, true);
        assert_eq!(one.control_register(), 0b1010);
        let mut sixteen = PinLevels::default();
        sixteen.set(16, true);
        assert_eq!(sixteen.control_register(), 0b1111);
        let mut two_and_nine = PinLevels::default();
        two_and_nine.set(2, true);
        two_and_nine.set(9, true);
        assert_eq!(two_and_nine.data_register(), 0b1000_0001);
    }

    #[test]
    fn status_pins_decode_with_busy_inverted() {
        // Busy (pin 11) reads as S7 = 0 when the pin is high.
        assert_eq!(status_pin_high(0b0000_0000, 11), Some(true));
        assert_eq!(status_pin_high(0b1000_0000, 11), Some(false));
        assert_eq!(status_pin_high(0b0100_0000, 10), Some(true));
        assert_eq!(status_pin_high(0b0000_1000, 15), Some(true));
        assert_eq!(status_pin_high(0b0001_0000, 13), Some(true));
        assert_eq!(status_pin_high(0b0010_0000, 12), Some(true));
        assert_eq!(status_pin_high(0xff, 2), None);
        for pin in INPUT_PINS {
            let mut levels = PinLevels::default();
            levels.set(pin, true);
            let reg = status_register(levels);
            for other in INPUT_PINS {
                assert_eq!(status_pin_high(reg, other), Some(other == pin));
            }
        }
    }

    fn map(inverted: &[Pin]) -> PinMap {
        PinMap {
            axes: 2,
            step: [2, 4, 6, 8, 0, 0],
            dir: [3, 5, 7, 9, 0, 0],
            enable: Some(1),
            flush: None,
            spark: None,
            condition: [0; CONDITION_BITS],
            condition_bits: 0,
            inverted: inverted.iter().fold(0, |m, &p| m | 1 << p),
            short: Some(10),
            open: Some(11),
            probe: None,
            wire_break: None,
            estop: None,
            limits: Vec::new(),
        }
    }

    #[test]
    fn idle_is_every_output_inactive_with_inversions() {
        let plain = map(&[]);
        assert_eq!(plain.idle(), PinLevels::default());
        assert!(plain.ready().is_high(1));
        let inv = map(&[2, 5, 1]);
        let idle = inv.idle();
        assert!(idle.is_high(2), "active-low step idles high");
        assert!(idle.is_high(5), "inverted dir idles high");
        assert!(idle.is_high(1), "active-low enable idles high");
        assert!(!inv.ready().is_high(1));
        assert!(!idle.is_high(3) && !idle.is_high(4));
    }

    #[test]
    fn a_tick_writes_direction_then_step_then_release() {
        let timing = StepTiming {
            step_length_ns: 5000,
            step_space_ns: 5000,
            dir_setup_ns: 20000,
            dir_hold_ns: 20000,
        };
        let mut enc = StepEncoder::new(map(&[4]), timing);
        let w: Vec<TimedWrite> = enc.tick(&[1, -1, 0, 0, 0, 0]).iter().copied().collect();
        assert_eq!(w.len(), 3);
        assert_eq!(w[0].phase, Phase::Direction);
        assert_eq!(w[0].offset_ns, 0);
        assert!(w[0].levels.is_high(3), "X positive");
        assert!(!w[0].levels.is_high(5), "Y negative");
        assert!(
            !w[0].levels.is_high(2) && w[0].levels.is_high(4),
            "steps still idle"
        );
        assert_eq!((w[1].phase, w[1].offset_ns), (Phase::StepEdge, 20000));
        assert!(
            w[1].levels.is_high(2) && !w[1].levels.is_high(4),
            "Y's step is active low"
        );
        assert_eq!((w[2].phase, w[2].offset_ns), (Phase::StepRelease, 25000));
        assert_eq!(w[2].levels, w[0].levels);
        // Same directions again: no direction write, the step edge at the same offset.
        let w: Vec<TimedWrite> = enc.tick(&[1, 0, 0, 0, 0, 0]).iter().copied().collect();
        assert_eq!(w.len(), 2);
        assert_eq!(w[0].offset_ns, 20000);
        assert!(enc.tick(&[0; MAX_AXES]).iter().next().is_none());
        assert_eq!(timing.min_tick_ns(), 45000);
    }
}
