//! The shared vocabulary: the few plain types that every floor of edmd speaks.
//!
//! Axis letters, the two predictor and segmentation kinds, the spark gap's state and the
//! tick period are named by the G-code reader, the preprocessor, the tick core, the devices
//! and the configuration alike. They live here, in a module that imports nothing of edmd's,
//! so that no lower floor has to reach up into `config` (or `gap`) for a word: the
//! configuration *reads* these values at the edge and hands them down.
//!
//! Must never: import another edmd module, do I/O, or grow behaviour beyond naming,
//! parsing and converting its own values.

use serde::{Deserialize, Serialize};

/// Most axes a machine (and so a curve) can have.
pub const MAX_AXES: usize = 6;

/// The slowest feed edmd accepts anywhere (mm/min: the G-code `F` word, a jog, the
/// configuration's feeds): a micrometre a minute. Slower is a typing error (`F1e-300`),
/// and a move at it would never end.
pub const MIN_FEED_MM_PER_MIN: f64 = 0.001;

/// A position in steps, one count per axis (the axes a machine lacks stay 0): the unit of the
/// pulse ledger, of step blocks and of checkpoints.
pub type Steps = [i64; MAX_AXES];

/// A machine axis letter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Axis {
    X,
    Y,
    Z,
    A,
    B,
    C,
    U,
    V,
}

impl Axis {
    pub const ALL: [Axis; 8] = [
        Axis::X,
        Axis::Y,
        Axis::Z,
        Axis::A,
        Axis::B,
        Axis::C,
        Axis::U,
        Axis::V,
    ];

    /// The axis for a G-code word letter (upper case), if it is one.
    pub fn from_letter(letter: char) -> Option<Axis> {
        Axis::ALL.into_iter().find(|a| a.letter() == letter)
    }

    pub fn letter(self) -> char {
        match self {
            Axis::X => 'X',
            Axis::Y => 'Y',
            Axis::Z => 'Z',
            Axis::A => 'A',
            Axis::B => 'B',
            Axis::C => 'C',
            Axis::U => 'U',
            Axis::V => 'V',
        }
    }
}

impl std::fmt::Display for Axis {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.letter())
    }
}

/// How the segmenter predicts the next curve parameter (`interpolation.predictor`): the
/// corrected second-order Taylor update, or Hamming's predictor (seed 001), each followed by
/// the Lagrange correction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Predictor {
    Taylor,
    Hamming,
}

/// How a curve is cut into segments (`interpolation.segmentation`): the longest chords within
/// the chord tolerance, or one segment per interpolation period along the planned profile.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Segmentation {
    Chord,
    Period,
}

/// The gap voltages that separate its states: below `short_below` (V) a short, above
/// `open_above` open, sparking in between. One fact for the ADC input, the voltage law and the
/// simulator's voltage (`gap.short_below_v`, `gap.open_above_v`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GapVolts {
    pub short_below: f64,
    pub open_above: f64,
}

impl GapVolts {
    /// The gap state of a gap voltage.
    #[inline]
    pub fn state_of(&self, volts: f64) -> GapState {
        if volts < self.short_below {
            GapState::Short
        } else if volts > self.open_above {
            GapState::Open
        } else {
            GapState::Normal
        }
    }
}

/// The state of the spark gap.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GapState {
    /// Discharging: machine at the normal servo feed.
    Normal,
    /// No discharge: the electrode is too far; close in at the open feed.
    Open,
    /// Short circuit: turn back along the executed path.
    Short,
}

impl GapState {
    /// In the order of the counts by gap state (`gap_ticks`): [`GapState::index`].
    pub const ALL: [GapState; 3] = [GapState::Normal, GapState::Open, GapState::Short];

    /// Where this state stands in [`GapState::ALL`].
    pub fn index(self) -> usize {
        match self {
            GapState::Normal => 0,
            GapState::Open => 1,
            GapState::Short => 2,
        }
    }

    /// `normal`, `open` or `short`, as in the pulse log and gap scripts.
    pub fn name(self) -> &'static str {
        match self {
            GapState::Normal => "normal",
            GapState::Open => "open",
            GapState::Short => "short",
        }
    }

    pub fn from_name(name: &str) -> Option<GapState> {
        match name.to_ascii_lowercase().as_str() {
            "normal" => Some(GapState::Normal),
            "open" => Some(GapState::Open),
            "short" => Some(GapState::Short),
            _ => None,
        }
    }
}

/// The fine interpolator's tick period: the one place a tick is converted to seconds or
/// nanoseconds.
///
/// The configuration gives it in whole microseconds (`fine.tick_us`, 1 to 1,000,000); the
/// tick core integrates speed over [`secs`](Self::secs), the real-time loop sleeps in
/// [`ns`](Self::ns), and reports turn tick counts into seconds with
/// [`ticks_to_secs`](Self::ticks_to_secs). Every conversion goes through these methods, so
/// the rounding is the same everywhere (a pulse log replayed against a summary agrees to the
/// last bit).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TickPeriod {
    us: u32,
}

