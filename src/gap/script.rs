//! `gap.kind = "script"`: a schedule of gap states, one `TICK STATE` line per change.
//!
//! ```text
//! # comments and blank lines are ignored
//! 0      normal
//! 12000  short      # from tick 12000 on ...
//! 12400  normal     # ... until tick 12400
//! ```
//!
//! The state holds from its tick until the next line's; before the first line the gap is
//! normal. `wire-break` is not a state but an event: from its tick the wire is broken (the
//! gap reads open and the wire-break input is set) until the operator's rethread. `estop`
//! presses the emergency stop and `limit X+` (an axis and its side) closes a limit switch,
//! from their tick to the end of the job or, for a switch, to a `release X+` line (the
//! switch opens: the axis moved off it). `TICK pulses NORMAL ARC SHORT OPEN [DELAY_US]` gives
//! the pulses a discriminator counts in each tick from then on (and their mean ignition
//! delay), as `edmd.gap.pulses-*` would: the servo laws and the adaptive law read them. Ticks
//! must not decrease. The whole script is read and checked before the job starts,
//! so a bad line is an error with `file:line:col`, never a surprise mid-job.

use std::path::Path;

use super::{GapError, GapSensor, GapState};
use crate::inputs::{InputError, InputReading, MachineInputs, SimulatedWire};
use crate::vocab::{LimitSwitch, PulseCounts, SafetyInputs};

/// A gap script that could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ScriptError {
    /// `what`: which file ("gap script", "sim events file").
    #[error("{path}: cannot read the {what}: {source}")]
    Io {
        path: String,
        what: &'static str,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}:{line}:{col}: {message}")]
    Invalid {
        path: String,
        line: usize,
        col: usize,
        message: String,
    },
}

/// Reads a script file (`what` names it in the error): its text and its name for messages.
pub(crate) fn read_script(
    path: &Path,
    what: &'static str,
) -> Result<(String, String), ScriptError> {
    let name = path.display().to_string();
    // Read without blocking: a FIFO in the script's place is an error, not a job start that
    // waits for a writer.
    match crate::sys::read_regular(path) {
        Ok(text) => Ok((crate::vocab::without_bom(&text).to_string(), name)),
        Err(source) => Err(ScriptError::Io {
            path: name,
            what,
            source,
        }),
    }
}

/// The whitespace-separated words of a script line (comment already cut), each with its
/// 1-based column in characters.
pub(crate) fn words(content: &str) -> Vec<(usize, &str)> {
    let mut words = Vec::with_capacity(3);
    let mut start = None;
    for (at, c) in content
        .char_indices()
        .chain(std::iter::once((content.len(), ' ')))
    {
        match (c.is_whitespace(), start) {
            (false, None) => start = Some(at),
            (true, Some(from)) => {
                words.push((content[..from].chars().count() + 1, &content[from..at]));
                start = None;
            }
            _ => {}
        }
    }
    words
}

/// A parsed gap script: the machine it scripts, a gap side and an inputs side, replayed
/// against the tick count.
#[derive(Debug, Clone)]
pub struct GapScript {
    pub gap: ScriptGap,
    pub inputs: ScriptInputs,
}

/// The script's gap states.
#[derive(Debug, Clone)]
pub struct ScriptGap {
    changes: Vec<(u64, GapState)>,
    next: usize,
    state: GapState,
    /// No wire, no discharge: the gap reads open while the script's wire is broken.
    wire: SimulatedWire,
    /// The `pulses` lines: each tick's pulses from their tick on; the next one to apply and
    /// those in force (none before the first line).
    pulse_changes: Vec<(u64, PulseCounts)>,
    next_pulses: usize,
    pulses: Option<PulseCounts>,
}

/// The script's machine inputs: its E-stop, limit switches and wire breaks.
#[derive(Debug, Clone)]
pub struct ScriptInputs {
    /// Ticks of the `wire-break` lines, and how many of them have happened.
    breaks: Vec<u64>,
    breaks_done: usize,
    wire: SimulatedWire,
    /// The safety inputs' changes (`estop`, `limit X+`), by tick, and those in force.
    trips: Vec<(u64, SafetyInputs)>,
    next_trip: usize,
    safety: SafetyInputs,
}

