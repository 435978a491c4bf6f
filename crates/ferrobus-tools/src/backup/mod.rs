//! Backups of a device's parameters, as a library: reading them in the profile's read plan and
//! writing them ([`device`]), the backup file (TOML, one parameter a
//! line in the profile's order, under a comment with its label; [`file`](mod@file)), a point's registers
//! to the file's raw value and back ([`param`]), the profile a backup is made with and the
//! SHA-256 that pins a profile file ([`view`]), the comparison of two backups
//! ([`diff`]) and of a device or a backup with the profile's factory defaults ([`defaults`]),
//! and the rules that write a backup file atomically and never let a worse backup
//! replace a better one ([`save`](mod@save)), and a restore's plan and its writes
//! ([`restore`]). The `ferrobus` command's `backup`, `diff` and `restore` are built on it.
//!
//! ```text
//!   device::read(target, view, points, watch) → Readings ──▶ Backup ──render──▶ file.toml ──Backup::parse──▶ Backup
//!   diff::compare(view, a, b) → the differences (through the registers, so 1.0 = 1 for an f32)
//! ```
//!
//! # The backup file
//!
//! TOML, one parameter a line, in the profile's order, each under a comment with its label, so
//! that two backups compare with any text diff:
//!
//! ```toml
//! # ferrobus backup of unit 1 (Omron 3G3RX inverter), profile omron-3g3rx
//! [backup]
//! format = 1                         # this layout; a later one is refused, not misread
//! profile = "omron-3g3rx"            # a built-in name, or the path of a profile file
//! profile_hash = "sha256:…"          # only for a profile file: the exact file used
//! device = "Omron 3G3RX inverter"
//! time = "2026-12-01T22:00:00Z"      # ISO-8601 UTC
//! connection = "/dev/ttyUSB0 at 19200 8E1 (RTU)"
//! identification = "none: …"         # or "FC2B/0E", "FC11", or why it failed
//! unit = 1
//!
//! [identification]                   # the objects read, if the device has them
//! VendorName = "…"
//!
//! [parameters]
//! # Acceleration time 1
//! F002 = { raw = 1000, value = "10.00 s" }
//! # Base frequency
//! A003 = { error = "exception 0x22 (vendor-specific): the device restricts execution" }
//! ```
//!
//! `raw` is the value the device holds: an integer (a decimal string for a `u64` past
//! `i64::MAX`), a float for `f32`/`f64`, a string for text, `true`/`false` for a coil. Only
//! `raw` is read back; `value` (the raw value in the profile's unit) is for people. A
//! parameter that could not be read has `error` instead, with the reason.
//!
//! Every error is typed and names what was seen: [`BackupError`] a file and its line,
//! [`ParamError`] a value and its point, [`ViewError`] a profile.

pub mod defaults;
pub mod device;
pub mod diff;
pub mod file;
pub mod param;
pub mod restore;
pub mod save;
pub mod view;

pub use device::{Readings, Target, Unwatched, Watch};
pub use diff::{Difference, Side, compare, same};
pub use file::{Backup, BackupError, Entry, FORMAT, Header, State, now_utc};
pub use param::ParamError;
pub use restore::{Item, Outcome, RestoreError};
pub use save::{Completeness, SaveError, Saved, save};
pub use view::{Identification, View, ViewError};

use ferrobus_profile::Point;

/// One entry per parameter, in `params`' order, from what was read: its value, or why it has
/// none; and how many have none.
pub fn entries(params: &[&Point], readings: &Readings) -> (Vec<Entry>, usize) {
    let mut failed = 0;
    let entries = params
        .iter()
        .map(|p| {
            let state = match readings.values.get(&p.code) {
                Some(Ok(words)) => match param::decode(p, words) {
                    Ok(raw) => State::Value { shown: p.show(&raw), raw: param::to_toml(&raw) },
                    Err(why) => State::Failed(why.to_string()),
                },
                Some(Err(why)) => State::Failed(why.clone()),
                None => State::Failed("not read".into()),
            };
            if matches!(state, State::Failed(_)) {
                failed += 1;
            }
            Entry { code: p.code.clone(), label: param::label(p).to_string(), line: 0, state }
        })
        .collect();
    (entries, failed)
}
