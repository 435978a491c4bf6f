//! The profile file: its sections and entries as written, parsed and checked.
//!
//! A profile says which function codes the device answers, how many items it takes per
//! request, its register and coil map (codes, labels, types, word orders, units, scaling,
//! ranges, access, enumerations, bit fields, groups, dependencies, the manual's numbering),
//! the address spans in which it answers reads of unmapped addresses, how to tell that it
//! runs, its exception codes and their meaning, its response wait, its broadcast rules, its
//! identification, and the faults a simulated unit starts with. The built-in profiles are in
//! `profiles/` and compiled in; users write their own in the same format.
//!
//! A profile is refused when its entries of one kind overlap (two registers sharing an
//! address, a 32-bit value covering the next register), and every error names the file, the
//! line, and the entry and field at fault.

use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;

use serde::Deserialize;

use crate::point::{self, Point};

/// A device model.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Profile {
    /// What the device is.
    pub device: DeviceSection,
    /// How the manual numbers addresses, and the default word order.
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
    /// Ranges in which the device answers reads of every address, mapped or not.
    #[serde(default)]
    pub span: Vec<SpanDef>,
    /// How a client tells the device's state (whether it runs).
    #[serde(default)]
    pub state: State,
    /// The device's own words for its exception codes.
    #[serde(default)]
    pub exception_meaning: Vec<ExceptionMeaning>,
    /// File records (0x14, 0x15).
    pub files: Option<Files>,
    /// The FIFO queue (0x18).
    pub fifo: Option<Fifo>,
    /// Faults every simulated unit of this profile starts with, written as `ferrobus sim
    /// --fault` takes them: `"drop=10%,delay=50ms"` (the simulator reads them).
    pub faults: Option<String>,
    /// Fault rules aimed at requests, tried in order after those of `faults`: `[[fault_rule]]`
    /// tables with the keys of a `--fault` rule, e.g. `fc = 0x03`, `addr = "0x1000-0x100F"`,
    /// `share = "50%"`, and one action: `exception = 0x06`, `no-reply = true`,
    /// `delay = "200ms"`, `short = true` or `short = 3`, `malformed = true`, `unit = 7`,
    /// `tid = "+1"`, `trickle = "5ms"` (the simulator reads them).
    #[serde(default)]
    pub fault_rule: Vec<toml::Table>,
    /// Where the profile came from (a built-in name or a path), for messages.
    #[serde(skip)]
    pub origin: String,
    /// The line of `faults`, if any (from 1).
    #[serde(skip)]
    pub faults_line: Option<usize>,
    /// The line of each `[[fault_rule]]` (from 1).
    #[serde(skip)]
    pub fault_rule_lines: Vec<Option<usize>>,
    /// Every coil, discrete input and register entry resolved to points, in profile order.
    #[serde(skip)]
    points: Vec<Point>,
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
    #[serde(default)]
    pub base: u16,
    /// The order of multi-register values whose entry names none (default ABCD).
    #[serde(default)]
    pub order: Order,
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

impl Access {
    /// The name in a profile: `ro`, `rw`, `wo`.
    pub const fn name(self) -> &'static str {
        match self {
            Access::Ro => "ro",
            Access::Rw => "rw",
            Access::Wo => "wo",
        }
    }
}

/// The type of a register entry's value.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ValueType {
    /// One register, unsigned.
    #[default]
    U16,
    /// One register, two's complement.
    I16,
    /// Two registers, unsigned.
    U32,
    /// Two registers, two's complement.
    I32,
    /// Four registers, unsigned.
    U64,
    /// Four registers, two's complement.
    I64,
    /// Two registers, IEEE 754 single precision.
    F32,
    /// Four registers, IEEE 754 double precision.
    F64,
    /// `length` registers of text, two characters per register, high byte first, NUL padded.
    String,
    /// A coil or discrete input (not written in a profile: the table says it).
    #[serde(skip_deserializing)]
    Bit,
}

