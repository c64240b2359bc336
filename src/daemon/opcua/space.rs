//! The address space: a machine tool laid out after OPC 40501 (MachineTool), filled from the
//! daemon's status.
//!
//! ```text
//! Objects/Machines/edmd                              (events: holds, shorts, alarms)
//!   Identification   Manufacturer, Model, ProductInstanceUri, SoftwareRevision
//!   Monitoring
//!     MachineTool    State, Holds, Alarms
//!     Channel        ServoState, Feed (mm/min), FeedOverride (%), RapidOverride (%)
//!     EDMGenerator   GapState, Shorts, TurnBacks
//!     Axes/<X>       ActualPosition (machine, mm), WorkPosition (mm), Homed
//!   Production
//!     ActiveProgram  Name, State, Line, Progress (0 to 1), RemainingTime (s)
//!     LastJob        Name, Outcome
//!     Hold(), Abort()                                (a signed-in user only)
//!   Notification     (events: holds, shorts, alarms)
//! ```
//!
//! The browse names and the layout are the companion specification's; the nodes are plain
//! objects and variables of edmd's own namespace ([`NAMESPACE`]), not instances of its types
//! (edmd does not load the MachineTool nodeset). Every variable is read-only.

use opcua::server::address_space::{
    AddressSpace, EventNotifier, MethodBuilder, ObjectBuilder, ObjectTypeBuilder, VariableBuilder,
};
use opcua::types::{DataTypeId, NodeId, ObjectTypeId, QualifiedName, VariableTypeId, Variant};

use crate::daemon::protocol::Status;

/// edmd's namespace.
pub const NAMESPACE: &str = "urn:edmd:machine-tool";

/// What the Identification object says.
pub struct Identity {
    pub manufacturer: String,
    pub model: String,
    pub product_instance_uri: String,
    pub software_revision: String,
}

/// How a variable's value comes out of the status.
enum Read {
    Whole(ReadWhole),
    Axis(usize, ReadAxis),
}

struct Slot {
    id: NodeId,
    read: Read,
}

/// The event types edmd raises, each a subtype of `BaseEventType`.
pub struct EventTypes {
    pub hold: NodeId,
    pub short: NodeId,
    pub alarm: NodeId,
}

/// The nodes the server fills and calls.
pub struct Space {
    /// The machine: the source of every event.
    pub machine: NodeId,
    /// Where events are raised besides the machine (and the Server object).
    pub notification: NodeId,
    pub hold: NodeId,
    pub abort: NodeId,
    pub events: EventTypes,
    slots: Vec<Slot>,
}

fn text(s: &str) -> Variant {
    Variant::from(s)
}

fn job_text(status: &Status, f: fn(&crate::daemon::protocol::JobStatus) -> String) -> Variant {
    Variant::from(status.job.as_ref().map(f).unwrap_or_default())
}

/// A set point of the condition in force (0 without one).
fn set_point(status: &Status, f: fn(&crate::vocab::GeneratorSetPoints) -> f64) -> Variant {
    let set = status.job.as_ref().and_then(|j| j.generator.as_ref());
    Variant::from(set.map_or(0.0, f))
}

/// A figure of the job's process; empty without one.
fn process(
    status: &Status,
    f: fn(&crate::daemon::protocol::ProcessStatus) -> Option<f64>,
) -> Variant {
    status
        .job
        .as_ref()
        .and_then(|j| j.process.as_ref())
        .and_then(f)
        .map_or(Variant::Empty, Variant::from)
}

/// How a machine-wide variable is read from the status.
type ReadWhole = fn(&Status) -> Variant;
/// How an axis's variable is read from the status, given the axis's index.
type ReadAxis = fn(&Status, usize) -> Variant;

