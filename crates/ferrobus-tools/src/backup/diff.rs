//! Two backups compared parameter by parameter: a difference is a parameter whose raw values
//! differ to the device (through the registers they encode to, so `1.0` and `1` of an `f32`
//! agree), that one side could not read, or that only one side has.

use ferrobus_profile::Point;

use super::file::{Backup, Entry, State};
use super::param::{self, shown_toml};
use super::view::View;

/// One side of a comparison.
#[derive(Clone, Debug)]
pub enum Side {
    /// A value: raw, and shown in the profile's unit.
    Value(toml::Value, String),
    /// It could not be read: why.
    Failed(String),
    /// The side has no entry for it.
    Absent,
}

impl Side {
    fn of(entry: Option<&Entry>, point: Option<&Point>) -> Side {
        match entry.map(|e| &e.state) {
            Some(State::Value { raw, shown }) => {
                let shown = match point.and_then(|p| param::from_toml(p, raw).ok().map(|v| p.show(&v))) {
                    Some(shown) => shown,
                    None if shown.is_empty() => shown_toml(raw),
                    None => shown.clone(),
                };
                Side::Value(raw.clone(), shown)
            }
            Some(State::Failed(why)) => Side::Failed(why.clone()),
            None => Side::Absent,
        }
    }

    /// The side as a table shows it: the value in the profile's unit, or why there is none.
    pub fn shown(&self) -> String {
        match self {
            Side::Value(_, shown) => shown.clone(),
            Side::Failed(why) => format!("(not read: {why})"),
            Side::Absent => "(absent)".into(),
        }
    }
}

/// Whether two raw values are the same to the device: through the registers they encode to,
/// when the parameter is known and both encode; as TOML values otherwise.
pub fn same(point: Option<&Point>, a: &toml::Value, b: &toml::Value) -> bool {
    let words = |p: &Point, raw: &toml::Value| param::from_toml(p, raw).and_then(|v| param::encode(p, &v));
    if let Some(p) = point
        && let (Ok(x), Ok(y)) = (words(p, a), words(p, b))
    {
        return x == y;
    }
    a == b
}

/// One difference.
#[derive(Clone, Debug)]
pub struct Difference {
    /// The code.
    pub code: String,
    /// The label, if the profile knows it.
    pub label: String,
    /// The first side (the file).
    pub a: Side,
    /// The second side (the device, or the second file).
    pub b: Side,
}

/// The differences between `a` and `b`, in `a`'s order then `b`'s extras.
pub fn compare(view: Option<&View>, a: &Backup, b: &Backup) -> Vec<Difference> {
    let mut codes: Vec<&str> = a.entries.iter().map(|e| e.code.as_str()).collect();
    for e in &b.entries {
        if a.entry(&e.code).is_none() {
            codes.push(&e.code);
        }
    }
    let mut out = Vec::new();
    for code in codes {
        let point = view.and_then(|v| v.find(code));
        let (ea, eb) = (a.entry(code), b.entry(code));
        let equal = match (ea.map(|e| &e.state), eb.map(|e| &e.state)) {
            (Some(State::Value { raw: x, .. }), Some(State::Value { raw: y, .. })) => same(point, x, y),
            _ => false,
        };
        if !equal {
            out.push(Difference {
                code: code.to_string(),
                label: point.map(|p| param::label(p).to_string()).unwrap_or_default(),
                a: Side::of(ea, point),
                b: Side::of(eb, point),
            });
        }
    }
    out
}
