//! The profile an import writes: TOML that reads like a hand-written profile.

use std::fmt::Write as _;

use super::{Entry, Format};
use crate::model::{BitDef, DeviceSection, Profile, RegisterDef, Table, ValueType};

/// The profile named `name` with `entries`, as data, not yet checked.
pub(crate) fn profile(name: &str, entries: &[Entry]) -> Profile {
    let mut device = DeviceSection::new(name, "unknown", "imported", "unknown");
    device.identification = false;
    let mut profile = Profile::new(device);
    for table in [Table::Coils, Table::DiscreteInputs, Table::Holding, Table::Input] {
        for e in entries.iter().filter(|e| e.table == table) {
            match table {
                Table::Coils => profile.coils.push(bit(e)),
                Table::DiscreteInputs => profile.discrete_inputs.push(bit(e)),
                Table::Holding => profile.registers.push(register(e)),
                Table::Input => profile.inputs.push(register(e)),
            }
        }
    }
    profile
}

/// The file of `profile`, imported from `origin` in `format`: a header that says so, with
/// `notes` on how the source was read, then the profile.
pub(crate) fn file(profile: &Profile, origin: &str, format: Format, notes: &[String]) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "# Imported by `ferrobus profile import --from {}` from {}.", format.name(), line(origin));
    for note in notes {
        comment(&mut out, note);
    }
    out.push_str("# Addresses are the frame's (from 0). Check the units, scales and access against the\n");
    out.push_str("# device's manual: a map says what a tool read, not always what the device allows.\n\n");
    out.push_str(&profile.to_toml());
    out
}

/// A coil or discrete input: a name, an access, a group and a default only (the draft listed
/// whatever else its source gave it).
fn bit(e: &Entry) -> BitDef {
    let mut bit = BitDef::new(u32::from(e.address), &e.name);
    bit.label.clone_from(&e.label);
    bit.description.clone_from(&e.description);
    bit.access = e.access;
    bit.group.clone_from(&e.group);
    bit.default = e.default.as_ref().and_then(toml::Value::as_bool);
    bit
}

fn register(e: &Entry) -> RegisterDef {
    let mut r = RegisterDef::new(u32::from(e.address), &e.name, e.value_type);
    r.label.clone_from(&e.label);
    r.description.clone_from(&e.description);
    r.length = e.length.filter(|_| e.value_type == ValueType::String);
    r.order = e.order.filter(|_| e.value_type.registers() > 1);
    (r.scale, r.offset, r.min, r.max) = (e.scale, e.offset, e.min, e.max);
    r.unit.clone_from(&e.unit);
    r.access = e.access;
    r.group.clone_from(&e.group);
    r.values = e.values.iter().cloned().collect();
    r.bits = e.bits.iter().cloned().collect();
    r.default.clone_from(&e.default);
    r
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
