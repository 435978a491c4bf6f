//! Plain mode: every point a JSON message on its own topic, for consumers that do not speak
//! Sparkplug (dashboards, Node-RED, Telegraf).
//!
//! ```text
//!   PREFIX/DEVICE/POINT          {"value":60.0,"unit":"Hz","timestamp":"2026-12-02T01:02:03.456Z","quality":"good"}
//!                                 the value at the point's resolution; an enumeration's or a bit
//!                                 field's with its "meaning": {"value":3,"meaning":"run",...}
//!                                 quality "bad" (value null) when the read failed, "stale" (the last
//!                                 value) when the device did not answer, both with an "error";
//!                                 "historical":true when replayed from the store; retained if configured
//!   PREFIX/DEVICE/status         "online" / "offline" (retained)
//!   PREFIX/status                "online" at the connection (then the devices' status and, with
//!                                 retain, every point's last value again); the Will "offline" (retained)
//!   PREFIX/DEVICE/POINT/set      a write: "45", "45 Hz", "on", or {"value":45}
//!   PREFIX/DEVICE/POINT/set/result  {"ok":true,"value":"45"} or {"ok":false,"value":"45","error":"..."}
//!   DISCOVERY/COMPONENT/NODE/OBJECT/config  with `discovery`, Home Assistant's config of each point
//!                                 at the connection (retained; see `discovery.rs`)
//! ```

use std::collections::{HashMap, VecDeque};
use std::time::SystemTime;

use ferrobus_profile::Value;
use ferrobus_tools::poll::{Cell, Sample, iso8601_ms};

use super::deadband::Seen;
use super::device::{Device, Liveness, devices_of};
use super::discovery;
use super::record::Record;
use super::{Action, DeviceRef, EdgeError, EdgeStats, Output, Publish, Reply};
use crate::config::reload::{Fate, Plan};
use crate::config::{PlainConfig, Plant};
use crate::sparkplug::convert::is_scaled;

/// A device in plain mode.
#[derive(Debug)]
struct PlainDevice {
    device: Device,
    /// `[group]`: the group's points were last published as stale.
    stale: Vec<bool>,
}

/// The plain-mode edge.
#[derive(Debug)]
pub(crate) struct PlainEdge {
    config: PlainConfig,
    devices: Vec<PlainDevice>,
    connected: bool,
    /// With `discovery`: Home Assistant's config of every point, published at each connection.
    discovery: Vec<Publish>,
    /// The values of the writes asked and not yet [`PlainEdge::written`], by cell, oldest first.
    pending: HashMap<(DeviceRef, usize, usize), VecDeque<String>>,
    /// What a reload while offline owes the broker at the next connection: the discovery
    /// configs of removed points (empty, retained) and the status of removed devices.
    owed: Vec<Publish>,
    pub(crate) stats: EdgeStats,
}

/// Writes of one cell remembered for their results; older ones are forgotten past this.
const PENDING_PER_CELL: usize = 16;

/// The quality of a point's message.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Quality {
    Good,
    Bad,
    Stale,
}

impl PlainEdge {
    /// Its devices, in plant order.
    pub(crate) fn devices(&self) -> impl Iterator<Item = &Device> {
        self.devices.iter().map(|d| &d.device)
    }

    pub(crate) fn new(plant: &Plant, config: &PlainConfig) -> PlainEdge {
        let devices = devices_of(plant)
            .into_iter()
            .map(|device| {
                let stale = vec![false; device.groups.len()];
                PlainDevice { device, stale }
            })
            .collect();
        let discovery = config.discovery.as_deref().map(|at| discovery::configs(plant, config, at)).unwrap_or_default();
        PlainEdge {
            config: config.clone(),
            devices,
            connected: false,
            discovery,
            pending: HashMap::new(),
            owed: Vec::new(),
            stats: EdgeStats::default(),
        }
    }

