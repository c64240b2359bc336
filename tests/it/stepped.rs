//! The stepped part of issue [3/7] (Sato et al.'s reproduction): a straight rough cut of
//! 15 mm through a part 60 mm high, 20 mm from 5 to 10 mm, 60 mm again, with poor flushing
//! from 6 to 9 mm (`tests/data/stepped/`). Cut through the job's own tick loop
//! (`consumer::run_loop`) in virtual time around the simulator's discharge model, with the
//! voltage servo; the off time fixed, or adapted by `[adaptive]`.
//!
//! Shared by the test (`tests/it/process.rs`, a few seeds) and the benchmark
//! (`benches/stepped_part.rs`, twenty seeds and the search for the baseline's off time).

#![allow(dead_code)]

use std::path::{Path, PathBuf};

use edmd::buffer::{StepBlock, VecSource};
use edmd::config::Config;
use edmd::fine::{FineSettings, Interpolator};
use edmd::gap::{GapError, GapSensor, GapState};
use edmd::output::NullOutput;
use edmd::process::ConditionTable;
use edmd::runtime::consumer::run_loop;
use edmd::runtime::{LoopSettings, Published};
use edmd::sim::{SimGap, SimMachine, SimSettings};
use edmd::vocab::{GeneratorSetPoints, MAX_AXES, PulseCounts};

/// The cut's length, mm, and where its stretches end: 60 mm high, 20 mm (poorly flushed
/// from 6 to 9), 60 mm.
pub const LENGTH_MM: f64 = 15.0;
pub const STRETCHES: [(&str, f64, f64); 5] = [
    ("60 mm", 0.0, 5.0),
    ("20 mm", 5.0, 6.0),
    ("20 mm, poor flushing", 6.0, 9.0),
    ("20 mm", 9.0, 10.0),
    ("60 mm", 10.0, 15.0),
];

/// The true part height at `mm` into the cut.
pub fn true_height(mm: f64) -> f64 {
    if (5.0..10.0).contains(&mm) {
        20.0
    } else {
        60.0
    }
}

/// How the off time is set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OffTime {
    Fixed(f64),
    Adaptive,
}

/// One point along the cut, each 0.1 mm the first time it is reached.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    pub mm: f64,
    pub seconds: f64,
    pub off_time_us: f64,
    pub height_mm: f64,
}

/// What one cut did.
#[derive(Debug, Clone)]
pub struct Cut {
    pub seed: u64,
    pub off: OffTime,
    /// Machine time to the end or to the break, s.
    pub seconds: f64,
    /// Where the wire broke (mm into the cut).
    pub broke_at_mm: Option<f64>,
    pub samples: Vec<Sample>,
    pub pulses: PulseCounts,
}

impl Cut {
    /// Machine time from `from` to `to` mm (None if the cut did not get there).
    pub fn seconds_between(&self, from: f64, to: f64) -> Option<f64> {
        let at = |mm: f64| {
            if mm <= 0.0 {
                return Some(0.0);
            }
            self.samples
                .iter()
                .find(|s| s.mm >= mm - 1e-9)
                .map(|s| s.seconds)
        };
        Some(at(to)? - at(from)?)
    }

    /// The largest error of the height estimate, as a share of the true height, from
    /// `settle_mm` after each change of height to the next.
    pub fn worst_height_error(&self, settle_mm: f64) -> f64 {
        let changes = [0.0, 5.0, 10.0];
        self.samples
            .iter()
            .filter(|s| {
                let since = changes
                    .iter()
                    .filter(|&&c| c <= s.mm)
                    .map(|c| s.mm - c)
                    .fold(f64::INFINITY, f64::min);
                since >= settle_mm && s.mm < LENGTH_MM - 0.05
            })
            .map(|s| (s.height_mm - true_height(s.mm)).abs() / true_height(s.mm))
            .fold(0.0, f64::max)
    }
}

/// The reproduction's data directory (from the tests' crate or the benchmarks', one below).
pub fn data() -> PathBuf {
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = here.join("tests/data/stepped");
    if dir.exists() {
        dir
    } else {
        here.join("../tests/data/stepped")
    }
}

/// The machine of `tests/data/stepped/stepped.toml` for `seed` and `off`, with `sets`.
pub fn config(seed: u64, off: OffTime, sets: &[String]) -> Config {
    let dir = data();
    let mut all = vec![
        format!("sim.seed={seed}"),
        format!(
            "sim.events={:?}",
            dir.join("stepped.events").display().to_string()
        ),
        format!("adaptive.enabled={}", off == OffTime::Adaptive),
    ];
    if let OffTime::Fixed(us) = off {
        all.push(format!(
            "generator.condition=[{{ number = 21, on_us = 8.0, off_us = {us}, current_a = 12.0, \
             v_ref = 64.0, open_voltage_v = 90.0, wire_speed_m_per_min = 9.0, \
             flushing_bar = 12.0, feed_mm_per_min = 30.0 }}]"
        ));
    }
    all.extend_from_slice(sets);
    Config::load(Some(&dir.join("stepped.toml")), &all).expect("the stepped part's config")
}

