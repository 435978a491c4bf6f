//! The edge node without IO, on explicit time and without a broker: every Publish is decoded
//! with the Sparkplug payload types (or as JSON in plain mode) and checked against the rules
//! of Sparkplug B 3.0 and of the plain topics.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::{Duration, SystemTime};

use ferrobus_bridge::config::{
    Broker, Connection, DeviceSpec, LineMode, LineSpec, Mode, PlainConfig, Plant, SparkplugConfig,
};
use ferrobus_bridge::edge::{Action, DeviceRef, Edge, EdgeError, MAX_METRICS_PER_COMMAND, Output, Publish};
use ferrobus_bridge::sparkplug::convert::UintEncoding;
use ferrobus_bridge::sparkplug::payload::{DataType, Metric, MetricValue, Payload, PropertyValueKind};
use ferrobus_bridge::sparkplug::topic::HostState;
use ferrobus_bridge::store::StoreConfig;
use ferrobus_profile::{Profile, Value};
use ferrobus_tools::poll::{Failure, FailureKind, Group, Layout, Reading, Sample, Table, Traffic};

const DRIVE: DeviceRef = DeviceRef { line: 0, device: 0 };
const METER: DeviceRef = DeviceRef { line: 1, device: 0 };

// ---------------------------------------------------------------------------------------------
// The plant: a 3G3RX (F001 set frequency, d001 output frequency with a 0.5 Hz deadband, the
// running coil) on one line, a meter with two raw registers on another.
// ---------------------------------------------------------------------------------------------

/// The 3G3RX profile, loaded once for all tests.
fn rx() -> Arc<Profile> {
    static RX: std::sync::OnceLock<Arc<Profile>> = std::sync::OnceLock::new();
    Arc::clone(RX.get_or_init(|| Arc::new(Profile::load("omron-3g3rx").unwrap())))
}

fn drive() -> DeviceSpec {
    let rx = rx();
    let names: Vec<String> = ["F001", "d001", "running"].iter().map(|s| (*s).to_string()).collect();
    let groups = Group::points(&rx, 1, &names, &[], Duration::from_secs(1)).unwrap();
    let deadbands =
        groups.iter().map(|g| g.cells.iter().map(|c| if c.name == "d001" { 0.5 } else { 0.0 }).collect()).collect();
    DeviceSpec { id: "drive1".into(), unit: 1, profile: Some(rx), groups, deadbands, death_after: 3 }
}

fn meter() -> DeviceSpec {
    let layout = Layout { aliases: vec![(0, "temperature".into())], ..Layout::default() };
    let group = Group::raw(
        "meter",
        ferrobus_tools::poll::RawRange { unit: 2, table: Table::Holding, count: 2, ..Default::default() },
        &layout,
    )
    .unwrap();
    DeviceSpec {
        id: "meter".into(),
        unit: 2,
        profile: None,
        deadbands: vec![vec![2.0, 0.0]],
        groups: vec![group],
        death_after: 2,
    }
}

fn plant(mode: Mode) -> Plant {
    let line = |name: &str, device: DeviceSpec| LineSpec {
        name: name.into(),
        connection: Connection::Tcp("127.0.0.1:502".into()),
        client: ferrobus::ClientConfig::default(),
        mode: LineMode::Poll,
        devices: vec![device],
    };
    Plant {
        origin: "test.toml".into(),
        broker: Broker {
            host: "127.0.0.1".into(),
            port: 1883,
            client_id: "test".into(),
            username: None,
            password: None,
            tls: None,
            keep_alive: Duration::from_secs(30),
            reconnect: Duration::from_secs(1),
        },
        mode,
        store: StoreConfig::default(),
        lines: vec![line("rs485", drive()), line("tcp", meter())],
    }
}

fn sparkplug_config(primary_host: Option<&str>) -> SparkplugConfig {
    SparkplugConfig {
        group_id: "plant".into(),
        edge_node_id: "edge1".into(),
        primary_host: primary_host.map(str::to_string),
        uint_encoding: UintEncoding::Spec,
    }
}

fn sparkplug_plant() -> Plant {
    plant(Mode::Sparkplug(sparkplug_config(None)))
}

/// `(group, cell)` of a metric.
fn locate(plant: &Plant, at: DeviceRef, name: &str) -> (usize, usize) {
    let device = &plant.lines[at.line].devices[at.device];
    for (g, group) in device.groups.iter().enumerate() {
        if let Some(c) = group.cells.iter().position(|c| c.name == name) {
            return (g, c);
        }
    }
    panic!("no metric {name}");
}

fn t(ms: u64) -> SystemTime {
    SystemTime::UNIX_EPOCH + Duration::from_millis(1_764_633_600_000 + ms)
}

fn ms(time: SystemTime) -> u64 {
    u64::try_from(time.duration_since(SystemTime::UNIX_EPOCH).unwrap().as_millis()).unwrap()
}

fn answered(group: usize, time: SystemTime, values: Vec<Value>) -> Sample {
    let result = Ok(values
        .into_iter()
        .enumerate()
        .map(|(cell, raw)| Reading { cell, raw: Ok(raw), scaled: None, shown: String::new() })
        .collect());
    sample(group, time, result)
}

fn failed(group: usize, time: SystemTime, kind: FailureKind) -> Sample {
    let exception = (kind == FailureKind::Exception).then_some(2);
    let diagnosis = match kind {
        FailureKind::Exception => "exception 0x02 (illegal data address)".to_string(),
        _ => "no reply within 100 ms".to_string(),
    };
    sample(group, time, Err(Failure { kind, exception, diagnosis }))
}

fn sample(group: usize, time: SystemTime, result: Result<Vec<Reading>, Failure>) -> Sample {
    Sample {
        group,
        seq: 0,
        time,
        due: Duration::ZERO,
        started: Duration::ZERO,
        response_time: Duration::from_millis(10),
        overrun: false,
        result,
        traffic: Traffic::default(),
    }
}

/// Polls every group of the drive once with these values by name (others 0 / false).
fn poll_drive(edge: &mut Edge, plant: &Plant, time: SystemTime, values: &[(&str, Value)]) -> Vec<Output> {
    let device = &plant.lines[0].devices[0];
    let mut out = Vec::new();
    for (g, group) in device.groups.iter().enumerate() {
        let raws = group
            .cells
            .iter()
            .map(|c| {
                values.iter().find(|(n, _)| *n == c.name).map_or_else(
                    || if c.name == "running" { Value::Bool(false) } else { Value::Int(0) },
                    |(_, v)| v.clone(),
                )
            })
            .collect();
        out.extend(edge.sample(DRIVE, g, &answered(g, time, raws)));
    }
    out
}

fn publishes(outputs: Vec<Output>) -> Vec<Publish> {
    outputs
        .into_iter()
        .map(|o| match o {
            Output::Publish(p) => p,
            Output::Store(_) => panic!("a record while online"),
        })
        .collect()
}

fn records(outputs: Vec<Output>) -> Vec<Vec<u8>> {
    outputs
        .into_iter()
        .map(|o| match o {
            Output::Store(r) => r,
            Output::Publish(p) => panic!("a publish while offline: {}", p.topic),
        })
        .collect()
}

fn decode(p: &Publish) -> Payload {
    Payload::decode(&p.payload).unwrap_or_else(|e| panic!("{}: {e}", p.topic))
}

fn kind(p: &Publish) -> &str {
    p.topic.split('/').nth(2).unwrap()
}

fn metric<'a>(payload: &'a Payload, name: &str) -> &'a Metric {
    payload.metrics.iter().find(|m| m.name.as_deref() == Some(name)).unwrap_or_else(|| panic!("no {name}"))
}

fn property<'a>(m: &'a Metric, key: &str) -> Option<&'a PropertyValueKind> {
    let set = m.properties.as_ref()?;
    let i = set.keys.iter().position(|k| k == key)?;
    set.values[i].value.as_ref()
}

fn bd_seq_of(p: &Publish) -> u64 {
    match metric(&decode(p), "bdSeq").value {
        Some(MetricValue::Long(n)) => n,
        ref other => panic!("bdSeq {other:?}"),
    }
}

/// An online edge with the drive born with every group read (polled before the connection,
/// F001 60.00 Hz, d001 59.90 Hz at t(100)): the edge and the DBIRTH's payload.
fn online_with_drive(plant: &Plant) -> (Edge, Payload) {
    let mut edge = Edge::new(plant);
    records(poll_drive(&mut edge, plant, t(100), &[("F001", Value::Int(6000)), ("d001", Value::Int(5990))]));
    let births = edge.connected(t(200));
    assert_eq!(births.iter().map(kind).collect::<Vec<_>>(), ["NBIRTH", "DBIRTH"]);
    let dbirth = decode(&births[1]);
    (edge, dbirth)
}

/// The alias → name map of a DBIRTH.
fn aliases(dbirth: &Payload) -> HashMap<u64, String> {
    dbirth.metrics.iter().map(|m| (m.alias.unwrap(), m.name.clone().unwrap())).collect()
}

fn dcmd(metrics: Vec<Metric>) -> Vec<u8> {
    Payload { timestamp: Some(ms(t(0))), metrics, ..Payload::default() }.encode()
}

// ---------------------------------------------------------------------------------------------
// Session: NBIRTH, bdSeq, seq.
// ---------------------------------------------------------------------------------------------

