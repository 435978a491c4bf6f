//! The profile's data: its sections and entries as a file writes them, and the points they
//! resolve to ([`Point`]) with their raw values ([`Value`]).
//!
//! A profile says which function codes the device answers, how many items it takes per
//! request, its register and coil map (codes, labels, types, word orders, units, scaling,
//! ranges, access, enumerations, bit fields, groups, dependencies, the manual's numbering),
//! the address spans in which it answers reads of unmapped addresses, how to tell that it
//! runs, its exception codes and their meaning, its response wait, its broadcast rules, its
//! identification, and the faults a simulated unit starts with. The built-in profiles are in
//! `profiles/` and compiled in; users write their own in the same format.
//!
//! These are plain data: `read` reads a file into them, `check` checks them and `point`
//! resolves the points.

use std::collections::BTreeMap;
use std::fmt;

use serde::{Deserialize, Serialize};

use crate::source::{Located, NotText, Place};
use crate::text;

/// A device model.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Profile {
    /// What the device is.
    pub device: DeviceSection,
    /// How the manual numbers addresses, and the default word order.
    #[serde(skip_serializing_if = "is_default", default)]
    pub addressing: Addressing,
    /// Function codes, timing, broadcast.
    #[serde(skip_serializing_if = "is_default", default)]
    pub comm: Comm,
    /// Items per request.
    #[serde(skip_serializing_if = "is_default", default)]
    pub limits: Limits,
    /// Vendor exception codes.
    #[serde(skip_serializing_if = "is_default", default)]
    pub exceptions: Exceptions,
    /// Plain read/write tables covering the address space from 0 (the generic device).
    #[serde(skip_serializing_if = "is_default", default)]
    pub tables: Tables,
    /// The physics model, if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model: Option<ModelSection>,
    /// Coils (0x01, 0x05, 0x0F).
    #[serde(skip_serializing_if = "Vec::is_empty", default)]
    pub coils: Vec<BitDef>,
    /// Discrete inputs (0x02).
    #[serde(skip_serializing_if = "Vec::is_empty", default)]
    pub discrete_inputs: Vec<BitDef>,
    /// Holding registers (0x03, 0x06, 0x10, 0x16, 0x17).
    #[serde(skip_serializing_if = "Vec::is_empty", default)]
    pub registers: Vec<RegisterDef>,
    /// Input registers (0x04).
    #[serde(skip_serializing_if = "Vec::is_empty", default)]
    pub inputs: Vec<RegisterDef>,
    /// Ranges in which the device answers reads of every address, mapped or not.
    #[serde(skip_serializing_if = "Vec::is_empty", default)]
    pub span: Vec<SpanDef>,
    /// How a client tells the device's state (whether it runs).
    #[serde(skip_serializing_if = "is_default", default)]
    pub state: State,
    /// The device's own words for its exception codes.
    #[serde(skip_serializing_if = "Vec::is_empty", default)]
    pub exception_meaning: Vec<ExceptionMeaning>,
    /// File records (0x14, 0x15).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub files: Option<Files>,
    /// The FIFO queue (0x18).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fifo: Option<Fifo>,
    /// Faults every simulated unit of this profile starts with, written as `ferrobus sim
    /// --fault` takes them: `"drop=10%,delay=50ms"` (the simulator reads them).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub faults: Option<String>,
    /// Fault rules aimed at requests, tried in order after those of `faults`: `[[fault_rule]]`
    /// tables with the keys of a `--fault` rule, e.g. `fc = 0x03`, `addr = "0x1000-0x100F"`,
    /// `share = "50%"`, and one action: `exception = 0x06`, `no-reply = true`,
    /// `delay = "200ms"`, `short = true` or `short = 3`, `malformed = true`, `unit = 7`,
    /// `tid = "+1"`, `trickle = "5ms"` (the simulator reads them).
    #[serde(skip_serializing_if = "Vec::is_empty", default)]
    pub fault_rule: Vec<toml::Table>,
    /// Where the profile came from (a built-in name or a path), for messages.
    #[serde(skip)]
    pub origin: String,
    /// Where `faults` is written, if anywhere.
    #[serde(skip)]
    pub faults_place: Option<Place>,
    /// Where each `[[fault_rule]]` starts.
    #[serde(skip)]
    pub fault_rule_places: Vec<Option<Place>>,
    /// Every coil, discrete input and register entry resolved to points, in profile order.
    #[serde(skip)]
    pub(crate) points: Vec<Point>,
}

