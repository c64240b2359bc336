//! Job management after OPC 40001-3 (Machinery Job Management, which OPC 40501-1 v1.02
//! references for machine tools): an MES stores job orders on the machine, starts, pauses
//! and aborts them, lists them with their states, and reads each one's result.
//!
//! ```text
//! Objects/Machines/edmd/JobManagement
//!   JobOrderControl
//!     Store(JobOrderID, Program, Passes, Technology, WorkSystem)   → ReturnStatus, Message
//!     StoreAndStart(…the same…), Start(JobOrderID), Pause(JobOrderID) (= hold),
//!     Resume(JobOrderID), Abort(JobOrderID), Clear(JobOrderID)      (a signed-in user only)
//!     JobOrderIDs, JobOrderStates, JobOrderPrograms                 String[], one per order
//!   JobOrderResults
//!     RequestJobResponseByJobOrderID(JobOrderID) → ReturnStatus, JobState, Outcome,
//!         MachineTime (s), Started, Ended, Passes, Shorts, Error
//! ```
//!
//! **States** are ISA-95's job order states as 40001-3 names them: `AllowedToStart` once
//! stored, `Running`, `Interrupted` (held or paused), `Ended` (the program ran to its end)
//! and `Aborted` (stopped, refused or failed). An order's result is its line of the job
//! history ([`crate::daemon::history`]), read when the order ends.
//!
//! **What it simplifies.** The orders are plain arguments and string arrays of edmd's
//! namespace, not the specification's ISA95JobOrderDataType structures (edmd does not load
//! the nodesets, as with 40501); `ReturnStatus` is 0 for success, 1 for an unknown order, 2
//! for an invalid request and 3 for a request its order's or the machine's state does not
//! allow, with `Message` saying why. Orders live as long as the daemon: a restart forgets
//! them (the job history keeps what ran).

use opcua::server::address_space::{AddressSpace, MethodBuilder};
use opcua::types::{DataTypeId, NodeId, QualifiedName, Variant};

use super::space::{node, object, variable};
use crate::daemon::history::JobRecord;
use crate::daemon::protocol::{DaemonState, Request, Status};

/// A job order's state, as OPC 40001-3 names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OrderState {
    AllowedToStart,
    Running,
    Interrupted,
    Ended,
    Aborted,
}

impl OrderState {
    pub fn name(self) -> &'static str {
        match self {
            OrderState::AllowedToStart => "AllowedToStart",
            OrderState::Running => "Running",
            OrderState::Interrupted => "Interrupted",
            OrderState::Ended => "Ended",
            OrderState::Aborted => "Aborted",
        }
    }

    fn started(self) -> bool {
        matches!(self, OrderState::Running | OrderState::Interrupted)
    }
}

/// What a job method answers: `ReturnStatus` and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Answer {
    pub code: u64,
    pub message: String,
}

pub const OK: u64 = 0;
pub const UNKNOWN_ORDER: u64 = 1;
pub const INVALID: u64 = 2;
pub const NOT_NOW: u64 = 3;

impl Answer {
    pub fn ok(message: impl Into<String>) -> Answer {
        Answer {
            code: OK,
            message: message.into(),
        }
    }

    pub fn refused(code: u64, message: impl Into<String>) -> Answer {
        Answer {
            code,
            message: message.into(),
        }
    }

    pub fn variants(&self) -> Vec<Variant> {
        vec![
            Variant::from(self.code),
            Variant::from(self.message.as_str()),
        ]
    }
}

/// One stored job: what to cut and how, and how far it got.
#[derive(Debug, Clone)]
pub struct JobOrder {
    pub id: String,
    /// A program of `daemon.program_dir`, by its name there.
    pub program: String,
    pub passes: Option<usize>,
    pub technology: Option<String>,
    /// `G54` … `G59.3` selected before it starts; `None`: the one in force.
    pub work_system: Option<String>,
    pub state: OrderState,
    /// The daemon's count of jobs started when this one was asked to start.
    jobs_before: u64,
    /// Its line of the job history, once it ended.
    pub result: Option<JobRecord>,
    /// Why it was aborted before it ran (a refused check).
    pub error: Option<String>,
    /// A Start is on its way (its work system, then its run): another Start is refused, and
    /// an Abort meanwhile cancels it before it runs ([`JobOrders::abort_stored`]).
    starting: bool,
    /// An Abort came while it was starting: the start does not run it.
    abort_asked: bool,
}

