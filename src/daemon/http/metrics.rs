//! `GET /metrics`: the status in Prometheus' text exposition format (version 0.0.4), every
//! name prefixed `edmd_`, base units (seconds, ratios; lengths in mm as the machine's unit).
//! Counters are the daemon's life-long [`Counters`] (finished jobs plus the running one), so
//! they only grow; the job's own figures are gauges. Checked by `promtool check metrics` and
//! scraped by a real Prometheus in `tests/it/http.rs`.

use std::fmt::Write;

use crate::daemon::protocol::{Counters, DaemonState, JobStatus, MqttStatus, Status};
use crate::runtime::consumer::LATENCY_BUCKETS_US;

struct Out(String);

impl Out {
    fn family(&mut self, name: &str, kind: &str, help: &str) {
        let _ = writeln!(self.0, "# HELP edmd_{name} {help}");
        let _ = writeln!(self.0, "# TYPE edmd_{name} {kind}");
    }

    fn sample(&mut self, name: &str, labels: &str, value: f64) {
        let value = if value.is_finite() {
            format!("{value}")
        } else if value.is_nan() {
            "NaN".to_string()
        } else if value > 0.0 {
            "+Inf".to_string()
        } else {
            "-Inf".to_string()
        };
        if labels.is_empty() {
            let _ = writeln!(self.0, "edmd_{name} {value}");
        } else {
            let _ = writeln!(self.0, "edmd_{name}{{{labels}}} {value}");
        }
    }

    fn one(&mut self, name: &str, kind: &str, help: &str, value: f64) {
        self.family(name, kind, help);
        self.sample(name, "", value);
    }
}

/// Label value escaping of the text format.
fn label(value: &str) -> String {
    value
        .replace('\\', "\\\\")
        .replace('"', "\\\"")
        .replace('\n', "\\n")
}

pub fn render(status: &Status) -> String {
    let mut o = Out(String::with_capacity(4096));
    o.one("up", "gauge", "1 while the daemon answers.", 1.0);
    o.one(
        "uptime_seconds",
        "gauge",
        "Seconds since the daemon started.",
        status.uptime_s,
    );
    o.one(
        "control_requests_total",
        "counter",
        "Requests the control loop answered (commands; status reads come from its board).",
        status.control_requests as f64,
    );
    o.family(
        "state",
        "gauge",
        "The daemon's state: 1 for the one it is in, 0 for the others.",
    );
    for state in &DaemonState::ALL {
        let labels = format!("state=\"{}\"", state.name());
        o.sample(
            "state",
            &labels,
            f64::from(u8::from(*state == status.state)),
        );
    }
    o.one(
        "feed_override_ratio",
        "gauge",
        "The operator's feed override (1 is 100 %).",
        f64::from(status.overrides.feed_pct) / 100.0,
    );
    o.one(
        "rapid_override_ratio",
        "gauge",
        "The operator's rapid override (1 is 100 %).",
        f64::from(status.overrides.rapid_pct) / 100.0,
    );
    let job = status.job.as_ref();
    o.one(
        "job_running",
        "gauge",
        "1 while a job is in hand (cutting, held or stopping).",
        f64::from(u8::from(job.is_some())),
    );
    if let Some(j) = job {
        job_metrics(&mut o, j, &status.axes);
    }
    counter_metrics(&mut o, &status.counters);
    if let Some(m) = &status.mqtt {
        mqtt_metrics(&mut o, m);
    }
    o.0
}

/// The Sparkplug B edge node (when `daemon.mqtt` is on).
fn mqtt_metrics(o: &mut Out, m: &MqttStatus) {
    o.one(
        "mqtt_connected",
        "gauge",
        "1 while the Sparkplug B edge node is connected to its broker.",
        f64::from(u8::from(m.connected)),
    );
    for (name, help, value) in [
        ("mqtt_births_total", "NBIRTHs published.", m.births),
        (
            "mqtt_published_total",
            "Sparkplug messages handed to the broker's queue.",
            m.published,
        ),
        (
            "mqtt_dropped_total",
            "Sparkplug messages dropped: the queue to the broker was full.",
            m.dropped,
        ),
        (
            "mqtt_commands_refused_total",
            "NCMD holds and aborts refused (daemon.mqtt.commands is false).",
            m.commands_refused,
        ),
    ] {
        o.one(name, "counter", help, value as f64);
    }
}

