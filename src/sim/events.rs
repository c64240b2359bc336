//! `sim.events`: scripted events for the simulated gap, one `TICK EVENT [VALUE]` per line.
//!
//! ```text
//! # tick    event     value
//! 200000    debris              # a debris bridge at the next sparking tick (sim.debris_clear_um)
//! 250000    debris    800       # ... that clears after turning back 800 µm
//! 300000    erosion   40        # harder material from here: 40 mm/min
//! 400000    short     20000     # a welded short: the gap reads short for 20000 ticks
//! 500000    open      2000      # a dielectric failure: the gap reads open for 2000 ticks
//! 600000    estop                 # the emergency stop is pressed (to the end of the job)
//! 700000    limit     X+          # the X axis's upper limit switch trips
//! @5.0      height    20          # from 5 mm into the work the part is 20 mm high
//! @7.5      flushing  0.3         # ... and flushed poorly (1: the nozzle at the part)
//! ```
//!
//! A line that starts `@MM` is placed by path position instead: that far into the work (the
//! cutting travel less the turn-backs over it), the discharge model's part height (mm) or
//! flushing changes. The file is read and checked before the job starts (`file:line:col` on
//! error); ticks, and positions, must not decrease.

use std::path::Path;

use crate::gap::ScriptError;
use crate::gap::{GapState, read_script, words};

/// One scripted event.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SimEvent {
    /// A debris bridge forms at the next sparking tick; it clears after the electrode has
    /// turned back `clear_mm` (`None`: `sim.debris_clear_um`).
    Debris { clear_mm: Option<f64> },
    /// The material's erosion rate changes (mm/s).
    Erosion { mm_per_s: f64 },
    /// The gap reads `state` for `ticks` ticks, whatever the electrode does.
    Hold { state: GapState, ticks: u64 },
    /// The emergency stop is pressed.
    Estop,
    /// A limit switch trips.
    Limit(crate::vocab::LimitSwitch),
}

impl SimEvent {
    /// The event presses one of the machine's inputs (the inputs side applies it); the
    /// others change the gap (the gap side's).
    pub fn presses_an_input(&self) -> bool {
        matches!(self, SimEvent::Estop | SimEvent::Limit(_))
    }
}

/// What changes along the cut, placed by path position (`@MM` lines).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CutChange {
    /// The part is this high from here, mm.
    Height(f64),
    /// The flushing reaches the slot this well from here (1: the nozzle at the part).
    Flushing(f64),
}

/// An events file: the events by tick, and the changes by position into the work (mm).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SimScript {
    pub by_tick: Vec<(u64, SimEvent)>,
    pub by_cut_mm: Vec<(f64, CutChange)>,
}

/// Reads and checks an events file.
pub fn load(path: &Path) -> Result<SimScript, ScriptError> {
    let (text, name) = read_script(path, "sim events file")?;
    parse(&text, &name)
}

