//! What the two YAML readers share: parsing with the place of a mistake, and reading the
//! scalars of a tree whose shape the file's author chose.

use serde_yaml_ng::{Mapping, Value};

use super::{Draft, ImportError};

/// Parses `text`; a mistake names its line and column (the YAML reader's message does).
pub(super) fn parse(text: &str, draft: &Draft) -> Result<Value, ImportError> {
    serde_yaml_ng::from_str(text).map_err(|e| draft.malformed(format!("not YAML: {e}")))
}

/// A scalar as written, for a message (a tree is shown by its kind).
pub(super) fn shown(value: &Value) -> String {
    match value {
        Value::Null => "null".to_string(),
        Value::Bool(b) => b.to_string(),
        Value::Number(n) => n.to_string(),
        Value::String(s) => s.clone(),
        Value::Sequence(items) => format!("a list of {}", items.len()),
        Value::Mapping(map) => format!("a map of {} keys", map.len()),
        Value::Tagged(tagged) => format!("{} {}", tagged.tag, shown(&tagged.value)),
    }
}

/// A key as text.
pub(super) fn key(value: &Value) -> String {
    match value {
        Value::String(s) => s.clone(),
        other => shown(other),
    }
}

/// The text of a string, number or boolean.
pub(super) fn text(value: &Value) -> Option<String> {
    match value {
        Value::String(s) => Some(s.trim().to_string()),
        Value::Number(n) => Some(n.to_string()),
        Value::Bool(b) => Some(b.to_string()),
        _ => None,
    }
}

/// A non-negative integer: a YAML integer, or text of one (decimal or `0x` hex).
pub(super) fn unsigned(value: &Value) -> Option<u64> {
    match value {
        Value::Number(n) => n.as_u64(),
        Value::String(s) => {
            let s = s.trim();
            match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
                Some(hex) => u64::from_str_radix(hex, 16).ok(),
                None => s.parse().ok(),
            }
        }
        _ => None,
    }
}

/// A finite number: a YAML number, or text of one.
pub(super) fn real(value: &Value) -> Option<f64> {
    let value = match value {
        Value::Number(n) => n.as_f64(),
        Value::String(s) => s.trim().parse().ok(),
        _ => None,
    }?;
    value.is_finite().then_some(value)
}

/// A unit number (`slave`, `device_address`, evcc's `id`): 0-255.
pub(super) fn unit(value: &Value) -> Option<u8> {
    unsigned(value).and_then(|u| u8::try_from(u).ok())
}

/// The entries of `map` in the file's order, keys as text.
pub(super) fn entries(map: &Mapping) -> impl Iterator<Item = (String, &Value)> {
    map.iter().map(|(k, v)| (key(k), v))
}

/// The items of a list, or the one item a map is (YAML lets a list of one be written bare).
pub(super) fn items(value: &Value) -> Vec<&Value> {
    match value {
        Value::Sequence(items) => items.iter().collect(),
        Value::Null => Vec::new(),
        other => vec![other],
    }
}

/// Lists every key of `map` that `known` does not name as not mapped, at `place`, for `why`.
pub(super) fn rest(map: &Mapping, known: &[&str], place: &str, why: &dyn Fn(&str) -> String, draft: &mut Draft) {
    for (k, v) in entries(map) {
        if !known.contains(&k.as_str()) {
            draft.unmapped(place, &k, &shown(v), &why(&k));
        }
    }
}
