//! Technology tables: what a shop picks (the material, the part height and the wire; or the
//! electrode, the work material and the electrode's area) turned into what the machine cuts
//! with (the passes, their offsets, conditions and feeds; the generator's set points).
//!
//! A table is one TOML file in `technology.dir`, the machine builder's data for one material
//! and one wire (or one electrode on one material), with the conditions it uses and its rows.
//! A wire table's rows go by part height, each a pass list (offset, condition, feed, corner
//! control, direction); a sinker table's by electrode area, each a stage list (condition,
//! undersize per side, orbit, jumps). Every file is checked when it is read, each mistake
//! located `file:line:col` as in the main configuration.
//!
//! A request selects one table and a row ([`Tables::select`]); a height between two rows
//! takes the thicker row's passes (a row is made for parts up to its height) with the
//! offset and feed of each pass the two rows cut in one condition interpolated linearly, and
//! the thicker row's own where the thinner row has no such pass. A request outside the
//! table is refused, naming the nearest rows: edmd never extrapolates a technology.
//!
//! The [`Selection`] is applied to the job's copy of the configuration
//! ([`Selection::apply`]): its conditions take the place of `[generator]`'s of the same
//! number, a wire table's passes the place of `[wire] pass`, so the job's path, servo, plan,
//! ETA and generator outputs all read the technology through the one configuration they
//! already read. Never reads a program but its header, never extrapolates, never guesses
//! between two tables that fit.

mod request;
mod select;
mod table;
#[cfg(test)]
mod tests;

use std::path::{Path, PathBuf};

pub use request::{Request, header, header_of};
pub use table::{SinkerTable, Stage, Table, WireTable, parse};

use crate::config::{Condition, Config};
use crate::gcode::Orbit;
use crate::path::WirePass;
use crate::vocab::OrbitShape;

/// Where something is written: `file:line:col`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Place {
    pub file: String,
    pub line: usize,
    pub col: usize,
}

impl std::fmt::Display for Place {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}:{}", self.file, self.line, self.col)
    }
}

/// Why a table could not be read or a request not served.
#[derive(Debug, thiserror::Error)]
pub enum TechError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// The program whose header is looked for cannot be read (said as the reader says it).
    #[error("{}: cannot read the program: {source}", path.display())]
    Program {
        path: PathBuf,
        source: std::io::Error,
    },
    /// A table that does not read.
    #[error("{at}: {message}")]
    Invalid { at: Place, message: String },
    /// A request that does not read.
    #[error("{at}: technology: {message}")]
    Request { at: Place, message: String },
    /// Two tables for the same thing.
    #[error("{second}: the same {what} as {first}: one table for each")]
    Twice {
        what: String,
        first: String,
        second: String,
    },
    /// A request no table serves.
    #[error("technology refused: {message}")]
    Refused { message: String },
}

/// Every table of `technology.dir`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Tables {
    dir: PathBuf,
    tables: Vec<Table>,
}

impl Tables {
    /// Reads every table in `dir`. A missing folder is no tables (a request is then refused
    /// saying so); a table that does not read is an error.
    pub fn load(dir: &Path) -> Result<Tables, TechError> {
        let tables = match table::read_dir(dir) {
            // The folder itself missing: no tables. A table file missing (a dangling link) is
            // an error like any other.
            Err(TechError::Io { path, source })
                if source.kind() == std::io::ErrorKind::NotFound && path == dir =>
            {
                Vec::new()
            }
            other => other?,
        };
        Tables::new(dir, tables)
    }

    /// The tables of `config` (`technology.dir`).
    pub fn of(config: &Config) -> Result<Tables, TechError> {
        Tables::load(&config.technology.dir)
    }