    /// The plant is reloaded (`plan`, from the running plant to `plant`): an unchanged device
    /// keeps its state (renumbered to its place in `plant`), a changed or added one starts
    /// afresh; a removed one's status becomes "offline"; with `discovery`, the configs of the
    /// points gone are removed (empty, retained) and the new or changed ones published. Offline,
    /// what is owed goes out at the next connection (after the bridge's status).
    pub(crate) fn reload(&mut self, plant: &Plant, config: &PlainConfig, plan: &Plan) -> Vec<Publish> {
        let mut old: Vec<Option<PlainDevice>> = std::mem::take(&mut self.devices).into_iter().map(Some).collect();
        let mut moved: HashMap<DeviceRef, DeviceRef> = HashMap::new();
        let mut devices = Vec::new();
        for (device, fate) in devices_of(plant).into_iter().zip(&plan.devices) {
            let kept = match fate {
                Fate::Unchanged { was } => old.get_mut(*was).and_then(Option::take),
                Fate::Changed { .. } | Fate::Added => None,
            };
            if let Some(mut kept) = kept {
                moved.insert(kept.device.at, device.at);
                kept.device.at = device.at;
                devices.push(kept);
            } else {
                let stale = vec![false; device.groups.len()];
                devices.push(PlainDevice { device, stale });
            }
        }
        self.devices = devices;
        self.pending = std::mem::take(&mut self.pending)
            .into_iter()
            .filter_map(|((at, g, c), q)| Some(((*moved.get(&at)?, g, c), q)))
            .collect();
        let mut out = Vec::new();
        for i in &plan.removed_devices {
            let id = plan_device_id(&old, *i);
            if let Some(id) = id {
                out.push(Self::status(format!("{}/{id}/status", config.prefix), "offline"));
            }
        }
        let discovery = config.discovery.as_deref().map(|at| discovery::configs(plant, config, at)).unwrap_or_default();
        for gone in self.discovery.iter().filter(|o| !discovery.iter().any(|n| n.topic == o.topic)) {
            out.push(Publish { payload: Vec::new(), ..gone.clone() });
        }
        out.extend(discovery.iter().filter(|n| !self.discovery.contains(n)).cloned());
        self.discovery = discovery;
        self.config = config.clone();
        if self.connected {
            self.stats.data += out.len() as u64;
            return out;
        }
        // Offline: the new configs go out with the connection's; the rest is owed.
        let published = &self.discovery;
        self.owed.extend(out.into_iter().filter(|m| !published.contains(m)));
        Vec::new()
    }

    fn status_topic(&self) -> String {
        format!("{}/status", self.config.prefix)
    }

    fn status(topic: String, text: &str) -> Publish {
        Publish { topic, payload: text.as_bytes().to_vec(), qos: 1, retain: true }
    }

    pub(crate) fn subscriptions(&self) -> Vec<(String, u8)> {
        vec![(format!("{}/+/+/set", self.config.prefix), self.config.qos)]
    }

    pub(crate) fn will(&self) -> Publish {
        Self::status(self.status_topic(), "offline")
    }

    pub(crate) fn shutdown(&mut self) -> Publish {
        self.connected = false;
        self.will()
    }

    /// The bridge's status, Home Assistant's discovery configs (with `discovery`), each known
    /// device's status, and with `retain` the last value of every point read (what the broker retains must not stay as it was before the outage; the
    /// values taken meanwhile follow as historical, unretained, from the store).
    pub(crate) fn connected(&mut self) -> Vec<Publish> {
        self.connected = true;
        let mut out = vec![Self::status(self.status_topic(), "online")];
        out.append(&mut self.owed);
        out.extend(self.discovery.iter().cloned());
        for d in self.devices.iter().filter(|d| d.device.answered_once()) {
            out.push(self.device_status(&d.device));
            if !self.config.retain {
                continue;
            }
            for (g, group) in d.device.groups.iter().enumerate() {
                if d.stale.get(g).copied().unwrap_or(true) {
                    continue;
                }
                out.extend((0..group.cells.len()).filter_map(|c| self.point_message(&d.device, g, c, None)));
            }
        }
        out
    }

    pub(crate) fn is_online(&self) -> bool {
        self.connected
    }

    pub(crate) fn disconnected(&mut self) {
        self.connected = false;
    }

