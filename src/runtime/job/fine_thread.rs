//! The fine-interpolation thread ("edmd-fine"): started once, handed one job at a time.
//!
//! ```text
//!  FineThread::start ─► spawn "edmd-fine" ─► SCHED_FIFO, mlockall, CPU pin (once)
//!                                         ─► idle: wait for a job, beat every 100 ms
//!  submit(job) ───────────────────────────► skip to the checkpoint (resume only)
//!                                         ─► run_loop ─► output.finish ─► done channel
//! ```
//!
//! The daemon starts it before it reports READY, so the real-time settings are in force (or
//! their refusal logged) before the first job, and the thread stays alive between jobs: its
//! heartbeat ([`FineThread::heartbeat`]) plus the job's tick counter are what the systemd
//! watchdog pings on. `edmd run` starts one for its single job.
//!
//! A job's output, gap source and machine inputs are moved in and handed back in
//! [`FineDone`], so a parallel port claimed once by the daemon is used by every job.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::thread::{JoinHandle, Thread};
use std::time::Duration;

use crossbeam::channel::{self, Receiver, RecvTimeoutError, Sender};

use super::super::tick::consumer::{self, LoopReport, LoopSettings, Published};
use super::super::tick::realtime::apply_realtime;
use super::devices::{BoxedGap, BoxedInputs, BoxedOutput};
use crate::buffer::LoopBuffer;
use crate::fine::{FineSettings, Interpolator, SkipError};
use crate::output::OutputError;
use crate::servo::PathPoint;
use crate::vocab::Steps;

/// How often the idle thread proves it is alive.
const IDLE_BEAT: Duration = Duration::from_millis(100);

/// Where a resumed job starts: a point of the program and the ledger there.
#[derive(Debug, Clone, PartialEq)]
pub struct ResumePoint {
    pub here: PathPoint,
    /// Steps per configured axis.
    pub position: Vec<i64>,
    /// Seconds of a `G4` dwell the first run still owed there.
    pub dwell_s: f64,
    /// The source line there (for the checkpoint a resumed job writes before it moves).
    pub line: u64,
}

/// One job for the fine thread.
pub struct FineJob {
    pub buffer: Arc<LoopBuffer>,
    pub published: Arc<Published>,
    pub output: BoxedOutput,
    pub gap: BoxedGap,
    pub inputs: BoxedInputs,
    pub settings: FineSettings,
    pub loop_settings: LoopSettings,
    pub resume: Option<ResumePoint>,
    /// The machine position the job starts from (steps): the ledger's first value.
    pub start: Steps,
    /// Unparked when the job ends, so its supervisor wakes at once.
    pub supervisor: Thread,
}

/// What the fine thread hands back at the end of a job.
pub struct FineDone {
    pub fine: Interpolator,
    pub report: LoopReport,
    /// `finish()` of the output (flush, drives idle).
    pub finished: Result<(), OutputError>,
    /// The resumed job could not reach its checkpoint; nothing moved.
    pub skip: Result<(), SkipError>,
    pub output: BoxedOutput,
    pub gap: BoxedGap,
    pub inputs: BoxedInputs,
}

type Submission = (FineJob, Sender<FineDone>);

/// The running fine thread. Dropping it ends the thread once its job (if any) is over.
pub struct FineThread {
    jobs: Option<Sender<Submission>>,
    handle: Option<JoinHandle<()>>,
    beat: Arc<AtomicU64>,
    rt_refused: Vec<String>,
}

impl FineThread {
    /// Spawns the thread and applies the real-time settings to it; returns once they are in
    /// force (or refused: see [`rt_refused`](Self::rt_refused)).
    pub fn start(settings: &LoopSettings) -> std::io::Result<FineThread> {
        let (jobs, inbox) = channel::bounded::<Submission>(1);
        let (ready, applied) = channel::bounded(1);
        let beat = Arc::new(AtomicU64::new(0));
        let settings = *settings;
        let thread_beat = beat.clone();
        let handle = std::thread::Builder::new()
            .name("edmd-fine".to_string())
            .spawn(move || {
                let realtime = apply_realtime(&settings);
                let _ = ready.send(realtime.refused.clone());
                serve_jobs(&inbox, &thread_beat, &realtime.refused);
                drop(realtime);
            })?;
        let rt_refused = applied.recv().unwrap_or_default();
        Ok(FineThread {
            jobs: Some(jobs),
            handle: Some(handle),
            beat,
            rt_refused,
        })
    }

    /// Real-time features the system refused (already logged as warnings).
    pub fn rt_refused(&self) -> &[String] {
        &self.rt_refused
    }

    /// Grows while the thread is alive and idle, and once per job.
    pub fn heartbeat(&self) -> u64 {
        self.beat.load(Ordering::Relaxed)
    }

    /// The thread has ended (it only does when dropped, or if a job panicked in it).
    pub fn is_finished(&self) -> bool {
        self.handle.as_ref().is_none_or(|h| h.is_finished())
    }

    /// Hands `job` to the thread; the result arrives on the returned channel. A closed
    /// channel means the thread died (a panic in the job).
    pub fn submit(&self, job: FineJob) -> Receiver<FineDone> {
        let (done, result) = channel::bounded(1);
        if let Some(jobs) = &self.jobs {
            let _ = jobs.send((job, done));
        }
        result
    }
}

impl Drop for FineThread {
    fn drop(&mut self) {
        self.jobs = None;
        if let Some(handle) = self.handle.take() {
            let _ = handle.join();
        }
    }
}

fn serve_jobs(inbox: &Receiver<Submission>, beat: &AtomicU64, rt_refused: &[String]) {
    loop {
        match inbox.recv_timeout(IDLE_BEAT) {
            Ok((job, done)) => {
                let result = run(job, rt_refused);
                beat.fetch_add(1, Ordering::Relaxed);
                let _ = done.send(result);
            }
            Err(RecvTimeoutError::Timeout) => {
                beat.fetch_add(1, Ordering::Relaxed);
            }
            Err(RecvTimeoutError::Disconnected) => return,
        }
    }
}

fn run(job: FineJob, rt_refused: &[String]) -> FineDone {
    let FineJob {
        buffer,
        published,
        mut output,
        mut gap,
        mut inputs,
        settings,
        loop_settings,
        resume,
        start,
        supervisor,
    } = job;
    let mut fine = Interpolator::new(settings, start);
    // The walk to the checkpoint waits for the producer whatever the time mode: nothing
    // ticks yet, so waiting costs no deadline.
    let mut source = buffer.consumer(true);
    let skip = match &resume {
        Some(point) => fine
            .skip_to(point.here, &point.position, &mut source)
            .map(|()| fine.resume_dwell((point.dwell_s / settings.dt).round() as u64)),
        None => Ok(()),
    };
    source.set_wait_for_producer(loop_settings.virtual_time);
    published.publish(0, &fine);
    let (report, finished) = if skip.is_ok() {
        let mut report = consumer::run_loop(
            &mut fine,
            &mut source,
            &mut output,
            &mut gap,
            &mut inputs,
            &loop_settings,
            &published,
        );
        report.rt_refused = rt_refused.to_vec();
        (report, output.finish())
    } else {
        published.finished.store(true, Ordering::Release);
        (LoopReport::empty(), Ok(()))
    };
    // Releases a producer still waiting for space (after an alarm or a stop).
    buffer.abort();
    supervisor.unpark();
    FineDone {
        fine,
        report,
        finished,
        skip,
        output,
        gap,
        inputs,
    }
}