impl JobOrder {
    pub fn new(
        id: String,
        program: String,
        passes: Option<usize>,
        technology: Option<String>,
        work_system: Option<String>,
    ) -> JobOrder {
        JobOrder {
            id,
            program,
            passes,
            technology,
            work_system,
            state: OrderState::AllowedToStart,
            jobs_before: 0,
            result: None,
            error: None,
            starting: false,
            abort_asked: false,
        }
    }

    /// The run request that starts it.
    pub fn run_request(&self) -> Request {
        Request::Run {
            program: self.program.clone(),
            dry_run: false,
            from_line: None,
            approach: None,
            wire_at: None,
            pass: None,
            passes: self.passes,
            tab_mm: None,
            technology: self.technology.clone(),
            force: false,
        }
    }

    /// Whether the daemon's job or check of `path` is this order's program.
    fn is_program(&self, path: &str) -> bool {
        std::path::Path::new(path).ends_with(&self.program)
    }
}

/// The orders, in the order they were stored.
#[derive(Debug, Default)]
pub struct JobOrders {
    orders: Vec<JobOrder>,
}

impl JobOrders {
    pub fn get(&self, id: &str) -> Option<&JobOrder> {
        self.orders.iter().find(|o| o.id == id)
    }

    pub fn store(&mut self, order: JobOrder) -> Answer {
        if order.id.trim().is_empty() {
            return Answer::refused(INVALID, "a job order needs a JobOrderID");
        }
        if self.get(&order.id).is_some() {
            return Answer::refused(INVALID, format!("job order {:?} exists", order.id));
        }
        let message = format!("job order {:?} stored: {}", order.id, order.program);
        self.orders.push(order);
        Answer::ok(message)
    }

    /// Begins the start of `id`: stored, not started or starting, and no other order started
    /// or starting. The order is marked starting (and a copy handed back) until
    /// [`started_now`](Self::started_now) or [`start_failed`](Self::start_failed).
    pub fn begin_start(&mut self, id: &str) -> Result<JobOrder, Answer> {
        let order = self
            .get(id)
            .ok_or_else(|| Answer::refused(UNKNOWN_ORDER, format!("no job order {id:?}")))?;
        if order.state != OrderState::AllowedToStart || order.starting {
            return Err(Answer::refused(
                NOT_NOW,
                format!(
                    "job order {id:?} is {}",
                    if order.starting {
                        "starting"
                    } else {
                        order.state.name()
                    }
                ),
            ));
        }
        if let Some(other) = self.orders.iter().find(|o| o.state.started() || o.starting) {
            return Err(Answer::refused(
                NOT_NOW,
                format!("job order {:?} is {}", other.id, other.state.name()),
            ));
        }
        let order = self.orders.iter_mut().find(|o| o.id == id).expect("found");
        order.starting = true;
        order.abort_asked = false;
        Ok(order.clone())
    }

    /// An Abort came while `id` was starting: it is aborted now, and its start does not run
    /// it (`true`), the start having not yet asked for the run.
    pub fn aborted_while_starting(&mut self, id: &str) -> bool {
        match self.orders.iter_mut().find(|o| o.id == id) {
            Some(o) if o.starting && o.abort_asked => {
                o.starting = false;
                o.state = OrderState::Aborted;
                true
            }
            _ => false,
        }
    }

    /// The start of `id` did not run it (refused, or the machine busy): it may start again,
    /// unless an Abort came meanwhile.
    pub fn start_failed(&mut self, id: &str) {
        if let Some(o) = self.orders.iter_mut().find(|o| o.id == id) {
            o.starting = false;
            if o.abort_asked {
                o.state = OrderState::Aborted;
            }
        }
    }

    /// `id` was started with the daemon's job count at `jobs_before`.
    pub fn started_now(&mut self, id: &str, jobs_before: u64) {
        if let Some(o) = self.orders.iter_mut().find(|o| o.id == id) {
            o.state = OrderState::Running;
            o.starting = false;
            o.jobs_before = jobs_before;
        }
    }

    /// The started order `id`, for Pause, Resume and Abort.
    pub fn running(&self, id: &str) -> Result<&JobOrder, Answer> {
        let order = self
            .get(id)
            .ok_or_else(|| Answer::refused(UNKNOWN_ORDER, format!("no job order {id:?}")))?;
        if order.state.started() {
            Ok(order)
        } else {
            Err(Answer::refused(
                NOT_NOW,
                format!("job order {id:?} is {}", order.state.name()),
            ))
        }
    }

