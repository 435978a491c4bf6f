//! Restoring a backup: the plan and its execution. The parameters that differ are [`Item`]s,
//! put in dependency order ([`order`]: the profile's `depends_on` first, its order otherwise),
//! checked against the profile's write guard with the drive's run state as read ([`guard`]),
//! written one per request ([`apply`]: a refusal stops only what depends on it, no reply or a
//! stop stops them all), and verified against what reads back ([`verify`]).

use std::collections::BTreeSet;

use ferrobus_profile::{Point, Profile, RunState, Value, Write};

use super::device::{self, Readings, Target, Watch, unless};
use super::file::{Backup, State};
use super::param::{self, shown_toml};
use super::view::View;
use crate::write::WriteError;
use ferrobus::error::Error;

/// A value of the file to restore: its parameter, the raw value and its registers.
pub type Candidate<'v> = (&'v Point, Value, Vec<u16>);

/// The file's values that can be restored, and notes on those left as they are.
#[derive(Clone, Debug)]
pub struct Checked<'v> {
    /// The values to compare with the device, in the file's order.
    pub candidates: Vec<Candidate<'v>>,
    /// What is left as it is, and why (`FILE:LINE: CODE: ...`).
    pub notes: Vec<String>,
}

/// Why a restore cannot be planned.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum RestoreError {
    /// Values of the file that cannot be restored: not in the profile, not of its type, out of
    /// range, wider than a write request. Nothing was sent.
    #[error("{file} cannot be restored; nothing was sent:\n  {}", problems.join("\n  "))]
    Unrestorable {
        /// The file.
        file: String,
        /// Each problem, with the file's line.
        problems: Vec<String>,
    },
    /// Parameters that differ and that the profile marks read-only. Nothing was written.
    #[error("{file} cannot be restored; nothing was written:\n  {}", read_only.join("\n  "))]
    ReadOnly {
        /// The file.
        file: String,
        /// Each parameter, with both values.
        read_only: Vec<String>,
    },
    /// The profile's `depends_on` make a cycle among these parameters.
    #[error("the profile's depends_on make a cycle among {}; nothing was written", codes.join(", "))]
    Cycle {
        /// The parameters of the cycle (and those that wait for them).
        codes: Vec<String>,
    },
}

/// One parameter to restore.
#[derive(Clone, Debug)]
pub struct Item<'a> {
    /// The parameter.
    pub param: &'a Point,
    /// The file's raw value.
    pub raw: Value,
    /// Its registers.
    pub words: Vec<u16>,
    /// The device's value before, shown.
    pub before: String,
    /// What became of it.
    pub outcome: Outcome,
}

/// What happened to a parameter.
#[derive(Clone, PartialEq, Debug)]
pub enum Outcome {
    /// Not (yet) written; once written, written with the device's confirmation.
    Pending,
    /// Ctrl-C came while it was being written: it may or may not have been.
    InFlight,
    /// Written and read back equal.
    Verified,
    /// Written; the read-back differs or failed.
    Unverified(String),
    /// Not written, and why.
    NotWritten(String),
}

