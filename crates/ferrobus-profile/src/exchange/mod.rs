//! Device maps users already have, to and from profiles: a vendor's CSV register list, the
//! YAML of a Home Assistant `modbus:` configuration, and the YAML of an evcc configuration.
//!
//! ```text
//!   CSV / HA YAML / evcc YAML ──import()──▶ Imported { toml, unmapped }   (a profile, checked)
//!   Profile ──export_csv()──▶ CSV (the columns of our own format, one row per point)
//! ```
//!
//! An import writes a profile that reads like a hand-written one: a comment naming the source
//! and its format, `[device]`, then one entry per point, in the file's order, each table in
//! its own list. Everything of the source that has no place in a profile — a Home Assistant
//! display setting, an evcc template expression, a CSV column of no meaning here, a byte swap
//! of a 16-bit value, a second entry at an address already taken — is listed in
//! [`Imported::unmapped`] with where it is in the source (a CSV row, a YAML path such as
//! `modbus[0].sensors[3]`) and why; nothing is dropped silently. The profile text is parsed and
//! checked before it is returned, so what `import` gives passes `profile check`.
//!
//! Addresses: the YAML formats carry the address the frame carries (from 0), and so does our
//! CSV unless [`ImportOptions::base`] says the file numbers from 1 (a manual's register
//! numbers), or, without it, every address of the file is a Modicon register number (30001 is
//! input register 0, 40001 holding register 0: meters' manuals number them so; a note says
//! so); the profile written has `base = 0`.
//!
//! YAML is read event by event (yaml-rust2's parser) into serde_yaml_ng's `Value`, its
//! scalars resolved as serde_yaml_ng resolves them, as Home Assistant's loader reads a file:
//! merge keys, `!include` and `!secret` (from [`ImportOptions::dir`]), each unresolved tag
//! listed; nesting, aliases, includes and sizes bounded ([`MAP_MAX`]). CSV is the `csv`
//! crate, the delimiter (`,`, `;` or a tab) taken from the header line. The formats and their mapping tables are documented in
//! `docs/device-maps.md`.

mod csv;
mod evcc;
mod ha;
mod write;
mod yaml;

use std::collections::{HashMap, HashSet};
use std::fmt;
use std::path::PathBuf;

pub use csv::export_csv;

use crate::check::text::{LABEL_MAX, NAME_MAX, TEXT_MAX, UNIT_MAX, forbidden};
use crate::model::{Access, Order, Table, ValueType};

/// What a map file is.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Format {
    /// A register list as CSV: ferrobus's own columns, and the common vendor variants.
    Csv,
    /// A Home Assistant `modbus:` configuration (sensors, binary sensors, switches, ...).
    HaYaml,
    /// An evcc configuration: every `source: modbus` block with a `register`.
    EvccYaml,
}

impl Format {
    /// The name on the command line: `csv`, `ha-yaml`, `evcc-yaml`.
    pub const fn name(self) -> &'static str {
        match self {
            Format::Csv => "csv",
            Format::HaYaml => "ha-yaml",
            Format::EvccYaml => "evcc-yaml",
        }
    }
}

/// How to read a map.
#[derive(Clone, Debug, Default)]
pub struct ImportOptions {
    /// The profile's `[device] name`; by default the source file's name.
    pub name: Option<String>,
    /// Only the entries of this unit (Home Assistant's `slave`/`device_address`, evcc's `id`):
    /// needed when a file describes several devices.
    pub unit: Option<u8>,
    /// Only the entries of the evcc device of this `name:` (a meter, a charger): needed when
    /// the file describes several, which are one profile each. It names the profile too,
    /// unless [`ImportOptions::name`] does.
    pub device: Option<String>,
    /// The number a CSV file gives the first address (1 for a manual's register numbers);
    /// subtracted from every CSV address. Unless given, a file whose every address is a
    /// Modicon register number (30001, 40001, ...) is read as one, and any other from 0.
    pub base: Option<u16>,
    /// The directory of the map file: a YAML map's `!include` files are read from it (and
    /// from the including file's directory, inside it), its `!secret` values from the
    /// `secrets.yaml` files there. `None` (the default): no file is read, and every
    /// `!include` and `!secret` is listed as not mapped.
    pub dir: Option<PathBuf>,
}