/// `[device]`
#[derive(Clone, Debug, Deserialize, Serialize)]
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
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vendor_url: Option<String>,
    /// Object 0x04 ProductName.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub product_name: Option<String>,
    /// Object 0x05 ModelName.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model_name: Option<String>,
    /// Object 0x06 UserApplicationName.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub user_application_name: Option<String>,
    /// Whether the device answers 0x2B/0x0E and 0x11 (else exception 01).
    #[serde(skip_serializing_if = "is_true", default = "yes")]
    pub identification: bool,
    /// The server id bytes of 0x11, before the run indicator (ASCII).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub server_id: Option<String>,
}

impl DeviceSection {
    /// A device named `name`, with the three identification objects every device has; the
    /// others absent, identification answered.
    pub fn new(name: &str, vendor: &str, product_code: &str, revision: &str) -> DeviceSection {
        DeviceSection {
            name: name.to_string(),
            vendor: vendor.to_string(),
            product_code: product_code.to_string(),
            revision: revision.to_string(),
            vendor_url: None,
            product_name: None,
            model_name: None,
            user_application_name: None,
            identification: true,
            server_id: None,
        }
    }
}

/// `[addressing]`
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Addressing {
    /// The number of the first item in the manual: 1 when the frame carries number − 1.
    #[serde(skip_serializing_if = "is_default", default)]
    pub base: u16,
    /// The order of multi-register values whose entry names none (default ABCD).
    #[serde(skip_serializing_if = "is_default", default, deserialize_with = "order", serialize_with = "order_name")]
    pub order: Order,
}

/// `[comm]`
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Comm {
    /// The function codes answered; the others get exception 01. Absent: all public codes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub functions: Option<Vec<u8>>,
    /// The 0x08 sub-functions answered; absent: all.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub diagnostics: Option<Vec<u16>>,
    /// Wait before replying, on top of t3.5 (3G3RX C078).
    #[serde(skip_serializing_if = "is_default", default)]
    pub response_wait_ms: u32,
    /// Whether reads sent by broadcast are executed (they are never answered).
    #[serde(skip_serializing_if = "is_false", default)]
    pub broadcast_reads: bool,
    /// Whether 0x08 by broadcast is executed.
    #[serde(skip_serializing_if = "is_false", default)]
    pub broadcast_diagnostics: bool,
}

/// `[limits]`: the most items per request; absent: the spec's limits.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    /// 0x01 and 0x02 (spec: 2000).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub read_coils: Option<u16>,
    /// 0x0F (spec: 1968).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub write_coils: Option<u16>,
    /// 0x03, 0x04 and the read of 0x17 (spec: 125).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub read_registers: Option<u16>,
    /// 0x10 and the write of 0x17 (spec: 123 and 121).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub write_registers: Option<u16>,
}

/// `[exceptions]`: which code the device answers for each kind of refusal.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq)]
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
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Tables {
    /// Coils.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coils: Option<u32>,
    /// Discrete inputs.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub discrete_inputs: Option<u32>,
    /// Holding registers.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub holding_registers: Option<u32>,
    /// Input registers.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub input_registers: Option<u32>,
}

/// `[model]`
#[derive(Clone, Debug, Deserialize, Serialize)]
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
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Polarity {
    /// 1 = reverse (Omron MX2/RX2 tables).
    #[default]
    OneIsReverse,
    /// 1 = forward (Hitachi SJ700-2 table).
    OneIsForward,
}

/// Read/write access.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Deserialize, Serialize)]
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
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug, Default, Deserialize, Serialize)]
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

