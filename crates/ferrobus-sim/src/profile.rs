//! Profile files: one device model each, in TOML.
//!
//! A profile says which function codes the device answers, how many items it takes per
//! request, its register and coil map (names, units, scaling, ranges, access, 32-bit pairs and
//! their word order, the manual's numbering), its response wait, its broadcast rules, its
//! vendor exception codes, its identification, and the faults its units start with (a
//! `faults` string and `[[fault_rule]]` tables, see [`crate::rule`]). The built-in profiles
//! are in `profiles/` and compiled in; users write their own in the same format.
//!
//! A profile is refused when its entries of one kind overlap (two registers sharing an
//! address, a 32-bit pair covering the next register), and every error names the file, the
//! line, and the entry and field at fault.

use std::fmt;
use std::path::Path;

use serde::Deserialize;

/// A device model.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Profile {
    /// What the device is.
    pub device: DeviceSection,
    /// How the manual numbers addresses.
    #[serde(default)]
    pub addressing: Addressing,
    /// Function codes, timing, broadcast.
    #[serde(default)]
    pub comm: Comm,
    /// Items per request.
    #[serde(default)]
    pub limits: Limits,
    /// Vendor exception codes.
    #[serde(default)]
    pub exceptions: Exceptions,
    /// Plain read/write tables covering the address space from 0 (the generic device).
    #[serde(default)]
    pub tables: Tables,
    /// The physics model, if any.
    pub model: Option<ModelSection>,
    /// Coils (0x01, 0x05, 0x0F).
    #[serde(default)]
    pub coils: Vec<BitDef>,
    /// Discrete inputs (0x02).
    #[serde(default)]
    pub discrete_inputs: Vec<BitDef>,
    /// Holding registers (0x03, 0x06, 0x10, 0x16, 0x17).
    #[serde(default)]
    pub registers: Vec<RegisterDef>,
    /// Input registers (0x04).
    #[serde(default)]
    pub inputs: Vec<RegisterDef>,
    /// File records (0x14, 0x15).
    pub files: Option<Files>,
    /// The FIFO queue (0x18).
    pub fifo: Option<Fifo>,
    /// Faults every unit of this profile starts with, written as `--fault` takes them:
    /// `"drop=10%,delay=50ms"`. A `--fault` for a unit replaces them.
    pub faults: Option<String>,
    /// Fault rules aimed at requests, tried in order after those of `faults`: `[[fault_rule]]`
    /// tables with the keys of a `--fault` rule, e.g. `fc = 0x03`, `addr = "0x1000-0x100F"`,
    /// `share = "50%"`, and one action: `exception = 0x06`, `no-reply = true`,
    /// `delay = "200ms"`, `short = true` or `short = 3`, `malformed = true`, `unit = 7`,
    /// `tid = "+1"`, `trickle = "5ms"`.
    #[serde(default)]
    pub fault_rule: Vec<toml::Table>,
}

/// `[device]`
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeviceSection {
    /// A human name.
    pub name: String,
    /// Identification object 0x00 VendorName.
    pub vendor: String,
    /// Identification object 0x01 ProductCode.
    pub product_code: String,
    /// Identification object 0x02 MajorMinorRevision.
    pub revision: String,
    /// Object 0x03 VendorUrl.
    pub vendor_url: Option<String>,
    /// Object 0x04 ProductName.
    pub product_name: Option<String>,
    /// Object 0x05 ModelName.
    pub model_name: Option<String>,
    /// Object 0x06 UserApplicationName.
    pub user_application_name: Option<String>,
    /// Whether the device answers 0x2B/0x0E and 0x11 (else exception 01).
    #[serde(default = "yes")]
    pub identification: bool,
    /// The server id bytes of 0x11, before the run indicator (ASCII).
    pub server_id: Option<String>,
}

/// `[addressing]`
#[derive(Clone, Copy, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Addressing {
    /// The number of the first item in the manual: 1 when the frame carries number − 1.
    pub base: u16,
}