/// The largest map file an import reads, and each file a YAML map includes: 16 MiB.
pub const MAP_MAX: u64 = 16 << 20;

/// Something of the source that the profile does not carry.
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct Unmapped {
    /// Where in the source: `line 7`, `modbus[0].sensors[3]` (bounded, control characters
    /// escaped).
    pub place: String,
    /// The field, the column or the key.
    pub field: String,
    /// Its value as written (bounded, control characters escaped).
    pub value: String,
    /// Why it could not be mapped (bounded, control characters escaped).
    pub why: String,
}

impl fmt::Display for Unmapped {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.value.is_empty() {
            write!(f, "{}: {}: {}", self.place, self.field, self.why)
        } else {
            write!(f, "{}: {} = {}: {}", self.place, self.field, self.value, self.why)
        }
    }
}

/// A map turned into a profile.
#[derive(Clone, Debug)]
pub struct Imported {
    /// The profile's file: a header saying where it came from, then [`Profile::to_toml`](crate::Profile::to_toml).
    pub toml: String,
    /// The profile, checked, its points resolved.
    pub profile: crate::Profile,
    /// How many points (entries) it has.
    pub points: usize,
    /// What of the source it does not carry, in the source's order.
    pub unmapped: Vec<Unmapped>,
    /// How the source was read where it could have been read otherwise (a CSV's Modicon
    /// register numbers), for the user to check; the profile's header says it too.
    pub notes: Vec<String>,
}

/// Why a map could not be imported.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ImportError {
    /// The file is not what its format says: CSV without a header or an address column, YAML
    /// that does not parse, a YAML tree without the format's sections.
    #[error("{origin}: {message}")]
    Malformed {
        /// The source, as named.
        origin: String,
        /// What is wrong, and where.
        message: String,
    },
    /// The file describes several devices and no `unit` picks one.
    #[error("{origin} describes units {units}: pick one with --only-unit")]
    SeveralUnits {
        /// The source, as named.
        origin: String,
        /// The units found, comma-separated.
        units: String,
    },
    /// The evcc file describes several devices and no `device` picks one.
    #[error(
        "{origin} describes {count} devices ({devices}): each is a profile of its own: import one with --only-device NAME"
    )]
    SeveralDevices {
        /// The source, as named.
        origin: String,
        /// How many.
        count: usize,
        /// Their names, comma-separated.
        devices: String,
    },
    /// Nothing of the file could be mapped to a point.
    #[error("{origin}: no entry could be mapped to a profile point{}", if *unmapped == 0 { String::new() } else { format!(" ({unmapped} things not mapped)") })]
    Nothing {
        /// The source, as named.
        origin: String,
        /// How many things were listed as unmapped.
        unmapped: usize,
        /// What was listed.
        list: Vec<Unmapped>,
    },
    /// The profile written does not pass the profile checks: a bug of the importer, with the
    /// checker's words.
    #[error("{origin}: the profile written from it does not check: {message}")]
    Invalid {
        /// The source, as named.
        origin: String,
        /// The checker's first complaint.
        message: String,
    },
}

/// Reads the map `text` (called `origin` in messages and in the profile's header) as `format`.
pub fn import(text: &str, origin: &str, format: Format, options: &ImportOptions) -> Result<Imported, ImportError> {
    let mut draft = Draft::new(origin, format, options);
    if text.len() as u64 > MAP_MAX {
        return Err(draft.malformed(format!("larger than the {} MiB a map file may be: refused", MAP_MAX >> 20)));
    }
    match format {
        Format::Csv => csv::read(text, &mut draft)?,
        Format::HaYaml => ha::read(text, &mut draft)?,
        Format::EvccYaml => evcc::read(text, &mut draft)?,
    }
    draft.finish()
}

