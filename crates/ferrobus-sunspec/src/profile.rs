//! The models found, as a device profile of named points.
//!
//! Every point of every model with a definition becomes a holding register entry named
//! `MODEL.POINT` (`common.Mn`, `inverter_three_phase.W`; repeating groups
//! `mppt.module1.DCW`), in the group `MODEL` (`get --group mppt`). A model that appears twice
//! is `MODEL_2` the second time. Types: uint16/acc16/count/enum16/bitfield16 → u16,
//! int16/sunssf → i16, uint32/acc32/enum32/bitfield32/ipaddr → u32, int32 → i32,
//! uint64/acc64/bitfield64/eui48 → u64, int64 → i64, float32 → f32, float64 → f64, string →
//! a string of its size; enumerations carry their symbols as values, bit fields as bits. `pad`
//! points and ipv6addr points (no 128-bit type) are left out. Access is `rw` where the
//! definition says RW.
//!
//! Scale factors are read once, at discovery: a point whose `sf` names a `sunssf` point gets
//! scale = 10^sf of the value read then (a device that changes a scale factor at run time needs
//! a new discovery).
//!
//! Every point carries SunSpec's "not implemented" value of its type as the profile's
//! `not_implemented` ([`not_implemented_value`]): int16 and sunssf 0x8000, uint16, count,
//! enum16 and bitfield16 0xFFFF, acc16 0, int32 0x80000000, uint32, enum32 and bitfield32
//! 0xFFFFFFFF, acc32 and ipaddr 0, int64 0x8000000000000000, uint64 and bitfield64
//! 0xFFFFFFFFFFFFFFFF, acc64 0, eui48 0xFFFFFFFFFFFF, float32 and float64 NaN (0x7FC00000),
//! a string whose first byte is NUL — the table of pysunspec2 (`sunspec2/mb.py`). `get`,
//! `poll`, `monitor` and the bridge show such a value as not implemented (`n/a`, empty in
//! CSV, null in JSON and Sparkplug), as pysunspec2 reads it as `None`. A point whose scale
//! factor read 0x8000 at discovery is not implemented either (`implemented = false`): with no
//! scale its number would be no reading (pysunspec2 would show it unscaled).
//!
//! Text from the device (the common model's `Mn`, `Md`, `Vr`) and from the model files
//! (labels, units, descriptions) reaches the profile with control characters spelled out
//! (`\u{1b}`) and cut to the profile's limits ([`ferrobus_profile::LABEL_MAX`], ...).
//!
//! A model without a definition, or whose length does not fit its definition, gets no points
//! (the scan lists it with what differs).

use std::collections::BTreeMap;

use ferrobus_profile::{Access, DeviceSection, Profile, ProfileError, RegisterDef, ValueType};
use toml::Value;

use crate::Definitions;
use crate::def::PointType;
use crate::discover::{Discovery, Found};
use crate::layout::{SfAt, layout};

/// Whether `raw` (the point's registers) is SunSpec's "not implemented" value of `kind` (see
/// the module doc).
pub fn not_implemented(kind: PointType, raw: &[u16]) -> bool {
    let all = |v: u16| raw.iter().all(|r| *r == v);
    match kind {
        PointType::Uint16
        | PointType::Enum16
        | PointType::Bitfield16
        | PointType::Count
        | PointType::Uint32
        | PointType::Enum32
        | PointType::Bitfield32
        | PointType::Uint64
        | PointType::Bitfield64 => all(0xFFFF),
        PointType::Int16 | PointType::Sunssf => raw == [0x8000],
        PointType::Int32 | PointType::Int64 => {
            raw.split_first().is_some_and(|(h, rest)| *h == 0x8000 && rest.iter().all(|r| *r == 0))
        }
        PointType::Acc16 | PointType::Acc32 | PointType::Acc64 | PointType::Ipaddr | PointType::Ipv6addr => all(0),
        PointType::String => raw.first().is_none_or(|r| r >> 8 == 0),
        PointType::Eui48 => raw.get(1..).is_some_and(|rest| rest.iter().all(|r| *r == 0xFFFF)),
        PointType::Float32 => match raw {
            [hi, lo] => f32::from_bits((u32::from(*hi) << 16) | u32::from(*lo)).is_nan(),
            _ => false,
        },
        PointType::Float64 => {
            raw.len() == 4 && f64::from_bits(raw.iter().fold(0, |acc, r| (acc << 16) | u64::from(*r))).is_nan()
        }
        PointType::Pad => false,
    }
}

