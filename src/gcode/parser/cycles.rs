//! The canned cycles, as LinuxCNC's interpreter makes them (`interp_cycles.cc`): blocks that
//! make several moves (as `G28`/`G30` do, in [`super::offsets`]):
//!
//! - the canned cycles `G81`, `G82`, `G83`, `G73` in the XY plane, for EDM hole drilling
//!   and a sinker's pecks: at each hole a rapid over it, a rapid down to the R plane, the
//!   plunge at the feed (under the servo, like any feed move; `G83` and `G73` in pecks of
//!   `Q`), and a rapid out to the R plane (`G99`, the default) or the level the series of
//!   cycles started at (`G98`). `R`, `Z`, `P` and `Q` hold until the mode changes; `L`
//!   repeats a hole (in `G91`, each one `X Y` further, or with `@ ^` each one that much
//!   further round the origin, as LinuxCNC's `hole-circle.ngc` drills a bolt circle);
//!
//! Never under the wire offset (LinuxCNC refuses them with cutter compensation).

use super::axes::MachineAxes;
use super::codes::Cycle;
use super::state::{BlockEnv, InterpState};
use super::{Fail, Letters, Step};
use crate::gcode::error::GcodeErrorKind;
use crate::gcode::{Block, BlockKind, Plane};
use crate::geometry::{NurbsCurve, Point};
use crate::vocab::Axis;

/// How far above the last peck `G83` and `G73` come back down (or back off) at the rapid,
/// mm, unless the block gives `D`: LinuxCNC 2.9's `G83_RAPID_DELTA`, 0.010 inch. (Its later
/// versions default to 1 mm on a mm machine and take `D`, as edmd does.)
const PECK_CLEARANCE_MM: f64 = 0.010 * super::MM_PER_INCH;

/// A canned cycle's block: its moves, made in `moves` (from `state`'s position), which
/// `state` moves to the last of. `continuing`: the block is in the mode the last one set (its
/// `R`, `Z`, `P`, `Q` hold).
pub(super) fn cycle_moves(
    state: &mut InterpState,
    env: &mut BlockEnv,
    cycle: Cycle,
    continuing: bool,
    letters: &Letters,
    col: usize,
    mut moves: MoveList,
) -> Step<Vec<Block>> {
    let words = cycle_words(state, env.axes, cycle, continuing, letters, col)?;
    let start = state.position;
    let offset = state.offset();
    let s = state.scale();
    let [ix, iy, iz] = words.axes;
    let first_level = *state.cycle.initial_level.get_or_insert(start[iz]);
    let incremental = state.modal.incremental;
    let (r, bottom) = if incremental {
        let r = words.r * s + first_level;
        (r, r + words.z * s)
    } else {
        (words.r * s + offset[iz], words.z * s + offset[iz])
    };
    // The R plane and the bottom in the program's units, where LinuxCNC steps the pecks.
    let units = if incremental {
        let r = (first_level - offset[iz]) / s + words.r;
        PeckUnits {
            r,
            bottom: r + words.z,
            scale: s,
            origin: offset[iz],
        }
    } else {
        PeckUnits {
            r: words.r,
            bottom: words.z,
            scale: s,
            origin: offset[iz],
        }
    };
    if r < bottom {
        return Err(cycle_fail(
            col,
            format!("{}: the R plane is below the bottom Z", cycle.g_code()),
        ));
    }
    let feed = env.feed_limit(state, col);
    // Each hole from the last: in G91 the block's X Y (or its polar @ ^, about the origin)
    // added to where the last one was; in G90 the same point each time.
    let next_hole = |[x, y]: [f64; 2]| -> Step<[f64; 2]> {
        let mut from = start;
        (from[ix], from[iy]) = (x, y);
        let (to, _) = env.target(state, &from, letters, "Z")?;
        Ok([to[ix], to[iy]])
    };
    let clear = state.cycle.retract_to_initial;
    let holes = Holes {
        from: [start[ix], start[iy]],
        count: words.repeats,
    };
    drill(
        &mut moves,
        cycle,
        (&words, &units),
        (holes, next_hole),
        [first_level, r, bottom],
        clear,
        feed,
        col,
    )?;
    state.cycle.r = words.r;
    state.cycle.z = words.z;
    state.cycle.p = words.p;
    state.cycle.q = words.q;
    state.position = moves.at();
    Ok(moves.blocks)
}