#[test]
fn the_will_is_an_ndeath_with_only_bdseq_no_seq_qos1_not_retained() {
    let edge = Edge::new(&sparkplug_plant());
    let will = edge.will().unwrap();
    assert_eq!(will.topic, "spBv1.0/plant/NDEATH/edge1");
    assert_eq!((will.qos, will.retain), (1, false));
    let payload = decode(&will);
    assert_eq!(payload.seq, None);
    assert_eq!(payload.metrics.len(), 1);
    let bd = &payload.metrics[0];
    assert_eq!(bd.name.as_deref(), Some("bdSeq"));
    assert_eq!(bd.datatype, Some(DataType::Int64.number()));
}

#[test]
fn nbirth_comes_first_with_seq_0_the_wills_bdseq_and_a_writable_rebirth_false() {
    let mut edge = Edge::new(&sparkplug_plant());
    edge.set_bd_seq(7);
    let will = edge.will().unwrap();
    let out = edge.connected(t(0));
    let nbirth = &out[0];
    assert_eq!(nbirth.topic, "spBv1.0/plant/NBIRTH/edge1");
    assert_eq!((nbirth.qos, nbirth.retain), (0, false));
    let payload = decode(nbirth);
    assert_eq!(payload.seq, Some(0));
    assert_eq!(payload.timestamp, Some(ms(t(0))));
    assert_eq!(bd_seq_of(nbirth), 7);
    assert_eq!(bd_seq_of(&will), 7);
    let rebirth = metric(&payload, "Node Control/Rebirth");
    assert_eq!(rebirth.datatype, Some(DataType::Boolean.number()));
    assert_eq!(rebirth.value, Some(MetricValue::Boolean(false)));
    assert_eq!(property(rebirth, "readOnly"), Some(&PropertyValueKind::Boolean(false)));
    let software = metric(&payload, "Properties/Software");
    assert!(matches!(&software.value, Some(MetricValue::String(s)) if s.starts_with("ferrobus ")));
}

#[test]
fn every_session_takes_the_next_bdseq_and_255_wraps_to_0() {
    let mut edge = Edge::new(&sparkplug_plant());
    edge.set_bd_seq(254);
    edge.connected(t(0));
    edge.disconnected();
    assert_eq!(edge.bd_seq(), 255);
    assert_eq!(bd_seq_of(&edge.will().unwrap()), 255);
    let nbirth = edge.connected(t(1)).remove(0);
    assert_eq!(bd_seq_of(&nbirth), 255);
    edge.disconnected();
    assert_eq!(edge.bd_seq(), 0);
    assert_eq!(bd_seq_of(&edge.connected(t(2))[0]), 0);
}

#[test]
fn shutdown_publishes_the_ndeath_of_the_current_bdseq_and_then_nothing() {
    let plant = sparkplug_plant();
    let (mut edge, _) = online_with_drive(&plant);
    let ndeath = edge.shutdown(t(500)).unwrap();
    assert_eq!(ndeath.topic, "spBv1.0/plant/NDEATH/edge1");
    assert_eq!(bd_seq_of(&ndeath), u64::from(edge.bd_seq()));
    assert_eq!(decode(&ndeath).seq, None);
    let out = poll_drive(&mut edge, &plant, t(600), &[("F001", Value::Int(100))]);
    assert!(out.iter().all(|o| matches!(o, Output::Store(_))), "after NDEATH, data is stored");
}

#[test]
fn seq_counts_every_message_and_wraps_after_256() {
    let plant = sparkplug_plant();
    let (mut edge, dbirth) = online_with_drive(&plant);
    assert_eq!(dbirth.seq, Some(1), "NBIRTH 0, DBIRTH 1");
    let (g, _) = locate(&plant, DRIVE, "F001");
    let mut seqs = Vec::new();
    for i in 0..300_u32 {
        let raw = Value::Int(i128::from(i % 2) * 100 + 1000);
        let out = publishes(edge.sample(DRIVE, g, &answered(g, t(1000 + u64::from(i)), vec![raw])));
        assert_eq!(out.len(), 1, "poll {i}: one DDATA");
        seqs.push(decode(&out[0]).seq.unwrap());
    }
    let expected: Vec<u64> = (2..302).map(|n| n % 256).collect();
    assert_eq!(seqs, expected);
    assert_eq!(seqs[253..256], [255, 0, 1]);
}

// ---------------------------------------------------------------------------------------------
// Births, aliases, data by exception.
// ---------------------------------------------------------------------------------------------

#[test]
fn dbirth_names_types_and_aliases_every_metric_with_unit_description_and_access() {
    let plant = sparkplug_plant();
    let (_, dbirth) = online_with_drive(&plant);
    let f001 = metric(&dbirth, "F001");
    assert_eq!(f001.datatype, Some(DataType::Double.number()), "scaled: engineering value");
    assert_eq!(f001.value, Some(MetricValue::Double(60.0)));
    assert_eq!(f001.timestamp, Some(ms(t(100))));
    assert_eq!(property(f001, "engUnit"), Some(&PropertyValueKind::String("Hz".into())));
    assert_eq!(property(f001, "description"), Some(&PropertyValueKind::String("output frequency setting".into())));
    assert_eq!(property(f001, "readOnly"), Some(&PropertyValueKind::Boolean(false)));
    let d001 = metric(&dbirth, "d001");
    assert_eq!(property(d001, "readOnly"), Some(&PropertyValueKind::Boolean(true)));
    let running = metric(&dbirth, "running");
    assert_eq!(running.datatype, Some(DataType::Boolean.number()));
    assert_eq!(running.value, Some(MetricValue::Boolean(false)));
    assert!(dbirth.metrics.iter().all(|m| m.alias.is_some()));
}

#[test]
fn a_device_born_before_all_its_groups_answered_has_those_metrics_null() {
    let plant = sparkplug_plant();
    let mut edge = Edge::new(&plant);
    edge.connected(t(0));
    let (g, _) = locate(&plant, DRIVE, "F001");
    let out = publishes(edge.sample(DRIVE, g, &answered(g, t(10), vec![Value::Int(6000)])));
    let dbirth = decode(&out[0]);
    assert_eq!(metric(&dbirth, "F001").value, Some(MetricValue::Double(60.0)));
    let d001 = metric(&dbirth, "d001");
    assert_eq!((d001.is_null, &d001.value), (Some(true), &None));
    assert_eq!(d001.timestamp, Some(ms(t(10))), "an unread metric is stamped with the birth");
}

#[test]
fn aliases_are_unique_in_the_node_and_the_same_for_the_same_plant() {
    let plant = sparkplug_plant();
    let birth_all = |edge: &mut Edge| {
        edge.connected(t(0));
        let mut births = publishes(poll_drive(edge, &plant, t(1), &[]));
        births.extend(publishes(edge.sample(METER, 0, &answered(0, t(2), vec![Value::Int(1), Value::Int(2)]))));
        births
            .iter()
            .filter(|p| kind(p) == "DBIRTH")
            .flat_map(|p| decode(p).metrics)
            .map(|m| (m.name, m.alias))
            .collect::<Vec<_>>()
    };
    let first = birth_all(&mut Edge::new(&plant));
    let second = birth_all(&mut Edge::new(&plant));
    assert_eq!(first, second);
    let mut all: Vec<u64> = first.iter().map(|(_, a)| a.unwrap()).collect();
    assert_eq!(all.len(), 5, "F001, d001, running, temperature, 0x0001");
    all.sort_unstable();
    all.dedup();
    assert_eq!(all.len(), 5, "unique across devices");
}

#[test]
fn ddata_carries_only_aliases_of_the_dbirth_with_the_samples_time_and_no_datatype() {
    let plant = sparkplug_plant();
    let (mut edge, dbirth) = online_with_drive(&plant);
    let names = aliases(&dbirth);
    let out = publishes(poll_drive(
        &mut edge,
        &plant,
        t(2000),
        &[("F001", Value::Int(4500)), ("d001", Value::Int(5990)), ("running", Value::Bool(true))],
    ));
    assert_eq!(out.len(), 2, "F001's and running's groups changed; d001 did not");
    for p in &out {
        assert_eq!(p.topic, "spBv1.0/plant/DDATA/edge1/drive1");
        assert_eq!((p.qos, p.retain), (0, false));
        let payload = decode(p);
        assert_eq!(payload.timestamp, Some(ms(t(2000))));
        for m in &payload.metrics {
            assert_eq!((m.name.as_ref(), m.datatype), (None, None));
            assert!(names.contains_key(&m.alias.unwrap()), "alias {:?} resolves", m.alias);
            assert_eq!(m.timestamp, Some(ms(t(2000))));
        }
    }
    let values: Vec<(String, Option<MetricValue>)> =
        out.iter().flat_map(|p| decode(p).metrics).map(|m| (names[&m.alias.unwrap()].clone(), m.value)).collect();
    assert!(values.contains(&("F001".into(), Some(MetricValue::Double(45.0)))));
    assert!(values.contains(&("running".into(), Some(MetricValue::Boolean(true)))));
}

