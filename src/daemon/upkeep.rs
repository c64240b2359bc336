//! The control loop's round and what it does besides answering commands: signals (stop,
//! reload, log level), the web side's reload, and the periodic work of every round (the dead-man of a
//! continuous jog, hold and periodic checkpoints, overrun reports, the status line, the
//! systemd watchdog).

use super::*;

/// The log target: the control loop's, whatever file its code stands in (logs are filtered
/// and read by target).
const TARGET: &str = "edmd::daemon";

/// A SIGHUP's reads in progress.
pub(super) struct Reloading {
    since: Instant,
    /// The time-out was reported.
    reported: bool,
    /// Another SIGHUP came meanwhile: read again when this one answers.
    again: bool,
}

impl Core {
    /// The control loop: one message at a time (a request, a signal, a job's end, a
    /// check's verdict, a reload's reads), then the periodic work, until it is told to stop.
    pub(super) fn run(&mut self, inbox: &Receiver<CoreMsg>) {
        loop {
            // A continuous jog's dead-man is looked at when it falls due, not a period late;
            // while something moves, the board is posted every POST_EVERY.
            let period = self.post_period();
            let wait = self.jobs.pendant.deadline_ns().map_or(period, |deadline| {
                Duration::from_nanos(deadline.saturating_sub(crate::sys::monotonic_ns()))
                    .min(period)
            });
            let message = inbox.recv_timeout(wait);
            // Anything but a status request may change what the status says.
            self.post_due |= !matches!(message, Ok(CoreMsg::Request(Request::Status {}, _)));
            self.control_requests += u64::from(matches!(message, Ok(CoreMsg::Request(..))));
            match message {
                Ok(CoreMsg::Request(Request::Jobs { count, skip }, reply)) => {
                    self.list_jobs(count, skip, reply)
                }
                Ok(CoreMsg::Request(request, reply)) => {
                    let answer = self.handle(request);
                    // Posted before the reply: a client that reads the status after its
                    // command's reply sees what the command did.
                    self.post_status();
                    // A client that went away changes nothing: the command stands or was
                    // refused either way.
                    let _ = reply.send(answer);
                }
                Ok(CoreMsg::Signal(signal)) => self.on_signal(signal),
                Ok(CoreMsg::JobDone(end)) => self.on_job_done(*end),
                Ok(CoreMsg::Checked { id, result }) => self.on_checked(id, *result),
                Ok(CoreMsg::Reloaded(read)) => self.on_reloaded(*read),
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return,
            }
            self.periodic();
            self.post_status();
            if self.shutting_down && self.jobs.job.is_none() && self.jobs.check.is_none() {
                return;
            }
        }
    }
}

impl Core {
    /// After the loop: NDEATH before the socket goes (a host sees the machine leave, not
    /// time out), the socket removed, and for HAL the owner record (a clean stop: `edmd
    /// hal-wait` ends with success).
    pub(super) fn stopped(&mut self, socket_path: &std::path::Path) {
        self.notifier.send("STOPPING=1");
        if let Some(mqtt) = self.clients.mqtt.as_mut() {
            mqtt.stop();
        }
        socket::remove(socket_path);
        if self.config.output.kind == crate::config::OutputKind::Hal {
            crate::hal::owner::remove_record(
                &crate::hal::HalSettings::from_config(&self.config).owner_file,
            );
        }
        tracing::info!("stopped");
    }