/// One point of the profile to write.
#[derive(Clone, Debug)]
pub(crate) struct Entry {
    pub(crate) table: Table,
    /// The frame's address.
    pub(crate) address: u16,
    pub(crate) name: String,
    pub(crate) label: Option<String>,
    pub(crate) description: String,
    pub(crate) value_type: ValueType,
    /// Registers of a string.
    pub(crate) length: Option<u16>,
    pub(crate) order: Option<Order>,
    pub(crate) scale: Option<f64>,
    pub(crate) offset: Option<f64>,
    pub(crate) unit: Option<String>,
    pub(crate) access: Access,
    pub(crate) min: Option<f64>,
    pub(crate) max: Option<f64>,
    pub(crate) group: Option<String>,
    pub(crate) values: Vec<(String, String)>,
    pub(crate) bits: Vec<(String, String)>,
    pub(crate) default: Option<toml::Value>,
    /// Where it came from, for the messages about it.
    pub(crate) place: String,
}

impl Entry {
    /// A point of `table` at `address` named `name`, everything else unset: u16 (a bit for
    /// the bit tables), read-only.
    pub(crate) fn new(table: Table, address: u16, name: &str, place: String) -> Entry {
        let (code, label) = code_and_label(name);
        Entry {
            table,
            address,
            name: code,
            label,
            description: String::new(),
            value_type: if table.is_bits() { ValueType::Bit } else { ValueType::U16 },
            length: None,
            order: None,
            scale: None,
            offset: None,
            unit: None,
            access: Access::Ro,
            min: None,
            max: None,
            group: None,
            values: Vec::new(),
            bits: Vec::new(),
            default: None,
            place,
        }
    }

    /// Registers (or bits) it takes.
    pub(crate) fn width(&self) -> u16 {
        match self.value_type {
            ValueType::String => self.length.unwrap_or(1),
            other => other.registers(),
        }
    }
}

/// A profile being built from a map.
pub(crate) struct Draft {
    origin: String,
    format: Format,
    pub(crate) options: ImportOptions,
    entries: Vec<Entry>,
    pub(crate) unmapped: Vec<Unmapped>,
    /// How the source was read where it could have been read otherwise.
    pub(crate) notes: Vec<String>,
    /// Per table, the addresses taken: (first, end, entry index).
    taken: HashMap<Table, Vec<(u32, u32, usize)>>,
    /// The codes taken, in lower case.
    codes: HashSet<String>,
    /// What [`Draft::unmapped_once`] listed: (field, value, why) -> index in `unmapped`.
    repeated: HashMap<(String, String, String), usize>,
    /// How many more places each of those was seen at: (index in `unmapped`, count).
    more: Vec<(usize, usize)>,
    /// The (place, field) of each value a YAML `!secret` gave, and that `!secret NAME`: a
    /// listing shows the tag, never the secret.
    pub(crate) secret_at: HashMap<(String, String), String>,
    /// The text of each text value a `!secret` gave, and that `!secret NAME`: where an alias
    /// or a merge took it elsewhere, the listing still shows the tag.
    pub(crate) secret_texts: HashMap<String, String>,
}

impl Draft {
    fn new(origin: &str, format: Format, options: &ImportOptions) -> Draft {
        Draft {
            origin: origin.to_string(),
            format,
            options: options.clone(),
            entries: Vec::new(),
            unmapped: Vec::new(),
            notes: Vec::new(),
            taken: HashMap::new(),
            codes: HashSet::new(),
            repeated: HashMap::new(),
            more: Vec::new(),
            secret_at: HashMap::new(),
            secret_texts: HashMap::new(),
        }
    }

    /// The error for a file that is not what its format says.
    pub(crate) fn malformed(&self, message: impl Into<String>) -> ImportError {
        ImportError::Malformed { origin: self.origin.clone(), message: message.into() }
    }

    /// The error for an evcc file of several devices when none was picked.
    pub(crate) fn several_devices(&self, names: &[&str]) -> ImportError {
        let devices = names.iter().map(|n| shown(n)).collect::<Vec<_>>().join(", ");
        ImportError::SeveralDevices { origin: self.origin.clone(), count: names.len(), devices }
    }

    /// The error for a file of several units when none was picked.
    pub(crate) fn several_units(&self, units: &[u8]) -> ImportError {
        let units = units.iter().map(ToString::to_string).collect::<Vec<_>>().join(", ");
        ImportError::SeveralUnits { origin: self.origin.clone(), units }
    }