/// SunSpec's "not implemented" value of `kind` as the profile's `not_implemented` of the
/// point's profile type (u64's past TOML's integers, as text); `None` for a pad.
pub fn not_implemented_value(kind: PointType) -> Option<Value> {
    Some(match kind {
        PointType::Uint16 | PointType::Enum16 | PointType::Bitfield16 | PointType::Count => Value::Integer(0xFFFF),
        PointType::Int16 | PointType::Sunssf => Value::Integer(i64::from(i16::MIN)),
        PointType::Uint32 | PointType::Enum32 | PointType::Bitfield32 => Value::Integer(0xFFFF_FFFF),
        PointType::Int32 => Value::Integer(i64::from(i32::MIN)),
        PointType::Int64 => Value::Integer(i64::MIN),
        PointType::Uint64 | PointType::Bitfield64 => Value::String("0xFFFFFFFFFFFFFFFF".into()),
        PointType::Eui48 => Value::Integer(0xFFFF_FFFF_FFFF),
        PointType::Acc16 | PointType::Acc32 | PointType::Acc64 | PointType::Ipaddr => Value::Integer(0),
        PointType::Float32 | PointType::Float64 => Value::Float(f64::NAN),
        PointType::String => Value::String(String::new()),
        PointType::Pad | PointType::Ipv6addr => return None,
    })
}

/// The power of ten of a point's scale factor (a fixed one, or the `sunssf` point's value
/// read in `registers`, if from -10 to 10), and false when that point is not implemented.
fn scale_of(sf: Option<SfAt>, registers: &[u16]) -> (Option<i8>, bool) {
    match sf {
        Some(SfAt::Fixed(n)) => (Some(n), true),
        Some(SfAt::Offset(at)) => {
            let read = usize::try_from(at).ok().and_then(|at| registers.get(at)).map(|r| r.cast_signed());
            let power = read.filter(|sf| (-10..=10).contains(sf)).and_then(|sf| i8::try_from(sf).ok());
            (power, read != Some(i16::MIN))
        }
        None => (None, true),
    }
}

/// `text` from a device or a model file as a profile holds it: control characters spelled out
/// (`\u{1b}`), cut to `max` characters.
fn printable(text: &str, max: usize) -> String {
    let mut out = String::new();
    for c in text.chars() {
        if c.is_control() && !matches!(c, '\t' | '\n') {
            out.extend(c.escape_unicode());
        } else {
            out.push(c);
        }
    }
    match out.char_indices().nth(max) {
        Some((cut, _)) => out.get(..cut).unwrap_or_default().to_string(),
        None => out,
    }
}

/// The profile's type of a point, if the point is kept.
fn value_type(kind: PointType) -> Option<ValueType> {
    Some(match kind {
        PointType::Uint16 | PointType::Acc16 | PointType::Count | PointType::Enum16 | PointType::Bitfield16 => {
            ValueType::U16
        }
        PointType::Int16 | PointType::Sunssf => ValueType::I16,
        PointType::Uint32 | PointType::Acc32 | PointType::Enum32 | PointType::Bitfield32 | PointType::Ipaddr => {
            ValueType::U32
        }
        PointType::Int32 => ValueType::I32,
        PointType::Uint64 | PointType::Acc64 | PointType::Bitfield64 | PointType::Eui48 => ValueType::U64,
        PointType::Int64 => ValueType::I64,
        PointType::Float32 => ValueType::F32,
        PointType::Float64 => ValueType::F64,
        PointType::String => ValueType::String,
        PointType::Pad | PointType::Ipv6addr => return None,
    })
}