/// `[comm]`
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Comm {
    /// The function codes answered; the others get exception 01. Absent: all public codes.
    pub functions: Option<Vec<u8>>,
    /// The 0x08 sub-functions answered; absent: all.
    pub diagnostics: Option<Vec<u16>>,
    /// Wait before replying, on top of t3.5 (3G3RX C078).
    #[serde(default)]
    pub response_wait_ms: u32,
    /// Whether reads sent by broadcast are executed (they are never answered).
    #[serde(default)]
    pub broadcast_reads: bool,
    /// Whether 0x08 by broadcast is executed.
    #[serde(default)]
    pub broadcast_diagnostics: bool,
}

/// `[limits]`: the most items per request; absent: the spec's limits.
#[derive(Clone, Copy, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    /// 0x01 and 0x02 (spec: 2000).
    pub read_coils: Option<u16>,
    /// 0x0F (spec: 1968).
    pub write_coils: Option<u16>,
    /// 0x03, 0x04 and the read of 0x17 (spec: 125).
    pub read_registers: Option<u16>,
    /// 0x10 and the write of 0x17 (spec: 123 and 121).
    pub write_registers: Option<u16>,
}

/// `[exceptions]`: which code the device answers for each kind of refusal.
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Exceptions {
    /// A value outside a register's range (spec: 0x03; 3G3RX: 0x21).
    #[serde(default = "illegal_value")]
    pub out_of_range: u8,
    /// Not allowed in the device's state, e.g. while running (3G3RX: 0x22).
    #[serde(default = "device_failure")]
    pub not_allowed: u8,
    /// A write to a read-only item (spec: 0x02; 3G3RX: 0x22).
    #[serde(default = "illegal_address")]
    pub read_only: u8,
}

impl Default for Exceptions {
    fn default() -> Self {
        Exceptions { out_of_range: illegal_value(), not_allowed: device_failure(), read_only: illegal_address() }
    }
}

fn yes() -> bool {
    true
}
fn illegal_value() -> u8 {
    0x03
}
fn device_failure() -> u8 {
    0x04
}
fn illegal_address() -> u8 {
    0x02
}

/// `[tables]`: plain tables of this many items from address 0 (the generic device).
#[derive(Clone, Copy, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tables {
    /// Coils.
    pub coils: Option<u32>,
    /// Discrete inputs.
    pub discrete_inputs: Option<u32>,
    /// Holding registers.
    pub holding_registers: Option<u32>,
    /// Input registers.
    pub input_registers: Option<u32>,
}

/// `[model]`
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, tag = "kind", rename_all = "kebab-case")]
pub enum ModelSection {
    /// A frequency inverter.
    Inverter {
        /// Direction coil polarity.
        #[serde(default)]
        direction: Polarity,
        /// A004, 0.01 Hz.
        max_frequency: u32,
        /// 0.01 A.
        rated_current: u32,
        /// 0.1 V.
        rated_voltage: u32,
        /// 0.1 V.
        dc_bus_voltage: u32,
    },
    /// A servo drive.
    Servo {
        /// r/min.
        rated_speed: u32,
        /// Encoder pulses per revolution.
        pulses_per_revolution: u32,
    },
}

/// How a direction coil reads.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Polarity {
    /// 1 = reverse (Omron MX2/RX2 tables).
    #[default]
    OneIsReverse,
    /// 1 = forward (Hitachi SJ700-2 table).
    OneIsForward,
}

/// Read/write access.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Access {
    /// Read only.
    #[default]
    Ro,
    /// Read and write.
    Rw,
    /// Write only (reads as zero).
    Wo,
}

/// Word order of a 32-bit pair: the core's, named `high-first` or `low-first` in a profile.
pub use ferrobus_proto::words::WordOrder;