    fn device_status(&self, device: &Device) -> Publish {
        let text = if device.alive() { "online" } else { "offline" };
        Self::status(format!("{}/{}/status", self.config.prefix, device.id), text)
    }

    /// The device at `at`.
    pub(crate) fn device(&self, at: DeviceRef) -> Option<&Device> {
        let i = self.devices.binary_search_by_key(&at, |d| d.device.at).ok()?;
        self.devices.get(i).map(|d| &d.device)
    }

    pub(crate) fn sample(&mut self, at: DeviceRef, group: usize, sample: &Sample) -> Vec<Output> {
        let Some(i) = self.devices.binary_search_by_key(&at, |d| d.device.at).ok() else { return Vec::new() };
        let Some(d) = self.devices.get_mut(i) else { return Vec::new() };
        let Some(liveness) = d.device.apply(group, sample) else { return Vec::new() };
        let count = d.device.groups.get(group).map_or(0, |g| g.cells.len());
        let was_stale = d.stale.get(group).copied().unwrap_or(false);
        let answered = matches!(liveness, Liveness::Answered { .. });
        if let Some(stale) = d.stale.get_mut(group) {
            *stale = !answered;
        }
        let (cells, stale, status) = match liveness {
            // Back from stale: every point again, good; else what moved beyond its deadband.
            Liveness::Answered { back, .. } => {
                let cells = if was_stale { (0..count).collect() } else { d.device.changes(group) };
                d.device.mark_published(group, &cells);
                (cells, None, back)
            }
            // The first silent poll of the group: its points stale, once.
            Liveness::Silent { died, .. } => {
                let error = match &sample.result {
                    Err(failure) => failure.diagnosis.clone(),
                    Ok(_) => "no reply".to_string(),
                };
                let fresh = !was_stale && d.device.answered_once();
                let cells = if fresh { (0..count).collect() } else { Vec::new() };
                (cells, Some(error), died)
            }
        };
        let Some(d) = self.devices.get(i) else { return Vec::new() };
        let mut messages: Vec<Publish> = Vec::new();
        if status {
            messages.push(self.device_status(&d.device));
        }
        let stale = stale.as_deref().map(|e| (e, sample.time));
        messages.extend(cells.into_iter().filter_map(|c| self.point_message(&d.device, group, c, stale)));
        if self.connected {
            self.stats.data += messages.len() as u64;
            return messages.into_iter().map(Output::Publish).collect();
        }
        // Offline: the points' messages are stored; statuses are sent again at the connection.
        let stored: Vec<Output> = messages
            .into_iter()
            .filter(|m| !m.topic.ends_with("/status"))
            .map(|m| Output::Store(Record::Plain { topic: m.topic, payload: m.payload }.encode()))
            .collect();
        self.stats.stored += stored.len() as u64;
        stored
    }

    /// The message of cell `(g, c)`: its latest reading, or `stale` with the failed poll's
    /// error and time.
    fn point_message(
        &self,
        device: &Device,
        g: usize,
        c: usize,
        failure: Option<(&str, SystemTime)>,
    ) -> Option<Publish> {
        let cell = device.cell(g, c)?;
        let state = device.state(g, c)?;
        let (value, quality, error, time) = match (&state.latest, failure) {
            (seen, Some((error, time))) => (json_value(cell, seen), Quality::Stale, Some(error.to_string()), time),
            (seen @ Seen::Value(_), None) => (json_value(cell, seen), Quality::Good, None, state.time),
            (Seen::Failed(why), None) => ("null".to_string(), Quality::Bad, Some(why.clone()), state.time),
            (Seen::Unread, None) => return None,
        };
        let meaning = match &state.latest {
            Seen::Value(raw) => cell.point.meaning(raw),
            _ => None,
        };
        let json = point_json(&value, meaning.as_deref(), cell.unit(), &iso8601_ms(time), quality, error.as_deref());
        Some(Publish {
            topic: format!("{}/{}/{}", self.config.prefix, device.id, cell.name),
            payload: json.into_bytes(),
            qos: self.config.qos,
            retain: self.config.retain,
        })
    }

