//! `[[program.mcode]]`: the machine builder's M-codes. A wire CAM post writes its machine's
//! own codes (`M50` cut the wire, `M60` thread it, flushing and pump codes); each is given
//! one of the actions edmd has, so a program that uses it reads instead of stopping at
//! "unknown M word". The codes edmd reads itself cannot be redefined.

use super::Condition;
use super::raw::RawMcode;
use super::validate::{Invalid, in_range};
use crate::gcode::{VendorAction, VendorM};

const KEY: &str = "program.mcode";
/// The M-codes edmd reads itself (program flow, pauses, flushing, spindle and tool words it
/// ignores, modal state, subprograms).
const OWN: &[u32] = &[0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 30, 70, 71, 72, 73, 98, 99];

impl RawMcode {
    /// One entry, checked against those before it (`taken`) and the conditions: its number
    /// once, not one of edmd's own, its action complete.
    pub(super) fn validate(
        self,
        taken: &[VendorM],
        conditions: &[Condition],
    ) -> Result<VendorM, Invalid> {
        vendor_code(self, taken, conditions)
    }
}

fn vendor_code(
    m: RawMcode,
    taken: &[VendorM],
    conditions: &[Condition],
) -> Result<VendorM, Invalid> {
    let number = in_range(KEY, m.number, 0, 9999)? as u32;
    if OWN.contains(&number) {
        return Err((KEY, format!("M{number} is one of edmd's own M-codes")));
    }
    if taken.iter().any(|c| c.number == number) {
        return Err((KEY, format!("M{number} is defined twice")));
    }
    let message = |what: &str| {
        m.message
            .clone()
            .filter(|t| !t.trim().is_empty())
            .ok_or((KEY, format!("M{number}: action \"{what}\" needs a message")))
    };
    let action = match m.action.as_str() {
        "flush_on" => VendorAction::Flush(true),
        "flush_off" => VendorAction::Flush(false),
        "condition" => {
            let Some(n) = m.condition else {
                return Err((
                    KEY,
                    format!("M{number}: action \"condition\" needs condition = <E number>"),
                ));
            };
            let n = in_range(KEY, n, 1, 999)? as u32;
            if !conditions.iter().any(|c| c.number == n) {
                return Err((
                    KEY,
                    format!("M{number}: E{n} is not a [[generator.condition]]"),
                ));
            }
            VendorAction::Condition(n)
        }
        "pause" => VendorAction::Pause(message("pause")?),
        "ignore" => VendorAction::Ignore(message("ignore")?),
        other => {
            return Err((
                KEY,
                format!(
                    "M{number}: action {other:?} is not one of flush_on, flush_off, condition, \
                     pause, ignore"
                ),
            ));
        }
    };
    if m.condition.is_some() && !matches!(action, VendorAction::Condition(_)) {
        return Err((
            KEY,
            format!("M{number}: condition is for action \"condition\" only"),
        ));
    }
    Ok(VendorM { number, action })
}
