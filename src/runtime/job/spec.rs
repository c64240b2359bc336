//! What a job's threads need, read from the configuration once, when the job starts: plain
//! settings ([`JobSpec`]), so that no thread of a job (producer, fine thread, supervisor)
//! sees the `Config` or builds a setting again.

use crate::config::Config;
use crate::fine::FineSettings;
use crate::gcode::WorkStart;
use crate::path::{CutPlan, PathSpec};
use crate::preprocess::PlanSettings;
use crate::process::ConditionTable;
use crate::vocab::{Axis, Steps, TickPeriod};

use super::super::tick::consumer::LoopSettings;

/// Everything a job's threads need.
#[derive(Debug, Clone)]
pub struct JobSpec {
    pub axes: Vec<Axis>,
    pub step_mm: Vec<f64>,
    /// The job's path: how the program reads, where the job starts, what of it is cut.
    pub path: PathSpec,
    /// How the producer segments and plans it (and the rapid feed the ETA counts).
    pub plan: PlanSettings,
    /// The tick core's settings.
    pub fine: FineSettings,
    /// The consumer's loop: tick, time mode, real-time settings, whether `M0`/`M1` hold.
    pub run_loop: LoopSettings,
    pub tick: TickPeriod,
    /// Loop-buffer capacity and reserved area (blocks).
    pub buffer_capacity: usize,
    pub buffer_reserved: usize,
    /// Executed blocks kept beyond the reserved area (`buffer.trail_blocks`).
    pub buffer_trail: usize,
    pub conditions: ConditionTable,
    /// The fastest path speed the outputs can take (one step per axis per tick), mm/s.
    pub speed_cap: f64,
    pub max_feed_mm_per_min: f64,
}

impl JobSpec {
    /// The settings of `config` for a job. `program_pauses`: an operator is there to resume
    /// (the daemon), so `M0`/`M1`, collisions and alarms hold the job instead of passing or
    /// ending it (`edmd run`).
    pub fn from_config(config: &Config, program_pauses: bool) -> JobSpec {
        let mut run_loop = LoopSettings::from_config(config);
        run_loop.program_pauses = program_pauses;
        JobSpec {
            axes: config.machine.axes.clone(),
            step_mm: config.machine.step_mm.clone(),
            // The machine origin in `G54` with no offsets, the whole program, unless the
            // caller says otherwise.
            path: PathSpec::from_config(config, &WorkStart::default(), &CutPlan::default()),
            plan: PlanSettings::from_config(config),
            fine: FineSettings::from_config(config),
            run_loop,
            tick: config.fine.tick,
            buffer_capacity: config.buffer.capacity,
            buffer_reserved: config.buffer.reserved,
            buffer_trail: if config.wire_can_break() {
                config.buffer.trail_blocks
            } else {
                0
            },
            conditions: ConditionTable::from_config(config),
            speed_cap: fine_speed_cap(config),
            max_feed_mm_per_min: config.machine.max_feed_mm_per_min,
        }
    }

    /// The machine position the job starts from, in steps.
    pub fn start_steps(&self) -> Steps {
        start_steps(&self.path.machine_start(), &self.step_mm)
    }

    /// The axis names (`X`, `Y`, …).
    pub fn axis_names(&self) -> Vec<String> {
        self.axes.iter().map(|a| a.letter().to_string()).collect()
    }

    /// The straight distance between two step positions, mm.
    pub fn distance_mm(&self, a: &[i64], b: &[i64]) -> f64 {
        self.step_mm
            .iter()
            .zip(a.iter().zip(b))
            .map(|(mm, (a, b))| ((b - a) as f64 * mm).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    /// `X1.234 Y5.678` (mm) of a step position.
    pub fn position_text(&self, steps: &[i64]) -> String {
        self.axes
            .iter()
            .zip(steps)
            .zip(&self.step_mm)
            .map(|((a, &s), mm)| format!("{}{:.4}", a.letter(), s as f64 * mm))
            .collect::<Vec<_>>()
            .join(" ")
    }
}

/// The machine position of `start` in steps (it was made from steps, so this is exact).
pub fn start_steps(start: &WorkStart, step_mm: &[f64]) -> Steps {
    std::array::from_fn(|i| {
        step_mm
            .get(i)
            .map_or(0, |mm| (start.position_mm[i] / mm).round() as i64)
    })
}

/// The highest path speed the fine interpolator can reach (mm/s): one step of the coarsest
/// axis per tick.
pub fn fine_speed_cap(config: &Config) -> f64 {
    let coarsest = config.machine.step_mm.iter().cloned().fold(0.0, f64::max);
    coarsest / config.fine.tick.secs()
}
