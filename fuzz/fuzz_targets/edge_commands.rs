//! The edge node of the demo plant (`Plant::demo`: the 3G3RX and the servo) fed what a broker
//! may deliver, through `Edge::message`, interleaved with samples, connections and losses,
//! replays and write results. The demo runs as Sparkplug B, as Sparkplug B with a primary host
//! (`scada`) and UInt32 in `long_value`, and as plain JSON.
//!
//! Topics are built around the plant's own (NCMD, DCMD to each device, the host's STATE,
//! `PREFIX/DEVICE/POINT/set`) or are any text; payloads are Sparkplug payloads of metrics by
//! alias or by name with any value, STATE JSON, a plain write's text, or any bytes.
//!
//! - Nothing panics.
//! - Every `Action::Write` names a cell of the plant whose point's `check_write` passes the raw
//!   value (and whose registers can hold it).
//! - Sparkplug: every message goes to a topic of this edge node, its payload decodes, its seq
//!   is 0 to 255: 0 for an NBIRTH, the previous message's + 1 (255 → 0) for the others, none
//!   for an NDEATH; an NBIRTH's and an NDEATH's bdSeq is that of the session's Will. Plain:
//!   every topic is under the prefix, every payload text.
//! - QoS is 0 to 2; every refusal has a message.
#![no_main]

use std::sync::LazyLock;
use std::time::{Duration, SystemTime};

use arbitrary::Arbitrary;
use ferrobus_bridge::config::{Mode, PlainConfig, Plant};
use ferrobus_bridge::edge::{Action, DeviceRef, Edge, Output, Publish};
use ferrobus_bridge::sparkplug::convert::UintEncoding;
use ferrobus_bridge::sparkplug::payload::{Metric, MetricValue, Payload};
use ferrobus_bridge::sparkplug::topic::{self, HostState, MessageType, NAMESPACE, Topic};
use ferrobus_profile::{Value, ValueType};
use ferrobus_tools::poll::{Failure, FailureKind, Reading, Sample, Traffic};
use libfuzzer_sys::fuzz_target;

/// The primary host of the second plant.
const HOST: &str = "scada";
/// The prefix of the plain plant.
const PREFIX: &str = "fuzz/plant";

/// The demo plant three ways: Sparkplug, Sparkplug with a primary host, plain.
static PLANTS: LazyLock<Vec<Plant>> = LazyLock::new(|| {
    let demo = Plant::demo("127.0.0.1:1883").unwrap_or_else(|e| panic!("the demo plant: {e}"));
    let mut hosted = demo.clone();
    if let Mode::Sparkplug(config) = &mut hosted.mode {
        config.primary_host = Some(HOST.to_owned());
        config.uint_encoding = UintEncoding::LongValue;
    }
    let mut plain = demo.clone();
    plain.mode = Mode::Plain(PlainConfig { prefix: PREFIX.to_owned(), retain: true, qos: 1, discovery: None });
    vec![demo, hosted, plain]
});

/// One run: a plant and what happens to its edge.
#[derive(Arbitrary, Debug)]
struct Input {
    plant: u8,
    steps: Vec<(i16, Step)>,
}

/// One event; the clock moves by the step's milliseconds (× 16, backwards too) before it.
#[derive(Arbitrary, Debug)]
enum Step {
    Connected,
    Disconnected,
    Shutdown,
    Message {
        topic: TopicPick,
        payload: PayloadPick,
    },
    Sample {
        device: u8,
        group: u8,
        reply: Reply,
    },
    /// The result of the write asked `which` writes ago (plain mode publishes it).
    Written {
        which: u8,
        ok: bool,
    },
    /// The oldest record stored so far (`all`: through `replay_all`).
    Replay {
        all: bool,
    },
    /// Any bytes as a record.
    ReplayBytes(Vec<u8>),
    Replayed,
}