/// A `word_order` in a profile, by the core's names.
fn word_order<'de, D: serde::Deserializer<'de>>(deserializer: D) -> Result<WordOrder, D::Error> {
    let name = String::deserialize(deserializer)?;
    WordOrder::from_name(&name)
        .ok_or_else(|| serde::de::Error::invalid_value(serde::de::Unexpected::Str(&name), &"high-first or low-first"))
}

/// A coil or discrete input, or a run of them.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BitDef {
    /// The manual's number of the first.
    pub number: u32,
    /// How many (default 1).
    #[serde(default = "one")]
    pub count: u32,
    /// A short name.
    pub name: String,
    /// What it is.
    #[serde(default)]
    pub description: String,
    /// Access.
    #[serde(default)]
    pub access: Access,
    /// The value at start.
    #[serde(default)]
    pub default: bool,
}

/// A register or 32-bit pair, or a run of plain registers.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegisterDef {
    /// The manual's number of the first register.
    pub number: u32,
    /// How many items (default 1).
    #[serde(default = "one")]
    pub count: u32,
    /// 1 or 2 registers per item.
    #[serde(default = "one")]
    pub size: u32,
    /// Word order of a 2-register item.
    #[serde(default, deserialize_with = "word_order")]
    pub word_order: WordOrder,
    /// A short name (a parameter code such as `F001`).
    pub name: String,
    /// What it is.
    #[serde(default)]
    pub description: String,
    /// Engineering unit.
    pub unit: Option<String>,
    /// Engineering value = raw × scale.
    pub scale: Option<f64>,
    /// Lowest raw value accepted by a write.
    pub min: Option<i64>,
    /// Highest raw value accepted by a write.
    pub max: Option<i64>,
    /// Whether the raw value is signed.
    #[serde(default)]
    pub signed: bool,
    /// Access.
    #[serde(default)]
    pub access: Access,
    /// Whether it may be written while the drive runs (default yes).
    #[serde(default = "yes")]
    pub while_running: bool,
    /// The raw value at start.
    #[serde(default)]
    pub default: i64,
}

fn one() -> u32 {
    1
}

/// `[files]`
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Files {
    /// Files 1..=count.
    pub count: u16,
    /// Records per file.
    pub records: u16,
}

/// `[fifo]`
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fifo {
    /// The FIFO pointer address (a holding register holding the count).
    pub address: u16,
}

/// Why a profile could not be loaded.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ProfileError {
    /// No built-in profile by that name (and it does not look like a path).
    #[error("no profile named {name:?}: the built-in ones are {}, or give a path to a .toml file", BUILTIN.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", "))]
    Unknown {
        /// What was asked for.
        name: String,
    },
    /// A path that names no file.
    #[error("profile {path}: no such file")]
    NoSuchFile {
        /// The path.
        path: String,
    },
    /// The file could not be read.
    #[error("reading {path}: {source}")]
    Read {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// The TOML is malformed, has unknown fields, or a field of the wrong type.
    #[error("in {origin}{}: {message}", at_line(*line, text))]
    Parse {
        /// The profile.
        origin: String,
        /// The line where it is wrong (from 1), if known.
        line: Option<usize>,
        /// That line's text.
        text: String,
        /// What is wrong, from the TOML reader.
        message: String,
    },
    /// The TOML is well formed but does not describe a possible device.
    #[error("in {origin}{}: {problem}", at_line(*line, ""))]
    Invalid {
        /// The profile.
        origin: String,
        /// The line of the entry at fault (from 1), if known.
        line: Option<usize>,
        /// What is wrong, naming the entry and the field.
        problem: String,
    },
}

fn at_line(line: Option<usize>, text: &str) -> String {
    match (line, text.trim()) {
        (None, _) => String::new(),
        (Some(line), "") => format!(", line {line}"),
        (Some(line), text) => format!(", line {line} ({text})"),
    }
}

