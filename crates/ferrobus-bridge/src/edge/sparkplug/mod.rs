//! The Sparkplug B 3.0 edge node: births, data by exception, deaths, commands, the primary
//! host's STATE, and the records kept while the broker is away.
//!
//! See the [module doc of `edge`](super) for the rules; this file carries them out for the
//! session, the births, the data and the replay; `command.rs` takes what the broker sends
//! (NCMD, DCMD, the primary host's STATE).

mod command;

use std::time::SystemTime;

use ferrobus_tools::poll::Sample;

use super::deadband::Seen;
use super::device::{Device, Liveness, devices_of};
use super::record::Record;
use super::{DeviceRef, EdgeError, EdgeStats, Output, Publish, millis};
use crate::config::reload::{Fate, Plan};
use crate::config::{Plant, SparkplugConfig};
use crate::sparkplug::convert::{UintEncoding, datatype_of, metric_value, properties_of};
use crate::sparkplug::payload::{
    DataType, Metric, MetricValue, Payload, PropertySet, PropertyValue, PropertyValueKind,
};
use crate::sparkplug::topic::{MessageType, Topic, state_topic};

/// The node metric carrying the session's birth/death sequence number.
pub(crate) const BD_SEQ: &str = "bdSeq";
/// The node metric a host sets to true to ask for births again.
pub(crate) const REBIRTH: &str = "Node Control/Rebirth";
/// The node metric naming the software.
pub(crate) const SOFTWARE: &str = "Properties/Software";
/// The property of a metric that a host may not write.
const READ_ONLY: &str = "readOnly";
/// The property of a metric that says what it is.
const DESCRIPTION: &str = "description";

/// A device as the Sparkplug session sees it.
#[derive(Debug)]
struct SpDevice {
    device: Device,
    /// `[group][cell]`: the metric aliases, unique in the edge node.
    aliases: Vec<Vec<u64>>,
    /// Its DBIRTH went out in this session (and no DDEATH since).
    born: bool,
    /// Born at a (re)connection while dead, so that the historical data stored for it
    /// resolve: its DDEATH is due once the store is replayed (or at its next silent poll).
    death_due: bool,
}

/// The Sparkplug edge node.
#[derive(Debug)]
pub(crate) struct SparkplugEdge {
    config: SparkplugConfig,
    devices: Vec<SpDevice>,
    bd_seq: u8,
    seq: u8,
    connected: bool,
    /// The primary host's last STATE said online (always true without a primary host).
    host_online: bool,
    /// The primary host's last STATE timestamp, to ignore older ones.
    host_timestamp: Option<u64>,
    /// The NBIRTH of this session went out.
    node_born: bool,
    /// The next metric alias: never given twice in the process's life, so that a device added
    /// or changed by a reload takes aliases no live metric has.
    next_alias: u64,
    pub(crate) stats: EdgeStats,
}

impl SparkplugEdge {
    /// Its devices, in plant order.
    pub(crate) fn devices(&self) -> impl Iterator<Item = &Device> {
        self.devices.iter().map(|d| &d.device)
    }

    pub(crate) fn new(plant: &Plant, config: &SparkplugConfig) -> SparkplugEdge {
        let mut edge = SparkplugEdge {
            config: config.clone(),
            devices: Vec::new(),
            bd_seq: 0,
            seq: 0,
            connected: false,
            host_online: config.primary_host.is_none(),
            host_timestamp: None,
            node_born: false,
            next_alias: 1,
            stats: EdgeStats::default(),
        };
        edge.devices = devices_of(plant).into_iter().map(|device| edge.fresh(device)).collect();
        edge
    }

    /// A device not born yet, with aliases never given before.
    fn fresh(&mut self, device: Device) -> SpDevice {
        let aliases = device
            .groups
            .iter()
            .map(|g| {
                g.cells
                    .iter()
                    .map(|_| {
                        let alias = self.next_alias;
                        self.next_alias = self.next_alias.saturating_add(1);
                        alias
                    })
                    .collect()
            })
            .collect();
        SpDevice { device, aliases, born: false, death_due: false }
    }