    /// Aborts an order that has not started (a started one is aborted through the machine).
    /// One whose Start is on its way is aborted by that Start, which has not asked for its
    /// run yet (the run is asked for under the same lock that marks it running): it never
    /// runs.
    pub fn abort_stored(&mut self, id: &str) -> Answer {
        match self.orders.iter_mut().find(|o| o.id == id) {
            None => Answer::refused(UNKNOWN_ORDER, format!("no job order {id:?}")),
            Some(o) if o.starting => {
                o.abort_asked = true;
                Answer::ok(format!(
                    "job order {id:?} aborted while it was starting: it does not run"
                ))
            }
            Some(o) if o.state == OrderState::AllowedToStart => {
                o.state = OrderState::Aborted;
                Answer::ok(format!("job order {id:?} aborted before it started"))
            }
            Some(o) => Answer::refused(NOT_NOW, format!("job order {id:?} is {}", o.state.name())),
        }
    }

    /// Removes an order that ended or was aborted.
    pub fn clear(&mut self, id: &str) -> Answer {
        match self.orders.iter().position(|o| o.id == id) {
            None => Answer::refused(UNKNOWN_ORDER, format!("no job order {id:?}")),
            Some(i)
                if matches!(
                    self.orders[i].state,
                    OrderState::Ended | OrderState::Aborted
                ) =>
            {
                self.orders.remove(i);
                Answer::ok(format!("job order {id:?} cleared"))
            }
            Some(i) => Answer::refused(
                NOT_NOW,
                format!("job order {id:?} is {}", self.orders[i].state.name()),
            ),
        }
    }

    /// Follows the machine: the started order runs, is interrupted, or ended (its id is
    /// returned, for its history line to be read).
    pub fn observe(&mut self, status: &Status) -> Option<String> {
        let order = self.orders.iter_mut().find(|o| o.state.started())?;
        if let Some(job) = &status.job {
            if order.is_program(&job.program) {
                order.state = match status.state {
                    DaemonState::Holding
                    | DaemonState::Held
                    | DaemonState::Paused
                    | DaemonState::WireBreak
                    | DaemonState::Rethreading
                    | DaemonState::Threading => OrderState::Interrupted,
                    _ => OrderState::Running,
                };
            }
            return None;
        }
        if status.state == DaemonState::Checking {
            return None;
        }
        if status.counters.jobs > order.jobs_before {
            // Its job ran and ended.
            let done = status
                .last_job
                .as_ref()
                .is_some_and(|j| order.is_program(&j.program) && j.outcome.name() == "done");
            order.state = if done {
                OrderState::Ended
            } else {
                OrderState::Aborted
            };
            return Some(order.id.clone());
        }
        if let Some(check) = status.check.as_ref().filter(|c| c.phase == "refused")
            && order.is_program(&check.program)
        {
            order.state = OrderState::Aborted;
            order.error = check.error.clone();
        }
        None
    }

    /// The history line of the order `id` that ended: the newest of `records` for its
    /// program.
    pub fn attach_result(&mut self, id: &str, records: &[JobRecord]) {
        if let Some(o) = self.orders.iter_mut().find(|o| o.id == id) {
            o.result = records
                .iter()
                .rev()
                .find(|r| o.is_program(&r.program))
                .cloned();
        }
    }

    fn column(&self, f: impl Fn(&JobOrder) -> String) -> Variant {
        Variant::from(self.orders.iter().map(f).collect::<Vec<String>>())
    }
}

/// The job management nodes.
pub struct JobNodes {
    pub store: NodeId,
    pub store_and_start: NodeId,
    pub start: NodeId,
    pub pause: NodeId,
    pub resume: NodeId,
    pub abort: NodeId,
    pub clear: NodeId,
    pub result: NodeId,
    ids: NodeId,
    states: NodeId,
    programs: NodeId,
}

const CONTROL: &str = "JobManagement/JobOrderControl";
const RESULTS: &str = "JobManagement/JobOrderResults";

/// The arguments of Store and StoreAndStart.
const STORE_ARGS: &[(&str, DataTypeId)] = &[
    ("JobOrderID", DataTypeId::String),
    ("Program", DataTypeId::String),
    ("Passes", DataTypeId::UInt32),
    ("Technology", DataTypeId::String),
    ("WorkSystem", DataTypeId::String),
];

const RESULT_OUT: &[(&str, DataTypeId)] = &[
    ("ReturnStatus", DataTypeId::UInt64),
    ("JobState", DataTypeId::String),
    ("Outcome", DataTypeId::String),
    ("MachineTime", DataTypeId::Double),
    ("Started", DataTypeId::String),
    ("Ended", DataTypeId::String),
    ("Passes", DataTypeId::UInt32),
    ("Shorts", DataTypeId::UInt64),
    ("Error", DataTypeId::String),
];

