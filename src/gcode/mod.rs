//! G-code: program text in, motion [`Block`]s out, streamed.
//!
//! [`BlockReader`] pulls lines from any `BufRead`, so a program of hundreds of megabytes is read
//! in constant memory (one line, plus the control points of a NURBS curve until it closes). Each
//! line goes through the lexer ([`lexer`]: words, comments, columns) and then a modal
//! interpreter ([`parser`]) that keeps the state an RS274 controller keeps (units, distance
//! mode, plane, motion mode, feed, position) and turns every motion into a [`Block`] whose path
//! is a [`NurbsCurve`] in millimetres and machine axis order:
//!
//! - `G0`/`G1`: degree-1 curves; `G2`/`G3` (I J K or R, full circles, G17/G18/G19): exact
//!   rational quadratics;
//! - NURBS in three dialects: `G38` (seed 000: `O` degree, `C` point count, `W` weight, knots
//!   clamped uniform on [0, 1] unless every line carries `K`), `G06.2`/`G6.2` (Fanuc: `P` order,
//!   `K` knot, `R` weight, closed by `P` knot-only blocks; LinuxCNC's `Q` ignored), and
//!   `G5.2`…`G5.3` (LinuxCNC: the current position is the first control point, `P` weight, `L`
//!   order defaulting to 3, knots clamped uniform in whole numbers).
//!
//! Anything edmd cannot do exactly is an error with `file:line:col`, never a silent skip. Words
//! that mean nothing on an EDM (`S`, `T`, `M3`–`M9`) are accepted with a [`Warning`].
//!
//! The reader says what the program means and rewrites nothing: each block carries the modes
//! it is cut in (the wire offset, the taper, the condition), and [`crate::path`] makes the
//! wire offset, taper and orbit of them.

mod error;
mod expr;
mod lexer;
mod lines;
mod parser;
mod work;

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

pub use error::{GcodeError, GcodeErrorKind, OPERATOR_MESSAGE, Warning};
pub use expr::{MAX_NESTING, NUMBERED_MAX, PARSER_STACK_BYTES};
pub use lines::MAX_LINE_BYTES;
pub use parser::{
    ARC_RADIUS_TOLERANCE_MM, BlockReader, CURVE_START_TOLERANCE_MM, MAX_CALL_DEPTH,
    MAX_CURVE_POINTS,
};
pub use work::{StartModes, WORK_SYSTEMS, WorkOffsets, WorkStart, WorkSystem};

use crate::geometry::{NurbsCurve, Point};
use crate::vocab::{Axis, Guides, OrbitShape};

/// The three NURBS block forms.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NurbsForm {
    /// Seed 000's `G38 O<degree> C<count> X Y [W]`.
    G38,
    /// Fanuc's `G06.2 P<order> K<knot> X Y [R<weight>]`.
    Fanuc,
    /// LinuxCNC's `G5.2 [X Y] [P<weight>] [L<order>]` … `G5.3`.
    LinuxCnc,
}

impl NurbsForm {
    pub fn name(self) -> &'static str {
        match self {
            NurbsForm::G38 => "G38",
            NurbsForm::Fanuc => "G06.2",
            NurbsForm::LinuxCnc => "G5.2",
        }
    }

    fn inside_name(self) -> &'static str {
        match self {
            NurbsForm::G38 => "inside a G38 curve",
            NurbsForm::Fanuc => "inside a G06.2 curve",
            NurbsForm::LinuxCnc => "inside a G5.2 curve",
        }
    }

    fn weight_letter(self) -> char {
        match self {
            NurbsForm::G38 => 'W',
            NurbsForm::Fanuc => 'R',
            NurbsForm::LinuxCnc => 'P',
        }
    }
}

/// Arc plane.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Plane {
    /// G17
    XY,
    /// G18 (Z then X, so that G2 is clockwise seen from +Y)
    ZX,
    /// G19
    YZ,
}