    /// The plant is reloaded (`plan`, from the running plant to `plant`): an unchanged device
    /// keeps its state, aliases and birth (renumbered to its place in `plant`); a removed or
    /// changed one that is born gets its DDEATH now; a changed or added one starts unborn with
    /// new aliases (its DBIRTH comes at its first answered poll).
    pub(crate) fn reload(
        &mut self,
        plant: &Plant,
        config: &SparkplugConfig,
        plan: &Plan,
        now: SystemTime,
    ) -> Vec<Publish> {
        self.config = config.clone();
        let mut old: Vec<Option<SpDevice>> = std::mem::take(&mut self.devices).into_iter().map(Some).collect();
        let mut deaths = Vec::new();
        for &i in &plan.removed_devices {
            if let Some(d) = old.get_mut(i).and_then(Option::take) {
                deaths.push(d);
            }
        }
        let mut devices = Vec::new();
        for (device, fate) in devices_of(plant).into_iter().zip(&plan.devices) {
            let was = match fate {
                Fate::Unchanged { was } | Fate::Changed { was } => old.get_mut(*was).and_then(Option::take),
                Fate::Added => None,
            };
            match (fate, was) {
                (Fate::Unchanged { .. }, Some(mut kept)) => {
                    kept.device.at = device.at;
                    devices.push(kept);
                }
                (_, was) => {
                    deaths.extend(was);
                    devices.push(self.fresh(device));
                }
            }
        }
        self.devices = devices;
        let mut out = Vec::new();
        let online = self.node_born;
        for d in deaths.into_iter().filter(|d| d.born && online) {
            out.push(self.ddeath_of(&d.device.id, now));
        }
        out
    }

    pub(crate) fn bd_seq(&self) -> u8 {
        self.bd_seq
    }

    pub(crate) fn is_online(&self) -> bool {
        self.node_born
    }

    pub(crate) fn set_bd_seq(&mut self, bd_seq: u8) {
        self.bd_seq = bd_seq;
    }

    fn topic(&self, kind: MessageType, device: Option<&str>) -> String {
        let c = &self.config;
        match device {
            Some(d) => Topic::device(&c.group_id, kind, &c.edge_node_id, d),
            None => Topic::node(&c.group_id, kind, &c.edge_node_id),
        }
        .to_string()
    }

    fn encoding(&self) -> UintEncoding {
        self.config.uint_encoding
    }

    /// The seq of the next message, then one more (255 → 0).
    fn next_seq(&mut self) -> u64 {
        let seq = self.seq;
        self.seq = self.seq.wrapping_add(1);
        u64::from(seq)
    }

    fn publish(&self, kind: MessageType, device: Option<&str>, payload: &Payload) -> Publish {
        let qos = u8::from(kind == MessageType::NDeath);
        Publish { topic: self.topic(kind, device), payload: payload.encode(), qos, retain: false }
    }

    pub(crate) fn subscriptions(&self) -> Vec<(String, u8)> {
        let mut subs =
            vec![(self.topic(MessageType::NCmd, None), 1), (format!("{}/+", self.topic(MessageType::DCmd, None)), 1)];
        if let Some(host) = &self.config.primary_host {
            subs.push((state_topic(host), 1));
        }
        subs
    }

    fn ndeath(&self, now: Option<SystemTime>) -> Publish {
        let payload = Payload {
            timestamp: now.map(millis),
            metrics: vec![Metric::new(BD_SEQ, DataType::Int64, Some(MetricValue::Long(u64::from(self.bd_seq))))],
            ..Payload::default()
        };
        self.publish(MessageType::NDeath, None, &payload)
    }

    pub(crate) fn will(&self) -> Publish {
        self.ndeath(None)
    }

    pub(crate) fn shutdown(&mut self, now: SystemTime) -> Publish {
        self.unborn();
        self.stats.node_deaths += 1;
        self.ndeath(Some(now))
    }

    pub(crate) fn connected(&mut self, now: SystemTime) -> Vec<Publish> {
        self.connected = true;
        self.births_if_ready(now)
    }

    pub(crate) fn disconnected(&mut self) {
        self.bd_seq = self.bd_seq.wrapping_add(1);
        self.connected = false;
        self.host_online = self.config.primary_host.is_none();
        self.unborn();
    }