/// The line (from 1) of byte `offset` in `text`.
fn line_of(text: &str, offset: usize) -> usize {
    text.get(..offset).unwrap_or(text).matches('\n').count().saturating_add(1)
}

/// The line of `field` in the entry whose header is at `span` of `text` (up to the next
/// header), else the header's line.
fn field_line(text: &str, span: &std::ops::Range<usize>, field: &str) -> usize {
    let header = line_of(text, span.start);
    let body = text.get(span.end..).unwrap_or_default().lines().skip(1);
    for (n, line) in (header.saturating_add(1)..).zip(body) {
        let line = line.trim_start();
        if line.starts_with('[') {
            break;
        }
        if line.strip_prefix(field).is_some_and(|rest| rest.trim_start().starts_with('=')) {
            return n;
        }
    }
    header
}

/// Where each entry of a profile starts, read by a second pass over the same text.
#[derive(Default, Deserialize)]
struct Spans {
    #[serde(default)]
    coils: Vec<toml::Spanned<toml::Table>>,
    #[serde(default)]
    discrete_inputs: Vec<toml::Spanned<toml::Table>>,
    #[serde(default)]
    registers: Vec<toml::Spanned<toml::Table>>,
    #[serde(default)]
    inputs: Vec<toml::Spanned<toml::Table>>,
    #[serde(default)]
    fault_rule: Vec<toml::Spanned<toml::Table>>,
    faults: Option<toml::Spanned<String>>,
}

/// A problem with the entry at a line.
type Problem = (Option<usize>, String);

/// The profiles compiled into the binary.
pub const BUILTIN: &[(&str, &str)] = &[
    ("omron-3g3rx", include_str!("../../ferrobus-profile/profiles/omron-3g3rx.toml")),
    ("sdp-servo", include_str!("../../ferrobus-profile/profiles/sdp-servo.toml")),
    ("generic", include_str!("../../ferrobus-profile/profiles/generic.toml")),
];

impl Profile {
    /// A built-in profile by name, or a profile file by path.
    pub fn load(name_or_path: &str) -> Result<Profile, ProfileError> {
        if let Some((name, text)) = BUILTIN.iter().find(|(n, _)| *n == name_or_path) {
            return Profile::parse(text, name);
        }
        let path = Path::new(name_or_path);
        if !path.exists() {
            let looks_like_a_path = name_or_path.contains(['/', '\\'])
                || name_or_path.starts_with('.')
                || path.extension().is_some_and(|e| e.eq_ignore_ascii_case("toml"));
            return Err(if looks_like_a_path {
                ProfileError::NoSuchFile { path: name_or_path.to_string() }
            } else {
                ProfileError::Unknown { name: name_or_path.to_string() }
            });
        }
        let text = std::fs::read_to_string(path)
            .map_err(|source| ProfileError::Read { path: path.display().to_string(), source })?;
        Profile::parse(&text, &path.display().to_string())
    }

    /// Parses and checks a profile; `origin` names it in errors, with the line at fault.
    pub fn parse(text: &str, origin: &str) -> Result<Profile, ProfileError> {
        let profile: Profile = toml::from_str(text).map_err(|e| {
            let line = e.span().map(|span| line_of(text, span.start));
            let source_line = line.and_then(|l| text.lines().nth(l.saturating_sub(1))).unwrap_or_default();
            ProfileError::Parse {
                origin: origin.to_string(),
                line,
                text: source_line.to_string(),
                message: e.message().trim().to_string(),
            }
        })?;
        // The same text has parsed once; a second reader that fails only loses the lines.
        let spans: Spans = toml::from_str(text).unwrap_or_default();
        profile.validate(text, &spans).map_err(|(line, problem)| ProfileError::Invalid {
            origin: origin.to_string(),
            line,
            problem,
        })?;
        Ok(profile)
    }

    /// The faults the profile asks for: its `faults` string, then its `[[fault_rule]]`s.
    pub fn faults(&self) -> Result<crate::Faults, String> {
        self.faults_at(None, &[]).map_err(|(_, problem)| problem)
    }

