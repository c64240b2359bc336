//! What the control loop does besides answering commands: signals (stop, reload, log
//! level), the web side's reload, and the periodic work of every round (the dead-man of a
//! continuous jog, hold and periodic checkpoints, overrun reports, the status line, the
//! systemd watchdog).

use super::*;

/// The log target: the control loop's, whatever file its code stands in (logs are filtered
/// and read by target).
const TARGET: &str = "edmd::daemon";

impl Core {
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
            SIGHUP => {
                let running = self.jobs.job.is_some();
                match reload::reload(&self.source, &self.keys, running) {
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
                self.reload_http();
                self.reload_opcua_users();
                self.notify_status();
            }
            SIGUSR1 => {
                for line in self.status().text().lines() {
                    tracing::info!(target: TARGET, "status: {line}");
                }
            }
            _ => {}
        }
    }

    /// SIGHUP: the token file is read again (whether or not its name changed) and the web
    /// side takes it, the program directory and the host list in force. A token the file no
    /// longer holds validly leaves the old one in force.
    pub(super) fn reload_http(&mut self) {
        let Some(server) = &self.clients.http else {
            return;
        };
        let d = &self.config.daemon;
        match http::token::load_or_create(&d.http_token_file) {
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

    /// SIGHUP: the OPC UA users file is read again; on an error the users in force stay.
    pub(super) fn reload_opcua_users(&mut self) {
        let Some(server) = &self.clients.opcua else {
            return;
        };
        let path = &self.config.daemon.opcua_users_file;
        match server.reload_users(path) {
            Ok(n) => {
                tracing::info!(target: TARGET, "reload: opcua: {n} user(s) of {} in force", path.display())
            }
            Err(e) => {
                tracing::error!(target: TARGET, "reload: opcua: {e}; the previous users stay in force")
            }
        }
    }

    // ---- job end and periodic work --------------------------------------------------------

    pub(super) fn periodic(&mut self) {
        self.watchdog();
        self.dead_man();
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
                self.machine.standstill(&snap.position);
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
            job.progress.track(snap.path_mm, now);
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