/// Parses events text; `name` is used in error messages.
pub fn parse(text: &str, name: &str) -> Result<SimScript, ScriptError> {
    let mut events: Vec<(u64, SimEvent)> = Vec::new();
    let mut along: Vec<(f64, CutChange)> = Vec::new();
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        let invalid = |col: usize, message: String| ScriptError::Invalid {
            path: name.to_string(),
            line,
            col,
            message,
        };
        let words = words(raw.split('#').next().unwrap_or(""));
        let Some(&(tick_col, tick)) = words.first() else {
            continue;
        };
        if let Some(at) = tick.strip_prefix('@') {
            along.push(cut_change(&words, at, along.last().map(|a| a.0), &invalid)?);
            continue;
        }
        let tick: u64 = tick.parse().map_err(|_| {
            invalid(
                tick_col,
                format!("\"{tick}\" is not a tick number (a whole number >= 0)"),
            )
        })?;
        if let Some(&(last, _)) = events.last()
            && tick < last
        {
            return Err(invalid(
                tick_col,
                format!("tick {tick} comes before the previous line's tick {last}"),
            ));
        }
        let Some(&(event_col, event)) = words.get(1) else {
            return Err(invalid(
                tick_col,
                "expected `TICK EVENT [VALUE]`, e.g. `120000 debris`".to_string(),
            ));
        };
        let value = words.get(2).copied();
        if let Some(&(col, extra)) = words.get(3) {
            return Err(invalid(
                col,
                format!("unexpected \"{extra}\" after the value"),
            ));
        }
        let number = |what: &str| -> Result<f64, ScriptError> {
            let (col, text) = value
                .ok_or_else(|| invalid(event_col, format!("`{event}` needs a value: {what}")))?;
            match text.parse::<f64>() {
                Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
                _ => Err(invalid(
                    col,
                    format!("\"{text}\" is not a positive number ({what})"),
                )),
            }
        };
        let ticks = || -> Result<u64, ScriptError> {
            let (col, text) = value.ok_or_else(|| {
                invalid(
                    event_col,
                    format!("`{event}` needs a value: how many ticks"),
                )
            })?;
            text.parse::<u64>().map_err(|_| {
                invalid(
                    col,
                    format!("\"{text}\" is not a number of ticks (a whole number >= 0)"),
                )
            })
        };
        let parsed = match event.to_ascii_lowercase().as_str() {
            "debris" => SimEvent::Debris {
                clear_mm: match value {
                    None => None,
                    Some(_) => Some(number("the turn-back that clears it, µm")? / 1000.0),
                },
            },
            "erosion" => SimEvent::Erosion {
                mm_per_s: number("the erosion rate, mm/min")? / 60.0,
            },
            "short" => SimEvent::Hold {
                state: GapState::Short,
                ticks: ticks()?,
            },
            "open" => SimEvent::Hold {
                state: GapState::Open,
                ticks: ticks()?,
            },
            "estop" => SimEvent::Estop,
            "limit" => {
                let (col, text) = value.ok_or_else(|| {
                    invalid(event_col, "`limit` needs the switch, e.g. X+".to_string())
                })?;
                SimEvent::Limit(crate::vocab::LimitSwitch::parse(text).ok_or_else(|| {
                    invalid(
                        col,
                        format!("\"{text}\" is not a limit switch, e.g. X+ or Y-"),
                    )
                })?)
            }
            _ => {
                return Err(invalid(
                    event_col,
                    format!(
                        "\"{event}\" is not an event; use debris, erosion, short, open, estop \
                         or limit"
                    ),
                ));
            }
        };
        events.push((tick, parsed));
    }
    Ok(SimScript {
        by_tick: events,
        by_cut_mm: along,
    })
}

