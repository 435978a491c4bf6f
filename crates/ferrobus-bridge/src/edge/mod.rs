//! The edge node without IO: what each sample, connection and command publishes, as Sparkplug
//! B 3.0 or as plain JSON. No sockets, no files, no clock: the runtime ([`crate::run`]) hands
//! in samples, broker events and the time, and sends what comes out.
//!
//! ```text
//!   will() ─────────────▶ the Will of the next CONNECT (NDEATH with its bdSeq)
//!   connected(now) ─────▶ NBIRTH, DBIRTHs          (or, with a primary host, after its STATE)
//!   sample(device, ..) ─▶ DBIRTH | DDATA | DDEATH  (offline: Output::Store records)
//!   replay_all(record) ─▶ historical DDATA          (after the births, in the store's order)
//!   replayed(now) ──────▶ DDEATH of the devices born dead at the connection
//!   message(topic, ..) ─▶ rebirths, Action::Write, Action::Reconnect, refusals
//!   disconnected() ─────  the next CONNECT takes the next bdSeq
//!   shutdown(now) ──────▶ NDEATH before an intentional disconnect
//! ```
//!
//! # Sparkplug B
//!
//! - **Session.** [`Edge::will`] is the NDEATH (only the `bdSeq` metric, no seq, QoS 1, not
//!   retained) to register in CONNECT; [`Edge::connected`]'s NBIRTH carries the same bdSeq;
//!   [`Edge::disconnected`] moves to the next (255 → 0). [`Edge::bd_seq`] and
//!   [`Edge::set_bd_seq`] let the runtime keep it across restarts. One seq per edge node,
//!   +1 per message (NBIRTH, DBIRTH, DDATA, DDEATH), 255 → 0; every NBIRTH has seq 0.
//! - **Aliases** are numbered from 1 in line, device, group and cell order: the same plant
//!   gives the same aliases. [`Edge::reload`] keeps an unchanged device's and gives an added
//!   or changed device new ones from a counter that never gives a number twice. Node metrics
//!   (`bdSeq`, `Node Control/Rebirth`, `Properties/Software`) have none.
//! - **Births.** NBIRTH: `bdSeq` (Int64), `Node Control/Rebirth` (Boolean false, writable),
//!   `Properties/Software`. A device is born at its first answered poll: its DBIRTH has every
//!   metric (name, alias, datatype, last value or null, timestamp, properties `engUnit`,
//!   `description` from the point's label, `readOnly`).
//! - **Data by exception.** DDATA has aliases only, no datatype: the cells that moved beyond
//!   their deadband from the value last published (0: any change; a bit or text: any change),
//!   one DDATA per sample, each metric stamped with the sample's time. A failed read (an
//!   exception reply) publishes its group's metrics once as null.
//! - **Deaths.** After `death_after` polls in a row without a reply: DDEATH. The next answered
//!   poll: DBIRTH again, with the values known.
//! - **Offline** (before [`Edge::connected`], after [`Edge::disconnected`] or
//!   [`Edge::shutdown`], while waiting for the primary host or after its STATE offline; see
//!   [`Edge::is_online`]): the DDATA that would have been published become [`Output::Store`]
//!   records, by metric name and datatype (see `record.rs`), so they still mean the same after
//!   a restart. Births and deaths are not stored: they are a session's, and the broker's Will
//!   said the node died. At the connection the NBIRTH is followed by a DBIRTH for **every
//!   device that answered at least once in this run**, alive or not, so that every stored
//!   record's metrics resolve to an alias of the current births; [`Edge::replay`] turns each
//!   record into DDATA with those aliases, `is_historical` on each metric, the original
//!   timestamps and the next seq. A device that is dead at the connection gets its DDEATH
//!   when the runtime says the store is replayed ([`Edge::replayed`]), or at its next silent
//!   poll, whichever comes first; so its history arrives while it is born, as the specification
//!   wants DATA between BIRTH and DEATH. A record of a device that is configured but not born
//!   now (not answered since a restart of the bridge, or dead since the connection):
//!   [`Edge::replay_all`] sends its DBIRTH first (values known, null for the rest) and its
//!   DDEATH the same way; [`Edge::replay`] gives `None`. A record of a device or metrics gone
//!   from the plant maps to nothing, counted in [`EdgeStats::unmapped`].
//! - **Commands.** NCMD `Node Control/Rebirth` = true: NBIRTH and the DBIRTHs of the born
//!   devices again, same bdSeq. DCMD: each metric (by alias, else by name) is converted to the
//!   point's raw value and checked by the profile (access, range); a command with any refused
//!   metric, or with more than [`MAX_METRICS_PER_COMMAND`] metrics, writes nothing and returns
//!   an [`EdgeError`] per refusal. The runtime puts an accepted command through the profile's
//!   write guard (a run-locked metric while the drive runs refuses it whole), writes its
//!   metrics in order and stops at the first the bus fails (it says which were written: a bus
//!   cannot undo).
//! - **Primary host.** With `primary_host` set, births wait for its STATE `{"online":true}`
//!   (held if [`Edge::connected`] came first; samples meanwhile are stored); `online:false`
//!   while born → [`Action::Reconnect`]. A STATE older than the last one is ignored.
//!
//! # Plain JSON
//!
//! See `plain.rs`: `PREFIX/DEVICE/POINT` messages by exception with the same deadbands,
//! device and bridge status topics, writes on `.../set` with the result on `.../set/result`;
//! with `discovery`, Home Assistant's MQTT discovery config of every point at each connection
//! (`discovery.rs`).