/// The order of a multi-register value's bytes over its registers: the project's one
/// word-order type, [`ferrobus_proto::words::WordOrder`] (ABCD, CDAB, BADC, DCBA), under the
/// name profiles use. A profile's `order` takes what [`Order::from_name`] takes: the four
/// names in any case, `high-first` (ABCD) and `low-first` (CDAB).
pub use ferrobus_proto::words::WordOrder as Order;

/// A profile's `order = "..."`, read by the one parser of word orders.
fn order<'de, D: serde::Deserializer<'de>>(deserializer: D) -> Result<Order, D::Error> {
    let text = String::deserialize(deserializer)?;
    Order::from_name(&text)
        .ok_or_else(|| serde::de::Error::custom(format!("{text:?} is not a word order: use {}", Order::NAMES)))
}

/// A word order as a profile writes it (`ABCD`).
#[expect(clippy::trivially_copy_pass_by_ref, reason = "serde's serialize_with takes the field by reference")]
fn order_name<S: serde::Serializer>(order: &Order, serializer: S) -> Result<S::Ok, S::Error> {
    serializer.serialize_str(order.name())
}

/// [`order_name`] for an optional field (skipped when `None`).
#[expect(
    clippy::ref_option,
    clippy::trivially_copy_pass_by_ref,
    reason = "serde's serialize_with takes the field by reference"
)]
fn some_order_name<S: serde::Serializer>(order: &Option<Order>, serializer: S) -> Result<S::Ok, S::Error> {
    match order {
        Some(order) => order_name(order, serializer),
        None => serializer.serialize_none(),
    }
}

#[expect(clippy::trivially_copy_pass_by_ref, reason = "serde's skip_serializing_if takes the field by reference")]
fn is_true(b: &bool) -> bool {
    *b
}
#[expect(clippy::trivially_copy_pass_by_ref, reason = "serde's skip_serializing_if takes the field by reference")]
fn is_false(b: &bool) -> bool {
    !*b
}
#[expect(clippy::trivially_copy_pass_by_ref, reason = "serde's skip_serializing_if takes the field by reference")]
fn is_one(n: &u32) -> bool {
    *n == 1
}
fn is_default<T: Default + PartialEq>(value: &T) -> bool {
    *value == T::default()
}

/// [`order`] for an optional field.
fn some_order<'de, D: serde::Deserializer<'de>>(deserializer: D) -> Result<Option<Order>, D::Error> {
    order(deserializer).map(Some)
}

/// A coil or discrete input, or a run of them.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct BitDef {
    /// The manual's number of the first.
    pub number: u32,
    /// How many (default 1); the items of a run are named NAME1, NAME2, ...
    #[serde(skip_serializing_if = "is_one", default = "one")]
    pub count: u32,
    /// A short name (the code).
    pub name: String,
    /// A short descriptive name shown beside the code.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub label: Option<String>,
    /// What it is.
    #[serde(skip_serializing_if = "String::is_empty", default)]
    pub description: String,
    /// Access.
    #[serde(skip_serializing_if = "is_default", default)]
    pub access: Access,
    /// The value at start (the simulator's) and out of the factory; off when not given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub default: Option<bool>,
    /// A group name for `--group`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub group: Option<String>,
    /// Whether a backup saves it (default: when read/write).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub backup: Option<bool>,
    /// The manual section it comes from.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
    /// False when the fact could not be confirmed.
    #[serde(skip_serializing_if = "is_true", default = "yes")]
    pub confirmed: bool,
}

