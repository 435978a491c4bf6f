//! Scalars as serde_yaml_ng resolves them, and the tags a file's own nodes carry.

use serde_yaml_ng::Value;
use serde_yaml_ng::value::{Tag, TaggedValue};
use yaml_rust2::parser::Tag as YamlTag;
use yaml_rust2::scanner::TScalarStyle;

/// `value` with the tag a container was written with (none for the standard `!!` ones).
pub(super) fn tagged(value: Value, tag: Option<&YamlTag>) -> Value {
    match tag {
        Some(tag) if tag.handle != "tag:yaml.org,2002:" => match tag_of(tag) {
            Some(tag) => Value::Tagged(Box::new(TaggedValue { tag, value })),
            None => value,
        },
        _ => value,
    }
}

/// serde_yaml_ng's tag for a tag as written (none for the empty `!`).
fn tag_of(tag: &YamlTag) -> Option<Tag> {
    let text = if tag.handle == "!" { format!("!{}", tag.suffix) } else { format!("{}{}", tag.handle, tag.suffix) };
    (!text.is_empty() && text != "!").then(|| Tag::new(text))
}

/// A scalar: text if quoted, a block or `!!str`, else resolved as a plain scalar; a tag of
/// the file's own kept.
pub(super) fn scalar(text: String, style: TScalarStyle, tag: Option<&YamlTag>) -> Value {
    match tag {
        Some(tag) if tag.handle == "tag:yaml.org,2002:" => match tag.suffix.as_str() {
            "str" | "binary" | "timestamp" => Value::String(text),
            _ => plain(text),
        },
        Some(tag) => match tag_of(tag) {
            Some(t) => Value::Tagged(Box::new(TaggedValue { tag: t, value: scalar(text, style, None) })),
            None => Value::String(text),
        },
        None if style == TScalarStyle::Plain => plain(text),
        None => Value::String(text),
    }
}

/// A plain scalar as serde_yaml_ng resolves it: null, a boolean, an integer (decimal, `0x`,
/// `0o`, `0b`), a finite float or `.inf`/`.nan`, else text.
fn plain(text: String) -> Value {
    match text.as_str() {
        "" | "~" | "null" | "Null" | "NULL" => return Value::Null,
        "true" | "True" | "TRUE" => return Value::Bool(true),
        "false" | "False" | "FALSE" => return Value::Bool(false),
        _ => {}
    }
    if let Some(n) = unsigned_int(&text) {
        return Value::Number(n.into());
    }
    if let Some(n) = negative_int(&text) {
        return Value::Number(n.into());
    }
    if !leading_zero(&text)
        && let Some(f) = float(&text)
    {
        return Value::Number(f.into());
    }
    Value::String(text)
}

/// Digits after a leading zero (`0123`): text in YAML 1.2, as serde_yaml_ng reads it.
fn leading_zero(text: &str) -> bool {
    let digits = text.strip_prefix(['-', '+']).unwrap_or(text);
    digits.len() > 1 && digits.starts_with('0') && digits.bytes().all(|b| b.is_ascii_digit())
}

/// A non-negative integer: `+`, then `0x`, `0o`, `0b` or decimal digits.
fn unsigned_int(text: &str) -> Option<u64> {
    let digits = text.strip_prefix('+').unwrap_or(text);
    for (prefix, radix) in [("0x", 16), ("0o", 8), ("0b", 2)] {
        if let Some(rest) = digits.strip_prefix(prefix) {
            if rest.starts_with(['+', '-']) {
                return None;
            }
            if let Ok(n) = u64::from_str_radix(rest, radix) {
                return Some(n);
            }
        }
    }
    if digits.starts_with(['+', '-']) || leading_zero(text) {
        return None;
    }
    digits.parse().ok()
}

/// A negative integer: `-`, then `0x`, `0o`, `0b` or decimal digits.
fn negative_int(text: &str) -> Option<i64> {
    let rest = text.strip_prefix('-')?;
    for (prefix, radix) in [("0x", 16), ("0o", 8), ("0b", 2)] {
        if let Some(digits) = rest.strip_prefix(prefix)
            && let Ok(n) = i64::from_str_radix(&format!("-{digits}"), radix)
        {
            return Some(n);
        }
    }
    if leading_zero(text) {
        return None;
    }
    text.parse().ok()
}

/// A float: `.inf`, `-.inf`, `.nan` (in their cases), or a finite number.
fn float(text: &str) -> Option<f64> {
    let unsigned = match text.strip_prefix('+') {
        Some(rest) if rest.starts_with(['+', '-']) => return None,
        Some(rest) => rest,
        None => text,
    };
    match (unsigned, text) {
        (".inf" | ".Inf" | ".INF", _) => return Some(f64::INFINITY),
        (_, "-.inf" | "-.Inf" | "-.INF") => return Some(f64::NEG_INFINITY),
        (_, ".nan" | ".NaN" | ".NAN") => return Some(f64::NAN),
        _ => {}
    }
    unsigned.parse::<f64>().ok().filter(|f| f.is_finite())
}