/// A topic: the plant's own, or any text.
#[derive(Arbitrary, Debug)]
enum TopicPick {
    Text(String),
    /// `spBv1.0/<group>/<kind>/<node>`.
    Node {
        kind: u8,
    },
    /// `spBv1.0/<group>/<kind>/<node>/<device>`: a device of the plant, or any id.
    Device {
        kind: u8,
        device: u8,
        other: Option<String>,
    },
    /// `spBv1.0/STATE/<host>`: the primary host, or another.
    State {
        other: Option<String>,
    },
    /// `PREFIX/<device>/<metric>/set`, the names taken from the plant.
    Set {
        device: u8,
        metric: u16,
        suffix: Option<String>,
    },
}

/// A payload.
#[derive(Arbitrary, Debug)]
enum PayloadPick {
    Bytes(Vec<u8>),
    Sparkplug { timestamp: Option<u64>, seq: Option<u64>, metrics: Vec<MetricPick> },
    State { online: bool, timestamp: Option<u64> },
    Text(String),
    JsonNumber(f64),
}

/// A command's metric.
#[derive(Arbitrary, Debug)]
struct MetricPick {
    key: Key,
    datatype: Option<u32>,
    is_null: Option<bool>,
    value: Option<ValuePick>,
}

/// How a metric names what it writes.
#[derive(Arbitrary, Debug)]
enum Key {
    Alias(u8),
    /// A metric name of the plant, by index over all devices' names.
    Name(u16),
    Rebirth,
    Text(String),
    AliasAndName(u8, u16),
}

/// A metric value (the scalar kinds; the others are any bytes' business).
#[derive(Arbitrary, Debug)]
enum ValuePick {
    Int(u32),
    Long(u64),
    Float(f32),
    Double(f64),
    Boolean(bool),
    String(String),
    Bytes(Vec<u8>),
}

/// What a poll gave.
#[derive(Arbitrary, Debug)]
enum Reply {
    /// The group's registers `base`, `base + step`, `base + 2 × step`, ... (wrapping), a bit
    /// from the low bit; the cell `bad` (if any) does not decode. Of a fixed size, so that an
    /// input holds many polls.
    Answered {
        base: u16,
        step: u16,
        bad: Option<u8>,
    },
    Failed {
        kind: u8,
    },
}

/// The edge under test, what it was told and what it must keep to.
struct Run<'p> {
    plant: &'p Plant,
    edge: Edge,
    now: SystemTime,
    /// The seq of the last Sparkplug message with one.
    last_seq: Option<u64>,
    /// While connected: the bdSeq of the Will registered at the connection.
    session: Option<u64>,
    records: Vec<Vec<u8>>,
    writes: Vec<(DeviceRef, usize, usize)>,
}

fuzz_target!(|input: Input| {
    let plant = &PLANTS[usize::from(input.plant) % PLANTS.len()];
    let mut run = Run {
        plant,
        edge: Edge::new(plant),
        now: SystemTime::UNIX_EPOCH + Duration::from_millis(1_764_633_600_000),
        last_seq: None,
        session: None,
        records: Vec::new(),
        writes: Vec::new(),
    };
    for (topic, qos) in run.edge.subscriptions() {
        assert!(qos <= 2 && !topic.is_empty(), "subscription {topic:?} QoS {qos}");
    }
    for (advance, step) in input.steps {
        let delta = Duration::from_millis(u64::from(advance.unsigned_abs()) * 16);
        run.now = if advance < 0 { run.now.checked_sub(delta) } else { run.now.checked_add(delta) }.unwrap_or(run.now);
        run.step(step);
    }
    let _ = run.edge.stats();
});