impl GapScript {
    pub fn load(path: &Path) -> Result<GapScript, ScriptError> {
        let (text, name) = read_script(path, "gap script")?;
        GapScript::parse(&text, &name)
    }

    /// Parses script text; `name` is used in error messages.
    pub fn parse(text: &str, name: &str) -> Result<GapScript, ScriptError> {
        let mut changes: Vec<(u64, GapState)> = Vec::new();
        let mut breaks: Vec<u64> = Vec::new();
        let mut trips: Vec<(u64, SafetyInputs)> = Vec::new();
        let mut pulse_changes: Vec<(u64, PulseCounts)> = Vec::new();
        for (index, raw) in crate::vocab::without_bom(text).lines().enumerate() {
            let line = index + 1;
            let content = raw.split('#').next().unwrap_or("");
            let invalid = |col: usize, message: String| ScriptError::Invalid {
                path: name.to_string(),
                line,
                col,
                message,
            };
            let words = words(content);
            match words.as_slice() {
                [] => continue,
                [(col, tick), (state_col, state)] => {
                    let tick: u64 = tick.parse().map_err(|_| {
                        invalid(
                            *col,
                            format!("\"{tick}\" is not a tick number (a whole number >= 0)"),
                        )
                    })?;
                    let last = changes.last().map(|c| c.0).max(breaks.last().copied());
                    if let Some(last) = last
                        && tick < last
                    {
                        return Err(invalid(
                            *col,
                            format!("tick {tick} comes before the previous line's tick {last}"),
                        ));
                    }
                    if *state == "wire-break" {
                        breaks.push(tick);
                        continue;
                    }
                    if *state == "estop" {
                        let mut inputs = trips.last().map(|t| t.1).unwrap_or_default();
                        inputs.estop = true;
                        trips.push((tick, inputs));
                        continue;
                    }
                    let state = GapState::from_name(state).ok_or_else(|| {
                        invalid(
                            *state_col,
                            format!(
                                "\"{state}\" is not a gap state; use normal, open or short (or \
                                 wire-break)"
                            ),
                        )
                    })?;
                    changes.push((tick, state));
                }
                [
                    (col, tick),
                    (_, verb @ ("limit" | "release")),
                    (switch_col, switch),
                ] => {
                    let tick: u64 = tick.parse().map_err(|_| {
                        invalid(
                            *col,
                            format!("\"{tick}\" is not a tick number (a whole number >= 0)"),
                        )
                    })?;
                    let limit = LimitSwitch::parse(switch).ok_or_else(|| {
                        invalid(
                            *switch_col,
                            format!("\"{switch}\" is not a limit switch; write the axis and its side, e.g. X+ or Y-"),
                        )
                    })?;
                    let mut inputs = trips.last().map(|t| t.1).unwrap_or_default();
                    if *verb == "limit" {
                        inputs.limits.insert(limit);
                    } else {
                        inputs.limits.remove(limit);
                    }
                    trips.push((tick, inputs));
                }
                [(col, _)] => {
                    return Err(invalid(
                        *col,
                        "expected `TICK STATE`, e.g. `1200 short`".to_string(),
                    ));
                }
                [(col, tick), (_, "pulses"), counts @ ..] => {
                    let last = pulse_changes.last().map(|p| p.0);
                    pulse_changes.push(pulse_line(*col, tick, counts, last, &invalid)?);
                }
                [_, _, (col, extra), ..] => {
                    return Err(invalid(
                        *col,
                        format!("unexpected \"{extra}\" after `TICK STATE`"),
                    ));
                }
            }
        }
        let wire = SimulatedWire::default();
        Ok(GapScript {
            gap: ScriptGap {
                changes,
                next: 0,
                state: GapState::Normal,
                wire: wire.clone(),
                pulse_changes,
                next_pulses: 0,
                pulses: None,
            },
            inputs: ScriptInputs {
                breaks,
                breaks_done: 0,
                wire,
                trips,
                next_trip: 0,
                safety: SafetyInputs::default(),
            },
        })
    }
}