mod deadband;
mod device;
mod discovery;
mod plain;
mod record;
mod sparkplug;

use std::time::SystemTime;

use ferrobus_profile::Value;
use ferrobus_tools::poll::Sample;

use crate::config::reload::Plan;
use crate::config::{Mode, Plant};
pub(crate) use device::{Device, Liveness};
#[cfg(test)]
pub(crate) use device::{Health, answered};
use plain::PlainEdge;
use record::Record;
use sparkplug::SparkplugEdge;

/// The most metrics one DCMD may write: a command with more is refused whole (the bus takes
/// a write at a time, and one message must not queue thousands of them).
pub const MAX_METRICS_PER_COMMAND: usize = 64;

/// A device of the plant: indexes into `Plant.lines[line].devices[device]` (ordered by line,
/// then device).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct DeviceRef {
    /// The line's index.
    pub line: usize,
    /// The device's index on its line.
    pub device: usize,
}

/// An MQTT message to publish.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Publish {
    /// Its topic.
    pub topic: String,
    /// Its payload.
    pub payload: Vec<u8>,
    /// Its QoS (0, 1 or 2).
    pub qos: u8,
    /// Whether the broker retains it.
    pub retain: bool,
}

/// What a sample gives.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Output {
    /// A message to publish now.
    Publish(Publish),
    /// The broker is offline: a record for the store, to [`Edge::replay`] later.
    Store(Vec<u8>),
}

/// What the runtime is asked to do.
#[derive(Clone, Debug, PartialEq)]
pub enum Action {
    /// Write `raw` to cell `cell` of group `group` of `device` (checked by the profile).
    Write {
        /// The device.
        device: DeviceRef,
        /// The group's index in the device's groups.
        group: usize,
        /// The cell's index in the group.
        cell: usize,
        /// The raw value to write.
        raw: Value,
        /// The value as the command gave it, for messages.
        typed: String,
    },
    /// The primary host went offline: NDEATH, disconnect, connect again.
    Reconnect,
}

/// A command or record the edge refused.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum EdgeError {
    /// A command (NCMD, DCMD, a plain `set`) asked for something that is not done.
    #[error("{command} {target}: {metric}: refused: {reason}")]
    Refused {
        /// `NCMD`, `DCMD` or `set`.
        command: &'static str,
        /// The edge node or device.
        target: String,
        /// The metric or point.
        metric: String,
        /// Why.
        reason: String,
    },
    /// A message whose payload is not what its topic takes.
    #[error("{topic}: {detail}")]
    Malformed {
        /// The topic.
        topic: String,
        /// What was seen.
        detail: String,
    },
    /// A store record that cannot be read.
    #[error("a stored record: {0}")]
    Record(String),
    /// [`Edge::replay`] while not online (not connected, or births not out yet): keep the
    /// record and replay it after the births.
    #[error("not online: a record is replayed after the births")]
    Offline,
}

