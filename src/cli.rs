//! The `edmd` command line: argument parsing, logging set-up, and the exit codes of
//! `design.md` (0 success, 1 runtime failure, 2 bad input).

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use clap::{Args, Parser, Subcommand};

use crate::check;
use crate::config::{self, Config, LogFormat};
use crate::gcode;
use crate::plan;
use crate::runtime::{self, JobError, Outcome};

/// Exit code for bad input: program, configuration or usage.
pub const EXIT_BAD_INPUT: u8 = 2;
/// Exit code for a runtime failure: alarm, device error.
pub const EXIT_RUNTIME: u8 = 1;

#[derive(Parser, Debug)]
#[command(
    name = "edmd",
    version,
    about = "Real-time NURBS interpolation daemon for EDM controllers"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Parse and validate a program; print what it contains. Exit 2 on errors.
    Check(CheckArgs),
    /// Run the preprocessor alone, offline: trace CSV, summary (text and JSON) and SVG plots.
    Plan(PlanArgs),
    /// Run one job in the foreground through both threads, then print a summary.
    /// Exit 1 on an alarm or a device error.
    Run(RunArgs),
    /// The daemon: claim the output, start the real-time thread, take jobs from the control
    /// socket (daemon.socket). SIGTERM/SIGINT: controlled stop and checkpoint; SIGHUP:
    /// reload; SIGUSR1: status into the log.
    Serve(ServeArgs),
    /// Talk to a running daemon: run, hold, resume, abort, status.
    Ctl(CtlArgs),
    /// Bench mode: run the real-time loop alone for a while (an endless square path, pulses
    /// discarded, gap always normal) and print its wake-up latency histogram in cyclictest's
    /// format. See scripts/latency-vs-cyclictest.sh.
    Latency(LatencyArgs),
}

#[derive(Args, Debug)]
struct ServeArgs {
    #[command(flatten)]
    config: ConfigArgs,
}

#[derive(Args, Debug)]
struct CtlArgs {
    /// The daemon's control socket [default: daemon.socket of the configuration]
    #[arg(long, value_name = "PATH", global = true)]
    socket: Option<PathBuf>,
    /// Print the daemon's reply as JSON (one line) instead of text
    #[arg(long, global = true)]
    json: bool,
    #[command(flatten)]
    config: ConfigArgs,
    #[command(subcommand)]
    command: CtlCommand,
}

#[derive(Subcommand, Debug)]
enum CtlCommand {
    /// Run a program (a path inside daemon.program_dir): the daemon copies and checks it,
    /// then starts the job; this waits for that verdict (exit 0: started; 1: refused)
    Run {
        /// Program path, relative to daemon.program_dir (or absolute inside it)
        program: String,
        /// Return as soon as the daemon has accepted the request (the verdict shows in
        /// `edmd ctl status`)
        #[arg(long)]
        no_wait: bool,
    },
    /// Brake to a standstill and hold there (checkpoint written)
    Hold,
    /// Release a hold; with no job running, resume the checkpoint's job (waiting for its
    /// check, as `run` does)
    Resume {
        /// Resume from a checkpoint written while cutting (the electrode may be past it)
        #[arg(long)]
        force: bool,
        /// Return as soon as the daemon has accepted the request
        #[arg(long)]
        no_wait: bool,
    },
    /// Brake to a standstill and end the job (checkpoint kept)
    Abort,
    /// Print what the daemon is doing
    Status,
}

/// Options shared by every command that reads the configuration.
#[derive(Args, Debug)]
struct ConfigArgs {
    /// Configuration file [default: config/edmd.toml if present, else the built-in default]
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Override one key, e.g. --set buffer.capacity=64 (TOML value; repeatable)
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    set: Vec<String>,
}

impl ConfigArgs {
    /// The file to read: `--config`, else `config/edmd.toml` if present, else none (the
    /// built-in default).
    fn path(&self) -> Option<PathBuf> {
        match &self.config {
            Some(path) => Some(path.clone()),
            None => {
                let default = Path::new(config::DEFAULT_CONFIG_PATH);
                default.exists().then(|| default.to_path_buf())
            }
        }
    }

    fn load(&self) -> Result<Config, config::ConfigError> {
        Config::load(self.path().as_deref(), &self.set)
    }
}

#[derive(Args, Debug)]
struct CheckArgs {
    /// G-code program
    program: PathBuf,
    #[command(flatten)]
    config: ConfigArgs,
    /// Print only the totals, not one line per block
    #[arg(short, long)]
    quiet: bool,
}

#[derive(Args, Debug)]
struct PlanArgs {
    /// G-code program
    program: PathBuf,
    /// Output directory (created if needed): trace.csv, summary.json, summary.txt, *.svg
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    #[command(flatten)]
    config: ConfigArgs,
    /// No progress bar, even on a terminal
    #[arg(short, long)]
    quiet: bool,
}

#[derive(Args, Debug)]
struct RunArgs {
    /// G-code program
    program: PathBuf,
    #[command(flatten)]
    config: ConfigArgs,
    /// Also write the end-of-job summary as JSON to FILE
    #[arg(long, value_name = "FILE")]
    summary: Option<PathBuf>,
}

