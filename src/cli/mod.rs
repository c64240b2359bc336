//! The `edmd` command line: argument parsing, logging set-up, and the exit codes of
//! `design.md` (0 success, 1 runtime failure, 2 bad input).

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use clap::{Args, CommandFactory, Parser, Subcommand};

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
    /// Talk to a running daemon: jobs (run, hold, resume, abort, rethread), the machine (home,
    /// jog, mdi, find, touch-off, offsets, override, single-block, reset) and what it does
    /// (status, monitor).
    Ctl(CtlArgs),
    /// Bench mode: run the real-time loop alone for a while (an endless square path, pulses
    /// discarded, gap always normal) and print its wake-up latency histogram in cyclictest's
    /// format. See scripts/latency-vs-cyclictest.sh.
    Latency(latency::LatencyArgs),
    /// The technology tables: list them, or explain what a request selects and why.
    Tech(tech::TechArgs),
    /// A HAL file's last line (not `waitusr edmd`): exit 1 if edmd ends uncleanly
    HalWait(hal::HalWaitArgs),
    /// Before `loadusr -W edmd serve`: removes the component a killed edmd left
    HalReap(hal::HalReapArgs),
    /// Print the shell completion script for bash, zsh or fish.
    Completions(docs::CompletionsArgs),
    /// Write the man pages (edmd(1), one per subcommand) into a directory.
    #[command(hide = true)]
    Man(docs::ManArgs),
}

#[derive(Args, Debug)]
struct ServeArgs {
    #[command(flatten)]
    config: ConfigArgs,
}

/// Options shared by every command that reads the configuration.
#[derive(Args, Debug)]
struct ConfigArgs {
    /// Configuration file [default: $EDMD_CONFIG, else ./config/edmd.toml, else
    /// /etc/edmd/edmd.toml, the first that exists; else the built-in default]
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Override one key, e.g. --set buffer.capacity=64 (TOML value; repeatable)
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    set: Vec<String>,
}

/// The installed configuration, read when no other is named and no checkout's is at hand.
/// `print!` for standard output that a closed pipe cannot turn into a panic:
/// `edmd check big.nc | head -1` ends quietly, with the exit status of a Unix tool killed by
/// SIGPIPE (141), instead of panicking. (SIGPIPE itself stays ignored: the daemon and `ctl`
/// must outlive a peer that hangs up.)
macro_rules! out {
    ($($arg:tt)*) => { write_stdout(format_args!($($arg)*), false) };
}

/// [`out!`] with a line break, for `println!`.
macro_rules! outln {
    ($($arg:tt)*) => { write_stdout(format_args!($($arg)*), true) };
}

/// Exit status after standard output was closed under us: 128 + SIGPIPE, as a shell reports it.
const EXIT_CLOSED_PIPE: i32 = 141;

fn write_stdout(args: std::fmt::Arguments, newline: bool) {
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    let written = stdout.write_fmt(args).and_then(|()| {
        if newline {
            stdout.write_all(b"\n")
        } else {
            Ok(())
        }
    });
    match written {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => {
            std::process::exit(EXIT_CLOSED_PIPE)
        }
        Err(e) => {
            eprintln!("edmd: error: standard output: {e}");
            std::process::exit(i32::from(EXIT_RUNTIME))
        }
    }
}

mod check_cmd;
mod ctl;
mod cut;
mod docs;
mod hal;
mod journal;
mod latency;
mod run_state;
mod tech;
mod touch;

use check_cmd::run_check;
use ctl::{CtlArgs, run_ctl};
use run_state::RunState;

const INSTALLED_CONFIG: &str = "/etc/edmd/edmd.toml";

impl ConfigArgs {
    /// The file to read and how it was found: `--config`, else `$EDMD_CONFIG`, else
    /// `./config/edmd.toml` (a checkout), else `/etc/edmd/edmd.toml` (an installation), else
    /// none: the built-in default (the shipped file, compiled in).
    fn source(&self) -> (Option<PathBuf>, &'static str) {
        if let Some(path) = &self.config {
            return (Some(path.clone()), "--config");
        }
        if let Some(path) = std::env::var_os("EDMD_CONFIG").filter(|p| !p.is_empty()) {
            return (Some(PathBuf::from(path)), "$EDMD_CONFIG");
        }
        for (path, how) in [
            (config::DEFAULT_CONFIG_PATH, "the checkout's"),
            (INSTALLED_CONFIG, "the installed one"),
        ] {
            if Path::new(path).exists() {
                return (Some(PathBuf::from(path)), how);
            }
        }
        (None, "no file found")
    }