fn job_method(
    space: &mut AddressSpace,
    ns: u16,
    parent: &str,
    name: &str,
    inputs: &[(&str, DataTypeId)],
    outputs: &[(&str, DataTypeId)],
) -> NodeId {
    let id = node(ns, &format!("{parent}/{name}"));
    let args = |list: &[(&str, DataTypeId)]| -> Vec<opcua::types::Argument> {
        list.iter().map(|(n, t)| (*n, *t).into()).collect()
    };
    MethodBuilder::new(&id, QualifiedName::new(ns, name), name)
        .component_of(node(ns, parent))
        .executable(true)
        .user_executable(true)
        .input_args(
            space,
            &node(ns, &format!("{parent}/{name}/InputArguments")),
            &args(inputs),
        )
        .output_args(
            space,
            &node(ns, &format!("{parent}/{name}/OutputArguments")),
            &args(outputs),
        )
        .insert(space);
    id
}

impl JobNodes {
    pub fn build(space: &mut AddressSpace, ns: u16) -> JobNodes {
        for path in ["JobManagement", CONTROL, RESULTS] {
            object(space, ns, path, false);
        }
        let answer = &[
            ("ReturnStatus", DataTypeId::UInt64),
            ("Message", DataTypeId::String),
        ];
        let id_only = &[("JobOrderID", DataTypeId::String)];
        let list = |space: &mut AddressSpace, name: &str| {
            let id = node(ns, &format!("{CONTROL}/{name}"));
            variable(space, &id, name, DataTypeId::String, &node(ns, CONTROL));
            id
        };
        JobNodes {
            store: job_method(space, ns, CONTROL, "Store", STORE_ARGS, answer),
            store_and_start: job_method(space, ns, CONTROL, "StoreAndStart", STORE_ARGS, answer),
            start: job_method(space, ns, CONTROL, "Start", id_only, answer),
            pause: job_method(space, ns, CONTROL, "Pause", id_only, answer),
            resume: job_method(space, ns, CONTROL, "Resume", id_only, answer),
            abort: job_method(space, ns, CONTROL, "Abort", id_only, answer),
            clear: job_method(space, ns, CONTROL, "Clear", id_only, answer),
            result: job_method(
                space,
                ns,
                RESULTS,
                "RequestJobResponseByJobOrderID",
                id_only,
                RESULT_OUT,
            ),
            ids: list(space, "JobOrderIDs"),
            states: list(space, "JobOrderStates"),
            programs: list(space, "JobOrderPrograms"),
        }
    }

    /// The methods only a signed-in user may call.
    pub fn guarded(&self) -> Vec<NodeId> {
        vec![
            self.store.clone(),
            self.store_and_start.clone(),
            self.start.clone(),
            self.pause.clone(),
            self.resume.clone(),
            self.abort.clone(),
            self.clear.clone(),
        ]
    }

    /// The job list's variables.
    pub fn values(&self, orders: &JobOrders) -> [(NodeId, Variant); 3] {
        [
            (self.ids.clone(), orders.column(|o| o.id.clone())),
            (
                self.states.clone(),
                orders.column(|o| o.state.name().to_string()),
            ),
            (self.programs.clone(), orders.column(|o| o.program.clone())),
        ]
    }
}