/// The profile of `discovery` as data, not yet checked (see the module doc; its file is
/// [`Profile::to_toml`]); `origin` names
/// the device (`sunspec at 10.0.0.5:502 unit 1`), `limit` is the registers per read request.
pub fn profile_data(discovery: &Discovery, defs: &Definitions, origin: &str, limit: u16) -> Profile {
    let text_of = |m: &Found, point: &str| -> Option<String> {
        let def = defs.get(m.id)?;
        let placed = layout(def, m.length, &m.registers);
        let p = placed.points.iter().find(|p| p.name == point)?;
        let start = usize::try_from(p.offset).ok()?;
        let regs = m.registers.get(start..start + usize::from(p.def.size))?;
        let bytes: Vec<u8> = regs.iter().flat_map(|r| r.to_be_bytes()).take_while(|b| *b != 0).collect();
        let text = printable(String::from_utf8_lossy(&bytes).trim(), 32);
        Some(text).filter(|s| !s.is_empty())
    };
    let common = discovery.models.iter().find(|m| m.id == 1);
    let field = |point: &str| common.and_then(|m| text_of(m, point));
    let vendor = field("Mn").unwrap_or_else(|| "unknown".into());
    let product = field("Md").unwrap_or_else(|| "unknown".into());
    let name = printable(&format!("SunSpec device {vendor} {product} ({origin})"), ferrobus_profile::LABEL_MAX);
    let mut device = DeviceSection::new(&name, &vendor, &product, &field("Vr").unwrap_or_default());
    device.identification = false;
    let mut profile = Profile::new(device);
    profile.limits.read_registers = Some(limit.clamp(1, 125));

    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    for m in &discovery.models {
        let Some(def) = defs.get(m.id) else { continue };
        if m.fits != Some(Ok(())) {
            continue;
        }
        let times = seen.entry(def.name().to_string()).or_insert(0);
        *times += 1;
        let model = if *times == 1 { def.name().to_string() } else { format!("{}_{times}", def.name()) };
        let placed = layout(def, m.length, &m.registers);
        for p in &placed.points {
            let Some(ty) = value_type(p.def.kind) else { continue };
            let mut e =
                RegisterDef::new(u32::from(m.start).saturating_add(p.offset), &format!("{model}.{}", p.name), ty);
            if p.def.kind == PointType::String {
                e.length = Some(p.def.size);
            }
            e.label = p.def.label.as_ref().map(|label| printable(label, ferrobus_profile::LABEL_MAX));
            if let Some(desc) = &p.def.desc {
                e.description = printable(desc, ferrobus_profile::TEXT_MAX);
            }
            e.unit = p.def.units.as_ref().filter(|u| !u.is_empty()).map(|u| printable(u, ferrobus_profile::UNIT_MAX));
            e.not_implemented = not_implemented_value(p.def.kind);
            let (sf, implemented) = scale_of(p.sf, &m.registers);
            // A scale factor not implemented: nor is the value it scales.
            e.implemented = implemented;
            e.scale = sf.filter(|sf| *sf != 0).map(|sf| 10f64.powi(i32::from(sf)));
            e.access = if p.def.writable { Access::Rw } else { Access::Ro };
            e.group = Some(model.clone());
            let symbols = |limit: i64| -> BTreeMap<String, String> {
                p.def
                    .symbols
                    .iter()
                    .filter(|(v, _)| (0..limit).contains(v))
                    .map(|(v, n)| (v.to_string(), printable(n, ferrobus_profile::LABEL_MAX)))
                    .collect()
            };
            match p.def.kind {
                PointType::Enum16 | PointType::Enum32 if !p.def.symbols.is_empty() => {
                    let max = if p.def.kind == PointType::Enum16 { 0x1_0000 } else { 0x1_0000_0000 };
                    e.values = symbols(max);
                }
                PointType::Bitfield16 | PointType::Bitfield32 | PointType::Bitfield64 if !p.def.symbols.is_empty() => {
                    e.bits = symbols(i64::from(p.def.size) * 16);
                }
                _ => {}
            }
            profile.registers.push(e);
        }
    }
    profile
}

/// The profile of `discovery`: [`profile_data`] checked and its points resolved, or the
/// first mistake found.
pub fn profile(discovery: &Discovery, defs: &Definitions, origin: &str, limit: u16) -> Result<Profile, ProfileError> {
    profile_data(discovery, defs, origin, limit).build(origin).map_err(|mut mistakes| mistakes.swap_remove(0))
}
