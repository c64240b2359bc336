//! One technology file read and checked: its TOML, each entry located (`file:line:col`) so a
//! wrong value is found where it is written, as in the main configuration.

use std::path::Path;

use serde::Deserialize;
use toml::Spanned;

use super::{Place, TechError};
use crate::config::{Condition, ConditionSpec, CornerControl, FeedRule};
use crate::vocab::OrbitShape;

/// A wire table: one material, one wire, rows by part height.
#[derive(Debug, Clone, PartialEq)]
pub struct WireTable {
    pub file: String,
    pub example: bool,
    pub description: String,
    pub material: String,
    pub wire_diameter_mm: f64,
    pub wire_type: String,
    /// The conditions its passes name (their feeds are the passes').
    pub conditions: Vec<Condition>,
    /// By height, rising.
    pub rows: Vec<WireRow>,
}

/// A row of a wire table: the passes that cut a part this high.
#[derive(Debug, Clone, PartialEq)]
pub struct WireRow {
    pub at: Place,
    pub height_mm: f64,
    pub passes: Vec<TablePass>,
}

/// A pass of a row.
#[derive(Debug, Clone, PartialEq)]
pub struct TablePass {
    pub offset_mm: f64,
    pub condition: u32,
    /// The cutting feed at this row's height, mm/min.
    pub feed_mm_per_min: f64,
    pub corner: Option<CornerControl>,
    pub reverse: bool,
}

/// A sinker table: one electrode material on one work material, rows by electrode area.
#[derive(Debug, Clone, PartialEq)]
pub struct SinkerTable {
    pub file: String,
    pub example: bool,
    pub description: String,
    pub electrode: String,
    pub material: String,
    pub conditions: Vec<Condition>,
    /// By area, rising, not overlapping.
    pub rows: Vec<SinkerRow>,
}

/// A row of a sinker table: the stages, rough to finish, for electrodes of this area.
#[derive(Debug, Clone, PartialEq)]
pub struct SinkerRow {
    pub at: Place,
    /// Smallest and largest electrode area, cm².
    pub area_cm2: [f64; 2],
    pub stages: Vec<Stage>,
}

/// A stage of a sinker row: the condition it sinks in, the undersize per side the electrode
/// needs for it, the orbit that takes up the rest, and its jumps.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Stage {
    pub condition: u32,
    pub undersize_mm: f64,
    pub orbit_radius_mm: f64,
    #[serde(skip)]
    pub orbit_shape: Option<OrbitShape>,
    pub jump_interval_s: Option<f64>,
    pub jump_height_mm: Option<f64>,
    pub jump_feed_mm_per_min: Option<f64>,
}