    /// Lists `field = value` at `place` as not mapped, for `why`, unless the same was listed
    /// before: then that listing counts one more place (a connection setting every block of a
    /// file repeats is listed once).
    pub(crate) fn unmapped_once(&mut self, place: &str, field: &str, value: &str, why: &str) {
        let key = (shown(field), shown(value), why.to_string());
        if let Some(&index) = self.repeated.get(&key) {
            if let Some((_, more)) = self.more.iter_mut().find(|(i, _)| *i == index) {
                *more += 1;
            } else {
                self.more.push((index, 1));
            }
            return;
        }
        self.repeated.insert(key, self.unmapped.len());
        self.unmapped(place, field, value, why);
    }

    /// Lists `field = value` at `place` as not mapped, for `why`.
    pub(crate) fn unmapped(&mut self, place: &str, field: &str, value: &str, why: &str) {
        // A place is a path of the file's own keys, and a reason may quote the file: both are
        // bounded and escaped as a value is. A secret's value is shown as its tag.
        let value = self
            .secret_at
            .get(&(place.to_string(), field.to_string()))
            .or_else(|| self.secret_texts.get(value.trim()))
            .map_or(value, String::as_str);
        self.unmapped.push(Unmapped {
            place: bounded(place, 160),
            field: shown(field),
            value: shown(value),
            why: bounded(why, 400),
        });
    }

    /// Adds `entry`, unless it shares an address with one added before (then it is listed);
    /// a name taken already gets a suffix (listed too).
    pub(crate) fn add(&mut self, mut entry: Entry) {
        self.bound(&mut entry);
        if entry.table.is_bits() {
            self.bits_only(&mut entry);
        } else {
            self.fit(&mut entry);
        }
        if matches!(entry.table, Table::Input | Table::DiscreteInputs) && entry.access != Access::Ro {
            let why = format!("{} cannot be written (no function code writes them): read-only", entry.table.name());
            let at = entry.place.clone();
            self.unmapped(&at, "access", entry.access.name(), &why);
            entry.access = Access::Ro;
        }
        let first = u32::from(entry.address);
        let end = first + u32::from(entry.width());
        if end > 0x1_0000 {
            let why = format!("{} registers from address {} run past the address space", entry.width(), entry.address);
            self.unmapped(&entry.place.clone(), "address", &entry.address.to_string(), &why);
            return;
        }
        let taken = self.taken.entry(entry.table).or_default();
        if let Some(&(a, b, owner)) = taken.iter().find(|(a, b, _)| first < *b && *a < end) {
            let Some(kept) = self.entries.get_mut(owner) else {
                return;
            };
            let (name, place) = (kept.name.clone(), kept.place.clone());
            let at = entry.place.clone();
            if (a, b) == (first, end) && kept.value_type == entry.value_type && kept.order == entry.order {
                // The same value read in one place and written in another (evcc's `enabled`
                // and `enable`), or shown twice: one point, writable if either writes it.
                if entry.access != Access::Ro && kept.access != entry.access {
                    kept.access = Access::Rw;
                }
                let why = format!(
                    "the same {} {} as {name} ({place}): one point, {}",
                    entry.table.name(),
                    entry.address,
                    kept.access.name()
                );
                self.unmapped(&at, "name", &entry.name, &why);
                return;
            }
            let why =
                format!("{} {} shares its address with {name} ({place}), kept", entry.table.name(), entry.address);
            self.unmapped(&at, "address", &entry.address.to_string(), &why);
            return;
        }
        taken.push((first, end, self.entries.len()));
        // A code is the profile's one, in any case and every table: `get` finds a point by its
        // code whatever its case, and the profile's check refuses two points with one.
        if self.codes.contains(&entry.name.to_lowercase()) {
            let base = entry.name.clone();
            // Fewer codes than suffixes: one of the first `len + 2` is free.
            let free = (2..self.codes.len() + 3)
                .map(|n| format!("{base}_{n}"))
                .find(|n| !self.codes.contains(&n.to_lowercase()));
            if let Some(free) = free {
                let at = entry.place.clone();
                self.unmapped(&at, "name", &base, &format!("taken by an earlier entry: written as {free}"));
                entry.name = free;
            }
        }
        self.codes.insert(entry.name.to_lowercase());
        self.entries.push(entry);
    }