    /// The session's births no longer hold: nothing is published (samples are stored) until
    /// the next births.
    fn unborn(&mut self) {
        self.node_born = false;
        for d in &mut self.devices {
            d.born = false;
            d.death_due = false;
        }
    }

    /// NBIRTH and the DBIRTHs once connected and (with a primary host) the host is online.
    fn births_if_ready(&mut self, now: SystemTime) -> Vec<Publish> {
        if !self.connected || self.node_born || !self.host_online {
            return Vec::new();
        }
        self.births(now, true)
    }

    /// NBIRTH (seq 0, this session's bdSeq), then a DBIRTH for every device that answered in
    /// this run (`all`, at a connection: dead ones too, their DDEATH due after the replay) or
    /// every device born in this session (a rebirth).
    fn births(&mut self, now: SystemTime, all: bool) -> Vec<Publish> {
        self.seq = 0;
        self.node_born = true;
        let mut out = vec![self.nbirth(now)];
        for i in 0..self.devices.len() {
            let Some(d) = self.devices.get_mut(i) else { continue };
            let wanted = if all { d.device.answered_once() } else { d.born };
            if wanted {
                d.death_due = !d.device.alive();
                out.extend(self.dbirth(i, now));
            }
        }
        out
    }

    fn nbirth(&mut self, now: SystemTime) -> Publish {
        let t = millis(now);
        let rebirth = Metric {
            properties: Some(property_set(vec![(READ_ONLY, PropertyValueKind::Boolean(false))])),
            ..Metric::new(REBIRTH, DataType::Boolean, Some(MetricValue::Boolean(false)))
        };
        let software = format!("ferrobus {}", env!("CARGO_PKG_VERSION"));
        let metrics = vec![
            Metric::new(BD_SEQ, DataType::Int64, Some(MetricValue::Long(u64::from(self.bd_seq)))),
            rebirth,
            Metric::new(SOFTWARE, DataType::String, Some(MetricValue::String(software))),
        ]
        .into_iter()
        .map(|m| Metric { timestamp: Some(t), ..m })
        .collect();
        let payload = Payload { timestamp: Some(t), metrics, seq: Some(self.next_seq()), ..Payload::default() };
        self.stats.births += 1;
        self.publish(MessageType::NBirth, None, &payload)
    }

    /// The DBIRTH of device `i`: every metric with name, alias, datatype, last value (or
    /// null), timestamp and properties. Marks it born and every cell published.
    fn dbirth(&mut self, i: usize, now: SystemTime) -> Option<Publish> {
        let encoding = self.encoding();
        if i >= self.devices.len() {
            return None;
        }
        let seq = self.next_seq();
        let d = self.devices.get_mut(i)?;
        let mut metrics = Vec::new();
        for (g, group) in d.device.groups.iter().enumerate() {
            for (c, cell) in group.cells.iter().enumerate() {
                let state = d.device.state(g, c);
                let value = state.and_then(|s| value_of(&cell.point, &s.latest, encoding));
                let time = state.filter(|s| s.latest != Seen::Unread).map_or(now, |s| s.time);
                let alias = d.aliases.get(g).and_then(|a| a.get(c)).copied();
                metrics.push(Metric {
                    alias,
                    timestamp: Some(millis(time)),
                    properties: Some(birth_properties(cell)),
                    ..Metric::new(&cell.name, datatype_of(&cell.point), value)
                });
            }
        }
        d.device.mark_all_published();
        d.born = true;
        let payload = Payload { timestamp: Some(millis(now)), metrics, seq: Some(seq), ..Payload::default() };
        let id = d.device.id.clone();
        self.stats.device_births += 1;
        Some(self.publish(MessageType::DBirth, Some(&id), &payload))
    }

    fn ddeath(&mut self, i: usize, now: SystemTime) -> Option<Publish> {
        let d = self.devices.get_mut(i)?;
        d.born = false;
        d.death_due = false;
        let id = d.device.id.clone();
        Some(self.ddeath_of(&id, now))
    }

