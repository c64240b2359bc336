//! The process: the machining condition in force and what it sets, owned in one place.
//!
//! A program names its conditions (`E<number>`); the job's [`ConditionTable`] says what each
//! sets: the generator's set points (on and off time, peak current, …; what the output writes
//! to `edmd.gen.*`) and what it asks of the servo (the sparking feed, the voltage law's
//! reference, the jumps). The blocks in the loop buffer carry only the number; the tick core's
//! [`Process`] looks the number up when a move of another condition is entered and holds the
//! set points in force from then on. Whoever changes the process during a cut (an adaptive
//! law changing the off time, an operator's edit) changes the [`Process`]; the servo and the
//! output read it from there, and [`Process::changes`] tells the thread loop the output's
//! set points are due again.
//!
//! Like the tick core it belongs to, it never allocates after the job is assembled: the
//! table is built before the first tick and only read afterwards.

mod adaptive;

pub use adaptive::{AdaptiveLaw, AdaptiveSettings, AdaptiveView, OffTimeBounds};

use crate::vocab::{GeneratorSetPoints, PulseCounts};

/// What a machining condition asks of the servo. A value the condition does not give keeps
/// the `[servo]` setting: a feed or reference of 0, a jump value of NaN.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoSetPoints {
    /// The three-state law's sparking feed (mm/s).
    pub feed_mm_per_s: f32,
    /// The voltage law's reference (V).
    pub v_ref: f32,
    /// Jumps: interval (s; 0 turns them off), height (mm) and feed (mm/s).
    pub jump: [f32; 3],
}

impl ServoSetPoints {
    /// Everything the `[servo]` settings' (no condition in force).
    pub const KEEP: ServoSetPoints = ServoSetPoints {
        feed_mm_per_s: 0.0,
        v_ref: 0.0,
        jump: [f32::NAN; 3],
    };
}

/// One machining condition of a job: its number and what it sets.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Condition {
    /// `E<number>`; 0 is no condition.
    pub number: u16,
    pub servo: ServoSetPoints,
    pub generator: GeneratorSetPoints,
    /// The adaptive law adjusts this condition's off time within these bounds; `None`: it
    /// runs as set.
    pub adaptive: Option<OffTimeBounds>,
}

impl Condition {
    /// No condition: the servo's settings, and the generator's own (every set point 0).
    pub const NONE: Condition = Condition {
        number: 0,
        servo: ServoSetPoints::KEEP,
        generator: GeneratorSetPoints {
            on_time_us: 0.0,
            off_time_us: 0.0,
            peak_current_a: 0.0,
            open_voltage_v: 0.0,
            servo_ref_v: 0.0,
            wire_tension_n: 0.0,
            wire_speed_m_per_min: 0.0,
            flushing_bar: 0.0,
        },
        adaptive: None,
    };
}

/// The job's machining conditions (a short list: a lookup is a scan), and the adaptive
/// law's settings for those it adapts.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ConditionTable {
    conditions: Vec<Condition>,
    adaptive: Option<AdaptiveSettings>,
}

impl ConditionTable {
    pub fn new(conditions: Vec<Condition>) -> ConditionTable {
        ConditionTable {
            conditions,
            adaptive: None,
        }
    }

    /// The table with the adaptive law's settings (`[adaptive]`): its conditions with bounds
    /// are adapted.
    pub fn with_adaptive(mut self, settings: AdaptiveSettings) -> ConditionTable {
        self.adaptive = Some(settings);
        self
    }

    /// Condition `number`; [`Condition::NONE`] (under that number) when the table has none.
    pub fn get(&self, number: u16) -> Condition {
        self.conditions
            .iter()
            .find(|c| c.number == number)
            .copied()
            .unwrap_or(Condition {
                number,
                ..Condition::NONE
            })
    }
}

/// The condition in force during a job and its set points: the tick core's part that owns
/// them.
#[derive(Debug, Clone)]
pub struct Process {
    table: ConditionTable,
    in_force: Condition,
    /// Bumped on every change of the set points in force.
    changes: u32,
    /// The adaptive law, from the first adapted condition on (its height estimate carries
    /// over from one condition to the next).
    law: Option<AdaptiveLaw>,
    /// Every pulse the gap input counted in the job, by class (normal, arc, short, open),
    /// and the sum of their ignition delays (µs).
    pulse_totals: [u64; 4],
    delay_sum_us: f64,
}

impl Default for Process {
    fn default() -> Process {
        Process::new(ConditionTable::default())
    }
}

