//! What the daemon reports: its state, the [`Status`] a client receives, the periodic
//! status line of the log and systemd's `STATUS=`. Read-only views of the control loop's
//! state and of the running job's seqlocked snapshot; the status posted on the board
//! ([`super::board`]) and the history's pages read for clients, both off the loop's time.

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use super::protocol::{
    CheckStatus, CheckpointStatus, Counters, DaemonState, JobStatus, OverrideStatus, Reply, Status,
};
use super::{Core, MAX_HISTORY_READERS, PERIOD, ReplyTo, board, history, mqtt};
use crate::runtime::{Published, Snapshot};
use crate::servo::{Excursion, PauseKind, ServoState};

impl Core {
    pub(super) fn state(&self) -> DaemonState {
        match &self.jobs.job {
            None if self.jobs.check.is_some() => DaemonState::Checking,
            None => match self.machine.state.trip {
                Some(crate::vocab::Trip::EStop) => DaemonState::Estop,
                Some(crate::vocab::Trip::Limit(_)) => DaemonState::Limit,
                None => DaemonState::Idle,
            },
            Some(job) => {
                let snap = job.published.snapshot();
                if job.stop.load(Ordering::Relaxed) {
                    DaemonState::Stopping
                } else if snap.state == ServoState::WireBroken {
                    DaemonState::WireBreak
                } else if snap.state == ServoState::Threading {
                    DaemonState::Threading
                } else if job.published.hold.load(Ordering::Relaxed) {
                    // An operator's hold during the way back to the start hole is a hold.
                    if snap.still && job.published.paused_line.load(Ordering::Relaxed) != 0 {
                        DaemonState::Paused
                    } else if snap.still {
                        DaemonState::Held
                    } else {
                        DaemonState::Holding
                    }
                } else if snap.state == ServoState::Retreat
                    && snap.excursion == Some(Excursion::Rethread)
                {
                    DaemonState::Rethreading
                } else {
                    match job.kind {
                        super::launch::JobKind::Program | super::launch::JobKind::DryRun => {
                            DaemonState::Running
                        }
                        super::launch::JobKind::Mdi => DaemonState::Mdi,
                        super::launch::JobKind::Jog { .. } => DaemonState::Jogging,
                        super::launch::JobKind::Home { .. } => DaemonState::Homing,
                        super::launch::JobKind::Touch { .. } => DaemonState::Finding,
                    }
                }
            }
        }
    }

    pub(super) fn status(&self) -> Status {
        let config = &self.config;
        // One snapshot for the job's view and its counts, so the two agree.
        let snapshot = self.jobs.job.as_ref().map(|job| job.published.snapshot());
        let job = self
            .jobs
            .job
            .as_ref()
            .zip(snapshot.as_ref())
            .map(|(job, snap)| job_status(job, snap));
        // A running job's ledger, in the work system its program is in.
        let live = snapshot
            .as_ref()
            .zip(self.jobs.job.as_ref())
            .map(|(s, job)| (s.position, &job.cuts_in));
        Status {
            machine: super::machine::machine_status(
                &self.machine,
                config,
                live,
                self.touch.status().cloned(),
            ),
            overrides: OverrideStatus {
                feed_pct: self.jobs.controls.feed_pct,
                rapid_pct: self.jobs.controls.rapid_pct,
            },
            single_block: self.jobs.controls.single_block,
            mqtt: self.clients.mqtt.as_ref().map(mqtt::MqttNode::status),
            state: self.state(),
            version: env!("CARGO_PKG_VERSION").to_string(),
            uptime_s: self.started.elapsed().as_secs_f64(),
            axes: config.machine.axis_names(),
            job,
            last_job: self.jobs.last.clone(),
            checkpoint: self.checkpoints.current.as_ref().map(|c| {
                CheckpointStatus::of(c, self.jobs.job.is_none() && self.jobs.check.is_none())
            }),
            kept_checkpoint: self
                .checkpoints
                .parked
                .as_ref()
                .map(|c| CheckpointStatus::of(c, false)),
            checkpoint_write_error: self.checkpoints.write_error.as_ref().map(|e| e.to_string()),
            check: match &self.jobs.check {
                Some(c) => {
                    let (phase, done, total) = c.progress.get();
                    Some(CheckStatus {
                        id: c.id,
                        program: c.name.clone(),
                        phase: phase.name().to_string(),
                        bytes_done: done,
                        bytes_total: total,
                        error: None,
                        message: None,
                        resume: c.is_resume(),
                    })
                }
                None => self.jobs.last_check.clone(),
            },
            rt_refused: self.jobs.fine.rt_refused().to_vec(),
            hours: self.history.counters,
            history_write_error: self.history.write_error.clone(),
            control_requests: self.control_requests,
            counters: {
                let mut counters = match self.jobs.job.as_ref().zip(snapshot.as_ref()) {
                    Some((job, snap)) => {
                        self.jobs.finished.plus(&job_counters(&job.published, snap))
                    }
                    None => self.jobs.finished.clone(),
                };
                counters.checkpoint_failures = self.checkpoints.failures;
                counters
            },
        }
    }

