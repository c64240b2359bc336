use super::*;
use crate::daemon::protocol::Status;

fn bands() -> Deadbands {
    Deadbands {
        mm: 0.001,
        mm_per_min: 1.0,
        fraction: 0.01,
        s: 5.0,
    }
}

fn sample(status: &Status) -> Sample<'_> {
    Sample {
        status,
        shares: [0.0; 3],
        dropped: 0,
        answer: "",
        commands: false,
    }
}

fn decode(bytes: &[u8]) -> Payload {
    Payload::decode(bytes).unwrap()
}

/// The metric of `payload` named `name` (by name, or by the alias `node` gave it).
fn metric<'a>(node: &EdgeNode, payload: &'a Payload, name: &str) -> Option<&'a Metric> {
    let alias = node
        .defs
        .iter()
        .position(|d| d.name == name)
        .map(|i| i as u64 + 1);
    payload
        .metrics
        .iter()
        .find(|m| m.name.as_deref() == Some(name) || (m.name.is_none() && m.alias == alias))
}

#[test]
fn birth_names_types_and_aliases_every_metric_with_seq_0_and_the_bd_seq() {
    let mut status = Status::bare(DaemonState::Idle);
    status.machine.position_machine_mm = vec![1.5, -2.0];
    let mut node = EdgeNode::new(&["X".into(), "Y".into()], bands());
    let birth = decode(&node.birth(&sample(&status), 7));
    assert_eq!(birth.seq, Some(0));
    assert_eq!(birth.timestamp, Some(7));
    let bd = &birth.metrics[0];
    assert_eq!(bd.name.as_deref(), Some("bdSeq"));
    assert_eq!(bd.value, Some(metric::Value::LongValue(0)));
    // Every metric but bdSeq has a name, an alias and a type.
    for m in &birth.metrics[1..] {
        assert!(
            m.name.is_some() && m.alias.is_some() && m.datatype.is_some(),
            "{m:?}"
        );
    }
    let x = metric(&node, &birth, "Axes/X/Machine Position").unwrap();
    assert_eq!(x.value, Some(metric::Value::DoubleValue(1.5)));
    assert_eq!(x.datatype, Some(DataType::Double as u32));
    let state = metric(&node, &birth, "Machine/State").unwrap();
    assert_eq!(state.value, Some(metric::Value::StringValue("idle".into())));
    let rebirth = metric(&node, &birth, REBIRTH).unwrap();
    assert_eq!(rebirth.value, Some(metric::Value::BooleanValue(false)));
}

#[test]
fn data_sends_only_what_moved_past_its_deadband_by_alias_and_counts_seq() {
    let mut status = Status::bare(DaemonState::Idle);
    status.machine.position_machine_mm = vec![0.0, 0.0];
    let mut node = EdgeNode::new(&["X".into(), "Y".into()], bands());
    assert!(
        node.data(&sample(&status), 1).is_none(),
        "no data before the birth"
    );
    node.birth(&sample(&status), 1);
    assert!(node.data(&sample(&status), 2).is_none(), "nothing moved");
    // Inside the deadband: not sent.
    status.machine.position_machine_mm[0] = 0.0005;
    assert!(node.data(&sample(&status), 3).is_none());
    // Past it: sent, by alias, with seq 1.
    status.machine.position_machine_mm[0] = 0.0015;
    status.state = DaemonState::Running;
    let data = decode(&node.data(&sample(&status), 4).unwrap());
    assert_eq!(data.seq, Some(1));
    assert_eq!(data.metrics.len(), 2, "{:?}", data.metrics);
    assert!(
        data.metrics
            .iter()
            .all(|m| m.name.is_none() && m.alias.is_some())
    );
    let x = metric(&node, &data, "Axes/X/Machine Position").unwrap();
    assert_eq!(x.value, Some(metric::Value::DoubleValue(0.0015)));
    // The deadband is measured from what was sent, so a slow creep is sent once it adds up.
    status.machine.position_machine_mm[0] = 0.0022;
    assert!(node.data(&sample(&status), 5).is_none());
    status.machine.position_machine_mm[0] = 0.0026;
    assert_eq!(
        decode(&node.data(&sample(&status), 6).unwrap()).seq,
        Some(2)
    );
    // Back to zero is told exactly.
    status.machine.position_machine_mm[0] = 0.0;
    let back = decode(&node.data(&sample(&status), 7).unwrap());
    let x = metric(&node, &back, "Axes/X/Machine Position").unwrap();
    assert_eq!(x.value, Some(metric::Value::DoubleValue(0.0)));
}

