//! Starting a job: `run` (with a dry run or from a line) and `resume` of a checkpoint go
//! through a check on a worker thread (copy, precheck); its verdict starts the job thread
//! with the job's I/O, its recording and a write-ahead checkpoint, or records why not.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use super::desk::{Desk, Order};
use super::jobs::{Check, Resume};
use super::launch::{Checked, JobKind, Launch, Source, copy_and_check};
use super::protocol::CheckStatus;
use super::refusal::{CheckRefusal, Refusal};
use super::{Core, CoreMsg, Job, JobRecording, confine};
use crate::checkpoint::{self, Reason};
use crate::config::Config;
use crate::record::Recording;
use crate::runtime::program::{JobProgram, Progress};
use crate::runtime::{self, ResumePoint};

/// The report's programmed path, drawn on a thread of its own (a long program must not
/// hold the control loop) into the job's recording; a job that ends first has its report
/// without it.
fn draw_programmed(recording: &JobRecording, program: &JobProgram, spec: &runtime::JobSpec) {
    let (recording, file, name) = (
        recording.clone(),
        program.path.clone(),
        program.name.clone(),
    );
    let (axes, options, start) = (
        spec.axes.clone(),
        spec.path.program.clone(),
        spec.path.work.clone(),
    );
    let spawned = std::thread::Builder::new()
        .name("edmd-report-path".into())
        .stack_size(crate::gcode::PARSER_STACK_BYTES)
        .spawn(move || {
            let drawn = crate::report::programmed::for_report(&file, &name, &axes, options, &start);
            recording.lock().programmed = drawn;
        });
    if let Err(e) = spawned {
        tracing::warn!("report: the programmed path is not drawn: {e}");
    }
}

/// The folder of a job's report, when the configuration asks for one. The folder is made
/// first: a job must not learn at its end that its report has nowhere to go. Jogs, MDI lines,
/// homing and touch cycles are the machine's, not jobs: no report.
/// The longest stem of a program's name a report folder carries: the date and time before it
/// (20 bytes) and a suffix after it (`-99`) keep the folder's name within 255 bytes.
const MAX_REPORT_STEM_BYTES: usize = 200;

/// `text` cut to at most `max` bytes at a character boundary.
fn cut_at(text: &str, max: usize) -> &str {
    let mut end = text.len().min(max);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    &text[..end]
}

fn job_report(
    config: &Config,
    program_name: &str,
    kind: JobKind,
) -> Result<Option<PathBuf>, Refusal> {
    if !matches!(kind, JobKind::Program | JobKind::DryRun) {
        return Ok(None);
    }
    Ok(match &config.daemon.report_dir {
        Some(dir) => {
            // The folder's name is the date, the time and the program's stem, cut so that it
            // stays a name the file system takes (255 bytes) whatever the program's name is.
            let stem = Path::new(program_name)
                .file_stem()
                .map_or_else(|| "job".to_string(), |s| s.to_string_lossy().into_owned());
            let stem = cut_at(&stem, MAX_REPORT_STEM_BYTES);
            // Named by the local date and time it started; a second job in the same second
            // gets a suffix rather than the first one's folder.
            let stamp = crate::sys::local_stamp();
            let mut n = 1;
            loop {
                let name = match n {
                    1 => format!("{stamp}-{stem}"),
                    n => format!("{stamp}-{stem}-{n}"),
                };
                let path = dir.join(name);
                let made = std::fs::create_dir_all(dir).and_then(|()| std::fs::create_dir(&path));
                match made {
                    Ok(()) => break Some(path),
                    Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && n < 100 => n += 1,
                    Err(source) => return Err(Refusal::ReportDir { dir: path, source }),
                }
            }
        }
        None => None,
    })
}

