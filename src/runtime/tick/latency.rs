//! Wake-up latency of the real-time loop: how late each tick started after its deadline.
//!
//! The histogram itself is [`LatencyHistogram`] (in `histogram.rs`, shared with the tick
//! loop). [`measure`] is the bench mode behind `edmd latency`: the real consumer loop
//! ([`run_loop`](super::consumer::run_loop)) on its own thread with the configured real-time
//! set-up, ticking for a given time over an endless square path (the program-independent part
//! of a job), and its histogram printed in cyclictest's format, so that
//! `scripts/latency-vs-cyclictest.sh` can read both with the same code.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use super::consumer::{LoopSettings, Published, run_loop};
use super::histogram::LatencyHistogram;
use super::realtime::apply_realtime;
use crate::buffer::{BlockSource, Fetch, StepBlock};
use crate::config::Config;
use crate::fine::{FineSettings, Interpolator};
use crate::gap::AlwaysNormal;
use crate::output::NullOutput;
use crate::vocab::{MAX_AXES, Steps};

/// What [`measure`] measured.
#[derive(Debug)]
pub struct LatencyRun {
    pub histogram: LatencyHistogram,
    pub ticks: u64,
    pub overruns: u64,
    pub missed_deadlines: u64,
    pub wall_ns: u64,
    /// Pulses the loop emitted, all axes (it did the work of a job, not just wake up).
    pub pulses: u64,
    /// Real-time features the system refused.
    pub rt_refused: Vec<String>,
}

/// Runs the real consumer loop in real time at `config.fine.tick` with the configured
/// priority, memory locking and CPU, for `duration`, over an endless square path at the servo's
/// normal feed, discarding the pulses (`NullOutput`) with the gap always normal. Virtual time
/// in `config` is ignored: latency only exists in real time.
pub fn measure(config: &Config, duration: Duration) -> std::io::Result<LatencyRun> {
    let mut loop_settings = LoopSettings::from_config(config);
    loop_settings.virtual_time = false;
    let fine_settings = FineSettings::from_config(config);
    let published = Arc::new(Published::new(1024));
    let thread_published = published.clone();
    let worker = std::thread::Builder::new()
        .name("edmd-fine".into())
        .spawn(move || {
            let guard = apply_realtime(&loop_settings);
            let mut fine = Interpolator::new(fine_settings, [0; MAX_AXES]);
            let mut source = SquarePath::new(&fine_settings);
            thread_published.publish(0, &fine);
            let report = run_loop(
                &mut fine,
                &mut source,
                &mut NullOutput,
                &mut AlwaysNormal,
                &mut crate::inputs::NoInputs,
                &loop_settings,
                &thread_published,
            );
            (report, guard.refused)
        })?;
    std::thread::sleep(duration);
    published.stop.store(true, Ordering::Relaxed);
    let (report, rt_refused) = worker
        .join()
        .map_err(|_| std::io::Error::other("the loop thread panicked"))?;
    Ok(LatencyRun {
        histogram: report.latency.unwrap_or_default(),
        ticks: report.ticks,
        overruns: report.overruns,
        missed_deadlines: report.missed_deadlines,
        wall_ns: report.wall_ns,
        pulses: published.snapshot().pulses.iter().sum(),
        rt_refused,
    })
}

/// An endless source of blocks going round a square, 10 mm a side on the first two axes,
/// planned at the normal feed throughout, generated as they are asked for (no allocation, no
/// producer thread).
struct SquarePath {
    side_steps: i64,
    side_mm: f64,
    feed: f64,
    next_seq: u64,
    at: Steps,
}

impl SquarePath {
    fn new(settings: &FineSettings) -> SquarePath {
        let step = settings.step_mm[0].max(settings.step_mm[1]);
        let side_steps = (10.0 / step).round().max(1.0) as i64;
        SquarePath {
            side_steps,
            side_mm: side_steps as f64 * step,
            feed: settings.feeds.normal,
            next_seq: 0,
            at: [0; MAX_AXES],
        }
    }
}

impl BlockSource for SquarePath {
    fn next(&mut self, out: &mut StepBlock) -> Fetch {
        let mut end = self.at;
        let (axis, sign) = [(0, 1), (1, 1), (0, -1), (1, -1)][(self.next_seq % 4) as usize];
        end[axis] += sign * self.side_steps;
        *out = StepBlock {
            seq: self.next_seq,
            start: self.at,
            end,
            length_mm: self.side_mm,
            v_entry: self.feed,
            v_exit: self.feed,
            v_cruise: self.feed,
            v_limit: self.feed,
            path: crate::preprocess::PathLimits {
                cruise: self.feed,
                entry: self.feed,
                exit: self.feed,
            },
            ..StepBlock::EMPTY
        };
        self.at = end;
        self.next_seq += 1;
        Fetch::Block
    }

    fn previous(&mut self, _out: &mut StepBlock) -> bool {
        false // the gap is always normal: no turn-back
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bench_mode_ticks_in_real_time_and_steps() {
        let config = Config::load(
            None,
            &["fine.rt_priority=0".into(), "fine.lock_memory=false".into()],
        )
        .unwrap();
        let run = measure(&config, Duration::from_millis(200)).unwrap();
        let tick_s = config.fine.tick.secs();
        // Wall clock bounds the ticks (deadlines missed on a loaded machine are skipped, so
        // fewer is possible; more is not).
        let most = (run.wall_ns as f64 * 1e-9 / tick_s).ceil() as u64 + 1;
        assert!(
            run.ticks > 0 && run.ticks <= most,
            "{} ticks, at most {most}",
            run.ticks
        );
        assert_eq!(run.histogram.samples(), run.ticks);
        assert!(run.pulses > 0, "the loop moved nothing");
        let text = run.histogram.cyclictest_format();
        let total: u64 = text
            .lines()
            .filter(|l| !l.starts_with('#'))
            .map(|l| l.split_whitespace().nth(1).unwrap().parse::<u64>().unwrap())
            .sum();
        let overflows: u64 = text
            .lines()
            .find_map(|l| l.strip_prefix("# Histogram Overflows: "))
            .unwrap()
            .parse()
            .unwrap();
        assert_eq!(total + overflows, run.ticks);
    }
}
