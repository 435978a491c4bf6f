//! Profiles, from [`ferrobus_profile`] (re-exported here so the simulator's code reads as
//! before), and the part of a profile only the simulator reads: the faults its units start
//! with (a `faults` string and `[[fault_rule]]` tables, see [`crate::rule`]).

pub use ferrobus_profile::*;

/// Word order of a 32-bit pair: the core's (a profile names it `order = "ABCD"` or `"CDAB"`).
pub use ferrobus_proto::words::WordOrder;

use ferrobus_profile::source::Place;

use crate::{Faults, Rule};

/// The simulator's reading of a profile.
pub trait ProfileFaults {
    /// The faults the profile asks for: its `faults` string, then its `[[fault_rule]]`s; an
    /// error names the file, the line and the column.
    fn faults(&self) -> Result<Faults, ProfileError> {
        self.every_fault().map_err(|mut mistakes| mistakes.swap_remove(0))
    }

    /// The same, with every mistake when there are any (never an empty list).
    fn every_fault(&self) -> Result<Faults, Vec<ProfileError>>;
}

impl ProfileFaults for Profile {
    fn every_fault(&self) -> Result<Faults, Vec<ProfileError>> {
        let problem = |place: Option<Place>, problem: String| self.problem(place, &problem);
        let mut mistakes = Vec::new();
        let mut faults: Faults = match self.faults.as_deref().map(str::parse::<Faults>) {
            Some(Ok(faults)) => faults,
            Some(Err(e)) => {
                mistakes.push(problem(self.faults_place, format!("faults: {e}")));
                Faults::default()
            }
            None => Faults::default(),
        };
        for (i, table) in self.fault_rule.iter().enumerate() {
            let place = self.fault_rule_places.get(i).copied().flatten();
            match rule_spec(table).and_then(|spec| spec.parse::<Rule>()) {
                Ok(rule) => faults.rules.push(rule),
                Err(p) => mistakes.push(problem(place, format!("[[fault_rule]]: {p}"))),
            }
        }
        if mistakes.is_empty() { Ok(faults) } else { Err(mistakes) }
    }
}

/// Loads a profile (see [`Profile::load`]) and checks the faults it asks for, so that a
/// mistake there is reported with the file and place like any other.
pub fn load(name_or_path: &str) -> Result<Profile, ProfileError> {
    load_all(name_or_path).map_err(|mut mistakes| mistakes.swap_remove(0))
}

/// [`load`] with every mistake of the file (see [`Profile::load_all`]), its faults' too when
/// the rest is sound; never an empty list.
pub fn load_all(name_or_path: &str) -> Result<Profile, Vec<ProfileError>> {
    let profile = Profile::load_all(name_or_path)?;
    profile.every_fault()?;
    Ok(profile)
}

/// A `[[fault_rule]]` table as a `--fault` rule: `key=value,...`, `key` alone for `true`.
fn rule_spec(table: &toml::Table) -> Result<String, String> {
    let mut parts = Vec::new();
    for (key, value) in table {
        match value {
            toml::Value::String(s) if s.contains(',') => return Err(format!("{key} = {s:?}: one value, no commas")),
            toml::Value::String(s) => parts.push(format!("{key}={s}")),
            toml::Value::Integer(n) => parts.push(format!("{key}={n}")),
            toml::Value::Float(x) => parts.push(format!("{key}={x}")),
            toml::Value::Boolean(true) => parts.push(key.clone()),
            toml::Value::Boolean(false) => {}
            _ => return Err(format!("{key}: expected a string, a number or true")),
        }
        if key.contains([',', '=']) {
            return Err(format!("unknown key {key:?}"));
        }
    }
    Ok(parts.join(","))
}

#[cfg(test)]
mod tests {
    use super::*;

    const DEVICE: &str = "[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\n";

    fn error(text: &str) -> String {
        let error = Profile::parse(text, "mine.toml").unwrap().faults().unwrap_err();
        // A mistake in the file, with its place: the profile loader's own kind of error.
        assert!(matches!(error, ProfileError::Invalid { .. }), "{error:?}");
        error.to_string()
    }

    #[test]
    fn a_profile_can_ask_for_faults() {
        let text = format!("faults = 'drop=10%,silent'\n{DEVICE}");
        let faults = Profile::parse(&text, "mine.toml").unwrap().faults().unwrap();
        assert!(faults.silent && (faults.drop - 0.1).abs() < 1e-12);
        let bad = format!("faults = 'drop=2'\n{DEVICE}");
        assert!(error(&bad).contains("drop: '2' is not between 0 and 1"));
    }

    #[test]
    fn a_profile_can_give_fault_rules_as_tables() {
        let text = format!(
            "faults = 'drop=10%'\n{DEVICE}[[fault_rule]]\nfc = 0x03\naddr = '0x1000-0x100F'\nshare = 0.5\nexception = 6\n\n\
             [[fault_rule]]\nno-reply = true\naddr = 7\n"
        );
        let faults = Profile::parse(&text, "mine.toml").unwrap().faults().unwrap();
        assert!((faults.drop - 0.1).abs() < 1e-12);
        let rules: Vec<String> = faults.rules.iter().map(ToString::to_string).collect();
        assert_eq!(
            rules,
            ["exception 0x06 for 50% of 0x03 at 0x1000-0x100F", "no reply for every request at 0x0007-0x0007"]
        );
        let bad = format!("{DEVICE}\n[[fault_rule]]\nfc = 3\nshort = 0\n");
        assert_eq!(error(&bad), "mine.toml:7:1: [[fault_rule]]: short: '0' is not a number of bytes from 1");
        let bad_faults = format!("\nfaults = 'drop=2'\n{DEVICE}");
        assert!(
            error(&bad_faults).starts_with("mine.toml:2:10: faults: fault \"drop=2\": drop:"),
            "{}",
            error(&bad_faults)
        );
        assert!(load("./nope.toml").unwrap_err().to_string().contains("no such file"));
    }

    #[test]
    fn every_bad_fault_of_a_profile_is_listed_each_with_its_place() {
        let text =
            format!("faults = 'drop=2'\n{DEVICE}[[fault_rule]]\nshort = 0\n\n[[fault_rule]]\nfc = 3\nshare = 7\n");
        let mistakes: Vec<String> = Profile::parse(&text, "mine.toml")
            .unwrap()
            .every_fault()
            .unwrap_err()
            .iter()
            .map(ToString::to_string)
            .collect();
        let places: Vec<&str> = mistakes.iter().filter_map(|m| m.split(": ").next()).collect();
        assert_eq!(places, ["mine.toml:1:10", "mine.toml:7:1", "mine.toml:10:1"], "{mistakes:#?}");
    }
}
