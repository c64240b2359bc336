//! Choosing from the tables: the table a request names, the row (or the two rows) its height
//! or area falls on, and what the job cuts with, each choice with its reason.

use super::table::{SinkerTable, Stage, Table, TablePass, WireRow, WireTable};
use super::{Request, SelectedPass, Selection, Tables, TechError};
use crate::config::Condition;
use crate::path::WirePass;

/// Two numbers a table and a request both write are the same one.
const SAME: f64 = 1e-6;

fn eq(a: &str, b: &str) -> bool {
    a.trim().eq_ignore_ascii_case(b.trim())
}

/// `30 mm (file:41)`.
fn row_name(row: &WireRow) -> String {
    format!("{} mm ({})", row.height_mm, row.at)
}

impl Tables {
    /// What `request` selects, or why nothing does (naming what is nearest).
    pub fn select(&self, request: &Request) -> Result<Selection, TechError> {
        if self.tables.is_empty() {
            return Err(TechError::Refused {
                message: format!(
                    "there are no technology tables in {} (technology.dir)",
                    self.dir.display()
                ),
            });
        }
        match request {
            Request::Wire {
                material,
                height_mm,
                wire_mm,
                wire_type,
            } => {
                let table = self.wire_table(material, *wire_mm, wire_type.as_deref())?;
                select_wire(table, request, *height_mm)
            }
            Request::Sinker {
                electrode,
                material,
                area_cm2,
            } => {
                let table = self.sinker_table(electrode, material)?;
                select_sinker(table, request, *area_cm2)
            }
        }
    }

    fn refused(&self, message: String) -> TechError {
        TechError::Refused {
            message: format!("{message} (tables in {})", self.dir.display()),
        }
    }

    fn wire_tables(&self) -> impl Iterator<Item = &WireTable> {
        self.tables.iter().filter_map(|t| match t {
            Table::Wire(w) => Some(w),
            Table::Sinker(_) => None,
        })
    }

    fn wire_table(
        &self,
        material: &str,
        wire_mm: f64,
        wire_type: Option<&str>,
    ) -> Result<&WireTable, TechError> {
        let describe = |t: &WireTable| {
            format!(
                "{} with {} mm {} wire ({})",
                t.material, t.wire_diameter_mm, t.wire_type, t.file
            )
        };
        let of_material: Vec<&WireTable> = self
            .wire_tables()
            .filter(|t| eq(&t.material, material))
            .collect();
        if of_material.is_empty() {
            let have: Vec<String> = self.wire_tables().map(describe).collect();
            return Err(self.refused(format!(
                "no wire table for material {material:?}: the tables are for {}",
                list_or_none(&have)
            )));
        }
        let fits: Vec<&WireTable> = of_material
            .iter()
            .copied()
            .filter(|t| (t.wire_diameter_mm - wire_mm).abs() <= SAME)
            .filter(|t| wire_type.is_none_or(|w| eq(&t.wire_type, w)))
            .collect();
        match fits.as_slice() {
            [one] => Ok(one),
            [] => {
                let mut near = of_material.clone();
                near.sort_by(|a, b| {
                    (a.wire_diameter_mm - wire_mm)
                        .abs()
                        .total_cmp(&(b.wire_diameter_mm - wire_mm).abs())
                });
                let have: Vec<String> = near.iter().map(|t| describe(t)).collect();
                Err(self.refused(format!(
                    "no {material} table for {wire_mm} mm{} wire: the nearest are {}",
                    wire_type.map_or(String::new(), |t| format!(" {t}")),
                    have.join("; ")
                )))
            }
            several => Err(self.refused(format!(
                "{} tables fit {material} with {wire_mm} mm wire: say which wire with type= \
                 ({})",
                several.len(),
                several
                    .iter()
                    .map(|t| format!("type={} in {}", t.wire_type, t.file))
                    .collect::<Vec<_>>()
                    .join("; ")
            ))),
        }
    }

    fn sinker_table(&self, electrode: &str, material: &str) -> Result<&SinkerTable, TechError> {
        let sinkers: Vec<&SinkerTable> = self
            .tables
            .iter()
            .filter_map(|t| match t {
                Table::Sinker(s) => Some(s),
                Table::Wire(_) => None,
            })
            .collect();
        sinkers
            .iter()
            .find(|t| eq(&t.electrode, electrode) && eq(&t.material, material))
            .copied()
            .ok_or_else(|| {
                let have: Vec<String> = sinkers
                    .iter()
                    .map(|t| format!("{} on {} ({})", t.electrode, t.material, t.file))
                    .collect();
                self.refused(format!(
                    "no sinker table for a {electrode} electrode on {material}: the tables are \
                     for {}",
                    list_or_none(&have)
                ))
            })
    }
}

fn list_or_none(items: &[String]) -> String {
    if items.is_empty() {
        "nothing (no table of this kind)".to_string()
    } else {
        items.join("; ")
    }
}

fn refused(table: &str, message: String) -> TechError {
    TechError::Refused {
        message: format!("{message} ({table})"),
    }
}