impl ValueType {
    /// The name in a profile.
    pub const fn name(self) -> &'static str {
        match self {
            ValueType::U16 => "u16",
            ValueType::I16 => "i16",
            ValueType::U32 => "u32",
            ValueType::I32 => "i32",
            ValueType::U64 => "u64",
            ValueType::I64 => "i64",
            ValueType::F32 => "f32",
            ValueType::F64 => "f64",
            ValueType::String => "string",
            ValueType::Bit => "bit",
        }
    }

    /// Registers of one value (bits: 1 bit); a string's come from its `length`.
    pub const fn registers(self) -> u16 {
        match self {
            ValueType::U16 | ValueType::I16 | ValueType::Bit | ValueType::String => 1,
            ValueType::U32 | ValueType::I32 | ValueType::F32 => 2,
            ValueType::U64 | ValueType::I64 | ValueType::F64 => 4,
        }
    }

    /// Whether the type is an integer.
    pub const fn is_integer(self) -> bool {
        matches!(
            self,
            ValueType::U16 | ValueType::I16 | ValueType::U32 | ValueType::I32 | ValueType::U64 | ValueType::I64
        )
    }

    /// Whether the type is a float.
    pub const fn is_float(self) -> bool {
        matches!(self, ValueType::F32 | ValueType::F64)
    }

    /// The smallest and largest raw value of an integer type.
    pub const fn integer_range(self) -> (i128, i128) {
        match self {
            ValueType::U16 => (0, u16::MAX as i128),
            ValueType::I16 => (i16::MIN as i128, i16::MAX as i128),
            ValueType::U32 => (0, u32::MAX as i128),
            ValueType::I32 => (i32::MIN as i128, i32::MAX as i128),
            ValueType::U64 => (0, u64::MAX as i128),
            ValueType::I64 => (i64::MIN as i128, i64::MAX as i128),
            ValueType::Bit => (0, 1),
            ValueType::F32 | ValueType::F64 | ValueType::String => (0, 0),
        }
    }
}

/// The order of a multi-register value's bytes over its registers, by the names integrators
/// use. For 64-bit values the same four generalise: ABCD is big-endian, words high first;
/// CDAB words low first (bytes big-endian in each); BADC bytes swapped in each word, words
/// high first; DCBA fully little-endian.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug, Default, Deserialize)]
pub enum Order {
    /// Big-endian: high word first, high byte first.
    #[default]
    #[serde(rename = "ABCD")]
    Abcd,
    /// Low word first, high byte first in each word.
    #[serde(rename = "CDAB")]
    Cdab,
    /// High word first, low byte first in each word.
    #[serde(rename = "BADC")]
    Badc,
    /// Little-endian: low word first, low byte first.
    #[serde(rename = "DCBA")]
    Dcba,
}

impl Order {
    /// All four, the default first.
    pub const ALL: [Order; 4] = [Order::Abcd, Order::Cdab, Order::Badc, Order::Dcba];

    /// The name in a profile.
    pub const fn name(self) -> &'static str {
        match self {
            Order::Abcd => "ABCD",
            Order::Cdab => "CDAB",
            Order::Badc => "BADC",
            Order::Dcba => "DCBA",
        }
    }

    /// The order named `name` (case-insensitive; `high-first` is ABCD, `low-first` CDAB).
    pub fn from_name(name: &str) -> Option<Order> {
        match name.to_ascii_lowercase().as_str() {
            "high-first" => Some(Order::Abcd),
            "low-first" => Some(Order::Cdab),
            lower => Order::ALL.into_iter().find(|o| o.name().eq_ignore_ascii_case(lower)),
        }
    }

    /// Whether the words run low first.
    pub const fn words_low_first(self) -> bool {
        matches!(self, Order::Cdab | Order::Dcba)
    }

    /// Whether the bytes in each word are swapped.
    pub const fn bytes_swapped(self) -> bool {
        matches!(self, Order::Badc | Order::Dcba)
    }
}

/// A coil or discrete input, or a run of them.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BitDef {
    /// The manual's number of the first.
    pub number: u32,
    /// How many (default 1); the items of a run are named NAME1, NAME2, ...
    #[serde(default = "one")]
    pub count: u32,
    /// A short name (the code).
    pub name: String,
    /// A short descriptive name shown beside the code.
    pub label: Option<String>,
    /// What it is.
    #[serde(default)]
    pub description: String,
    /// Access.
    #[serde(default)]
    pub access: Access,
    /// The value at start (the simulator's).
    #[serde(default)]
    pub default: bool,
    /// A group name for `--group`.
    pub group: Option<String>,
    /// Whether a backup saves it (default: when read/write).
    pub backup: Option<bool>,
    /// The manual section it comes from.
    pub source: Option<String>,
    /// False when the fact could not be confirmed.
    #[serde(default = "yes")]
    pub confirmed: bool,
}

