//! The wake-up latency histogram of the real-time loop: how late each tick started after its
//! deadline, in 100 ns buckets up to 2 ms (an overflow count beyond). Allocated once before
//! the loop; recording is two array writes, so the tick loop may record every tick.

use serde::{Deserialize, Serialize};

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
    fn quantile_ns(&self, q: f64) -> u64 {
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
    fn per_microsecond(&self) -> (Vec<u64>, u64) {
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

#[cfg(test)]
mod tests {
    use super::*;

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
