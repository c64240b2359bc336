//! The machine's safety words: limit switches and the set of those closed, the E-stop and
//! limits read together, what tripped the machine, home switches and what a probing move
//! reads as its contact.

use super::motion::{Axis, MAX_AXES, Steps};

/// A limit switch: its axis and its end of travel (`positive`: the upper one).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LimitSwitch {
    pub axis: Axis,
    pub positive: bool,
}

impl LimitSwitch {
    /// `X+`, `y-`: an axis letter and its side.
    pub fn parse(text: &str) -> Option<LimitSwitch> {
        let mut chars = text.chars();
        let axis = Axis::from_letter(chars.next()?.to_ascii_uppercase())?;
        let positive = match (chars.next()?, chars.next()) {
            ('+', None) => true,
            ('-', None) => false,
            _ => return None,
        };
        Some(LimitSwitch { axis, positive })
    }
}

impl std::fmt::Display for LimitSwitch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}{}", self.axis, if self.positive { '+' } else { '-' })
    }
}

/// The limit switches that read closed: one bit per axis end (`Axis` index × 2, `+1` for
/// the upper end), so every switch of a machine fits and motion can be told apart by axis
/// and direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LimitSet(u16);

impl LimitSet {
    pub const EMPTY: LimitSet = LimitSet(0);

    fn bit(switch: LimitSwitch) -> u16 {
        1 << (switch.axis as usize * 2 + usize::from(switch.positive))
    }

    pub fn insert(&mut self, switch: LimitSwitch) {
        self.0 |= Self::bit(switch);
    }

    pub fn remove(&mut self, switch: LimitSwitch) {
        self.0 &= !Self::bit(switch);
    }

    pub fn contains(self, switch: LimitSwitch) -> bool {
        self.0 & Self::bit(switch) != 0
    }

    pub fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// The set as bits (two per axis, in [`Axis`] order: negative, positive), for an atomic.
    pub fn bits(self) -> u16 {
        self.0
    }

    pub fn from_bits(bits: u16) -> LimitSet {
        LimitSet(bits)
    }

    /// The switches of `self` that are not in `other`.
    #[inline]
    pub fn without(self, other: LimitSet) -> LimitSet {
        LimitSet(self.0 & !other.0)
    }

    /// The closed switches, X− first.
    pub fn iter(self) -> impl Iterator<Item = LimitSwitch> {
        Axis::ALL
            .into_iter()
            .flat_map(|axis| [false, true].map(|positive| LimitSwitch { axis, positive }))
            .filter(move |&s| self.contains(s))
    }

    /// The first closed switch that a tick's `steps` (machine axis order, `axes` naming
    /// them) would move further into: motion away from a closed switch, and motion of other
    /// axes, is allowed, as LinuxCNC allows it.
    #[inline]
    pub fn blocking(
        self,
        axes: &[Option<Axis>; MAX_AXES],
        steps: &[i8; MAX_AXES],
    ) -> Option<LimitSwitch> {
        if self.0 == 0 {
            return None;
        }
        for (axis, &step) in axes.iter().zip(steps) {
            if let Some(axis) = *axis
                && step != 0
            {
                let switch = LimitSwitch {
                    axis,
                    positive: step > 0,
                };
                if self.contains(switch) {
                    return Some(switch);
                }
            }
        }
        None
    }
}

impl std::fmt::Display for LimitSet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let names: Vec<String> = self.iter().map(|s| s.to_string()).collect();
        f.write_str(&names.join(" "))
    }
}

/// The machine's safety inputs, read at every tick: the emergency stop and the limit
/// switches. An E-stop stops motion within the tick it is seen; a limit switch stops motion
/// that would go further into it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SafetyInputs {
    pub estop: bool,
    pub limits: LimitSet,
}

impl SafetyInputs {
    /// Something that stops motion is active.
    pub fn tripped(self) -> bool {
        self.estop || !self.limits.is_empty()
    }

    /// Both readings: what either source reads active is active.
    pub fn merged(self, other: SafetyInputs) -> SafetyInputs {
        SafetyInputs {
            estop: self.estop || other.estop,
            limits: LimitSet(self.limits.0 | other.limits.0),
        }
    }
}

/// What stopped the machine and holds it: an E-stop, or a limit switch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Trip {
    /// Nothing moves until the input is released and `reset` is given.
    EStop,
    /// Only motion away from the switch moves, until it opens.
    Limit(LimitSwitch),
}

impl Trip {
    /// What the inputs show, the E-stop first.
    pub fn of(inputs: SafetyInputs) -> Option<Trip> {
        if inputs.estop {
            Some(Trip::EStop)
        } else {
            inputs.limits.iter().next().map(Trip::Limit)
        }
    }

    /// The state file's word: `estop`, or the switch (`X+`).
    pub fn name(self) -> String {
        match self {
            Trip::EStop => "estop".to_string(),
            Trip::Limit(switch) => switch.to_string(),
        }
    }

    pub fn parse(text: &str) -> Option<Trip> {
        match text {
            "estop" => Some(Trip::EStop),
            _ => LimitSwitch::parse(text).map(Trip::Limit),
        }
    }
}

/// The home switch a homing job searches for: its probing moves stop on this switch instead
/// of the probe. Each gap input takes what it has of it: the parallel port reads `pin`, the
/// simulator places a switch `at_steps` from where the job starts on `axis` (pressed from
/// there on in the search direction), a script answers as scripted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HomeSwitch {
    /// Index of the axis in `machine.axes`.
    pub axis: usize,
    /// The search runs towards +.
    pub positive: bool,
    /// The port's status pin; `None` on a machine with no switch wired for this axis.
    pub pin: Option<u8>,
    /// The simulated switch, in steps from the job's start on `axis`.
    pub at_steps: i64,
}

/// What a job's probing moves read as their contact. Each gap input takes what it has of
/// it: the parallel port reads a home switch's pin (else the probe's), the simulator
/// answers from its model, a script as scripted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ProbeReads {
    /// The probe (the work, through the gap): a program's `G38`.
    #[default]
    Probe,
    /// A homing job's switch.
    Switch(HomeSwitch),
    /// A wire-touch cycle's move (`edmd ctl find`): the probe, as always; the simulator
    /// answers from its part (`sim.part_edge_mm`, `sim.hole_*`) with the wire at `start`
    /// (the machine position in steps where the job starts). `bounce`: the cycle's first
    /// approach, which the simulator's `touch_bounce_mm` disturbs.
    Touch { start: Steps, bounce: bool },
}