/// The cut as step blocks of 0.1 mm along X (1 µm steps), planned at 30 mm/min in E21.
fn blocks() -> Vec<StepBlock> {
    let n = (LENGTH_MM * 10.0).round() as i64;
    straight_blocks(n, 0.5, 7)
        .into_iter()
        .map(|b| StepBlock { condition: 21, ..b })
        .collect()
}

/// `count` step blocks of 0.1 mm along X (1 µm steps) from the origin, at `v` mm/s from a
/// standstill to a standstill, all from source line `line`: a straight cut the servo sets
/// the pace of (also `servo_laws.rs`'s).
pub fn straight_blocks(count: i64, v: f64, line: u64) -> Vec<StepBlock> {
    (0..count)
        .map(|i| {
            let mut start = [0i64; MAX_AXES];
            let mut end = [0i64; MAX_AXES];
            start[0] = i * 100;
            end[0] = (i + 1) * 100;
            let entry = if i == 0 { 0.0 } else { v };
            let exit = if i == count - 1 { 0.0 } else { v };
            StepBlock {
                seq: i as u64,
                start,
                end,
                length_mm: 0.1,
                v_entry: entry,
                v_exit: exit,
                v_cruise: v,
                v_limit: v,
                path: edmd::preprocess::PathLimits {
                    cruise: v,
                    entry,
                    exit,
                },
                line,
                path_end_mm: 0.1 * (i + 1) as f64,
                ..StepBlock::EMPTY
            }
        })
        .collect()
}

/// The simulated gap, recording where the cut has got to each 0.1 mm: when, the off time
/// the generator was told, and the height the law estimates (from the published snapshot).
struct Recorder<'a> {
    gap: SimGap,
    published: &'a Published,
    tick: u64,
    dt: f64,
    x_steps: i64,
    off_time_us: f64,
    samples: Vec<Sample>,
}

impl GapSensor for Recorder<'_> {
    fn sample(&mut self, tick: u64) -> Result<GapState, GapError> {
        self.tick = tick;
        self.gap.sample(tick)
    }

    fn observe(&mut self, steps: &[i8; MAX_AXES], dir: i8) {
        self.gap.observe(steps, dir);
        self.x_steps += i64::from(steps[0]);
        let next = (self.samples.len() as i64 + 1) * 100;
        if self.x_steps >= next {
            self.samples.push(Sample {
                mm: next as f64 / 1000.0,
                seconds: self.tick as f64 * self.dt,
                off_time_us: self.off_time_us,
                height_mm: self.published.snapshot().height_mm,
            });
        }
    }

    fn moving_in(&mut self, now: edmd::buffer::Activity) {
        self.gap.moving_in(now)
    }

    fn volts(&self) -> Option<f64> {
        self.gap.volts()
    }

    fn ratios(&self) -> Option<(f64, f64)> {
        self.gap.ratios()
    }

    fn pulses(&self) -> Option<PulseCounts> {
        self.gap.pulses()
    }

    fn flushing(&self) -> Option<f64> {
        self.gap.flushing()
    }

    fn generator(&mut self, set: &GeneratorSetPoints) {
        self.off_time_us = set.off_time_us;
        self.gap.generator(set)
    }
}

/// Cuts the stepped part once.
pub fn cut(seed: u64, off: OffTime) -> Cut {
    cut_with(seed, off, &[])
}

/// Cuts the stepped part once, with more configuration `sets`.
pub fn cut_with(seed: u64, off: OffTime, sets: &[String]) -> Cut {
    let config = config(seed, off, sets);
    let settings = FineSettings::from_config(&config);
    let mut fine = Interpolator::new(settings, [0; MAX_AXES]);
    fine.set_conditions(ConditionTable::from_config(&config));
    let SimMachine { gap, mut inputs } =
        SimMachine::load(&SimSettings::from_config(&config), &[(0.0, LENGTH_MM)])
            .expect("the stepped part's events");
    let published = Published::new(4096);
    let mut recorder = Recorder {
        gap,
        published: &published,
        tick: 0,
        dt: config.fine.tick.secs(),
        x_steps: 0,
        off_time_us: f64::NAN,
        samples: Vec::new(),
    };
    let mut source = VecSource::new(blocks(), 64);
    let loop_settings = LoopSettings::from_config(&config);
    // The events queue is drained here, as the daemon's logger would.
    let report = std::thread::scope(|scope| {
        let drain = scope.spawn(|| {
            while !published
                .finished
                .load(std::sync::atomic::Ordering::Acquire)
            {
                while published.events.pop().is_some() {}
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
        });
        let report = run_loop(
            &mut fine,
            &mut source,
            &mut NullOutput,
            &mut recorder,
            &mut inputs,
            &loop_settings,
            &published,
        );
        drain.join().unwrap();
        report
    });
    let counted = published.snapshot();
    let [normal, arc, short, open] = counted.pulse_totals;
    Cut {
        seed,
        off,
        seconds: report.ticks as f64 * config.fine.tick.secs(),
        broke_at_mm: report.wire_break.map(|_| recorder.x_steps as f64 / 1000.0),
        samples: recorder.samples,
        pulses: PulseCounts {
            normal: normal as u32,
            arc: arc as u32,
            short: short as u32,
            open: open as u32,
            delay_sum_us: counted.delay_sum_us,
        },
    }
}
