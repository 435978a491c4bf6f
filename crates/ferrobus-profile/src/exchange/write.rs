//! The profile an import writes: TOML that reads like a hand-written profile.

use std::fmt::Write as _;

use super::{Entry, Format};
use crate::model::{Table, ValueType};

/// The profile named `name` with `entries`, from `origin` in `format`; `notes` say how the
/// source was read.
pub(crate) fn profile(name: &str, origin: &str, format: Format, notes: &[String], entries: &[Entry]) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "# Imported by `ferrobus profile import --from {}` from {}.", format.name(), line(origin));
    for note in notes {
        comment(&mut out, note);
    }
    out.push_str("# Addresses are the frame's (from 0). Check the units, scales and access against the\n");
    out.push_str("# device's manual: a map says what a tool read, not always what the device allows.\n\n");
    out.push_str("[device]\n");
    let _ = writeln!(out, "name = {}", string(name));
    out.push_str("vendor = \"unknown\"\n");
    out.push_str("product_code = \"imported\"\n");
    out.push_str("revision = \"unknown\"\n");
    out.push_str("identification = false\n\n");
    out.push_str("[addressing]\nbase = 0\n");
    for table in [Table::Coils, Table::DiscreteInputs, Table::Holding, Table::Input] {
        for entry in entries.iter().filter(|e| e.table == table) {
            out.push('\n');
            write_entry(&mut out, entry);
        }
    }
    out
}

/// The list an entry of `table` goes in.
fn list(table: Table) -> &'static str {
    match table {
        Table::Coils => "coils",
        Table::DiscreteInputs => "discrete_inputs",
        Table::Holding => "registers",
        Table::Input => "inputs",
    }
}

fn write_entry(out: &mut String, e: &Entry) {
    let _ = writeln!(out, "[[{}]]", list(e.table));
    let _ = writeln!(out, "number = {}", e.address);
    let _ = writeln!(out, "name = {}", string(&e.name));
    if let Some(label) = &e.label {
        let _ = writeln!(out, "label = {}", string(label));
    }
    if !e.description.is_empty() {
        let _ = writeln!(out, "description = {}", string(&e.description));
    }
    if e.table.is_bits() {
        // A coil or discrete input has a name, an access, a group and a default only (the
        // draft listed whatever else its source gave it).
        let _ = writeln!(out, "access = \"{}\"", e.access.name());
        if let Some(group) = &e.group {
            let _ = writeln!(out, "group = {}", string(group));
        }
        if let Some(default) = &e.default {
            let _ = writeln!(out, "default = {default}");
        }
        return;
    }
    if e.value_type != ValueType::U16 {
        let _ = writeln!(out, "type = \"{}\"", e.value_type.name());
    }
    if let Some(length) = e.length.filter(|_| e.value_type == ValueType::String) {
        let _ = writeln!(out, "length = {length}");
    }
    if let Some(order) = e.order.filter(|_| e.value_type.registers() > 1) {
        let _ = writeln!(out, "order = \"{}\"", order.name());
    }
    for (key, value) in [("scale", e.scale), ("offset", e.offset), ("min", e.min), ("max", e.max)] {
        if let Some(value) = value {
            let _ = writeln!(out, "{key} = {}", number(value));
        }
    }
    if let Some(unit) = &e.unit {
        let _ = writeln!(out, "unit = {}", string(unit));
    }
    let _ = writeln!(out, "access = \"{}\"", e.access.name());
    if let Some(group) = &e.group {
        let _ = writeln!(out, "group = {}", string(group));
    }
    for (key, pairs) in [("values", &e.values), ("bits", &e.bits)] {
        if !pairs.is_empty() {
            let inner: Vec<String> = pairs.iter().map(|(k, v)| format!("{} = {}", string(k), string(v))).collect();
            let _ = writeln!(out, "{key} = {{ {} }}", inner.join(", "));
        }
    }
    if let Some(default) = &e.default {
        let _ = writeln!(out, "default = {default}");
    }
}

/// A TOML basic string, escaped by the TOML writer.
fn string(text: &str) -> String {
    toml::Value::String(text.to_string()).to_string()
}

/// A TOML float that reads back as the same f64 (Rust's shortest round-trip form).
fn number(value: f64) -> String {
    format!("{value:?}")
}

/// `text` on one line, for a comment.
/// `text` as `#` comment lines of at most 90 characters (a longer word has its own line).
fn comment(out: &mut String, text: &str) {
    let mut line = String::from("#");
    for word in text.split_whitespace() {
        if line.len() > 1 && line.len() + 1 + word.len() > 90 {
            let _ = writeln!(out, "{line}");
            line = String::from("#");
        }
        line.push(' ');
        line.push_str(&super::shown(word));
    }
    let _ = writeln!(out, "{line}");
}

fn line(text: &str) -> String {
    super::shown(text).replace(['\n', '\r'], " ")
}