impl Plane {
    /// The plane's two axes in the order that makes G3 counter-clockwise.
    pub fn axis_letters(self) -> [char; 2] {
        match self {
            Plane::XY => ['X', 'Y'],
            Plane::ZX => ['Z', 'X'],
            Plane::YZ => ['Y', 'Z'],
        }
    }

    /// The centre-offset words for those axes.
    pub fn offset_letters(self) -> [char; 2] {
        match self {
            Plane::XY => ['I', 'J'],
            Plane::ZX => ['K', 'I'],
            Plane::YZ => ['J', 'K'],
        }
    }

    pub fn g_code(self) -> &'static str {
        match self {
            Plane::XY => "G17",
            Plane::ZX => "G18",
            Plane::YZ => "G19",
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Plane::XY => "XY",
            Plane::ZX => "ZX",
            Plane::YZ => "YZ",
        }
    }
}

/// What a block is, with what a report needs to describe it.
#[derive(Debug, Clone, PartialEq)]
pub enum BlockKind {
    Rapid,
    Line,
    Arc {
        center: Point,
        radius: f64,
        /// Radians; positive is counter-clockwise in the plane's axis order.
        sweep: f64,
        plane: Plane,
    },
    Nurbs {
        form: NurbsForm,
    },
    /// `G38.2`…`G38.5`, `G31`: a straight move toward (or away from) contact.
    Probe(Probe),
}

/// What a probing move looks for (LinuxCNC's `G38.x`, Fanuc's `G31`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Probe {
    /// Until contact is lost (`G38.4`, `G38.5`), not until it is made.
    pub away: bool,
    /// Reaching the end point without contact is an error (`G38.2`, `G38.4`).
    pub must_touch: bool,
}

impl Probe {
    /// `G38.2`, `G38.3`, `G38.4` or `G38.5` (`G31` reads as `G38.3`).
    pub fn g_code(self) -> &'static str {
        match (self.away, self.must_touch) {
            (false, true) => "G38.2",
            (false, false) => "G38.3",
            (true, true) => "G38.4",
            (true, false) => "G38.5",
        }
    }
}

impl BlockKind {
    /// The same kind with an arc's sweep times `factor` (a part of it, or run backwards);
    /// every other kind as it is.
    fn sweep_scaled(&self, factor: f64) -> BlockKind {
        match self {
            BlockKind::Arc {
                center,
                radius,
                sweep,
                plane,
            } => BlockKind::Arc {
                center: *center,
                radius: *radius,
                sweep: sweep * factor,
                plane: *plane,
            },
            other => other.clone(),
        }
    }

    /// `rapid`, `line`, `arc` or `nurbs`, as in the trace CSV.
    pub fn name(&self) -> &'static str {
        match self {
            BlockKind::Rapid => "rapid",
            BlockKind::Line => "line",
            BlockKind::Arc { .. } => "arc",
            BlockKind::Nurbs { .. } => "nurbs",
            BlockKind::Probe(_) => "probe",
        }
    }
}

/// The `[program]` options that change how a program reads, and the wire offsets.
#[derive(Debug, Clone, PartialEq)]
pub struct ProgramOptions {
    /// Lines starting with `/` are skipped (the block-delete switch is on).
    pub block_delete: bool,
    /// `M1` pauses (the optional-stop switch is on); otherwise `M1` does nothing.
    pub optional_stop: bool,
    /// A loop that runs more often than this is an error (a runaway loop).
    pub max_loop_iterations: u64,
    /// `D` registers for `G41`/`G42`, mm: `d_mm[k]` is `Dk` (`D0` is 0).
    pub d_mm: Vec<f64>,
    /// How far a NURBS curve's offset polyline may stray from the true offset, mm.
    pub offset_tolerance_mm: f64,
    /// The machining conditions `E<number>` may select.
    pub conditions: Vec<u32>,
    /// Where the wire's guides are (`[wire]`): what a taper (`G51`/`G52`) is computed with.
    pub guides: Guides,
    /// The work's thickness above the program plane (`[wire] thickness_mm`): a taper's
    /// walls end there, so that is where a corner or an arc is checked for gouges.
    pub thickness_mm: f64,
    /// How sinking moves orbit (`[sinker.orbit]`; none by default).
    pub orbit: OrbitOptions,
    /// The machine builder's M-codes (`[[program.mcode]]`): what a vendor's `M50` means here.
    pub mcodes: Vec<VendorM>,
}