#[test]
fn seq_wraps_at_256_and_a_birth_starts_it_again() {
    let mut status = Status::bare(DaemonState::Idle);
    let mut node = EdgeNode::new(&[], bands());
    node.birth(&sample(&status), 0);
    let mut last = 0;
    for n in 1..=300u64 {
        status.counters.holds = n;
        last = decode(&node.data(&sample(&status), n).unwrap())
            .seq
            .unwrap();
        assert_eq!(last, n % 256);
    }
    assert_eq!(last, 300 % 256);
    assert_eq!(decode(&node.birth(&sample(&status), 0)).seq, Some(0));
    status.counters.holds = 1000;
    assert_eq!(
        decode(&node.data(&sample(&status), 1).unwrap()).seq,
        Some(1)
    );
}

#[test]
fn death_and_the_birth_of_a_session_carry_its_bd_seq() {
    let status = Status::bare(DaemonState::Idle);
    let mut node = EdgeNode::new(&[], bands());
    for session in 0..260u64 {
        node.set_session(session % 256);
        let death = decode(&death(node.bd_seq(), 1));
        let birth = decode(&node.birth(&sample(&status), 2));
        assert_eq!(death.seq, None, "NDEATH has no seq");
        assert_eq!(death.metrics.len(), 1);
        assert_eq!(death.metrics[0].value, birth.metrics[0].value);
        assert_eq!(
            death.metrics[0].value,
            Some(metric::Value::LongValue(session % 256))
        );
    }
}

#[test]
fn gap_shares_are_over_the_last_sample() {
    let mut status = Status::bare(DaemonState::Running);
    let mut node = EdgeNode::new(&[], bands());
    status.counters.gap_ticks = [100, 100, 0];
    assert_eq!(node.shares(&status), [0.0; 3], "no window yet");
    status.counters.gap_ticks = [160, 120, 20];
    assert_eq!(node.shares(&status), [0.6, 0.2, 0.2]);
    assert_eq!(node.shares(&status), [0.0; 3], "nothing read since");
}

fn ncmd(metrics: Vec<Metric>) -> Vec<u8> {
    Payload {
        timestamp: Some(1),
        metrics,
        seq: None,
        uuid: None,
        body: None,
    }
    .encode_to_vec()
}

fn written(name: Option<&str>, alias: Option<u64>, value: metric::Value) -> Metric {
    let mut m = Metric::new();
    m.name = name.map(str::to_string);
    m.alias = alias;
    m.datatype = Some(DataType::Boolean as u32);
    m.value = Some(value);
    m
}

#[test]
fn commands_are_read_by_name_or_alias_and_anything_else_is_refused() {
    let node = EdgeNode::new(&["X".into()], bands());
    let yes = metric::Value::BooleanValue(true);
    let asked = node
        .commands(&ncmd(vec![
            written(Some(REBIRTH), None, yes.clone()),
            written(None, Some(2), yes.clone()),
            written(Some(ABORT), None, metric::Value::BooleanValue(false)),
        ]))
        .unwrap();
    assert_eq!(asked, vec![Command::Rebirth, Command::Hold]);
    let refused = node
        .commands(&ncmd(vec![written(
            Some("Machine/State"),
            None,
            yes.clone(),
        )]))
        .unwrap_err();
    assert!(refused.contains("cannot be written"), "{refused}");
    let refused = node
        .commands(&ncmd(vec![written(
            Some(HOLD),
            None,
            metric::Value::StringValue("yes".into()),
        )]))
        .unwrap_err();
    assert!(refused.contains("Boolean"), "{refused}");
    assert!(
        node.commands(&ncmd(vec![written(None, Some(999), yes)]))
            .is_err()
    );
    assert!(node.commands(b"\xff\xff\xff").is_err());
}

#[test]
fn topics_follow_the_namespace() {
    let t = Topics::new("plant-1", "edm-7");
    assert_eq!(t.nbirth, "spBv1.0/plant-1/NBIRTH/edm-7");
    assert_eq!(t.ndata, "spBv1.0/plant-1/NDATA/edm-7");
    assert_eq!(t.ndeath, "spBv1.0/plant-1/NDEATH/edm-7");
    assert_eq!(t.ncmd, "spBv1.0/plant-1/NCMD/edm-7");
}