#[test]
fn deadband_edges_exactly_the_band_is_held_beyond_it_is_sent_from_the_last_published() {
    let plant = sparkplug_plant();
    let (mut edge, dbirth) = online_with_drive(&plant);
    let names = aliases(&dbirth);
    let (g, _) = locate(&plant, DRIVE, "d001");
    let mut poll = |time, raw: i128| {
        let out = publishes(edge.sample(DRIVE, g, &answered(g, t(time), vec![Value::Int(raw)])));
        out.iter().flat_map(decode_metrics).map(|m| (names[&m.alias.unwrap()].clone(), m.value)).collect::<Vec<_>>()
    };
    // Born at 59.90 Hz, deadband 0.5 Hz.
    assert!(poll(1000, 6040).is_empty(), "+0.50 Hz: not beyond");
    assert!(poll(1100, 5940).is_empty(), "−0.50 Hz: not beyond");
    let sent = poll(1200, 6041);
    assert!(
        matches!(sent.as_slice(), [(name, Some(MetricValue::Double(x)))] if name == "d001" && (x - 60.41).abs() < 1e-9),
        "{sent:?}"
    );
    assert!(poll(1300, 5992).is_empty(), "0.49 Hz from the last published 60.41, though 0.02 from the birth");
    assert_eq!(poll(1400, 5990).len(), 1, "0.51 Hz from 60.41");
}

fn decode_metrics(p: &Publish) -> Vec<Metric> {
    decode(p).metrics
}

#[test]
fn an_unchanged_sample_publishes_nothing() {
    let plant = sparkplug_plant();
    let (mut edge, _) = online_with_drive(&plant);
    let out = poll_drive(&mut edge, &plant, t(3000), &[("F001", Value::Int(6000)), ("d001", Value::Int(5990))]);
    assert!(out.is_empty(), "{out:?}");
}

#[test]
fn an_exception_reply_publishes_its_groups_metrics_null_once_and_is_an_answer() {
    let plant = sparkplug_plant();
    let (mut edge, dbirth) = online_with_drive(&plant);
    let names = aliases(&dbirth);
    let (g, _) = locate(&plant, DRIVE, "F001");
    for i in 0..5 {
        let out = publishes(edge.sample(DRIVE, g, &failed(g, t(1000 + i), FailureKind::Exception)));
        if i == 0 {
            assert_eq!(out.len(), 1);
            let m = &decode(&out[0]).metrics[0];
            assert_eq!(names[&m.alias.unwrap()], "F001");
            assert_eq!((m.is_null, &m.value), (Some(true), &None));
        } else {
            assert!(out.is_empty(), "null once, and no DDEATH: poll {i} ({out:?})");
        }
    }
    let out = publishes(edge.sample(DRIVE, g, &answered(g, t(2000), vec![Value::Int(6000)])));
    assert_eq!(decode(&out[0]).metrics[0].value, Some(MetricValue::Double(60.0)), "a value again");
}

// ---------------------------------------------------------------------------------------------
// Deaths.
// ---------------------------------------------------------------------------------------------

#[test]
fn ddeath_after_exactly_death_after_silent_polls_and_dbirth_with_the_known_values_on_return() {
    let plant = sparkplug_plant();
    let (mut edge, _) = online_with_drive(&plant);
    let (g, _) = locate(&plant, DRIVE, "F001");
    let (gd, _) = locate(&plant, DRIVE, "d001");
    assert!(edge.sample(DRIVE, g, &failed(g, t(1000), FailureKind::Timeout)).is_empty());
    assert!(edge.sample(DRIVE, gd, &failed(gd, t(1100), FailureKind::Port)).is_empty(), "any group counts");
    let out = publishes(edge.sample(DRIVE, g, &failed(g, t(1200), FailureKind::Timeout)));
    assert_eq!(out.len(), 1, "the third silent poll: DDEATH");
    assert_eq!(out[0].topic, "spBv1.0/plant/DDEATH/edge1/drive1");
    let ddeath = decode(&out[0]);
    assert_eq!(ddeath.timestamp, Some(ms(t(1200))));
    assert!(ddeath.seq.is_some());
    assert!(edge.sample(DRIVE, g, &failed(g, t(1300), FailureKind::Timeout)).is_empty(), "dead once");
    let out = publishes(edge.sample(DRIVE, gd, &answered(gd, t(1400), vec![Value::Int(3000)])));
    assert_eq!(out.len(), 1);
    assert_eq!(kind(&out[0]), "DBIRTH");
    let dbirth = decode(&out[0]);
    assert_eq!(metric(&dbirth, "d001").value, Some(MetricValue::Double(30.0)));
    assert_eq!(metric(&dbirth, "F001").value, Some(MetricValue::Double(60.0)), "the value known");
    assert_eq!(metric(&dbirth, "F001").timestamp, Some(ms(t(100))), "when it was read");
}

#[test]
fn an_answer_between_silent_polls_restarts_the_count() {
    let plant = sparkplug_plant();
    let (mut edge, _) = online_with_drive(&plant);
    let (g, _) = locate(&plant, DRIVE, "F001");
    for round in 0..3 {
        for i in 0..2 {
            let time = t(1000 + round * 100 + i);
            assert!(edge.sample(DRIVE, g, &failed(g, time, FailureKind::Timeout)).is_empty());
        }
        edge.sample(DRIVE, g, &answered(g, t(1050 + round * 100), vec![Value::Int(6000)]));
    }
    assert_eq!(edge.stats().device_deaths, 0);
}

/// The liveness rule Sparkplug follows (the bridge's one, `edge::Health`): a device that
/// never answered is given up after `death_after` silent polls, with no DDEATH (it was never
/// born), and a reply that does not fit is an answer: its DBIRTH.
#[test]
fn a_device_that_never_answered_is_given_up_without_a_ddeath_and_born_at_its_first_answer() {
    let plant = sparkplug_plant();
    let (mut edge, _) = online_with_drive(&plant);
    for i in 0..4 {
        assert!(edge.sample(METER, 0, &failed(0, t(1000 + i), FailureKind::Timeout)).is_empty(), "silent poll {i}");
    }
    assert_eq!(edge.stats().device_deaths, 0, "never born, never dead");
    let out = publishes(edge.sample(METER, 0, &failed(0, t(2000), FailureKind::BadReply)));
    assert_eq!(out.iter().map(|p| p.topic.as_str()).collect::<Vec<_>>(), ["spBv1.0/plant/DBIRTH/edge1/meter"]);
}

// ---------------------------------------------------------------------------------------------
// Commands.
// ---------------------------------------------------------------------------------------------

#[test]
fn ncmd_rebirth_sends_nbirth_with_seq_0_and_the_same_bdseq_then_the_dbirths() {
    let plant = sparkplug_plant();
    let (mut edge, _) = online_with_drive(&plant);
    let bd = edge.bd_seq();
    let cmd = dcmd(vec![Metric::new("Node Control/Rebirth", DataType::Boolean, Some(MetricValue::Boolean(true)))]);
    let (out, actions, errors) = edge.message("spBv1.0/plant/NCMD/edge1", &cmd, t(5000));
    assert!(actions.is_empty() && errors.is_empty(), "{errors:?}");
    let kinds: Vec<&str> = out.iter().map(kind).collect();
    assert_eq!(kinds, ["NBIRTH", "DBIRTH"], "the meter never answered: no DBIRTH");
    assert_eq!(decode(&out[0]).seq, Some(0));
    assert_eq!(bd_seq_of(&out[0]), u64::from(bd));
    assert_eq!(decode(&out[1]).seq, Some(1));
    assert_eq!(metric(&decode(&out[1]), "F001").value, Some(MetricValue::Double(60.0)));
}

#[test]
fn ncmd_other_than_a_boolean_rebirth_is_refused_and_rebirth_false_does_nothing() {
    let plant = sparkplug_plant();
    let (mut edge, _) = online_with_drive(&plant);
    let ncmd = |edge: &mut Edge, metric: Metric| edge.message("spBv1.0/plant/NCMD/edge1", &dcmd(vec![metric]), t(1));
    let (out, _, errors) =
        ncmd(&mut edge, Metric::new("Node Control/Rebirth", DataType::Boolean, Some(MetricValue::Boolean(false))));
    assert!(out.is_empty() && errors.is_empty());
    let (out, _, errors) =
        ncmd(&mut edge, Metric::new("Node Control/Rebirth", DataType::Int32, Some(MetricValue::Int(1))));
    assert!(out.is_empty());
    assert!(errors[0].to_string().contains("takes a Boolean"), "{}", errors[0]);
    let (out, _, errors) =
        ncmd(&mut edge, Metric::new("Node Control/Reboot", DataType::Boolean, Some(MetricValue::Boolean(true))));
    assert!(out.is_empty());
    assert!(errors[0].to_string().contains("NCMD edge1: Node Control/Reboot"), "{}", errors[0]);
    assert_eq!(edge.stats().rebirths, 0);
}

#[test]
fn dcmd_in_range_becomes_a_write_of_the_raw_value() {
    let plant = sparkplug_plant();
    let (mut edge, dbirth) = online_with_drive(&plant);
    let alias = metric(&dbirth, "F001").alias;
    let by_alias = Metric { alias, value: Some(MetricValue::Double(60.0)), ..Metric::default() };
    let (out, actions, errors) = edge.message("spBv1.0/plant/DCMD/edge1/drive1", &dcmd(vec![by_alias]), t(1));
    assert!(out.is_empty() && errors.is_empty(), "{errors:?}");
    let (g, c) = locate(&plant, DRIVE, "F001");
    match actions.as_slice() {
        [Action::Write { device, group, cell, raw, .. }] => {
            assert_eq!((*device, *group, *cell), (DRIVE, g, c));
            assert_eq!(*raw, Value::Int(6000), "60.00 Hz is raw 6000 (0.01 Hz)");
        }
        other => panic!("{other:?}"),
    }
    let by_name = Metric { value: Some(MetricValue::Double(45.5)), ..Metric::new("F001", DataType::Double, None) };
    let (_, actions, errors) = edge.message("spBv1.0/plant/DCMD/edge1/drive1", &dcmd(vec![by_name]), t(2));
    assert!(errors.is_empty(), "{errors:?}");
    assert!(matches!(&actions[..], [Action::Write { raw: Value::Int(4550), .. }]));
}