/// RequestJobResponseByJobOrderID's outputs for `order` (`None`: no order `id`).
pub fn result_variants(order: Option<&JobOrder>, id: &str) -> Vec<Variant> {
    let Some(order) = order else {
        return vec![
            Variant::from(UNKNOWN_ORDER),
            Variant::from(""),
            Variant::from(""),
            Variant::from(0.0),
            Variant::from(""),
            Variant::from(""),
            Variant::from(0u32),
            Variant::from(0u64),
            Variant::from(format!("no job order {id:?}")),
        ];
    };
    let r = order.result.as_ref();
    vec![
        Variant::from(OK),
        Variant::from(order.state.name()),
        Variant::from(r.map_or("", |r| r.outcome.as_str())),
        Variant::from(r.map_or(0.0, |r| r.machine_time_s)),
        Variant::from(r.map_or("", |r| r.started.as_str())),
        Variant::from(r.map_or("", |r| r.ended.as_str())),
        Variant::from(r.map_or(0, |r| r.passes.len() as u32)),
        Variant::from(r.map_or(0, |r| r.shorts)),
        Variant::from(
            r.and_then(|r| r.error.clone())
                .or_else(|| order.error.clone())
                .unwrap_or_default(),
        ),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::daemon::protocol::Status;

    fn order(id: &str) -> JobOrder {
        JobOrder::new(id.into(), "die.ngc".into(), None, None, None)
    }

    #[test]
    fn orders_are_stored_once_and_start_one_at_a_time() {
        let mut orders = JobOrders::default();
        assert_eq!(orders.store(order("A")).code, OK);
        assert_eq!(orders.store(order("A")).code, INVALID);
        assert_eq!(orders.store(order(" ")).code, INVALID);
        assert_eq!(orders.store(order("B")).code, OK);
        assert!(orders.begin_start("A").is_ok());
        assert_eq!(
            orders.begin_start("A").unwrap_err().code,
            NOT_NOW,
            "starting"
        );
        assert_eq!(
            orders.begin_start("B").unwrap_err().code,
            NOT_NOW,
            "A starts"
        );
        assert_eq!(orders.begin_start("Z").unwrap_err().code, UNKNOWN_ORDER);
        orders.started_now("A", 0);
        assert_eq!(orders.begin_start("B").unwrap_err().code, NOT_NOW);
        assert_eq!(orders.begin_start("A").unwrap_err().code, NOT_NOW);
        assert_eq!(orders.clear("A").code, NOT_NOW, "a running order stays");
        assert_eq!(orders.abort_stored("B").code, OK);
        assert_eq!(orders.get("B").unwrap().state, OrderState::Aborted);
        assert_eq!(orders.clear("B").code, OK);
        assert!(orders.get("B").is_none());
    }

    #[test]
    fn an_abort_while_a_start_is_on_its_way_stops_it_before_its_run_and_says_so() {
        let mut orders = JobOrders::default();
        orders.store(order("A"));
        orders.begin_start("A").unwrap();
        // The Abort comes while the start selects the work system.
        let said = orders.abort_stored("A");
        assert_eq!(said.code, OK);
        assert!(said.message.contains("does not run"), "{said:?}");
        // The start, about to ask for the run, finds it aborted: nothing runs.
        assert!(orders.aborted_while_starting("A"));
        assert_eq!(orders.get("A").unwrap().state, OrderState::Aborted);
        assert_eq!(orders.abort_stored("A").code, NOT_NOW, "aborted already");

        // An Abort that comes once the run was asked for finds it running: the machine's.
        orders.store(order("B"));
        orders.begin_start("B").unwrap();
        assert!(!orders.aborted_while_starting("B"));
        orders.started_now("B", 0);
        assert!(orders.running("B").is_ok(), "aborted through the machine");

        // A start that failed after an Abort leaves the order aborted, not startable.
        let mut fresh = JobOrders::default();
        fresh.store(order("C"));
        fresh.begin_start("C").unwrap();
        fresh.abort_stored("C");
        fresh.start_failed("C");
        assert_eq!(fresh.get("C").unwrap().state, OrderState::Aborted);
        fresh.store(order("D"));
        fresh.begin_start("D").unwrap();
        fresh.start_failed("D");
        assert_eq!(fresh.get("D").unwrap().state, OrderState::AllowedToStart);
        assert!(fresh.begin_start("D").is_ok(), "it may start again");
    }

    #[test]
    fn an_order_follows_its_job_to_interrupted_and_ended() {
        let mut orders = JobOrders::default();
        orders.store(order("A"));
        orders.started_now("A", 3);
        let mut status = Status::bare(DaemonState::Checking);
        status.counters.jobs = 3;
        assert_eq!(orders.observe(&status), None);
        assert_eq!(orders.get("A").unwrap().state, OrderState::Running);
        // A job of another program is not this order's.
        status.state = DaemonState::Idle;
        status.counters.jobs = 3;
        assert_eq!(orders.observe(&status), None);
        assert_eq!(orders.get("A").unwrap().state, OrderState::Running);
        let result = serde_json::json!({
            "program": "/srv/programs/die.ngc", "started": "s", "ended": "e",
            "outcome": "done", "machine_time_s": 12.5, "passes": [], "shorts": 2,
            "turn_backs": 2, "wire_breaks": 0, "dry_run": false
        });
        let record: JobRecord = serde_json::from_value(result).unwrap();
        orders.attach_result("A", std::slice::from_ref(&record));
        assert_eq!(orders.get("A").unwrap().result.as_ref(), Some(&record));
    }
}