    pub(crate) fn replay(&mut self, record: Record) -> Result<Option<Publish>, EdgeError> {
        if !self.connected {
            return Err(EdgeError::Offline);
        }
        let Record::Plain { topic, payload } = record else {
            return Err(EdgeError::Record("a Sparkplug record, and the bridge speaks plain JSON".to_string()));
        };
        let text = std::str::from_utf8(&payload).map_err(|e| EdgeError::Record(format!("{topic}: not UTF-8: {e}")))?;
        let fields: serde_json::Map<String, serde_json::Value> = serde_json::from_str(text)
            .map_err(|e| EdgeError::Record(format!("{topic}: not a JSON object ({e}): {text:?}")))?;
        // The message as it was, its fields in their order, then the flag.
        let open = text.trim_end().strip_suffix('}').unwrap_or("{");
        let comma = if fields.is_empty() { "" } else { "," };
        let payload = format!("{open}{comma}\"historical\":true}}").into_bytes();
        self.stats.replayed += 1;
        Ok(Some(Publish { topic, payload, qos: self.config.qos, retain: false }))
    }

    pub(crate) fn message(&mut self, topic: &str, payload: &[u8]) -> Reply {
        let Some((device, point)) = self.set_target(topic) else {
            self.stats.ignored += 1;
            return (Vec::new(), Vec::new(), Vec::new());
        };
        match self.write_of(&device, &point, payload) {
            Ok(action) => {
                self.stats.writes += 1;
                if let Action::Write { device, group, cell, typed, .. } = &action {
                    let queue = self.pending.entry((*device, *group, *cell)).or_default();
                    if queue.len() == PENDING_PER_CELL {
                        queue.pop_front();
                    }
                    queue.push_back(typed.clone());
                }
                (Vec::new(), vec![action], Vec::new())
            }
            Err(reason) => {
                self.stats.refused += 1;
                let typed = set_text(payload).ok();
                let result = self.result(&device, &point, typed.as_deref(), &Err(reason.clone()));
                let error = EdgeError::refused("set", &device, &point, &reason);
                (vec![result], Vec::new(), vec![error])
            }
        }
    }

    /// The device and point of a `PREFIX/DEVICE/POINT/set` topic.
    fn set_target(&self, topic: &str) -> Option<(String, String)> {
        let rest = topic.strip_prefix(&self.config.prefix)?.strip_prefix('/')?.strip_suffix("/set")?;
        let (device, point) = rest.split_once('/')?;
        (!device.is_empty() && !point.is_empty()).then(|| (device.to_string(), point.to_string()))
    }

    fn write_of(&self, device: &str, point: &str, payload: &[u8]) -> Result<Action, String> {
        let d = self.devices.iter().find(|d| d.device.id == device).ok_or("no such device")?;
        let (g, c) = d.device.find(point).ok_or("the device publishes no such point")?;
        let cell = d.device.cell(g, c).ok_or("no such point")?;
        let typed = set_text(payload)?;
        let raw = cell.point.prepare_write(&typed).map_err(|e| e.to_string())?;
        Ok(Action::Write { device: d.device.at, group: g, cell: c, raw, typed })
    }

    /// `{"ok":true,"value":"45"}` or `{"ok":false,"value":"45","error":"..."}` on the point's
    /// `.../set/result` (the value as the write gave it, when known).
    fn result(&self, device: &str, point: &str, typed: Option<&str>, result: &Result<(), String>) -> Publish {
        let mut payload = format!("{{\"ok\":{}", result.is_ok());
        if let Some(typed) = typed {
            payload.push_str(",\"value\":");
            payload.push_str(&json_string(typed));
        }
        if let Err(e) = result {
            payload.push_str(",\"error\":");
            payload.push_str(&json_string(e));
        }
        payload.push('}');
        Publish {
            topic: format!("{}/{device}/{point}/set/result", self.config.prefix),
            payload: payload.into_bytes(),
            qos: self.config.qos,
            retain: false,
        }
    }