/// Logs a job's start; what the command answers.
fn started(program: &str, blocks: u64, resumed: bool, kind: JobKind, message: &str) -> String {
    tracing::info!(
        edmd_event = "job_start",
        edmd_program = program,
        "job start: {program}{}",
        match (resumed, kind == JobKind::DryRun) {
            (true, _) => " (resumed)",
            (_, true) => " (dry run: spark off, the servo out of the loop)",
            _ => "",
        }
    );
    if resumed {
        format!("resuming {program}: {blocks} blocks")
    } else {
        format!("running {program}: {blocks} blocks{message}")
    }
}

/// A `run` request's arguments.
pub(super) struct RunAsk<'a> {
    pub program: &'a str,
    pub dry_run: bool,
    pub from_line: Option<u64>,
    pub approach: Option<crate::path::Approach>,
    /// Where the wire stands, as the operator says, for a run from a line by the path.
    pub wire_at: Option<crate::path::WireAt>,
    /// The pass a run from a line cuts its line in.
    pub pass: Option<u8>,
    pub passes: Option<usize>,
    /// In passes: the tab the job leaves (mm), in place of `wire.tab_mm`.
    pub tab_mm: Option<f64>,
    /// `material=steel,height=32,wire=0.25`.
    pub technology: Option<&'a str>,
    pub force: bool,
}

