//! The transports' dispatch: a request from any client (the socket, the page, OPC UA) is
//! handled here, on the control loop. The machine's commands ask the desk
//! ([`super::desk`]) what to launch, and the loop launches it when it is free (a check
//! first, as for any program); the desk's [`Pendant`](super::desk::pendant::Pendant) keeps a
//! continuous jog's button, and the jobs' room brakes the job it moves.

use std::sync::atomic::Ordering;

use super::desk;
use super::desk::manual::sign;
use super::desk::pendant::{LetGo, Press};
use super::launch::JobKind;
use super::protocol::{Reply, Request};
use super::refusal::Refusal;
use super::{Core, start};

impl Core {
    /// A client's request, answered with the status as it stands after it.
    pub(super) fn handle(&mut self, request: Request) -> Reply {
        // What the fine thread saw of the machine since the last round counts before any
        // command: a run sent right after an E-stop pulse is refused.
        self.watch_inputs();
        let result = match request {
            Request::Technology { request } => {
                let mut reply = match request.as_deref().map(|r| self.explain(r)) {
                    None => Reply::ok(self.technology.list().join("\n"), self.status()),
                    Some(Ok(text)) => Reply::ok(text, self.status()),
                    Some(Err(e)) => Reply::error(e, Some(self.status())),
                };
                reply.technology = Some(self.technology.summaries());
                return reply;
            }
            // Read off the loop (`list_jobs`); a request here is answered the same way.
            Request::Jobs { .. } => Ok("jobs".to_string()),
            Request::Status {} => Ok("status".to_string()),
            Request::Run {
                program,
                dry_run,
                from_line,
                approach,
                wire_at,
                pass,
                passes,
                tab_mm,
                technology,
                force,
            } => self.run_program(start::RunAsk {
                program: &program,
                dry_run,
                from_line,
                approach,
                wire_at,
                pass,
                passes,
                tab_mm,
                technology: technology.as_deref(),
                force,
            }),
            Request::Hold {} => self.hold(),
            Request::Resume { force } => self.resume(force),
            Request::Abort {} => self.abort(),
            Request::Rethread { here } => self.rethread(here),
            Request::Offsets {} => Ok(desk::offsets::table(&self.machine)),
            Request::WebLink {} => match &self.clients.http {
                Some(http) => http
                    .login_link()
                    .map_err(|e| Refusal::BadArgument(format!("cannot make a login code: {e}"))),
                None => Err(Refusal::BadArgument(
                    "daemon.http is off: there is no page to log in to".into(),
                )),
            },
            Request::TouchOff {
                axis,
                value,
                system,
            } => self.refuse_if_busy().and_then(|()| {
                desk::offsets::touch_off(
                    &self.config,
                    &mut self.machine,
                    &axis,
                    value,
                    system.as_deref(),
                )
            }),
            Request::Home { axes, here, force } => self.home(&axes, here, force),
            Request::Find { target, system } => self.find(&target, system.as_deref()),
            Request::Jog {
                axis,
                distance_mm,
                feed_mm_per_min,
            } => self.jog(&axis, distance_mm, feed_mm_per_min),
            Request::Mdi { line } => self.mdi(&line),
            Request::JogContinuous {
                axis,
                positive,
                feed_mm_per_min,
            } => self.jog_continuous(&axis, positive, feed_mm_per_min),
            Request::JogStop {} => self.jog_stop(),
            Request::Reset {} => self.reset(),
            Request::Discard { confirm } => self.discard_checkpoint(confirm),
            Request::Override { kind, percent } => self.jobs.set_override(kind, percent),
            Request::SingleBlock { on } => self.jobs.set_single_block(on),
        };
        self.notify_status();
        match result {
            Ok(message) => Reply::ok(message, self.status()),
            Err(refusal) => Reply::error(refusal.to_string(), Some(self.status())),
        }
    }

    /// `home [AXIS…] [--here]`.
    fn home(&mut self, axes: &[String], here: bool, force: bool) -> Result<String, Refusal> {
        self.refuse_if_busy()?;
        self.desk().refuse_if_tripped(None)?;
        if here {
            return desk::homing::here(&self.config, &mut self.machine, axes, force);
        }
        let order = desk::homing::by_switch(self.desk(), axes)?;
        let names: Vec<String> = order
            .iter()
            .map(|&i| self.config.machine.axes[i].to_string())
            .collect();
        let (first, rest) = order.split_first().expect("at least one axis");
        self.machine.homing_queue = rest.to_vec();
        let job = desk::homing::axis_job(self.desk(), *first);
        let id = self.begin_check(job.source, None, job.launch);
        Ok(format!(
            "homing {} by their switches, in that order (check {id})",
            names.join(", ")
        ))
    }

    /// `jog AXIS DISTANCE [--feed F]`.
    fn jog(&mut self, axis: &str, distance_mm: f64, feed: Option<f64>) -> Result<String, Refusal> {
        self.refuse_if_busy()?;
        let order = desk::manual::jog(self.desk(), axis, distance_mm, feed)?;
        Ok(self.launch(order))
    }

    /// `mdi LINES`.
    fn mdi(&mut self, lines: &str) -> Result<String, Refusal> {
        self.refuse_if_busy()?;
        let order = desk::manual::mdi(self.desk(), lines)?;
        Ok(self.launch(order))
    }