    fn faults_at(&self, faults_line: Option<usize>, rule_lines: &[Option<usize>]) -> Result<crate::Faults, Problem> {
        let mut faults: crate::Faults = match self.faults.as_deref() {
            Some(spec) => spec.parse().map_err(|e| (faults_line, format!("faults: {e}")))?,
            None => crate::Faults::default(),
        };
        for (i, table) in self.fault_rule.iter().enumerate() {
            let line = rule_lines.get(i).copied().flatten();
            let spec = rule_spec(table).map_err(|problem| (line, format!("[[fault_rule]]: {problem}")))?;
            let rule = spec.parse::<crate::Rule>().map_err(|problem| (line, format!("[[fault_rule]]: {problem}")))?;
            faults.rules.push(rule);
        }
        Ok(faults)
    }

    fn validate(&self, text: &str, spans: &Spans) -> Result<(), Problem> {
        let lines = |entries: &[toml::Spanned<toml::Table>]| -> Vec<Option<usize>> {
            entries.iter().map(|e| Some(line_of(text, e.span().start))).collect()
        };
        let faults_line = spans.faults.as_ref().map(|f| line_of(text, f.span().start));
        self.faults_at(faults_line, &lines(&spans.fault_rule))?;
        if self.comm.response_wait_ms > 60_000 {
            return Err((None, format!("response_wait_ms = {} is more than a minute", self.comm.response_wait_ms)));
        }
        let base = u64::from(self.addressing.base);
        for (kind, entries, spans) in
            [("registers", &self.registers, &spans.registers), ("inputs", &self.inputs, &spans.inputs)]
        {
            let lines = lines(spans);
            let at = |i: usize, field: &str| spans.get(i).map(|e| field_line(text, &e.span(), field));
            for (i, r) in entries.iter().enumerate() {
                let entry = format!("[[{kind}]] {} ({})", r.number, r.name);
                if !(1..=2).contains(&r.size) {
                    return Err((at(i, "size"), format!("{entry}: size = {} must be 1 or 2", r.size)));
                }
                if u64::from(r.number) < base {
                    return Err((at(i, "number"), format!("{entry}: number is below the base {base}")));
                }
                if u64::from(r.number) + u64::from(r.count) * u64::from(r.size) > 0x1_0000 + base {
                    return Err((at(i, "count"), format!("{entry}: count = {} runs past the address space", r.count)));
                }
                if let (Some(min), Some(max)) = (r.min, r.max) {
                    if min > max {
                        return Err((at(i, "max"), format!("{entry}: min = {min} is above max = {max}")));
                    }
                }
            }
            let extents = entries.iter().map(|r| (r.number, u64::from(r.count) * u64::from(r.size), r.name.as_str()));
            no_overlaps(kind, extents, &lines)?;
        }
        for (kind, entries, spans) in
            [("coils", &self.coils, &spans.coils), ("discrete_inputs", &self.discrete_inputs, &spans.discrete_inputs)]
        {
            let lines = lines(spans);
            for (i, b) in entries.iter().enumerate() {
                if u64::from(b.number) < base || u64::from(b.number) + u64::from(b.count) > 0x1_0000 + base {
                    let at = lines.get(i).copied().flatten();
                    return Err((
                        at,
                        format!("[[{kind}]] {} ({}): number and count run outside the address space", b.number, b.name),
                    ));
                }
            }
            no_overlaps(kind, entries.iter().map(|b| (b.number, u64::from(b.count), b.name.as_str())), &lines)?;
        }
        for t in
            [self.tables.coils, self.tables.discrete_inputs, self.tables.holding_registers, self.tables.input_registers]
                .into_iter()
                .flatten()
        {
            if t > 0x1_0000 {
                return Err((None, format!("[tables]: a table of {t} items is larger than the address space")));
            }
        }
        Ok(())
    }
}