    /// `tables`, as read from `dir`: refused if two are for the same thing.
    pub fn new(dir: &Path, tables: Vec<Table>) -> Result<Tables, TechError> {
        for (i, a) in tables.iter().enumerate() {
            for b in &tables[..i] {
                let same = match (a, b) {
                    (Table::Wire(a), Table::Wire(b)) => {
                        (a.material.eq_ignore_ascii_case(&b.material)
                            && (a.wire_diameter_mm - b.wire_diameter_mm).abs() < 1e-9
                            && a.wire_type.eq_ignore_ascii_case(&b.wire_type))
                        .then(|| {
                            (
                                format!(
                                    "material and wire ({}, {} mm {})",
                                    a.material, a.wire_diameter_mm, a.wire_type
                                ),
                                b.file.clone(),
                                a.file.clone(),
                            )
                        })
                    }
                    (Table::Sinker(a), Table::Sinker(b)) => (a
                        .electrode
                        .eq_ignore_ascii_case(&b.electrode)
                        && a.material.eq_ignore_ascii_case(&b.material))
                    .then(|| {
                        (
                            format!("electrode and material ({} on {})", a.electrode, a.material),
                            b.file.clone(),
                            a.file.clone(),
                        )
                    }),
                    _ => None,
                };
                if let Some((what, first, second)) = same {
                    return Err(TechError::Twice {
                        what,
                        first,
                        second,
                    });
                }
            }
        }
        Ok(Tables {
            dir: dir.to_path_buf(),
            tables,
        })
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn tables(&self) -> &[Table] {
        &self.tables
    }

    /// How many of the tables are the shipped examples.
    pub fn examples(&self) -> usize {
        self.tables
            .iter()
            .filter(|t| match t {
                Table::Wire(w) => w.example,
                Table::Sinker(s) => s.example,
            })
            .count()
    }

    /// What each table is for, as the page's run dialog offers them.
    pub fn summaries(&self) -> Vec<TableSummary> {
        self.tables
            .iter()
            .map(|t| match t {
                Table::Wire(w) => TableSummary {
                    kind: "wire".into(),
                    material: w.material.clone(),
                    wire_mm: Some(w.wire_diameter_mm),
                    wire_type: Some(w.wire_type.clone()),
                    electrode: None,
                    heights_mm: w.rows.iter().map(|r| r.height_mm).collect(),
                    areas_cm2: Vec::new(),
                    file: w.file.clone(),
                    example: w.example,
                },
                Table::Sinker(s) => TableSummary {
                    kind: "sinker".into(),
                    material: s.material.clone(),
                    wire_mm: None,
                    wire_type: None,
                    electrode: Some(s.electrode.clone()),
                    heights_mm: Vec::new(),
                    areas_cm2: s.rows.iter().map(|r| r.area_cm2).collect(),
                    file: s.file.clone(),
                    example: s.example,
                },
            })
            .collect()
    }

    /// One line per table: what it is for, its rows, its file.
    pub fn list(&self) -> Vec<String> {
        self.tables
            .iter()
            .map(|t| match t {
                Table::Wire(w) => format!(
                    "wire    material={} wire={} type={}  heights {} mm  {}{}",
                    w.material,
                    w.wire_diameter_mm,
                    w.wire_type,
                    w.rows
                        .iter()
                        .map(|r| r.height_mm.to_string())
                        .collect::<Vec<_>>()
                        .join(", "),
                    w.file,
                    if w.example { "  (example)" } else { "" }
                ),
                Table::Sinker(s) => format!(
                    "sinker  electrode={} material={}  areas {} cm²  {}{}",
                    s.electrode,
                    s.material,
                    s.rows
                        .iter()
                        .map(|r| format!("{}-{}", r.area_cm2[0], r.area_cm2[1]))
                        .collect::<Vec<_>>()
                        .join(", "),
                    s.file,
                    if s.example { "  (example)" } else { "" }
                ),
            })
            .collect()
    }
}

/// What a table is for: its keys and rows, its file.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TableSummary {
    /// `wire` or `sinker`.
    pub kind: String,
    pub material: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wire_mm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wire_type: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub electrode: Option<String>,
    /// A wire table's row heights, mm.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub heights_mm: Vec<f64>,
    /// A sinker table's row areas, cm².
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub areas_cm2: Vec<[f64; 2]>,
    pub file: String,
    pub example: bool,
}

/// A pass a wire table chose, with the row it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct SelectedPass {
    pub pass: WirePass,
    /// `32 mm, between the 30 and 40 mm rows`, or `30 mm row`.
    pub row: String,
}

/// What a request selected: the table, the rows and why, and what the job cuts with.
#[derive(Debug, Clone, PartialEq)]
pub struct Selection {
    pub request: Request,
    /// The table's file.
    pub table: String,
    pub example: bool,
    /// `steel with 0.25 mm brass wire`, `copper electrode on steel`.
    pub title: String,
    pub description: String,
    /// Which rows were used and why.
    pub why: Vec<String>,
    /// A wire table's passes, first to last.
    pub passes: Vec<SelectedPass>,
    /// A sinker table's stages, rough to finish.
    pub stages: Vec<Stage>,
    /// The conditions the job cuts in, as the table sets them (a wire pass's feed and corner
    /// control are its condition's; a sinker stage's orbit and jumps too).
    pub conditions: Vec<Condition>,
    pub wire_diameter_mm: Option<f64>,
}