impl Process {
    /// No condition in force yet (the first move's takes over), the job's `table`.
    pub fn new(table: ConditionTable) -> Process {
        Process {
            table,
            in_force: Condition::NONE,
            changes: 0,
            law: None,
            pulse_totals: [0; 4],
            delay_sum_us: 0.0,
        }
    }

    /// A move of condition `number` is entered: its set points are in force from now on (a
    /// move of the condition already in force keeps what is in force, adaptations included).
    pub fn enter(&mut self, number: u16) {
        if number != self.in_force.number {
            self.in_force = self.table.get(number);
            self.changes = self.changes.wrapping_add(1);
            if self.law.is_none()
                && self.in_force.adaptive.is_some()
                && let Some(settings) = self.table.adaptive
            {
                self.law = Some(AdaptiveLaw::new(settings));
            }
        }
    }

    /// Phase 5 of a tick (after the drive): the gap's pulses of the tick and the net travel
    /// along the path (mm). The adaptive law, where the condition in force is adapted, takes
    /// them; at the end of its window the off time it asks for is in force (a change of the
    /// set points, which the thread loop then writes to the generator).
    #[inline]
    pub fn observe(&mut self, pulses: Option<&PulseCounts>, travel_mm: f64, flushing: Option<f64>) {
        if let Some(p) = pulses {
            for (total, n) in self
                .pulse_totals
                .iter_mut()
                .zip([p.normal, p.arc, p.short, p.open])
            {
                *total += u64::from(n);
            }
            self.delay_sum_us += p.delay_sum_us;
        }
        let (Some(law), Some(bounds), Some(pulses)) =
            (self.law.as_mut(), self.in_force.adaptive, pulses)
        else {
            return;
        };
        if let Some(off) = law.observe(
            pulses,
            travel_mm,
            flushing,
            &self.in_force.generator,
            bounds,
        ) && off != self.in_force.generator.off_time_us
        {
            self.in_force.generator.off_time_us = off;
            self.changes = self.changes.wrapping_add(1);
        }
    }

    /// Every pulse counted in the job by class (normal, arc, short, open), and the sum of
    /// the ignition delays of the normal and arc ones (µs).
    pub fn pulse_totals(&self) -> ([u64; 4], f64) {
        (self.pulse_totals, self.delay_sum_us)
    }

    /// What the adaptive law measured, once it runs.
    pub fn adaptive(&self) -> Option<&AdaptiveView> {
        self.law.as_ref().map(|l| l.view())
    }

    /// The condition in force.
    pub fn condition(&self) -> u16 {
        self.in_force.number
    }

    /// What the condition in force asks of the servo.
    pub fn servo(&self) -> &ServoSetPoints {
        &self.in_force.servo
    }

    /// What the generator is set to now.
    pub fn generator(&self) -> &GeneratorSetPoints {
        &self.in_force.generator
    }

    /// A count that changes whenever the set points in force do: the thread loop writes them
    /// to the output when it differs from the count it last wrote.
    pub fn changes(&self) -> u32 {
        self.changes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn condition(number: u16, off_time_us: f64, v_ref: f32) -> Condition {
        Condition {
            number,
            servo: ServoSetPoints {
                v_ref,
                ..ServoSetPoints::KEEP
            },
            generator: GeneratorSetPoints {
                off_time_us,
                ..GeneratorSetPoints::default()
            },
            adaptive: None,
        }
    }

    #[test]
    fn a_move_of_another_condition_brings_its_set_points() {
        let mut process = Process::new(ConditionTable::new(vec![
            condition(1, 20.0, 40.0),
            condition(2, 8.0, 35.0),
        ]));
        assert_eq!(process.condition(), 0);
        assert!(process.servo().jump[0].is_nan());
        let before = process.changes();
        process.enter(1);
        assert_eq!(process.generator().off_time_us, 20.0);
        assert_eq!(process.servo().v_ref, 40.0);
        let after_one = process.changes();
        assert_ne!(after_one, before);
        // The same condition again is no change.
        process.enter(1);
        assert_eq!(process.changes(), after_one);
        process.enter(2);
        assert_eq!(process.generator().off_time_us, 8.0);
        assert_eq!(process.servo().v_ref, 35.0);
        assert_ne!(process.changes(), after_one);
    }

    #[test]
    fn a_condition_the_table_lacks_sets_nothing() {
        let mut process = Process::new(ConditionTable::new(vec![condition(1, 20.0, 40.0)]));
        process.enter(1);
        process.enter(7);
        assert_eq!(process.condition(), 7);
        assert_eq!(*process.generator(), GeneratorSetPoints::default());
        assert_eq!(process.servo().v_ref, 0.0);
        process.enter(0);
        assert_eq!(process.condition(), 0);
    }
}
