//! The loop buffer's unit: a step block, its flags, and what the machine is doing while it
//! runs one (`Activity`).

use crate::preprocess::PathLimits;
use crate::vocab::{MAX_AXES, Steps};

/// One block of the loop buffer (seed 000 Fig. 4): a straight move between two lattice points.
///
/// `start` and `end` are absolute step positions, each rounded once from the segment's end
/// point in mm; a block's `start` is the previous block's `end` (the same rounding of the same
/// point), so no rounding error accumulates however long the program is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepBlock {
    /// Position in the program's sequence of blocks (0-based).
    pub seq: u64,
    pub start: Steps,
    pub end: Steps,
    /// Length of the move in mm (the chord between the exact end points).
    pub length_mm: f64,
    /// Planned speeds (mm/s): at the start, at the end, and the cruise limit in between.
    pub v_entry: f64,
    pub v_exit: f64,
    pub v_cruise: f64,
    /// The highest cruise a feed override above 100 % may reach (mm/s): the block's limits
    /// without its programmed feed; at least `v_cruise`.
    pub v_limit: f64,
    /// What the path allows whatever the feed (cruise, and the junctions at both ends): the
    /// limits of a turn-back at the retract feed and of the re-advance after it.
    pub path: PathLimits,
    /// Source line of the G-code block the move belongs to.
    pub line: u64,
    /// Curve parameter at the move's end, in the program's knot units (NURBS blocks; NaN for
    /// lines and arcs). Checkpoints report it; motion never uses it.
    pub u_end: f64,
    pub flags: BlockFlags,
    /// Path length from the program's start to the move's end (mm, forward, chords summed):
    /// how far along the job this move ends, for progress and ETA.
    pub path_end_mm: f64,
    /// Path from the move's end to the end of its G-code block (mm), on spark-off moves
    /// (`RAPID`); 0 on the block's last move and on cuts. A jerk-limited rapid brakes over it.
    pub rest_mm: f64,
    /// Lattice path from the start of the contour (the move after a rapid through the open or
    /// a probing move, or the start hole) to the move's end (mm): how far a rethread's way
    /// back to the start hole has to go.
    pub contour_mm: f64,
    /// `G4` dwell before the move, s (first move of its G-code block only).
    pub dwell_s: f64,
    /// The machining condition the move is cut in (`E<number>`; 0 none). What it sets is
    /// looked up by the tick core's process part when the move is entered.
    pub condition: u16,
    /// The pass of the technology table this move belongs to (1-based; 0: the job does not
    /// run in passes), so a report marks where each pass starts, also after a resume.
    pub pass: u8,
    /// The wire offset this move was offset by (mm; + left of travel, `G41`; − right, `G42`;
    /// 0 without one): what the console shows in force.
    pub wire_offset_mm: f32,
}

/// What a move is besides its geometry: a small set of flags, two bytes in the ring.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct BlockFlags(u16);

impl BlockFlags {
    pub const NONE: BlockFlags = BlockFlags(0);
    /// Last move of its G-code block.
    pub const LAST_OF_BLOCK: BlockFlags = BlockFlags(1);
    /// Part of a rapid (G0).
    pub const RAPID: BlockFlags = BlockFlags(2);
    /// `M0`/`M1`: stop before this move and wait for the operator (first move of its block).
    pub const PAUSE: BlockFlags = BlockFlags(4);
    /// Flushing is on (`M7`/`M8`) during this move.
    pub const FLUSH: BlockFlags = BlockFlags(8);
    /// A probing move (`G38.x`, `G31`): it stops where contact happens (or ends).
    pub const PROBE: BlockFlags = BlockFlags(16);
    /// With `PROBE`: until contact is lost (`G38.4`/`G38.5`), not until it is made.
    pub const PROBE_AWAY: BlockFlags = BlockFlags(32);
    /// With `PROBE`: reaching the end point without contact is an error (`G38.2`/`G38.4`).
    pub const PROBE_MUST: BlockFlags = BlockFlags(64);
    /// The first move of a pass of the technology table.
    pub const PASS_START: BlockFlags = BlockFlags(128);
    /// The move starts at the start hole (a pass that starts there): a rethread's way back
    /// ends at its start.
    pub const START_HOLE: BlockFlags = BlockFlags(256);
    /// The first move of the tab, after the slug is secured (with `PAUSE`).
    pub const TAB: BlockFlags = BlockFlags(512);
    /// With `RAPID`: a spark-off move along a path already cut, not through the open (a
    /// retreat may walk back through it).
    pub const IN_KERF: BlockFlags = BlockFlags(1024);
    /// A drilling move watched for breakthrough (`[sinker] breakthrough`): the producer
    /// waits for where it ends, as after a probing move.
    pub const BREAKTHROUGH: BlockFlags = BlockFlags(2048);
    /// A move of an orbit (`[sinker.orbit]`): a jump lifts off it along the tool axis rather
    /// than back along the spiral it came.
    pub const ORBIT: BlockFlags = BlockFlags(4096);
    /// A move the job made, not the program: the approach of a run from a line (with
    /// `RAPID`). Single block does not stop before it.
    pub const APPROACH: BlockFlags = BlockFlags(8192);

    /// Every flag of `other` is set.
    pub const fn contains(self, other: BlockFlags) -> bool {
        self.0 & other.0 == other.0
    }

    /// Some flag of `other` is set.
    pub const fn intersects(self, other: BlockFlags) -> bool {
        self.0 & other.0 != 0
    }
}

impl std::ops::BitOr for BlockFlags {
    type Output = BlockFlags;
    fn bitor(self, other: BlockFlags) -> BlockFlags {
        BlockFlags(self.0 | other.0)
    }
}

impl std::ops::BitOrAssign for BlockFlags {
    fn bitor_assign(&mut self, other: BlockFlags) {
        self.0 |= other.0;
    }
}

/// What the machine is doing, as the consumer's thread loop tells the output and the gap
/// input when it changes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Activity {
    /// The move in hand's flags (rapid, flushing, probing, …).
    pub flags: BlockFlags,
    /// The generator is off for an excursion (a jump, a rethread and the ways there and
    /// back), whatever the move.
    pub excursion: bool,
    /// The generator sparks: a cutting move in hand, not held, not over, no excursion.
    pub spark: bool,
    /// The machining condition in force (`E<number>`; 0 none).
    pub condition: u16,
    /// Changes whenever the generator's set points in force do (a new condition, or one
    /// adapted during the cut): the output is due to be told them.
    pub set_points: u32,
}

impl StepBlock {
    /// An all-zero block (a placeholder for preallocated storage).
    pub const EMPTY: StepBlock = StepBlock {
        seq: 0,
        start: [0; MAX_AXES],
        end: [0; MAX_AXES],
        length_mm: 0.0,
        v_entry: 0.0,
        v_exit: 0.0,
        v_cruise: 0.0,
        v_limit: 0.0,
        path: PathLimits::ZERO,
        line: 0,
        u_end: f64::NAN,
        flags: BlockFlags::NONE,
        path_end_mm: 0.0,
        rest_mm: 0.0,
        contour_mm: 0.0,
        dwell_s: 0.0,
        condition: 0,
        pass: 0,
        wire_offset_mm: 0.0,
    };

    /// Signed step count of each axis.
    pub fn delta(&self) -> Steps {
        std::array::from_fn(|i| self.end[i] - self.start[i])
    }

    /// Steps of the axis that moves most: the number of Bresenham step events of the block.
    pub fn events(&self) -> u64 {
        self.delta()
            .iter()
            .map(|d| d.unsigned_abs())
            .max()
            .unwrap_or(0)
    }
}