    /// One line for the log and `check -v`: which configuration is in use.
    fn describe(&self) -> String {
        match self.source() {
            (Some(path), how) => format!("configuration: {} ({how})", path.display()),
            (None, _) => format!(
                "configuration: the built-in default (no --config, $EDMD_CONFIG, {} or {})",
                config::DEFAULT_CONFIG_PATH,
                INSTALLED_CONFIG
            ),
        }
    }

    fn load(&self) -> Result<Config, config::ConfigError> {
        Config::load(self.source().0.as_deref(), &self.set)
    }
}

#[derive(Args, Debug)]
struct CheckArgs {
    /// G-code program
    program: PathBuf,
    #[command(flatten)]
    config: ConfigArgs,
    /// Print only the summary (the totals): no line per block, no progress bar
    #[arg(short, long)]
    quiet: bool,
    /// Also say which configuration file is in use
    #[arg(short, long)]
    verbose: bool,
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
    /// Print only the summary: no progress bar, even on a terminal
    #[arg(short, long)]
    quiet: bool,
    /// Plan the program once per pass of the technology table ([wire] pass), as a job run
    /// with --passes N cuts it: each pass at its offset, condition and feed
    #[arg(long, value_name = "N")]
    passes: Option<usize>,
    /// Cut with a technology table (technology.dir): material=steel,height=32,wire=0.25 or
    /// electrode=copper,material=steel,area=4 [default: the program's (TECH …) header]
    #[arg(long, value_name = "KEY=VALUE,…")]
    technology: Option<String>,
}

#[derive(Args, Debug)]
struct RunArgs {
    /// G-code program
    program: PathBuf,
    #[command(flatten)]
    config: ConfigArgs,
    /// Start from the machine state in FILE (position, work offsets, active system; as
    /// `daemon.state_file` keeps it) and write where the job left the machine back to it;
    /// a missing file is machine zero, no offsets [default: machine zero, no offsets, no file]
    #[arg(long, value_name = "FILE")]
    state: Option<PathBuf>,
    /// Also write the end-of-job summary as JSON to FILE
    #[arg(long, value_name = "FILE")]
    summary: Option<PathBuf>,
    /// Write a report of what ran into DIR (created if needed): path.svg, feed.svg,
    /// events.csv, summary.json
    #[arg(long, value_name = "DIR")]
    report: Option<PathBuf>,
    /// When the job does not finish (alarm, collision, stop, device error), write a
    /// checkpoint there: `edmd serve` with this file as `daemon.checkpoint` resumes it
    #[arg(long, value_name = "FILE")]
    checkpoint: Option<PathBuf>,
    /// Cut from this source line: the program is interpreted from its start without
    /// cutting, then the machine approaches the line's start
    #[arg(long, value_name = "LINE", value_parser = clap::value_parser!(u64).range(1..))]
    from_line: Option<u64>,
    /// How a run from a line reaches its start: path (along the program, spark off) or
    /// direct (up to machine.safe_z_mm, across, down) [default: direct where
    /// machine.safe_z_mm is set, path otherwise]
    #[arg(long, value_parser = ctl::parse_approach, requires = "from_line")]
    approach: Option<crate::path::Approach>,
    /// Cut the program once per pass of the technology table ([wire] pass): the first N
    #[arg(long, value_name = "N", conflicts_with = "from_line")]
    passes: Option<usize>,
    /// Cut with a technology table (technology.dir): material=steel,height=32,wire=0.25 or
    /// electrode=copper,material=steel,area=4 [default: the program's (TECH …) header]
    #[arg(long, value_name = "KEY=VALUE,…")]
    technology: Option<String>,
}

