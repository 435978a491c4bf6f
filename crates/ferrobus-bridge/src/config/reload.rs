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
//! `death_after`; a line's its connection and client settings. A broker setting, or a mode
//! setting other than the edge node's identity (the primary host, the integer encoding,
//! plain mode's retain, QoS and discovery), changed: the session to the broker is made again.
//!
//! The runtime ([`crate::run`]) does not yet carry a plan out: `ferrobus bridge` checks the file
//! on SIGHUP, logs its plan and keeps the running plant until a restart.
//!
//! Fixed for the bridge's life ([`Fixed`]): Sparkplug or plain; the Sparkplug group and edge
//! node ids (the node's identity: its bdSeq, Will and the topics of every message); plain
//! mode's topic prefix; the store (its folder and bounds: it is open).

use std::fmt;

use super::{DeviceSpec, LineSpec, Mode, Plant};

/// What becomes of one line, or one device, of the new plant.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Fate {
    /// It was at index `was` of the running plant (its lines, or its devices in line and
    /// device order) and goes on as it is.
    Unchanged {
        /// Its index in the running plant.
        was: usize,
    },
    /// It was at index `was` and is stopped and started again with its new settings.
    Changed {
        /// Its index in the running plant.
        was: usize,
    },
    /// It is new.
    Added,
}

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

/// `N added, N changed, N removed, N unchanged` of `fates`, `removed` besides.
fn tally(f: &mut fmt::Formatter<'_>, what: &str, fates: &[Fate], removed: usize) -> fmt::Result {
    let added = fates.iter().filter(|f| **f == Fate::Added).count();
    let changed = fates.iter().filter(|f| matches!(f, Fate::Changed { .. })).count();
    let unchanged = fates.len() - added - changed;
    let plural = if added == 1 { "" } else { "s" };
    write!(f, "{added} {what}{plural} added, {changed} changed, {removed} removed, {unchanged} unchanged")
}

/// `1 device added, 1 changed, 0 removed, 2 unchanged; 0 lines added, ...; broker unchanged`.
impl fmt::Display for Plan {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        tally(f, "device", &self.devices, self.removed_devices.len())?;
        f.write_str("; ")?;
        tally(f, "line", &self.lines, self.removed_lines.len())?;
        f.write_str(if self.reconnect { "; broker session made again" } else { "; broker unchanged" })
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
    let lines = fates(&running.lines, &new.lines, |l| &l.name, same_line);
    let removed_lines = removed(&running.lines, &new.lines, |l| &l.name);
    let old: Vec<(&LineSpec, &DeviceSpec)> = running.devices().collect();
    let now: Vec<(&LineSpec, &DeviceSpec)> = new.devices().collect();
    let devices = fates(&old, &now, device_id, |(la, a), (lb, b)| la.name == lb.name && same_device(a, b));
    let removed_devices = removed(&old, &now, device_id);
    let reconnect = running.broker != new.broker || running.mode != new.mode;
    Ok(Plan { lines, removed_lines, devices, removed_devices, reconnect })
}

/// Each of `new`'s fate among `old`, known by `key`, `same` telling unchanged from changed.
fn fates<T>(old: &[T], new: &[T], key: impl Fn(&T) -> &String, same: impl Fn(&T, &T) -> bool) -> Vec<Fate> {
    new.iter()
        .map(|item| match old.iter().position(|o| key(o) == key(item)) {
            Some(was) if old.get(was).is_some_and(|o| same(o, item)) => Fate::Unchanged { was },
            Some(was) => Fate::Changed { was },
            None => Fate::Added,
        })
        .collect()
}

/// The indices of `old`'s items that `new` does not name.
fn removed<T>(old: &[T], new: &[T], key: impl Fn(&T) -> &String) -> Vec<usize> {
    (0..old.len()).filter(|&i| old.get(i).is_some_and(|o| !new.iter().any(|n| key(n) == key(o)))).collect()
}

/// A device's id, beside its line.
fn device_id<'a>(device: &'a (&LineSpec, &DeviceSpec)) -> &'a String {
    &device.1.id
}

/// A line polls the same: the same connection and client settings (its devices apart).
fn same_line(a: &LineSpec, b: &LineSpec) -> bool {
    a.connection == b.connection && a.client == b.client
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
mod tests;