/// A `TICK pulses NORMAL ARC SHORT OPEN [DELAY_US]` line (`counts`: the words after
/// `pulses`) after a pulses line at tick `last`: its tick and the pulses of each tick from
/// then on.
fn pulse_line(
    col: usize,
    tick: &str,
    counts: &[(usize, &str)],
    last: Option<u64>,
    invalid: &dyn Fn(usize, String) -> ScriptError,
) -> Result<(u64, PulseCounts), ScriptError> {
    let tick: u64 = tick.parse().map_err(|_| {
        invalid(
            col,
            format!("\"{tick}\" is not a tick number (a whole number >= 0)"),
        )
    })?;
    if let Some(last) = last.filter(|&last| tick < last) {
        return Err(invalid(
            col,
            format!("tick {tick} comes before the previous pulses line's {last}"),
        ));
    }
    if !(4..=5).contains(&counts.len()) {
        return Err(invalid(
            col,
            "expected `TICK pulses NORMAL ARC SHORT OPEN [DELAY_US]`, e.g. `0 pulses 2 0 0 1 9.5`"
                .to_string(),
        ));
    }
    let mut n = [0u32; 4];
    for (slot, &(c, word)) in n.iter_mut().zip(counts) {
        *slot = word.parse().map_err(|_| {
            invalid(
                c,
                format!("\"{word}\" is not a pulse count (a whole number >= 0)"),
            )
        })?;
    }
    let delay = match counts.get(4) {
        None => 0.0,
        Some(&(c, word)) => match word.parse::<f64>() {
            Ok(v) if v.is_finite() && v >= 0.0 => v,
            _ => {
                return Err(invalid(
                    c,
                    format!("\"{word}\" is not an ignition delay (µs >= 0)"),
                ));
            }
        },
    };
    let [normal, arc, short, open] = n;
    Ok((
        tick,
        PulseCounts {
            normal,
            arc,
            short,
            open,
            delay_sum_us: delay * f64::from(normal + arc),
        },
    ))
}

impl ScriptGap {
    /// A script from a list of changes (for tests and benches).
    pub fn from_changes(mut changes: Vec<(u64, GapState)>) -> ScriptGap {
        changes.sort_by_key(|&(tick, _)| tick);
        ScriptGap {
            changes,
            next: 0,
            state: GapState::Normal,
            wire: SimulatedWire::default(),
            pulse_changes: Vec::new(),
            next_pulses: 0,
            pulses: None,
        }
    }
}

impl GapSensor for ScriptGap {
    /// Ticks are expected in increasing order (the consumer's order). The inputs side is
    /// read first in a tick, so a `wire-break` of this tick is already in the wire.
    fn sample(&mut self, tick: u64) -> Result<GapState, GapError> {
        while let Some(&(at, state)) = self.changes.get(self.next) {
            if at > tick {
                break;
            }
            self.state = state;
            self.next += 1;
        }
        while let Some(&(at, pulses)) = self.pulse_changes.get(self.next_pulses) {
            if at > tick {
                break;
            }
            self.pulses = Some(pulses);
            self.next_pulses += 1;
        }
        Ok(if self.wire.is_broken() {
            GapState::Open
        } else {
            self.state
        })
    }

    fn pulses(&self) -> Option<PulseCounts> {
        self.pulses
    }
}

impl MachineInputs for ScriptInputs {
    fn sample(&mut self, tick: u64) -> Result<InputReading, InputError> {
        while let Some(&(at, inputs)) = self.trips.get(self.next_trip) {
            if at > tick {
                break;
            }
            self.safety = inputs;
            self.next_trip += 1;
        }
        while self
            .breaks
            .get(self.breaks_done)
            .is_some_and(|&at| at <= tick)
        {
            self.wire.set_broken(true);
            self.breaks_done += 1;
        }
        Ok(self.wire.reading(self.safety))
    }