/// Entry point of the binary.
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        // Parsing runs on a stack of a known size, whatever the main thread's limit is.
        Command::Check(args) => on_parser_stack("edmd-check", || run_check(&args)),
        Command::Plan(args) => on_parser_stack("edmd-plan", || run_plan(&args)),
        Command::Run(args) => run_job(&args),
        Command::Serve(args) => run_serve(&args),
        Command::Ctl(args) => run_ctl(&args),
        Command::Latency(args) => latency::run_latency(args),
        Command::Tech(args) => tech::run_tech(&args),
        Command::HalWait(args) => hal::run_hal_wait(&args),
        Command::HalReap(args) => hal::run_hal_reap(&args),
        Command::Completions(args) => docs::completions(&args, Cli::command()),
        Command::Man(args) => docs::man(&args, Cli::command()),
    }
}

fn on_parser_stack(name: &str, work: impl FnOnce() -> ExitCode + Send) -> ExitCode {
    gcode::on_parser_stack(name, work).unwrap_or_else(|e| {
        eprintln!("edmd: error: cannot start the {name} thread: {e}");
        ExitCode::from(EXIT_RUNTIME)
    })
}

/// Sets up logging as configured; returns the way to change the level later (SIGHUP).
/// Logging for a command that plans or moves. The daemon says the configuration's warnings
/// once when it starts, in its journal; a one-shot command (`run`, `plan`) only at the debug
/// level: its summary reports the feeds it reached, and a warning on every command is noise.
fn init_logging_for(cfg: &Config, daemon: bool) -> crate::daemon::SetLogLevel {
    let set_level = init_logging(&cfg.log);
    if let Some(warning) = config::max_feed_warning(cfg) {
        if daemon {
            tracing::warn!("{warning}");
        } else {
            tracing::debug!("{warning}");
        }
    }
    set_level
}

fn init_logging(cfg: &config::LogConfig) -> crate::daemon::SetLogLevel {
    use tracing_subscriber::layer::SubscriberExt;
    use tracing_subscriber::util::SubscriberInitExt;
    use tracing_subscriber::{EnvFilter, Layer, Registry, fmt, reload};

    let from_env = std::env::var_os("RUST_LOG").is_some();
    let filter = EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| EnvFilter::new(filter_directives(cfg.level.name())));
    let (filter, handle) = reload::Layer::<EnvFilter, Registry>::new(filter);
    let terminal = std::io::stderr().is_terminal();
    // The journal's structured fields (`edmd_event`, …) are for the journal; the text formats
    // show the message and any other field.
    let text_fields = fmt::format::debug_fn(|writer, field, value| {
        let name = field.name();
        if name.starts_with(journal::FIELD_PREFIX) {
            Ok(())
        } else if name == "message" {
            write!(writer, "{value:?}")
        } else {
            write!(writer, " {name}={value:?}")
        }
    });
    let layer = fmt::layer().with_writer(std::io::stderr);
    let journal = match cfg.format {
        LogFormat::Journal => journal::JournalLayer::connect(),
        LogFormat::Auto if journal::stderr_is_journal() => journal::JournalLayer::connect(),
        _ => None,
    };
    let layer = match (cfg.format, journal) {
        (_, Some(journal)) => journal.boxed(),
        (LogFormat::Json, None) => layer.json().boxed(),
        (LogFormat::Plain | LogFormat::Journal, None) => {
            layer.with_ansi(false).fmt_fields(text_fields).boxed()
        }
        // On a terminal: local time, no module paths, each line printed with the progress
        // bar lifted (`term`).
        (LogFormat::Human | LogFormat::Auto, None) if terminal => fmt::layer()
            .with_writer(crate::term::LogWriter)
            .with_timer(crate::term::LocalTime)
            .with_target(false)
            .fmt_fields(text_fields)
            .boxed(),
        (LogFormat::Human | LogFormat::Auto, None) => {
            layer.with_ansi(false).fmt_fields(text_fields).boxed()
        }
    };
    // Asked at every event of the library (a budget is spent), at no other callsite.
    let noise = tracing_subscriber::filter::DynFilterFn::new(|meta, _| library_noise(meta))
        .with_callsite_filter(|meta| {
            if meta.is_event() && meta.target().starts_with("opcua") {
                tracing::subscriber::Interest::sometimes()
            } else {
                tracing::subscriber::Interest::always()
            }
        });
    let layer = layer.with_filter(noise);
    set_noise_limited(cfg.level.name());
    // A second initialisation (tests calling twice) is harmless, so its error is ignored.
    let _ = tracing_subscriber::registry()
        .with(filter)
        .with(layer)
        .try_init();
    Box::new(move |level: &str| {
        if from_env {
            return Err("RUST_LOG is set and takes precedence; level unchanged".into());
        }
        handle
            .reload(EnvFilter::new(filter_directives(level)))
            .map_err(Into::<Box<dyn std::error::Error + Send + Sync>>::into)?;
        set_noise_limited(level);
        Ok(())
    })
}