/// A cycle block's words, checked, with those the last block held where it has none.
fn cycle_words(
    state: &InterpState,
    axes: &MachineAxes,
    cycle: Cycle,
    continuing: bool,
    letters: &Letters,
    col: usize,
) -> Step<CycleWords> {
    let code = cycle.g_code();
    let own = match cycle {
        Cycle::Drill => "RL",
        Cycle::DwellAtBottom => "RLP",
        Cycle::Peck | Cycle::ChipBreak => "RLQD",
    };
    axes.check_letters_with(letters, true, &|c| own.contains(c), &|| {
        format!("with {code}")
    })?;
    if state.modal.wire_offset.engaged() {
        return Err(cycle_fail(
            col,
            format!("{code} cannot run with the wire offset on (G40 first)"),
        ));
    }
    if state.modal.plane != Plane::XY {
        let plane = state.modal.plane.g_code();
        return Err(cycle_fail(
            col,
            format!("{code} in {plane}: edmd's canned cycles plunge along Z, in G17"),
        ));
    }
    let index = |axis| axes.iter().position(|&a| a == axis);
    let (Some(ix), Some(iy), Some(iz)) = (index(Axis::X), index(Axis::Y), index(Axis::Z)) else {
        let list = axes.list();
        return Err(cycle_fail(
            col,
            format!("{code} needs the axes X, Y and Z (machine.axes has {list})"),
        ));
    };
    let held = &state.cycle;
    let word = |letter: char, held: f64, name: &str| -> Step<f64> {
        match letters.get(letter) {
            Some(w) => Ok(w.value),
            None if continuing => Ok(held),
            None => Err(cycle_fail(col, format!("{code} needs {letter}, {name}"))),
        }
    };
    let at = |letter: char| letters.get(letter).map_or(col, |w| w.col);
    let z = word('Z', held.z, "the bottom of the hole")?;
    let r = word('R', held.r, "the R plane the plunge starts from")?;
    let p = match cycle {
        Cycle::DwellAtBottom => word('P', held.p, "the dwell at the bottom (s)")?,
        _ => held.p,
    };
    if !(0.0..=86_400.0).contains(&p) {
        return Err(cycle_fail(
            at('P'),
            format!("{code}'s dwell P is 0 to 86400 s"),
        ));
    }
    let q = match cycle {
        Cycle::Peck | Cycle::ChipBreak => word('Q', held.q, "the depth of each peck")?,
        _ => held.q,
    };
    if matches!(cycle, Cycle::Peck | Cycle::ChipBreak) && q <= 0.0 {
        return Err(cycle_fail(
            at('Q'),
            format!("{code}'s peck Q must be more than 0"),
        ));
    }
    let repeats = match letters.get('L') {
        Some(l) => super::whole_as(l, 1.0, 1e6, "a cycle's repeat count L")? as u32,
        None => 1,
    };
    let s = state.scale();
    Ok(CycleWords {
        axes: [ix, iy, iz],
        r,
        z,
        p,
        q,
        repeats,
        clearance_mm: letters.get('D').map_or(PECK_CLEARANCE_MM, |d| d.value * s),
    })
}

fn cycle_fail(col: usize, what: String) -> Fail {
    Fail::from((col, GcodeErrorKind::Cycle(what)))
}

/// A cycle block's words: the axes' indices (X, Y, Z), `R`, `Z`, `P`, `Q` as written
/// (program units), the repeats, the peck clearance in mm.
struct CycleWords {
    axes: [usize; 3],
    r: f64,
    z: f64,
    p: f64,
    q: f64,
    repeats: u32,
    clearance_mm: f64,
}

/// A cycle's R plane and bottom in the program's units (its `Z` axis, work coordinates), and
/// the way back to machine mm: the pecks are stepped there, as LinuxCNC's `G83` loop does
/// (`depth -= Q` while `depth > bottom`), so a depth that is an exact multiple of `Q` in
/// inches pecks as often as it does.
struct PeckUnits {
    r: f64,
    bottom: f64,
    scale: f64,
    origin: f64,
}

/// Where the holes start from (machine X, Y: where the block starts) and how many there are
/// (`L`); each is found from the last by the block's words.
struct Holes {
    from: [f64; 2],
    count: u32,
}