impl Core {
    /// What the machine's commands read: the configuration and the machine.
    pub(super) fn desk(&self) -> Desk<'_> {
        Desk {
            config: &self.config,
            machine: &self.machine,
        }
    }

    /// Starts the check of what a command ordered; what the operator is told.
    pub(super) fn launch(&mut self, order: Order) -> String {
        let Order {
            source,
            launch,
            said,
        } = order;
        let id = self.begin_check(source, None, launch);
        format!("{said} (check {id})")
    }

    /// A command that starts a check is refused while the loop has a job or a check in hand,
    /// or is shutting down.
    pub(super) fn refuse_if_busy(&self) -> Result<(), Refusal> {
        if self.shutting_down {
            return Err(Refusal::ShuttingDown);
        }
        if let Some(job) = &self.jobs.job {
            return Err(Refusal::JobRunning {
                state: self.state().name(),
                program: job.program.clone(),
            });
        }
        if let Some(check) = &self.jobs.check {
            return Err(Refusal::Checking {
                name: check.name.clone(),
                id: check.id,
            });
        }
        Ok(())
    }

    /// What `request` selects from the tables in force, explained.
    pub(super) fn explain(&self, request: &str) -> Result<String, String> {
        crate::technology::Request::parse(request, "technology", 1, 1)
            .and_then(|r| self.technology.select(&r))
            .map(|s| s.explain())
            .map_err(|e| e.to_string())
    }

    pub(super) fn run_program(&mut self, ask: RunAsk) -> Result<String, Refusal> {
        let RunAsk {
            program: requested,
            dry_run,
            from_line,
            approach,
            wire_at,
            pass,
            passes,
            tab_mm: tab_asked,
            technology,
            force,
        } = ask;
        if let Some(tab) = tab_asked
            && !(tab.is_finite() && tab >= 0.0)
        {
            return Err(Refusal::BadArgument(format!(
                "tab {tab}: a tab is a length along the contour, 0 mm (none) or more"
            )));
        }
        self.refuse_if_busy()?;
        self.desk().refuse_if_tripped(None)?;
        self.desk().refuse_if_unhomed()?;
        let from_line =
            self.run_from_line(dry_run, from_line, approach)?
                .map(|f| crate::path::FromLine {
                    pass,
                    wire_at: wire_at.unwrap_or_default(),
                    ..f
                });
        if pass.is_some() && from_line.is_none() {
            return Err(Refusal::BadArgument(
                "a pass is for a run from a line: give from_line too (a whole job cuts every \
                 pass)"
                    .into(),
            ));
        }
        if pass == Some(0) {
            return Err(Refusal::BadArgument(
                "pass counts from 1 (the first pass of the table)".into(),
            ));
        }
        if from_line.is_some() {
            self.desk().refuse_if_untrusted("run from a line", force)?;
        } else if force {
            return Err(Refusal::BadArgument(
                "--force is for a run from a line (a whole program starts where it says)".into(),
            ));
        }
        let asked = technology
            .map(|t| crate::technology::Request::parse(t, "technology", 1, 1))
            .transpose()
            .map_err(|e| Refusal::BadArgument(e.to_string()))?;
        let passes_asked = passes;
        let passes = match passes {
            None => Vec::new(),
            Some(0) => {
                return Err(Refusal::BadArgument(
                    "passes counts from 1 (the first pass of the table)".into(),
                ));
            }
            // A technology's passes are counted by the check, which selects it.
            Some(_) if asked.is_some() => Vec::new(),
            // The table's; what is wrong with them is said now unless the program's header
            // names a technology, which the check reads.
            Some(n) => crate::path::passes::first(
                &self.config.wire.passes,
                n,
                &self.config.condition_numbers(),
            )
            .unwrap_or_default(),
        };
        let tab_mm = if passes.is_empty() {
            0.0
        } else {
            tab_asked.unwrap_or(self.config.wire.tab_mm)
        };

        let program = confine(&self.config.daemon.program_dir, requested)?;
        let recovery = self.recovery(&program, from_line.as_ref(), wire_at)?;
        let cut = crate::path::CutPlan {
            from_line,
            passes,
            tab_mm,
            dry_run_feed_mm_per_min: dry_run.then_some(self.config.machine.dry_run_feed_mm_per_min),
            kerf_end: recovery.kerf_end,
        };
        let with = asked
            .as_ref()
            .map(|r| format!(" with the technology {}", r.text()))
            .unwrap_or_default();
        let launch = Launch {
            technology: super::launch::JobTechnology::Ask(super::launch::TechAsk {
                asked,
                passes: passes_asked,
                tab_mm: tab_asked,
                resume: false,
                tables: self.technology.clone(),
            }),
            start: recovery.start,
            kind: if dry_run {
                JobKind::DryRun
            } else {
                JobKind::Program
            },
            cut: cut.clone(),
            recovers: recovery.sha256,
        };
        let id = self.begin_check(Source::Original(program.clone()), None, launch);
        let from = match (cut.from_line, cut.passes.len()) {
            (Some(f), _) => format!(" from {} ({})", f.text(), f.approach_text()),
            (None, 0) => String::new(),
            (None, n) => format!(" in {n} passes"),
        };
        Ok(format!(
            "accepted: checking {}{from}{with} (check {id}); the job starts when the check \
             passes",
            program.display()
        ))
    }

    /// Where a run from a line starts, as [`Desk::recovery`] holds the operator's word to
    /// the stopped job of the program, if one is kept; a whole job starts here.
    fn recovery(
        &self,
        program: &std::path::Path,
        from: Option<&crate::path::FromLine>,
        wire_at: Option<crate::path::WireAt>,
    ) -> Result<super::desk::Recovery, Refusal> {
        let Some(from) = from else {
            if wire_at.is_some() {
                return Err(Refusal::BadArgument(
                    "where the wire stands is for a run from a line: give from_line too".into(),
                ));
            }
            return Ok(super::desk::Recovery {
                start: self.machine.state.work_start(),
                kerf_end: None,
                sha256: None,
            });
        };
        let stopped = self.checkpoints.of_program(program);
        self.desk()
            .recovery(&program.display().to_string(), from, wire_at, stopped)
    }

    /// The run-from-line of a `run` request: a line from 1, an approach only with a line,
    /// not with a dry run; the approach by default `direct` where a safe Z is set (a
    /// sinker), `path` otherwise (a wire machine).
    fn run_from_line(
        &self,
        dry_run: bool,
        line: Option<u64>,
        approach: Option<crate::path::Approach>,
    ) -> Result<Option<crate::path::FromLine>, Refusal> {
        let Some(line) = line else {
            return match approach {
                Some(_) => Err(Refusal::BadArgument(
                    "an approach is for a run from a line: give from_line too".into(),
                )),
                None => Ok(None),
            };
        };
        if line == 0 {
            return Err(Refusal::BadArgument(
                "from_line counts from 1 (the program's first line)".into(),
            ));
        }
        if dry_run {
            return Err(Refusal::BadArgument(
                "a dry run proves the whole program: it does not start from a line".into(),
            ));
        }
        let approach = approach.unwrap_or(crate::path::Approach::default_for(
            self.config.machine.safe_z_mm,
        ));
        Ok(Some(crate::path::FromLine {
            line,
            approach,
            pass: None,
            wire_at: Default::default(),
        }))
    }

    /// The job about to start, as the core keeps it.
    fn new_job(
        &self,
        program: &JobProgram,
        check: &runtime::Precheck,
        launch: Launch,
        (report, recording): (Option<PathBuf>, JobRecording),
        progress: runtime::ProgressTracker,
        resumed: bool,
    ) -> Job {
        Job {
            program: PathBuf::from(&program.name),
            program_sha256: program.sha256.clone(),
            published: Arc::new(self.jobs.published()),
            stop: Arc::new(AtomicBool::new(false)),
            stop_reason: None,
            started: Instant::now(),
            started_at: super::history::local_time(),
            resumed,
            hold_checkpointed: false,
            last_checkpoint: Instant::now(),
            overruns_seen: 0,
            last_overrun_report: Instant::now(),
            config: launch.job_config(&self.config),
            report,
            recording,
            motion_settings: checkpoint::motion_settings(&self.keys),
            progress,
            resumed_from: if resumed {
                self.checkpoints.current.clone()
            } else {
                None
            },
            start: launch.start,
            leaves: (check.work_offsets.clone(), check.work_system),
            cuts_in: check.cuts_in.clone(),
            modes: check.modes,
            pause_messages: check.pause_messages.clone(),
            kind: launch.kind,
            technology: match launch.technology {
                super::launch::JobTechnology::Selected(s) => Some(s),
                _ => None,
            },
            cut: launch.cut,
        }
    }

    /// A new job's recording, also the page's executed path from now on.
    fn record(
        &mut self,
        program: &str,
        start: &[i64],
        kind: JobKind,
        (offsets, system): &(crate::gcode::WorkOffsets, crate::gcode::WorkSystem),
    ) -> JobRecording {
        let recording: JobRecording = Arc::new(parking_lot::Mutex::new(
            Recording::new(&self.config.machine.step_mm, self.config.fine.tick)
                .with_upper_guide(self.config.machine.upper_guide_axes())
                .starting_at(start),
        ));
        // The page's executed path is what was cut: a homing search, a jog or a touch cycle
        // moves the machine but cuts nothing, and the last cut stays on the page.
        if matches!(kind, JobKind::Program | JobKind::DryRun | JobKind::Mdi) {
            let offset = offsets.get(*system);
            *self.jobs.executed.lock() = Some(super::http::executed::Executed {
                program: program.to_string(),
                recording: recording.clone(),
                work_system: system.name().to_string(),
                work_offset_mm: [offset[0], offset[1]],
                dry_run: kind == JobKind::DryRun,
            });
        }
        recording
    }

    /// Starts copying and checking a program on a worker thread; the verdict comes back as
    /// [`CoreMsg::Checked`]. Returns the check's id.
    pub(super) fn begin_check(
        &mut self,
        source: Source,
        resume: Option<Resume>,
        launch: Launch,
    ) -> u64 {
        self.jobs.next_check_id += 1;
        let id = self.jobs.next_check_id;
        let progress = Arc::new(Progress::new());
        let name = match &source {
            Source::Original(path) => path.display().to_string(),
            Source::Copy(program) => program.name.clone(),
            Source::Generated { name, .. } => name.clone(),
        };
        let (mut config, dir, tx) = (
            self.config.clone(),
            super::checkpoints::copy_dir(&self.config.daemon.checkpoint),
            self.clients.to_core.clone(),
        );
        if matches!(launch.kind, JobKind::Home { .. }) {
            // Homing finds where the machine is: the soft limits mean nothing yet.
            config.machine.travel.iter_mut().for_each(|t| *t = None);
        }
        let expect = resume.as_ref().map(|r| r.sha256.clone());
        let worker_progress = progress.clone();
        let worker_launch = launch;
        let spawned = std::thread::Builder::new()
            .name("edmd-check".to_string())
            .stack_size(crate::gcode::PARSER_STACK_BYTES)
            .spawn(move || {
                let result = copy_and_check(
                    source,
                    &dir,
                    &config,
                    worker_launch,
                    expect.as_deref(),
                    &worker_progress,
                );
                let result = Box::new(result);
                let _ = tx.send(CoreMsg::Checked { id, result });
            });
        if let Err(e) = spawned {
            let result = Err(CheckRefusal::Thread(e));
            let result = Box::new(result);
            let _ = self.clients.to_core.send(CoreMsg::Checked { id, result });
        }
        tracing::info!("check {id}: {name}: copying and checking");
        self.jobs.check = Some(Check {
            id,
            name,
            progress,
            resume,
        });
        id
    }

    /// The verdict of a check: start the job, or record why not.
    pub(super) fn on_checked(&mut self, id: u64, result: Result<Checked, CheckRefusal>) {
        let Some(check) = self.jobs.check.take_if(|c| c.id == id) else {
            return;
        };
        let outcome = if self.shutting_down {
            Err(Refusal::ShuttingDown)
        } else {
            result.map_err(Refusal::from).and_then(|checked| {
                self.refuse_if_tripped_since(checked.launch.kind)?;
                let resume = check.resume.as_ref().map(|r| r.point.clone());
                self.start_job(checked.program, checked.precheck, resume, checked.launch)
            })
        };
        let (bytes_done, bytes_total) = {
            let (_, done, total) = check.progress.get();
            (done, total)
        };
        let mut status = CheckStatus {
            id,
            program: check.name.clone(),
            phase: String::new(),
            bytes_done,
            bytes_total,
            error: None,
            message: None,
            resume: check.resume.is_some(),
        };
        match outcome {
            Ok(message) => {
                tracing::info!("check {id}: {message}");
                status.phase = "started".to_string();
                status.message = Some(message);
            }
            Err(error) => {
                // A homing sequence and a touch cycle stop at their first refusal.
                self.machine.homing_queue.clear();
                self.touch.refused(&error.to_string());
                tracing::error!(
                    edmd_event = "refusal",
                    edmd_program = check.name,
                    "check {id}: refused: {error}"
                );
                status.phase = "refused".to_string();
                status.error = Some(error.to_string());
            }
        }
        self.jobs.last_check = Some(status);
        self.notify_status();
    }

    /// A trip that came while the check ran refuses the start, as it would have refused the
    /// request: an E-stop anything, a limit switch anything but a jog (whose direction was
    /// judged against the switch when it was asked for).
    fn refuse_if_tripped_since(&self, kind: JobKind) -> Result<(), Refusal> {
        match (kind, self.machine.state.trip) {
            (JobKind::Jog { .. }, Some(crate::vocab::Trip::Limit(_))) => Ok(()),
            _ => self.desk().refuse_if_tripped(None),
        }
    }

    /// Opens the I/O and starts the job thread on a checked program.
    fn start_job(
        &mut self,
        program: JobProgram,
        check: runtime::Precheck,
        resume: Option<ResumePoint>,
        launch: Launch,
    ) -> Result<String, Refusal> {
        let config = launch.job_config(&self.config);
        let spec = launch.spec(&config);
        let switch = launch.home_switch();
        let kind = launch.kind;
        let from_line = launch.cut.from_line;
        let blocks = check.blocks;
        if resume.is_none() && matches!(kind, JobKind::Program | JobKind::DryRun) && !check.tapers {
            self.desk().refuse_if_leaning()?;
        }
        let ledger = resume
            .as_ref()
            .map_or_else(|| spec.start_steps().to_vec(), |r| r.position.clone());
        // A report of what this job runs, when the configuration asks for one. Its folder is
        // made first: a job must not learn at its end that its report has nowhere to go.
        let report = job_report(&config, &program.name, kind)?;
        let mut io = self.jobs.job_io(&config, &check, &ledger)?;
        // A homing job's probing moves read its switch, a touch cycle's the part; any other
        // job's the probe (the claimed port's gap input is lent to every job).
        io.probe_reads = launch.probe_reads(&spec.start_steps());
        let recording = self.record(&program.name, &ledger, kind, &check.cuts_in);
        if report.is_some() {
            draw_programmed(&recording, &program, &spec);
        }
        io.recording = Some(recording.clone());
        let resumed = resume.is_some();
        let progress = runtime::ProgressTracker::new(
            check.path_mm,
            check.pace.clone(),
            spec.plan.rapid_feed_mm_per_s,
        );
        let job = self.new_job(
            &program,
            &check,
            launch,
            (report, recording),
            progress,
            resumed,
        );
        let (published, stop) = (job.published.clone(), job.stop.clone());
        // A continuous jog's dead-man is kept by the job's own thread too.
        if matches!(kind, JobKind::Jog { .. })
            && let Some(deadline_ns) = self.jobs.pendant.deadline_ns()
        {
            published
                .dead_man_ns
                .store(deadline_ns, std::sync::atomic::Ordering::Release);
        }
        // A new program keeps a stopped job's checkpoint aside, and only now that it really
        // starts (a jog, MDI, homing or a dry run leave it alone): it is the checkpoint again
        // once this job is done, until the operator discards it.
        // Write-ahead: before the first step the checkpoint on disk says this job is moving,
        // from where it starts; a job that cannot record that does not start.
        let at = super::checkpoints::write_ahead_point(resume.as_ref(), &spec, &config);
        super::desk::homing::started(&mut self.machine, switch.as_ref());
        self.machine.save(true).map_err(super::desk::unwritten)?;
        let checkpoint_path = self.config.daemon.checkpoint.clone();
        let kept = match !resumed && kind == JobKind::Program {
            true => self.checkpoints.park(&checkpoint_path, &program.sha256)?,
            false => None,
        };
        if let Err(error) = self.checkpoints.write(&job, &at, Reason::Moving, false) {
            self.checkpoints.unpark(&checkpoint_path);
            return Err(Refusal::WriteAhead {
                error,
                consequence: "the job does not start without its checkpoint",
            });
        }
        let message = kept
            .map(|program| {
                format!(
                    "; the checkpoint of {program} is kept: `resume` continues it after this job"
                )
            })
            .unwrap_or_default();
        self.jobs.prune_copies(
            &self.checkpoints,
            &self.config.daemon.checkpoint,
            Some(&program.sha256),
        );
        let (fine, tx) = (self.jobs.fine.clone(), self.clients.to_core.clone());
        let (job_published, job_stop, job_program) =
            (published.clone(), stop.clone(), program.clone());
        std::thread::Builder::new()
            .name("edmd-job".to_string())
            .spawn(move || {
                let job = runtime::JobRun {
                    program: &job_program,
                    check: &check,
                    spec: &spec,
                    resume,
                };
                let end = runtime::run(&fine, job, io, job_published, &job_stop);
                let _ = tx.send(CoreMsg::JobDone(Box::new(end)));
            })
            .map_err(Refusal::JobThread)?;
        self.jobs.job = Some(job);
        let message = match from_line {
            Some(f) => format!(" from {} ({}){message}", f.text(), f.approach_text()),
            None => message,
        };
        Ok(started(&program.name, blocks, resumed, kind, &message))
    }
}
