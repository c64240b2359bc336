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

use crate::vocab::GeneratorSetPoints;

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
    };
}

/// The job's machining conditions (a short list: a lookup is a scan).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ConditionTable(Vec<Condition>);

impl ConditionTable {
    pub fn new(conditions: Vec<Condition>) -> ConditionTable {
        ConditionTable(conditions)
    }

    /// Condition `number`; [`Condition::NONE`] (under that number) when the table has none.
    pub fn get(&self, number: u16) -> Condition {
        self.0
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
        }
    }

    /// A move of condition `number` is entered: its set points are in force from now on (a
    /// move of the condition already in force keeps what is in force, adaptations included).
    pub fn enter(&mut self, number: u16) {
        if number != self.in_force.number {
            self.in_force = self.table.get(number);
            self.changes = self.changes.wrapping_add(1);
        }
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