impl TickPeriod {
    /// Longest period accepted (1 s).
    pub const MAX_US: u32 = 1_000_000;

    /// A period of `us` microseconds, `None` outside 1 to [`MAX_US`](Self::MAX_US).
    pub const fn from_us(us: u32) -> Option<TickPeriod> {
        if us >= 1 && us <= Self::MAX_US {
            Some(TickPeriod { us })
        } else {
            None
        }
    }

    /// The period in whole microseconds (as configured, and as the pulse log records it).
    pub const fn us(self) -> u32 {
        self.us
    }

    /// The period in nanoseconds (the real-time loop's deadlines).
    pub const fn ns(self) -> u64 {
        self.us as u64 * 1000
    }

    /// The period in seconds (the tick core's `dt`).
    pub fn secs(self) -> f64 {
        self.us as f64 * 1e-6
    }

    /// The time `ticks` ticks take, in seconds.
    pub fn ticks_to_secs(self, ticks: u64) -> f64 {
        ticks as f64 * self.secs()
    }
}

impl std::fmt::Display for TickPeriod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} µs", self.us)
    }
}

/// The UTF-8 byte-order mark, which some Windows editors and CAM posts write at the start of
/// a file. It is not text: programs, configurations and gap scripts skip it.
pub const BOM: &str = "\u{feff}";

/// `text` without a leading byte-order mark.
pub fn without_bom(text: &str) -> &str {
    text.strip_prefix(BOM).unwrap_or(text)
}

/// A number in a message, as a person writes it: at most six decimals and no trailing
/// zeros (`0.1`, not `0.10000000000000178`), in scientific notation beyond 10^9 or below
/// 10^-6 (`1e200`, not two hundred digits).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Num(pub f64);

impl std::fmt::Display for Num {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let v = self.0;
        if !v.is_finite() {
            return write!(f, "{v}");
        }
        let trim = |s: String| -> String {
            if s.contains('.') {
                s.trim_end_matches('0').trim_end_matches('.').to_string()
            } else {
                s
            }
        };
        let a = v.abs();
        if a != 0.0 && !(1e-6..1e9).contains(&a) {
            let text = format!("{v:.5e}");
            let (mantissa, exponent) = text.split_once('e').unwrap_or((&text, "0"));
            return write!(f, "{}e{exponent}", trim(mantissa.to_string()));
        }
        let text = trim(format!("{v:.6}"));
        f.write_str(if text == "-0" { "0" } else { &text })
    }
}

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

/// A die-sinker's orbit (planetary motion) around the tool axis while it sinks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum OrbitShape {
    /// No orbit: a straight plunge.
    #[default]
    None,
    Circle,
    Square,
    /// Back and forth along X.
    VectorX,
    /// Back and forth along Y.
    VectorY,
    /// A circle with the tool axis raised on a sphere: a rounded floor.
    Sphere,
}

impl OrbitShape {
    pub const ALL: [OrbitShape; 6] = [
        OrbitShape::None,
        OrbitShape::Circle,
        OrbitShape::Square,
        OrbitShape::VectorX,
        OrbitShape::VectorY,
        OrbitShape::Sphere,
    ];

    /// As the configuration spells it: `none`, `circle`, `square`, `vector-x`, `vector-y`,
    /// `sphere`.
    pub fn name(self) -> &'static str {
        match self {
            OrbitShape::None => "none",
            OrbitShape::Circle => "circle",
            OrbitShape::Square => "square",
            OrbitShape::VectorX => "vector-x",
            OrbitShape::VectorY => "vector-y",
            OrbitShape::Sphere => "sphere",
        }
    }

    pub fn parse(text: &str) -> Option<OrbitShape> {
        OrbitShape::ALL
            .into_iter()
            .find(|s| s.name() == text.trim())
    }
}

/// The wire's two guides. X/Y move the lower guide; U/V are the upper guide's position
/// relative to the lower one, so the wire crosses the program plane at
/// `(x, y) + (u, v) · lower_mm / (lower_mm + upper_mm)`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Guides {
    /// From the lower guide up to the program plane (mm; negative: the plane is below it).
    pub lower_mm: f64,
    /// From the program plane up to the upper guide (mm).
    pub upper_mm: f64,
}