/// The job in hand: its program, progress, position, feed and buffer.
fn job_metrics(o: &mut Out, j: &JobStatus, axes: &[String]) {
    let program = format!("program=\"{}\"", label(&j.program));
    o.family("job_info", "gauge", "The job in hand, as labels.");
    o.sample(
        "job_info",
        &format!("{program},servo=\"{}\"", label(j.servo.name())),
        1.0,
    );
    o.one(
        "job_progress_ratio",
        "gauge",
        "Fraction of the program's path done (0 to 1).",
        j.progress,
    );
    o.one(
        "job_path_done_mm",
        "gauge",
        "Path length done, mm.",
        j.path_done_mm,
    );
    o.one(
        "job_path_total_mm",
        "gauge",
        "Path length of the whole program, mm.",
        j.path_total_mm,
    );
    if let Some(eta) = j.eta_s {
        o.one(
            "job_eta_seconds",
            "gauge",
            "Seconds to the program's end at the recent feed.",
            eta,
        );
    }
    o.one(
        "job_line",
        "gauge",
        "Source line of the move in hand.",
        j.line as f64,
    );
    o.family(
        "position_mm",
        "gauge",
        "Position per axis (the pulse ledger), mm.",
    );
    for (axis, mm) in axes.iter().zip(&j.position_mm) {
        o.sample("position_mm", &format!("axis=\"{}\"", label(axis)), *mm);
    }
    o.one(
        "feed_mm_per_minute",
        "gauge",
        "Path speed, mm/min.",
        j.feed_mm_per_min,
    );
    if let Some(p) = &j.process {
        process_metrics(o, p);
    }
    o.family("buffer_blocks", "gauge", "Loop-buffer blocks by area.");
    o.sample(
        "buffer_blocks",
        "area=\"unprocessed\"",
        j.buffer_unprocessed as f64,
    );
    o.sample(
        "buffer_blocks",
        "area=\"reserved\"",
        j.buffer_reserved as f64,
    );
    o.one(
        "buffer_capacity_blocks",
        "gauge",
        "Loop-buffer capacity, blocks.",
        j.buffer_capacity as f64,
    );
}

/// The process as the pulses tell it: rates by class, the ignition delay, the off time, the
/// height estimate and the cut rate.
fn process_metrics(o: &mut Out, p: &crate::daemon::protocol::ProcessStatus) {
    o.family(
        "gap_pulses_per_second",
        "gauge",
        "The generator's pulses per second by class, over the job so far.",
    );
    let r = &p.rates_hz;
    for (class, rate) in [
        ("normal", r.normal),
        ("arc", r.arc),
        ("short", r.short),
        ("open", r.open),
    ] {
        o.sample("gap_pulses_per_second", &format!("class=\"{class}\""), rate);
    }
    if let Some(delay) = p.mean_ignition_delay_us {
        o.one(
            "gap_ignition_delay_us",
            "gauge",
            "Mean ignition delay of the discharges so far, µs.",
            delay,
        );
    }
    o.one(
        "generator_off_time_us",
        "gauge",
        "The generator's off time in force (adapted or as set), µs.",
        p.off_time_us,
    );
    if let Some(h) = p.height_estimate_mm {
        o.one(
            "process_height_estimate_mm",
            "gauge",
            "The adaptive law's estimate of the part height, mm.",
            h,
        );
    }
    if let Some(rate) = p.cut_rate_mm2_per_min {
        o.one(
            "process_cut_rate_mm2_per_minute",
            "gauge",
            "Recent feed times the estimated height, mm²/min.",
            rate,
        );
    }
}