    pub(crate) fn written(
        &mut self,
        at: DeviceRef,
        group: usize,
        cell: usize,
        result: &Result<(), String>,
    ) -> Vec<Publish> {
        let typed = self.pending.get_mut(&(at, group, cell)).and_then(VecDeque::pop_front);
        if self.pending.get(&(at, group, cell)).is_some_and(VecDeque::is_empty) {
            self.pending.remove(&(at, group, cell));
        }
        let Some(d) = self.devices.iter().find(|d| d.device.at == at) else { return Vec::new() };
        let Some(cell) = d.device.cell(group, cell) else { return Vec::new() };
        vec![self.result(&d.device.id, &cell.name, typed.as_deref(), result)]
    }
}

/// The text of a write's payload: as typed (`45`, `45 Hz`, `run`), or a JSON object's `value`.
fn set_text(payload: &[u8]) -> Result<String, String> {
    let text = std::str::from_utf8(payload).map_err(|e| format!("the payload is not UTF-8: {e}"))?.trim();
    if !text.starts_with('{') {
        if text.is_empty() {
            return Err("an empty payload; send a value (\"45\", \"45 Hz\", {\"value\":45})".to_string());
        }
        return Ok(text.to_string());
    }
    let json: serde_json::Value = serde_json::from_str(text).map_err(|e| format!("not JSON: {e}"))?;
    match json.get("value") {
        Some(serde_json::Value::Number(n)) => Ok(n.to_string()),
        Some(serde_json::Value::String(s)) => Ok(s.clone()),
        Some(serde_json::Value::Bool(b)) => Ok(b.to_string()),
        Some(other) => Err(format!("\"value\" is {other}, not a number, text or boolean")),
        None => Err(format!("{text} has no \"value\"")),
    }
}

/// A reading's value in JSON: the engineering value of a scaled point at its resolution
/// ([`ferrobus_profile::Point::engineering`]: 34.98, not 34.980000000000004), an integer as
/// such, a bit as a boolean, a text as a string; `null` when there is none.
fn json_value(cell: &Cell, seen: &Seen) -> String {
    let Seen::Value(raw) = seen else { return "null".to_string() };
    if !cell.point.implemented(raw) {
        return "null".to_string(); // the device's "not implemented" value (SunSpec's 0xFFFF, ...)
    }
    match raw {
        Value::Bool(b) => b.to_string(),
        Value::Text(s) => json_string(s),
        Value::Int(n) if !is_scaled(&cell.point) => n.to_string(),
        number => match cell.scaled(number) {
            Some(x) if x.is_finite() => serde_json::Value::from(x).to_string(),
            _ => "null".to_string(),
        },
    }
}

fn json_string(text: &str) -> String {
    serde_json::Value::from(text).to_string()
}

/// A point's message: its value, an enumeration's or a bit field's meaning (`"run"`), unit,
/// time, quality and error.
fn point_json(
    value: &str,
    meaning: Option<&str>,
    unit: Option<&str>,
    timestamp: &str,
    quality: Quality,
    error: Option<&str>,
) -> String {
    let mut json = format!("{{\"value\":{value}");
    if let Some(meaning) = meaning {
        json.push_str(",\"meaning\":");
        json.push_str(&json_string(meaning));
    }
    if let Some(unit) = unit.filter(|u| !u.is_empty()) {
        json.push_str(",\"unit\":");
        json.push_str(&json_string(unit));
    }
    let quality = match quality {
        Quality::Good => "good",
        Quality::Bad => "bad",
        Quality::Stale => "stale",
    };
    json.push_str(",\"timestamp\":");
    json.push_str(&json_string(timestamp));
    json.push_str(",\"quality\":");
    json.push_str(&json_string(quality));
    if let Some(error) = error {
        json.push_str(",\"error\":");
        json.push_str(&json_string(error));
    }
    json.push('}');
    json
}

/// The id of running device `i` (`old`, taken or not).
fn plan_device_id(old: &[Option<PlainDevice>], i: usize) -> Option<String> {
    old.get(i).and_then(Option::as_ref).map(|d| d.device.id.clone())
}