    fn rethreaded(&mut self) {
        self.wire.set_broken(false);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn states_hold_until_the_next_line() {
        let mut gap = GapScript::parse("# test\n10 short\n\n20 open # comment\n20 normal\n", "g")
            .unwrap()
            .gap;
        let states: Vec<_> = [0, 9, 10, 19, 20, 1000]
            .into_iter()
            .map(|t| gap.sample(t).unwrap())
            .collect();
        use GapState::*;
        assert_eq!(states, [Normal, Normal, Short, Short, Normal, Normal]);
    }

    #[test]
    fn a_wire_break_holds_until_the_rethread() {
        let GapScript {
            mut gap,
            mut inputs,
        } = GapScript::parse("0 normal\n10 wire-break\n20 short\n", "g").unwrap();
        // The loop's order in a tick: the inputs, then the gap.
        let mut tick = |t| {
            let wire = inputs.sample(t).unwrap().wire_broken;
            (wire, gap.sample(t).unwrap())
        };
        assert_eq!(tick(9), (false, GapState::Normal));
        assert_eq!(tick(10), (true, GapState::Open));
        assert_eq!(tick(25), (true, GapState::Open), "no wire, no short");
        inputs.rethreaded();
        assert!(!inputs.sample(26).unwrap().wire_broken);
        assert_eq!(gap.sample(26).unwrap(), GapState::Short);
    }

    #[test]
    fn a_byte_order_mark_is_skipped() {
        let mut gap = GapScript::parse("\u{feff}10 short\n", "g").unwrap().gap;
        assert_eq!(gap.sample(10).unwrap(), GapState::Short);
    }

    #[test]
    fn bad_lines_are_located() {
        let err = |text: &str| GapScript::parse(text, "gap.txt").unwrap_err().to_string();
        assert_eq!(
            err("10 short\n  5 normal\n"),
            "gap.txt:2:3: tick 5 comes before the previous line's tick 10"
        );
        assert_eq!(
            err("10 shorted\n"),
            "gap.txt:1:4: \"shorted\" is not a gap state; use normal, open or short (or \
             wire-break)"
        );
        assert_eq!(
            err("-3 short\n"),
            "gap.txt:1:1: \"-3\" is not a tick number (a whole number >= 0)"
        );
        assert_eq!(
            err("7\n"),
            "gap.txt:1:1: expected `TICK STATE`, e.g. `1200 short`"
        );
        assert_eq!(
            err("7 open now\n"),
            "gap.txt:1:8: unexpected \"now\" after `TICK STATE`"
        );
    }

    #[test]
    fn pulses_lines_give_each_ticks_pulses_from_their_tick_on() {
        let mut gap = GapScript::parse(
            "5 pulses 2 1 0 0 8.5
9 pulses 0 0 3 0
",
            "g",
        )
        .unwrap()
        .gap;
        assert_eq!(gap.sample(0).unwrap(), GapState::Normal);
        assert_eq!(gap.pulses(), None);
        gap.sample(6).unwrap();
        let p = gap.pulses().unwrap();
        assert_eq!((p.normal, p.arc, p.short, p.open), (2, 1, 0, 0));
        assert_eq!(p.mean_delay_us(), 8.5);
        gap.sample(9).unwrap();
        assert_eq!(gap.pulses().unwrap().short, 3);
        let err = |text: &str| GapScript::parse(text, "gap.txt").unwrap_err().to_string();
        assert_eq!(
            err("5 pulses 2 1 0\n"),
            "gap.txt:1:1: expected `TICK pulses NORMAL ARC SHORT OPEN [DELAY_US]`, e.g. \
             `0 pulses 2 0 0 1 9.5`"
        );
        assert_eq!(
            err("5 pulses 2 x 0 0\n"),
            "gap.txt:1:12: \"x\" is not a pulse count (a whole number >= 0)"
        );
        assert_eq!(
            err("9 pulses 1 0 0 0\n5 pulses 1 0 0 0\n"),
            "gap.txt:2:1: tick 5 comes before the previous pulses line's 9"
        );
    }
}
