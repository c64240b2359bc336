//! Why the daemon refuses a command or a job: one typed error per reason, each worded for the
//! operator (the reply's `error` is its text). Nothing in the daemon passes a refusal around
//! as a bare string.

use std::path::PathBuf;

use crate::checkpoint::{CheckpointError, Reason};
use crate::runtime::JobError;
use crate::runtime::program::CopyError;
use crate::servo::ServoState;

/// A program name a client gave that does not name a runnable program. Missing, outside the
/// directory, `..` and not-a-file read alike: the reply tells a client nothing of the
/// machine's other files (the daemon's log says which it was).
#[derive(Debug, thiserror::Error)]
pub enum NameRefusal {
    #[error("an empty program name")]
    Empty,
    #[error("{name:?}: a program name has no control characters")]
    ControlCharacter { name: String },
    #[error("{name}: no such program in the program directory")]
    NoSuchProgram { name: String },
    #[error("daemon.program_dir = {dir}: {source}")]
    ProgramDir {
        dir: PathBuf,
        source: std::io::Error,
    },
}

/// A checkpoint that could not be written: where, why it was being written, what failed.
#[derive(Debug, Clone, thiserror::Error)]
#[error("{}: cannot write the checkpoint ({}): {message}", path.display(), reason.name())]
pub struct CheckpointWriteError {
    pub path: PathBuf,
    pub reason: Reason,
    /// The system's error, as text (kept to compare one failure with the next).
    pub message: String,
}