    /// `find TARGET [--system G5x]`: the touch cycle's first move.
    fn find(&mut self, target: &str, system: Option<&str>) -> Result<String, Refusal> {
        self.refuse_if_busy()?;
        let order = self
            .touch
            .start(&self.config, &mut self.machine, target, system)?;
        Ok(self.launch(order))
    }

    /// `reset` after an E-stop: refused while the E-stop input still reads pressed (on the
    /// claimed device, whose inputs the fine thread reads between jobs).
    fn reset(&mut self) -> Result<String, Refusal> {
        // Whatever the fine thread saw since the last look counts first: a reset must not
        // clear an E-stop pressed (and released) a moment ago that no trip records yet.
        self.watch_inputs();
        let fine = &self.jobs.fine;
        let estop_reads = fine.has_claim() && fine.idle_watch().reading().is_none_or(|r| r.estop);
        desk::trips::reset(&mut self.machine, estop_reads)
    }

    /// `discard`: the checkpoint of a stopped job the operator will not resume, removed once
    /// confirmed; not while a job runs (it is that job's).
    fn discard_checkpoint(&mut self, confirm: bool) -> Result<String, Refusal> {
        self.refuse_if_busy()?;
        let Some(current) = &self.checkpoints.current else {
            return Err(Refusal::NothingToDiscard);
        };
        if !confirm {
            return Err(Refusal::DiscardUnconfirmed {
                program: current.program.display().to_string(),
                line: current.line,
            });
        }
        let path = self.config.daemon.checkpoint.clone();
        let gone = self
            .checkpoints
            .discard(&path)
            .map_err(|e| Refusal::BadArgument(format!("{}: {e}", path.display())))?
            .expect("a current checkpoint");
        let kept = self
            .checkpoints
            .current
            .as_ref()
            .map(|c| {
                format!(
                    "; the checkpoint of {} (line {}) is the checkpoint again",
                    c.program.display(),
                    c.line
                )
            })
            .unwrap_or_default();
        self.notify_status();
        Ok(format!(
            "checkpoint of {} (line {}) discarded{kept}",
            gone.program.display(),
            gone.line
        ))
    }

    /// Between jobs the fine thread reads the claimed device's inputs every millisecond and
    /// latches what it saw ([`crate::runtime::Claimed`]); the desk's trips judge it
    /// ([`desk::trips::watch`]). Called every round of the loop and before any command.
    pub(super) fn watch_inputs(&mut self) {
        if self.jobs.job.is_some() || !self.jobs.fine.has_claim() {
            return;
        }
        let seen = self.jobs.fine.idle_watch().take();
        if desk::trips::watch(&mut self.machine, seen) {
            self.latch_stopped_jog();
        }
    }

    /// `jog-continuous`: towards the soft limit (or the longest jog) while renewed (the
    /// desk's [`Pendant`](desk::pendant::Pendant)). Another axis or direction while one moves
    /// is refused.
    fn jog_continuous(
        &mut self,
        axis: &str,
        positive: bool,
        feed: Option<f64>,
    ) -> Result<String, Refusal> {
        let (i, letter) = self.desk().axis(axis)?;
        let stopped_in_job = self.jobs.job.as_ref().is_some_and(|job| {
            matches!(job.kind, JobKind::Jog { .. })
                && (job.published.hold.load(Ordering::Relaxed)
                    || job.published.dead_man_tripped.load(Ordering::Relaxed))
        });
        let now = crate::sys::monotonic_ns();
        let stopped = || {
            Refusal::BadArgument(format!(
                "jog {letter}{} was stopped (a hold, its dead-man, a trip or its end): renewals \
                 are refused; let go and start it again",
                sign(positive)
            ))
        };
        match self.jobs.pendant.press(i, positive, now, stopped_in_job) {
            Press::Latched => return Err(stopped()),
            Press::StoppedInJob => {
                self.stop_continuous("held: a renewal does not move it again", true);
                return Err(stopped());
            }
            Press::Renewed { deadline_ns } => {
                if let Some(job) = &self.jobs.job {
                    job.published
                        .dead_man_ns
                        .store(deadline_ns, Ordering::Release);
                }
                return Ok(format!("jog {letter}{}: renewed", sign(positive)));
            }
            Press::Busy { axis, positive } => {
                return Err(Refusal::BadArgument(format!(
                    "a continuous jog of {}{} is moving: stop it first",
                    self.config.machine.axes[axis],
                    sign(positive)
                )));
            }
            Press::New => {}
        }
        self.refuse_if_busy()?;
        let order = desk::manual::continuous(self.desk(), i, letter, positive, feed)?;
        let reply = self.launch(order);
        self.jobs
            .pendant
            .started(i, positive, crate::sys::monotonic_ns());
        Ok(reply)
    }

    /// `jog-stop`: the continuous jog brakes to a standstill now.
    fn jog_stop(&mut self) -> Result<String, Refusal> {
        match self.jobs.pendant.let_go() {
            LetGo::Stop => {
                self.stop_continuous("stopped", false);
                Ok("jog: braking to a standstill".into())
            }
            LetGo::AlreadyStopped => Ok("jog: already stopped".into()),
            LetGo::Nothing => Err(Refusal::BadArgument("no continuous jog is moving".into())),
        }
    }
}