/// The moves of a cycle (LinuxCNC's `CYCLE_MACRO` and `convert_cycle_g8x`): from the level
/// the series started at up to R if below it, then at each hole over it, down to R, the
/// plunge (in pecks for `G83`/`G73`), out to R or (`to_initial`) the initial level.
#[allow(clippy::too_many_arguments)]
fn drill(
    moves: &mut MoveList,
    cycle: Cycle,
    (words, units): (&CycleWords, &PeckUnits),
    (holes, mut next_hole): (Holes, impl FnMut([f64; 2]) -> Step<[f64; 2]>),
    [first_level, r, bottom]: [f64; 3],
    to_initial: bool,
    feed: Option<f64>,
    col: usize,
) -> Step<()> {
    let [ix, iy, iz] = words.axes;
    let mut level = first_level;
    if level < r {
        moves.to(col, &[(iz, r)])?;
        level = r;
    }
    let clear = if to_initial { level } else { r };
    let mut hole = holes.from;
    for k in 0..holes.count {
        hole = next_hole(hole)?;
        let [x, y] = hole;
        if k == 0 && moves.at()[iz] > r {
            moves.to(col, &[(ix, x), (iy, y)])?;
        } else {
            moves.to(col, &[(ix, x), (iy, y), (iz, clear)])?;
        }
        moves.to(col, &[(iz, r)])?;
        if matches!(cycle, Cycle::Peck | Cycle::ChipBreak) {
            let mut depth_u = units.r - words.q;
            while depth_u > units.bottom {
                let depth = depth_u * units.scale + units.origin;
                moves.feed_to(col, &[(iz, depth)], feed)?;
                if cycle == Cycle::Peck {
                    moves.to(col, &[(iz, r)])?;
                }
                moves.to(col, &[(iz, depth + words.clearance_mm)])?;
                depth_u -= words.q;
            }
        }
        moves.feed_to(col, &[(iz, bottom)], feed)?;
        if cycle == Cycle::DwellAtBottom {
            moves.dwell_s = words.p;
        }
        moves.to(col, &[(iz, clear)])?;
    }
    Ok(())
}

/// Moves being built from where the last one ended.
pub(super) struct MoveList {
    at: Point,
    /// A dwell for the next move to wait (`G82`'s at the bottom).
    dwell_s: f64,
    blocks: Vec<Block>,
    line: u64,
    axes: usize,
}

impl MoveList {
    /// No moves yet, from `at`, on line `line`, on a machine of `axes` axes, made into
    /// `reuse` (emptied; its room kept from the last block that made moves).
    pub(super) fn new(at: Point, line: u64, axes: usize, mut reuse: Vec<Block>) -> MoveList {
        reuse.clear();
        MoveList {
            at,
            dwell_s: 0.0,
            blocks: reuse,
            line,
            axes,
        }
    }

    /// Where the last move ends.
    pub(super) fn at(&self) -> Point {
        self.at
    }

    /// The moves.
    pub(super) fn into_blocks(self) -> Vec<Block> {
        self.blocks
    }

    /// A rapid setting the axes `to` (index, mm); a move that goes nowhere is left out.
    pub(super) fn to(&mut self, col: usize, to: &[(usize, f64)]) -> Step<()> {
        self.straight(col, to, BlockKind::Rapid, None)
    }

    /// A feed move (at `feed`, `None`: no `F` programmed) setting the axes `to`.
    fn feed_to(&mut self, col: usize, to: &[(usize, f64)], feed: Option<f64>) -> Step<()> {
        self.straight(col, to, BlockKind::Line, feed)
    }

    fn straight(
        &mut self,
        col: usize,
        to: &[(usize, f64)],
        kind: BlockKind,
        feed: Option<f64>,
    ) -> Step<()> {
        let mut target = self.at;
        for &(i, v) in to {
            target[i] = v;
        }
        if target == self.at {
            return Ok(());
        }
        let curve = NurbsCurve::line(self.axes, &self.at, &target)
            .map_err(|e| Fail::from((col, e.into())))?;
        let mut block = Block::new(self.line, kind, curve, feed);
        block.dwell_s = std::mem::take(&mut self.dwell_s);
        self.blocks.push(block);
        self.at = target;
        Ok(())
    }
}