/// The OPC UA library's warnings and errors are held to a noise budget below `debug`.
static NOISE_LIMITED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(true);

fn set_noise_limited(level: &str) {
    NOISE_LIMITED.store(
        !matches!(level, "debug" | "trace"),
        std::sync::atomic::Ordering::Relaxed,
    );
}

/// The OPC UA library logs a stranger's malformed connection at ERROR, several lines each,
/// so anyone who can reach the port could fill the journal: below `debug` its warnings and
/// errors pass a [`crate::daemon::noise::Budget`] (ten a minute), the rest are dropped.
fn library_noise(meta: &tracing::Metadata<'_>) -> bool {
    static LIBRARY: crate::daemon::noise::Budget = crate::daemon::noise::Budget::new();
    if !meta.is_event()
        || !meta.target().starts_with("opcua")
        || *meta.level() > tracing::Level::WARN
        || !NOISE_LIMITED.load(std::sync::atomic::Ordering::Relaxed)
    {
        return true;
    }
    matches!(
        LIBRARY.spend(crate::sys::monotonic_ns()),
        crate::daemon::noise::Loudness::Warn { .. }
    )
}

/// The log filter for `level`: at `info`, the OPC UA library's own chatter (a line per
/// connection and session) is left out, its warnings and errors (a client certificate
/// rejected) kept.
fn filter_directives(level: &str) -> String {
    match level {
        "info" => "info,opcua_server=warn,opcua_core=warn,opcua_crypto=warn".to_string(),
        _ => level.to_string(),
    }
}

fn load_config(args: &ConfigArgs) -> Result<Config, ExitCode> {
    args.load().map_err(|e| {
        eprintln!("edmd: error: {e}");
        ExitCode::from(EXIT_BAD_INPUT)
    })
}