/// An M-code of the machine builder's (a wire CAM post's `M50`, `M60`…) and what edmd does
/// for it.
#[derive(Debug, Clone, PartialEq)]
pub struct VendorM {
    pub number: u32,
    pub action: VendorAction,
}

/// What a [`VendorM`] does, of what edmd has.
#[derive(Debug, Clone, PartialEq)]
pub enum VendorAction {
    /// Flushing on (as `M8`) or off (as `M9`).
    Flush(bool),
    /// Select the machining condition (as `E<n>`).
    Condition(u32),
    /// Pause as `M0` does, the message shown to the operator (wire thread or cut by hand,
    /// check the slug).
    Pause(String),
    /// Nothing to do on this machine, with the reason (said once per program).
    Ignore(String),
}

impl Default for ProgramOptions {
    /// LinuxCNC's defaults: block delete off (`/` lines run), optional stop off.
    fn default() -> Self {
        Self {
            block_delete: false,
            optional_stop: false,
            max_loop_iterations: 1_000_000,
            d_mm: vec![0.0],
            offset_tolerance_mm: 0.001,
            conditions: Vec::new(),
            // The shipped `[wire]` guides (config's tests hold the two equal).
            guides: Guides {
                lower_mm: 10.0,
                upper_mm: 40.0,
            },
            thickness_mm: 20.0,
            orbit: OrbitOptions::default(),
            mcodes: Vec::new(),
        }
    }
}

/// A programmed stop before a block's motion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pause {
    /// `M0`: wait for the operator's resume.
    Program,
    /// `M1` with `program.optional_stop` on.
    Optional,
    /// Before a wire contour's tab (set by the job, never by the program): the operator
    /// secures the slug, which the tab's cut frees.
    Slug,
}

/// One motion of the program.
#[derive(Debug, Clone, PartialEq)]
pub struct Block {
    /// Source line where the block starts (a NURBS curve's first line).
    pub line: u64,
    pub kind: BlockKind,
    /// The path, in mm and machine axis order.
    pub curve: NurbsCurve,
    /// Programmed feed limit in mm/min: `None` for rapids and for feed moves before any `F`
    /// (both run at up to the machine's maximum; feed moves as the gap servo allows).
    pub feed_mm_per_min: Option<f64>,
    /// `G4` dwell before the motion, s: the electrode holds its place while the gap sparks.
    pub dwell_s: f64,
    /// `M0`/`M1` before the motion, with the line that asked for it.
    pub pause: Option<(u64, Pause)>,
    /// Flushing (`M7`/`M8` on, `M9` off) during the motion.
    pub flushing: bool,
    /// The machining condition (`E<number>`, modal) in force; 0 before any.
    pub condition: u32,
    /// The move positions with the spark off and the servo out of the loop, whatever its
    /// kind, and where: the approach of a job run from a line, a tabbed run's travel between
    /// passes (set by the job, never by the program); `None`: as the program says.
    pub spark_off: Option<Travel>,
    /// The wire's tilt in force (`G51`/`G52`): the tangent of its angle from vertical, + to
    /// the left of the direction of travel. The path's taper stage turns it into the guides'
    /// X/Y and U/V; a block handed out carries the tilt it was cut with.
    pub taper: f64,
    /// The orbit this sinking move was turned into (its stage: shape, radius, depths).
    pub orbit: Option<OrbitStage>,
    /// The wire offset in force (`G41`/`G42` with its `D`): the path's wire-offset stage
    /// offsets the move by it. `None` with the offset off, and on the exit move (the first
    /// after `G40`), which the stage ends the offset path with.
    pub wire_offset: Option<WireOffset>,
}

/// A wire offset as the program sets it: the side (`G41` left of travel, `G42` right) and
/// the distance, mm (the `D` register's value, never 0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WireOffset {
    pub left: bool,
    pub d_mm: f64,
}