    /// One line for the log and systemd's STATUS=.
    pub(super) fn status_line(&self) -> String {
        self.status().line()
    }

    pub(super) fn notify_status(&self) {
        if self.notifier.active() {
            self.notifier.status(&self.status_line());
        }
    }
}

/// The process as the job's pulses tell it; `None` from a gap input that counts none.
fn process_status(job: &super::Job, snap: &Snapshot) -> Option<super::protocol::ProcessStatus> {
    use super::protocol::{ProcessStatus, PulseClasses};
    let [normal, arc, short, open] = snap.pulse_totals;
    if normal + arc + short + open == 0 {
        return None;
    }
    let seconds = job.config.fine.tick.ticks_to_secs(snap.tick).max(1e-9);
    let ignited = normal + arc;
    let height = snap.height_mm.is_finite().then_some(snap.height_mm);
    Some(ProcessStatus {
        pulses: PulseClasses {
            normal,
            arc,
            short,
            open,
        },
        rates_hz: PulseClasses {
            normal: normal as f64 / seconds,
            arc: arc as f64 / seconds,
            short: short as f64 / seconds,
            open: open as f64 / seconds,
        },
        mean_ignition_delay_us: (ignited > 0).then(|| snap.delay_sum_us / ignited as f64),
        off_time_us: snap.off_time_us,
        height_estimate_mm: height,
        cut_rate_mm2_per_min: height
            .or_else(|| job.technology.as_ref().and_then(|t| t.part_height_mm()))
            .zip(job.progress.recent_feed())
            .map(|(h, feed)| h * feed * 60.0),
    })
}

/// The running job as the status shows it, from its snapshot `snap`.
fn job_status(job: &super::Job, snap: &Snapshot) -> JobStatus {
    let p = &job.published;
    let axes = job.config.machine.axes.len();
    let samples = p.latency_samples.load(Ordering::Relaxed);
    JobStatus {
        program: job.program.display().to_string(),
        line: snap.line,
        segment: snap.here.seq,
        step: snap.here.event,
        parameter: snap.u_end.is_finite().then_some(snap.u_end),
        servo: snap.state,
        gap: p.gap(),
        gap_volts: p.gap_volts(),
        process: process_status(job, snap),
        position_steps: snap.position[..axes].to_vec(),
        position_mm: mm(&snap.position[..axes], &job.config.machine.step_mm),
        feed_mm_per_min: snap.speed * 60.0,
        buffer_unprocessed: p.buffer_unprocessed.load(Ordering::Relaxed),
        buffer_reserved: p.buffer_reserved.load(Ordering::Relaxed),
        buffer_capacity: job.config.buffer.capacity as u64,
        servo_counters: snap.servo,
        last_probe: crate::runtime::LastProbe::new(
            p.probe.last().as_ref(),
            &job.config.machine.step_mm[..axes],
        ),
        overruns: p.overruns.load(Ordering::Relaxed),
        pulses: snap.pulses[..axes].to_vec(),
        ticks: snap.tick,
        machine_time_s: job.config.fine.tick.ticks_to_secs(snap.tick),
        elapsed_s: job.started.elapsed().as_secs_f64(),
        latency_mean_us: (samples > 0)
            .then(|| p.latency_sum_ns.load(Ordering::Relaxed) as f64 / samples as f64 / 1000.0),
        latency_max_us: (samples > 0)
            .then(|| p.latency_max_ns.load(Ordering::Relaxed) as f64 / 1000.0),
        resumed: job.resumed,
        progress: job.progress.fraction(),
        path_done_mm: job.progress.done_mm(),
        path_total_mm: job.progress.total_mm(),
        eta_s: job.progress.eta_s(),
        recent_feed_mm_per_min: job.progress.recent_feed().map(|f| f * 60.0),
        dry_run: job.kind == super::launch::JobKind::DryRun,
        from_line: job.cut.from_line,
        passes: job.cut.passes.len(),
        pass: (snap.pass > 0).then_some(snap.pass),
        inch: job.modes.inch,
        condition: (snap.condition > 0).then_some(snap.condition),
        generator: job
            .config
            .conditions
            .iter()
            .find(|c| u64::from(c.number) == snap.condition)
            // The off time in force: the adaptive law's where it adapts the condition.
            .map(|c| crate::vocab::GeneratorSetPoints {
                off_time_us: if snap.off_time_us > 0.0 {
                    snap.off_time_us
                } else {
                    c.generator.off_time_us
                },
                ..c.generator
            }),
        technology: job.technology.as_ref().map(|t| t.summary()),
        technology_table: job.technology.as_ref().map(|t| t.table.clone()),
        wire_offset: super::protocol::WireOffsetStatus::of(snap.wire_offset_mm),
        paused_before_line: match p.paused_line.load(Ordering::Relaxed) {
            0 => None,
            line => Some(line),
        },
        pause: match p.paused_line.load(Ordering::Relaxed) {
            0 => None,
            _ => PauseKind::from_code(p.paused_kind.load(Ordering::Relaxed))
                .map(|k| k.name().to_string()),
        },
        pause_message: match p.paused_line.load(Ordering::Relaxed) {
            0 => None,
            line => PauseKind::from_code(p.paused_kind.load(Ordering::Relaxed))
                .filter(|k| *k == PauseKind::Program)
                .and_then(|_| {
                    let i = job.pause_messages.binary_search_by_key(&line, |(l, _)| *l);
                    i.ok().map(|i| job.pause_messages[i].1.clone())
                }),
        },
    }
}