/// Checks that no two entries of `kind` — `(number, items, name)`, at `lines` — share an
/// address; names the later one and the line of the earlier one.
fn no_overlaps<'a>(
    kind: &str,
    entries: impl Iterator<Item = (u32, u64, &'a str)>,
    lines: &[Option<usize>],
) -> Result<(), Problem> {
    let mut sorted: Vec<(u64, u64, &str, usize)> =
        entries.enumerate().map(|(i, (n, items, name))| (u64::from(n), items, name, i)).collect();
    sorted.sort_by_key(|&(start, _, _, i)| (start, i));
    // The entry reaching furthest so far: where it ends, and which it is.
    let mut reach: Option<(u64, usize)> = None;
    for (k, &(start, items, _, _)) in sorted.iter().enumerate() {
        if items == 0 {
            continue;
        }
        if let Some((_, owner)) = reach.filter(|&(end, _)| start < end) {
            let (Some(a), Some(b)) = (sorted.get(owner), sorted.get(k)) else { break };
            // Name the entry written later, and the line of the one written first.
            let (first, later) = if a.3 < b.3 { (a, b) } else { (b, a) };
            let what = if a.0 == b.0 { "is at the same number as" } else { "overlaps" };
            let line = |i: usize| lines.get(i).copied().flatten();
            let earlier = line(first.3).map_or(String::new(), |l| format!(" on line {l}"));
            return Err((
                line(later.3),
                format!("[[{kind}]] {} ({}) {what} {} ({}){earlier}", later.0, later.2, first.0, first.2),
            ));
        }
        let end = start.saturating_add(items);
        if reach.is_none_or(|(furthest, _)| end > furthest) {
            reach = Some((end, k));
        }
    }
    Ok(())
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

impl fmt::Display for Profile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} ({} {})", self.device.name, self.device.vendor, self.device.product_code)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_builtin_profile_loads() {
        for (name, _) in BUILTIN {
            let p = Profile::load(name).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert!(!p.device.name.is_empty());
        }
        let rx = Profile::load("omron-3g3rx").unwrap();
        assert_eq!(rx.limits.read_registers, Some(4));
        assert_eq!(rx.exceptions.out_of_range, 0x21);
        assert_eq!(rx.addressing.base, 1);
    }

    #[test]
    fn an_unknown_name_lists_the_builtins() {
        let e = Profile::load("omron-3g3xx").unwrap_err();
        assert_eq!(
            e.to_string(),
            "no profile named \"omron-3g3xx\": the built-in ones are omron-3g3rx, sdp-servo, generic, or give a path to a .toml file"
        );
    }

    #[test]
    fn a_profile_can_ask_for_faults() {
        let text = "faults = 'drop=10%,silent'\n[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\n";
        let faults = Profile::parse(text, "mine.toml").unwrap().faults().unwrap();
        assert!(faults.silent && (faults.drop - 0.1).abs() < 1e-12);
        let bad = "faults = 'drop=2'\n[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\n";
        assert!(Profile::parse(bad, "mine.toml").unwrap_err().to_string().contains("drop: '2' is not between 0 and 1"));
    }

    const DEVICE: &str = "[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\n";

    fn error(text: &str) -> String {
        Profile::parse(text, "mine.toml").unwrap_err().to_string()
    }

    #[test]
    fn mistakes_in_a_profile_are_reported_with_the_file_the_line_and_the_field() {
        assert_eq!(
            error(&format!("{DEVICE}colour = 'red'\n")),
            "in mine.toml, line 6 (colour = 'red'): unknown field `colour`, expected one of `name`, `vendor`, \
             `product_code`, `revision`, `vendor_url`, `product_name`, `model_name`, `user_application_name`, \
             `identification`, `server_id`"
        );
        let wrong_type = error(&format!("{DEVICE}[[registers]]\nnumber = 'one'\nname = 'r'\n"));
        assert!(wrong_type.starts_with("in mine.toml, line 7 (number = 'one'): invalid type: string"), "{wrong_type}");
        assert_eq!(
            error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\nsize=3\n")),
            "in mine.toml, line 9: [[registers]] 1 (r): size = 3 must be 1 or 2"
        );
        assert_eq!(
            error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\nmin=5\nmax=4\n")),
            "in mine.toml, line 10: [[registers]] 1 (r): min = 5 is above max = 4"
        );
    }

    #[test]
    fn a_word_order_is_read_by_the_cores_names_and_a_wrong_one_is_refused_naming_them() {
        let pair = |order: &str| format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\nsize=2\nword_order='{order}'\n");
        let low = Profile::parse(&pair("low-first"), "mine.toml").unwrap();
        assert_eq!(low.registers[0].word_order, WordOrder::LowFirst);
        let wrong = error(&pair("cdab"));
        assert!(
            wrong.starts_with("in mine.toml, line 10 (word_order='cdab'): invalid value: string \"cdab\", expected high-first or low-first"),
            "{wrong}"
        );
    }

    #[test]
    fn overlapping_registers_are_refused_naming_both_and_their_lines() {
        let text = format!(
            "{DEVICE}[[registers]]\nnumber=10\nname='a'\ncount=4\n\n[[registers]]\nnumber=20\nname='b'\n\n\
             [[registers]]\nnumber=12\nname='c'\nsize=2\n"
        );
        assert_eq!(error(&text), "in mine.toml, line 15: [[registers]] 12 (c) overlaps 10 (a) on line 6");
        let duplicate = format!("{DEVICE}[[coils]]\nnumber=3\nname='a'\n[[coils]]\nnumber=3\nname='b'\n");
        assert_eq!(error(&duplicate), "in mine.toml, line 9: [[coils]] 3 (b) is at the same number as 3 (a) on line 6");
        // A 32-bit pair takes two numbers; the next one may follow it.
        let pairs = format!("{DEVICE}[[inputs]]\nnumber=1\nname='a'\nsize=2\n[[inputs]]\nnumber=3\nname='b'\n");
        assert!(Profile::parse(&pairs, "mine.toml").is_ok());
        let clash = format!("{DEVICE}[[inputs]]\nnumber=1\nname='a'\nsize=2\n[[inputs]]\nnumber=2\nname='b'\n");
        assert_eq!(error(&clash), "in mine.toml, line 10: [[inputs]] 2 (b) overlaps 1 (a) on line 6");
        // The same number in two tables is no overlap: coils and registers are apart.
        let apart = format!("{DEVICE}[[coils]]\nnumber=1\nname='a'\n[[registers]]\nnumber=1\nname='b'\n");
        assert!(Profile::parse(&apart, "mine.toml").is_ok());
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
        assert_eq!(error(&bad), "in mine.toml, line 7: [[fault_rule]]: short: '0' is not a number of bytes from 1");
        let bad_faults = format!("\nfaults = 'drop=2'\n{DEVICE}");
        assert!(
            error(&bad_faults).starts_with("in mine.toml, line 2: faults: fault \"drop=2\": drop:"),
            "{}",
            error(&bad_faults)
        );
    }

    #[test]
    fn a_missing_file_says_so_and_a_bare_unknown_name_lists_the_builtins() {
        assert_eq!(Profile::load("./nope.toml").unwrap_err().to_string(), "profile ./nope.toml: no such file");
        assert_eq!(Profile::load("drives/nope").unwrap_err().to_string(), "profile drives/nope: no such file");
        assert_eq!(Profile::load("nope.toml").unwrap_err().to_string(), "profile nope.toml: no such file");
        assert!(
            Profile::load("nope")
                .unwrap_err()
                .to_string()
                .starts_with("no profile named \"nope\": the built-in ones are")
        );
    }
}