/// The counts since the daemon started, and the latency histogram.
fn counter_metrics(o: &mut Out, c: &Counters) {
    o.one("jobs_total", "counter", "Jobs started.", c.jobs as f64);
    for (name, help, value) in c.servo.counts() {
        o.one(&format!("{name}_total"), "counter", help, value as f64);
    }
    let counters: [(&str, &str, u64); 3] = [
        (
            "holds_total",
            "Holds: operator, programmed stop, collision, alarm, wire break.",
            c.holds,
        ),
        (
            "overruns_total",
            "Ticks whose work ended after the next deadline.",
            c.overruns,
        ),
        (
            "checkpoint_failures_total",
            "Checkpoint writes that failed (motion waits for the write-ahead ones).",
            c.checkpoint_failures,
        ),
    ];
    for (name, help, value) in counters {
        o.one(name, "counter", help, value as f64);
    }
    o.one(
        "ticks_total",
        "counter",
        "Fine-interpolation ticks.",
        c.ticks as f64,
    );
    o.family("gap_ticks_total", "counter", "Ticks by the gap state read.");
    for (state, n) in ["normal", "open", "short"].iter().zip(c.gap_ticks) {
        o.sample("gap_ticks_total", &format!("state=\"{state}\""), n as f64);
    }
    o.family(
        "tick_latency_seconds",
        "histogram",
        "Wake-up latency of the real-time ticks (one per fine.ticks_per_wake ticks; none in virtual time).",
    );
    let mut cumulative = 0;
    for (i, le) in LATENCY_BUCKETS_US.iter().enumerate() {
        cumulative += c.latency_buckets.get(i).copied().unwrap_or(0);
        let labels = format!("le=\"{}\"", *le as f64 / 1e6);
        o.sample("tick_latency_seconds_bucket", &labels, cumulative as f64);
    }
    cumulative += c
        .latency_buckets
        .get(LATENCY_BUCKETS_US.len())
        .copied()
        .unwrap_or(0);
    o.sample(
        "tick_latency_seconds_bucket",
        "le=\"+Inf\"",
        cumulative as f64,
    );
    o.sample("tick_latency_seconds_sum", "", c.latency_sum_us * 1e-6);
    o.sample("tick_latency_seconds_count", "", cumulative as f64);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::daemon::protocol::Counters;

    fn status() -> Status {
        Status {
            uptime_s: 12.5,
            counters: Counters {
                jobs: 2,
                servo: crate::servo::ServoCounters {
                    shorts: 7,
                    ..Default::default()
                },
                gap_ticks: [10, 20, 30],
                latency_buckets: vec![5, 0, 3, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1],
                latency_sum_us: 40.0,
                ..Counters::default()
            },
            ..Status::bare(DaemonState::Held)
        }
    }

    #[test]
    fn states_counters_and_a_cumulative_histogram() {
        let text = render(&status());
        assert!(text.contains("edmd_state{state=\"held\"} 1\n"), "{text}");
        assert!(text.contains("edmd_state{state=\"idle\"} 0\n"));
        assert!(
            text.contains("# TYPE edmd_feed_override_ratio gauge\nedmd_feed_override_ratio 1\n")
        );
        assert!(text.contains("# TYPE edmd_shorts_total counter\nedmd_shorts_total 7\n"));
        assert!(text.contains("edmd_gap_ticks_total{state=\"short\"} 30\n"));
        assert!(text.contains("edmd_tick_latency_seconds_bucket{le=\"0.000001\"} 5\n"));
        assert!(text.contains("edmd_tick_latency_seconds_bucket{le=\"0.000005\"} 8\n"));
        assert!(text.contains("edmd_tick_latency_seconds_bucket{le=\"+Inf\"} 9\n"));
        assert!(text.contains("edmd_tick_latency_seconds_count 9\n"));
        assert_eq!(text.matches("edmd_state{").count(), DaemonState::ALL.len());
    }

    #[test]
    fn every_state_has_its_gauge() {
        // The match names every variant (a new one does not compile until it is placed);
        // `ALL` must hold each exactly once.
        let place = |s: DaemonState| match s {
            DaemonState::Idle => 0,
            DaemonState::Checking => 1,
            DaemonState::Running => 2,
            DaemonState::Holding => 3,
            DaemonState::Held => 4,
            DaemonState::Paused => 5,
            DaemonState::Stopping => 6,
            DaemonState::WireBreak => 7,
            DaemonState::Rethreading => 8,
            DaemonState::Mdi => 9,
            DaemonState::Estop => 10,
            DaemonState::Limit => 11,
            DaemonState::Jogging => 12,
            DaemonState::Homing => 13,
            DaemonState::Threading => 14,
            DaemonState::Finding => 15,
        };
        let mut seen: Vec<usize> = DaemonState::ALL.iter().map(|&s| place(s)).collect();
        seen.sort_unstable();
        assert_eq!(seen, (0..16).collect::<Vec<_>>());
    }

    #[test]
    fn label_values_are_escaped() {
        assert_eq!(label("a\"b\\c\nd"), "a\\\"b\\\\c\\nd");
    }
}
