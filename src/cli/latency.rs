//! `edmd latency`: the real-time loop alone for a while, its wake-up latency histogram in
//! cyclictest's format (`scripts/latency-vs-cyclictest.sh`).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;

use super::{ConfigArgs, EXIT_BAD_INPUT, EXIT_RUNTIME, init_logging, load_config, write_stdout};
use crate::runtime;

#[derive(Args, Debug)]
pub(super) struct LatencyArgs {
    #[command(flatten)]
    config: ConfigArgs,
    /// Tick period in µs [default: fine.tick_us]
    #[arg(long, value_name = "US")]
    tick_us: Option<u32>,
    /// SCHED_FIFO priority, 0 for none [default: fine.rt_priority]
    #[arg(long, value_name = "PRIO")]
    priority: Option<u8>,
    /// How long to run
    #[arg(long, value_name = "SECONDS", default_value_t = 10.0)]
    seconds: f64,
    /// Write the histogram (cyclictest's -h layout) to FILE instead of standard output
    #[arg(long, value_name = "FILE")]
    histogram: Option<PathBuf>,
}

pub(super) fn run_latency(mut args: LatencyArgs) -> ExitCode {
    if !(args.seconds.is_finite() && args.seconds > 0.0) {
        eprintln!(
            "edmd: error: --seconds {}: must be a positive number",
            args.seconds
        );
        return ExitCode::from(EXIT_BAD_INPUT);
    }
    if let Some(us) = args.tick_us {
        args.config.set.push(format!("fine.tick_us={us}"));
    }
    if let Some(priority) = args.priority {
        args.config.set.push(format!("fine.rt_priority={priority}"));
    }
    let cfg = match load_config(&args.config) {
        Ok(c) => c,
        Err(code) => return code,
    };
    let _ = init_logging(&cfg.log);
    let run =
        match runtime::latency::measure(&cfg, std::time::Duration::from_secs_f64(args.seconds)) {
            Ok(run) => run,
            Err(e) => {
                eprintln!("edmd: error: cannot start the loop thread: {e}");
                return ExitCode::from(EXIT_RUNTIME);
            }
        };
    let s = run.histogram.summary();
    let header = format!(
        "# edmd latency: tick {} µs, SCHED_FIFO {}, {:.1} s, {} ticks, {} pulses\n\
         # p50 {:.1} µs  p99 {:.1} µs  p99.9 {:.1} µs  max {:.1} µs  mean {:.2} µs\n\
         # overruns {} ({} deadlines skipped)\n",
        cfg.fine.tick.us(),
        cfg.fine.rt_priority,
        run.wall_ns as f64 * 1e-9,
        run.ticks,
        run.pulses,
        s.p50_us,
        s.p99_us,
        s.p999_us,
        s.max_us,
        s.mean_us,
        run.overruns,
        run.missed_deadlines,
    );
    let histogram = run.histogram.cyclictest_format();
    for reason in &run.rt_refused {
        eprintln!("edmd: warning: {reason}");
    }
    match &args.histogram {
        Some(path) => {
            if let Err(e) = std::fs::write(path, format!("{header}{histogram}")) {
                eprintln!("edmd: error: {}: {e}", path.display());
                return ExitCode::from(EXIT_RUNTIME);
            }
            out!("{header}");
        }
        None => out!("{header}{histogram}"),
    }
    ExitCode::SUCCESS
}