/// The variables under each object: (object path, browse name, data type, how to read).
const WHOLE: &[(&str, &str, DataTypeId, ReadWhole)] = &[
    ("Monitoring/MachineTool", "State", DataTypeId::String, |s| {
        text(s.state.name())
    }),
    ("Monitoring/MachineTool", "Holds", DataTypeId::UInt64, |s| {
        Variant::from(s.counters.holds)
    }),
    (
        "Monitoring/MachineTool",
        "Alarms",
        DataTypeId::UInt64,
        |s| Variant::from(s.counters.servo.alarms),
    ),
    (
        "Monitoring/Channel",
        "ServoState",
        DataTypeId::String,
        |s| job_text(s, |j| j.servo.name().to_string()),
    ),
    ("Monitoring/Channel", "Feed", DataTypeId::Double, |s| {
        Variant::from(s.job.as_ref().map_or(0.0, |j| j.feed_mm_per_min))
    }),
    (
        "Monitoring/Channel",
        "FeedOverride",
        DataTypeId::Double,
        |s| Variant::from(f64::from(s.overrides.feed_pct)),
    ),
    (
        "Monitoring/Channel",
        "RapidOverride",
        DataTypeId::Double,
        |s| Variant::from(f64::from(s.overrides.rapid_pct)),
    ),
    (
        "Monitoring/EDMGenerator",
        "GapState",
        DataTypeId::String,
        |s| {
            job_text(s, |j| {
                j.gap.map(|g| g.name().to_string()).unwrap_or_default()
            })
        },
    ),
    // What is cutting now: the move in hand's condition (0: none), wire offset (mm, + G41,
    // − G42, 0: none) and the gap voltage the input measures (empty where it measures none).
    (
        "Monitoring/EDMGenerator",
        "Condition",
        DataTypeId::UInt64,
        |s| Variant::from(s.job.as_ref().and_then(|j| j.condition).unwrap_or(0)),
    ),
    (
        "Monitoring/EDMGenerator",
        "WireOffset",
        DataTypeId::Double,
        |s| {
            let offset = s.job.as_ref().and_then(|j| j.wire_offset.as_ref());
            Variant::from(offset.map_or(0.0, |w| if w.side == "G42" { -w.mm } else { w.mm }))
        },
    ),
    (
        "Monitoring/EDMGenerator",
        "GapVoltage",
        DataTypeId::Double,
        |s| {
            s.job
                .as_ref()
                .and_then(|j| j.gap_volts)
                .map_or(Variant::Empty, Variant::from)
        },
    ),
    // The process as the pulses tell it (empty without a counting gap input).
    (
        "Monitoring/EDMGenerator",
        "IgnitionDelay",
        DataTypeId::Double,
        |s| process(s, |p| p.mean_ignition_delay_us),
    ),
    (
        "Monitoring/EDMGenerator",
        "NormalPulseRate",
        DataTypeId::Double,
        |s| process(s, |p| Some(p.rates_hz.normal)),
    ),
    (
        "Monitoring/EDMGenerator",
        "ArcPulseRate",
        DataTypeId::Double,
        |s| process(s, |p| Some(p.rates_hz.arc)),
    ),
    (
        "Monitoring/EDMGenerator",
        "ShortPulseRate",
        DataTypeId::Double,
        |s| process(s, |p| Some(p.rates_hz.short)),
    ),
    (
        "Monitoring/EDMGenerator",
        "OpenPulseRate",
        DataTypeId::Double,
        |s| process(s, |p| Some(p.rates_hz.open)),
    ),
    (
        "Monitoring/EDMGenerator",
        "HeightEstimate",
        DataTypeId::Double,
        |s| process(s, |p| p.height_estimate_mm),
    ),
    (
        "Monitoring/EDMGenerator",
        "CutRate",
        DataTypeId::Double,
        |s| process(s, |p| p.cut_rate_mm2_per_min),
    ),
    // The condition's set points (0: not given, or no condition in force; the off time the
    // one in force, adapted or not).
    (
        "Monitoring/EDMGenerator",
        "OnTime",
        DataTypeId::Double,
        |s| set_point(s, |g| g.on_time_us),
    ),
    (
        "Monitoring/EDMGenerator",
        "OffTime",
        DataTypeId::Double,
        |s| set_point(s, |g| g.off_time_us),
    ),
    (
        "Monitoring/EDMGenerator",
        "PeakCurrent",
        DataTypeId::Double,
        |s| set_point(s, |g| g.peak_current_a),
    ),
    (
        "Monitoring/EDMGenerator",
        "ServoReferenceVoltage",
        DataTypeId::Double,
        |s| set_point(s, |g| g.servo_ref_v),
    ),
    (
        "Monitoring/EDMGenerator",
        "Shorts",
        DataTypeId::UInt64,
        |s| Variant::from(s.counters.servo.shorts),
    ),
    (
        "Monitoring/EDMGenerator",
        "TurnBacks",
        DataTypeId::UInt64,
        |s| Variant::from(s.counters.servo.turn_backs),
    ),
    (
        "Production/ActiveProgram",
        "Name",
        DataTypeId::String,
        |s| job_text(s, |j| j.program.clone()),
    ),
    (
        "Production/ActiveProgram",
        "State",
        DataTypeId::String,
        |s| text(if s.job.is_some() { s.state.name() } else { "" }),
    ),
    (
        "Production/ActiveProgram",
        "Line",
        DataTypeId::UInt64,
        |s| Variant::from(s.job.as_ref().map_or(0, |j| j.line)),
    ),
    // The pass of the technology table being cut, and how many (0: not in passes).
    (
        "Production/ActiveProgram",
        "Pass",
        DataTypeId::UInt64,
        |s| Variant::from(s.job.as_ref().and_then(|j| j.pass).unwrap_or(0)),
    ),
    (
        "Production/ActiveProgram",
        "Passes",
        DataTypeId::UInt64,
        |s| Variant::from(s.job.as_ref().map_or(0, |j| j.passes as u64)),
    ),
    // The technology it cuts with (empty: none).
    (
        "Production/ActiveProgram",
        "Technology",
        DataTypeId::String,
        |s| job_text(s, |j| j.technology.clone().unwrap_or_default()),
    ),
    (
        "Production/ActiveProgram",
        "Progress",
        DataTypeId::Double,
        |s| Variant::from(s.job.as_ref().map_or(0.0, |j| j.progress)),
    ),
    (
        "Production/ActiveProgram",
        "RemainingTime",
        DataTypeId::Double,
        |s| {
            s.job
                .as_ref()
                .and_then(|j| j.eta_s)
                .map_or(Variant::Empty, Variant::from)
        },
    ),
    ("Production/LastJob", "Name", DataTypeId::String, |s| {
        text(s.last_job.as_ref().map_or("", |j| j.program.as_str()))
    }),
    ("Production/LastJob", "Outcome", DataTypeId::String, |s| {
        text(s.last_job.as_ref().map_or("", |j| j.outcome.name()))
    }),
];