impl EdgeError {
    /// A refusal; a reason that starts with the metric's name (the profile's words) is not
    /// made to say it twice.
    fn refused(command: &'static str, target: &str, metric: &str, reason: &str) -> EdgeError {
        let reason = reason.strip_prefix(metric).and_then(|r| r.strip_prefix(": ")).unwrap_or(reason);
        EdgeError::Refused {
            command,
            target: target.to_string(),
            metric: metric.to_string(),
            reason: reason.to_string(),
        }
    }
}

/// What a message from the broker gives: messages to publish, actions, refusals.
type Reply = (Vec<Publish>, Vec<Action>, Vec<EdgeError>);

/// What the edge published and refused.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EdgeStats {
    /// NBIRTH messages.
    pub births: u64,
    /// DBIRTH messages.
    pub device_births: u64,
    /// DDATA messages (plain mode: point and status messages).
    pub data: u64,
    /// DDEATH messages.
    pub device_deaths: u64,
    /// NDEATH messages of [`Edge::shutdown`].
    pub node_deaths: u64,
    /// Rebirths asked by NCMD.
    pub rebirths: u64,
    /// Records handed to the store.
    pub stored: u64,
    /// Records replayed.
    pub replayed: u64,
    /// Records that no longer map (device not born, or no metric left).
    pub unmapped: u64,
    /// Metrics of replayed records that no longer exist (or changed datatype).
    pub unmapped_metrics: u64,
    /// Writes asked.
    pub writes: u64,
    /// Commands or metrics refused.
    pub refused: u64,
    /// Messages on topics the edge does not take.
    pub ignored: u64,
}

/// The edge node: Sparkplug B or plain JSON, as the plant's mode says.
#[derive(Debug)]
pub struct Edge {
    inner: Inner,
}

/// A point's latest reading ([`Edge::readings`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Reading {
    /// The device's id.
    pub device: String,
    /// The point, as its metric is named.
    pub point: String,
    /// The value as shown (`50.00 Hz`, `run`), or why the read failed.
    pub shown: String,
    /// When it was read.
    pub time: SystemTime,
    /// Whether the read failed (an exception, registers that do not decode).
    pub failed: bool,
}

#[derive(Debug)]
enum Inner {
    Sparkplug(Box<SparkplugEdge>),
    Plain(Box<PlainEdge>),
}

impl Edge {
    /// The edge node of `plant`, offline, bdSeq 0.
    pub fn new(plant: &Plant) -> Edge {
        let inner = match &plant.mode {
            Mode::Sparkplug(config) => Inner::Sparkplug(Box::new(SparkplugEdge::new(plant, config))),
            Mode::Plain(config) => Inner::Plain(Box::new(PlainEdge::new(plant, config))),
        };
        Edge { inner }
    }

    /// The topics to subscribe to, with their QoS: NCMD, DCMD (and the primary host's STATE),
    /// or `PREFIX/+/+/set`.
    pub fn subscriptions(&self) -> Vec<(String, u8)> {
        match &self.inner {
            Inner::Sparkplug(s) => s.subscriptions(),
            Inner::Plain(p) => p.subscriptions(),
        }
    }

    /// The Will of the next CONNECT: NDEATH with its bdSeq (QoS 1, not retained), or
    /// `PREFIX/status` "offline" (retained).
    pub fn will(&self) -> Option<Publish> {
        match &self.inner {
            Inner::Sparkplug(s) => Some(s.will()),
            Inner::Plain(p) => Some(p.will()),
        }
    }

    /// The bdSeq of the next (or current) session.
    pub fn bd_seq(&self) -> u8 {
        match &self.inner {
            Inner::Sparkplug(s) => s.bd_seq(),
            Inner::Plain(_) => 0,
        }
    }

