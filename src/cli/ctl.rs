//! `edmd ctl`: the client of `edmd serve`. One request per connection; `run` and `resume`
//! wait for their check's verdict unless told not to; `monitor` prints a line per interval.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Args, Subcommand};

use super::{ConfigArgs, EXIT_BAD_INPUT, EXIT_RUNTIME, load_config, write_stdout};

#[derive(Args, Debug)]
pub(super) struct CtlArgs {
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
pub(super) enum CtlCommand {
    /// Run a program (a path inside daemon.program_dir): the daemon copies and checks it,
    /// then starts the job; this waits for that verdict (exit 0: started; 1: refused)
    Run {
        /// Program path, relative to daemon.program_dir (or absolute inside it)
        program: String,
        /// Return as soon as the daemon has accepted the request (the verdict shows in
        /// `edmd ctl status`)
        #[arg(long)]
        no_wait: bool,
        /// Wait for the job's end too: exit 0 when it ended done, 1 otherwise (with its
        /// outcome); a held or paused job is waited for
        #[arg(long, conflicts_with = "no_wait")]
        wait_end: bool,
        /// Prove the program: its moves with the spark off and the servo out of the loop,
        /// feed moves at machine.dry_run_feed_mm_per_min (no checkpoint is kept)
        #[arg(long)]
        dry_run: bool,
        /// Cut from this source line: the program is interpreted from its start without
        /// cutting (modal state, parameters, offsets, wire offset, condition), then the
        /// machine approaches the line's start
        #[arg(long, value_name = "LINE")]
        from_line: Option<u64>,
        /// How a run from a line reaches its start: along the programmed path with the spark
        /// off (a wire machine), or direct: up to machine.safe_z_mm, across, down (a sinker)
        /// [default: direct where machine.safe_z_mm is set, path otherwise]
        #[arg(long, value_parser = parse_approach, requires = "from_line")]
        approach: Option<crate::path::Approach>,
        /// Where the wire stands, for a run from a line by the path (asked, never assumed):
        /// start-hole (the program's start hole: the approach runs the kerf forward) or
        /// stopped (where this program's stopped job stopped: it runs the kerf backwards)
        #[arg(long, value_parser = parse_wire_at, requires = "from_line")]
        wire_at: Option<crate::path::WireAt>,
        /// In a job in passes (a technology's, or --passes): the pass the line is cut in,
        /// from 1 [default: 1]; the later passes are cut whole after it
        #[arg(long, value_name = "K", requires = "from_line")]
        pass: Option<u8>,
        /// Cut the program once per pass of the technology table ([wire] pass, or the one
        /// --technology selects): the first N, each at its offset and condition
        #[arg(long, value_name = "N")]
        passes: Option<usize>,
        /// In passes: the tab this job leaves, mm (0: none) [default: wire.tab_mm]
        #[arg(long, value_name = "MM")]
        tab: Option<f64>,
        /// Cut with a technology table (technology.dir): material=steel,height=32,wire=0.25
        /// for a wire cut (all its passes unless --passes), or
        /// electrode=copper,material=steel,area=4 for a sinker [default: the program's
        /// (TECH …) header comment, if it has one]
        #[arg(long, value_name = "KEY=VALUE,…")]
        technology: Option<String>,
        /// A run from a line while the position is not trusted (edmd stopped while the
        /// machine moved, or an axis is unhomed): the operator has checked where it stands
        #[arg(long, requires = "from_line")]
        force: bool,
    },
    /// Brake to a standstill and hold there (checkpoint written)
    Hold,
    /// Release a hold; with no job running, resume the checkpoint's job (waiting for its
    /// check, as `run` does)
    Resume {
        /// Resume although the machine moved since the checkpoint, the offsets changed, an
        /// axis is unhomed or the position is not trusted after an unclean stop: the
        /// operator has checked where it stands
        #[arg(long)]
        force: bool,
        /// Return as soon as the daemon has accepted the request
        #[arg(long)]
        no_wait: bool,
    },
    /// Brake to a standstill and end the job (checkpoint kept)
    Abort,
    /// After a wire break: go back along the cut path to the start hole with the spark off
    /// and wait there for threading; `resume` then returns to the break point and cuts on
    Rethread {
        /// Thread the wire where it broke instead of at the start hole
        #[arg(long)]
        here: bool,
    },
    /// Print what the daemon is doing
    Status,
    /// Jog: move AXIS by DISTANCE mm with the spark off, stopping at the soft limits
    /// (waits for the move's check, as `run` does)
    Jog {
        /// Axis letter
        axis: String,
        /// mm, signed
        #[arg(allow_negative_numbers = true)]
        distance: f64,
        /// mm/min [default and most: machine.max_jog_feed_mm_per_min]
        #[arg(long, value_name = "F")]
        feed: Option<f64>,
    },
    /// Run G-code lines (MDI) as a job, in the units and distance mode the last MDI lines left
    Mdi {
        /// The lines (separate several with newlines)
        line: String,
    },
    /// Clear an E-stop once its input is released
    Reset,
    /// Discard the checkpoint of a stopped job that will not be resumed (it cannot be
    /// undone); a checkpoint kept aside while another job ran is the checkpoint again
    Discard {
        /// The operator confirms it
        #[arg(long)]
        yes: bool,
    },
    /// Feed override (0–200 %) or rapid override (0–100 %): in force at once, and for the
    /// jobs after
    Override {
        /// feed or rapid
        kind: OverrideArg,
        /// Percent
        percent: f64,
    },
    /// Single block: while on, a job stops before each program block; `resume` runs the
    /// next
    #[command(name = "single-block")]
    SingleBlock {
        /// on or off
        state: OnOff,
    },
    /// Print the work offset table (G54 … G59.3; the active system marked *)
    Offsets,
    /// Print the job history, newest first: program, start, outcome, machine time, each
    /// pass's time, shorts and wire breaks (kept across restarts in daemon.job_history)
    Jobs {
        /// How many jobs
        #[arg(long, default_value_t = 20, value_name = "N")]
        count: usize,
        /// Pass over the newest N first (the next page further back)
        #[arg(long, default_value_t = 0, value_name = "N")]
        skip: usize,
    },
    /// Print the daemon's technology tables, or explain what a request selects from them
    /// (the table, the rows and why, the passes and the conditions' set points)
    Tech {
        /// material=steel,height=32,wire=0.25 or electrode=copper,material=steel,area=4
        request: Option<String>,
    },
    /// Print a one-time link that logs a browser in to the web page (one use, 10 minutes)
    #[command(name = "web-link")]
    WebLink,
    /// Set a work offset so that where the machine stands reads VALUE on AXIS (G10 L20)
    #[command(name = "touch-off")]
    TouchOff {
        /// Axis letter (X, Y, …)
        axis: String,
        /// The coordinate the current position gets, mm
        #[arg(allow_negative_numbers = true)]
        value: f64,
        /// The work system to set (G54 … G59.3) [default: the active one]
        #[arg(long, value_name = "G5x")]
        system: Option<String>,
    },
    /// Find the part by touching it with the wire (spark off, in wire.touch_condition):
    /// `edge X+|X-|Y+|Y-` (the face met moving that way), `corner X+Y+` (etc.: the part lies
    /// that way from the wire, which stands off the corner) or `center` (of the hole the wire
    /// stands in). Waits for the result (exit 0: found; 1: failed)
    Find {
        /// edge, corner or center
        kind: String,
        /// The direction(s): X+, Y-, … for an edge; X+Y+, X-Y+, … for a corner
        direction: Option<String>,
        /// Write the result into this work offset (G54 … G59.3) as G10 L20: the edge, corner
        /// or centre reads 0 there
        #[arg(long, value_name = "G5x")]
        system: Option<String>,
        /// Return as soon as the daemon has started the cycle
        #[arg(long)]
        no_wait: bool,
    },
    /// Home axes by their switches ([[homing.axis]]; all that have one when none is named),
    /// in sequence order. `--here`: where the axes stand is their home position (the axes
    /// named, or all without a switch; an axis with a switch only with --force)
    Home {
        /// Axis letters
        axes: Vec<String>,
        /// Declare the current position to be home (home_position_mm, or machine zero)
        #[arg(long)]
        here: bool,
        /// With --here: also on an axis that has a home switch (the correction is reported)
        #[arg(long, requires = "here")]
        force: bool,
    },
    /// A status line every interval (one JSON status per line with --json), until N lines
    /// or until the daemon goes away
    Monitor {
        /// Seconds between lines
        #[arg(long, default_value_t = 1.0, value_name = "S")]
        interval: f64,
        /// Stop after this many lines [default: until interrupted or the daemon goes away]
        #[arg(long, value_name = "N")]
        count: Option<u64>,
    },
}

/// `edmd ctl single-block on|off`.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum OnOff {
    On,
    Off,
}