/// What a check of a program (before its job starts) refused.
#[derive(Debug, thiserror::Error)]
pub enum CheckRefusal {
    #[error(transparent)]
    Copy(#[from] CopyError),
    /// A resume's program is not the checkpoint's.
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    #[error(transparent)]
    Program(Box<JobError>),
    #[error("cannot start the check thread: {0}")]
    Thread(std::io::Error),
    /// The technology asked for (or in the program's header) selects nothing.
    #[error(transparent)]
    Technology(#[from] crate::technology::TechError),
    /// Its passes cannot be cut.
    #[error(transparent)]
    Passes(#[from] crate::path::PassError),
    /// A run from a line that follows a stopped job's kerf, of a program changed since.
    #[error(
        "{program}: the program changed since its job stopped (SHA-256 {found:.12}…, the \
         stopped job cut {expected:.12}…): the kerf is not this program's path, so a run from \
         a line cannot follow it. Restore the program, or discard the stopped job and start \
         with the wire at the start hole"
    )]
    KerfOfAnother {
        program: String,
        expected: String,
        found: String,
    },
}

impl From<JobError> for CheckRefusal {
    fn from(e: JobError) -> Self {
        CheckRefusal::Program(Box::new(e))
    }
}

/// Why a command was refused.
#[derive(Debug, thiserror::Error)]
pub enum Refusal {
    #[error("the daemon is shutting down")]
    ShuttingDown,
    #[error("{0}")]
    MachineState(String),
    #[error("E-stop: nothing moves until it is released and `edmd ctl reset` is given")]
    EStop,
    #[error("limit switch {switch} is tripped: only a jog away from it moves")]
    Limit { switch: crate::vocab::LimitSwitch },
    #[error("{0}")]
    BadArgument(String),
    #[error(
        "axis {axes} not homed and homing.required is on: home first (`edmd ctl home --here` \
         declares where it stands to be home)"
    )]
    Unhomed { axes: String },
    #[error(
        "{what}: the position is not trusted: edmd stopped while the machine was moving, and \
         where it stands now is only believed; home every axis (`edmd ctl home`, or `home \
         --here` where it stands at home), or, having checked the position, {what} with \
         --force"
    )]
    Distrusted { what: &'static str },
    #[error(
        "{what}: axis {axes} not homed and homing.required is on: home first (`edmd ctl \
         home`), or, having checked the position, {what} with --force"
    )]
    UnhomedResume { what: &'static str, axes: String },
    #[error(
        "the work offsets changed since the checkpoint was written ({changed}); the job would \
         resume in another place: put them back, or resume with --force"
    )]
    OffsetsChanged { changed: String },
    #[error(
        "the machine stands at {here} mm, the checkpoint's job stopped at {checkpoint} mm: \
         move back there (jog, MDI G53) or resume with --force"
    )]
    NotAtCheckpoint { here: String, checkpoint: String },
    #[error("a job is {state}: {program}; abort it first")]
    JobRunning {
        state: &'static str,
        program: PathBuf,
    },
    #[error("{name} is being checked (check {id}); abort cancels it")]
    Checking { name: String, id: u64 },
    #[error("no job is running")]
    NoJob,
    #[error("the job is stopping")]
    Stopping,
    #[error("the job is not held")]
    NotHeld,
    #[error(
        "the wire is broken: `edmd ctl rethread` goes back to the start hole for threading \
         (`--here`: thread where it broke), then `resume`"
    )]
    WireBroken,
    #[error("the wire is not broken (the servo is {}): nothing to rethread", state.name())]
    WireNotBroken { state: ServoState },
    #[error(transparent)]
    Name(#[from] NameRefusal),
    #[error("nothing to resume: {why}")]
    NothingToResume { why: String },
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    #[error("the checkpoint has {found} axes, the machine {machine}")]
    AxisCount { found: usize, machine: usize },
    /// The write-ahead checkpoint could not be written: the motion it would have let go
    /// does not start (`consequence` says what stays so).
    #[error("{error}: {consequence}")]
    WriteAhead {
        error: CheckpointWriteError,
        consequence: &'static str,
    },
    #[error(transparent)]
    Check(Box<CheckRefusal>),
    #[error(transparent)]
    Job(Box<JobError>),
    #[error(
        "daemon.report_dir: cannot make {}: {source}; the job does not start without its \
         report",
        dir.display()
    )]
    ReportDir {
        dir: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot start the job thread: {0}")]
    JobThread(std::io::Error),
    /// A program job would lose a stopped job's checkpoint: one is kept aside already.
    #[error(
        "the checkpoints of {kept} (kept aside) and of {stopped} (stopped at line {line}) are \
         both resumable: resume {stopped} or discard its checkpoint before another program runs"
    )]
    BothKept {
        kept: String,
        stopped: String,
        line: u64,
    },
    #[error("discarding the checkpoint of {program} (line {line}) cannot be undone: confirm it")]
    DiscardUnconfirmed { program: String, line: u64 },
    #[error("no checkpoint to discard")]
    NothingToDiscard,
    #[error(
        "the wire leans ({at}, the upper guide in machine coordinates) and this program does \
         not taper: it would cut tilted. Bring the wire vertical first (MDI `G53 G0 U0 V0`), \
         or run a program that sets its own taper"
    )]
    Leaning { at: String },
    #[error(
        "a run from a line by the path starts from where the wire stands ({at}): say where \
         that is. --wire-at start-hole: at the program's start hole; --wire-at stopped: where \
         the stopped job of this program stopped, in its kerf"
    )]
    WireAtUnsaid { at: String },
    #[error(
        "{program}: the wire stands at {at}, not at the start hole {start_hole} where its \
         stopped job started. {}",
        if *stopped_here {
            "It stands where that job stopped: run with --wire-at stopped (the approach goes \
             back along the kerf)"
        } else {
            "Bring it to the start hole along the kerf (jog), or to where the job stopped and \
             run with --wire-at stopped"
        }
    )]
    NotAtStartHole {
        program: String,
        at: String,
        start_hole: String,
        stopped_here: bool,
    },
    #[error(
        "{program}: --wire-at stopped, but no stopped job of it is kept (no checkpoint), so \
         where its kerf runs is not known: bring the wire to the start hole and run with \
         --wire-at start-hole"
    )]
    NoStoppedJob { program: String },
    #[error(
        "{program}: the wire stands at {at}, not where its job stopped ({stopped}, line \
         {line}): jog it back there along the kerf, or to the start hole and run with \
         --wire-at start-hole"
    )]
    NotWhereItStopped {
        program: String,
        at: String,
        stopped: String,
        line: u64,
    },
}

// The large errors travel boxed: a refusal is returned on every command's path.
impl From<CheckRefusal> for Refusal {
    fn from(e: CheckRefusal) -> Self {
        Refusal::Check(Box::new(e))
    }
}

impl From<JobError> for Refusal {
    fn from(e: JobError) -> Self {
        Refusal::Job(Box::new(e))
    }
}