impl Run<'_> {
    fn step(&mut self, step: Step) {
        let now = self.now;
        match step {
            Step::Connected => {
                let will = self.edge.will();
                self.session = Some(will.as_ref().and_then(bd_seq).unwrap_or(0));
                let births = self.edge.connected(now);
                self.check_publishes(&births);
            }
            Step::Disconnected => {
                self.edge.disconnected();
                self.session = None;
            }
            Step::Shutdown => {
                let death = self.edge.shutdown(now);
                self.check_publishes(death.as_slice());
                self.session = None;
            }
            Step::Message { topic, payload } => {
                let topic = self.topic(topic);
                let payload = self.payload(payload);
                let (publishes, actions, errors) = self.edge.message(&topic, &payload, now);
                self.check_publishes(&publishes);
                for action in &actions {
                    self.check_action(action);
                }
                for error in &errors {
                    assert!(!error.to_string().trim().is_empty(), "a refusal without a message: {error:?}");
                }
            }
            Step::Sample { device, group, reply } => self.sample(device, group, reply),
            Step::Written { which, ok } => {
                let Some(&(device, group, cell)) = self.writes.iter().rev().nth(usize::from(which)) else { return };
                let result = if ok { Ok(()) } else { Err("exception 0x03 (illegal data value)".to_owned()) };
                let publishes = self.edge.written(device, group, cell, result);
                self.check_publishes(&publishes);
            }
            Step::Replay { all } => {
                if !self.records.is_empty() {
                    let record = self.records.remove(0);
                    self.replay(&record, all);
                }
            }
            Step::ReplayBytes(bytes) => self.replay(&bytes, true),
            Step::Replayed => {
                let publishes = self.edge.replayed(now);
                self.check_publishes(&publishes);
            }
        }
    }

    /// A record replayed: through `replay_all`, or `replay`.
    fn replay(&mut self, record: &[u8], all: bool) {
        if all {
            if let Ok(publishes) = self.edge.replay_all(record, self.now) {
                self.check_publishes(&publishes);
            }
        } else if let Ok(Some(publish)) = self.edge.replay(record, self.now) {
            self.check_publishes(std::slice::from_ref(&publish));
        }
    }

    /// Every device of the plant, in line and device order.
    fn devices(&self) -> Vec<DeviceRef> {
        let lines = self.plant.lines.iter().enumerate();
        lines.flat_map(|(line, l)| (0..l.devices.len()).map(move |device| DeviceRef { line, device })).collect()
    }

    /// Every metric name of the plant.
    fn metric_names(&self) -> Vec<&str> {
        self.plant.devices().flat_map(|(_, d)| d.metric_names()).collect()
    }

    fn topic(&self, pick: TopicPick) -> String {
        let (group, node) = match &self.plant.mode {
            Mode::Sparkplug(c) => (c.group_id.as_str(), c.edge_node_id.as_str()),
            Mode::Plain(_) => ("plain", "plain"),
        };
        let ids: Vec<&str> = self.plant.devices().map(|(_, d)| d.id.as_str()).collect();
        let kind = |k: u8| MessageType::ALL[usize::from(k) % MessageType::ALL.len()];
        match pick {
            TopicPick::Text(text) => text,
            TopicPick::Node { kind: k } => Topic::node(group, kind(k), node).to_string(),
            TopicPick::Device { kind: k, device, other } => {
                let id = other.unwrap_or_else(|| ids[usize::from(device) % ids.len()].to_owned());
                format!("{NAMESPACE}/{group}/{}/{node}/{id}", kind(k))
            }
            TopicPick::State { other } => topic::state_topic(other.as_deref().unwrap_or(HOST)),
            TopicPick::Set { device, metric, suffix } => {
                let names = self.metric_names();
                let id = ids[usize::from(device) % ids.len()];
                let name = names[usize::from(metric) % names.len()];
                let suffix = suffix.unwrap_or_else(|| "set".to_owned());
                format!("{PREFIX}/{id}/{name}/{suffix}")
            }
        }
    }

    fn payload(&self, pick: PayloadPick) -> Vec<u8> {
        match pick {
            PayloadPick::Bytes(bytes) => bytes,
            PayloadPick::Sparkplug { timestamp, seq, metrics } => {
                let names = self.metric_names();
                let metrics = metrics.into_iter().map(|m| metric(m, &names)).collect();
                Payload { timestamp, seq, metrics, ..Payload::default() }.encode()
            }
            PayloadPick::State { online, timestamp } => HostState { online, timestamp }.to_json(),
            PayloadPick::Text(text) => text.into_bytes(),
            PayloadPick::JsonNumber(x) => serde_json::json!({ "value": x }).to_string().into_bytes(),
        }
    }

    fn sample(&mut self, device: u8, group: u8, reply: Reply) {
        let devices = self.devices();
        let at = devices[usize::from(device) % devices.len()];
        let spec = &self.plant.lines[at.line].devices[at.device];
        let g = usize::from(group) % spec.groups.len();
        let cells = &spec.groups[g].cells;
        let result = match reply {
            Reply::Answered { base, step, bad } => {
                let mut words = (0u16..).map(|i| base.wrapping_add(step.wrapping_mul(i)));
                let bad = bad.map(|b| usize::from(b) % cells.len());
                Ok(cells
                    .iter()
                    .enumerate()
                    .map(|(i, cell)| {
                        let point = &cell.point;
                        let raw = if Some(i) == bad {
                            Err("the registers decode to no value".to_owned())
                        } else if point.value_type == ValueType::Bit {
                            Ok(Value::Bool(words.next().unwrap_or(0) & 1 == 1))
                        } else {
                            let regs: Vec<u16> = (0..point.width).map(|_| words.next().unwrap_or(0)).collect();
                            point.decode(&regs).map_err(|e| e.to_string())
                        };
                        let scaled = raw.as_ref().ok().and_then(|r| point.engineering(r));
                        let shown = raw.as_ref().map_or_else(Clone::clone, |r| point.show(r));
                        Reading { cell: i, raw, scaled, shown }
                    })
                    .collect())
            }
            Reply::Failed { kind } => {
                let kind = FailureKind::ALL[usize::from(kind) % FailureKind::ALL.len()];
                let exception = (kind == FailureKind::Exception).then_some(2);
                Err(Failure { kind, exception, diagnosis: format!("{kind:?}") })
            }
        };
        let sample = Sample {
            group: g,
            seq: 0,
            time: self.now,
            due: Duration::ZERO,
            started: Duration::ZERO,
            response_time: Duration::from_millis(12),
            overrun: false,
            result,
            traffic: Traffic::default(),
        };
        let outputs = self.edge.sample(at, g, &sample);
        let mut publishes = Vec::new();
        for output in outputs {
            match output {
                Output::Publish(p) => publishes.push(p),
                Output::Store(record) => self.records.push(record),
            }
        }
        self.check_publishes(&publishes);
    }

    /// A write names a cell of the plant, and its point takes the value.
    fn check_action(&mut self, action: &Action) {
        let Action::Write { device, group, cell, raw, typed } = action else { return };
        let spec = self
            .plant
            .lines
            .get(device.line)
            .and_then(|l| l.devices.get(device.device))
            .unwrap_or_else(|| panic!("a write to {device:?}, not in the plant"));
        let point = &spec
            .groups
            .get(*group)
            .and_then(|g| g.cells.get(*cell))
            .unwrap_or_else(|| panic!("a write to {device:?} group {group} cell {cell}, not in the plant"))
            .point;
        point.check_write(raw, typed).unwrap_or_else(|e| panic!("a write that check_write refuses: {e} ({action:?})"));
        if point.value_type == ValueType::Bit {
            assert!(matches!(raw, Value::Bool(_)), "a bit written with {raw:?}");
        } else {
            point.encode(raw).unwrap_or_else(|e| panic!("a write the registers cannot hold: {e} ({action:?})"));
        }
        self.writes.push((*device, *group, *cell));
    }

    fn check_publishes(&mut self, publishes: &[Publish]) {
        for publish in publishes {
            assert!(publish.qos <= 2, "{}: QoS {}", publish.topic, publish.qos);
            match &self.plant.mode {
                Mode::Sparkplug(config) => {
                    let topic = Topic::parse(&publish.topic)
                        .unwrap_or_else(|| panic!("{:?} is no Sparkplug topic", publish.topic));
                    assert_eq!(
                        (topic.group.as_str(), topic.node.as_str()),
                        (config.group_id.as_str(), config.edge_node_id.as_str())
                    );
                    self.check_seq(topic.kind, publish);
                }
                Mode::Plain(config) => {
                    assert!(publish.topic.starts_with(&format!("{}/", config.prefix)), "{:?}", publish.topic);
                    assert!(std::str::from_utf8(&publish.payload).is_ok(), "{}: not text", publish.topic);
                }
            }
        }
    }

    fn check_seq(&mut self, kind: MessageType, publish: &Publish) {
        let payload = Payload::decode(&publish.payload)
            .unwrap_or_else(|e| panic!("{}: our payload does not decode: {e}", publish.topic));
        if kind == MessageType::NDeath {
            assert_eq!(payload.seq, None, "an NDEATH with a seq");
            self.check_bd_seq(publish);
            return;
        }
        let seq = payload.seq.unwrap_or_else(|| panic!("{}: no seq", publish.topic));
        assert!(seq <= 255, "{}: seq {seq}", publish.topic);
        if kind == MessageType::NBirth {
            assert_eq!(seq, 0, "an NBIRTH with seq {seq}");
            self.check_bd_seq(publish);
        } else if let Some(last) = self.last_seq {
            assert_eq!(seq, (last + 1) % 256, "{}: seq {seq} after {last}", publish.topic);
        }
        self.last_seq = Some(seq);
    }

    /// An NBIRTH or NDEATH of a session carries the bdSeq of that session's Will.
    fn check_bd_seq(&self, publish: &Publish) {
        let Some(will) = self.session else { return };
        let carried = bd_seq(publish).unwrap_or_else(|| panic!("{}: no Int64 bdSeq metric", publish.topic));
        assert_eq!(carried, will, "{}: bdSeq {carried}, the Will's {will}", publish.topic);
    }
}