    /// Fits an entry's text to what a profile may hold ([`crate::check::text`]), so that a
    /// long or unprintable cell costs that field and not the file: a label is cut, a
    /// description is cut and its control characters spelled out; a unit, a group, a meaning
    /// or a string default too long or holding a control character is listed and left out.
    /// (The code was fitted already: [`code_and_label`].)
    fn bound(&mut self, entry: &mut Entry) {
        let place = entry.place.clone();
        if let Some(label) = entry.label.take_if(|label| label.chars().nth(LABEL_MAX).is_some()) {
            let cut: String = label.chars().take(LABEL_MAX - 1).chain(['…']).collect();
            let why = format!("longer than the {LABEL_MAX} characters of a label: cut");
            self.unmapped(&place, "label", &label, &why);
            entry.label = Some(cut);
        }
        if entry.description.chars().any(|c| forbidden(c) && !matches!(c, '\t' | '\n' | '\r')) {
            entry.description = spelled(&entry.description, |c| matches!(c, '\t' | '\n' | '\r'));
        }
        if entry.description.chars().nth(TEXT_MAX).is_some() {
            let why = format!("longer than the {TEXT_MAX} characters of a description: cut");
            self.unmapped(&place, "description", &entry.description.clone(), &why);
            entry.description = entry.description.chars().take(TEXT_MAX - 1).chain(['…']).collect();
        }
        for (field, value, max) in [("unit", &mut entry.unit, UNIT_MAX), ("group", &mut entry.group, NAME_MAX)] {
            if let Some(text) = value.take_if(|text| !printable(text, max)) {
                self.unmapped(&place, field, &text, &unprintable(field, max));
            }
        }
        for (field, pairs) in [("values", &mut entry.values), ("bits", &mut entry.bits)] {
            let (kept, left): (Vec<_>, Vec<_>) =
                std::mem::take(pairs).into_iter().partition(|(_, meaning)| printable(meaning, LABEL_MAX));
            *pairs = kept;
            for (key, meaning) in left {
                self.unmapped(&place, field, &format!("{key}={meaning}"), &unprintable("meaning", LABEL_MAX));
            }
        }
        if let Some(default) = entry.default.take_if(|d| d.as_str().is_some_and(|text| !printable(text, TEXT_MAX))) {
            self.unmapped(&place, "default", &default.to_string(), &unprintable("default", TEXT_MAX));
        }
    }

    /// Lists and clears what a register's type cannot have, so that one bad cell costs its
    /// field and not the file: a string's range and scale, a range that is no raw value of the
    /// type or is upside down, an enumeration or bit field of another type or out of its
    /// range, a default that is no value of the type.
    fn fit(&mut self, entry: &mut Entry) {
        let place = entry.place.clone();
        let ty = entry.value_type;
        let name = ty.name();
        if ty == ValueType::String {
            let why = "a string has no range, scale or offset";
            for (field, value) in [
                ("min", entry.min.take()),
                ("max", entry.max.take()),
                ("scale", entry.scale.take()),
                ("offset", entry.offset.take()),
            ] {
                if let Some(value) = value {
                    self.unmapped(&place, field, &value.to_string(), why);
                }
            }
        }
        if ty.is_integer() {
            let (lo, hi) = ty.integer_range();
            #[allow(clippy::cast_precision_loss)] // the bounds of 64-bit types, compared as the checker does
            let (lo, hi) = (lo as f64, hi as f64);
            for (field, value) in [("min", &mut entry.min), ("max", &mut entry.max)] {
                if let Some(v) = value.take_if(|v| *v < lo || *v > hi || v.fract() != 0.0) {
                    self.unmapped(&place, field, &v.to_string(), &format!("not a raw {name} value (the range is raw)"));
                }
            }
        }
        if let (Some(min), Some(max)) = (entry.min, entry.max)
            && min > max
        {
            let why = format!("above max = {max}: the range is left out");
            self.unmapped(&place, "min", &min.to_string(), &why);
            entry.min = None;
            entry.max = None;
        }
        let (lo, hi) = ty.integer_range();
        let bit_count = i128::from(ty.registers()) * 16;
        let values = std::mem::take(&mut entry.values);
        entry.values = self.keep_pairs(&place, "values", values, ty, |k| (lo..=hi).contains(&k));
        let bits = std::mem::take(&mut entry.bits);
        entry.bits = self.keep_pairs(&place, "bits", bits, ty, |k| (0..bit_count).contains(&k));
        let default_fits = match (&entry.default, ty) {
            (None, _) => true,
            (Some(toml::Value::String(text)), ValueType::String) => {
                text.is_ascii() && text.len() <= usize::from(entry.width()) * 2
            }
            (Some(toml::Value::Integer(n)), t) if t.is_integer() => (lo..=hi).contains(&i128::from(*n)),
            (Some(toml::Value::Integer(_) | toml::Value::Float(_)), t) => t.is_float(),
            _ => false,
        };
        if !default_fits && let Some(default) = entry.default.take() {
            self.unmapped(&place, "default", &default.to_string(), &format!("not a {name} value: left out"));
        }
    }