/// A wire table's passes at `height`: a row's, or between two rows the thicker one's passes
/// with the offsets and feeds of the passes both rows cut in one condition interpolated.
fn select_wire(table: &WireTable, request: &Request, height: f64) -> Result<Selection, TechError> {
    let rows = &table.rows;
    let (first, last) = (&rows[0], &rows[rows.len() - 1]);
    let name = format!(
        "{} with {} mm {} wire",
        table.material, table.wire_diameter_mm, table.wire_type
    );
    if height < first.height_mm - SAME || height > last.height_mm + SAME {
        let nearest = if height < first.height_mm {
            first
        } else {
            last
        };
        return Err(refused(
            &table.file,
            format!(
                "height {height} mm is outside the {name} table (rows from {} to {} mm): the \
                 nearest row is {}; a part outside the rows needs a row of its own from the \
                 generator's maker",
                first.height_mm,
                last.height_mm,
                row_name(nearest)
            ),
        ));
    }
    let upper = rows
        .iter()
        .position(|r| r.height_mm >= height - SAME)
        .expect("the height is within the rows");
    let hi = &rows[upper];
    let mut why = Vec::new();
    let passes: Vec<(TablePass, String)> = if (hi.height_mm - height).abs() <= SAME {
        why.push(format!("height {height} mm: the row {}", row_name(hi)));
        hi.passes
            .iter()
            .map(|p| (p.clone(), format!("{} mm row", hi.height_mm)))
            .collect()
    } else {
        let lo = &rows[upper - 1];
        let t = (height - lo.height_mm) / (hi.height_mm - lo.height_mm);
        why.push(format!(
            "height {height} mm lies between the rows {} and {}: {:.0} % of the way; the passes \
             are the {} mm row's (a row is made for parts up to its height), with the offset \
             and feed of each pass both rows cut in one condition interpolated",
            row_name(lo),
            row_name(hi),
            t * 100.0,
            hi.height_mm
        ));
        hi.passes
            .iter()
            .map(
                |p| match lo.passes.iter().find(|q| q.condition == p.condition) {
                    Some(q) => (
                        TablePass {
                            offset_mm: q.offset_mm + t * (p.offset_mm - q.offset_mm),
                            feed_mm_per_min: q.feed_mm_per_min
                                + t * (p.feed_mm_per_min - q.feed_mm_per_min),
                            ..p.clone()
                        },
                        format!(
                            "{} mm, between the {} and {} mm rows",
                            height, lo.height_mm, hi.height_mm
                        ),
                    ),
                    None => (
                        p.clone(),
                        format!(
                            "{} mm row (E{} is not in the {} mm row)",
                            hi.height_mm, p.condition, lo.height_mm
                        ),
                    ),
                },
            )
            .collect()
    };
    let conditions = passes
        .iter()
        .map(|(p, _)| {
            let mut c = condition(&table.conditions, p.condition);
            c.feed_mm_per_min = p.feed_mm_per_min;
            c.corner = p.corner.or(c.corner);
            c
        })
        .collect();
    Ok(Selection {
        request: request.clone(),
        table: table.file.clone(),
        example: table.example,
        title: name,
        description: table.description.clone(),
        why,
        passes: passes
            .into_iter()
            .map(|(p, row)| SelectedPass {
                pass: WirePass {
                    offset_mm: p.offset_mm,
                    condition: p.condition,
                    feed_mm_per_min: Some(p.feed_mm_per_min),
                    reverse: p.reverse,
                },
                row,
            })
            .collect(),
        stages: Vec::new(),
        conditions,
        wire_diameter_mm: Some(table.wire_diameter_mm),
    })
}

/// A sinker table's stages for an electrode of `area` cm²: the row whose areas hold it.
fn select_sinker(
    table: &SinkerTable,
    request: &Request,
    area: f64,
) -> Result<Selection, TechError> {
    let name = format!("{} electrode on {}", table.electrode, table.material);
    let Some(row) = table
        .rows
        .iter()
        .find(|r| (r.area_cm2[0] - SAME..=r.area_cm2[1] + SAME).contains(&area))
    else {
        let distance = |r: &&super::table::SinkerRow| {
            (r.area_cm2[0] - area)
                .abs()
                .min((r.area_cm2[1] - area).abs())
        };
        let mut near: Vec<_> = table.rows.iter().collect();
        near.sort_by(|a, b| distance(a).total_cmp(&distance(b)));
        return Err(refused(
            &table.file,
            format!(
                "an electrode of {area} cm² is in no row of the {name} table: the nearest rows \
                 are {}",
                near.iter()
                    .take(2)
                    .map(|r| format!("{} to {} cm² ({})", r.area_cm2[0], r.area_cm2[1], r.at))
                    .collect::<Vec<_>>()
                    .join(" and ")
            ),
        ));
    };
    let conditions = row
        .stages
        .iter()
        .map(|s: &Stage| {
            let mut c = condition(&table.conditions, s.condition);
            c.orbit_radius_mm = Some(s.orbit_radius_mm);
            c.orbit_shape = s.orbit_shape.or(c.orbit_shape);
            c.jump_interval_s = s.jump_interval_s.or(c.jump_interval_s);
            c.jump_height_mm = s.jump_height_mm.or(c.jump_height_mm);
            c.jump_feed_mm_per_min = s.jump_feed_mm_per_min.or(c.jump_feed_mm_per_min);
            c
        })
        .collect();
    Ok(Selection {
        request: request.clone(),
        table: table.file.clone(),
        example: table.example,
        title: name,
        description: table.description.clone(),
        why: vec![format!(
            "area {area} cm²: the row for {} to {} cm² ({})",
            row.area_cm2[0], row.area_cm2[1], row.at
        )],
        passes: Vec::new(),
        stages: row.stages.clone(),
        conditions,
        wire_diameter_mm: None,
    })
}

/// The table's condition `n` (a row names only its table's, checked on load).
fn condition(conditions: &[Condition], n: u32) -> Condition {
    conditions
        .iter()
        .find(|c| c.number == n)
        .cloned()
        .expect("a row names only its table's conditions (checked on load)")
}
