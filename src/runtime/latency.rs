//! Wake-up latency of the real-time loop: how late each tick started after its deadline.
//!
//! [`LatencyHistogram`] is allocated once before the loop; recording is two array writes.
//! [`measure`] is the bench mode behind `edmd latency`: the real consumer loop
//! ([`run_loop`](super::consumer::run_loop)) on its own thread with the configured real-time
//! set-up, ticking for a given time over an endless square path (the program-independent part
//! of a job), and its histogram printed in cyclictest's format, so that
//! `scripts/latency-vs-cyclictest.sh` can read both with the same code.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::consumer::{LoopSettings, Published, apply_realtime, run_loop};
use crate::buffer::{BlockSource, Fetch, StepBlock};
use crate::config::Config;
use crate::fine::{FineSettings, Interpolator};
use crate::gap::AlwaysNormal;
use crate::geometry::MAX_AXES;
use crate::output::NullOutput;

/// Bucket width (ns).
const BUCKET_NS: u64 = 100;
/// Buckets: 0 to 2 ms at 100 ns; later wake-ups go to the last bucket (the maximum is
/// kept exactly).
const BUCKETS: usize = 20_000;

#[derive(Debug, Clone)]
pub struct LatencyHistogram {
    counts: Box<[u64]>,
    samples: u64,
    max_ns: u64,
    sum_ns: u128,
}

/// Percentiles of a histogram, in µs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LatencySummary {
    pub samples: u64,
    pub p50_us: f64,
    pub p99_us: f64,
    pub p999_us: f64,
    pub max_us: f64,
    pub mean_us: f64,
}

impl Default for LatencyHistogram {
    fn default() -> Self {
        LatencyHistogram {
            counts: vec![0; BUCKETS].into_boxed_slice(),
            samples: 0,
            max_ns: 0,
            sum_ns: 0,
        }
    }
}

impl LatencyHistogram {
    #[inline]
    pub fn record(&mut self, latency_ns: u64) {
        let bucket = ((latency_ns / BUCKET_NS) as usize).min(BUCKETS - 1);
        self.counts[bucket] += 1;
        self.samples += 1;
        self.max_ns = self.max_ns.max(latency_ns);
        self.sum_ns += latency_ns as u128;
    }

    pub fn samples(&self) -> u64 {
        self.samples
    }

    /// The latency (ns) below which a fraction `q` of the samples fall: the upper edge of
    /// the bucket holding the `q`-quantile, never above the maximum seen.
    pub fn quantile_ns(&self, q: f64) -> u64 {
        if self.samples == 0 {
            return 0;
        }
        let rank = ((q * self.samples as f64).ceil() as u64).clamp(1, self.samples);
        let mut seen = 0;
        for (i, &c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= rank {
                if i == BUCKETS - 1 {
                    return self.max_ns;
                }
                return ((i as u64 + 1) * BUCKET_NS).min(self.max_ns);
            }
        }
        self.max_ns
    }

    pub fn summary(&self) -> LatencySummary {
        let us = |ns: u64| ns as f64 / 1000.0;
        LatencySummary {
            samples: self.samples,
            p50_us: us(self.quantile_ns(0.50)),
            p99_us: us(self.quantile_ns(0.99)),
            p999_us: us(self.quantile_ns(0.999)),
            max_us: us(self.max_ns),
            mean_us: if self.samples == 0 {
                0.0
            } else {
                self.sum_ns as f64 / self.samples as f64 / 1000.0
            },
        }
    }

    /// Counts per whole microsecond, `counts[us]` holding wake-ups in `[us, us + 1)` µs, up to
    /// the histogram's range (2 ms), and the count beyond it: cyclictest's `-h` layout.
    pub fn per_microsecond(&self) -> (Vec<u64>, u64) {
        let per_us = (1000 / BUCKET_NS) as usize;
        let (inside, beyond) = self.counts.split_at(BUCKETS - 1);
        let counts = inside.chunks(per_us).map(|c| c.iter().sum()).collect();
        (counts, beyond[0])
    }

    /// The histogram as cyclictest prints it with `-h`: one `µs count` line per microsecond
    /// up to the last non-empty one, then the overflow count and the maximum.
    pub fn cyclictest_format(&self) -> String {
        use std::fmt::Write;
        let (counts, overflows) = self.per_microsecond();
        let last = counts.iter().rposition(|&c| c > 0).map_or(0, |i| i + 1);
        let mut out = String::from("# Histogram\n");
        for (us, c) in counts[..last].iter().enumerate() {
            let _ = writeln!(out, "{us:06} {c:06}");
        }
        let _ = writeln!(out, "# Total: {:09}", self.samples);
        let _ = writeln!(out, "# Histogram Overflows: {overflows:05}");
        let _ = writeln!(out, "# Max Latencies: {:05}", self.max_ns / 1000);
        out
    }
}

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

/// Runs the real consumer loop in real time at `config.fine.tick_us` with the configured
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
    at: [i64; MAX_AXES],
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
            line: 0,
            u_end: f64::NAN,
            flags: 0,
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
        let tick_s = config.fine.tick_us as f64 * 1e-6;
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

    #[test]
    fn per_microsecond_buckets_add_up() {
        let mut h = LatencyHistogram::default();
        for ns in [0, 999, 1000, 1500, 2999, 3_000_000] {
            h.record(ns);
        }
        let (counts, beyond) = h.per_microsecond();
        assert_eq!(&counts[..4], &[2, 2, 1, 0]);
        assert_eq!(beyond, 1);
        assert_eq!(counts.len(), 2000 - 1 + 1); // 1999.9 µs: the last µs holds 9 buckets
        assert!(h.cyclictest_format().contains("# Max Latencies: 03000"));
    }

    #[test]
    fn quantiles_come_from_the_buckets() {
        let mut h = LatencyHistogram::default();
        for i in 0..1000u64 {
            h.record(i * 10); // 0 .. 9.99 µs, uniform
        }
        h.record(5_000_000); // one 5 ms outlier, beyond the last bucket
        let s = h.summary();
        assert_eq!(s.samples, 1001);
        assert!((s.p50_us - 5.0).abs() <= 0.1, "{}", s.p50_us);
        assert!((s.p99_us - 9.9).abs() <= 0.1, "{}", s.p99_us);
        assert_eq!(s.max_us, 5000.0);
        assert_eq!(h.quantile_ns(1.0), 5_000_000);
    }
}