#[test]
fn a_dcmd_of_3000_metrics_is_refused_whole_and_one_of_64_is_taken() {
    let plant = sparkplug_plant();
    let (mut edge, _) = online_with_drive(&plant);
    let f001 = |hz: f64| Metric { value: Some(MetricValue::Double(hz)), ..Metric::new("F001", DataType::Double, None) };
    let topic = "spBv1.0/plant/DCMD/edge1/drive1";
    let (out, actions, errors) = edge.message(topic, &dcmd(vec![f001(10.0); 3000]), t(1));
    assert!(out.is_empty() && actions.is_empty(), "nothing is written of a refused command: {actions:?}");
    assert_eq!(errors.len(), 1, "one refusal for the command, not one per metric: {errors:?}");
    let said = errors[0].to_string();
    assert!(said.contains("3000 metrics") && said.contains("at most 64"), "{said}");
    let (_, actions, errors) = edge.message(topic, &dcmd(vec![f001(10.0); MAX_METRICS_PER_COMMAND]), t(2));
    assert!(errors.is_empty(), "{errors:?}");
    assert_eq!(actions.len(), MAX_METRICS_PER_COMMAND);
}

#[test]
fn dcmd_out_of_range_read_only_unknown_or_malformed_is_refused_and_nothing_is_written() {
    let plant = sparkplug_plant();
    let (mut edge, dbirth) = online_with_drive(&plant);
    let alias = |name| metric(&dbirth, name).alias;
    let good = Metric { alias: alias("F001"), value: Some(MetricValue::Double(50.0)), ..Metric::default() };
    let cases: Vec<(Vec<Metric>, &str)> = vec![
        (vec![Metric { alias: alias("F001"), value: Some(MetricValue::Double(500.0)), ..Metric::default() }], "F001"),
        (vec![Metric { alias: alias("d001"), value: Some(MetricValue::Double(10.0)), ..Metric::default() }], "d001"),
        (vec![Metric { alias: Some(999), value: Some(MetricValue::Double(1.0)), ..Metric::default() }], "alias 999"),
        (
            vec![Metric { alias: alias("F001"), value: Some(MetricValue::String("fast".into())), ..Metric::default() }],
            "F001",
        ),
        (vec![Metric { alias: alias("F001"), is_null: Some(true), ..Metric::default() }], "null"),
        // One good metric does not carry a refused one through.
        (vec![good, Metric { alias: Some(999), value: Some(MetricValue::Int(1)), ..Metric::default() }], "999"),
    ];
    for (metrics, seen) in cases {
        let (_, actions, errors) = edge.message("spBv1.0/plant/DCMD/edge1/drive1", &dcmd(metrics), t(1));
        assert!(actions.is_empty(), "{seen}: {actions:?}");
        assert_eq!(errors.len(), 1, "{seen}: {errors:?}");
        let text = errors[0].to_string();
        assert!(text.contains("DCMD drive1") && text.contains(seen), "{seen}: {text}");
    }
    let (_, actions, errors) = edge.message("spBv1.0/plant/DCMD/edge1/drive1", b"\xff\xff\xff", t(1));
    assert!(actions.is_empty());
    assert!(matches!(&errors[..], [EdgeError::Malformed { .. }]), "{errors:?}");
    let (_, actions, errors) = edge.message("spBv1.0/plant/DCMD/edge1/pump9", &dcmd(vec![]), t(1));
    assert!(actions.is_empty());
    assert!(errors[0].to_string().contains("pump9"), "{errors:?}");
    let stats = edge.stats();
    assert_eq!(stats.writes, 0);
    assert!(stats.refused >= 8, "{stats:?}");
}

#[test]
fn the_refusal_says_why_in_the_profiles_words() {
    let plant = sparkplug_plant();
    let (mut edge, dbirth) = online_with_drive(&plant);
    let over =
        Metric { alias: metric(&dbirth, "F001").alias, value: Some(MetricValue::Double(500.0)), ..Metric::default() };
    let (_, _, errors) = edge.message("spBv1.0/plant/DCMD/edge1/drive1", &dcmd(vec![over]), t(1));
    let text = errors[0].to_string();
    assert!(text.contains("500") && text.contains("400"), "{text}");
    let ro =
        Metric { alias: metric(&dbirth, "d001").alias, value: Some(MetricValue::Double(1.0)), ..Metric::default() };
    let (_, _, errors) = edge.message("spBv1.0/plant/DCMD/edge1/drive1", &dcmd(vec![ro]), t(1));
    assert!(errors[0].to_string().contains("read"), "{}", errors[0]);
}

#[test]
fn messages_on_other_topics_are_ignored_and_counted() {
    let mut edge = Edge::new(&sparkplug_plant());
    for topic in ["spBv1.0/other/NCMD/edge1", "spBv1.0/plant/NCMD/edge2", "spBv1.0/plant/DDATA/edge1/drive1", "x/y"] {
        let (out, actions, errors) = edge.message(topic, b"", t(0));
        assert!(out.is_empty() && actions.is_empty() && errors.is_empty(), "{topic}");
    }
    assert_eq!(edge.stats().ignored, 4);
}

#[test]
fn subscriptions_are_ncmd_dcmd_and_the_primary_hosts_state() {
    let edge = Edge::new(&plant(Mode::Sparkplug(sparkplug_config(Some("scada")))));
    let topics: Vec<String> = edge.subscriptions().into_iter().map(|(t, _)| t).collect();
    assert_eq!(topics, ["spBv1.0/plant/NCMD/edge1", "spBv1.0/plant/DCMD/edge1/+", "spBv1.0/STATE/scada"]);
}

// ---------------------------------------------------------------------------------------------
// Primary host STATE.
// ---------------------------------------------------------------------------------------------

#[test]
fn births_wait_for_the_primary_host_online_and_its_offline_asks_for_a_reconnect() {
    let plant = plant(Mode::Sparkplug(sparkplug_config(Some("scada"))));
    let mut edge = Edge::new(&plant);
    assert!(edge.connected(t(0)).is_empty(), "held until the host's STATE");
    assert!(!edge.is_online());
    let stored = records(poll_drive(&mut edge, &plant, t(10), &[("F001", Value::Int(6000))]));
    assert!(!stored.is_empty(), "no births yet: the data is stored");
    let state = |online, ts| HostState { online, timestamp: Some(ts) }.to_json();
    let (out, actions, _) = edge.message("spBv1.0/STATE/scada", &state(true, 100), t(20));
    assert!(actions.is_empty());
    let kinds: Vec<&str> = out.iter().map(kind).collect();
    assert_eq!(kinds, ["NBIRTH", "DBIRTH"]);
    assert!(edge.is_online());
    let (out, actions, _) = edge.message("spBv1.0/STATE/scada", &state(false, 50), t(30));
    assert!(out.is_empty() && actions.is_empty(), "an older STATE is ignored");
    let (_, actions, _) = edge.message("spBv1.0/STATE/scada", &state(false, 200), t(40));
    assert_eq!(actions, [Action::Reconnect]);
    assert!(!edge.is_online());
    let after = poll_drive(&mut edge, &plant, t(45), &[("F001", Value::Int(1))]);
    assert!(
        !after.is_empty() && after.iter().all(|o| matches!(o, Output::Store(_))),
        "no data for a host that is gone"
    );
    let ndeath = edge.shutdown(t(46)).unwrap();
    assert_eq!(kind(&ndeath), "NDEATH");
    let (_, _, errors) = edge.message("spBv1.0/STATE/scada", b"online", t(50));
    assert!(matches!(&errors[..], [EdgeError::Malformed { .. }]));
}

#[test]
fn a_state_online_before_the_connection_releases_the_births_at_connack() {
    let plant = plant(Mode::Sparkplug(sparkplug_config(Some("scada"))));
    let mut edge = Edge::new(&plant);
    edge.connected(t(0));
    let online = HostState { online: true, timestamp: None }.to_json();
    assert_eq!(edge.message("spBv1.0/STATE/scada", &online, t(1)).0.len(), 1);
    edge.disconnected();
    assert!(edge.connected(t(2)).is_empty(), "a new session waits for the STATE again");
    assert_eq!(edge.message("spBv1.0/STATE/scada", &online, t(3)).0.len(), 1);
}

// ---------------------------------------------------------------------------------------------
// Offline: records, replay.
// ---------------------------------------------------------------------------------------------