/// Each value of the file with its parameter and registers, checked before anything is sent:
/// a parameter the profile lacks (skipped with `--force`), a value not of its type, out of
/// range, or in no request the device takes ([`Point::wire_write`]: wider than its write
/// limit, or a table it has no function for); `force` skips a parameter the profile lacks,
/// with a note.
pub fn checked<'v>(backup: &Backup, view: &'v View, file: &str, force: bool) -> Result<Checked<'v>, RestoreError> {
    let mut candidates: Vec<Candidate<'v>> = Vec::new();
    let mut problems = Vec::new();
    let mut notes = Vec::new();
    for entry in &backup.entries {
        let at = format!("{file}:{}: {}", entry.line, entry.code);
        let raw = match &entry.state {
            State::Value { raw, .. } => raw,
            State::Failed(why) => {
                notes.push(format!("{at}: the backup holds no value (it could not be read: {why}); left as it is"));
                continue;
            }
        };
        let Some(param) = view.find(&entry.code) else {
            if force {
                notes.push(format!("{at}: not in profile {}; skipped", view.name));
            } else {
                problems.push(format!("{at}: profile {} has no such parameter", view.name));
            }
            continue;
        };
        let rules = view.profile.write_rules();
        match param::from_toml(param, raw).and_then(|v| param::encode(param, &v).map(|w| (v, w))) {
            Err(why) => problems.push(format!("{at}: {why}")),
            Ok((value, words)) => {
                let write = Write { point: param, raw: &value, typed: &param.show(&value) };
                // A read-only parameter is kept to compare: it refuses the restore only if it differs.
                let checked =
                    view.profile.check_value(&write).and_then(|()| param.wire_write(&value, &rules).map(drop));
                match checked {
                    Err(why) if param.writable() => problems.push(format!("{file}:{}: {why}", entry.line)),
                    _ => candidates.push((param, value, words)),
                }
            }
        }
    }
    if !problems.is_empty() {
        return Err(RestoreError::Unrestorable { file: file.to_string(), problems });
    }
    Ok(Checked { candidates, notes })
}

/// The candidates whose value on the device differs from the file's; a read-only one among
/// them refuses the restore.
pub fn differing<'v>(
    candidates: Vec<Candidate<'v>>,
    before: &Readings,
    file: &str,
) -> Result<Vec<Item<'v>>, RestoreError> {
    let mut items = Vec::new();
    let mut read_only = Vec::new();
    for (param, raw, words) in candidates {
        let (known, before_shown) = match before.values.get(&param.code) {
            Some(Ok(current)) if *current == words => continue,
            Some(Ok(current)) => match param::decode(param, current) {
                Ok(value) => (true, param.show(&value)),
                Err(why) => (false, format!("(not read: {why})")),
            },
            Some(Err(why)) => (false, format!("(not read: {why})")),
            None => (false, "(not read)".into()),
        };
        if !param.writable() {
            read_only.push(format!(
                "{}: the profile marks it read-only; the device holds {before_shown}, the file {}",
                param.code,
                param.show(&raw)
            ));
            continue;
        }
        let outcome = if known {
            Outcome::Pending
        } else {
            Outcome::NotWritten(format!("its value could not be read first: {before_shown}"))
        };
        items.push(Item { param, raw, words, before: before_shown, outcome });
    }
    if !read_only.is_empty() {
        return Err(RestoreError::ReadOnly { file: file.to_string(), read_only });
    }
    Ok(items)
}

/// Sorts the items so that each comes after those it depends on (among the items), keeping
/// the profile's order otherwise; a cycle is an error.
pub fn order(items: &mut Vec<Item<'_>>) -> Result<(), RestoreError> {
    let mut rest: Vec<Item<'_>> = std::mem::take(items);
    while !rest.is_empty() {
        let ready = rest.iter().position(|item| {
            !item.param.depends_on.iter().any(|d| rest.iter().any(|other| other.param.code.eq_ignore_ascii_case(d)))
        });
        let Some(at) = ready else {
            return Err(RestoreError::Cycle { codes: rest.iter().map(|i| i.param.code.clone()).collect() });
        };
        items.push(rest.remove(at));
    }
    Ok(())
}

