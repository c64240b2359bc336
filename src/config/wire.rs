//! `[wire]`: the technology table of a wire machine's passes (`[[wire.pass]]`), checked
//! against the offset registers and the conditions it names.

use super::raw::RawWire;
use super::validate::{Invalid, positive};
use super::{CompensationConfig, Condition};
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
}

/// One pass: the wire offset (every `D` of the program reads it), the condition (every `E` of
/// the program reads it), a feed ceiling, and the direction.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WirePass {
    pub offset_mm: f64,
    pub condition: u32,
    pub feed_mm_per_min: Option<f64>,
    /// Cut this pass the other way round.
    pub reverse: bool,
}

impl RawWire {
    pub(super) fn validate(
        self,
        compensation: &CompensationConfig,
        conditions: &[Condition],
    ) -> Result<WireConfig, Invalid> {
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
            let condition = u32::try_from(p.condition)
                .ok()
                .filter(|c| conditions.iter().any(|x| x.number == *c))
                .ok_or_else(|| {
                    (
                        KEY,
                        format!(
                            "pass {n}: condition = {} is not one of [generator] condition",
                            p.condition
                        ),
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
        })
    }
}