    /// The pairs of an enumeration or bit field (`field`) of a `ty` whose keys `fits`; the others
    /// listed.
    fn keep_pairs(
        &mut self,
        place: &str,
        field: &str,
        pairs: Vec<(String, String)>,
        ty: ValueType,
        fits: impl Fn(i128) -> bool,
    ) -> Vec<(String, String)> {
        let mut kept = Vec::new();
        for (key, meaning) in pairs {
            if ty.is_integer() && crate::model::parse_key(&key).is_some_and(&fits) {
                kept.push((key, meaning));
                continue;
            }
            let why = if ty.is_integer() {
                format!(
                    "{key} is no raw {} value{}: the pair is left out",
                    ty.name(),
                    if field == "bits" { "'s bit" } else { "" }
                )
            } else {
                format!("a {} has no {field}: left out", ty.name())
            };
            self.unmapped(place, field, &format!("{key}={meaning}"), &why);
        }
        kept
    }

    /// Lists and clears what a coil or discrete input cannot have: a type, a scale, a unit, ...
    fn bits_only(&mut self, entry: &mut Entry) {
        let place = entry.place.clone();
        let why = "a coil or discrete input is one bit: it has no type, scale, unit or range";
        if entry.value_type != ValueType::Bit {
            self.unmapped(&place, "type", entry.value_type.name(), why);
            entry.value_type = ValueType::Bit;
        }
        for (field, value) in [("scale", entry.scale), ("offset", entry.offset), ("min", entry.min), ("max", entry.max)]
        {
            if let Some(value) = value {
                self.unmapped(&place, field, &value.to_string(), why);
            }
        }
        if let Some(unit) = entry.unit.take() {
            self.unmapped(&place, "unit", &unit, why);
        }
        if let Some(order) = entry.order.take() {
            self.unmapped(&place, "order", order.name(), why);
        }
        entry.scale = None;
        entry.offset = None;
        entry.min = None;
        entry.max = None;
        entry.length = None;
        if !entry.values.is_empty() || !entry.bits.is_empty() {
            self.unmapped(&place, "values", "", why);
            entry.values.clear();
            entry.bits.clear();
        }
    }

    /// Writes and checks the profile.
    fn finish(mut self) -> Result<Imported, ImportError> {
        for (index, more) in std::mem::take(&mut self.more) {
            if let Some(listed) = self.unmapped.get_mut(index) {
                listed.place = format!("{} (and {more} more)", listed.place);
            }
        }
        if self.entries.is_empty() {
            return Err(ImportError::Nothing {
                origin: self.origin,
                unmapped: self.unmapped.len(),
                list: self.unmapped,
            });
        }
        let name = self.options.name.clone().unwrap_or_else(|| default_name(&self.origin));
        // A device's name is a label: printable, and cut to its length.
        let name: String = spelled(&name, |_| false).chars().take(LABEL_MAX).collect();
        let profile = match write::profile(&name, &self.entries).build(&self.origin) {
            Ok(profile) => profile,
            Err(mistakes) => {
                let message = mistakes.first().map(ToString::to_string).unwrap_or_default();
                return Err(ImportError::Invalid { origin: self.origin, message });
            }
        };
        let toml = write::file(&profile, &self.origin, self.format, &self.notes);
        Ok(Imported { toml, profile, points: self.entries.len(), unmapped: self.unmapped, notes: self.notes })
    }
}