/// A register or multi-register value, or a run of them.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RegisterDef {
    /// The manual's number of the first register.
    pub number: u32,
    /// How many items (default 1); the items of a run are named NAME1, NAME2, ...
    #[serde(skip_serializing_if = "is_one", default = "one")]
    pub count: u32,
    /// The value's type (default u16).
    #[serde(skip_serializing_if = "is_default", default, rename = "type")]
    pub value_type: ValueType,
    /// The order of a multi-register value (default: `[addressing] order`).
    #[serde(
        skip_serializing_if = "Option::is_none",
        default,
        deserialize_with = "some_order",
        serialize_with = "some_order_name"
    )]
    pub order: Option<Order>,
    /// Registers of a string.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub length: Option<u16>,
    /// A short name (a parameter code such as `F001`).
    pub name: String,
    /// A short descriptive name shown beside the code.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub label: Option<String>,
    /// What it is.
    #[serde(skip_serializing_if = "String::is_empty", default)]
    pub description: String,
    /// Engineering unit.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
    /// Engineering value = raw × scale + offset (default 1).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scale: Option<f64>,
    /// Engineering value = raw × scale + offset (default 0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub offset: Option<f64>,
    /// Lowest raw value accepted by a write.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min: Option<f64>,
    /// Highest raw value accepted by a write.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max: Option<f64>,
    /// Access.
    #[serde(skip_serializing_if = "is_default", default)]
    pub access: Access,
    /// Whether it may be written while the drive runs (default yes).
    #[serde(skip_serializing_if = "is_true", default = "yes")]
    pub while_running: bool,
    /// A group name for `--group`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub group: Option<String>,
    /// An enumeration: raw value (as a string key) → meaning.
    #[serde(skip_serializing_if = "BTreeMap::is_empty", default)]
    pub values: BTreeMap<String, String>,
    /// A bit field: bit index (as a string key) → meaning.
    #[serde(skip_serializing_if = "BTreeMap::is_empty", default)]
    pub bits: BTreeMap<String, String>,
    /// Codes a restore writes before this one.
    #[serde(skip_serializing_if = "Vec::is_empty", default)]
    pub depends_on: Vec<String>,
    /// Whether a backup saves it (default: when read/write).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub backup: Option<bool>,
    /// The manual section it comes from.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
    /// False when the fact could not be confirmed.
    #[serde(skip_serializing_if = "is_true", default = "yes")]
    pub confirmed: bool,
    /// The raw value at start (the simulator's) and out of the factory: an integer, a float
    /// for f32/f64, text for a string.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub default: Option<toml::Value>,
    /// The raw value by which the device says it does not implement the point (SunSpec's
    /// 0xFFFF for a u16, 0x8000 for an i16, `nan` for a float, `""` for a string; an integer
    /// may be written as text, `"0xFFFFFFFFFFFFFFFF"`, past TOML's 64-bit signed integers):
    /// read, it shows as not implemented (`n/a`, empty in CSV, null in JSON), not as a reading.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub not_implemented: Option<toml::Value>,
    /// False when the device does not implement the point at all (a SunSpec point whose scale
    /// factor read 0x8000): every value read shows as not implemented. Default true.
    #[serde(skip_serializing_if = "is_true", default = "yes")]
    pub implemented: bool,
}

impl BitDef {
    /// One read-only bit numbered `number`, named `name`, with every other key at its default.
    pub fn new(number: u32, name: &str) -> BitDef {
        BitDef {
            number,
            count: 1,
            name: name.to_string(),
            label: None,
            description: String::new(),
            access: Access::default(),
            default: None,
            group: None,
            backup: None,
            source: None,
            confirmed: true,
        }
    }
}

impl RegisterDef {
    /// One read-only value of `value_type` at `number`, named `name`, with every other key at
    /// its default (no unit, no scale, the profile's word order).
    pub fn new(number: u32, name: &str, value_type: ValueType) -> RegisterDef {
        RegisterDef {
            number,
            count: 1,
            value_type,
            order: None,
            length: None,
            name: name.to_string(),
            label: None,
            description: String::new(),
            unit: None,
            scale: None,
            offset: None,
            min: None,
            max: None,
            access: Access::default(),
            while_running: true,
            group: None,
            values: BTreeMap::new(),
            bits: BTreeMap::new(),
            depends_on: Vec::new(),
            backup: None,
            source: None,
            confirmed: true,
            default: None,
            not_implemented: None,
            implemented: true,
        }
    }
}

fn one() -> u32 {
    1
}

/// The four tables of the data model.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug, PartialOrd, Ord, Deserialize, Serialize)]
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
#[derive(Clone, Copy, Debug, Deserialize, Serialize)]
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
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct State {
    /// How to tell that the drive runs.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub running: Option<RunningRule>,
}

