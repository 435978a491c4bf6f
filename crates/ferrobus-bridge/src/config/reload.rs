//! What a reload of the plant file changes: the [`Plan`] from the running [`Plant`] to the one
//! read again, decided from the two alone (no IO), or the settings that cannot change while the
//! bridge runs ([`Fixed`]).
//!
//! A line is known by its name, a device by its id (both unique in a plant):
//!
//! | in the new plant | line | device |
//! |---|---|---|
//! | the same name or id, the same settings | unchanged: it keeps polling | unchanged: its Sparkplug session goes on, no new DBIRTH |
//! | the same name or id, other settings | changed: stopped, then started | changed: DDEATH, then DBIRTH with its new metrics |
//! | new | added | added: DBIRTH at its first answered poll |
//! | gone | removed | removed: DDEATH |
//!
//! A device's settings are its line, unit, profile, groups (points and rates), deadbands and
//! `death_after`; a line's its connection, client settings and mode (polled or listened to). A broker setting, or a mode
//! setting other than the edge node's identity (the primary host, the integer encoding,
//! plain mode's retain, QoS and discovery), changed: the session to the broker is made again.
//!
//! The runtime carries a plan out while it runs ([`crate::run::Reload`]); `ferrobus bridge` hands
//! it the file read again on SIGHUP.
//!
//! Fixed for the bridge's life ([`Fixed`]): Sparkplug or plain; the Sparkplug group and edge
//! node ids (the node's identity: its bdSeq, Will and the topics of every message); plain
//! mode's topic prefix; the store (its folder and bounds: it is open).

use std::fmt;

pub use ferrobus_tools::reload::Fate;
use ferrobus_tools::reload::{fates, removed, tally};

use super::{DeviceSpec, LineSpec, Mode, Plant};

/// What a reload of the plant does.
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct Plan {
    /// By the new plant's line index.
    pub lines: Vec<Fate>,
    /// The running lines the new plant does not name, by index.
    pub removed_lines: Vec<usize>,
    /// By the new plant's devices, in line and device order ([`Plant::devices`]).
    pub devices: Vec<Fate>,
    /// The running devices the new plant does not name, in line and device order.
    pub removed_devices: Vec<usize>,
    /// The session to the broker is made again: a broker or session setting changed.
    pub reconnect: bool,
}

impl Plan {
    /// Whether the reload changes nothing.
    pub fn is_empty(&self) -> bool {
        !self.reconnect
            && self.removed_lines.is_empty()
            && self.removed_devices.is_empty()
            && self.lines.iter().chain(&self.devices).all(|f| matches!(f, Fate::Unchanged { .. }))
    }
}

/// `1 device added, 1 changed, 0 removed, 2 unchanged; 0 lines added, ...; broker unchanged`.
impl fmt::Display for Plan {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let broker = if self.reconnect { "broker session made again" } else { "broker unchanged" };
        let devices = tally("device", &self.devices, self.removed_devices.len());
        write!(f, "{devices}; {}; {broker}", tally("line", &self.lines, self.removed_lines.len()))
    }
}

/// Settings that differ between the running plant and the new one and cannot change while the
/// bridge runs, named as the file names them.
#[derive(Clone, PartialEq, Eq, Debug, thiserror::Error)]
#[error("{} cannot change while the bridge runs (restart it to change them); the running plant stays", .0.join(", "))]
pub struct Fixed(pub Vec<&'static str>);

/// The plan from the `running` plant to `new`, both read and checked; the settings that cannot
/// change, if any changed.
pub fn plan(running: &Plant, new: &Plant) -> Result<Plan, Fixed> {
    fixed(running, new)?;
    let named = |a: &LineSpec, b: &LineSpec| a.name == b.name;
    let lines = fates(&running.lines, &new.lines, named, same_line);
    let removed_lines = removed(&running.lines, &new.lines, named);
    let old: Vec<(&LineSpec, &DeviceSpec)> = running.devices().collect();
    let now: Vec<(&LineSpec, &DeviceSpec)> = new.devices().collect();
    let id = |(_, a): &(&LineSpec, &DeviceSpec), (_, b): &(&LineSpec, &DeviceSpec)| a.id == b.id;
    let devices = fates(&old, &now, id, |(la, a), (lb, b)| la.name == lb.name && same_device(a, b));
    let removed_devices = removed(&old, &now, id);
    let reconnect = running.broker != new.broker || running.mode != new.mode;
    Ok(Plan { lines, removed_lines, devices, removed_devices, reconnect })
}

/// A line polls the same: the same connection, client settings and mode (its devices apart).
fn same_line(a: &LineSpec, b: &LineSpec) -> bool {
    a.connection == b.connection && a.client == b.client && a.mode == b.mode
}

/// A device publishes the same metrics, polled the same way.
fn same_device(a: &DeviceSpec, b: &DeviceSpec) -> bool {
    let profile = match (&a.profile, &b.profile) {
        (Some(a), Some(b)) => a.to_toml() == b.to_toml(),
        (None, None) => true,
        _ => false,
    };
    a.unit == b.unit && a.groups == b.groups && a.deadbands == b.deadbands && a.death_after == b.death_after && profile
}

/// The settings fixed for the bridge's life that differ.
fn fixed(running: &Plant, new: &Plant) -> Result<(), Fixed> {
    let mut differ = Vec::new();
    match (&running.mode, &new.mode) {
        (Mode::Sparkplug(a), Mode::Sparkplug(b)) => {
            if a.group_id != b.group_id {
                differ.push("[sparkplug] group_id");
            }
            if a.edge_node_id != b.edge_node_id {
                differ.push("[sparkplug] edge_node_id");
            }
        }
        (Mode::Plain(a), Mode::Plain(b)) => {
            if a.prefix != b.prefix {
                differ.push("[plain] prefix");
            }
        }
        _ => differ.push("the mode ([sparkplug] or [plain])"),
    }
    if running.store != new.store {
        differ.push("[store]");
    }
    if differ.is_empty() { Ok(()) } else { Err(Fixed(differ)) }
}

#[cfg(test)]
pub(crate) mod tests;