/// `edmd ctl override feed|rapid`.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum OverrideArg {
    Feed,
    Rapid,
}

pub(super) fn run_ctl(args: &CtlArgs) -> ExitCode {
    use crate::daemon::protocol::Request;
    let socket = match &args.socket {
        Some(socket) => socket.clone(),
        None => match load_config(&args.config) {
            Ok(cfg) => cfg.daemon.socket,
            Err(code) => return code,
        },
    };
    if let CtlCommand::Monitor { interval, count } = &args.command {
        return monitor(&socket, *interval, *count, args.json);
    }
    if let CtlCommand::Find { no_wait: false, .. } = &args.command {
        return super::touch::find_and_wait(&socket, request_of(&args.command).0, args.json);
    }
    let (request, wait) = request_of(&args.command);
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
                && matches!(
                    request,
                    Request::Run { .. }
                        | Request::Resume { .. }
                        | Request::Jog { .. }
                        | Request::Mdi { .. }
                )
        });
    let reply = match check {
        Some(check) => {
            if !args.json {
                outln!("{}", reply.message.as_deref().unwrap_or_default());
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
    let reply = match &args.command {
        CtlCommand::Run {
            wait_end: true,
            program,
            ..
        } if reply.ok => {
            if !args.json {
                outln!("{}", reply.message.as_deref().unwrap_or_default());
            }
            match crate::daemon::socket::wait_for_end(&socket, program) {
                Ok(reply) => reply,
                Err(e) => {
                    eprintln!("edmd: error: {e}");
                    return ExitCode::from(EXIT_RUNTIME);
                }
            }
        }
        _ => reply,
    };
    if args.json {
        out!("{}", reply.to_line());
    } else {
        if let Some(message) = reply
            .message
            .as_ref()
            .filter(|_| request != Request::Status {})
        {
            outln!("{message}");
        }
        if let Some(status) = reply
            .status
            .as_ref()
            .filter(|_| request == Request::Status {})
        {
            out!("{}", status.text());
        }
    }
    match (&reply.ok, &reply.error) {
        (true, _) => ExitCode::SUCCESS,
        (false, error) => {
            // The reason first; what the daemon is doing after it, in one line.
            eprintln!(
                "edmd: error: {}",
                error.as_deref().unwrap_or("the daemon refused")
            );
            if let Some(status) = reply.status.as_ref().filter(|_| !args.json) {
                eprintln!("edmd: the daemon: {}", status.line());
            }
            ExitCode::from(EXIT_RUNTIME)
        }
    }
}

/// `--approach path|direct`.
pub(super) fn parse_approach(text: &str) -> Result<crate::path::Approach, String> {
    crate::path::Approach::parse(text)
        .ok_or_else(|| format!("{text:?}: the approach is path or direct"))
}

/// `--wire-at start-hole|stopped`.
fn parse_wire_at(text: &str) -> Result<crate::path::WireAt, String> {
    crate::path::WireAt::parse(text)
        .ok_or_else(|| format!("{text:?}: the wire stands at the start-hole or where it stopped"))
}

/// The request a `ctl` command sends, and whether `ctl` waits for the check it starts.
fn request_of(command: &CtlCommand) -> (crate::daemon::protocol::Request, bool) {
    use crate::daemon::protocol::Request;
    match command {
        CtlCommand::Run {
            program,
            no_wait,
            dry_run,
            from_line,
            approach,
            wire_at,
            pass,
            passes,
            tab,
            technology,
            force,
            wait_end: _,
        } => (
            Request::Run {
                pass: *pass,
                program: program.clone(),
                dry_run: *dry_run,
                from_line: *from_line,
                approach: *approach,
                wire_at: *wire_at,
                passes: *passes,
                tab_mm: *tab,
                technology: technology.clone(),
                force: *force,
            },
            !no_wait,
        ),
        CtlCommand::Hold => (Request::Hold {}, false),
        CtlCommand::Resume { force, no_wait } => (Request::Resume { force: *force }, !no_wait),
        CtlCommand::Abort => (Request::Abort {}, false),
        CtlCommand::Rethread { here } => (Request::Rethread { here: *here }, false),
        CtlCommand::Status | CtlCommand::Monitor { .. } => (Request::Status {}, false),
        CtlCommand::Offsets => (Request::Offsets {}, false),
        CtlCommand::Jobs { count, skip } => (
            Request::Jobs {
                count: Some(*count),
                skip: Some(*skip),
            },
            false,
        ),
        CtlCommand::WebLink => (Request::WebLink {}, false),
        CtlCommand::Tech { request } => (
            Request::Technology {
                request: request.clone(),
            },
            false,
        ),
        CtlCommand::Reset => (Request::Reset {}, false),
        CtlCommand::Discard { yes } => (Request::Discard { confirm: *yes }, false),
        CtlCommand::SingleBlock { state } => (
            Request::SingleBlock {
                on: matches!(state, OnOff::On),
            },
            false,
        ),
        CtlCommand::Override { kind, percent } => (
            Request::Override {
                kind: match kind {
                    OverrideArg::Feed => crate::daemon::protocol::OverrideKind::Feed,
                    OverrideArg::Rapid => crate::daemon::protocol::OverrideKind::Rapid,
                },
                percent: *percent,
            },
            false,
        ),
        CtlCommand::Jog {
            axis,
            distance,
            feed,
        } => (
            Request::Jog {
                axis: axis.clone(),
                distance_mm: *distance,
                feed_mm_per_min: *feed,
            },
            true,
        ),
        CtlCommand::Mdi { line } => (Request::Mdi { line: line.clone() }, true),
        CtlCommand::TouchOff {
            axis,
            value,
            system,
        } => (
            Request::TouchOff {
                axis: axis.clone(),
                value: *value,
                system: system.clone(),
            },
            false,
        ),
        CtlCommand::Find {
            kind,
            direction,
            system,
            no_wait,
        } => (
            Request::Find {
                target: format!("{kind} {}", direction.as_deref().unwrap_or_default())
                    .trim()
                    .to_string(),
                system: system.clone(),
            },
            !no_wait,
        ),
        CtlCommand::Home { axes, here, force } => (
            Request::Home {
                axes: axes.clone(),
                here: *here,
                force: *force,
            },
            false,
        ),
    }
}

/// `edmd ctl monitor`: one status line (or JSON object) per interval.
fn monitor(socket: &Path, interval: f64, count: Option<u64>, json: bool) -> ExitCode {
    use crate::daemon::protocol::Request;
    if !(interval.is_finite() && (0.05..=3600.0).contains(&interval)) {
        eprintln!("edmd: error: --interval {interval}: must be 0.05 to 3600 seconds");
        return ExitCode::from(EXIT_BAD_INPUT);
    }
    let mut printed = 0u64;
    while count.is_none_or(|n| printed < n) {
        if printed > 0 {
            std::thread::sleep(std::time::Duration::from_secs_f64(interval));
        }
        let status = match crate::daemon::socket::request(socket, &Request::Status {}) {
            Ok(reply) => reply.status,
            Err(e) if printed > 0 => {
                eprintln!("edmd: the daemon went away ({e})");
                return ExitCode::SUCCESS;
            }
            Err(e) => {
                eprintln!("edmd: error: {e}");
                return ExitCode::from(EXIT_RUNTIME);
            }
        };
        let Some(status) = status else {
            eprintln!("edmd: error: a status reply without a status");
            return ExitCode::from(EXIT_RUNTIME);
        };
        if json {
            outln!(
                "{}",
                serde_json::to_string(&status).expect("a status serialises")
            );
        } else {
            outln!("{}", status.line());
        }
        printed += 1;
    }
    ExitCode::SUCCESS
}