fn run_plan(args: &PlanArgs) -> ExitCode {
    let cfg = match load_config(&args.config) {
        Ok(c) => c,
        Err(code) => return code,
    };
    let _ = init_logging_for(&cfg, false);
    let job = cut::CliJob::new(cfg, &args.program, args.technology.as_deref(), args.passes);
    let job = match job {
        Ok(job) => job,
        Err(code) => return code,
    };
    match plan::plan_program(&args.program, &job.cfg, &job.cut, &args.out, !args.quiet) {
        Ok(summary) => {
            out!("{}", summary.text());
            outln!("written to {}", args.out.display());
            ExitCode::SUCCESS
        }
        Err(e @ (plan::PlanError::Program(_) | plan::PlanError::NotADirectory { .. })) => {
            eprintln!("edmd: error: {e}");
            ExitCode::from(EXIT_BAD_INPUT)
        }
        Err(e) => {
            eprintln!("edmd: error: {e}");
            ExitCode::from(EXIT_RUNTIME)
        }
    }
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
    let _ = init_logging_for(&cfg, false);
    tracing::info!("{}", args.config.describe());
    let job = match args.job(cfg) {
        Ok(job) => job,
        Err(code) => return code,
    };
    let cfg = &job.cfg;
    if let Some(t) = &job.technology {
        tracing::info!("technology: {}", t.summary());
    }
    let stop = stop_on_signals();
    let terminal = std::io::stderr().is_terminal();
    let progress = job_progress(terminal, cfg.fine.tick);
    let recording = args.report.as_ref().map(|_| {
        Arc::new(parking_lot::Mutex::new(
            crate::record::Recording::new(&cfg.machine.step_mm, cfg.fine.tick)
                .with_upper_guide(cfg.machine.upper_guide_axes()),
        ))
    });
    let observers = runtime::Observers {
        progress: Some(progress),
        recording: recording.clone(),
    };
    let from_line = args.from_line.is_some();
    let mut machine = match RunState::open(args.state.as_deref(), cfg, from_line) {
        Ok(m) => m,
        Err(code) => return code,
    };
    let start = machine.work_start();
    let result = runtime::run_file_from(&args.program, cfg, &start, &job.cut, &stop, observers);
    crate::term::finish();
    let summary = match result {
        Ok((summary, left)) => {
            if let Err(code) = machine.stopped(&summary, left) {
                return code;
            }
            summary
        }
        Err(e) => {
            eprintln!("edmd: error: {e}");
            // Nothing moved: the state is a standstill's again.
            let _ = machine.save(false);
            // A device that cannot be opened is a runtime failure; anything else that stops
            // a job before it starts is bad input.
            let code = match e {
                JobError::Output(_) | JobError::Parport(_) => EXIT_RUNTIME,
                _ => EXIT_BAD_INPUT,
            };
            return ExitCode::from(code);
        }
    };
    out!("{}", summary.text());
    if let (Some(dir), Some(recording)) = (&args.report, &recording)
        && let Err(e) = {
            let programmed = crate::report::programmed::for_report(
                &args.program,
                &args.program.display().to_string(),
                &cfg.machine.axes,
                crate::gcode::ProgramOptions::from_config(cfg),
                &start,
            );
            let mut recording = recording.lock();
            recording.programmed = programmed;
            let passes = job.pass_times(&recording, summary.ticks);
            crate::report::write_report(dir, &mut recording, &summary, &passes)
        }
    {
        eprintln!("edmd: error: {e}");
        return ExitCode::from(EXIT_RUNTIME);
    }
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
    if let (Some(path), Some(at)) = (&args.checkpoint, &summary.stopped_at) {
        match run_state::write_run_checkpoint(path, args, &job, &summary, at, &start) {
            Ok(()) => eprintln!("edmd: checkpoint written to {}", path.display()),
            Err(e) => {
                eprintln!(
                    "edmd: error: {}: cannot write the checkpoint: {e}",
                    path.display()
                );
                return ExitCode::from(EXIT_RUNTIME);
            }
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
    let (path, _) = args.config.source();
    let (cfg, keys) = match Config::load_with_keys(path.as_deref(), &args.config.set) {
        Ok(loaded) => loaded,
        Err(e) => {
            eprintln!("edmd: error: {e}");
            return ExitCode::from(EXIT_BAD_INPUT);
        }
    };
    let set_level = init_logging_for(&cfg, true);
    tracing::info!("{}", args.config.describe());
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

/// How often `edmd run` logs its progress when standard error is not a terminal.
const PROGRESS_LOG_EVERY: std::time::Duration = std::time::Duration::from_secs(10);

/// `edmd run`'s progress: a bar with the ETA on a terminal, a log line every
/// [`PROGRESS_LOG_EVERY`] otherwise (a journal, a file, CI).
fn job_progress(terminal: bool, tick: crate::vocab::TickPeriod) -> runtime::ProgressFn {
    use crate::daemon::protocol::duration_text;
    let mut last_log: Option<std::time::Instant> = None;
    let bar = crate::term::bar(1000, terminal);
    Box::new(move |tracker, snap| {
        let eta = tracker.eta_s().map_or_else(
            || "ETA unknown".to_string(),
            |s| format!("ETA {}", duration_text(s)),
        );
        let fraction = tracker.fraction();
        if terminal {
            bar.set_position((fraction * 1000.0) as u64);
            bar.set_message(format!(
                "line {}  {:.1} s machine time  {eta}",
                snap.line,
                tick.ticks_to_secs(snap.tick)
            ));
        } else if last_log.is_none_or(|t| t.elapsed() >= PROGRESS_LOG_EVERY) {
            last_log = Some(std::time::Instant::now());
            tracing::info!(
                "progress: {:.1} % of {:.3} mm (line {}), {:.1} s machine time, {eta}",
                fraction * 100.0,
                tracker.total_mm(),
                snap.line,
                tick.ticks_to_secs(snap.tick)
            );
        }
    })
}