    /// Sets the bdSeq the next [`Edge::will`] and NBIRTH carry (a restart continues after the
    /// last one used). No effect in plain mode.
    pub fn set_bd_seq(&mut self, bd_seq: u8) {
        if let Inner::Sparkplug(s) = &mut self.inner {
            s.set_bd_seq(bd_seq);
        }
    }

    /// The broker accepted the connection (CONNACK): the births, or nothing while waiting for
    /// the primary host's STATE.
    pub fn connected(&mut self, now: SystemTime) -> Vec<Publish> {
        match &mut self.inner {
            Inner::Sparkplug(s) => s.connected(now),
            Inner::Plain(p) => p.connected(),
        }
    }

    /// The session is gone: the next CONNECT takes the next bdSeq (255 → 0); samples now
    /// become [`Output::Store`] records.
    pub fn disconnected(&mut self) {
        match &mut self.inner {
            Inner::Sparkplug(s) => s.disconnected(),
            Inner::Plain(p) => p.disconnected(),
        }
    }

    /// A poll of group `group` of `device`: a DBIRTH when the device is born (or back), DDATA
    /// with what moved beyond the deadbands, DDEATH after `death_after` polls without a reply;
    /// records for the store while offline.
    pub fn sample(&mut self, device: DeviceRef, group: usize, sample: &Sample) -> Vec<Output> {
        match &mut self.inner {
            Inner::Sparkplug(s) => s.sample(device, group, sample),
            Inner::Plain(p) => p.sample(device, group, sample),
        }
    }

    /// What the last sample of `device` did to its liveness (the one rule, [`Health`]), for
    /// the bridge's status lines: `None` before its first sample.
    pub(crate) fn liveness(&self, device: DeviceRef) -> Option<Liveness> {
        match &self.inner {
            Inner::Sparkplug(s) => s.device(device),
            Inner::Plain(p) => p.device(device),
        }
        .and_then(Device::last_liveness)
    }

    /// A stored record as historical data (the next seq, the original timestamps); `None` when
    /// it no longer maps to a born device's metrics (counted). See [`Edge::replay_all`], which
    /// also replays the records of a device not born now.
    ///
    /// # Errors
    /// [`EdgeError::Offline`] before the births (keep the record); [`EdgeError::Record`] when
    /// the bytes are not a record of this mode (drop it).
    pub fn replay(&mut self, record: &[u8], now: SystemTime) -> Result<Option<Publish>, EdgeError> {
        let record = Record::decode(record).map_err(EdgeError::Record)?;
        match &mut self.inner {
            Inner::Sparkplug(s) => Ok(s.replay(record, now, false)?.pop()),
            Inner::Plain(p) => p.replay(record),
        }
    }

    /// [`Edge::replay`], and for a record of a device that is configured but not born now (it
    /// has not answered since a restart, or died after the connection): its DBIRTH first (the
    /// values known, null for the rest), then the historical DDATA; its DDEATH comes with
    /// [`Edge::replayed`] or its next silent poll, unless it answers first. Nothing is lost
    /// for a device that is still in the plant. Empty when the device or all its metrics are
    /// gone (counted).
    ///
    /// # Errors
    /// As [`Edge::replay`].
    pub fn replay_all(&mut self, record: &[u8], now: SystemTime) -> Result<Vec<Publish>, EdgeError> {
        let record = Record::decode(record).map_err(EdgeError::Record)?;
        match &mut self.inner {
            Inner::Sparkplug(s) => s.replay(record, now, true),
            Inner::Plain(p) => Ok(p.replay(record)?.into_iter().collect()),
        }
    }

    /// The store is replayed (empty): the DDEATH of every device that was dead at the
    /// connection and born only so that its history resolves. Nothing in plain mode.
    pub fn replayed(&mut self, now: SystemTime) -> Vec<Publish> {
        match &mut self.inner {
            Inner::Sparkplug(s) => s.replayed(now),
            Inner::Plain(_) => Vec::new(),
        }
    }

