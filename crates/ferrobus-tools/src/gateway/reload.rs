//! What a reload of the lines file changes: the [`Plan`] from the running file to the new one,
//! decided from the two files alone (no IO), and carried out by [`Gateway::reload`](super::Gateway::reload).
//!
//! A line is known by what it is connected to ([`LineSettings::target`]: its serial port, or
//! its device's address), not by its place in the file:
//!
//! | the new file's line | its fate |
//! |---|---|
//! | same target, same settings | unchanged: it keeps running (its port, its connections, its per-unit backoff, its counters), at its new place |
//! | same target, other settings | changed: stopped (its queued and in-flight requests answered or timed out first, the port let go), then opened anew |
//! | a target the running file lacks | added: opened and started |
//! | a running target the new file lacks | removed: stopped as a changed line is, and not started again |
//!
//! A line's units (`units`, `renumber`) are no setting of the line: the routes are swapped for
//! new requests at once, and a line whose units alone changed runs on. Nothing in a lines file
//! is fixed for the gateway's life: what is (the listening address, `--rtu-in`, TLS, the
//! defaults every line starts from) is on the command line, which a reload does not read.

use std::fmt;

use super::config::{LineSettings, LinesFile};

/// What becomes of one line of the new file.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Fate {
    /// The running line `was` (its index there) goes on as it is.
    Unchanged {
        /// Its index among the running lines.
        was: usize,
    },
    /// The running line `was` is stopped and this one started on its port.
    Changed {
        /// Its index among the running lines.
        was: usize,
    },
    /// A new line.
    Added,
}

/// What a reload does: each new line's [`Fate`], the running lines that go, and whether the
/// routes change.
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct Plan {
    /// By the new file's line index.
    pub lines: Vec<Fate>,
    /// The running lines the new file does not name, by their index.
    pub removed: Vec<usize>,
    /// Whether any unit now goes elsewhere (another line, another unit, or nowhere).
    pub routes_changed: bool,
}

impl Plan {
    /// Whether the reload changes nothing at all.
    pub fn is_empty(&self) -> bool {
        !self.routes_changed
            && self.removed.is_empty()
            && self.lines.iter().all(|f| matches!(f, Fate::Unchanged { .. }))
    }

    /// How many lines of the new file have `fate`'s kind.
    fn count(&self, kind: fn(&Fate) -> bool) -> usize {
        self.lines.iter().filter(|f| kind(f)).count()
    }
}

/// `reload: 1 line added, 1 changed, 0 removed, 3 unchanged; routes changed`.
impl fmt::Display for Plan {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let added = self.count(|f| *f == Fate::Added);
        let changed = self.count(|f| matches!(f, Fate::Changed { .. }));
        let unchanged = self.count(|f| matches!(f, Fate::Unchanged { .. }));
        let plural = if added == 1 { "line" } else { "lines" };
        write!(
            f,
            "{added} {plural} added, {changed} changed, {} removed, {unchanged} unchanged; routes {}",
            self.removed.len(),
            if self.routes_changed { "changed" } else { "unchanged" }
        )
    }
}

/// The plan from the running file `old` to `new`, both read and checked.
pub fn plan(old: &LinesFile, new: &LinesFile) -> Plan {
    plan_settings(&old.settings, &new.settings, old.routes != new.routes)
}

/// The plan from the running lines' settings to the new ones'.
fn plan_settings(old: &[LineSettings], new: &[LineSettings], routes_changed: bool) -> Plan {
    let lines = new
        .iter()
        .map(|line| match old.iter().position(|o| o.same_target(line)) {
            Some(was) if old.get(was) == Some(line) => Fate::Unchanged { was },
            Some(was) => Fate::Changed { was },
            None => Fate::Added,
        })
        .collect();
    let removed =
        (0..old.len()).filter(|i| old.get(*i).is_some_and(|o| !new.iter().any(|n| n.same_target(o)))).collect();
    Plan { lines, removed, routes_changed }
}

#[cfg(test)]
mod tests;