/// Each axis's variables: (browse name, data type, how to read).
const PER_AXIS: &[(&str, DataTypeId, ReadAxis)] = &[
    ("ActualPosition", DataTypeId::Double, |s, i| {
        Variant::from(s.machine.position_machine_mm.get(i).copied().unwrap_or(0.0))
    }),
    ("WorkPosition", DataTypeId::Double, |s, i| {
        Variant::from(s.machine.position_work_mm.get(i).copied().unwrap_or(0.0))
    }),
    ("Homed", DataTypeId::Boolean, |s, i| {
        Variant::from(s.machine.homed.get(i).copied().unwrap_or(false))
    }),
];

/// The node of `path` below the machine.
pub fn node(ns: u16, path: &str) -> NodeId {
    if path.is_empty() {
        NodeId::new(ns, "edmd")
    } else {
        NodeId::new(ns, format!("edmd/{path}"))
    }
}

/// Adds the object `path` (its parent: everything before the last `/`) as a component.
pub(super) fn object(space: &mut AddressSpace, ns: u16, path: &str, notifier: bool) -> NodeId {
    let id = node(ns, path);
    let (parent, name) = path.rsplit_once('/').unwrap_or(("", path));
    let mut builder = ObjectBuilder::new(&id, QualifiedName::new(ns, name), name)
        .has_type_definition(ObjectTypeId::BaseObjectType)
        .component_of(node(ns, parent));
    if notifier {
        builder = builder.event_notifier(EventNotifier::SUBSCRIBE_TO_EVENTS);
    }
    builder.insert(space);
    id
}

pub(super) fn variable(
    space: &mut AddressSpace,
    id: &NodeId,
    name: &str,
    kind: DataTypeId,
    parent: &NodeId,
) {
    VariableBuilder::new(id, QualifiedName::new(id.namespace, name), name)
        .data_type(kind)
        .value(Variant::Empty)
        .has_type_definition(VariableTypeId::BaseDataVariableType)
        .component_of(parent.clone())
        .insert(space);
}