    pub(super) fn on_signal(&mut self, signal: i32) {
        use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM, SIGUSR1};
        match signal {
            SIGTERM | SIGINT => {
                if self.shutting_down {
                    if let Some(job) = &self.jobs.job {
                        tracing::warn!(target: TARGET, "second stop signal: stopping where it is");
                        job.published.stop.store(true, Ordering::Relaxed);
                    }
                    return;
                }
                self.shutting_down = true;
                self.notifier.send("STOPPING=1");
                if let Some(check) = &self.jobs.check {
                    tracing::info!(target: TARGET, "signal {signal}: check {} cancelled", check.id);
                    check.progress.cancel();
                }
                match &mut self.jobs.job {
                    Some(job) => {
                        tracing::info!(
                            target: TARGET,
                            "signal {signal}: controlled stop of {} (braking, then checkpoint)",
                            job.program.display()
                        );
                        job.stop_reason = Some(Reason::Stop);
                        job.stop.store(true, Ordering::Relaxed);
                    }
                    None => tracing::info!(target: TARGET, "signal {signal}: stopping"),
                }
            }
            SIGHUP => self.start_reload(),
            SIGUSR1 => {
                for line in self.status().text().lines() {
                    tracing::info!(target: TARGET, "status: {line}");
                }
            }
            _ => {}
        }
    }

    /// SIGHUP: the configuration and the secrets are read on the reload worker; one that
    /// comes while a read is in progress is read after it.
    fn start_reload(&mut self) {
        if let Some(reloading) = &mut self.reloading {
            reloading.again = true;
            tracing::info!(target: TARGET, "reload: a read is in progress; this one follows it");
            return;
        }
        let d = &self.config.daemon;
        let in_force = reload::SecretPaths {
            token: self
                .clients
                .http
                .as_ref()
                .map(|_| d.http_token_file.clone()),
            users: self
                .clients
                .opcua
                .as_ref()
                .map(|_| d.opcua_users_file.clone()),
            technology: self.config.technology.dir.clone(),
        };
        let to_core = self.clients.to_core.clone();
        match reload::spawn_read(self.source.clone(), in_force, move |read| {
            let _ = to_core.send(CoreMsg::Reloaded(Box::new(read)));
        }) {
            Ok(()) => {
                self.reloading = Some(Reloading {
                    since: Instant::now(),
                    reported: false,
                    again: false,
                })
            }
            Err(e) => tracing::error!(target: TARGET, "reload: cannot start the reader: {e}"),
        }
    }

    /// The reload worker's reads: the configuration decided key by key, then the web side's
    /// token and the OPC UA users put in force.
    pub(super) fn on_reloaded(&mut self, read: reload::ReadBack) {
        let again = self.reloading.take().is_some_and(|r| r.again);
        let running = self.jobs.job.is_some();
        match read
            .config
            .map_err(reload::ReloadRefusal::from)
            .and_then(|(config, keys)| reload::decide(&self.keys, config, keys, running))
        {
            Ok(None) => tracing::info!(target: TARGET, "reload: nothing changed"),
            Ok(Some((config, keys, changes))) => {
                for change in &changes {
                    tracing::info!(target: TARGET, "reload: {change}");
                }
                if config.log.level != self.config.log.level
                    && let Err(e) = (self.set_log_level)(config.log.level.name())
                {
                    tracing::warn!(target: TARGET, "reload: log.level: {e}");
                }
                self.clients
                    .max_clients
                    .store(config.daemon.max_clients, Ordering::Relaxed);
                self.config = config;
                self.keys = keys;
            }
            Err(e) => {
                tracing::error!(target: TARGET, "reload refused, configuration unchanged: {e}")
            }
        }
        match read.technology {
            Ok(tables) => {
                technology_read(&tables);
                self.technology = Arc::new(tables);
            }
            Err(e) => tracing::error!(
                target: TARGET,
                "reload: technology tables unchanged: {e}"
            ),
        }
        if let (Some(server), Some(token)) = (&self.clients.http, read.token) {
            let d = &self.config.daemon;
            match token {
                Ok(token) => {
                    server.reload(http::Reloadable {
                        token,
                        program_dir: d.program_dir.clone(),
                        allowed_hosts: d.http_allowed_hosts.clone(),
                    });
                    tracing::info!(target: TARGET, "reload: http: token, program directory and hosts in force");
                }
                Err(e) => {
                    tracing::error!(target: TARGET, "reload: http: {e}; the previous token stays in force")
                }
            }
        }
        if let Some(server) = &self.clients.opcua {
            server.set_program_dir(self.config.daemon.program_dir.clone());
        }
        if let (Some(server), Some(users)) = (&self.clients.opcua, read.users) {
            let path = &self.config.daemon.opcua_users_file;
            match users {
                Ok(users) => {
                    let n = server.set_users(users);
                    tracing::info!(target: TARGET, "reload: opcua: {n} user(s) of {} in force", path.display())
                }
                Err(e) => {
                    tracing::error!(target: TARGET, "reload: opcua: {e}; the previous users stay in force")
                }
            }
        }
        self.notify_status();
        if again {
            self.start_reload();
        }
    }

    /// A reload whose reads have not answered in [`reload::READ_TIMEOUT`] is reported once;
    /// the control loop goes on meanwhile.
    fn watch_reload(&mut self) {
        let source = self.source.path.as_ref().map(|p| p.display().to_string());
        if let Some(r) = &mut self.reloading
            && !r.reported
            && r.since.elapsed() >= reload::READ_TIMEOUT
        {
            r.reported = true;
            tracing::error!(
                target: TARGET,
                "reload: reading {} has not finished after {} s (a FIFO, a hung mount?); the \
                 configuration in force stays, and the control loop goes on",
                source.as_deref().unwrap_or("the configuration"),
                reload::READ_TIMEOUT.as_secs()
            );
        }
    }

    // ---- job end and periodic work --------------------------------------------------------

    pub(super) fn periodic(&mut self) {
        self.watchdog();
        self.dead_man();
        self.watch_inputs();
        self.watch_reload();
        self.history.retry();
        let now = Instant::now();
        if let Some(mut job) = self.jobs.job.take() {
            let snap = job.published.snapshot();
            let stopping = job.stop.load(Ordering::Relaxed);
            if job.published.hold.load(Ordering::Relaxed)
                && snap.still
                && job.published.output_synced.load(Ordering::Acquire)
                && !stopping
                && !job.hold_checkpointed
                && self
                    .checkpoints
                    .write(&job, &snap, Reason::Hold, true)
                    .is_ok()
            {
                // A failed write is tried again on the next round (the disk may free up); the
                // moving checkpoint on disk meanwhile says what it should.
                job.hold_checkpointed = true;
                job.last_checkpoint = now;
                // The machine state says the standstill too (a restart may resume from it).
                let _ = self
                    .machine
                    .standstill(&snap.position)
                    .map_err(super::desk::unwritten);
                tracing::info!(
                    target: TARGET,
                    "held at {}:{} ({:?} steps)",
                    job.program.display(),
                    snap.line,
                    &snap.position[..job.config.machine.axes.len()]
                );
                self.notify_status();
            }
            if let Some(interval) = self.config.daemon.checkpoint_interval_s
                && !snap.still
                && !snap.state.is_final()
                && now.duration_since(job.last_checkpoint).as_secs_f64() >= interval
            {
                let _ = self.checkpoints.write(&job, &snap, Reason::Periodic, false);
                job.last_checkpoint = now;
            }
            job.progress.track(
                snap.path_mm,
                now,
                job.published.hold.load(Ordering::Relaxed),
            );
            let overruns = job.published.overruns.load(Ordering::Relaxed);
            if overruns > job.overruns_seen
                && now.duration_since(job.last_overrun_report) >= OVERRUN_REPORT
            {
                job.last_overrun_report = now;
                tracing::warn!(
                    target: TARGET,
                    "{} overruns (a tick ended after the next deadline) since the last report; \
                     {overruns} in this job",
                    overruns - job.overruns_seen
                );
                job.overruns_seen = overruns;
            }
            self.jobs.job = Some(job);
        }
        if let Some(interval) = self.config.daemon.status_interval_s
            && now.duration_since(self.last_status_line).as_secs_f64() >= interval
        {
            self.last_status_line = now;
            tracing::info!(target: TARGET, "status: {}", self.status_line());
            self.notify_status();
        }
    }

    /// Pings systemd's watchdog every half period, only if the fine thread made progress
    /// since the last ping (its idle heartbeat, or the job's ticks).
    pub(super) fn watchdog(&mut self) {
        let now = self.started.elapsed();
        let Some(gate) = self.watchdog.as_mut() else {
            return;
        };
        let ticks = self
            .jobs
            .job
            .as_ref()
            .map_or(0, |j| j.published.ticks.load(Ordering::Relaxed));
        let progress = self.jobs.fine.heartbeat().wrapping_add(ticks);
        match gate.check(now, progress, !self.jobs.fine.is_finished()) {
            Watchdog::Wait | Watchdog::Stalled { first: false } => {}
            Watchdog::Ping => self.notifier.send("WATCHDOG=1"),
            Watchdog::Stalled { first: true } => tracing::error!(
                target: TARGET,
                "the fine interpolation thread made no progress for {:.1} s: not pinging the \
                 watchdog",
                gate.since_ping(now).as_secs_f64()
            ),
        }
    }
}

/// Logs the technology tables read (and whether they are the shipped examples).
pub(super) fn technology_read(tables: &crate::technology::Tables) {
    let n = tables.tables().len();
    tracing::info!(
        target: TARGET,
        "technology: {n} table{} in {}",
        if n == 1 { "" } else { "s" },
        tables.dir().display()
    );
    let examples = tables.examples();
    if examples > 0 {
        tracing::warn!(
            target: TARGET,
            "technology: {examples} of them are edmd's example tables (example = true): \
             replace them with your generator maker's data"
        );
    }
}
