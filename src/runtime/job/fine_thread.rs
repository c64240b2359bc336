//! The fine-interpolation thread ("edmd-fine"): started once, handed one job at a time.
//!
//! ```text
//!  FineThread::start ─► spawn "edmd-fine" ─► SCHED_FIFO, mlockall, CPU pin (once)
//!                                         ─► idle: wait for a job; watch the claimed
//!                                            device every 1 ms (idle.rs), or beat every
//!                                            100 ms without one
//!  submit(job) ───────────────────────────► skip to the checkpoint (resume only)
//!                                         ─► run_loop ─► output.finish(why) ─► done channel
//! ```
//!
//! The daemon starts it before it reports READY, so the real-time settings are in force (or
//! their refusal logged) before the first job, and the thread stays alive between jobs: its
//! heartbeat ([`FineThread::heartbeat`]) plus the job's tick counter are what the systemd
//! watchdog pings on. `edmd run` starts one for its single job.
//!
//! **The claimed device lives here.** A parallel port or HAL component the daemon claims at
//! startup is handed to the thread once ([`Claimed`]) and stays with it: lent to each job
//! that asks for it (a job's `None` devices), watched between jobs ([`super::super::tick::idle`]),
//! never wrapped for good (a job's recorder wraps a borrow of it for that job only). A
//! job's own devices (the simulator, a pulse log, `edmd run`'s) are moved in and handed back
//! in [`FineDone`].

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::thread::{JoinHandle, Thread};
use std::time::Duration;

use crossbeam::channel::{self, Receiver, RecvTimeoutError, Sender};

use super::super::tick::consumer::{self, LoopReport, LoopSettings, Published};
use super::super::tick::idle::{IDLE_POLL, IdleWatch, Parked};
use super::super::tick::realtime::apply_realtime;
use super::devices::{BoxedGap, BoxedInputs, BoxedOutput};
use crate::buffer::LoopBuffer;
use crate::fine::{FineSettings, Interpolator, SkipError};
use crate::gap::{AlwaysNormal, GapSensor};
use crate::inputs::{Both, MachineInputs, NoInputs};
use crate::output::{NullOutput, OutputError, PulseOutput, StopReason};
use crate::process::ConditionTable;
use crate::record::{ProcessTap, RecordedOutput, Recorder};
use crate::servo::PathPoint;
use crate::vocab::{Steps, Trip};

/// How often the idle thread proves it is alive when it has no device to watch.
const IDLE_BEAT: Duration = Duration::from_millis(100);

/// The device the daemon claimed (a parallel port, a HAL component), handed to the fine
/// thread for its whole life.
pub struct Claimed {
    pub output: BoxedOutput,
    /// The device's own gap input, for jobs whose gap is the device's.
    pub gap: Option<BoxedGap>,
    pub inputs: BoxedInputs,
}

/// A job's recording: its recorder's queue, how often it samples, and the ledger it starts
/// from.
pub struct JobRecorder {
    pub queue: Arc<Recorder>,
    pub every_ticks: u64,
    pub start: Steps,
    /// The process trace, queued by the consumer's loop.
    pub process: ProcessTap,
}

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
    /// The job's own devices; `None`: the claimed device's.
    pub output: Option<BoxedOutput>,
    pub gap: Option<BoxedGap>,
    pub inputs: Option<BoxedInputs>,
    /// The inputs side of a simulated gap, read beside the machine's (dropped at the end).
    pub gap_inputs: Option<BoxedInputs>,
    /// Wrap the output in a recorder for this job.
    pub recorder: Option<JobRecorder>,
    /// What the job's probing moves read as their contact.
    pub probe_reads: crate::vocab::ProbeReads,
    /// The job's machining conditions: what each E number sets.
    pub conditions: ConditionTable,
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
    /// The job's own devices, handed back (the claimed device stays with the thread).
    pub output: Option<BoxedOutput>,
    pub gap: Option<BoxedGap>,
    pub inputs: Option<BoxedInputs>,
}

type Submission = (FineJob, Sender<FineDone>);

/// The running fine thread. Dropping it ends the thread once its job (if any) is over.
pub struct FineThread {
    jobs: Option<Sender<Submission>>,
    handle: Option<JoinHandle<()>>,
    beat: Arc<AtomicU64>,
    rt_refused: Vec<String>,
    idle: Arc<IdleWatch>,
    /// A device was claimed (the thread watches it between jobs).
    claimed: bool,
}

impl FineThread {
    /// Spawns the thread and applies the real-time settings to it; returns once they are in
    /// force (or refused: see [`rt_refused`](Self::rt_refused)). `claimed`: the device the
    /// thread keeps, lends to jobs and watches between them.
    pub fn start(settings: &LoopSettings, claimed: Option<Claimed>) -> std::io::Result<FineThread> {
        let (jobs, inbox) = channel::bounded::<Submission>(1);
        let (ready, applied) = channel::bounded(1);
        let beat = Arc::new(AtomicU64::new(0));
        let idle = Arc::new(IdleWatch::default());
        let settings = *settings;
        let (thread_beat, thread_idle) = (beat.clone(), idle.clone());
        let has_claim = claimed.is_some();
        let handle = std::thread::Builder::new()
            .name("edmd-fine".to_string())
            .spawn(move || {
                let realtime = apply_realtime(&settings);
                let _ = ready.send(realtime.refused.clone());
                let mut device = claimed.map(Device::new);
                serve_jobs(
                    &inbox,
                    &thread_beat,
                    &thread_idle,
                    &mut device,
                    &realtime.refused,
                );
                drop(realtime);
            })?;
        let rt_refused = applied.recv().unwrap_or_default();
        Ok(FineThread {
            jobs: Some(jobs),
            handle: Some(handle),
            beat,
            rt_refused,
            idle,
            claimed: has_claim,
        })
    }