    /// The DDEATH of device `id` (the next seq).
    fn ddeath_of(&mut self, id: &str, now: SystemTime) -> Publish {
        let seq = self.next_seq();
        let payload = Payload { timestamp: Some(millis(now)), seq: Some(seq), ..Payload::default() };
        self.stats.device_deaths += 1;
        self.publish(MessageType::DDeath, Some(id), &payload)
    }

    fn index(&self, at: DeviceRef) -> Option<usize> {
        self.devices.binary_search_by_key(&at, |d| d.device.at).ok()
    }

    /// The device at `at`.
    pub(crate) fn device(&self, at: DeviceRef) -> Option<&Device> {
        self.devices.get(self.index(at)?).map(|d| &d.device)
    }

    pub(crate) fn sample(&mut self, at: DeviceRef, group: usize, sample: &Sample) -> Vec<Output> {
        let Some(i) = self.index(at) else { return Vec::new() };
        let online = self.node_born;
        let Some(d) = self.devices.get_mut(i) else { return Vec::new() };
        let Some(liveness) = d.device.apply(group, sample) else { return Vec::new() };
        let born = d.born;
        match liveness {
            Liveness::Answered { .. } if online && !born => {
                self.dbirth(i, sample.time).map(Output::Publish).into_iter().collect()
            }
            Liveness::Answered { .. } => {
                d.death_due = false;
                let changes = d.device.changes(group);
                if changes.is_empty() {
                    return Vec::new();
                }
                d.device.mark_published(group, &changes);
                if online {
                    self.ddata(i, group, &changes, sample.time).map(Output::Publish).into_iter().collect()
                } else {
                    vec![Output::Store(self.record(i, group, &changes, sample.time))]
                }
            }
            Liveness::Silent { died, .. } => {
                let dies = online && born && (died || d.death_due);
                if dies { self.ddeath(i, sample.time).map(Output::Publish).into_iter().collect() } else { Vec::new() }
            }
        }
    }

    /// The metric of cell `(g, c)` of device `i` with its latest value, and `named` or aliased.
    fn data_metric(&self, i: usize, g: usize, c: usize, named: bool) -> Option<Metric> {
        let d = self.devices.get(i)?;
        let cell = d.device.cell(g, c)?;
        let state = d.device.state(g, c)?;
        let value = value_of(&cell.point, &state.latest, self.encoding());
        let mut metric = Metric {
            timestamp: Some(millis(state.time)),
            is_null: value.is_none().then_some(true),
            value,
            ..Metric::default()
        };
        if named {
            metric.name = Some(cell.name.clone());
            metric.datatype = Some(datatype_of(&cell.point).number());
        } else {
            metric.alias = d.aliases.get(g).and_then(|a| a.get(c)).copied();
        }
        Some(metric)
    }

    fn ddata(&mut self, i: usize, g: usize, cells: &[usize], time: SystemTime) -> Option<Publish> {
        let metrics: Vec<Metric> = cells.iter().filter_map(|&c| self.data_metric(i, g, c, false)).collect();
        let id = self.devices.get(i)?.device.id.clone();
        let seq = self.next_seq();
        let payload = Payload { timestamp: Some(millis(time)), metrics, seq: Some(seq), ..Payload::default() };
        self.stats.data += 1;
        Some(self.publish(MessageType::DData, Some(&id), &payload))
    }

    /// What the DDATA would have carried, by metric name, for the store.
    fn record(&mut self, i: usize, g: usize, cells: &[usize], time: SystemTime) -> Vec<u8> {
        let metrics: Vec<Metric> = cells.iter().filter_map(|&c| self.data_metric(i, g, c, true)).collect();
        let device = self.devices.get(i).map(|d| d.device.id.clone()).unwrap_or_default();
        let payload = Payload { timestamp: Some(millis(time)), metrics, ..Payload::default() };
        self.stats.stored += 1;
        Record::Sparkplug { device, payload: payload.encode() }.encode()
    }