/// Whether `value` is exactly `default` (a scale of 1, an offset of 0): then it is left out.
#[allow(clippy::float_cmp)] // exactly the default, not near it: 1.0000001 is a scale to keep
pub(crate) fn is(value: f64, default: f64) -> bool {
    value == default
}

/// The profile's name from the source's: its file name without the extension.
fn default_name(origin: &str) -> String {
    let file = origin.rsplit(['/', '\\']).next().unwrap_or(origin);
    let stem = file.rsplit_once('.').map_or(file, |(stem, _)| stem);
    if stem.is_empty() { "imported map".to_string() } else { stem.to_string() }
}

/// The characters of a code an import writes: a profile's [`NAME_MAX`] less room for the
/// suffix ([`Draft::add`]'s `_2`, `_3`, ...) that a name taken already gets.
const CODE_MAX: usize = NAME_MAX - 16;

/// A point's code from a source's name (runs of blanks and control characters become `_`, cut
/// to [`CODE_MAX`] characters), and the name itself as its label when the two differ (control
/// characters but the tab spelled out, `\u{7}`).
pub(crate) fn code_and_label(name: &str) -> (String, Option<String>) {
    let name = name.trim();
    let mut code = String::with_capacity(name.len().min(CODE_MAX * 4));
    for c in name.chars().take(CODE_MAX) {
        if c.is_whitespace() || forbidden(c) {
            if !code.ends_with('_') {
                code.push('_');
            }
        } else {
            code.push(c);
        }
    }
    // A profile holds no control character but the tab: the label spells them out.
    let label = (code != name).then(|| spelled(name, |c| c == '\t'));
    (code, label)
}

/// `text` with the characters a profile may not hold spelled out (`\u{7}`), but those `kept`.
fn spelled(text: &str, kept: impl Fn(char) -> bool) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        if forbidden(c) && !kept(c) {
            out.extend(c.escape_unicode());
        } else {
            out.push(c);
        }
    }
    out
}

/// Whether `text` is one line of at most `max` printable characters (a tab allowed).
fn printable(text: &str, max: usize) -> bool {
    !text.chars().any(|c| c != '\t' && forbidden(c)) && text.chars().nth(max).is_none()
}

/// Why a `field` that is not [`printable`] is left out.
fn unprintable(field: &str, max: usize) -> String {
    format!("a {field} is one line of at most {max} printable characters: left out")
}

/// `text` bounded to 80 characters, control characters escaped: a value from a file is shown,
/// never obeyed.
pub(crate) fn shown(text: &str) -> String {
    bounded(text, 80)
}

/// `text` with control characters escaped, cut (then `…`) so that what is shown is at most
/// `limit` characters before the ellipsis.
fn bounded(text: &str, limit: usize) -> String {
    let mut out = String::new();
    let mut shown = 0;
    for c in text.chars() {
        let escaped: Vec<char> = if c.is_control() { c.escape_default().collect() } else { vec![c] };
        if shown + escaped.len() > limit {
            out.push('…');
            break;
        }
        shown += escaped.len();
        out.extend(escaped);
    }
    out
}

/// The word order a 32- or 64-bit value is in when its words are swapped (`swapped`) and its
/// bytes within each word (`bytes`).
pub(crate) fn order_of(swapped: bool, bytes: bool) -> Order {
    match (swapped, bytes) {
        (false, false) => Order::Abcd,
        (true, false) => Order::Cdab,
        (false, true) => Order::Badc,
        (true, true) => Order::Dcba,
    }
}

#[cfg(test)]
mod tests;
#[cfg(test)]
mod yaml_tests;