    /// A message from the broker: NCMD Rebirth → NBIRTH and DBIRTHs (same bdSeq); DCMD →
    /// [`Action::Write`]s, or an error per refused metric and no write; the primary host's STATE
    /// → births released, or [`Action::Reconnect`]; plain `PREFIX/DEVICE/POINT/set` → a write,
    /// or its refusal on `.../set/result`. Other topics are ignored (counted).
    pub fn message(
        &mut self,
        topic: &str,
        payload: &[u8],
        now: SystemTime,
    ) -> (Vec<Publish>, Vec<Action>, Vec<EdgeError>) {
        match &mut self.inner {
            Inner::Sparkplug(s) => s.message(topic, payload, now),
            Inner::Plain(p) => p.message(topic, payload),
        }
    }

    /// A write's outcome: plain mode publishes it on `PREFIX/DEVICE/POINT/set/result`;
    /// Sparkplug publishes nothing (the next DDATA shows the value).
    #[allow(clippy::needless_pass_by_value)] // the interface's shape: the runtime hands over the outcome
    pub fn written(
        &mut self,
        device: DeviceRef,
        group: usize,
        cell: usize,
        result: Result<(), String>,
    ) -> Vec<Publish> {
        match &mut self.inner {
            Inner::Sparkplug(_) => Vec::new(),
            Inner::Plain(p) => p.written(device, group, cell, &result),
        }
    }

    /// Before an intentional disconnect: NDEATH with the current bdSeq (plain mode:
    /// `PREFIX/status` "offline"). Nothing more is published until the next connection.
    pub fn shutdown(&mut self, now: SystemTime) -> Option<Publish> {
        match &mut self.inner {
            Inner::Sparkplug(s) => Some(s.shutdown(now)),
            Inner::Plain(p) => Some(p.shutdown()),
        }
    }

    /// Whether the births are out (plain mode: connected): samples are published live and
    /// stored records may be replayed; otherwise samples become [`Output::Store`] records.
    pub fn is_online(&self) -> bool {
        match &self.inner {
            Inner::Sparkplug(s) => s.is_online(),
            Inner::Plain(p) => p.is_online(),
        }
    }

    /// The plant is reloaded: `plan` from the running plant to `plant` (the same mode: a plan
    /// never changes it). Sparkplug: an unchanged device keeps its session (no new DBIRTH, its
    /// aliases); a removed or changed device that is born gets its DDEATH now; a changed or
    /// added one its DBIRTH at its first answered poll, with aliases never given before in this
    /// process. Plain: a removed device's status "offline", and with discovery the configs of
    /// the points gone removed and the new ones published. Devices are renumbered to their
    /// places in `plant`; the new mode settings are taken (a plan that changes them also
    /// reconnects: call [`Edge::shutdown`] before, as for an intentional disconnect).
    pub fn reload(&mut self, plant: &Plant, plan: &Plan, now: SystemTime) -> Vec<Publish> {
        match (&mut self.inner, &plant.mode) {
            (Inner::Sparkplug(s), Mode::Sparkplug(config)) => s.reload(plant, config, plan, now),
            (Inner::Plain(p), Mode::Plain(config)) => p.reload(plant, config, plan),
            _ => Vec::new(),
        }
    }

    /// Every point's latest reading, device by device in plant order: what a status page
    /// shows (a point never read is not there).
    pub fn readings(&self) -> Vec<Reading> {
        match &self.inner {
            Inner::Sparkplug(s) => s.devices().flat_map(Device::readings).collect(),
            Inner::Plain(p) => p.devices().flat_map(Device::readings).collect(),
        }
    }

    /// What was published, stored and refused so far.
    pub fn stats(&self) -> EdgeStats {
        match &self.inner {
            Inner::Sparkplug(s) => s.stats,
            Inner::Plain(p) => p.stats,
        }
    }
}

/// Milliseconds since the Unix epoch, as Sparkplug timestamps are.
fn millis(time: SystemTime) -> u64 {
    let since = time.duration_since(SystemTime::UNIX_EPOCH).unwrap_or_default();
    u64::try_from(since.as_millis()).unwrap_or(u64::MAX)
}