impl Selection {
    /// The part's height a wire cut was asked for (mm); none for a sinker.
    pub fn part_height_mm(&self) -> Option<f64> {
        match self.request {
            Request::Wire { height_mm, .. } => Some(height_mm),
            Request::Sinker { .. } => None,
        }
    }

    /// The passes, as `--passes` cuts them.
    pub fn wire_passes(&self) -> Vec<WirePass> {
        self.passes.iter().map(|p| p.pass).collect()
    }

    /// The row each pass came from.
    pub fn pass_rows(&self) -> Vec<String> {
        self.passes.iter().map(|p| p.row.clone()).collect()
    }

    /// `material=steel height=32 wire=0.25 (steel with 0.25 mm brass wire)`: the one line
    /// the status, the history and the report carry.
    pub fn summary(&self) -> String {
        format!("{} ({})", self.request.text(), self.title)
    }

    /// The job's configuration: `config` with the table's conditions in place of any of the
    /// same number, a wire table's passes in place of `[wire] pass` and its wire's diameter,
    /// a sinker stage's orbit for its condition.
    pub fn apply(&self, config: &mut Config) {
        for c in &self.conditions {
            match config.conditions.iter_mut().find(|x| x.number == c.number) {
                Some(x) => *x = c.clone(),
                None => config.conditions.push(c.clone()),
            }
            let orbits = &mut config.sinker.orbit;
            orbits.by_condition.retain(|(n, _)| *n != c.number);
            if c.orbit_radius_mm.is_some() || c.orbit_shape.is_some() {
                let default = orbits.default;
                // A stage that gives a radius orbits: in the machine's shape, a circle where
                // the machine's is none.
                let shape = match (c.orbit_shape, default.shape) {
                    (Some(shape), _) => shape,
                    (None, OrbitShape::None) => OrbitShape::Circle,
                    (None, shape) => shape,
                };
                orbits.by_condition.push((
                    c.number,
                    Orbit {
                        shape,
                        radius_mm: c.orbit_radius_mm.unwrap_or(default.radius_mm),
                    },
                ));
            }
        }
        if !self.passes.is_empty() {
            config.wire.passes = self.wire_passes();
        }
        if let Some(d) = self.wire_diameter_mm {
            config.wire.diameter_mm = d;
        }
    }

    /// What was selected and why, for `edmd tech explain`.
    pub fn explain(&self) -> String {
        use std::fmt::Write as _;
        let mut out = format!(
            "technology: {}\ntable: {} ({})\n",
            self.request.text(),
            self.title,
            self.table
        );
        if self.example {
            out += "  an EXAMPLE table shipped with edmd: replace it with your generator maker's data\n";
        }
        if !self.description.is_empty() {
            let _ = writeln!(out, "  {}", self.description);
        }
        for why in &self.why {
            let _ = writeln!(out, "{why}");
        }
        if !self.passes.is_empty() {
            out += "\npass  condition  offset mm  feed mm/min  direction  from\n";
            for (i, p) in self.passes.iter().enumerate() {
                let _ = writeln!(
                    out,
                    "{:<4}  E{:<8}  {:<9.4}  {:<11.2}  {:<9}  {}",
                    i + 1,
                    p.pass.condition,
                    p.pass.offset_mm,
                    p.pass.feed_mm_per_min.unwrap_or(0.0),
                    if p.pass.reverse { "reverse" } else { "forward" },
                    p.row
                );
            }
        }
        if !self.stages.is_empty() {
            out += "\nstage  condition  undersize mm/side  orbit radius mm  jumps\n";
            for (i, s) in self.stages.iter().enumerate() {
                let jumps = match (s.jump_interval_s, s.jump_height_mm) {
                    (Some(every), Some(height)) => format!("every {every} s, {height} mm"),
                    _ => "the condition's".to_string(),
                };
                let _ = writeln!(
                    out,
                    "{:<5}  E{:<8}  {:<17.3}  {:<15.3}  {jumps}",
                    i + 1,
                    s.condition,
                    s.undersize_mm,
                    s.orbit_radius_mm
                );
            }
        }
        out +=
            "\nconditions (they take the place of [generator]'s of the same number for the job):\n";
        for c in &self.conditions {
            let corner = c.corner.map_or(String::new(), |k| {
                format!(
                    "; corners under {}°: feed × {} over {} mm",
                    k.angle_deg, k.feed_factor, k.distance_mm
                )
            });
            let _ = writeln!(
                out,
                "E{}: {}; sparking feed {} mm/min{corner}",
                c.number,
                c.generator.describe(),
                c.feed_mm_per_min
            );
        }
        out
    }
}