#[derive(Args, Debug)]
struct LatencyArgs {
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

/// Entry point of the binary.
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Check(args) => run_check(&args),
        Command::Plan(args) => run_plan(&args),
        Command::Run(args) => run_job(&args),
        Command::Serve(args) => run_serve(&args),
        Command::Ctl(args) => run_ctl(&args),
        Command::Latency(args) => run_latency(args),
    }
}

/// Sets up logging as configured; returns the way to change the level later (SIGHUP).
fn init_logging(cfg: &config::LogConfig) -> crate::daemon::SetLogLevel {
    use tracing_subscriber::layer::SubscriberExt;
    use tracing_subscriber::util::SubscriberInitExt;
    use tracing_subscriber::{EnvFilter, Layer, Registry, fmt, reload};

    let from_env = std::env::var_os("RUST_LOG").is_some();
    let filter =
        EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(cfg.level.name()));
    let (filter, handle) = reload::Layer::<EnvFilter, Registry>::new(filter);
    let terminal = std::io::stderr().is_terminal();
    let layer = fmt::layer().with_writer(std::io::stderr);
    let layer = match cfg.format {
        LogFormat::Json => layer.json().boxed(),
        LogFormat::Plain => layer.with_ansi(false).boxed(),
        LogFormat::Human | LogFormat::Auto => layer.with_ansi(terminal).boxed(),
    };
    // A second initialisation (tests calling twice) is harmless, so its error is ignored.
    let _ = tracing_subscriber::registry()
        .with(filter)
        .with(layer)
        .try_init();
    Box::new(move |level: &str| {
        if from_env {
            return Err("RUST_LOG is set and takes precedence; level unchanged".to_string());
        }
        handle
            .reload(EnvFilter::new(level))
            .map_err(|e| e.to_string())
    })
}

fn load_config(args: &ConfigArgs) -> Result<Config, ExitCode> {
    args.load().map_err(|e| {
        eprintln!("edmd: error: {e}");
        ExitCode::from(EXIT_BAD_INPUT)
    })
}

fn run_check(args: &CheckArgs) -> ExitCode {
    let cfg = match load_config(&args.config) {
        Ok(c) => c,
        Err(code) => return code,
    };
    let _ = init_logging(&cfg.log);
    let axes = &cfg.machine.axes;
    let mut reader = match gcode::open_program(&args.program, axes) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("edmd: error: {e}");
            return ExitCode::from(EXIT_BAD_INPUT);
        }
    };
    let name = args.program.display().to_string();
    let mut totals = check::Totals::default();
    if !args.quiet {
        println!("{name}");
        println!("{}", check::BLOCK_TABLE_HEADER);
    }
    let mut failed = None;
    for item in reader.by_ref() {
        match item {
            Ok(block) => {
                let length = block.curve.length();
                if !args.quiet {
                    println!("{}", check::describe_block(&block, length, axes));
                }
                totals.add(&block, length);
            }
            Err(e) => {
                failed = Some(e);
                break;
            }
        }
    }
    for w in reader.take_warnings() {
        if w.line == 0 {
            eprintln!("{name}: warning: {}", w.message);
        } else {
            eprintln!("{name}:{}:{}: warning: {}", w.line, w.col, w.message);
        }
    }
    if let Some(e) = failed {
        eprintln!("edmd: error: {e}");
        return ExitCode::from(EXIT_BAD_INPUT);
    }
    println!(
        "{}",
        check::describe_totals(&totals, axes, cfg.machine.max_feed_mm_per_min)
    );
    if let Some(line) = reader.program_end_line() {
        println!("program end: line {line}");
    }
    ExitCode::SUCCESS
}

fn run_plan(args: &PlanArgs) -> ExitCode {
    let cfg = match load_config(&args.config) {
        Ok(c) => c,
        Err(code) => return code,
    };
    let _ = init_logging(&cfg.log);
    match plan::plan_program(&args.program, &cfg, &args.out, !args.quiet) {
        Ok(summary) => {
            print!("{}", summary.text());
            println!("written to {}", args.out.display());
            ExitCode::SUCCESS
        }
        Err(e @ plan::PlanError::Program(_)) => {
            eprintln!("edmd: error: {e}");
            ExitCode::from(EXIT_BAD_INPUT)
        }
        Err(e) => {
            eprintln!("edmd: error: {e}");
            ExitCode::from(EXIT_RUNTIME)
        }
    }
}

fn run_latency(mut args: LatencyArgs) -> ExitCode {
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
            print!("{header}");
        }
        None => print!("{header}{histogram}"),
    }
    ExitCode::SUCCESS
}