/// A register or multi-register value, or a run of them.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegisterDef {
    /// The manual's number of the first register.
    pub number: u32,
    /// How many items (default 1); the items of a run are named NAME1, NAME2, ...
    #[serde(default = "one")]
    pub count: u32,
    /// The value's type (default u16).
    #[serde(default, rename = "type")]
    pub value_type: ValueType,
    /// The order of a multi-register value (default: `[addressing] order`).
    pub order: Option<Order>,
    /// Registers of a string.
    pub length: Option<u16>,
    /// A short name (a parameter code such as `F001`).
    pub name: String,
    /// A short descriptive name shown beside the code.
    pub label: Option<String>,
    /// What it is.
    #[serde(default)]
    pub description: String,
    /// Engineering unit.
    pub unit: Option<String>,
    /// Engineering value = raw × scale + offset (default 1).
    pub scale: Option<f64>,
    /// Engineering value = raw × scale + offset (default 0).
    pub offset: Option<f64>,
    /// Lowest raw value accepted by a write.
    pub min: Option<f64>,
    /// Highest raw value accepted by a write.
    pub max: Option<f64>,
    /// Access.
    #[serde(default)]
    pub access: Access,
    /// Whether it may be written while the drive runs (default yes).
    #[serde(default = "yes")]
    pub while_running: bool,
    /// A group name for `--group`.
    pub group: Option<String>,
    /// An enumeration: raw value (as a string key) → meaning.
    #[serde(default)]
    pub values: BTreeMap<String, String>,
    /// A bit field: bit index (as a string key) → meaning.
    #[serde(default)]
    pub bits: BTreeMap<String, String>,
    /// Codes a restore writes before this one.
    #[serde(default)]
    pub depends_on: Vec<String>,
    /// Whether a backup saves it (default: when read/write).
    pub backup: Option<bool>,
    /// The manual section it comes from.
    pub source: Option<String>,
    /// False when the fact could not be confirmed.
    #[serde(default = "yes")]
    pub confirmed: bool,
    /// The raw value at start (the simulator's): an integer, a float for f32/f64, text for a
    /// string.
    pub default: Option<toml::Value>,
}

fn one() -> u32 {
    1
}

/// The four tables of the data model.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug, PartialOrd, Ord, Deserialize)]
pub enum Table {
    /// Coils (read/write bits).
    #[serde(rename = "coils")]
    Coils,
    /// Discrete inputs (read-only bits).
    #[serde(rename = "discrete")]
    DiscreteInputs,
    /// Holding registers (read/write words).
    #[serde(rename = "holding")]
    Holding,
    /// Input registers (read-only words).
    #[serde(rename = "input")]
    Input,
}

impl Table {
    /// All four.
    pub const ALL: [Table; 4] = [Table::Coils, Table::DiscreteInputs, Table::Holding, Table::Input];

    /// Whether the table holds bits.
    pub const fn is_bits(self) -> bool {
        matches!(self, Table::Coils | Table::DiscreteInputs)
    }

    /// The name in a profile's `[[span]]`.
    pub const fn name(self) -> &'static str {
        match self {
            Table::Coils => "coils",
            Table::DiscreteInputs => "discrete",
            Table::Holding => "holding",
            Table::Input => "input",
        }
    }
}

/// `[[span]]`: a range (manual numbering) in which the device answers reads of every address.
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpanDef {
    /// The table.
    pub table: Table,
    /// The first number.
    pub first: u32,
    /// The last number.
    pub last: u32,
}

/// `[state]`
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct State {
    /// How to tell that the drive runs.
    pub running: Option<RunningRule>,
}

/// `[state] running = { point = "running", values = [1] }`
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunningRule {
    /// A coil, discrete input or register code.
    pub point: String,
    /// The raw values that mean running.
    pub values: Vec<i64>,
}

/// `[[exception_meaning]]`
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExceptionMeaning {
    /// The exception code.
    pub code: u8,
    /// What the device means by it.
    pub meaning: String,
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
    span: Vec<toml::Spanned<toml::Table>>,
    #[serde(default)]
    fault_rule: Vec<toml::Spanned<toml::Table>>,
    faults: Option<toml::Spanned<String>>,
    state: Option<toml::Spanned<toml::Table>>,
}

/// A problem with the entry at a line.
type Problem = (Option<usize>, String);

/// The profiles compiled into the binary.
pub const BUILTIN: &[(&str, &str)] = &[
    ("omron-3g3rx", include_str!("../profiles/omron-3g3rx.toml")),
    ("sdp-servo", include_str!("../profiles/sdp-servo.toml")),
    ("generic", include_str!("../profiles/generic.toml")),
];