/// An `@MM height H` or `@MM flushing F` line (`words`, `at` the text after `@`), after the
/// last position `last`.
fn cut_change(
    words: &[(usize, &str)],
    at: &str,
    last: Option<f64>,
    invalid: &dyn Fn(usize, String) -> ScriptError,
) -> Result<(f64, CutChange), ScriptError> {
    let (col, _) = words[0];
    let mm = match at.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => v,
        _ => {
            return Err(invalid(
                col,
                format!("\"@{at}\" is not a position into the work (mm >= 0)"),
            ));
        }
    };
    if let Some(last) = last
        && mm < last
    {
        return Err(invalid(
            col,
            format!("position {mm} mm comes before the previous line's {last} mm"),
        ));
    }
    let Some(&(event_col, event)) = words.get(1) else {
        return Err(invalid(
            col,
            "expected `@MM height MM` or `@MM flushing FACTOR`".to_string(),
        ));
    };
    let Some(&(value_col, text)) = words.get(2) else {
        return Err(invalid(event_col, format!("`{event}` needs a value")));
    };
    if let Some(&(extra_col, extra)) = words.get(3) {
        return Err(invalid(
            extra_col,
            format!("unexpected \"{extra}\" after the value"),
        ));
    }
    let value = text
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite() && *v > 0.0);
    let change = match (event.to_ascii_lowercase().as_str(), value) {
        ("height", Some(v)) if v <= 1000.0 => CutChange::Height(v),
        ("flushing", Some(v)) if v <= 1.0 => CutChange::Flushing(v),
        ("height", _) => {
            return Err(invalid(
                value_col,
                format!("\"{text}\" is not a part height (mm, above 0, at most 1000)"),
            ));
        }
        ("flushing", _) => {
            return Err(invalid(
                value_col,
                format!("\"{text}\" is not a flushing factor (above 0, at most 1)"),
            ));
        }
        _ => {
            return Err(invalid(
                event_col,
                format!("\"{event}\" cannot be placed by position; use height or flushing"),
            ));
        }
    };
    Ok((mm, change))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_event_parses() {
        let events = parse(
            "# header\n10 debris\n20 debris 800 # comment\n30 erosion 40\n40 SHORT 100\n\n50 open 7\n",
            "ev",
        )
        .unwrap()
        .by_tick;
        assert_eq!(
            events,
            vec![
                (10, SimEvent::Debris { clear_mm: None }),
                (
                    20,
                    SimEvent::Debris {
                        clear_mm: Some(0.8)
                    }
                ),
                (
                    30,
                    SimEvent::Erosion {
                        mm_per_s: 40.0 / 60.0
                    }
                ),
                (
                    40,
                    SimEvent::Hold {
                        state: GapState::Short,
                        ticks: 100
                    }
                ),
                (
                    50,
                    SimEvent::Hold {
                        state: GapState::Open,
                        ticks: 7
                    }
                ),
            ]
        );
    }

    #[test]
    fn estop_and_limit_events() {
        let events = parse("5 estop\n9 limit y-\n", "ev.txt").unwrap().by_tick;
        assert_eq!(events[0], (5, SimEvent::Estop));
        assert_eq!(
            events[1],
            (
                9,
                SimEvent::Limit(crate::vocab::LimitSwitch {
                    axis: crate::vocab::Axis::Y,
                    positive: false
                })
            )
        );
        let e = parse("9 limit Y\n", "ev.txt").unwrap_err().to_string();
        assert_eq!(e, "ev.txt:1:9: \"Y\" is not a limit switch, e.g. X+ or Y-");
    }

    #[test]
    fn bad_lines_are_located() {
        let err = |text: &str| parse(text, "ev.txt").unwrap_err().to_string();
        assert_eq!(
            err("10 debris\n5 debris\n"),
            "ev.txt:2:1: tick 5 comes before the previous line's tick 10"
        );
        assert_eq!(
            err("10 spark\n"),
            "ev.txt:1:4: \"spark\" is not an event; use debris, erosion, short, open, estop or limit"
        );
        assert_eq!(
            err("10 erosion\n"),
            "ev.txt:1:4: `erosion` needs a value: the erosion rate, mm/min"
        );
        assert_eq!(
            err("10 erosion -4\n"),
            "ev.txt:1:12: \"-4\" is not a positive number (the erosion rate, mm/min)"
        );
        assert_eq!(
            err("  10 short 1.5\n"),
            "ev.txt:1:12: \"1.5\" is not a number of ticks (a whole number >= 0)"
        );
        assert_eq!(
            err("x debris\n"),
            "ev.txt:1:1: \"x\" is not a tick number (a whole number >= 0)"
        );
        assert_eq!(
            err("10\n"),
            "ev.txt:1:1: expected `TICK EVENT [VALUE]`, e.g. `120000 debris`"
        );
        assert_eq!(
            err("10 open 5 now\n"),
            "ev.txt:1:11: unexpected \"now\" after the value"
        );
    }

    #[test]
    fn changes_along_the_cut_are_placed_by_position() {
        let script = parse("10 debris\n@5 height 20\n@7.5 FLUSHING 0.3\n", "ev").unwrap();
        assert_eq!(
            script.by_tick,
            vec![(10, SimEvent::Debris { clear_mm: None })]
        );
        assert_eq!(
            script.by_cut_mm,
            vec![
                (5.0, CutChange::Height(20.0)),
                (7.5, CutChange::Flushing(0.3))
            ]
        );
        let err = |text: &str| parse(text, "ev.txt").unwrap_err().to_string();
        assert_eq!(
            err("@5 height 20\n@4 height 60\n"),
            "ev.txt:2:1: position 4 mm comes before the previous line's 5 mm"
        );
        assert_eq!(
            err("@5 flushing 2\n"),
            "ev.txt:1:13: \"2\" is not a flushing factor (above 0, at most 1)"
        );
        assert_eq!(
            err("@x height 2\n"),
            "ev.txt:1:1: \"@x\" is not a position into the work (mm >= 0)"
        );
        assert_eq!(
            err("@1 estop now\n"),
            "ev.txt:1:4: \"estop\" cannot be placed by position; use height or flushing"
        );
    }
}
