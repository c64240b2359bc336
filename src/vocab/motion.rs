//! Axes, positions in steps, the wire's guides and the slowest feed: what a motion is made of.

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