impl Profile {
    /// A built-in profile by name.
    pub fn builtin(name: &str) -> Result<Profile, ProfileError> {
        match BUILTIN.iter().find(|(n, _)| *n == name) {
            Some((name, text)) => Profile::parse(text, name),
            None => Err(ProfileError::Unknown { name: name.to_string() }),
        }
    }

    /// A built-in profile by name, or a profile file by path.
    pub fn load(name_or_path: &str) -> Result<Profile, ProfileError> {
        if BUILTIN.iter().any(|(n, _)| *n == name_or_path) {
            return Profile::builtin(name_or_path);
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
        let mut profile: Profile = toml::from_str(text).map_err(|e| {
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
        profile.origin = origin.to_string();
        profile.faults_line = spans.faults.as_ref().map(|f| line_of(text, f.span().start));
        profile.fault_rule_lines = spans.fault_rule.iter().map(|e| Some(line_of(text, e.span().start))).collect();
        profile.validate(text, &spans).map_err(|(line, problem)| ProfileError::Invalid {
            origin: origin.to_string(),
            line,
            problem,
        })?;
        profile.points = point::resolve(&profile);
        Ok(profile)
    }

    /// Every coil, discrete input and register entry as points, in profile order (coils,
    /// discrete inputs, holding registers, input registers); a run of `count` items gives
    /// `count` points.
    pub fn points(&self) -> &[Point] {
        &self.points
    }

    /// The error for a problem found after parsing (e.g. by the simulator in `faults`).
    pub fn problem(&self, line: Option<usize>, problem: String) -> ProfileError {
        ProfileError::Invalid { origin: self.origin.clone(), line, problem }
    }

    #[allow(clippy::too_many_lines)]
    fn validate(&self, text: &str, spans: &Spans) -> Result<(), Problem> {
        let lines = |entries: &[toml::Spanned<toml::Table>]| -> Vec<Option<usize>> {
            entries.iter().map(|e| Some(line_of(text, e.span().start))).collect()
        };
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
                check_register(r, &entry, base, &|field| at(i, field))?;
            }
            let extents =
                entries.iter().map(|r| (r.number, u64::from(r.count) * u64::from(r.width()), r.name.as_str()));
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
        let span_lines = lines(&spans.span);
        for (i, s) in self.span.iter().enumerate() {
            let at = span_lines.get(i).copied().flatten();
            if s.first > s.last {
                return Err((
                    at,
                    format!("[[span]] {}: first = {} is above last = {}", s.table.name(), s.first, s.last),
                ));
            }
            if u64::from(s.first) < base || u64::from(s.last) >= 0x1_0000 + base {
                return Err((
                    at,
                    format!("[[span]] {} {}-{}: outside the address space", s.table.name(), s.first, s.last),
                ));
            }
        }
        self.check_references(text, spans)
    }

    /// `depends_on` and `[state] running` name points that exist.
    fn check_references(&self, text: &str, spans: &Spans) -> Result<(), Problem> {
        let names: Vec<&str> = self
            .coils
            .iter()
            .chain(&self.discrete_inputs)
            .map(|b| b.name.as_str())
            .chain(self.registers.iter().chain(&self.inputs).map(|r| r.name.as_str()))
            .collect();
        for (kind, entries, spans) in
            [("registers", &self.registers, &spans.registers), ("inputs", &self.inputs, &spans.inputs)]
        {
            for (i, r) in entries.iter().enumerate() {
                if let Some(missing) = r.depends_on.iter().find(|d| !names.contains(&d.as_str())) {
                    let line = spans.get(i).map(|e| field_line(text, &e.span(), "depends_on"));
                    return Err((
                        line,
                        format!(
                            "[[{kind}]] {} ({}): depends_on names {missing:?}, which the profile does not have",
                            r.number, r.name
                        ),
                    ));
                }
            }
        }
        if let Some(running) = &self.state.running {
            if !names.contains(&running.point.as_str()) {
                let line = spans.state.as_ref().map(|s| field_line(text, &s.span(), "running"));
                return Err((line, format!("[state] running: point {:?} is not in the profile", running.point)));
            }
        }
        Ok(())
    }
}

impl RegisterDef {
    /// Registers of one item: by its type, or its `length` for a string.
    pub fn width(&self) -> u16 {
        match self.value_type {
            ValueType::String => self.length.unwrap_or(1),
            other => other.registers(),
        }
    }
}

/// A raw integer written in a profile key: decimal, `0x` hex or `0b` binary, maybe negative.
pub(crate) fn parse_key(key: &str) -> Option<i128> {
    let key = key.trim();
    let (negative, digits) = key.strip_prefix('-').map_or((false, key), |rest| (true, rest));
    let value = if let Some(hex) = digits.strip_prefix("0x").or_else(|| digits.strip_prefix("0X")) {
        i128::from_str_radix(hex, 16).ok()?
    } else if let Some(bin) = digits.strip_prefix("0b").or_else(|| digits.strip_prefix("0B")) {
        i128::from_str_radix(bin, 2).ok()?
    } else {
        digits.parse::<i128>().ok()?
    };
    Some(if negative { -value } else { value })
}

#[allow(clippy::too_many_lines)]
fn check_register(r: &RegisterDef, entry: &str, base: u64, at: &dyn Fn(&str) -> Option<usize>) -> Result<(), Problem> {
    let ty = r.value_type;
    match (ty, r.length) {
        (ValueType::String, None | Some(0)) => {
            return Err((at("length"), format!("{entry}: a string needs length = its registers (1 or more)")));
        }
        (ValueType::String, Some(_)) | (_, None) => {}
        (_, Some(_)) => return Err((at("length"), format!("{entry}: length is for type = \"string\" only"))),
    }
    if r.order.is_some() && ty.registers() == 1 && ty != ValueType::String {
        return Err((
            at("order"),
            format!("{entry}: order is for values of more than one register, not {}", ty.name()),
        ));
    }
    if r.count == 0 {
        return Err((at("count"), format!("{entry}: count = 0 describes nothing")));
    }
    if u64::from(r.number) < base {
        return Err((at("number"), format!("{entry}: number is below the base {base}")));
    }
    if u64::from(r.number) + u64::from(r.count) * u64::from(r.width()) > 0x1_0000 + base {
        return Err((at("count"), format!("{entry}: count = {} runs past the address space", r.count)));
    }
    for (field, value) in [("scale", r.scale), ("offset", r.offset), ("min", r.min), ("max", r.max)] {
        if value.is_some_and(|v| !v.is_finite()) {
            return Err((at(field), format!("{entry}: {field} must be a finite number")));
        }
    }
    if r.scale == Some(0.0) {
        return Err((at("scale"), format!("{entry}: scale = 0 would make every value the same")));
    }
    if let (Some(min), Some(max)) = (r.min, r.max) {
        if min > max {
            return Err((at("max"), format!("{entry}: min = {min} is above max = {max}")));
        }
    }
    if ty == ValueType::String && (r.min.is_some() || r.max.is_some() || r.scale.is_some() || r.offset.is_some()) {
        return Err((at("type"), format!("{entry}: a string has no min, max, scale or offset")));
    }
    if ty.is_integer() {
        let (lo, hi) = ty.integer_range();
        #[allow(clippy::cast_precision_loss)]
        let (lo, hi) = (lo as f64, hi as f64);
        for (field, value) in [("min", r.min), ("max", r.max)] {
            if let Some(v) = value.filter(|v| *v < lo || *v > hi || v.fract() != 0.0) {
                return Err((at(field), format!("{entry}: {field} = {v} is not a raw {} value", ty.name())));
            }
        }
    }
    if !r.values.is_empty() && !ty.is_integer() {
        return Err((
            at("values"),
            format!("{entry}: values (an enumeration) needs an integer type, not {}", ty.name()),
        ));
    }
    for key in r.values.keys() {
        let (lo, hi) = ty.integer_range();
        if parse_key(key).is_none_or(|k| k < lo || k > hi) {
            return Err((at("values"), format!("{entry}: values key {key:?} is not a raw {} value", ty.name())));
        }
    }
    if !r.bits.is_empty() && !ty.is_integer() {
        return Err((at("bits"), format!("{entry}: bits (a bit field) needs an integer type, not {}", ty.name())));
    }
    let bit_count = i128::from(ty.registers()) * 16;
    for key in r.bits.keys() {
        if parse_key(key).is_none_or(|k| k < 0 || k >= bit_count) {
            return Err((at("bits"), format!("{entry}: bits key {key:?} is not a bit from 0 to {}", bit_count - 1)));
        }
    }
    if let Some(default) = &r.default {
        let fits = match (ty, default) {
            (ValueType::String, toml::Value::String(s)) => s.len() <= usize::from(r.width()) * 2 && s.is_ascii(),
            (t, toml::Value::Integer(n)) if t.is_integer() => {
                let (lo, hi) = t.integer_range();
                (lo..=hi).contains(&i128::from(*n))
            }
            (t, toml::Value::Integer(_) | toml::Value::Float(_)) => t.is_float(),
            _ => false,
        };
        if !fits {
            return Err((at("default"), format!("{entry}: default = {default} is not a {} value", ty.name())));
        }
    }
    Ok(())
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
        let bad_type = error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\ntype='u24'\n"));
        assert!(bad_type.starts_with("in mine.toml, line 9 (type='u24'): unknown variant `u24`"), "{bad_type}");
        assert_eq!(
            error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\ntype='string'\n")),
            "in mine.toml, line 6: [[registers]] 1 (r): a string needs length = its registers (1 or more)"
        );
        assert_eq!(
            error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\nvalues={{ 'x' = 'on' }}\n")),
            "in mine.toml, line 9: [[registers]] 1 (r): values key \"x\" is not a raw u16 value"
        );
        assert_eq!(
            error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\ndepends_on=['A004']\n")),
            "in mine.toml, line 9: [[registers]] 1 (r): depends_on names \"A004\", which the profile does not have"
        );
        assert_eq!(
            error(&format!("{DEVICE}[[span]]\ntable='holding'\nfirst=9\nlast=3\n")),
            "in mine.toml, line 6: [[span]] holding: first = 9 is above last = 3"
        );
        assert_eq!(
            error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\nmin=5\nmax=4\n")),
            "in mine.toml, line 10: [[registers]] 1 (r): min = 5 is above max = 4"
        );
    }

    #[test]
    fn an_order_is_one_of_the_four_names_and_defaults_to_the_devices() {
        let pair = |order: &str| {
            format!("[addressing]\norder='CDAB'\n{DEVICE}[[registers]]\nnumber=1\nname='r'\ntype='u32'\n{order}")
        };
        let default = Profile::parse(&pair(""), "mine.toml").unwrap();
        assert_eq!(default.points()[0].order, Order::Cdab);
        let own = Profile::parse(&pair("order='BADC'\n"), "mine.toml").unwrap();
        assert_eq!(own.points()[0].order, Order::Badc);
        let wrong = error(&pair("order='cdab'\n"));
        assert!(wrong.starts_with("in mine.toml, line 12 (order='cdab'): unknown variant `cdab`"), "{wrong}");
        let single = error(&format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\norder='CDAB'\n"));
        assert_eq!(
            single,
            "in mine.toml, line 9: [[registers]] 1 (r): order is for values of more than one register, not u16"
        );
    }

    #[test]
    fn overlapping_registers_are_refused_naming_both_and_their_lines() {
        let text = format!(
            "{DEVICE}[[registers]]\nnumber=10\nname='a'\ncount=4\n\n[[registers]]\nnumber=20\nname='b'\n\n\
             [[registers]]\nnumber=12\nname='c'\ntype='u32'\n"
        );
        assert_eq!(error(&text), "in mine.toml, line 15: [[registers]] 12 (c) overlaps 10 (a) on line 6");
        let duplicate = format!("{DEVICE}[[coils]]\nnumber=3\nname='a'\n[[coils]]\nnumber=3\nname='b'\n");
        assert_eq!(error(&duplicate), "in mine.toml, line 9: [[coils]] 3 (b) is at the same number as 3 (a) on line 6");
        // A 32-bit pair takes two numbers; the next one may follow it.
        let pairs = format!("{DEVICE}[[inputs]]\nnumber=1\nname='a'\ntype='i32'\n[[inputs]]\nnumber=3\nname='b'\n");
        assert!(Profile::parse(&pairs, "mine.toml").is_ok());
        let clash = format!("{DEVICE}[[inputs]]\nnumber=1\nname='a'\ntype='f32'\n[[inputs]]\nnumber=2\nname='b'\n");
        assert_eq!(error(&clash), "in mine.toml, line 10: [[inputs]] 2 (b) overlaps 1 (a) on line 6");
        // The same number in two tables is no overlap: coils and registers are apart.
        let apart = format!("{DEVICE}[[coils]]\nnumber=1\nname='a'\n[[registers]]\nnumber=1\nname='b'\n");
        assert!(Profile::parse(&apart, "mine.toml").is_ok());
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
