//! `[wire]`: the technology table of a wire machine's passes (`[[wire.pass]]`), checked
//! against the offset registers (the conditions it names are checked when passes are cut:
//! `path::passes::first`).

use super::CompensationConfig;
use super::raw::RawWire;
use super::validate::{Invalid, in_range, positive};
pub use crate::vocab::Guides;

/// `[wire]`: the passes a `--passes N` run cuts, first to last.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct WireConfig {
    pub passes: Vec<WirePass>,
    /// The tab a run in passes leaves (mm of the contour before it closes; 0: none).
    pub tab_mm: f64,
    /// Where the guides are: what a taper (`G51`/`G52`) is computed with.
    pub guides: Guides,
    /// The work's thickness (mm), from the program plane up.
    pub thickness_mm: f64,
    /// The wire's diameter (mm).
    pub diameter_mm: f64,
    /// The wire-touch cycles (`edmd ctl find`).
    pub touch: TouchConfig,
}

/// `[wire] touch_*`: how the wire-touch cycles touch the part.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TouchConfig {
    /// The condition (E number) they touch in: the generator's least energy (checked against
    /// the condition table when a cycle starts).
    pub condition: u32,
    /// The approach feed, mm/min; the retouch runs at a tenth of it.
    pub feed_mm_per_min: f64,
    /// How far an approach goes before it gives up, mm.
    pub search_mm: f64,
    /// How far the wire backs off a contact before it touches again, mm.
    pub backoff_mm: f64,
    /// Approaches again after a retouch that found nothing (a false first contact).
    pub retries: u32,
    /// How far past the corner a corner cycle moves along one axis to touch the other's face.
    pub corner_clearance_mm: f64,
    /// Most rounds of a hole-centre cycle (it ends when two rounds agree within a step).
    pub center_rounds: u32,
}

pub use crate::path::WirePass;

impl RawWire {
    pub(super) fn validate(self, compensation: &CompensationConfig) -> Result<WireConfig, Invalid> {
        const KEY: &str = "wire.pass";
        let mut passes = Vec::new();
        for (i, p) in self.pass.into_iter().enumerate() {
            let n = i + 1;
            let offset_mm = match (p.offset_mm, p.d) {
                (Some(mm), None) if (0.0..=10.0).contains(&mm) => mm,
                (Some(mm), None) => {
                    return Err((KEY, format!("pass {n}: offset_mm = {mm}: 0 to 10 mm")));
                }
                (None, Some(d)) => *usize::try_from(d)
                    .ok()
                    .and_then(|d| compensation.d_mm.get(d))
                    .ok_or_else(|| {
                        (
                            KEY,
                            format!(
                                "pass {n}: d = {d} is not a register of compensation.d_mm \
                                 (D0 to D{})",
                                compensation.d_mm.len() - 1
                            ),
                        )
                    })?,
                _ => {
                    return Err((
                        KEY,
                        format!("pass {n}: give the wire offset as offset_mm or as d (a register)"),
                    ));
                }
            };
            // Whether [generator] defines it is asked when the passes are cut (as for
            // wire.touch_condition): a machine builder's own conditions need not come with
            // the example pass table replaced, until passes are run.
            let condition = u32::try_from(p.condition).map_err(|_| {
                (
                    KEY,
                    format!("pass {n}: condition = {} is not an E number", p.condition),
                )
            })?;
            let feed_mm_per_min = p
                .feed_mm_per_min
                .map(|f| positive(KEY, f, 1e6, "mm/min (feed_mm_per_min)"))
                .transpose()?;
            passes.push(WirePass {
                offset_mm,
                condition,
                feed_mm_per_min,
                reverse: p.reverse,
            });
        }
        let tab_mm = if self.tab_mm == 0.0 {
            0.0
        } else {
            positive("wire.tab_mm", self.tab_mm, 1000.0, "mm (0: no tab)")?
        };
        let lower_mm = self.lower_guide_mm;
        if !(lower_mm.is_finite() && lower_mm.abs() <= 1000.0) {
            return Err((
                "wire.lower_guide_mm",
                format!("must be -1000 to 1000 mm, got {lower_mm}"),
            ));
        }
        let upper_mm = positive("wire.upper_guide_mm", self.upper_guide_mm, 1000.0, "mm")?;
        if lower_mm + upper_mm < 1.0 {
            return Err((
                "wire.upper_guide_mm",
                format!(
                    "the guides must be at least 1 mm apart: lower_guide_mm + upper_guide_mm \
                     is {}",
                    lower_mm + upper_mm
                ),
            ));
        }
        Ok(WireConfig {
            passes,
            tab_mm,
            guides: Guides { lower_mm, upper_mm },
            thickness_mm: positive("wire.thickness_mm", self.thickness_mm, 1000.0, "mm")?,
            diameter_mm: positive("wire.diameter_mm", self.diameter_mm, 2.0, "mm")?,
            touch: TouchConfig {
                // Checked against the condition table when a cycle is asked for: a table
                // replaced without thinking of touching must not make this key an error.
                condition: in_range("wire.touch_condition", self.touch_condition, 0, 1 << 20)?
                    as u32,
                feed_mm_per_min: positive(
                    "wire.touch_feed_mm_per_min",
                    self.touch_feed_mm_per_min,
                    1e5,
                    "mm/min",
                )?,
                search_mm: positive("wire.touch_search_mm", self.touch_search_mm, 1e4, "mm")?,
                backoff_mm: positive("wire.touch_backoff_mm", self.touch_backoff_mm, 10.0, "mm")?,
                retries: in_range("wire.touch_retries", self.touch_retries, 0, 10)? as u32,
                corner_clearance_mm: positive(
                    "wire.touch_corner_clearance_mm",
                    self.touch_corner_clearance_mm,
                    1e3,
                    "mm",
                )?,
                center_rounds: in_range(
                    "wire.touch_center_rounds",
                    self.touch_center_rounds,
                    2,
                    20,
                )? as u32,
            },
        })
    }
}