#[test]
fn offline_samples_become_records_replayed_as_historical_ddata_in_order_with_their_timestamps() {
    let plant = sparkplug_plant();
    let (mut edge, _) = online_with_drive(&plant);
    edge.disconnected();
    let (g, _) = locate(&plant, DRIVE, "F001");
    let mut stored = Vec::new();
    for (i, raw) in [1000, 2000, 2000, 3000].into_iter().enumerate() {
        stored.extend(records(edge.sample(DRIVE, g, &answered(g, t(10_000 + i as u64 * 1000), vec![Value::Int(raw)]))));
    }
    assert_eq!(stored.len(), 3, "by exception offline too");
    assert!(matches!(edge.replay(&stored[0], t(20_000)), Err(EdgeError::Offline)));
    let births = edge.connected(t(20_000));
    let kinds: Vec<&str> = births.iter().map(kind).collect();
    assert_eq!(kinds, ["NBIRTH", "DBIRTH"]);
    let names = aliases(&decode(&births[1]));
    let mut seq = decode(&births[1]).seq.unwrap();
    let mut seen = Vec::new();
    for record in &stored {
        let p = edge.replay(record, t(20_100)).unwrap().expect("maps");
        assert_eq!(p.topic, "spBv1.0/plant/DDATA/edge1/drive1");
        let payload = decode(&p);
        seq += 1;
        assert_eq!(payload.seq, Some(seq));
        for m in payload.metrics {
            assert_eq!(m.is_historical, Some(true));
            assert_eq!(m.name, None);
            seen.push((names[&m.alias.unwrap()].clone(), m.value, m.timestamp.unwrap()));
        }
    }
    assert_eq!(
        seen,
        [
            ("F001".into(), Some(MetricValue::Double(10.0)), ms(t(10_000))),
            ("F001".into(), Some(MetricValue::Double(20.0)), ms(t(11_000))),
            ("F001".into(), Some(MetricValue::Double(30.0)), ms(t(13_000))),
        ]
    );
    assert_eq!(edge.stats().replayed, 3);
}

#[test]
fn a_record_survives_a_new_edge_of_the_same_plant_and_maps_once_the_device_is_born() {
    let plant = sparkplug_plant();
    let mut before = Edge::new(&plant);
    let stored: Vec<Vec<u8>> = records(poll_drive(&mut before, &plant, t(10), &[("F001", Value::Int(1234))]));
    assert!(!stored.is_empty());
    let mut after = Edge::new(&plant);
    after.connected(t(100));
    assert_eq!(after.replay(&stored[0], t(101)).unwrap(), None, "drive1 is not born in this run yet");
    poll_drive(&mut after, &plant, t(200), &[]);
    let p = after.replay(&stored[0], t(201)).unwrap().expect("born now");
    assert!(decode(&p).metrics.iter().all(|m| m.is_historical == Some(true)));
    assert_eq!(after.stats().unmapped, 1);
}

#[test]
fn replay_all_births_a_device_not_born_since_a_restart_for_its_history_then_it_dies() {
    let plant = sparkplug_plant();
    let mut before = Edge::new(&plant);
    let stored = records(poll_drive(&mut before, &plant, t(10), &[("F001", Value::Int(1234))]));
    let mut after = Edge::new(&plant);
    after.connected(t(100));
    let mut kinds = Vec::new();
    let mut dbirth = None;
    for record in &stored {
        for p in after.replay_all(record, t(101)).unwrap() {
            kinds.push(kind(&p).to_string());
            if kind(&p) == "DBIRTH" {
                dbirth = Some(decode(&p));
            } else {
                assert!(decode(&p).metrics.iter().all(|m| m.is_historical == Some(true)));
            }
        }
    }
    assert_eq!(kinds[..2], ["DBIRTH", "DDATA"], "born once, then its history");
    assert!(kinds[2..].iter().all(|k| k == "DDATA"), "{kinds:?}");
    let dbirth = dbirth.unwrap();
    assert!(dbirth.metrics.iter().all(|m| m.is_null == Some(true)), "nothing read in this run yet");
    assert_eq!(after.replayed(t(102)).iter().map(kind).collect::<Vec<_>>(), ["DDEATH"]);
    let back = publishes(poll_drive(&mut after, &plant, t(200), &[]));
    assert_eq!(kind(&back[0]), "DBIRTH", "its first answer: born with live values");
}

#[test]
fn replay_all_of_a_device_that_answers_before_the_replay_ends_keeps_it_born() {
    let plant = sparkplug_plant();
    let mut before = Edge::new(&plant);
    let stored = records(poll_drive(&mut before, &plant, t(10), &[("F001", Value::Int(1234))]));
    let mut after = Edge::new(&plant);
    after.connected(t(100));
    assert_eq!(after.replay_all(&stored[0], t(101)).unwrap().len(), 2);
    let (g, _) = locate(&plant, DRIVE, "F001");
    let out = publishes(after.sample(DRIVE, g, &answered(g, t(150), vec![Value::Int(6000)])));
    assert_eq!(out.iter().map(kind).collect::<Vec<_>>(), ["DDATA"], "born already: its values as data");
    assert!(after.replayed(t(160)).is_empty(), "it answers: no DDEATH");
}

#[test]
fn a_record_of_a_device_or_metric_gone_from_the_plant_gives_none() {
    let plant = sparkplug_plant();
    let mut edge = Edge::new(&plant);
    let stored = records(poll_drive(&mut edge, &plant, t(10), &[]));
    let mut smaller = sparkplug_plant();
    smaller.lines[0].devices[0].id = "drive2".into();
    let mut other = Edge::new(&smaller);
    other.connected(t(100));
    poll_drive(&mut other, &smaller, t(200), &[]);
    for record in &stored {
        assert_eq!(other.replay(record, t(300)).unwrap(), None);
    }
    assert!(matches!(other.replay(b"garbage", t(300)), Err(EdgeError::Record(_))));
}

#[test]
fn a_device_dead_at_the_connection_is_born_for_its_history_then_dies_after_the_replay() {
    let plant = sparkplug_plant();
    let (mut edge, _) = online_with_drive(&plant);
    edge.disconnected();
    let (g, _) = locate(&plant, DRIVE, "F001");
    let stored = records(edge.sample(DRIVE, g, &answered(g, t(1000), vec![Value::Int(100)])));
    for i in 0..3 {
        assert!(edge.sample(DRIVE, g, &failed(g, t(2000 + i), FailureKind::Timeout)).is_empty());
    }
    let births = edge.connected(t(3000));
    assert_eq!(births.iter().map(kind).collect::<Vec<_>>(), ["NBIRTH", "DBIRTH"]);
    assert!(edge.replay(&stored[0], t(3001)).unwrap().is_some());
    let deaths = edge.replayed(t(3002));
    assert_eq!(deaths.iter().map(kind).collect::<Vec<_>>(), ["DDEATH"]);
    assert!(edge.replayed(t(3003)).is_empty(), "once");
}

#[test]
fn a_device_dead_at_the_connection_dies_at_its_next_silent_poll_if_the_replay_is_not_reported() {
    let plant = sparkplug_plant();
    let (mut edge, _) = online_with_drive(&plant);
    edge.disconnected();
    let (g, _) = locate(&plant, DRIVE, "F001");
    for i in 0..3 {
        edge.sample(DRIVE, g, &failed(g, t(2000 + i), FailureKind::Timeout));
    }
    edge.connected(t(3000));
    let out = publishes(edge.sample(DRIVE, g, &failed(g, t(4000), FailureKind::Timeout)));
    assert_eq!(out.iter().map(kind).collect::<Vec<_>>(), ["DDEATH"]);
}

// ---------------------------------------------------------------------------------------------
// Plain mode.
// ---------------------------------------------------------------------------------------------

fn plain_plant(retain: bool) -> Plant {
    plant(Mode::Plain(PlainConfig { prefix: "factory/line1".into(), retain, qos: 1, discovery: None }))
}

fn json(p: &Publish) -> serde_json::Value {
    serde_json::from_slice(&p.payload).unwrap_or_else(|e| panic!("{}: {e}", p.topic))
}

#[test]
fn plain_publishes_each_point_as_json_on_its_topic_by_exception() {
    let plant = plain_plant(true);
    let mut edge = Edge::new(&plant);
    let will = edge.will().unwrap();
    assert_eq!(
        (will.topic.as_str(), will.payload.as_slice(), will.retain),
        ("factory/line1/status", &b"offline"[..], true)
    );
    let hello = edge.connected(t(0));
    assert_eq!(hello.len(), 1);
    assert_eq!(hello[0].payload, b"online");
    let out =
        publishes(poll_drive(&mut edge, &plant, t(1), &[("F001", Value::Int(6000)), ("running", Value::Bool(true))]));
    let by_topic: HashMap<&str, &Publish> = out.iter().map(|p| (p.topic.as_str(), p)).collect();
    assert_eq!(by_topic["factory/line1/drive1/status"].payload, b"online");
    let f001 = by_topic["factory/line1/drive1/F001"];
    assert_eq!((f001.qos, f001.retain), (1, true));
    assert_eq!(
        json(f001),
        serde_json::json!({"value": 60.0, "unit": "Hz", "timestamp": ferrobus_tools::poll::iso8601_ms(t(1)), "quality": "good"})
    );
    assert_eq!(json(by_topic["factory/line1/drive1/running"])["value"], true);
    assert_eq!(out.len(), 4, "status, F001, d001, running");
    let again = poll_drive(
        &mut edge,
        &plant,
        t(2),
        &[("F001", Value::Int(6000)), ("d001", Value::Int(40)), ("running", Value::Bool(true))],
    );
    assert!(again.is_empty(), "d001 moved 0.40 Hz, inside its 0.5 Hz deadband: {again:?}");
    let raw = publishes(edge.sample(METER, 0, &answered(0, t(3), vec![Value::Int(215), Value::Int(7)])));
    let temperature = raw.iter().find(|p| p.topic == "factory/line1/meter/temperature").unwrap();
    assert_eq!(json(temperature)["value"], 215, "an unscaled integer stays an integer");
    assert!(json(temperature).get("unit").is_none());
}

