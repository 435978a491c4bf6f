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
pub use crate::reload::Fate;
use crate::reload::{fates, removed, tally};

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
}

/// `1 line added, 1 changed, 0 removed, 3 unchanged; routes changed`.
impl fmt::Display for Plan {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let routes = if self.routes_changed { "changed" } else { "unchanged" };
        write!(f, "{}; routes {routes}", tally("line", &self.lines, self.removed.len()))
    }
}

/// The plan from the running file `old` to `new`, both read and checked.
pub fn plan(old: &LinesFile, new: &LinesFile) -> Plan {
    let (running, now) = (&old.settings, &new.settings);
    let lines = fates(running, now, LineSettings::same_target, LineSettings::eq);
    let removed = removed(running, now, LineSettings::same_target);
    Plan { lines, removed, routes_changed: old.routes != new.routes }
}

#[cfg(test)]
mod tests;