    /// A stored record as historical DDATA under the aliases of the current births. A device
    /// not born now gives nothing, or with `birth` its DBIRTH first (the values known, null
    /// for the rest; its DDEATH due after the replay, unless it answers meanwhile).
    pub(crate) fn replay(&mut self, record: Record, now: SystemTime, birth: bool) -> Result<Vec<Publish>, EdgeError> {
        if !self.node_born {
            return Err(EdgeError::Offline);
        }
        let Record::Sparkplug { device, payload } = record else {
            return Err(EdgeError::Record("a plain-mode record, and the bridge speaks Sparkplug".to_string()));
        };
        let stored = Payload::decode(&payload).map_err(|e| EdgeError::Record(format!("device {device:?}: {e}")))?;
        let found = self.devices.iter().position(|d| d.device.id == device);
        let Some((i, born)) = found.and_then(|i| self.devices.get(i).map(|d| (i, d.born))).filter(|(_, b)| *b || birth)
        else {
            self.stats.unmapped += 1;
            return Ok(Vec::new());
        };
        let metrics: Vec<Metric> = stored.metrics.into_iter().filter_map(|m| self.historical(i, m)).collect();
        if metrics.is_empty() {
            self.stats.unmapped += 1;
            return Ok(Vec::new());
        }
        let mut out = Vec::new();
        if !born {
            if let Some(d) = self.devices.get_mut(i) {
                d.death_due = !d.device.alive();
            }
            out.extend(self.dbirth(i, now));
        }
        let seq = self.next_seq();
        let payload = Payload { timestamp: Some(millis(now)), metrics, seq: Some(seq), ..Payload::default() };
        self.stats.replayed += 1;
        out.push(self.publish(MessageType::DData, Some(&device), &payload));
        Ok(out)
    }

    /// A stored metric as historical data of device `i` under its alias of the current
    /// births; None when the device has no such metric (of that datatype) any more.
    fn historical(&mut self, i: usize, stored: Metric) -> Option<Metric> {
        let d = self.devices.get(i)?;
        let found = stored.name.as_deref().and_then(|n| d.device.find(n)).filter(|&(g, c)| {
            d.device.cell(g, c).is_some_and(|cell| Some(datatype_of(&cell.point).number()) == stored.datatype)
        });
        let Some((g, c)) = found else {
            self.stats.unmapped_metrics += 1;
            return None;
        };
        Some(Metric {
            name: None,
            datatype: None,
            alias: d.aliases.get(g).and_then(|a| a.get(c)).copied(),
            is_historical: Some(true),
            ..stored
        })
    }

    /// After the store was replayed: the DDEATH of every device born dead at the connection.
    pub(crate) fn replayed(&mut self, now: SystemTime) -> Vec<Publish> {
        if !self.node_born {
            return Vec::new();
        }
        let due: Vec<usize> =
            (0..self.devices.len()).filter(|&i| self.devices.get(i).is_some_and(|d| d.death_due)).collect();
        due.into_iter().filter_map(|i| self.ddeath(i, now)).collect()
    }
}

/// The metric value of a reading; None (null) when unread, failed, or not of the point's type.
fn value_of(point: &ferrobus_profile::Point, seen: &Seen, encoding: UintEncoding) -> Option<MetricValue> {
    match seen {
        Seen::Value(raw) => metric_value(point, raw, encoding),
        Seen::Unread | Seen::Failed(_) => None,
    }
}

/// A birth metric's properties: engineering unit, description (the point's label), and
/// whether it is read only.
fn birth_properties(cell: &ferrobus_tools::poll::Cell) -> PropertySet {
    let mut set = properties_of(&cell.point).unwrap_or_default();
    let point = &cell.point;
    let description = if point.label.is_empty() { &point.description } else { &point.label };
    if !description.is_empty() {
        set.keys.push(DESCRIPTION.to_string());
        set.values.push(property(PropertyValueKind::String(description.clone())));
    }
    set.keys.push(READ_ONLY.to_string());
    set.values.push(property(PropertyValueKind::Boolean(!point.writable())));
    set
}

fn property(value: PropertyValueKind) -> PropertyValue {
    let datatype = match &value {
        PropertyValueKind::Boolean(_) => DataType::Boolean,
        _ => DataType::String,
    };
    PropertyValue { r#type: Some(datatype.number()), is_null: None, value: Some(value) }
}

fn property_set(entries: Vec<(&str, PropertyValueKind)>) -> PropertySet {
    let (keys, values) = entries.into_iter().map(|(k, v)| (k.to_string(), property(v))).unzip();
    PropertySet { keys, values }
}