/// The write guard, before any write: every parameter to write goes through the profile's
/// guard (the one `set`, `monitor` and the bridge apply) with the run state read first, and one
/// refusal refuses the restore: the refusals, one per refused parameter, saying what and why.
pub fn guard(
    items: &[Item<'_>],
    profile: &Profile,
    running: Option<(&Point, &[i64])>,
    before: &Readings,
) -> Result<(), String> {
    let pending = || items.iter().filter(|i| i.outcome == Outcome::Pending);
    let Some((p, _)) = running else {
        let locked: Vec<&str> = pending().filter(|i| !i.param.while_running).map(|i| i.param.code.as_str()).collect();
        if !locked.is_empty() {
            eprintln!(
                "note: the profile does not say how to tell that the drive runs ([state] running): {} may not be \
                 written while it runs, and the drive may refuse them",
                locked.join(", ")
            );
        }
        return Ok(());
    };
    let state = match before.values.get(&p.code) {
        Some(Ok(words)) => param::decode(p, words).map_or_else(|e| RunState::Unreadable(e.to_string()), RunState::Read),
        Some(Err(why)) => RunState::Unreadable(why.clone()),
        None => RunState::NotRead,
    };
    let refused: Vec<String> = pending()
        .filter_map(|i| {
            let typed = i.param.show(&i.raw);
            profile.guard_write(&Write { point: i.param, raw: &i.raw, typed: &typed }, &state).err()
        })
        .map(|refusal| refusal.to_string())
        .collect();
    if refused.is_empty() {
        return Ok(());
    }
    Err(refused.join("; "))
}

/// Writes each pending item in order, telling `watch` of each. After a refusal
/// the rest go on, except what depends on it; after no reply, a lost port or Ctrl-C nothing
/// more is sent. Whether `watch` stopped the writes.
pub async fn apply(target: Target<'_>, view: &View, items: &mut [Item<'_>], watch: &mut impl Watch) -> bool {
    let mut failed: BTreeSet<String> =
        items.iter().filter(|i| matches!(i.outcome, Outcome::NotWritten(_))).map(|i| i.param.code.clone()).collect();
    let mut stopped: Option<String> = None;
    let mut interrupted = false;
    for item in items.iter_mut() {
        if item.outcome != Outcome::Pending {
            continue;
        }
        if let Some(why) = &stopped {
            item.outcome = Outcome::NotWritten(format!("not attempted: the writes stopped after {why}"));
            failed.insert(item.param.code.clone());
            continue;
        }
        if let Some(dep) = item.param.depends_on.iter().find(|d| failed.iter().any(|f| f.eq_ignore_ascii_case(d))) {
            item.outcome = Outcome::NotWritten(format!("it depends on {dep}, which was not written"));
            failed.insert(item.param.code.clone());
            continue;
        }
        tracing::info!(code = %item.param.code, words = ?item.words, "writing");
        watch.started(&item.param.code);
        match unless(watch, device::write(target, &view.profile, item.param, &item.raw)).await {
            Some(Ok(())) => watch.progress(1),
            None => {
                item.outcome = Outcome::InFlight;
                interrupted = true;
                stopped = Some("Ctrl-C or SIGTERM".to_string());
            }
            Some(Err(WriteError::Bus(error))) => {
                watch.progress(1);
                let why = device::describe(&error, view);
                if !matches!(error, Error::Exception { .. }) {
                    stopped = Some(why.clone());
                }
                item.outcome = Outcome::NotWritten(why);
                failed.insert(item.param.code.clone());
            }
            Some(Err(refused)) => {
                watch.progress(1);
                item.outcome = Outcome::NotWritten(refused.to_string());
                failed.insert(item.param.code.clone());
            }
        }
    }
    interrupted
}

/// What a restore reads back: the file, with the profile, and whether a stop cut the writes
/// short (then only what was or may have been written is read).
#[derive(Clone, Copy, Debug)]
pub struct ReadBack<'a> {
    /// The profile.
    pub view: &'a View,
    /// The file restored.
    pub backup: &'a Backup,
    /// Whether the writes were stopped.
    pub interrupted: bool,
}