/// An orbit: its shape and radius (the undersize it finishes to), mm.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Orbit {
    pub shape: OrbitShape,
    pub radius_mm: f64,
}

/// How sinking moves orbit (`[sinker.orbit]` and the conditions' own orbits).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct OrbitOptions {
    /// The orbit of a condition that sets none (and of no condition).
    pub default: Orbit,
    /// The speed around the orbit, mm/min: with the sinking feed, how many turns a move makes.
    pub feed_mm_per_min: f64,
    /// The radius grows from nothing at the top of a move to the orbit's at its bottom.
    pub expand: bool,
    /// Conditions with their own orbit (`orbit_shape`, `orbit_radius_mm`), by E number.
    pub by_condition: Vec<(u32, Orbit)>,
}

impl OrbitOptions {
    /// The orbit in force while condition `n` cuts.
    pub fn for_condition(&self, n: u32) -> Orbit {
        self.by_condition
            .iter()
            .find(|(c, _)| *c == n)
            .map_or(self.default, |&(_, o)| o)
    }
}

/// What a sinking move's orbit was (for the stage tables of `plan` and the reports).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OrbitStage {
    pub shape: OrbitShape,
    pub radius_mm: f64,
    /// The tool axis at the top and the bottom of the move (mm, machine coordinates).
    pub from_z: f64,
    pub to_z: f64,
    /// Whole turns made on the way down.
    pub turns: u32,
}

/// Where a spark-off move travels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Travel {
    /// Along a path already cut (the kerf): a rethread's way back may follow it.
    Kerf,
    /// Through the open: a way back ends at it, as at a rapid.
    Open,
}

impl Block {
    /// A motion with no dwell or pause before it and flushing off.
    pub fn new(
        line: u64,
        kind: BlockKind,
        curve: NurbsCurve,
        feed_mm_per_min: Option<f64>,
    ) -> Block {
        Block {
            line,
            kind,
            curve,
            feed_mm_per_min,
            dwell_s: 0.0,
            pause: None,
            flushing: false,
            condition: 0,
            spark_off: None,
            taper: 0.0,
            orbit: None,
            wire_offset: None,
        }
    }

    /// A sinking move along axis `tool` (Z): a feed move (`G1`) straight down it, every other
    /// axis still. An orbit turns one into an orbital path; breakthrough watches one.
    pub fn sinks(&self, tool: usize) -> bool {
        let (p0, p1) = (self.start(), self.end());
        self.kind == BlockKind::Line
            && self.spark_off.is_none()
            && p1[tool] < p0[tool]
            && (0..self.curve.dim()).all(|i| i == tool || (p1[i] - p0[i]).abs() < 1e-9)
    }

    /// The same move run the other way (a pass cut the other way round): the curve reversed,
    /// an arc's sweep negated; no dwell or pause before it (they belonged to the other end).
    pub fn reversed(&self) -> Block {
        Block {
            kind: self.kind.sweep_scaled(-1.0),
            curve: self.curve.reversed(),
            dwell_s: 0.0,
            pause: None,
            ..self.clone()
        }
    }

    /// The move cut in two at `mm` of its length from the start (an arc's sweep shared out
    /// by length); the second part has no dwell or pause before it. `None` unless `mm` lies
    /// strictly inside the move.
    pub fn split_at_length(&self, mm: f64) -> Option<(Block, Block)> {
        let length = self.curve.length();
        if !(mm > 0.0 && mm < length) {
            return None;
        }
        let u = self.curve.u_at_length(mm, 1e-9);
        let (first, second) = self.curve.split_at(u)?;
        let share = |part: f64| self.kind.sweep_scaled(part);
        let before = first.length() / length;
        Some((
            Block {
                kind: share(before),
                curve: first,
                ..self.clone()
            },
            Block {
                kind: share(1.0 - before),
                curve: second,
                dwell_s: 0.0,
                pause: None,
                ..self.clone()
            },
        ))
    }

    pub fn start(&self) -> Point {
        self.curve.start_point()
    }