impl Guides {
    /// Lower guide to upper guide (mm).
    pub fn span_mm(&self) -> f64 {
        self.lower_mm + self.upper_mm
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_in_messages_read_as_written() {
        let shown = |v: f64| Num(v).to_string();
        assert_eq!(shown(0.10000000000000178), "0.1");
        assert_eq!(shown(0.15), "0.15");
        assert_eq!(shown(-5.0), "-5");
        assert_eq!(shown(1e200), "1e200");
        assert_eq!(shown(1.5e-9), "1.5e-9");
        assert_eq!(shown(123456.7891234), "123456.789123");
        assert_eq!(shown(-0.0000001), "-1e-7");
        assert_eq!(shown(-0.0), "0");
        assert_eq!(shown(1e9), "1e9");
        assert_eq!(shown(f64::INFINITY), "inf");
    }

    #[test]
    fn axis_letters_round_trip() {
        for axis in Axis::ALL {
            assert_eq!(Axis::from_letter(axis.letter()), Some(axis));
        }
        assert_eq!(Axis::from_letter('W'), None);
    }

    #[test]
    fn gap_state_names_round_trip() {
        for state in [GapState::Normal, GapState::Open, GapState::Short] {
            assert_eq!(GapState::from_name(state.name()), Some(state));
        }
        assert_eq!(GapState::from_name("SHORT"), Some(GapState::Short));
        assert_eq!(GapState::from_name("shorted"), None);
    }

    #[test]
    fn a_leading_bom_is_skipped_and_only_there() {
        assert_eq!(without_bom("\u{feff}G1 X1"), "G1 X1");
        assert_eq!(without_bom("G1 X1"), "G1 X1");
        assert_eq!(without_bom("G1\u{feff}"), "G1\u{feff}");
    }

    #[test]
    fn tick_period_bounds_and_conversions() {
        assert_eq!(TickPeriod::from_us(0), None);
        assert_eq!(TickPeriod::from_us(1_000_001), None);
        let t = TickPeriod::from_us(50).unwrap();
        assert_eq!(t.us(), 50);
        assert_eq!(t.ns(), 50_000);
        // The exact expression every caller used before this type existed.
        let tick_us: u32 = 50;
        assert_eq!(t.secs().to_bits(), (tick_us as f64 * 1e-6).to_bits());
        assert_eq!(t.ticks_to_secs(20_000), 20_000.0 * (50.0 * 1e-6));
        assert_eq!(t.to_string(), "50 µs");
        let max = TickPeriod::from_us(TickPeriod::MAX_US).unwrap();
        assert_eq!(max.ns(), 1_000_000_000);
    }

    /// Every switch of every axis has its own bit; a step is blocked only by the switch it
    /// runs further into, never by one it moves away from or one of another axis.
    #[test]
    fn a_limit_set_blocks_only_motion_into_a_closed_switch() {
        let mut set = LimitSet::EMPTY;
        for axis in Axis::ALL {
            for positive in [false, true] {
                let s = LimitSwitch { axis, positive };
                assert!(!set.contains(s));
                set.insert(s);
                assert!(set.contains(s));
            }
        }
        assert_eq!(set.iter().count(), 16);
        let mut set = LimitSet::EMPTY;
        let x_plus = LimitSwitch::parse("X+").unwrap();
        set.insert(x_plus);
        assert_eq!(set.to_string(), "X+");
        // A machine X, U (U in slot 1).
        let mut axes = [None; MAX_AXES];
        axes[0] = Some(Axis::X);
        axes[1] = Some(Axis::U);
        let steps = |x: i8, u: i8| {
            let mut s = [0; MAX_AXES];
            s[0] = x;
            s[1] = u;
            s
        };
        assert_eq!(set.blocking(&axes, &steps(1, 0)), Some(x_plus));
        assert_eq!(set.blocking(&axes, &steps(1, -1)), Some(x_plus));
        assert_eq!(set.blocking(&axes, &steps(-1, 0)), None, "away");
        assert_eq!(set.blocking(&axes, &steps(0, 1)), None, "another axis");
        assert_eq!(set.blocking(&axes, &steps(0, 0)), None);
        set.remove(x_plus);
        assert!(set.is_empty());
        let u_minus = LimitSwitch::parse("u-").unwrap();
        set.insert(u_minus);
        assert_eq!(set.blocking(&axes, &steps(1, -1)), Some(u_minus));
        let inputs = SafetyInputs {
            estop: false,
            limits: set,
        };
        assert_eq!(Trip::of(inputs), Some(Trip::Limit(u_minus)));
        let both = inputs.merged(SafetyInputs {
            estop: true,
            limits: LimitSet::EMPTY,
        });
        assert_eq!(Trip::of(both), Some(Trip::EStop));
        assert!(both.limits.contains(u_minus));
        for trip in [Trip::EStop, Trip::Limit(u_minus)] {
            assert_eq!(Trip::parse(&trip.name()), Some(trip));
        }
        assert_eq!(Trip::parse("limit"), None);
    }
}