#[test]
fn plain_with_discovery_publishes_home_assistants_configs_retained_at_every_connection() {
    let mut plant = plain_plant(false);
    if let Mode::Plain(p) = &mut plant.mode {
        p.discovery = Some("homeassistant".into());
    }
    let mut edge = Edge::new(&plant);
    let hello = edge.connected(t(0));
    assert_eq!((hello[0].topic.as_str(), hello[0].payload.as_slice()), ("factory/line1/status", &b"online"[..]));
    let configs: Vec<&Publish> = hello.iter().filter(|p| p.topic.starts_with("homeassistant/")).collect();
    assert_eq!(configs.len(), hello.len() - 1, "the status, then a config per point: {hello:?}");
    let component = |name: &str| {
        let p =
            configs.iter().find(|p| json(p)["state_topic"].as_str().is_some_and(|t| t.ends_with(&format!("/{name}"))));
        p.map(|p| p.topic.split('/').nth(1).unwrap_or_default().to_string()).unwrap_or_default()
    };
    // drive1: F001 (rw, a range), d001 (ro), running (a ro coil); meter: two raw holding registers.
    assert_eq!(
        ["F001", "d001", "running", "temperature", "0x0001"].map(component),
        ["number", "sensor", "binary_sensor", "number", "number"]
    );
    assert!(configs.iter().all(|p| p.retain && p.qos == 1 && p.topic.ends_with("/config")), "{configs:?}");
    let f001 =
        configs.iter().find(|p| p.topic.starts_with("homeassistant/number/") && p.topic.contains("drive1")).unwrap();
    assert_eq!(json(f001)["command_topic"], "factory/line1/drive1/F001/set", "the existing checked write path");
    let meter = configs.iter().find(|p| json(p)["state_topic"] == "factory/line1/meter/temperature").unwrap();
    assert_eq!(json(meter)["device"]["name"], "meter");
    assert!(json(meter)["device"].get("manufacturer").is_none(), "no profile, no vendor: {}", json(meter));
    // The same configs, byte for byte, at the next connection: the topics and ids are stable.
    edge.disconnected();
    let again = edge.connected(t(10));
    let again: Vec<&Publish> = again.iter().filter(|p| p.topic.starts_with("homeassistant/")).collect();
    assert_eq!(again, configs);
    // Without discovery: nothing under homeassistant/.
    let mut plain = Edge::new(&plain_plant(false));
    assert!(plain.connected(t(0)).iter().all(|p| !p.topic.starts_with("homeassistant/")));
}

#[test]
fn plain_values_carry_the_points_resolution_and_enumerations_their_meaning() {
    let mut plant = plain_plant(false);
    let names: Vec<String> = ["F001", "status-a"].iter().map(|s| (*s).to_string()).collect();
    let device = &mut plant.lines[0].devices[0];
    device.groups = Group::points(&rx(), 1, &names, &[], Duration::from_secs(1)).unwrap();
    device.deadbands = device.groups.iter().map(|g| vec![0.0; g.cells.len()]).collect();
    let mut edge = Edge::new(&plant);
    edge.connected(t(0));
    let out =
        publishes(poll_drive(&mut edge, &plant, t(1), &[("F001", Value::Int(3498)), ("status-a", Value::Int(3))]));
    let by_topic: HashMap<&str, &Publish> = out.iter().map(|p| (p.topic.as_str(), p)).collect();
    // 3498 × 0.01 computes to 34.980000000000004: the message carries F001's two decimals.
    let f001 = by_topic["factory/line1/drive1/F001"];
    let text = String::from_utf8_lossy(&f001.payload);
    assert!(text.starts_with("{\"value\":34.98,\"unit\":\"Hz\","), "{text}");
    assert!(json(f001).get("meaning").is_none(), "{text}");
    let status = json(by_topic["factory/line1/drive1/status-a"]);
    assert_eq!((status["value"].clone(), status["meaning"].clone()), (3.into(), "run".into()), "{status}");
}

#[test]
fn plain_failures_are_bad_or_stale_once_with_the_error_and_the_device_goes_offline() {
    let plant = plain_plant(false);
    let mut edge = Edge::new(&plant);
    edge.connected(t(0));
    edge.sample(METER, 0, &answered(0, t(1), vec![Value::Int(20), Value::Int(7)]));
    edge.disconnected();
    assert_eq!(edge.connected(t(1)).len(), 2, "not retained: the statuses only, no values again");
    let out = publishes(edge.sample(METER, 0, &failed(0, t(2), FailureKind::Exception)));
    assert_eq!(out.len(), 2);
    let bad = json(&out[0]);
    assert_eq!((bad["quality"].as_str(), bad["value"].is_null()), (Some("bad"), true));
    assert!(bad["error"].as_str().unwrap().contains("exception"));
    assert!(publishes(edge.sample(METER, 0, &failed(0, t(3), FailureKind::Exception))).is_empty(), "once");
    edge.sample(METER, 0, &answered(0, t(4), vec![Value::Int(20), Value::Int(7)]));
    let out = publishes(edge.sample(METER, 0, &failed(0, t(5), FailureKind::Timeout)));
    assert_eq!(out.len(), 2, "stale, once");
    let stale = json(&out[0]);
    assert_eq!((stale["quality"].as_str(), stale["value"].as_i64()), (Some("stale"), Some(20)));
    assert_eq!(stale["timestamp"], ferrobus_tools::poll::iso8601_ms(t(5)));
    assert!(stale["error"].as_str().unwrap().contains("no reply"));
    let out = publishes(edge.sample(METER, 0, &failed(0, t(6), FailureKind::Timeout)));
    assert_eq!(out.len(), 1, "the second silent poll (death_after 2): offline");
    assert_eq!((out[0].topic.as_str(), out[0].payload.as_slice()), ("factory/line1/meter/status", &b"offline"[..]));
    let back = publishes(edge.sample(METER, 0, &answered(0, t(7), vec![Value::Int(20), Value::Int(7)])));
    assert_eq!(back.len(), 3, "online, then every point good again");
    assert_eq!(json(&back[1])["quality"], "good");
}

/// The liveness rule plain mode follows (the bridge's one, `edge::Health`): a device that
/// never answered gets no "offline" status when it is given up, nor stale points; its first
/// answer, an exception included, is "online".
#[test]
fn plain_a_device_that_never_answered_gets_no_offline_status_and_online_at_its_first_answer() {
    let plant = plain_plant(false);
    let mut edge = Edge::new(&plant);
    edge.connected(t(0));
    for i in 0..3 {
        assert!(publishes(edge.sample(METER, 0, &failed(0, t(1 + i), FailureKind::Timeout))).is_empty(), "poll {i}");
    }
    let out = publishes(edge.sample(METER, 0, &failed(0, t(5), FailureKind::Exception)));
    assert_eq!((out[0].topic.as_str(), out[0].payload.as_slice()), ("factory/line1/meter/status", &b"online"[..]));
    assert_eq!(out.len(), 3, "online, then its points bad: {out:?}");
}

