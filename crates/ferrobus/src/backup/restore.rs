//! Restoring a backup: the plan and its execution. The parameters that differ are [`Item`]s,
//! put in dependency order ([`order`]: the profile's `depends_on` first, its order otherwise),
//! checked against the profile's write guard with the drive's run state as read ([`guard`]),
//! written one per request ([`apply`]: a refusal stops only what depends on it, no reply or a
//! stop stops them all), and verified against what reads back ([`verify`]).

use std::collections::BTreeSet;

use ferrobus_profile::{Point, Profile, RunState, Value, Write};

use super::device::{self, Readings, Target, Watch, unless};
use super::param;
use super::view::View;
use crate::error::Error;

/// Why a restore cannot be planned.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum RestoreError {
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
        match unless(watch, device::write(target, item.param, &item.words)).await {
            Some(Ok(())) => watch.progress(1),
            None => {
                item.outcome = Outcome::InFlight;
                interrupted = true;
                stopped = Some("Ctrl-C or SIGTERM".to_string());
            }
            Some(Err(error)) => {
                watch.progress(1);
                let why = device::describe(&error, view);
                if !matches!(error, Error::Exception { .. }) {
                    stopped = Some(why.clone());
                }
                item.outcome = Outcome::NotWritten(why);
                failed.insert(item.param.code.clone());
            }
        }
    }
    interrupted
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
}
