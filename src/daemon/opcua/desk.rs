//! The job methods' handlers: each reads its arguments, checks the order against the list
//! ([`jobs::JobOrders`]) and asks the control loop, which decides as it does for any client
//! (a start is a `run`, a pause a `hold`). The server calls them on one of its workers; each
//! waits for the loop's answers, which come in microseconds (a start waits for the work
//! system's MDI line to finish too).

use std::path::{Component, Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use opcua::types::{StatusCode, Variant};
use parking_lot::Mutex;

use super::jobs::{self, Answer, JobOrder, JobOrders};
use super::{CORE_TIMEOUT, ask_blocking};
use crate::daemon::link::CoreLink;
use crate::daemon::protocol::{DaemonState, Request};

/// The work systems an order may select.
const WORK_SYSTEMS: &[&str] = &[
    "G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3",
];

/// What the job methods share.
#[derive(Clone)]
pub struct Desk {
    pub orders: Arc<Mutex<JobOrders>>,
    pub to_core: CoreLink,
    /// `daemon.program_dir`, as the last reload left it.
    pub program_dir: Arc<parking_lot::RwLock<PathBuf>>,
}

fn text(args: &[Variant], i: usize) -> Result<String, StatusCode> {
    match args.get(i) {
        Some(Variant::String(s)) => Ok(s.as_ref().to_string()),
        _ => Err(StatusCode::BadInvalidArgument),
    }
}

fn count(args: &[Variant], i: usize) -> Result<u64, StatusCode> {
    match args.get(i) {
        Some(Variant::UInt32(n)) => Ok(u64::from(*n)),
        Some(Variant::UInt64(n)) => Ok(*n),
        Some(Variant::Int32(n)) if *n >= 0 => Ok(*n as u64),
        Some(Variant::Int64(n)) if *n >= 0 => Ok(*n as u64),
        _ => Err(StatusCode::BadInvalidArgument),
    }
}

fn optional(s: String) -> Option<String> {
    let s = s.trim().to_string();
    (!s.is_empty()).then_some(s)
}

impl Desk {
    fn ask(&self, request: Request) -> Result<crate::daemon::protocol::Reply, Answer> {
        ask_blocking(&self.to_core, request)
            .map_err(|_| Answer::refused(jobs::NOT_NOW, "the daemon does not answer"))
    }

    /// A program name inside `program_dir` that exists.
    fn program(&self, name: &str) -> Result<(), Answer> {
        let plain = Path::new(name)
            .components()
            .all(|c| matches!(c, Component::Normal(_)));
        if name.is_empty() || !plain {
            return Err(Answer::refused(
                jobs::INVALID,
                format!("{name:?} is not a program name in daemon.program_dir"),
            ));
        }
        let dir = self.program_dir.read().clone();
        if !dir.join(name).is_file() {
            return Err(Answer::refused(
                jobs::INVALID,
                format!("no program {name:?} in {}", dir.display()),
            ));
        }
        Ok(())
    }

    /// The order Store's arguments describe, checked.
    fn order(&self, args: &[Variant]) -> Result<Result<JobOrder, Answer>, StatusCode> {
        let id = text(args, 0)?;
        let program = text(args, 1)?;
        let passes = count(args, 2)?;
        let technology = optional(text(args, 3)?);
        let work_system = optional(text(args, 4)?);
        if let Err(refused) = self.program(&program) {
            return Ok(Err(refused));
        }
        if let Some(ws) = &work_system
            && !WORK_SYSTEMS.contains(&ws.as_str())
        {
            return Ok(Err(Answer::refused(
                jobs::INVALID,
                format!("{ws:?} is not a work system (G54 … G59.3)"),
            )));
        }
        if let Some(request) = &technology {
            match self.ask(Request::Technology {
                request: Some(request.clone()),
            }) {
                Ok(reply) if !reply.ok => {
                    return Ok(Err(Answer::refused(
                        jobs::INVALID,
                        reply.error.unwrap_or_default(),
                    )));
                }
                Ok(_) => {}
                Err(refused) => return Ok(Err(refused)),
            }
        }
        Ok(Ok(JobOrder::new(
            id,
            program,
            (passes > 0).then_some(passes as usize),
            technology,
            work_system,
        )))
    }

    /// Store, or StoreAndStart when `start`.
    pub fn store(&self, args: &[Variant], start: bool) -> Result<Vec<Variant>, StatusCode> {
        let answer = match self.order(args)? {
            Err(refused) => refused,
            Ok(order) => {
                let id = order.id.clone();
                let stored = self.orders.lock().store(order);
                if start && stored.code == jobs::OK {
                    self.start_order(&id)
                } else {
                    stored
                }
            }
        };
        Ok(self.said("Store", answer))
    }

    pub fn start(&self, args: &[Variant]) -> Result<Vec<Variant>, StatusCode> {
        let id = text(args, 0)?;
        let answer = self.start_order(&id);
        Ok(self.said("Start", answer))
    }

    /// Selects the order's work system (an MDI line), then runs its program. An Abort that
    /// comes meanwhile stops it before its run is asked for; once asked (under the orders'
    /// lock, with the order marked running), an Abort goes to the machine.
    fn start_order(&self, id: &str) -> Answer {
        let order = match self.orders.lock().begin_start(id) {
            Ok(order) => order,
            Err(refused) => return refused,
        };
        let answer = self.start_marked(id, &order);
        if answer.code != jobs::OK {
            self.orders.lock().start_failed(id);
        }
        answer
    }

    fn start_marked(&self, id: &str, order: &JobOrder) -> Answer {
        let status = match self.ask(Request::Status {}).map(|r| r.status) {
            Ok(Some(status)) => status,
            Ok(None) => return Answer::refused(jobs::NOT_NOW, "no status"),
            Err(refused) => return refused,
        };
        if status.state != DaemonState::Idle {
            return Answer::refused(
                jobs::NOT_NOW,
                format!("the machine is {}", status.state.name()),
            );
        }
        if let Some(ws) = &order.work_system {
            match self.ask(Request::Mdi { line: ws.clone() }) {
                Ok(reply) if reply.ok => {}
                Ok(reply) => {
                    return Answer::refused(jobs::NOT_NOW, reply.error.unwrap_or_default());
                }
                Err(refused) => return refused,
            }
            if let Err(refused) = self.wait_idle() {
                return refused;
            }
        }
        // The run is asked for with the orders locked: an Abort sees the order either still
        // starting (and it then never runs) or running (and the machine aborts it).
        let mut orders = self.orders.lock();
        if orders.aborted_while_starting(id) {
            return Answer::refused(
                jobs::NOT_NOW,
                format!("job order {id:?} was aborted while it started: it did not run"),
            );
        }
        match self.ask(order.run_request()) {
            Ok(reply) if reply.ok => {
                orders.started_now(id, status.counters.jobs);
                Answer::ok(format!(
                    "job order {id:?} started: {}",
                    reply.message.unwrap_or_default()
                ))
            }
            Ok(reply) => Answer::refused(jobs::NOT_NOW, reply.error.unwrap_or_default()),
            Err(refused) => refused,
        }
    }

    /// Waits for the machine to be idle again (after the work system's MDI line).
    fn wait_idle(&self) -> Result<(), Answer> {
        let deadline = std::time::Instant::now() + CORE_TIMEOUT;
        loop {
            let status = self.ask(Request::Status {})?.status;
            if status.is_some_and(|s| s.state == DaemonState::Idle && s.job.is_none()) {
                return Ok(());
            }
            if std::time::Instant::now() > deadline {
                return Err(Answer::refused(
                    jobs::NOT_NOW,
                    "the work system's MDI line did not finish",
                ));
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Pause (a hold), Resume or Abort of the started order `args[0]`; Abort of a stored one
    /// just marks it.
    pub fn machine(
        &self,
        args: &[Variant],
        what: &'static str,
        request: Request,
    ) -> Result<Vec<Variant>, StatusCode> {
        let id = text(args, 0)?;
        let started = self.orders.lock().running(&id).map(|_| ());
        let answer = match started {
            Err(_) if what == "Abort" => self.orders.lock().abort_stored(&id),
            Err(refused) => refused,
            Ok(()) => match self.ask(request) {
                Ok(reply) if reply.ok => Answer::ok(format!(
                    "job order {id:?}: {}",
                    reply.message.unwrap_or_default()
                )),
                Ok(reply) => Answer::refused(jobs::NOT_NOW, reply.error.unwrap_or_default()),
                Err(refused) => refused,
            },
        };
        Ok(self.said(what, answer))
    }

    pub fn clear(&self, args: &[Variant]) -> Result<Vec<Variant>, StatusCode> {
        let id = text(args, 0)?;
        let answer = self.orders.lock().clear(&id);
        Ok(self.said("Clear", answer))
    }

    pub fn result(&self, args: &[Variant]) -> Result<Vec<Variant>, StatusCode> {
        let id = text(args, 0)?;
        let orders = self.orders.lock();
        Ok(jobs::result_variants(orders.get(&id), &id))
    }

    /// Logs what a method answered; its outputs.
    fn said(&self, what: &str, answer: Answer) -> Vec<Variant> {
        if answer.code == jobs::OK {
            tracing::info!("opcua: {what}: {}", answer.message);
        } else {
            tracing::info!(
                "opcua: {what} refused ({}): {}",
                answer.code,
                answer.message
            );
        }
        answer.variants()
    }
}