impl<'a> ReadBack<'a> {
    /// The parameters read back: every one of the file the profile has, or after a stop only
    /// those of `items` that were or may have been written.
    pub fn points<'i>(&self, items: &'i [Item<'a>]) -> Vec<&'a Point> {
        if self.interrupted {
            let written = |o: &Outcome| matches!(o, Outcome::Pending | Outcome::InFlight);
            items.iter().filter(|i| written(&i.outcome)).map(|i| i.param).collect()
        } else {
            self.backup.entries.iter().filter_map(|e| self.view.find(&e.code)).collect()
        }
    }
}

/// Reads back every parameter of the file (after an interruption, only what was or may have
/// been written): each written item verified or not, and the parameters not written that
/// differ from the file after the restore.
pub async fn read_back(
    target: Target<'_>,
    what: ReadBack<'_>,
    items: &mut [Item<'_>],
    watch: &mut impl Watch,
) -> Vec<String> {
    let ReadBack { view, backup, interrupted } = what;
    let all = what.points(items);
    let written = |o: &Outcome| matches!(o, Outcome::Pending | Outcome::InFlight);
    let after = device::read(target, view, &all, watch).await;
    for item in items.iter_mut().filter(|i| written(&i.outcome)) {
        item.outcome = verify(item, after.values.get(&item.param.code));
    }
    if interrupted {
        return Vec::new();
    }
    let mut drifted = Vec::new();
    for entry in &backup.entries {
        let (Some(param), State::Value { raw, .. }) = (view.find(&entry.code), &entry.state) else { continue };
        if items.iter().any(|i| i.param.code == param.code) {
            continue;
        }
        if let Some(Ok(words)) = after.values.get(&param.code)
            && param::from_toml(param, raw).and_then(|v| param::encode(param, &v)).is_ok_and(|w| w != *words)
        {
            drifted.push(format!("{} now reads {} (the file: {})", param.code, shown(param, words), shown_toml(raw)));
        }
    }
    drifted
}

/// The outcome of a written (or perhaps written) item, from what it reads back.
pub fn verify(item: &Item<'_>, back: Option<&Result<Vec<u16>, String>>) -> Outcome {
    let in_flight = item.outcome == Outcome::InFlight;
    match back {
        Some(Ok(words)) if *words == item.words => Outcome::Verified,
        Some(Ok(words)) if in_flight => {
            Outcome::NotWritten(format!("interrupted while being written; it still reads {}", shown(item.param, words)))
        }
        Some(Ok(words)) => Outcome::Unverified(format!("written, but reads back {}", shown(item.param, words))),
        Some(Err(why)) if in_flight => {
            Outcome::Unverified(format!("interrupted while being written, so perhaps written; not read back: {why}"))
        }
        Some(Err(why)) => Outcome::Unverified(format!("written, but not read back: {why}")),
        None => Outcome::Unverified("written, but not read back".into()),
    }
}

/// Registers read from the device, shown in the profile's unit.
pub fn shown(point: &Point, words: &[u16]) -> String {
    param::decode(point, words).map_or_else(|why| format!("(undecodable: {why})"), |v| point.show(&v))
}

#[cfg(test)]
mod tests {
    use super::*;
    use ferrobus_profile::Profile;
    use std::fmt::Write as _;

    fn profile(entries: &[(&str, &[&str])]) -> Profile {
        let mut text = String::from("[device]\nname = \"t\"\nvendor = \"t\"\nproduct_code = \"t\"\nrevision = \"1\"\n");
        for (number, (code, depends_on)) in entries.iter().enumerate() {
            let list: Vec<String> = depends_on.iter().map(|d| format!("\"{d}\"")).collect();
            let _ = write!(
                text,
                "[[registers]]\nnumber = {number}\nname = \"{code}\"\naccess = \"rw\"\ndepends_on = [{}]\n",
                list.join(", ")
            );
        }
        Profile::parse(&text, "t.toml").unwrap()
    }

    fn items(profile: &Profile) -> Vec<Item<'_>> {
        profile
            .points()
            .iter()
            .map(|param| Item {
                param,
                raw: Value::Int(0),
                words: vec![0],
                before: String::new(),
                outcome: Outcome::Pending,
            })
            .collect()
    }

    #[test]
    fn dependencies_come_first_and_the_profile_order_is_kept_otherwise() {
        let profile = profile(&[("F001", &["A004"]), ("B", &[]), ("A004", &["A003"]), ("A003", &[]), ("C", &["B"])]);
        let mut items = items(&profile);
        order(&mut items).unwrap();
        let codes: Vec<&str> = items.iter().map(|i| i.param.code.as_str()).collect();
        assert_eq!(codes, ["B", "A003", "A004", "F001", "C"]);
    }

    #[test]
    fn a_dependency_cycle_is_refused_before_any_write() {
        let profile = profile(&[("A", &["B"]), ("B", &["A"]), ("C", &[])]);
        let mut items = items(&profile);
        let err = order(&mut items).unwrap_err();
        assert_eq!(err, RestoreError::Cycle { codes: vec!["A".into(), "B".into()] });
        assert_eq!(err.to_string(), "the profile's depends_on make a cycle among A, B; nothing was written");
    }

    const RANGED: &str = "[device]\nname='t'\nvendor='t'\nproduct_code='t'\nrevision='1'\n\
        [[registers]]\nnumber=0\nname='A'\naccess='rw'\nmax=100\n\
        [[registers]]\nnumber=1\nname='R'\n";

    fn backup_file(parameters: &str) -> Backup {
        let text = format!(
            "[backup]\nformat = 1\nprofile = \"t.toml\"\ndevice = \"t\"\ntime = \"x\"\nconnection = \"x\"\n\
             identification = \"none\"\nunit = 1\n\n[parameters]\n{parameters}"
        );
        Backup::parse(&text, "f.toml").unwrap()
    }

    fn view() -> View {
        View { name: "t.toml".into(), hash: None, profile: Profile::parse(RANGED, "t.toml").unwrap() }
    }

    #[test]
    fn file_values_out_of_range_or_unknown_refuse_the_restore_with_their_lines_and_force_skips_the_unknown() {
        let view = view();
        let bad = backup_file("A = { raw = 101 }\nZ = { raw = 1 }\nR = { error = \"no reply\" }\n");
        let err = checked(&bad, &view, "f.toml", false).unwrap_err();
        let RestoreError::Unrestorable { problems, .. } = &err else { panic!("{err}") };
        assert_eq!(problems.len(), 2, "{err}");
        assert!(problems[0] == "f.toml:11: A: 101 is out of range: 0 to 100", "{err}");
        assert_eq!(problems[1], "f.toml:12: Z: profile t.toml has no such parameter");
        let forced = checked(&backup_file("A = { raw = 5 }\nZ = { raw = 1 }\n"), &view, "f.toml", true).unwrap();
        assert_eq!(forced.candidates.len(), 1);
        assert_eq!(forced.notes, ["f.toml:12: Z: not in profile t.toml; skipped"]);
    }

    #[test]
    fn only_what_differs_is_written_and_a_differing_read_only_parameter_refuses_the_restore() {
        let view = view();
        let file = backup_file("A = { raw = 5 }\nR = { raw = 1 }\n");
        let candidates = checked(&file, &view, "f.toml", false).unwrap().candidates;
        let mut before = Readings::default();
        before.values.insert("A".into(), Ok(vec![5]));
        before.values.insert("R".into(), Ok(vec![1]));
        assert!(differing(candidates.clone(), &before, "f.toml").unwrap().is_empty(), "nothing differs");
        before.values.insert("A".into(), Ok(vec![6]));
        let items = differing(candidates.clone(), &before, "f.toml").unwrap();
        assert_eq!((items.len(), items[0].param.code.as_str(), items[0].before.as_str()), (1, "A", "6"));
        before.values.insert("R".into(), Ok(vec![2]));
        let err = differing(candidates, &before, "f.toml").unwrap_err();
        assert!(matches!(&err, RestoreError::ReadOnly { read_only, .. } if read_only.len() == 1), "{err}");
        assert!(err.to_string().contains("R: the profile marks it read-only; the device holds 2, the file 1"), "{err}");
    }
}
