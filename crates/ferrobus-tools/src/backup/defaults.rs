//! What was changed from the factory default, as vendor tools show it: parameters whose value
//! (read from the device, or in a backup) differs from the `default` the profile gives,
//! compared through the registers both encode to. A parameter whose default the profile does
//! not know is not compared, only counted.

use ferrobus_profile::{Point, Value};

use super::file::{Backup, State};
use super::param;
use super::view::View;

/// A parameter that differs from its default.
#[derive(Clone, Debug)]
pub struct Changed<'v> {
    /// The parameter.
    pub point: &'v Point,
    /// Its value.
    pub value: Value,
    /// The profile's default.
    pub default: &'v Value,
}

/// What the comparison found.
#[derive(Clone, Debug, Default)]
pub struct Found<'v> {
    /// Parameters whose value is not the default, in the profile's order.
    pub changed: Vec<Changed<'v>>,
    /// Parameters compared (a default known, a value read).
    pub compared: usize,
    /// The codes of the parameters whose default the profile does not know.
    pub unknown: Vec<&'v str>,
    /// The codes of the parameters with a default but no value (not read), and why.
    pub unread: Vec<(&'v str, String)>,
}

/// The parameters the profile backs up, split into those whose default it knows and the
/// codes of the others.
pub fn split(view: &View) -> (Vec<&Point>, Vec<&str>) {
    let (known, unknown): (Vec<&Point>, Vec<&Point>) =
        view.backed_up().into_iter().partition(|p| p.factory_default.is_some());
    (known, unknown.into_iter().map(|p| p.code.as_str()).collect())
}

/// The backup's parameters against the profile's defaults (parameters the profile lacks are
/// left out).
pub fn of_backup<'v>(view: &'v View, backup: &Backup) -> Found<'v> {
    let mut unknown = Vec::new();
    let mut values = Vec::new();
    for entry in &backup.entries {
        let Some(point) = view.find(&entry.code) else { continue };
        if point.factory_default.is_none() {
            unknown.push(point.code.as_str());
            continue;
        }
        let value = match &entry.state {
            State::Value { raw, .. } => param::from_toml(point, raw).map_err(|e| e.to_string()),
            State::Failed(why) => Err(format!("the backup holds no value: {why}")),
        };
        values.push((point, value));
    }
    compare(values.into_iter(), unknown)
}

/// Each value against its point's default, through the registers both encode to.
pub fn compare<'v>(
    values: impl Iterator<Item = (&'v Point, Result<Value, String>)>,
    unknown: Vec<&'v str>,
) -> Found<'v> {
    let mut found = Found { changed: Vec::new(), compared: 0, unknown, unread: Vec::new() };
    for (point, value) in values {
        let Some(default) = &point.factory_default else { continue };
        match value {
            Ok(value) => {
                found.compared += 1;
                if param::encode(point, &value).ok() != param::encode(point, default).ok() {
                    found.changed.push(Changed { point, value, default });
                }
            }
            Err(why) => found.unread.push((point.code.as_str(), why)),
        }
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;
    use ferrobus_profile::Profile;

    const PROFILE: &str = "[device]\nname='t'\nvendor='t'\nproduct_code='t'\nrevision='1'\n\
        [[registers]]\nnumber=0\nname='A'\naccess='rw'\ndefault=60\nunit='Hz'\n\
        [[registers]]\nnumber=1\nname='B'\naccess='rw'\n\
        [[registers]]\nnumber=2\nname='C'\naccess='rw'\ndefault=0\n";

    fn backup(parameters: &str) -> Backup {
        let text = format!(
            "[backup]\nformat = 1\nprofile = \"t.toml\"\ndevice = \"t\"\ntime = \"x\"\nconnection = \"x\"\n\
             identification = \"none\"\nunit = 1\n\n[parameters]\n{parameters}"
        );
        Backup::parse(&text, "f.toml").unwrap()
    }

    #[test]
    fn a_backup_against_the_defaults_names_what_changed_counts_the_unknown_and_says_what_holds_no_value() {
        let view = View { name: "t.toml".into(), hash: None, profile: Profile::parse(PROFILE, "t.toml").unwrap() };
        let found = of_backup(&view, &backup("A = { raw = 50 }\nB = { raw = 1 }\nC = { error = \"no reply\" }\n"));
        let changed: Vec<(&str, &Value)> = found.changed.iter().map(|c| (c.point.code.as_str(), &c.value)).collect();
        assert_eq!(changed, [("A", &Value::Int(50))]);
        assert_eq!((found.compared, found.unknown.as_slice()), (1, ["B"].as_slice()));
        assert_eq!(found.unread, [("C", "the backup holds no value: no reply".to_string())]);
        let same = of_backup(&view, &backup("A = { raw = 60 }\nC = { raw = 0 }\n"));
        assert!(same.changed.is_empty() && same.compared == 2, "{same:?}");
        let (known, unknown) = split(&view);
        let codes: Vec<&str> = known.iter().map(|p| p.code.as_str()).collect();
        assert_eq!((codes, unknown), (vec!["A", "C"], vec!["B"]));
    }
}