    /// What the thread saw of the claimed device between jobs.
    pub fn idle_watch(&self) -> &IdleWatch {
        &self.idle
    }

    /// The thread keeps a claimed device.
    pub fn has_claim(&self) -> bool {
        self.claimed
    }

    /// Real-time features the system refused (already logged as warnings).
    pub fn rt_refused(&self) -> &[String] {
        &self.rt_refused
    }

    /// Grows while the thread is alive and idle (every idle poll), and once per job.
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

/// The claimed device as the thread keeps it.
struct Device {
    parked: Parked<dyn PulseOutput + Send, dyn MachineInputs + Send>,
    gap: Option<BoxedGap>,
}

impl Device {
    fn new(claimed: Claimed) -> Device {
        Device {
            parked: Parked::new(claimed.output, claimed.inputs),
            gap: claimed.gap,
        }
    }
}

fn serve_jobs(
    inbox: &Receiver<Submission>,
    beat: &AtomicU64,
    idle: &IdleWatch,
    device: &mut Option<Device>,
    rt_refused: &[String],
) {
    let period = if device.is_some() {
        IDLE_POLL
    } else {
        IDLE_BEAT
    };
    let mut last = crate::sys::monotonic_ns();
    loop {
        match inbox.recv_timeout(period) {
            Ok((job, done)) => {
                let result = run(job, device.as_mut(), rt_refused);
                beat.fetch_add(1, Ordering::Relaxed);
                last = crate::sys::monotonic_ns();
                let _ = done.send(result);
            }
            Err(RecvTimeoutError::Timeout) => {
                beat.fetch_add(1, Ordering::Relaxed);
                if let Some(d) = device.as_mut() {
                    let now = crate::sys::monotonic_ns();
                    d.parked.watch(idle, now.saturating_sub(last));
                    last = now;
                }
            }
            Err(RecvTimeoutError::Disconnected) => return,
        }
    }
}

/// Why the output goes quiet after the loop: what the loop's report says stopped it.
fn stop_reason(report: &LoopReport) -> StopReason {
    if matches!(report.tripped, Some((Trip::EStop, ..))) {
        StopReason::EStop
    } else if report.output_error.is_some()
        || report.gap_error.is_some()
        || report.input_error.is_some()
    {
        StopReason::Alarm
    } else {
        StopReason::Ended
    }
}

fn run(job: FineJob, device: Option<&mut Device>, rt_refused: &[String]) -> FineDone {
    let FineJob {
        buffer,
        published,
        mut output,
        mut gap,
        mut inputs,
        mut gap_inputs,
        recorder,
        probe_reads,
        conditions,
        settings,
        loop_settings,
        resume,
        start,
        supervisor,
    } = job;
    // The job's own devices, or the claimed device's lent for the job. A job that asks for
    // a claimed device the thread does not have (never made so) meets none: nothing moves
    // anywhere, and its steps go nowhere.
    let (mut no_output, mut no_gap, mut no_inputs) = (NullOutput, AlwaysNormal, NoInputs);
    let (mut claimed_output, mut claimed_gap, mut claimed_inputs) = (None, None, None);
    if let Some(d) = device {
        d.parked.used();
        claimed_output = Some(&mut *d.parked.output);
        claimed_inputs = Some(&mut *d.parked.inputs);
        claimed_gap = d.gap.as_deref_mut();
    }
    let out: &mut (dyn PulseOutput + Send) = match output.as_deref_mut() {
        Some(o) => o,
        None => claimed_output.map_or(&mut no_output, |o| o),
    };
    let sensor: &mut (dyn GapSensor + Send) = match gap.as_deref_mut() {
        Some(g) => g,
        None => claimed_gap.map_or(&mut no_gap, |g| g),
    };
    let machine_inputs: &mut (dyn MachineInputs + Send) = match inputs.as_deref_mut() {
        Some(i) => i,
        None => claimed_inputs.map_or(&mut no_inputs, |i| i),
    };
    // A simulated gap's machine is read beside the real one: either's E-stop stops.
    let mut both;
    let machine_inputs: &mut dyn MachineInputs = match gap_inputs.as_deref_mut() {
        Some(simulated) => {
            both = Both {
                first: machine_inputs,
                second: simulated,
            };
            &mut both
        }
        None => machine_inputs,
    };
    if let Some(r) = &recorder {
        // A job's Published is its own: the tap is set once, before its loop starts.
        let _ = published.process.set(r.process.clone());
    }
    let mut recorded;
    let out: &mut dyn PulseOutput = match recorder {
        Some(r) => {
            recorded = RecordedOutput::new(out, r.queue, r.every_ticks, r.start);
            &mut recorded
        }
        None => out,
    };
    out.prepare();
    sensor.probe_reads(probe_reads);
    machine_inputs.probe_reads(probe_reads);
    let mut fine = Interpolator::new(settings, start);
    fine.set_conditions(conditions);
    out.set_points(fine.process().condition(), fine.process().generator());
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
            out,
            sensor,
            machine_inputs,
            &loop_settings,
            &published,
        );
        report.rt_refused = rt_refused.to_vec();
        let why = stop_reason(&report);
        (report, out.finish(why))
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