/// `[state] running = { point = "running", values = [1] }`
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RunningRule {
    /// A coil, discrete input or register code.
    pub point: String,
    /// The raw values that mean running.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub values: Vec<i64>,
}

/// `[[exception_meaning]]`
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ExceptionMeaning {
    /// The exception code.
    pub code: u8,
    /// What the device means by it.
    pub meaning: String,
}

/// `[files]`
#[derive(Clone, Copy, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Files {
    /// Files 1..=count.
    pub count: u16,
    /// Records per file.
    pub records: u16,
}

/// `[fifo]`
#[derive(Clone, Copy, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Fifo {
    /// The FIFO pointer address (a holding register holding the count).
    pub address: u16,
}

/// One value of the device: a coil, a discrete input, or a register value of any type.
#[derive(Clone, Debug, PartialEq)]
#[allow(clippy::struct_excessive_bools)] // each one a fact of the profile's own entry
pub struct Point {
    /// Its table.
    pub table: Table,
    /// The wire address of its first register or bit (the manual's number − base).
    pub address: u16,
    /// The manual's number.
    pub number: u32,
    /// The code (the entry's `name`; NAME1, NAME2, ... for the items of a run).
    pub code: String,
    /// The short descriptive name (empty when the profile gives none).
    pub label: String,
    /// What it is.
    pub description: String,
    /// The value's type ([`ValueType::Bit`] for coils and discrete inputs).
    pub value_type: ValueType,
    /// The order of a multi-register value.
    pub order: Order,
    /// Registers (or bits) it takes.
    pub width: u16,
    /// Engineering unit.
    pub unit: Option<String>,
    /// Engineering value = raw × scale + offset.
    pub scale: f64,
    /// Engineering value = raw × scale + offset.
    pub offset: f64,
    /// The lowest raw value a write may set.
    pub min: Option<f64>,
    /// The highest raw value a write may set.
    pub max: Option<f64>,
    /// Access.
    pub access: Access,
    /// Whether it may be written while the drive runs.
    pub while_running: bool,
    /// Its group, if any.
    pub group: Option<String>,
    /// An enumeration: raw value → meaning, by raw value.
    pub values: Vec<(i128, String)>,
    /// A bit field: bit index → meaning, by bit.
    pub bits: Vec<(u8, String)>,
    /// Codes a restore writes before this one.
    pub depends_on: Vec<String>,
    /// Whether a backup saves it.
    pub backup: bool,
    /// The manual section it comes from.
    pub source: Option<String>,
    /// False when a fact about it could not be confirmed.
    pub confirmed: bool,
    /// The raw value at start (the simulator's): the profile's `default`, else zero (off).
    pub default: Value,
    /// The profile's `default` when it gives one: the value the device leaves the factory
    /// with (`diff --defaults` compares with it); `None` where `default` is a mere zero.
    pub factory_default: Option<Value>,
    /// The raw value by which the device says it does not implement the point (SunSpec's
    /// sentinels: 0xFFFF for a u16, ...), if it has one; see [`Point::implemented`].
    pub not_implemented: Option<Value>,
    /// False when the device does not implement the point at all: no value read is a reading.
    pub implemented: bool,
}

/// A point's raw value, as the device holds it.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// A coil or discrete input.
    Bool(bool),
    /// An integer register value (any of u16 ... i64).
    Int(i128),
    /// An f32 or f64 register value.
    Float(f64),
    /// A string register value, NUL padding removed.
    Text(String),
}

impl Value {
    /// The value as an integer, if it is one (a bit is 0 or 1).
    pub fn as_int(&self) -> Option<i128> {
        match self {
            Value::Bool(b) => Some(i128::from(*b)),
            Value::Int(n) => Some(*n),
            Value::Float(_) | Value::Text(_) => None,
        }
    }

    /// The value as a float, if it is a number.
    #[allow(clippy::cast_precision_loss)]
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Value::Float(x) => Some(*x),
            other => other.as_int().map(|n| n as f64),
        }
    }
}