impl CheckpointStatus {
    /// `checkpoint` as the status shows it; `resumable`: `resume` would continue it now.
    fn of(checkpoint: &crate::checkpoint::Checkpoint, resumable: bool) -> CheckpointStatus {
        CheckpointStatus {
            program: checkpoint.program.display().to_string(),
            line: checkpoint.line,
            reason: checkpoint.reason.name().to_string(),
            still: checkpoint.still,
            position_steps: checkpoint.position_steps.clone(),
            resumable,
        }
    }
}

pub(super) fn mm(steps: &[i64], step_mm: &[f64]) -> Vec<f64> {
    steps
        .iter()
        .zip(step_mm)
        .map(|(s, m)| *s as f64 * m)
        .collect()
}

/// One job's counts so far, from what its consumer publishes (`snap`: its snapshot).
pub(super) fn job_counters(p: &Published, snap: &Snapshot) -> Counters {
    let c = &snap.servo;
    let load = |a: &std::sync::atomic::AtomicU64| a.load(Ordering::Relaxed);
    Counters {
        jobs: 1,
        servo: *c,
        holds: load(&p.holds),
        overruns: load(&p.overruns),
        ticks: load(&p.ticks),
        checkpoint_failures: 0,
        gap_ticks: std::array::from_fn(|i| load(&p.gap_ticks[i])),
        latency_buckets: p.latency_buckets.iter().map(load).collect(),
        latency_sum_us: load(&p.latency_sum_ns) as f64 / 1000.0,
    }
}

/// The status posted for the transports, and the history read for them: both off the
/// control loop's own time.
impl Core {
    /// `jobs`: a page of the history, read on a thread of its own (a long history costs the
    /// reader, never the loop); at most [`MAX_HISTORY_READERS`] at once, more are refused.
    pub(super) fn list_jobs(&mut self, count: Option<usize>, skip: Option<usize>, reply: ReplyTo) {
        let status = self.status();
        if self.history_readers.fetch_add(1, Ordering::AcqRel) >= MAX_HISTORY_READERS {
            self.history_readers.fetch_sub(1, Ordering::AcqRel);
            let _ = reply.send(Reply::error(
                format!("{MAX_HISTORY_READERS} history reads are in progress: try again"),
                Some(status),
            ));
            return;
        }
        let file = self.history.file();
        let readers = self.history_readers.clone();
        let count = count.unwrap_or(20).clamp(1, history::MAX_LISTED);
        let skip = skip.unwrap_or(0);
        let read = std::thread::Builder::new()
            .name("edmd-history".to_string())
            .spawn(move || {
                let answer = match file.page(skip, count) {
                    Ok(page) => {
                        let mut r = Reply::ok(history::table(&page), status);
                        r.jobs = Some(page.jobs);
                        r
                    }
                    Err(e) => Reply::error(
                        format!(
                            "{}: cannot read the job history: {e}",
                            file.path().display()
                        ),
                        Some(status),
                    ),
                };
                let _ = reply.send(answer);
                readers.fetch_sub(1, Ordering::AcqRel);
            });
        if let Err(e) = read {
            self.history_readers.fetch_sub(1, Ordering::AcqRel);
            tracing::error!("jobs: cannot start the history reader: {e}");
        }
    }

    /// How long the loop may wait for a message: [`board::POST_EVERY`] while a job or a
    /// check runs (the status a page draws moves on), [`PERIOD`] otherwise.
    pub(super) fn post_period(&self) -> Duration {
        if self.jobs.job.is_some() || self.jobs.check.is_some() {
            board::POST_EVERY
        } else {
            PERIOD
        }
    }

    /// Posts the status on the board when something was handled since the last post, or
    /// when the last is a period old.
    pub(super) fn post_status(&mut self) {
        if self.post_due || self.posted_at.elapsed() >= self.post_period() {
            self.board.post(self.status());
            self.posted_at = Instant::now();
            self.post_due = false;
        }
    }
}