fn property(space: &mut AddressSpace, ns: u16, parent: &str, name: &str, value: &str) {
    VariableBuilder::new(
        &node(ns, &format!("{parent}/{name}")),
        QualifiedName::new(ns, name),
        name,
    )
    .data_type(DataTypeId::String)
    .value(value)
    .has_type_definition(VariableTypeId::PropertyType)
    .property_of(node(ns, parent))
    .insert(space);
}

fn event_type(space: &mut AddressSpace, ns: u16, name: &str) -> NodeId {
    let id = NodeId::new(ns, name);
    ObjectTypeBuilder::new(&id, QualifiedName::new(ns, name), name)
        .is_abstract(false)
        .subtype_of(ObjectTypeId::BaseEventType)
        .insert(space);
    id
}

fn method(space: &mut AddressSpace, ns: u16, name: &str) -> NodeId {
    let id = node(ns, &format!("Production/{name}"));
    MethodBuilder::new(&id, QualifiedName::new(ns, name), name)
        .component_of(node(ns, "Production"))
        .executable(true)
        .user_executable(true)
        .output_args(
            space,
            &node(ns, &format!("Production/{name}/OutputArguments")),
            &[("Message", DataTypeId::String).into()],
        )
        .insert(space);
    id
}

impl Space {
    /// Adds the machine's nodes to `space` in namespace `ns`.
    pub fn build(space: &mut AddressSpace, ns: u16, axes: &[String], identity: &Identity) -> Space {
        let machines = NodeId::new(ns, "Machines");
        space.add_folder(
            &machines,
            QualifiedName::new(ns, "Machines"),
            "Machines",
            &NodeId::objects_folder_id(),
        );
        let machine = node(ns, "");
        ObjectBuilder::new(&machine, QualifiedName::new(ns, "edmd"), "edmd")
            .has_type_definition(ObjectTypeId::BaseObjectType)
            .event_notifier(EventNotifier::SUBSCRIBE_TO_EVENTS)
            .organized_by(machines)
            .insert(space);
        object(space, ns, "Identification", false);
        for (name, value) in [
            ("Manufacturer", &identity.manufacturer),
            ("Model", &identity.model),
            ("ProductInstanceUri", &identity.product_instance_uri),
            ("SoftwareRevision", &identity.software_revision),
        ] {
            property(space, ns, "Identification", name, value);
        }
        for path in [
            "Monitoring",
            "Monitoring/MachineTool",
            "Monitoring/Channel",
            "Monitoring/EDMGenerator",
            "Monitoring/Axes",
            "Production",
            "Production/ActiveProgram",
            "Production/LastJob",
        ] {
            object(space, ns, path, false);
        }
        let notification = object(space, ns, "Notification", true);
        let mut slots = Vec::new();
        for (parent, name, kind, read) in WHOLE {
            let id = node(ns, &format!("{parent}/{name}"));
            variable(space, &id, name, *kind, &node(ns, parent));
            slots.push(Slot {
                id,
                read: Read::Whole(*read),
            });
        }
        for (i, axis) in axes.iter().enumerate() {
            let parent = object(space, ns, &format!("Monitoring/Axes/{axis}"), false);
            for (name, kind, read) in PER_AXIS {
                let id = node(ns, &format!("Monitoring/Axes/{axis}/{name}"));
                variable(space, &id, name, *kind, &parent);
                slots.push(Slot {
                    id,
                    read: Read::Axis(i, *read),
                });
            }
        }
        let events = EventTypes {
            hold: event_type(space, ns, "EdmHoldEventType"),
            short: event_type(space, ns, "EdmShortEventType"),
            alarm: event_type(space, ns, "EdmAlarmEventType"),
        };
        Space {
            hold: method(space, ns, "Hold"),
            abort: method(space, ns, "Abort"),
            machine,
            notification,
            events,
            slots,
        }
    }

    /// Every variable's value in `status`.
    pub fn values<'a>(&'a self, status: &'a Status) -> impl Iterator<Item = (&'a NodeId, Variant)> {
        self.slots.iter().map(move |slot| {
            let value = match &slot.read {
                Read::Whole(read) => read(status),
                Read::Axis(i, read) => read(status, *i),
            };
            (&slot.id, value)
        })
    }
}
