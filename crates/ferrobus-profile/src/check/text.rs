//! The strings of a profile: printable, and bounded in length.
//!
//! A profile's names, labels and units reach a terminal (`profile show`, `get`), logs and MQTT
//! topics; a map imported from another tool may carry anything. Every string of the file —
//! values and table keys, in every section and entry, read or not — is checked before the
//! entries are read:
//!
//! - no control character (C0, DEL, C1) but the tab, no line or paragraph separator, no
//!   bidirectional control; a `description` or `source` may break lines (`\n`, `\r`);
//! - at most [`NAME_MAX`] characters for a name, a code, a group or another short word,
//!   [`UNIT_MAX`] for a unit, [`LABEL_MAX`] for a label, a device's name or a meaning, and
//!   [`TEXT_MAX`] for a description and anything else.
//!
//! A mistake names the entry and the field, and shows the character escaped.

use toml::Spanned;
use toml::de::{DeTable, DeValue};

use crate::check::{LISTS, Problem, entry_name};

/// The most characters of a name, a code, a group, a reference to another point, an order, ...
pub const NAME_MAX: usize = 128;
/// The most characters of a unit.
pub const UNIT_MAX: usize = 32;
/// The most characters of a label, a device's name, an enumeration's or a bit's meaning.
pub const LABEL_MAX: usize = 256;
/// The most characters of a description, a source or any other string.
pub const TEXT_MAX: usize = 4096;

/// Whether `c` may not appear in a profile's text (the characters a log escapes).
pub(crate) fn forbidden(c: char) -> bool {
    c.is_control()
        || matches!(c,
            '\u{2028}' | '\u{2029}'
            | '\u{200E}' | '\u{200F}' | '\u{061C}'
            | '\u{202A}'..='\u{202E}'
            | '\u{2066}'..='\u{2069}')
}

/// What a string is, by the key that holds it: its limit, its name in messages, and whether
/// it may break lines.
fn kind(section: &str, parent: Option<&str>, key: &str) -> (usize, &'static str, bool) {
    if matches!(parent, Some("values" | "bits")) {
        return (LABEL_MAX, "meaning", false);
    }
    match key {
        "name" if section == "[device]" => (LABEL_MAX, "device name", false),
        "name" | "group" | "depends_on" | "point" | "vendor" | "product_code" | "revision" | "server_id" | "type"
        | "order" | "access" | "kind" | "direction" | "table" => (NAME_MAX, "name", false),
        "unit" => (UNIT_MAX, "unit", false),
        "label" | "product_name" | "model_name" | "vendor_url" | "user_application_name" | "meaning" => {
            (LABEL_MAX, "label", false)
        }
        "description" | "source" => (TEXT_MAX, "text", true),
        _ => (TEXT_MAX, "text", false),
    }
}

/// The mistakes of the strings of document `root`.
pub(crate) fn strings(root: &DeTable<'_>) -> Vec<Problem> {
    let mut problems = Vec::new();
    for (key, value) in root {
        let key = key.get_ref().as_ref();
        match value.get_ref() {
            DeValue::Array(items) if LISTS.contains(&key) => {
                for (i, item) in items.iter().enumerate() {
                    let table = item.get_ref().as_table();
                    let place = entry_name(key, i, table);
                    if let Some(table) = table {
                        walk_table(&place, None, table, &mut problems);
                    }
                }
            }
            DeValue::Table(table) => walk_table(&format!("[{key}]"), None, table, &mut problems),
            _ => walk(key, None, key, value, &mut problems),
        }
    }
    problems
}

fn walk_table(place: &str, parent: Option<&str>, table: &DeTable<'_>, problems: &mut Vec<Problem>) {
    for (key, value) in table {
        let name = key.get_ref().as_ref();
        if parent.is_some() {
            // A table's own keys (an enumeration's values, a bit's number) are short words.
            check(
                place,
                &format!("{} key", parent.unwrap_or_default()),
                name,
                key.span().start,
                (NAME_MAX, "key", false),
                problems,
            );
        }
        walk(place, parent, name, value, problems);
    }
}

fn walk(place: &str, parent: Option<&str>, key: &str, value: &Spanned<DeValue<'_>>, problems: &mut Vec<Problem>) {
    match value.get_ref() {
        DeValue::String(s) => {
            let field = parent.map_or_else(|| key.to_string(), |p| format!("{p}.{key}"));
            check(place, &field, s, value.span().start, kind(place, parent, key), problems);
        }
        DeValue::Array(items) => {
            for item in items {
                walk(place, parent, key, item, problems);
            }
        }
        DeValue::Table(table) => walk_table(place, Some(key), table, problems),
        _ => {}
    }
}

/// Pushes the mistake of string `text` of `field` at byte `at`, if it has one.
fn check(
    place: &str,
    field: &str,
    text: &str,
    at: usize,
    (max, what, lines): (usize, &str, bool),
    problems: &mut Vec<Problem>,
) {
    let allowed = |c: char| c == '\t' || (lines && matches!(c, '\n' | '\r'));
    if let Some((i, c)) = text.char_indices().find(|&(_, c)| forbidden(c) && !allowed(c)) {
        let shown: String = c.escape_unicode().collect();
        problems.push((
            Some(at),
            format!(
                "{place}: {field} holds the control character {shown} at character {}: a profile's text must be \
                 printable",
                text.get(..i).map_or(0, |s| s.chars().count()).saturating_add(1)
            ),
        ));
    }
    if text.chars().nth(max).is_some() {
        problems.push((
            Some(at),
            format!(
                "{place}: {field} is {} characters long, more than the {max} a {what} may have",
                text.chars().count()
            ),
        ));
    }
}