/// A table of either kind.
#[derive(Debug, Clone, PartialEq)]
pub enum Table {
    Wire(WireTable),
    Sinker(SinkerTable),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    kind: Spanned<String>,
    #[serde(default)]
    example: bool,
    #[serde(default)]
    description: String,
    material: Spanned<String>,
    wire_diameter_mm: Option<Spanned<f64>>,
    wire_type: Option<Spanned<String>>,
    electrode: Option<Spanned<String>>,
    #[serde(default)]
    condition: Vec<Spanned<ConditionSpec>>,
    #[serde(default)]
    row: Vec<Spanned<RawRow>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRow {
    height_mm: Option<f64>,
    area_cm2: Option<[f64; 2]>,
    pass: Option<Vec<Spanned<RawPass>>>,
    stage: Option<Vec<Spanned<RawStage>>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPass {
    offset_mm: f64,
    condition: i64,
    feed_mm_per_min: f64,
    #[serde(default)]
    reverse: bool,
    corner_angle_deg: Option<f64>,
    corner_feed_factor: Option<f64>,
    corner_distance_mm: Option<f64>,
    corner_dwell_ms: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawStage {
    condition: i64,
    undersize_mm: f64,
    orbit_radius_mm: f64,
    orbit_shape: Option<String>,
    jump_interval_s: Option<f64>,
    jump_height_mm: Option<f64>,
    jump_feed_mm_per_min: Option<f64>,
}

/// Where a byte of `text` is: `file:line:col`.
fn place(file: &str, text: &str, offset: usize) -> Place {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    Place {
        file: file.to_string(),
        line,
        col,
    }
}

/// A table's text being read: where each byte is, for messages.
struct Reader<'a> {
    file: &'a str,
    text: &'a str,
}

impl Reader<'_> {
    fn at(&self, offset: usize) -> Place {
        place(self.file, self.text, offset)
    }

    fn invalid(&self, offset: usize, message: String) -> TechError {
        TechError::Invalid {
            at: self.at(offset),
            message,
        }
    }

    /// A name the table gives (a material, an electrode, a wire type): not empty.
    fn name(&self, s: &Spanned<String>, what: &str) -> Result<String, TechError> {
        let v = s.get_ref().trim();
        if v.is_empty() {
            Err(self.invalid(s.span().start, format!("{what} must not be empty")))
        } else {
            Ok(v.to_string())
        }
    }

    /// Condition `n` of `conditions`, named at `offset`.
    fn defined(&self, conditions: &[Condition], n: i64, offset: usize) -> Result<u32, TechError> {
        conditions
            .iter()
            .find(|c| i64::from(c.number) == n)
            .map(|c| c.number)
            .ok_or_else(|| {
                self.invalid(
                    offset,
                    format!(
                        "condition = {n} is not one of this table's [[condition]] ({})",
                        conditions
                            .iter()
                            .map(|c| format!("E{}", c.number))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                )
            })
    }
}

/// Reads a table's text; `file` names it in messages.
pub fn parse(text: &str, file: &str) -> Result<Table, TechError> {
    let text = crate::vocab::without_bom(text);
    let r = Reader { file, text };
    let mut raw: RawFile = toml::from_str(text).map_err(|e| {
        let offset = e.span().map_or(0, |s| s.start);
        r.invalid(offset, e.message().trim().to_string())
    })?;
    let feed = match raw.kind.get_ref().as_str() {
        "wire" => FeedRule::FromPass,
        "sinker" => FeedRule::Given,
        other => {
            return Err(r.invalid(
                raw.kind.span().start,
                format!("kind = {other:?}: \"wire\" or \"sinker\""),
            ));
        }
    };
    let mut conditions: Vec<Condition> = Vec::new();
    for c in std::mem::take(&mut raw.condition) {
        let start = c.span().start;
        let condition = c
            .into_inner()
            .validate("condition", feed)
            .map_err(|(_, m)| r.invalid(start, m))?;
        if conditions.iter().any(|x| x.number == condition.number) {
            return Err(r.invalid(
                start,
                format!("E{} is defined twice in this table", condition.number),
            ));
        }
        conditions.push(condition);
    }
    if raw.row.is_empty() {
        return Err(r.invalid(0, "a table needs at least one [[row]]".into()));
    }
    match feed {
        FeedRule::FromPass => r.wire(raw, conditions).map(Table::Wire),
        FeedRule::Given => r.sinker(raw, conditions).map(Table::Sinker),
    }
}

impl Reader<'_> {
    fn wire(&self, raw: RawFile, conditions: Vec<Condition>) -> Result<WireTable, TechError> {
        let diameter = raw
            .wire_diameter_mm
            .ok_or_else(|| self.invalid(0, "a wire table needs wire_diameter_mm".into()))?;
        let d = *diameter.get_ref();
        if !(d.is_finite() && d > 0.0 && d <= 2.0) {
            return Err(self.invalid(
                diameter.span().start,
                format!("wire_diameter_mm = {d}: above 0, at most 2 mm"),
            ));
        }
        let wire_type = raw
            .wire_type
            .as_ref()
            .ok_or_else(|| self.invalid(0, "a wire table needs wire_type (\"brass\", …)".into()))?;
        let wire_type = self.name(wire_type, "wire_type")?;
        let at = |offset| self.at(offset);
        let defined = |n, offset| self.defined(&conditions, n, offset);
        let mut rows: Vec<WireRow> = Vec::new();
        for r in raw.row {
            let row = wire_row(r, &at, &defined)?;
            if let Some(last) = rows.last()
                && row.height_mm <= last.height_mm
            {
                return Err(TechError::Invalid {
                    at: row.at,
                    message: format!(
                        "height_mm = {} after the {} mm row: rows go by rising height",
                        row.height_mm, last.height_mm
                    ),
                });
            }
            rows.push(row);
        }
        Ok(WireTable {
            file: self.file.to_string(),
            example: raw.example,
            description: raw.description.trim().to_string(),
            material: self.name(&raw.material, "material")?,
            wire_diameter_mm: d,
            wire_type,
            conditions,
            rows,
        })
    }

    fn sinker(&self, raw: RawFile, conditions: Vec<Condition>) -> Result<SinkerTable, TechError> {
        let electrode = raw.electrode.as_ref().ok_or_else(|| {
            self.invalid(0, "a sinker table needs electrode (its material)".into())
        })?;
        let electrode = self.name(electrode, "electrode")?;
        let at = |offset| self.at(offset);
        let defined = |n, offset| self.defined(&conditions, n, offset);
        let mut rows: Vec<SinkerRow> = Vec::new();
        for r in raw.row {
            let row = sinker_row(r, &at, &defined)?;
            if let Some(last) = rows.last()
                && row.area_cm2[0] < last.area_cm2[1]
            {
                return Err(TechError::Invalid {
                    at: row.at,
                    message: format!(
                        "area_cm2 = {:?} overlaps the row before ({:?}): rows go by rising \
                         area, one row for an area",
                        row.area_cm2, last.area_cm2
                    ),
                });
            }
            rows.push(row);
        }
        Ok(SinkerTable {
            file: self.file.to_string(),
            example: raw.example,
            description: raw.description.trim().to_string(),
            electrode,
            material: self.name(&raw.material, "material")?,
            conditions,
            rows,
        })
    }
}

type Defined<'a> = dyn Fn(i64, usize) -> Result<u32, TechError> + 'a;

fn wire_row(
    r: Spanned<RawRow>,
    at: &dyn Fn(usize) -> Place,
    defined: &Defined,
) -> Result<WireRow, TechError> {
    let row_at = at(r.span().start);
    let bad = |place: &Place, message: String| TechError::Invalid {
        at: place.clone(),
        message,
    };
    let r = r.into_inner();
    if r.area_cm2.is_some() || r.stage.is_some() {
        return Err(bad(
            &row_at,
            "a wire table's row has height_mm and pass, not area_cm2 or stage".into(),
        ));
    }
    let height_mm = r
        .height_mm
        .filter(|h| h.is_finite() && *h > 0.0 && *h <= 1000.0)
        .ok_or_else(|| {
            bad(
                &row_at,
                "height_mm: the part height, above 0, at most 1000 mm".into(),
            )
        })?;
    let raw_passes = r.pass.unwrap_or_default();
    if raw_passes.is_empty() || raw_passes.len() > 20 {
        return Err(bad(
            &row_at,
            "a row needs 1 to 20 passes (pass = [ … ])".into(),
        ));
    }
    let mut passes: Vec<TablePass> = Vec::new();
    for (i, p) in raw_passes.into_iter().enumerate() {
        let start = p.span().start;
        let p_at = at(start);
        let p = p.into_inner();
        let condition = defined(p.condition, start)?;
        if let Some(j) = passes.iter().position(|q| q.condition == condition) {
            return Err(bad(
                &p_at,
                format!(
                    "pass {}: E{condition} cuts pass {} too: a pass's feed and corner control \
                     are its condition's while it cuts, so each pass of a row needs a \
                     condition of its own",
                    i + 1,
                    j + 1
                ),
            ));
        }
        if !(p.offset_mm.is_finite() && (0.0..=10.0).contains(&p.offset_mm)) {
            return Err(bad(
                &p_at,
                format!("pass {}: offset_mm = {}: 0 to 10 mm", i + 1, p.offset_mm),
            ));
        }
        if !(p.feed_mm_per_min.is_finite() && p.feed_mm_per_min > 0.0 && p.feed_mm_per_min <= 1e5) {
            return Err(bad(
                &p_at,
                format!(
                    "pass {}: feed_mm_per_min = {}: above 0, at most 100000",
                    i + 1,
                    p.feed_mm_per_min
                ),
            ));
        }
        let corner = CornerControl::from_keys(
            p.condition,
            [
                p.corner_angle_deg,
                p.corner_feed_factor,
                p.corner_distance_mm,
                p.corner_dwell_ms,
            ],
        )
        .map_err(|(_, m)| bad(&p_at, format!("pass {}: {m}", i + 1)))?;
        passes.push(TablePass {
            offset_mm: p.offset_mm,
            condition,
            feed_mm_per_min: p.feed_mm_per_min,
            corner,
            reverse: p.reverse,
        });
    }
    Ok(WireRow {
        at: row_at,
        height_mm,
        passes,
    })
}

fn sinker_row(
    r: Spanned<RawRow>,
    at: &dyn Fn(usize) -> Place,
    defined: &Defined,
) -> Result<SinkerRow, TechError> {
    let row_at = at(r.span().start);
    let bad = |place: &Place, message: String| TechError::Invalid {
        at: place.clone(),
        message,
    };
    let r = r.into_inner();
    if r.height_mm.is_some() || r.pass.is_some() {
        return Err(bad(
            &row_at,
            "a sinker table's row has area_cm2 and stage, not height_mm or pass".into(),
        ));
    }
    let area_cm2 = r
        .area_cm2
        .filter(|[a, b]| a.is_finite() && b.is_finite() && *a >= 0.0 && a < b && *b <= 1e5)
        .ok_or_else(|| {
            bad(
                &row_at,
                "area_cm2 = [smallest, largest]: the electrode areas this row is for, cm² \
                 (0 ≤ smallest < largest)"
                    .into(),
            )
        })?;
    let raw_stages = r.stage.unwrap_or_default();
    if raw_stages.is_empty() || raw_stages.len() > 20 {
        return Err(bad(
            &row_at,
            "a row needs 1 to 20 stages (stage = [ … ])".into(),
        ));
    }
    let mut stages = Vec::new();
    for (i, s) in raw_stages.into_iter().enumerate() {
        let start = s.span().start;
        let s_at = at(start);
        let s = s.into_inner();
        let n = i + 1;
        let condition = defined(s.condition, start)?;
        let length = |v: f64, what: &str| {
            if v.is_finite() && (0.0..=50.0).contains(&v) {
                Ok(v)
            } else {
                Err(bad(&s_at, format!("stage {n}: {what} = {v}: 0 to 50 mm")))
            }
        };
        let undersize_mm = length(s.undersize_mm, "undersize_mm")?;
        let orbit_radius_mm = length(s.orbit_radius_mm, "orbit_radius_mm")?;
        if orbit_radius_mm > undersize_mm {
            return Err(bad(
                &s_at,
                format!(
                    "stage {n}: orbit_radius_mm = {orbit_radius_mm} is more than the \
                     undersize ({undersize_mm} mm per side): the orbit would cut past size"
                ),
            ));
        }
        let orbit_shape = s
            .orbit_shape
            .map(|t| {
                OrbitShape::parse(&t).ok_or_else(|| {
                    bad(
                        &s_at,
                        format!(
                            "stage {n}: orbit_shape = {t:?}: {}",
                            OrbitShape::ALL.map(|s| s.name()).join(", ")
                        ),
                    )
                })
            })
            .transpose()?;
        let non_negative = |v: Option<f64>, what: &str, max: f64| match v {
            Some(v) if !(v.is_finite() && (0.0..=max).contains(&v)) => {
                Err(bad(&s_at, format!("stage {n}: {what} = {v}: 0 to {max}")))
            }
            v => Ok(v),
        };
        stages.push(Stage {
            condition,
            undersize_mm,
            orbit_radius_mm,
            orbit_shape,
            jump_interval_s: non_negative(s.jump_interval_s, "jump_interval_s", 86_400.0)?,
            jump_height_mm: non_negative(s.jump_height_mm, "jump_height_mm", 1000.0)?,
            jump_feed_mm_per_min: non_negative(
                s.jump_feed_mm_per_min,
                "jump_feed_mm_per_min",
                1e6,
            )?,
        });
    }
    Ok(SinkerRow {
        at: row_at,
        area_cm2,
        stages,
    })
}

/// Reads every `*.toml` of `dir` (any case), in name order. One that is not a readable
/// regular file (a dangling link, a directory, a FIFO) is an error naming it, as one that
/// does not parse is: a table is never skipped silently. Other files are passed over, said
/// in the log.
pub fn read_dir(dir: &Path) -> Result<Vec<Table>, TechError> {
    let io = |source| TechError::Io {
        path: dir.to_path_buf(),
        source,
    };
    let (mut files, others): (Vec<_>, Vec<_>) = std::fs::read_dir(dir)
        .map_err(io)?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .partition(|p| {
            p.extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("toml"))
        });
    files.sort();
    let others: Vec<String> = others
        .iter()
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .filter(|n| !n.starts_with('.'))
        .collect();
    if !others.is_empty() {
        tracing::info!(
            "technology: {} not read (not *.toml): {}",
            dir.display(),
            others.join(", ")
        );
    }
    files
        .iter()
        .map(|path| {
            let text = crate::sys::read_regular(path).map_err(|source| TechError::Io {
                path: path.clone(),
                source,
            })?;
            parse(&text, &path.display().to_string())
        })
        .collect()
}