/// SIGINT and SIGTERM set the returned flag: the job stops where it is, the outputs go
/// inactive and the summary reports the position. A second signal ends the process at once
/// (exit 1), in case stopping hangs.
fn stop_on_signals() -> Arc<AtomicBool> {
    use signal_hook::consts::{SIGINT, SIGTERM};
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [SIGINT, SIGTERM] {
        // The shutdown must be registered first: it acts on the second signal only.
        let registered = signal_hook::flag::register_conditional_shutdown(
            signal,
            EXIT_RUNTIME as i32,
            stop.clone(),
        )
        .and_then(|_| signal_hook::flag::register(signal, stop.clone()));
        if let Err(e) = registered {
            tracing::warn!("cannot handle signal {signal} ({e}); it will end the process");
        }
    }
    stop
}

fn run_job(args: &RunArgs) -> ExitCode {
    let cfg = match load_config(&args.config) {
        Ok(c) => c,
        Err(code) => return code,
    };
    let _ = init_logging(&cfg.log);
    let stop = stop_on_signals();
    let summary = match runtime::run_job_until(&args.program, &cfg, &stop) {
        Ok(summary) => summary,
        Err(e) => {
            eprintln!("edmd: error: {e}");
            // A device that cannot be opened is a runtime failure; anything else that stops
            // a job before it starts is bad input.
            let code = match e {
                JobError::Output(_) | JobError::Parport(_) => EXIT_RUNTIME,
                _ => EXIT_BAD_INPUT,
            };
            return ExitCode::from(code);
        }
    };
    print!("{}", summary.text());
    if let Some(path) = &args.summary {
        let json = serde_json::to_string_pretty(&summary).expect("the summary serialises");
        if let Err(e) = std::fs::write(path, json + "\n") {
            eprintln!(
                "edmd: error: {}: cannot write the summary: {e}",
                path.display()
            );
            return ExitCode::from(EXIT_RUNTIME);
        }
    }
    match summary.outcome {
        Outcome::Done => ExitCode::SUCCESS,
        _ => {
            if let Some(e) = &summary.error {
                eprintln!("edmd: error: {}: {e}", summary.outcome.name());
            }
            ExitCode::from(EXIT_RUNTIME)
        }
    }
}

fn run_serve(args: &ServeArgs) -> ExitCode {
    let path = args.config.path();
    let (cfg, keys) = match Config::load_with_keys(path.as_deref(), &args.config.set) {
        Ok(loaded) => loaded,
        Err(e) => {
            eprintln!("edmd: error: {e}");
            return ExitCode::from(EXIT_BAD_INPUT);
        }
    };
    let set_level = init_logging(&cfg.log);
    let source = crate::daemon::ConfigSource {
        path,
        overrides: args.config.set.clone(),
    };
    match crate::daemon::serve(cfg, keys, source, set_level) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("{e}");
            eprintln!("edmd: error: {e}");
            ExitCode::from(EXIT_RUNTIME)
        }
    }
}

fn run_ctl(args: &CtlArgs) -> ExitCode {
    use crate::daemon::protocol::Request;
    let socket = match &args.socket {
        Some(socket) => socket.clone(),
        None => match load_config(&args.config) {
            Ok(cfg) => cfg.daemon.socket,
            Err(code) => return code,
        },
    };
    let (request, wait) = match &args.command {
        CtlCommand::Run { program, no_wait } => (
            Request::Run {
                program: program.clone(),
            },
            !no_wait,
        ),
        CtlCommand::Hold => (Request::Hold {}, false),
        CtlCommand::Resume { force, no_wait } => (Request::Resume { force: *force }, !no_wait),
        CtlCommand::Abort => (Request::Abort {}, false),
        CtlCommand::Status => (Request::Status {}, false),
    };
    let reply = match crate::daemon::socket::request(&socket, &request) {
        Ok(reply) => reply,
        Err(e) => {
            eprintln!("edmd: error: {e}");
            return ExitCode::from(EXIT_RUNTIME);
        }
    };
    let check = reply
        .status
        .as_ref()
        .and_then(|s| s.check.as_ref())
        .filter(|c| {
            reply.ok
                && wait
                && !c.decided()
                && matches!(request, Request::Run { .. } | Request::Resume { .. })
        });
    let reply = match check {
        Some(check) => {
            if !args.json {
                println!("{}", reply.message.as_deref().unwrap_or_default());
            }
            match crate::daemon::socket::wait_for_verdict(&socket, check.id, !args.json) {
                Ok(reply) => reply,
                Err(e) => {
                    eprintln!("edmd: error: {e}");
                    return ExitCode::from(EXIT_RUNTIME);
                }
            }
        }
        None => reply,
    };
    if args.json {
        print!("{}", reply.to_line());
    } else {
        if let Some(message) = reply
            .message
            .as_ref()
            .filter(|_| request != Request::Status {})
        {
            println!("{message}");
        }
        if let Some(status) = &reply.status
            && (request == Request::Status {} || !reply.ok)
        {
            print!("{}", status.text());
        }
    }
    match (&reply.ok, &reply.error) {
        (true, _) => ExitCode::SUCCESS,
        (false, error) => {
            eprintln!(
                "edmd: error: {}",
                error.as_deref().unwrap_or("the daemon refused")
            );
            ExitCode::from(EXIT_RUNTIME)
        }
    }
}