#[test]
fn plain_set_writes_through_the_profile_and_the_result_is_published() {
    let plant = plain_plant(false);
    let mut edge = Edge::new(&plant);
    edge.connected(t(0));
    assert_eq!(edge.subscriptions(), [("factory/line1/+/+/set".to_string(), 1)]);
    let (g, c) = locate(&plant, DRIVE, "F001");
    for payload in [&b"45"[..], b"45 Hz", br#"{"value":45}"#, br#"{"value":"45.00"}"#] {
        let (out, actions, errors) = edge.message("factory/line1/drive1/F001/set", payload, t(1));
        assert!(out.is_empty() && errors.is_empty(), "{errors:?}");
        assert!(
            matches!(&actions[..], [Action::Write { device: DRIVE, group, cell, raw: Value::Int(4500), .. }] if (*group, *cell) == (g, c)),
            "{payload:?}: {actions:?}"
        );
    }
    let ok = edge.written(DRIVE, g, c, Ok(()));
    assert_eq!(ok[0].topic, "factory/line1/drive1/F001/set/result");
    assert_eq!(json(&ok[0]), serde_json::json!({"ok": true, "value": "45"}), "the results in the writes' order");
    assert_eq!(json(&edge.written(DRIVE, g, c, Ok(()))[0])["value"], "45 Hz");
    assert_eq!(json(&edge.written(DRIVE, g, c, Ok(()))[0])["value"], "45");
    let failed_write = edge.written(DRIVE, g, c, Err("timeout".into()));
    assert_eq!(json(&failed_write[0]), serde_json::json!({"ok": false, "value": "45.00", "error": "timeout"}));
    let unasked = edge.written(DRIVE, g, c, Ok(()));
    assert_eq!(json(&unasked[0]), serde_json::json!({"ok": true}), "a result nobody asked for: no value");
    for (topic, payload) in [
        ("factory/line1/drive1/F001/set", &b"500"[..]),
        ("factory/line1/drive1/F001/set", b"45 V"),
        ("factory/line1/drive1/d001/set", b"10"),
        ("factory/line1/drive1/nope/set", b"1"),
        ("factory/line1/pump/F001/set", b"1"),
        ("factory/line1/drive1/F001/set", b""),
        ("factory/line1/drive1/F001/set", br#"{"val":1}"#),
    ] {
        let (out, actions, errors) = edge.message(topic, payload, t(2));
        assert!(actions.is_empty(), "{topic} {payload:?}");
        assert_eq!(errors.len(), 1);
        assert_eq!(out[0].topic, format!("{topic}/result"));
        assert_eq!(json(&out[0])["ok"], false);
        assert!(!json(&out[0])["error"].as_str().unwrap().is_empty());
    }
}

#[test]
fn plain_offline_messages_are_stored_and_replayed_historical_unretained() {
    let plant = plain_plant(true);
    let mut edge = Edge::new(&plant);
    let stored = records(edge.sample(METER, 0, &answered(0, t(1), vec![Value::Int(20), Value::Int(7)])));
    assert_eq!(stored.len(), 2, "the points; the status is sent again at the connection");
    assert!(matches!(edge.replay(&stored[0], t(2)), Err(EdgeError::Offline)));
    let hello = edge.connected(t(10));
    let topics: Vec<&str> = hello.iter().map(|p| p.topic.as_str()).collect();
    assert_eq!(
        topics,
        [
            "factory/line1/status",
            "factory/line1/meter/status",
            "factory/line1/meter/temperature",
            "factory/line1/meter/0x0001"
        ],
        "retained: the last values again, live, so the broker does not keep those before the outage"
    );
    assert!(hello[2].retain && json(&hello[2]).get("historical").is_none());
    let p = edge.replay(&stored[0], t(11)).unwrap().unwrap();
    assert_eq!(p.topic, "factory/line1/meter/temperature");
    assert!(!p.retain, "history does not replace the retained last value");
    let body = json(&p);
    assert_eq!(body["historical"], true);
    assert_eq!(body["timestamp"], ferrobus_tools::poll::iso8601_ms(t(1)));
    for (bad, seen) in [(&b"[1]"[..], "not a JSON object"), (b"{", "not a JSON object")] {
        let record = records_of_plain("factory/line1/meter/temperature", bad);
        let error = edge.replay(&record, t(12)).unwrap_err().to_string();
        assert!(error.contains(seen), "{error}");
    }
    let empty = edge.replay(&records_of_plain("a/b/c", b"{}"), t(12)).unwrap().unwrap();
    assert_eq!(json(&empty), serde_json::json!({"historical": true}));
    let sparkplug_record =
        records(Edge::new(&sparkplug_plant()).sample(METER, 0, &answered(0, t(1), vec![Value::Int(1), Value::Int(2)])));
    assert!(matches!(edge.replay(&sparkplug_record[0], t(12)), Err(EdgeError::Record(_))));
}

// ---------------------------------------------------------------------------------------------
// Plants read by the config: the shipped demo and the plain example.
// ---------------------------------------------------------------------------------------------

#[test]
fn the_demo_plant_births_both_drives_and_a_dcmd_of_60_hz_to_the_3g3rx_writes_raw_6000() {
    let plant = Plant::demo("127.0.0.1:1883").unwrap();
    let mut edge = Edge::new(&plant);
    edge.connected(t(0));
    let mut dbirths = HashMap::new();
    for (l, line) in plant.lines.iter().enumerate() {
        for (d, device) in line.devices.iter().enumerate() {
            for (g, group) in device.groups.iter().enumerate() {
                let raws = group.cells.iter().map(|c| c.point.default.clone()).collect();
                for p in publishes(edge.sample(DeviceRef { line: l, device: d }, g, &answered(g, t(1), raws))) {
                    if kind(&p) == "DBIRTH" {
                        dbirths.insert(p.topic.rsplit('/').next().unwrap().to_string(), decode(&p));
                    }
                }
            }
        }
    }
    assert_eq!(dbirths.len(), 2, "{:?}", dbirths.keys());
    let inverter = &dbirths["inverter"];
    let f001 = metric(inverter, "F001");
    assert_eq!(property(f001, "engUnit"), Some(&PropertyValueKind::String("Hz".into())));
    let set = Metric { alias: f001.alias, value: Some(MetricValue::Double(60.0)), ..Metric::default() };
    let (_, actions, errors) = edge.message("spBv1.0/ferrobus-demo/DCMD/demo-edge/inverter", &dcmd(vec![set]), t(2));
    assert!(errors.is_empty(), "{errors:?}");
    assert!(matches!(&actions[..], [Action::Write { raw: Value::Int(6000), .. }]), "{actions:?}");
    let over = Metric { alias: f001.alias, value: Some(MetricValue::Double(400.01)), ..Metric::default() };
    let (_, actions, errors) = edge.message("spBv1.0/ferrobus-demo/DCMD/demo-edge/inverter", &dcmd(vec![over]), t(3));
    assert!(actions.is_empty() && errors.len() == 1, "{errors:?}");
}

#[test]
fn the_plain_example_publishes_on_its_prefix() {
    let text =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/bridge/plain.toml")).unwrap();
    let plant = Plant::parse(&text, "plain.toml", std::path::Path::new(".")).unwrap();
    let mut edge = Edge::new(&plant);
    assert_eq!(edge.subscriptions(), [("plant/hall-2/+/+/set".to_string(), 1)]);
    edge.connected(t(0));
    let device = &plant.lines[0].devices[0];
    let raws = device.groups[0].cells.iter().map(|c| c.point.default.clone()).collect();
    let out = publishes(edge.sample(DeviceRef { line: 0, device: 0 }, 0, &answered(0, t(1), raws)));
    assert!(out.iter().any(|p| p.topic == "plant/hall-2/pump/status"));
    assert!(out.iter().filter(|p| !p.topic.ends_with("/status")).all(|p| p.retain && json(p)["quality"] == "good"));
}

/// A plain-mode store record as the edge writes them (see edge/record.rs), for damaged ones.
fn records_of_plain(topic: &str, payload: &[u8]) -> Vec<u8> {
    let mut out = b"FBe\x01P".to_vec();
    out.extend_from_slice(&u16::try_from(topic.len()).unwrap().to_be_bytes());
    out.extend_from_slice(topic.as_bytes());
    out.extend_from_slice(payload);
    out
}

#[test]
fn the_long_value_switch_keeps_a_uint16_in_int_value_as_tahu_reads_it() {
    let config = SparkplugConfig { uint_encoding: UintEncoding::LongValue, ..sparkplug_config(None) };
    let plant = plant(Mode::Sparkplug(config));
    let mut edge = Edge::new(&plant);
    edge.connected(t(0));
    let out = publishes(edge.sample(METER, 0, &answered(0, t(1), vec![Value::Int(215), Value::Int(7)])));
    let dbirth = decode(&out[0]);
    let temperature = metric(&dbirth, "temperature");
    assert_eq!(temperature.datatype, Some(DataType::UInt16.number()));
    assert_eq!(temperature.value, Some(MetricValue::Int(215)), "only UInt32 moves to long_value");
}

// ---------------------------------------------------------------------------------------------
// Whatever comes from the broker or the store, nothing panics.
// ---------------------------------------------------------------------------------------------

mod hostile {
    use proptest::prelude::*;

    use super::*;

    const TOPICS: [&str; 6] = [
        "spBv1.0/plant/NCMD/edge1",
        "spBv1.0/plant/DCMD/edge1/drive1",
        "spBv1.0/plant/DCMD/edge1/meter",
        "spBv1.0/STATE/scada",
        "factory/line1/drive1/F001/set",
        "factory/line1/meter/temperature/set",
    ];

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]

        #[test]
        fn any_payload_on_any_topic_is_taken_or_refused(topic in 0..TOPICS.len(), payload in proptest::collection::vec(any::<u8>(), 0..64)) {
            for mode in [Mode::Sparkplug(sparkplug_config(Some("scada"))), Mode::Plain(PlainConfig { prefix: "factory/line1".into(), retain: false, qos: 0, discovery: None })] {
                let plant = plant(mode);
                let mut edge = Edge::new(&plant);
                edge.connected(t(0));
                let (_, actions, _) = edge.message(TOPICS[topic], &payload, t(1));
                for action in actions {
                    if let Action::Write { device, group, cell, raw, .. } = action {
                        let point = &plant.lines[device.line].devices[device.device].groups[group].cells[cell].point;
                        prop_assert!(point.check_write(&raw, "").is_ok(), "a write the profile refuses: {raw:?}");
                    }
                }
            }
        }

        #[test]
        fn any_bytes_as_a_record_are_replayed_or_refused(bytes in proptest::collection::vec(any::<u8>(), 0..64)) {
            let plant = sparkplug_plant();
            let (mut edge, _) = online_with_drive(&plant);
            let _ = edge.replay_all(&bytes, t(1));
            let mut prefixed = b"FBe\x01S\x00\x06drive1".to_vec();
            prefixed.extend_from_slice(&bytes);
            let _ = edge.replay_all(&prefixed, t(2));
        }

        #[test]
        fn any_dcmd_metric_values_write_only_what_the_profile_allows(raw in any::<f64>(), alias in 0_u64..8) {
            let plant = sparkplug_plant();
            let (mut edge, _) = online_with_drive(&plant);
            let m = Metric { alias: Some(alias), value: Some(MetricValue::Double(raw)), ..Metric::default() };
            let (_, actions, errors) = edge.message("spBv1.0/plant/DCMD/edge1/drive1", &dcmd(vec![m]), t(1));
            prop_assert_eq!(actions.len() + errors.len(), 1);
            if let [Action::Write { raw: Value::Int(n), .. }] = actions.as_slice() {
                prop_assert!((0..=40_000).contains(n));
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Values the device does not implement (a SunSpec device's 0xFFFF, 0x8000).
// ---------------------------------------------------------------------------------------------

#[test]
fn a_value_the_device_does_not_implement_is_a_null_metric_in_dbirth_and_ddata() {
    let text = "[device]\nname='inverter'\nvendor='v'\nproduct_code='p'\nrevision='1'\n\
                [[registers]]\nnumber=0\nname='St'\nnot_implemented=0xFFFF\n\
                [[registers]]\nnumber=1\nname='Tmp'\ntype='i16'\nscale=0.1\nunit='C'\nnot_implemented=-32768\n";
    let profile = Arc::new(Profile::parse(text, "inverter.toml").unwrap());
    let names = vec!["St".to_string(), "Tmp".to_string()];
    let groups = Group::points(&profile, 2, &names, &[], Duration::from_secs(1)).unwrap();
    let mut plant = sparkplug_plant();
    plant.lines[1].devices[0] = DeviceSpec {
        id: "inverter".into(),
        unit: 2,
        profile: Some(profile),
        deadbands: vec![vec![0.0, 0.0]],
        groups,
        death_after: 2,
    };
    let (g, _) = locate(&plant, METER, "St");
    let mut edge = Edge::new(&plant);
    edge.connected(t(0));
    let sentinels = || vec![Value::Int(0xFFFF), Value::Int(-32768)];
    let out = publishes(edge.sample(METER, g, &answered(g, t(10), sentinels())));
    let dbirth = decode(out.iter().find(|p| kind(p) == "DBIRTH").expect("a DBIRTH"));
    for name in ["St", "Tmp"] {
        let m = metric(&dbirth, name);
        assert_eq!((m.is_null, &m.value), (Some(true), &None), "{name}: not implemented, so no value");
    }
    let names = aliases(&dbirth);
    let values = |out: Vec<Publish>| -> Vec<(String, Option<bool>, Option<MetricValue>)> {
        out.iter().flat_map(decode_metrics).map(|m| (names[&m.alias.unwrap()].clone(), m.is_null, m.value)).collect()
    };
    let read = values(publishes(edge.sample(METER, g, &answered(g, t(20), vec![Value::Int(3), Value::Int(451)]))));
    assert_eq!(
        read,
        [("St".into(), None, Some(MetricValue::Int(3))), ("Tmp".into(), None, Some(MetricValue::Double(45.1)))]
    );
    let gone = values(publishes(edge.sample(METER, g, &answered(g, t(30), sentinels()))));
    assert_eq!(gone, [("St".into(), Some(true), None), ("Tmp".into(), Some(true), None)], "null again, as DDATA");
}

// ---------------------------------------------------------------------------------------------
// Reload: the edge carries out a plan from the running plant to a new one.
// ---------------------------------------------------------------------------------------------

/// The plant reloaded: the drive unchanged, the meter changed (`death_after`), a second drive
/// added on the drive's line after it.
fn grown(running: &Plant) -> Plant {
    let mut new = running.clone();
    new.lines[1].devices[0].death_after = 5;
    let mut second = drive();
    second.id = "drive2".into();
    second.unit = 3;
    new.lines[0].devices.push(second);
    new
}

fn poll_meter(edge: &mut Edge, at: DeviceRef, time: SystemTime, a: i128) -> Vec<Publish> {
    publishes(edge.sample(at, 0, &answered(0, time, vec![Value::Int(a), Value::Int(7)])))
}

#[test]
fn a_reload_keeps_the_unchanged_devices_session_kills_the_changed_and_births_come_with_fresh_aliases() {
    use ferrobus_bridge::config::reload::plan;
    let running = sparkplug_plant();
    let (mut edge, drive_birth) = online_with_drive(&running);
    let meter_birth = decode(&poll_meter(&mut edge, METER, t(300), 20)[0]);
    let new = grown(&running);
    let plan = plan(&running, &new).unwrap();
    let out = edge.reload(&new, &plan, t(400));
    assert_eq!(out.iter().map(|p| p.topic.as_str()).collect::<Vec<_>>(), ["spBv1.0/plant/DDEATH/edge1/meter"]);
    let ddeath = decode(&out[0]);
    assert_eq!(ddeath.seq, Some(3), "NBIRTH 0, DBIRTH 1, DBIRTH 2, DDEATH 3");
    // The drive goes on: the same sample publishes nothing, a change is DDATA under its aliases.
    assert!(
        publishes(poll_drive(&mut edge, &new, t(500), &[("F001", Value::Int(6000)), ("d001", Value::Int(5990))]))
            .is_empty()
    );
    let moved =
        publishes(poll_drive(&mut edge, &new, t(600), &[("F001", Value::Int(5000)), ("d001", Value::Int(5990))]));
    assert_eq!(moved.iter().map(kind).collect::<Vec<_>>(), ["DDATA"]);
    let f001 = metric(&drive_birth, "F001").alias;
    assert_eq!(decode(&moved[0]).metrics.iter().map(|m| m.alias).collect::<Vec<_>>(), [f001]);
    // The added drive and the changed meter are born at their first answers, with aliases no
    // metric had.
    let second = DeviceRef { line: 0, device: 1 };
    let mut born = Vec::new();
    for (g, group) in new.lines[0].devices[1].groups.iter().enumerate() {
        let raws =
            group.cells.iter().map(|c| if c.name == "running" { Value::Bool(false) } else { Value::Int(1) }).collect();
        born.extend(publishes(edge.sample(second, g, &answered(g, t(700), raws))));
    }
    assert_eq!(born[0].topic, "spBv1.0/plant/DBIRTH/edge1/drive2", "born at its first answered group");
    assert!(born[1..].iter().all(|p| p.topic == "spBv1.0/plant/DDATA/edge1/drive2"), "{born:?}");
    let reborn = poll_meter(&mut edge, METER, t(800), 20);
    assert_eq!(reborn.iter().map(|p| p.topic.as_str()).collect::<Vec<_>>(), ["spBv1.0/plant/DBIRTH/edge1/meter"]);
    let old: Vec<u64> = aliases(&drive_birth).into_keys().chain(aliases(&meter_birth).into_keys()).collect();
    let fresh: Vec<u64> =
        aliases(&decode(&born[0])).into_keys().chain(aliases(&decode(&reborn[0])).into_keys()).collect();
    assert!(fresh.iter().all(|a| !old.contains(a)), "old {old:?}, new {fresh:?}");
    let mut unique = fresh.clone();
    unique.sort_unstable();
    unique.dedup();
    assert_eq!(unique.len(), fresh.len(), "{fresh:?}");
    // A rebirth asked by the host: the same aliases as the births.
    let (again, _, _) = edge.message("spBv1.0/plant/NCMD/edge1", &rebirth_true(), t(900));
    assert_eq!(again.iter().map(kind).collect::<Vec<_>>(), ["NBIRTH", "DBIRTH", "DBIRTH", "DBIRTH"]);
    assert_eq!(aliases(&decode(&again[1])), aliases(&drive_birth));
}

fn rebirth_true() -> Vec<u8> {
    let m = Metric::new("Node Control/Rebirth", DataType::Boolean, Some(MetricValue::Boolean(true)));
    Payload { timestamp: Some(ms(t(0))), metrics: vec![m], ..Payload::default() }.encode()
}

#[test]
fn a_reload_that_removes_a_device_sends_its_ddeath_and_its_samples_name_nothing_then() {
    use ferrobus_bridge::config::reload::plan;
    let running = sparkplug_plant();
    let (mut edge, _) = online_with_drive(&running);
    let mut new = running.clone();
    new.lines.remove(0);
    let plan = plan(&running, &new).unwrap();
    let out = edge.reload(&new, &plan, t(400));
    assert_eq!(out.iter().map(|p| p.topic.as_str()).collect::<Vec<_>>(), ["spBv1.0/plant/DDEATH/edge1/drive1"]);
    // The meter, unborn, is now line 0: its first answer is its DBIRTH.
    let meter = poll_meter(&mut edge, DeviceRef { line: 0, device: 0 }, t(500), 1);
    assert_eq!(meter.iter().map(|p| p.topic.as_str()).collect::<Vec<_>>(), ["spBv1.0/plant/DBIRTH/edge1/meter"]);
    // Offline, a reload publishes nothing.
    edge.disconnected();
    let plan = ferrobus_bridge::config::reload::plan(&new, &running).unwrap();
    assert!(edge.reload(&running, &plan, t(600)).is_empty());
}

#[test]
fn plain_a_reload_marks_removed_devices_offline_and_moves_the_discovery_configs() {
    use ferrobus_bridge::config::reload::plan;
    let mut running = plain_plant(false);
    if let Mode::Plain(p) = &mut running.mode {
        p.discovery = Some("homeassistant".into());
    }
    let mut edge = Edge::new(&running);
    let hello = edge.connected(t(0));
    let meter_configs: Vec<String> =
        hello.iter().filter(|p| p.topic.contains("meter")).map(|p| p.topic.clone()).collect();
    assert!(!meter_configs.is_empty());
    let mut new = grown(&running);
    new.lines.remove(1);
    let plan = plan(&running, &new).unwrap();
    let out = edge.reload(&new, &plan, t(100));
    assert!(
        out.iter().any(|p| p.topic == "factory/line1/meter/status" && p.payload == b"offline" && p.retain),
        "{out:?}"
    );
    for topic in &meter_configs {
        assert!(
            out.iter().any(|p| &p.topic == topic && p.payload.is_empty() && p.retain),
            "{topic} not removed: {out:?}"
        );
    }
    let added: Vec<&Publish> =
        out.iter().filter(|p| p.topic.starts_with("homeassistant/") && !p.payload.is_empty()).collect();
    assert_eq!(added.len(), 3, "drive2's F001, d001 and running: {added:?}");
    assert!(added.iter().all(|p| p.topic.contains("drive2") && p.retain));
    assert!(out.iter().all(|p| !p.topic.contains("drive1")), "drive1 is unchanged: {out:?}");
}
