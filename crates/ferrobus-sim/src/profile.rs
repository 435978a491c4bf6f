//! Profile files: one device model each, in TOML.
//!
//! A profile says which function codes the device answers, how many items it takes per
//! request, its register and coil map (names, units, scaling, ranges, access, 32-bit pairs and
//! their word order, the manual's numbering), its response wait, its broadcast rules, its
//! vendor exception codes and its identification. The built-in profiles are in `profiles/`
//! and compiled in; users write their own in the same format.

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

/// Word order of a 32-bit pair.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum WordOrder {
    /// High word at the lower address (Omron).
    #[default]
    HighFirst,
    /// Low word at the lower address (the SDP example).
    LowFirst,
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
    #[serde(default)]
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
pub enum ProfileError {
    /// No built-in profile by that name, and no such file.
    #[error("no profile named {name:?}: the built-in ones are {}, or give a path to a .toml file", BUILTIN.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", "))]
    Unknown {
        /// What was asked for.
        name: String,
    },
    /// The file could not be read.
    #[error("reading {path}: {source}")]
    Read {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// The TOML is malformed or has unknown fields.
    #[error("in {origin}: {source}")]
    Parse {
        /// The profile.
        origin: String,
        /// What is wrong and where.
        source: Box<toml::de::Error>,
    },
    /// The TOML is well formed but does not describe a possible device.
    #[error("in {origin}: {problem}")]
    Invalid {
        /// The profile.
        origin: String,
        /// What is wrong.
        problem: String,
    },
}

/// The profiles compiled into the binary.
pub const BUILTIN: &[(&str, &str)] = &[
    ("omron-3g3rx", include_str!("../profiles/omron-3g3rx.toml")),
    ("sdp-servo", include_str!("../profiles/sdp-servo.toml")),
    ("generic", include_str!("../profiles/generic.toml")),
];

impl Profile {
    /// A built-in profile by name, or a profile file by path.
    pub fn load(name_or_path: &str) -> Result<Profile, ProfileError> {
        if let Some((name, text)) = BUILTIN.iter().find(|(n, _)| *n == name_or_path) {
            return Profile::parse(text, name);
        }
        let path = Path::new(name_or_path);
        if !path.exists() {
            return Err(ProfileError::Unknown { name: name_or_path.to_string() });
        }
        let text = std::fs::read_to_string(path)
            .map_err(|source| ProfileError::Read { path: path.display().to_string(), source })?;
        Profile::parse(&text, &path.display().to_string())
    }

    /// Parses and checks a profile; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Profile, ProfileError> {
        let profile: Profile = toml::from_str(text)
            .map_err(|source| ProfileError::Parse { origin: origin.to_string(), source: Box::new(source) })?;
        profile.validate().map_err(|problem| ProfileError::Invalid { origin: origin.to_string(), problem })?;
        Ok(profile)
    }

    /// The faults the profile asks for.
    pub fn faults(&self) -> Result<crate::Faults, String> {
        self.faults.as_deref().map_or(Ok(crate::Faults::default()), |spec| spec.parse().map_err(|e| format!("{e}")))
    }

    fn validate(&self) -> Result<(), String> {
        self.faults()?;
        if self.comm.response_wait_ms > 60_000 {
            return Err(format!("response_wait_ms = {} is more than a minute", self.comm.response_wait_ms));
        }
        for r in self.registers.iter().chain(&self.inputs) {
            if !(1..=2).contains(&r.size) {
                return Err(format!("register {} ({}): size must be 1 or 2", r.number, r.name));
            }
            if r.number < u32::from(self.addressing.base) {
                return Err(format!("register {} ({}) is below the base {}", r.number, r.name, self.addressing.base));
            }
            let end = u64::from(r.number) + u64::from(r.count) * u64::from(r.size);
            if end > 0x1_0000 + u64::from(self.addressing.base) {
                return Err(format!("register {} ({}) runs past the address space", r.number, r.name));
            }
            if let (Some(min), Some(max)) = (r.min, r.max) {
                if min > max {
                    return Err(format!("register {}: min {min} > max {max}", r.name));
                }
            }
        }
        for b in self.coils.iter().chain(&self.discrete_inputs) {
            if b.number < u32::from(self.addressing.base) || u64::from(b.number) + u64::from(b.count) > 0x1_0000 + 1 {
                return Err(format!("bit {} ({}) is outside the address space", b.number, b.name));
            }
        }
        for t in
            [self.tables.coils, self.tables.discrete_inputs, self.tables.holding_registers, self.tables.input_registers]
                .into_iter()
                .flatten()
        {
            if t > 0x1_0000 {
                return Err(format!("a table of {t} items is larger than the address space"));
            }
        }
        Ok(())
    }
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

    #[test]
    fn mistakes_in_a_profile_are_reported_with_where_they_are() {
        let e = Profile::parse(
            "[device]\nname = 'x'\nvendor='v'\nproduct_code='p'\nrevision='1'\ncolour = 'red'\n",
            "mine.toml",
        )
        .unwrap_err();
        assert!(e.to_string().starts_with("in mine.toml: "), "{e}");
        assert!(e.to_string().contains("colour"), "{e}");
        let bad = "[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\n[[registers]]\nnumber=1\nname='r'\nsize=3\n";
        assert_eq!(
            Profile::parse(bad, "mine.toml").unwrap_err().to_string(),
            "in mine.toml: register 1 (r): size must be 1 or 2"
        );
    }
}