/// The bdSeq metric of an NBIRTH or NDEATH.
fn bd_seq(publish: &Publish) -> Option<u64> {
    let payload = Payload::decode(&publish.payload).ok()?;
    let metric = payload.metrics.iter().find(|m| m.name.as_deref() == Some("bdSeq"))?;
    match metric.value {
        Some(MetricValue::Long(n)) => Some(n),
        _ => None,
    }
}

/// A command's metric from its pick.
fn metric(pick: MetricPick, names: &[&str]) -> Metric {
    let name_at = |i: u16| names[usize::from(i) % names.len()].to_owned();
    let (name, alias) = match pick.key {
        Key::Alias(a) => (None, Some(u64::from(a))),
        Key::Name(i) => (Some(name_at(i)), None),
        Key::Rebirth => (Some("Node Control/Rebirth".to_owned()), None),
        Key::Text(text) => (Some(text), None),
        Key::AliasAndName(a, i) => (Some(name_at(i)), Some(u64::from(a))),
    };
    let value = pick.value.map(|v| match v {
        ValuePick::Int(n) => MetricValue::Int(n),
        ValuePick::Long(n) => MetricValue::Long(n),
        ValuePick::Float(x) => MetricValue::Float(x),
        ValuePick::Double(x) => MetricValue::Double(x),
        ValuePick::Boolean(b) => MetricValue::Boolean(b),
        ValuePick::String(s) => MetricValue::String(s),
        ValuePick::Bytes(b) => MetricValue::Bytes(b),
    });
    Metric { name, alias, datatype: pick.datatype, is_null: pick.is_null, value, ..Metric::default() }
}