impl fmt::Display for Value {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Value::Bool(b) => write!(f, "{}", u8::from(*b)),
            Value::Int(n) => write!(f, "{n}"),
            Value::Float(x) => write!(f, "{x}"),
            Value::Text(s) => write!(f, "{s:?}"),
        }
    }
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
    /// The file is not UTF-8 text (a binary file, or a text in another encoding).
    #[error("{path}:{error}")]
    NotText {
        /// The file.
        path: String,
        /// Where the first byte that is not UTF-8 is.
        error: NotText,
    },
    /// The TOML is malformed, has unknown fields, or a field of the wrong type.
    #[error("{}", mistake.in_file(origin))]
    Parse {
        /// The profile.
        origin: String,
        /// Where and what, from the TOML reader, with an excerpt of the line.
        mistake: Located,
    },
    /// The TOML is well formed but does not describe a possible device.
    #[error("{}", mistake.in_file(origin))]
    Invalid {
        /// The profile.
        origin: String,
        /// Where (the entry or field at fault) and what, naming the entry and the field.
        mistake: Located,
    },
}

/// The profiles compiled into the binary.
pub const BUILTIN: &[(&str, &str)] = &[
    ("omron-3g3rx", include_str!("../profiles/omron-3g3rx.toml")),
    ("sdp-servo", include_str!("../profiles/sdp-servo.toml")),
    ("generic", include_str!("../profiles/generic.toml")),
    ("sunspec-inverter", include_str!("../profiles/sunspec-inverter.toml")),
];

impl Profile {
    /// A profile of `device` and nothing else, for a program to fill in as data (its entries,
    /// its limits), check with [`Profile::build`] and write with [`Profile::to_toml`]: the
    /// importer and SunSpec discovery build profiles so, not as text.
    ///
    /// ```
    /// use ferrobus_profile::{DeviceSection, Profile, RegisterDef, ValueType};
    ///
    /// let mut profile = Profile::new(DeviceSection::new("A meter", "ACME", "M1", "1.0"));
    /// let mut power = RegisterDef::new(0x0010, "power", ValueType::F32);
    /// power.unit = Some("W".into());
    /// profile.inputs.push(power);
    /// let profile = profile.build("a meter of mine").unwrap();
    /// assert_eq!(profile.points()[0].code, "power");
    /// assert!(profile.to_toml().contains("[[inputs]]"));
    /// ```
    pub fn new(device: DeviceSection) -> Profile {
        Profile {
            device,
            addressing: Addressing::default(),
            comm: Comm::default(),
            limits: Limits::default(),
            exceptions: Exceptions::default(),
            tables: Tables::default(),
            model: None,
            coils: Vec::new(),
            discrete_inputs: Vec::new(),
            registers: Vec::new(),
            inputs: Vec::new(),
            span: Vec::new(),
            state: State::default(),
            exception_meaning: Vec::new(),
            files: None,
            fifo: None,
            faults: None,
            fault_rule: Vec::new(),
            origin: String::new(),
            faults_place: None,
            fault_rule_places: Vec::new(),
            points: Vec::new(),
        }
    }

    /// The profile as a profile file says it: TOML that [`Profile::parse`] reads back to the
    /// same profile, its defaults left out.
    pub fn to_toml(&self) -> String {
        // Every field is a string, a number, a bool, an array or a table of them: nothing
        // TOML cannot hold, so the serializer has no error to give.
        toml::to_string(self).unwrap_or_default()
    }

    /// Every coil, discrete input and register entry as points, in profile order (coils,
    /// discrete inputs, holding registers, input registers); a run of `count` items gives
    /// `count` points.
    pub fn points(&self) -> &[Point] {
        &self.points
    }

    /// The error for a problem found after parsing (e.g. by the simulator in `faults`), at
    /// `place` of the file.
    pub fn problem(&self, place: Option<Place>, problem: &str) -> ProfileError {
        ProfileError::Invalid { origin: self.origin.clone(), mistake: Located::at(place, problem) }
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

/// A raw integer written in a profile key: the one grammar of integers, [`text::integer`].
pub(crate) fn parse_key(key: &str) -> Option<i128> {
    text::integer(key).map(|(value, _)| value)
}

impl fmt::Display for Profile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} ({} {})", self.device.name, self.device.vendor, self.device.product_code)
    }
}