    pub fn end(&self) -> Point {
        self.curve.end_point()
    }

    /// The block's path length (mm) for the tables and totals of `check`, on a machine of
    /// `axes`: in closed form for an arc or a helix whose curve still runs on its circle
    /// (its radius times its sweep, with the rise of the axes outside the plane), as the
    /// curve's estimate otherwise (a line or a plain arc exactly; a spiral, a NURBS, an arc
    /// the wire offset moved off its circle by quadrature). A helix is a fitted cubic of
    /// many pieces, whose quadrature was two thirds of what `check` spent on one.
    pub fn length_mm(&self, axes: &[Axis]) -> f64 {
        if let BlockKind::Arc {
            center,
            radius,
            sweep,
            plane,
        } = self.kind
        {
            let index = |letter: char| axes.iter().position(|a| a.letter() == letter);
            let [a, b] = plane.axis_letters();
            if let (Some(ia), Some(ib)) = (index(a), index(b)) {
                let (start, end) = (self.start(), self.end());
                let on_circle = |p: &Point| {
                    ((p[ia] - center[ia]).hypot(p[ib] - center[ib]) - radius).abs()
                        <= 1e-9 * radius.max(1.0)
                };
                // And the sweep still takes the start to the end (a trimmed arc's would not).
                let angle = |p: &Point| (p[ib] - center[ib]).atan2(p[ia] - center[ia]);
                let turn = (angle(&start) + sweep - angle(&end)) / std::f64::consts::TAU;
                let swept = (turn - turn.round()).abs() <= 1e-9;
                if on_circle(&start) && on_circle(&end) && swept {
                    let rise = (0..axes.len())
                        .filter(|&i| i != ia && i != ib)
                        .map(|i| (end[i] - start[i]).powi(2))
                        .sum::<f64>()
                        .sqrt();
                    return (radius * sweep.abs()).hypot(rise);
                }
            }
        }
        self.curve.length_estimate()
    }
}

/// Runs `work` on a thread named `name` with [`PARSER_STACK_BYTES`] of stack and returns
/// its result: what parses a program runs there, whatever stack the calling thread has.
pub fn on_parser_stack<T: Send>(name: &str, work: impl FnOnce() -> T + Send) -> std::io::Result<T> {
    std::thread::scope(|s| {
        let handle = std::thread::Builder::new()
            .name(name.to_string())
            .stack_size(PARSER_STACK_BYTES)
            .spawn_scoped(s, work)?;
        Ok(handle
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic)))
    })
}

/// A reader of the program in `file`, already open (by a caller that checked what it
/// opened); errors name the program `name`.
pub fn read_program(
    file: File,
    name: &str,
    axes: &[Axis],
    options: ProgramOptions,
) -> BlockReader<BufReader<File>> {
    BlockReader::with_options(
        BufReader::with_capacity(64 * 1024, file),
        name,
        axes,
        options,
    )
}

/// Opens `path` for streaming with the default [`ProgramOptions`]. Errors name the path as
/// given.
pub fn open_program(
    path: &Path,
    axes: &[Axis],
) -> Result<BlockReader<BufReader<File>>, GcodeError> {
    let name = path.display().to_string();
    open_program_as(path, &name, axes, ProgramOptions::default(), |file| file)
}

/// Opens `path` for streaming through `wrap` (a byte counter, say); errors name the program
/// `name` (the file the operator knows when `path` is a private copy of it).
pub fn open_program_as<R: std::io::Read + std::io::Seek>(
    path: &Path,
    name: &str,
    axes: &[Axis],
    options: ProgramOptions,
    wrap: impl FnOnce(File) -> R,
) -> Result<BlockReader<BufReader<R>>, GcodeError> {
    let file = File::open(path).map_err(|e| GcodeError {
        source_name: name.into(),
        line: 0,
        col: 0,
        kind: GcodeErrorKind::Io(e),
        text: String::new(),
        called_from: None,
    })?;
    Ok(BlockReader::with_options(
        BufReader::with_capacity(64 * 1024, wrap(file)),
        name,
        axes,
        options,
    ))
}
