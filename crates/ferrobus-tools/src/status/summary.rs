//! The one line a status page says about what runs ([`Status::summary`](super::Status)), and
//! what reloads (SIGHUP: the command's file read again) have done to it, shared by the command
//! and its [`Source`](super::Source).
//!
//! The line describes the file as applied: a reload applied replaces it, a refused one leaves
//! it. The reloads are counted (checked, refused) with when the last was applied, what it did
//! and when the last was refused, as the page's `Reloads` table. Why a reload was refused is
//! the command's to log at error level, so it is on the page already among the recent warnings
//! ([`RECENT`](super::RECENT)), escaped as every log line: the table points there rather than
//! saying it twice.

use std::time::SystemTime;

use super::Table;
use crate::poll::iso8601_ms;

/// What the page says of what runs, and the reloads so far.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Summary {
    text: String,
    reloads: Option<Reloads>,
}

/// What reloads have done so far.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Reloads {
    /// Files read again (applied or refused).
    pub checked: u64,
    /// Of them, refused: nothing changed.
    pub refused: u64,
    /// When the last one was applied, and what it did (`1 line added, ...`).
    pub applied: Option<(SystemTime, String)>,
    /// When the last one was refused.
    pub refused_at: Option<SystemTime>,
}

impl Summary {
    /// `text`, for a command with no file to read again: it never changes, and the page has
    /// no `Reloads` table.
    pub fn fixed(text: String) -> Self {
        Summary { text, reloads: None }
    }

    /// `text`, for a command whose file a reload reads again: none so far.
    pub fn reloadable(text: String) -> Self {
        Summary { text, reloads: Some(Reloads::default()) }
    }

    /// The line as it is now.
    pub fn text(&self) -> &str {
        &self.text
    }

    /// The reloads so far; `None` for a [`Summary::fixed`].
    pub fn reloads(&self) -> Option<&Reloads> {
        self.reloads.as_ref()
    }

    /// A reload was applied `at`: what runs is now `text`, and it did `done`.
    pub fn applied(&mut self, text: String, done: String, at: SystemTime) {
        self.text = text;
        let reloads = self.reloads.get_or_insert_with(Reloads::default);
        reloads.checked = reloads.checked.saturating_add(1);
        reloads.applied = Some((at, done));
    }

    /// A reload was refused `at`: what runs is as it was.
    pub fn refused(&mut self, at: SystemTime) {
        let reloads = self.reloads.get_or_insert_with(Reloads::default);
        reloads.checked = reloads.checked.saturating_add(1);
        reloads.refused = reloads.refused.saturating_add(1);
        reloads.refused_at = Some(at);
    }

    /// The page's `Reloads` table: one row, `never` for what has not happened; `None` for a
    /// [`Summary::fixed`].
    pub fn table(&self) -> Option<Table> {
        let reloads = self.reloads.as_ref()?;
        let mut table = Table::new("Reloads", &["checked", "refused", "last applied", "it did", "last refused"]);
        let (applied, did) = match &reloads.applied {
            Some((at, done)) => (iso8601_ms(*at), done.clone()),
            None => ("never".to_string(), "-".to_string()),
        };
        let refused = match reloads.refused_at {
            Some(at) => format!("{} (why: the recent warnings)", iso8601_ms(at)),
            None => "never".to_string(),
        };
        table.rows.push(vec![reloads.checked.to_string(), reloads.refused.to_string(), applied, did, refused]);
        Some(table)
    }
}

#[cfg(test)]
mod tests {
    use std::time::{Duration, SystemTime};

    use super::Summary;

    #[test]
    fn a_reload_applied_replaces_the_line_and_a_refused_one_leaves_it_and_both_are_counted() {
        let at = SystemTime::UNIX_EPOCH + Duration::from_secs(1_800_000_000);
        let mut summary = Summary::reloadable("2 lines".into());
        let row = |s: &Summary| s.table().unwrap().rows.concat();
        assert_eq!(row(&summary), ["0", "0", "never", "-", "never"]);

        summary.refused(at);
        assert_eq!(summary.text(), "2 lines", "a refused reload changes nothing that runs");
        assert_eq!(row(&summary), ["1", "1", "never", "-", "2027-01-15T08:00:00.000Z (why: the recent warnings)"]);

        summary.applied("3 lines".into(), "1 line added".into(), at + Duration::from_millis(1500));
        assert_eq!(summary.text(), "3 lines");
        let table = summary.table().unwrap();
        assert_eq!(table.title, "Reloads");
        assert_eq!(table.columns, ["checked", "refused", "last applied", "it did", "last refused"]);
        assert_eq!(
            row(&summary),
            [
                "2",
                "1",
                "2027-01-15T08:00:01.500Z",
                "1 line added",
                "2027-01-15T08:00:00.000Z (why: the recent warnings)"
            ]
        );

        summary.refused(at + Duration::from_secs(3));
        assert_eq!(summary.text(), "3 lines", "the line stays the last applied one's");
        assert_eq!(summary.reloads().map(|r| (r.checked, r.refused)), Some((3, 2)));
    }

    #[test]
    fn a_fixed_summary_has_no_reloads_table() {
        let summary = Summary::fixed("listening on 127.0.0.1:502".into());
        assert_eq!(summary.text(), "listening on 127.0.0.1:502");
        assert!(summary.reloads().is_none());
        assert!(summary.table().is_none());
    }
}
