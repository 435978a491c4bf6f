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
//! a new discovery). A scale factor the device does not implement (0x8000) leaves the point
//! unscaled. The profile machinery has no "not implemented" value: a point the device does not
//! implement (0xFFFF for uint16, 0x8000 for int16, 0x80000000 for int32, ...) shows as that
//! number; [`not_implemented`] tells them.
//!
//! A model without a definition, or whose length does not fit its definition, gets no points
//! (the scan lists it with what differs).

use std::collections::BTreeMap;

use ferrobus_profile::{Profile, ProfileError};
use toml::{Table, Value};

use crate::Definitions;
use crate::def::PointType;
use crate::discover::{Discovery, Found};
use crate::layout::{SfAt, layout};

/// Whether `raw` (the point's registers) is SunSpec's "not implemented" value of `kind`.
pub fn not_implemented(kind: PointType, raw: &[u16]) -> bool {
    let all = |v: u16| raw.iter().all(|r| *r == v);
    match kind {
        PointType::Uint16 | PointType::Enum16 | PointType::Bitfield16 | PointType::Count => all(0xFFFF),
        PointType::Int16 | PointType::Sunssf => raw == [0x8000],
        PointType::Uint32 | PointType::Enum32 | PointType::Bitfield32 | PointType::Uint64 | PointType::Bitfield64 => {
            all(0xFFFF)
        }
        PointType::Int32 | PointType::Int64 => {
            raw.split_first().is_some_and(|(h, rest)| *h == 0x8000 && rest.iter().all(|r| *r == 0))
        }
        PointType::Acc16
        | PointType::Acc32
        | PointType::Acc64
        | PointType::Ipaddr
        | PointType::Ipv6addr
        | PointType::Eui48
        | PointType::String => all(0),
        PointType::Float32 | PointType::Float64 => raw.first() == Some(&0x7FC0),
        PointType::Pad => false,
    }
}

/// The profile's type name and whether the point is kept.
fn value_type(kind: PointType) -> Option<&'static str> {
    Some(match kind {
        PointType::Uint16 | PointType::Acc16 | PointType::Count | PointType::Enum16 | PointType::Bitfield16 => "u16",
        PointType::Int16 | PointType::Sunssf => "i16",
        PointType::Uint32 | PointType::Acc32 | PointType::Enum32 | PointType::Bitfield32 | PointType::Ipaddr => "u32",
        PointType::Int32 => "i32",
        PointType::Uint64 | PointType::Acc64 | PointType::Bitfield64 | PointType::Eui48 => "u64",
        PointType::Int64 => "i64",
        PointType::Float32 => "f32",
        PointType::Float64 => "f64",
        PointType::String => "string",
        PointType::Pad | PointType::Ipv6addr => return None,
    })
}

/// The TOML text of the profile of `discovery` (see the module doc); `origin` names the device
/// (`sunspec at 10.0.0.5:502 unit 1`), `limit` is the registers per read request.
pub fn profile_text(discovery: &Discovery, defs: &Definitions, origin: &str, limit: u16) -> String {
    let mut root = Table::new();
    let text_of = |m: &Found, point: &str| -> Option<String> {
        let def = defs.get(m.id)?;
        let placed = layout(def, m.length, &m.registers);
        let p = placed.points.iter().find(|p| p.name == point)?;
        let start = usize::try_from(p.offset).ok()?;
        let regs = m.registers.get(start..start + usize::from(p.def.size))?;
        let bytes: Vec<u8> = regs.iter().flat_map(|r| r.to_be_bytes()).take_while(|b| *b != 0).collect();
        Some(String::from_utf8_lossy(&bytes).trim().to_string()).filter(|s| !s.is_empty())
    };
    let common = discovery.models.iter().find(|m| m.id == 1);
    let field = |point: &str| common.and_then(|m| text_of(m, point));
    let mut device = Table::new();
    let vendor = field("Mn").unwrap_or_else(|| "unknown".into());
    let product = field("Md").unwrap_or_else(|| "unknown".into());
    device.insert("name".into(), Value::String(format!("SunSpec device {vendor} {product} ({origin})")));
    device.insert("vendor".into(), Value::String(vendor));
    device.insert("product_code".into(), Value::String(product));
    device.insert("revision".into(), Value::String(field("Vr").unwrap_or_default()));
    device.insert("identification".into(), Value::Boolean(false));
    root.insert("device".into(), Value::Table(device));
    let mut limits = Table::new();
    limits.insert("read_registers".into(), Value::Integer(i64::from(limit.clamp(1, 125))));
    root.insert("limits".into(), Value::Table(limits));

    let mut registers = Vec::new();
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
            let mut e = Table::new();
            e.insert("number".into(), Value::Integer(i64::from(m.start) + i64::from(p.offset)));
            e.insert("name".into(), Value::String(format!("{model}.{}", p.name)));
            e.insert("type".into(), Value::String(ty.into()));
            if p.def.kind == PointType::String {
                e.insert("length".into(), Value::Integer(i64::from(p.def.size)));
            }
            if let Some(label) = &p.def.label {
                e.insert("label".into(), Value::String(label.clone()));
            }
            if let Some(desc) = &p.def.desc {
                e.insert("description".into(), Value::String(desc.clone()));
            }
            if let Some(units) = p.def.units.as_ref().filter(|u| !u.is_empty()) {
                e.insert("unit".into(), Value::String(units.clone()));
            }
            let sf = match p.sf {
                Some(SfAt::Fixed(n)) => Some(n),
                Some(SfAt::Offset(at)) => usize::try_from(at)
                    .ok()
                    .and_then(|at| m.registers.get(at))
                    .map(|r| i16::from_ne_bytes(r.to_ne_bytes()))
                    .filter(|sf| (-10..=10).contains(sf))
                    .and_then(|sf| i8::try_from(sf).ok()),
                None => None,
            };
            if let Some(sf) = sf.filter(|sf| *sf != 0) {
                e.insert("scale".into(), Value::Float(10f64.powi(i32::from(sf))));
            }
            e.insert("access".into(), Value::String(if p.def.writable { "rw" } else { "ro" }.into()));
            e.insert("group".into(), Value::String(model.clone()));
            let symbols = |limit: i64| -> Table {
                p.def
                    .symbols
                    .iter()
                    .filter(|(v, _)| (0..limit).contains(v))
                    .map(|(v, n)| (v.to_string(), Value::String(n.clone())))
                    .collect()
            };
            match p.def.kind {
                PointType::Enum16 | PointType::Enum32 if !p.def.symbols.is_empty() => {
                    let max = if p.def.kind == PointType::Enum16 { 0x1_0000 } else { 0x1_0000_0000 };
                    e.insert("values".into(), Value::Table(symbols(max)));
                }
                PointType::Bitfield16 | PointType::Bitfield32 | PointType::Bitfield64 if !p.def.symbols.is_empty() => {
                    e.insert("bits".into(), Value::Table(symbols(i64::from(p.def.size) * 16)));
                }
                _ => {}
            }
            registers.push(Value::Table(e));
        }
    }
    root.insert("registers".into(), Value::Array(registers));
    toml::to_string(&root).unwrap_or_default()
}

/// The profile of `discovery`: [`profile_text`] parsed.
pub fn profile(discovery: &Discovery, defs: &Definitions, origin: &str, limit: u16) -> Result<Profile, ProfileError> {
    Profile::parse(&profile_text(discovery, defs, origin, limit), origin)
}
