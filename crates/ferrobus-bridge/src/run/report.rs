//! The summary a run ends with: what was published, by Sparkplug message type (or plain
//! messages), what the store took, replayed and dropped, refused commands and writes, and per
//! line its polls and their failures by kind.

use std::collections::BTreeMap;
use std::fmt;

use ferrobus_tools::poll::{Counters, FailureKind};

use crate::config::Plant;
use crate::store::Store;

/// What a run did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Report {
    /// Messages handed to the MQTT client, by type (`NBIRTH`, `DDATA`, ..., `plain`, `result`).
    pub published: BTreeMap<String, u64>,
    /// Messages the client could not take (its queue was full).
    pub unsent: u64,
    /// Records kept in the store while the broker was away.
    pub stored: u64,
    /// Records replayed from the store.
    pub replayed: u64,
    /// Stored records that no longer map to the plant (or could not be read), passed over.
    pub unreplayable: u64,
    /// New records dropped because the store was full.
    pub dropped: u64,
    /// Store errors (each logged).
    pub store_errors: u64,
    /// Records of a previous run found in the store at the start.
    pub recovered: u64,
    /// Records still in the store at the end (kept on disk for the next run, if it has one).
    pub left: u64,
    /// Commands refused (nothing written).
    pub refused: u64,
    /// Incoming messages discarded unread: over the size the bridge takes.
    pub discarded: u64,
    /// Writes done.
    pub writes: u64,
    /// Writes the bus failed.
    pub write_failures: u64,
    /// Sessions the broker accepted.
    pub connections: u64,
    /// Sessions lost.
    pub broker_lost: u64,
    /// Each line's polls.
    pub lines: Vec<LineReport>,
}

/// One line's polls.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LineReport {
    /// Its name.
    pub name: String,
    /// Polls.
    pub polls: u64,
    /// Polls that gave values.
    pub ok: u64,
    /// Failed polls by kind.
    pub failures: BTreeMap<FailureKind, u64>,
    /// Polls that ended after their next was due.
    pub overruns: u64,
}

impl Report {
    /// An empty report for `plant`, whose store recovered `recovered` records.
    pub fn new(plant: &Plant, recovered: u64) -> Report {
        let lines = plant.lines.iter().map(|l| LineReport { name: l.name.clone(), ..LineReport::default() }).collect();
        Report { recovered, lines, ..Report::default() }
    }

    /// Fills in each line's counters (`counters[line]`, per poller group) and what is left in
    /// the store.
    pub fn finish(&mut self, counters: &[Vec<Counters>], store: &Store) {
        for (line, groups) in self.lines.iter_mut().zip(counters) {
            line.add(groups);
        }
        self.left = store.len();
    }

    /// Messages published of type `kind`.
    pub fn published(&self, kind: &str) -> u64 {
        self.published.get(kind).copied().unwrap_or(0)
    }
}

impl LineReport {
    /// Adds a poller's counters, group by group (a poller stopped by a reload is counted so).
    pub fn add(&mut self, groups: &[Counters]) {
        for c in groups {
            self.polls += c.polls;
            self.ok += c.ok;
            self.overruns += c.overruns;
            for (kind, n) in &c.failures {
                *self.failures.entry(*kind).or_default() += n;
            }
        }
    }
}

impl fmt::Display for Report {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // Sparkplug's order first (a session's life), then the rest.
        let order = ["NBIRTH", "DBIRTH", "DDATA", "NDATA", "DDEATH", "NDEATH"];
        let rank = |kind: &str| order.iter().position(|k| *k == kind).unwrap_or(order.len());
        let mut kinds: Vec<(&String, &u64)> = self.published.iter().collect();
        kinds.sort_by_key(|(kind, _)| rank(kind));
        let published: Vec<String> = kinds.iter().map(|(kind, n)| format!("{n} {kind}")).collect();
        let published = if published.is_empty() { "nothing".to_string() } else { published.join(", ") };
        writeln!(f, "published: {published}")?;
        if self.unsent > 0 {
            writeln!(f, "not sent (the MQTT client's queue was full): {}", self.unsent)?;
        }
        let sessions = if self.connections == 1 { "session" } else { "sessions" };
        writeln!(
            f,
            "broker: {} {sessions}, {} lost; store: {} stored, {} replayed, {} dropped, {} left, {} errors",
            self.connections, self.broker_lost, self.stored, self.replayed, self.dropped, self.left, self.store_errors
        )?;
        if self.recovered > 0 || self.unreplayable > 0 {
            writeln!(f, "store: {} recovered from a previous run, {} passed over", self.recovered, self.unreplayable)?;
        }
        writeln!(
            f,
            "commands: {} written, {} failed on the bus, {} refused",
            self.writes, self.write_failures, self.refused
        )?;
        if self.discarded > 0 {
            writeln!(f, "incoming messages discarded as too large: {}", self.discarded)?;
        }
        for line in &self.lines {
            let failed: u64 = line.failures.values().sum();
            let kinds: Vec<String> =
                line.failures.iter().filter(|(_, n)| **n > 0).map(|(k, n)| format!("{n} {}", k.name())).collect();
            let kinds = if kinds.is_empty() { String::new() } else { format!(" ({})", kinds.join(", ")) };
            writeln!(
                f,
                "line {}: {} polls, {} ok, {failed} failed{kinds}, {} overruns",
                line.name, line.polls, line.ok, line.overruns
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_report_says_what_was_published_by_type_and_each_lines_failures_by_kind() {
        let mut report = Report { stored: 12, replayed: 12, refused: 1, writes: 2, ..Report::default() };
        report.published.insert("DDATA".into(), 345);
        report.published.insert("NBIRTH".into(), 1);
        let mut failures = BTreeMap::new();
        failures.insert(FailureKind::Timeout, 4);
        failures.insert(FailureKind::Crc, 0);
        report.lines.push(LineReport { name: "drives".into(), polls: 100, ok: 96, failures, overruns: 0 });
        let text = report.to_string();
        assert!(text.contains("published: 1 NBIRTH, 345 DDATA"), "{text}");
        assert!(text.contains("broker: 0 sessions, 0 lost; store: 12 stored, 12 replayed, 0 dropped"), "{text}");
        assert!(text.contains("commands: 2 written, 0 failed on the bus, 1 refused"), "{text}");
        assert!(text.contains("line drives: 100 polls, 96 ok, 4 failed (4 timeout), 0 overruns"), "{text}");
        assert_eq!(report.published("DDATA"), 345);
        assert_eq!(report.published("DDEATH"), 0);
    }
}
