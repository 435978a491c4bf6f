//! evcc's configuration: every `source: modbus` block with a `register`, wherever it is in
//! the tree (a meter's `power`, a charger's `maxcurrent`, an element of `currents`, a `calc`
//! operand).
//!
//! A block becomes a point named after the device and the attribute it feeds
//! (`grid.power`, `wallbox.currents_2`): the address and table of its `register` (`holding`,
//! `input`, `coil`; `writesingle` and `writemultiple` are read/write holding registers), the
//! type of its `decode` (or `encoding`), whose `s` suffix (`int32s`, `float32s`) swaps the words
//! (CDAB), and its `scale`. The unit is the one evcc gives the attribute (W for power, kWh for
//! energy, A for currents, ...). The connection (`uri`, `device`, `baudrate`, `comset`, `rtu`,
//! `timeout`, ...), the blocks of other sources, SunSpec and meter-model `value`s, and the
//! blocks of another unit than the one imported are listed as not mapped.
//!
//! A file of several devices (a grid meter and a wallbox, each `id: 1` behind its own `uri`)
//! is one profile per device, a device being an endpoint (`uri` or serial `device`):
//! [`ImportOptions::device`](super::ImportOptions::device) picks one by name or endpoint. A device whose registers are evcc's own — a `template:` (`sdm630`), or a
//! `type: modbus` meter of a built-in `model:` — is named with where its registers are; so is
//! an evcc template definition (`render:`), whose registers are Go template text.

use serde_yaml_ng::{Mapping, Value};

use super::yaml::{self, entries, real, shown, text, unsigned};
use super::{Draft, Entry, ImportError};
use crate::model::{Access, Order, Table, ValueType};

/// Keys of a Modbus block that say how to reach the device, not what to read.
const CONNECTION: &[&str] =
    &["uri", "device", "baudrate", "comset", "rtu", "tcp", "timeout", "connectdelay", "delay", "id"];

/// Keys of a Modbus block that the reader takes.
const TAKEN: &[&str] = &["source", "register", "scale"];

/// Reads the evcc YAML `text` into `draft`.
pub(super) fn read(text: &str, draft: &mut Draft) -> Result<(), ImportError> {
    let root = yaml::parse(text, draft)?;
    let mut blocks = Vec::new();
    let mut others = Vec::new();
    let mut elsewhere = Vec::new();
    walk(&root, "", None, "", &mut blocks, &mut others);
    registers_elsewhere(&root, "", &mut elsewhere);
    if blocks.is_empty() {
        let mut message = "no `source: modbus` block: nothing of an evcc configuration to import".to_string();
        for hint in elsewhere.iter().take(8) {
            message.push_str("; ");
            message.push_str(&hint.sentence());
        }
        if elsewhere.is_empty() {
            message.push_str(
                " (a `type: custom` device's attributes with `source: modbus` and a `register` are imported)",
            );
        }
        return Err(draft.malformed(message));
    }
    for hint in &elsewhere {
        draft.unmapped(&hint.place, hint.field, &hint.value, hint.why());
    }
    let blocks = one_device(blocks, draft)?;
    for (place, source) in others {
        let why = if source == "calc" {
            "arithmetic over other sources: its Modbus operands are imported each on its own, the sum or product is not"
        } else {
            "a source other than Modbus"
        };
        draft.unmapped(&place, "source", &source, why);
    }
    let mut units: Vec<u8> = blocks.iter().map(|b| b.unit).collect();
    units.sort_unstable();
    units.dedup();
    let unit = match draft.options.unit {
        Some(unit) => unit,
        None if units.len() > 1 => return Err(draft.several_units(&units)),
        None => units[0],
    };
    for block in blocks {
        if block.unit != unit {
            let why = format!("a block of unit {}, not of unit {unit} (the one imported): skipped", block.unit);
            draft.unmapped(&block.place, "id", &block.unit.to_string(), &why);
            continue;
        }
        modbus(&block, draft);
    }
    Ok(())
}

/// The blocks of the one device imported — those of one endpoint (`uri` or serial `device`):
/// the one [`ImportOptions::device`] names (by a `name:` of its devices or its endpoint), or
/// the only one; the others' blocks are listed, a block that names no endpoint is kept.
/// Several endpoints and none picked is an error.
///
/// [`ImportOptions::device`]: super::ImportOptions::device
fn one_device<'a>(blocks: Vec<Block<'a>>, draft: &mut Draft) -> Result<Vec<Block<'a>>, ImportError> {
    // Each endpoint, with the names of the devices whose blocks read it.
    let mut endpoints: Vec<(&str, Vec<&str>)> = Vec::new();
    for block in blocks.iter().filter(|b| !b.endpoint.is_empty()) {
        let at = endpoints.iter().position(|(e, _)| *e == block.endpoint).unwrap_or_else(|| {
            endpoints.push((&block.endpoint, Vec::new()));
            endpoints.len() - 1
        });
        if let (Some(name), Some((_, names))) = (block.device.as_deref(), endpoints.get_mut(at))
            && !names.contains(&name)
        {
            names.push(name);
        }
    }
    let label = |(endpoint, names): &(&str, Vec<&str>)| {
        if names.is_empty() { (*endpoint).to_string() } else { format!("{} at {endpoint}", names.join("+")) }
    };
    let Some(wanted) = draft.options.device.clone() else {
        if endpoints.len() > 1 {
            let labels: Vec<String> = endpoints.iter().map(label).collect();
            return Err(draft.several_devices(&labels.iter().map(String::as_str).collect::<Vec<_>>()));
        }
        return Ok(blocks);
    };
    let Some((endpoint, devices)) =
        endpoints.iter().find(|(endpoint, devices)| *endpoint == wanted || devices.contains(&wanted.as_str()))
    else {
        let all: Vec<String> = endpoints.iter().map(|e| super::shown(&label(e))).collect();
        let message = format!("no device named {:?}: the file's devices are {}", super::shown(&wanted), all.join(", "));
        return Err(draft.malformed(message));
    };
    let endpoint = (*endpoint).to_string();
    if draft.options.name.is_none() {
        draft.options.name = Some(if devices.is_empty() { wanted.clone() } else { devices.join("+") });
    }
    let mut kept = Vec::new();
    for block in blocks {
        if block.endpoint == endpoint || block.endpoint.is_empty() {
            kept.push(block);
        } else {
            let device = block.device.clone().unwrap_or_default();
            let why = format!("a block of another device ({}), not the one imported: skipped", block.endpoint);
            draft.unmapped_once(&block.place, "device", &device, &why);
        }
    }
    Ok(kept)
}

/// A device of the file whose registers are not in it.
struct Elsewhere {
    place: String,
    /// The key that says so: `template`, `model` or `render`.
    field: &'static str,
    /// Its value (the template's or the model's name; `render`'s is not shown).
    value: String,
    /// The device's `name:`, if it has one.
    device: Option<String>,
}

impl Elsewhere {
    /// Why its registers are not imported, and where they are.
    fn why(&self) -> &'static str {
        match self.field {
            "template" => {
                "an evcc template: its registers are in evcc's template of that name, not in this file; import \
                 the device's register list (CSV), or a configuration with `source: modbus` blocks"
            }
            "model" => {
                "a `type: modbus` meter: its registers are those of evcc's built-in meter model, not in this file; \
                 import the meter's register list (CSV), or use --device sunspec for a SunSpec meter"
            }
            _ => {
                "an evcc template definition: its registers are Go template text (`{{ .id }}`, ...) that evcc \
                 fills in; import a configuration that uses it, with its `source: modbus` blocks, or the device's \
                 register list (CSV)"
            }
        }
    }

    /// The hint as a sentence of an error.
    fn sentence(&self) -> String {
        let device = self.device.as_deref().map(|d| format!(" ({})", super::shown(d))).unwrap_or_default();
        let value = if self.value.is_empty() { String::new() } else { format!(" {}", super::shown(&self.value)) };
        format!("{}{device} is {}{value}: {}", self.place, self.field, self.why())
    }
}

/// Collects the devices of `value` at `place` whose registers are evcc's own: a `template:`,
/// a `type: modbus` meter's `model:`, a template definition's `render:`.
fn registers_elsewhere(value: &Value, place: &str, out: &mut Vec<Elsewhere>) {
    match value {
        Value::Mapping(map) => {
            let device = map.get("name").and_then(text);
            let kind = map.get("type").and_then(text).map(|t| t.to_ascii_lowercase());
            let found = if map.contains_key("render") && map.contains_key("template") {
                Some(("render", String::new()))
            } else if let Some(template) = map.get("template").and_then(text) {
                Some(("template", template))
            } else if kind.as_deref() == Some("modbus") && !map.contains_key("source") {
                Some(("model", map.get("model").and_then(text).unwrap_or_default()))
            } else {
                None
            };
            if let Some((field, value)) = found {
                let place = if place.is_empty() { "the file".to_string() } else { place.to_string() };
                out.push(Elsewhere { place, field, value, device });
                return;
            }
            for (key, child) in entries(map) {
                let here = if place.is_empty() { key.clone() } else { format!("{place}.{key}") };
                registers_elsewhere(child, &here, out);
            }
        }
        Value::Sequence(list) => {
            for (i, child) in list.iter().enumerate() {
                registers_elsewhere(child, &format!("{place}[{i}]"), out);
            }
        }
        _ => {}
    }
}

/// A `source: modbus` block found in the tree.
struct Block<'a> {
    map: &'a Mapping,
    /// Its YAML path.
    place: String,
    /// The name of the device it belongs to (`name:` of the nearest map above that has one).
    device: Option<String>,
    /// The attribute it feeds, as a path below the device (`power`, `currents[1]`).
    attribute: String,
    unit: u8,
    /// Where the device is: its `uri` (Modbus/TCP) or serial `device`, as written.
    endpoint: String,
}

/// Collects the Modbus blocks of `value` at `place` into `out`, and the places and names of
/// the other sources into `others`; `device` and `below` name where `value` is.
fn walk<'a>(
    value: &'a Value,
    place: &str,
    device: Option<&str>,
    below: &str,
    out: &mut Vec<Block<'a>>,
    others: &mut Vec<(String, String)>,
) {
    match value {
        Value::Mapping(map) => {
            let source = map.get("source").and_then(text);
            if let Some(other) = source.as_deref().filter(|s| *s != "modbus") {
                others.push((place.to_string(), other.to_string()));
            } else if source.is_some() {
                out.push(Block {
                    map,
                    place: place.to_string(),
                    device: device.map(str::to_string),
                    attribute: below.to_string(),
                    unit: map.get("id").and_then(yaml::unit).unwrap_or(1),
                    endpoint: map.get("uri").or_else(|| map.get("device")).and_then(text).unwrap_or_default(),
                });
                return;
            }
            let named = map.get("name").and_then(text);
            let (device, below) = match &named {
                Some(name) => (Some(name.as_str()), ""),
                None => (device, below),
            };
            for (key, child) in entries(map) {
                let here = if place.is_empty() { key.clone() } else { format!("{place}.{key}") };
                let under = if below.is_empty() { key.clone() } else { format!("{below}.{key}") };
                walk(child, &here, device, &under, out, others);
            }
        }
        Value::Sequence(list) => {
            for (i, child) in list.iter().enumerate() {
                let here = format!("{place}[{i}]");
                let under = if below.is_empty() { String::new() } else { format!("{below}[{}]", i + 1) };
                walk(child, &here, device, &under, out, others);
            }
        }
        _ => {}
    }
}

/// The unit evcc gives an attribute's value.
fn unit_of(attribute: &str) -> Option<&'static str> {
    let last = attribute.rsplit('.').next().unwrap_or(attribute);
    let last = last.split('[').next().unwrap_or(last);
    Some(match last {
        "power" | "powers" | "maxpower" => "W",
        "energy" | "capacity" => "kWh",
        "currents" | "current" | "maxcurrent" => "A",
        "maxcurrentmillis" => "mA",
        "voltages" | "voltage" => "V",
        "soc" | "limitsoc" => "%",
        "range" | "odometer" => "km",
        _ => return None,
    })
}

/// The point's code: `device.attribute`, a list's index as `_N`.
fn name_of(block: &Block<'_>) -> String {
    let attribute = block.attribute.replace('[', "_").replace(']', "");
    match (&block.device, attribute.is_empty()) {
        (Some(device), false) => format!("{device}.{attribute}"),
        (Some(device), true) => device.clone(),
        (None, false) => attribute,
        (None, true) => block.place.replace('[', "_").replace(']', ""),
    }
}

/// One Modbus block.
fn modbus(block: &Block<'_>, draft: &mut Draft) {
    let (map, place) = (block.map, block.place.as_str());
    let Some(register) = map.get("register").and_then(Value::as_mapping) else {
        let why = if map.contains_key("value") {
            "a value of a predefined meter model or of a SunSpec model, not a register: import the device's \
             map, or use --device sunspec"
        } else {
            "no register: nothing to import"
        };
        let value = map.get("value").map(shown).unwrap_or_default();
        draft.unmapped(place, "value", &value, why);
        rest(map, &["value", "model"], place, draft);
        return;
    };
    let here = format!("{place}.register");
    let Some(address) = register.get("address").and_then(unsigned).and_then(|a| u16::try_from(a).ok()) else {
        let value = register.get("address").map(shown).unwrap_or_default();
        draft.unmapped(&here, "address", &value, "no address of 0-65535: skipped");
        return;
    };
    let kind = register.get("type").and_then(text).unwrap_or_else(|| "holding".to_string());
    let (table, access) = match kind.to_ascii_lowercase().as_str() {
        "holding" => (Table::Holding, Access::Ro),
        "input" => (Table::Input, Access::Ro),
        "coil" | "coils" => (Table::Coils, Access::Ro),
        "writesingle" | "writemultiple" | "writeholding" => (Table::Holding, Access::Rw),
        "writecoil" => (Table::Coils, Access::Rw),
        _ => {
            draft.unmapped(&here, "type", &kind, "not a register type (holding, input, coil, writesingle): skipped");
            return;
        }
    };
    let mut entry = Entry::new(table, address, &name_of(block), place.to_string());
    entry.access = access;
    let decode_key = if register.contains_key("decode") { "decode" } else { "encoding" };
    if !table.is_bits() {
        let decode = register.get(decode_key).and_then(text).unwrap_or_else(|| "uint16".to_string());
        let Some((value_type, swapped)) = decode_of(&decode) else {
            let why = "not a decoding of a profile type (int16|32|64, uint16|32|64, float32|64, int32s, uint32s, \
                       float32s): skipped";
            draft.unmapped(&here, decode_key, &decode, why);
            return;
        };
        if decode.ends_with("nan") {
            let why = "evcc reads the largest value as \"no value\"; the profile reads it as a number";
            draft.unmapped(&here, decode_key, &decode, why);
        }
        entry.value_type = value_type;
        entry.order = swapped.then_some(Order::Cdab);
        entry.unit = unit_of(&block.attribute).map(str::to_string);
    }
    if let Some(scale) = map.get("scale") {
        match real(scale) {
            Some(s) if !super::is(s, 0.0) => entry.scale = Some(s).filter(|s| !super::is(*s, 1.0)),
            _ => draft.unmapped(place, "scale", &shown(scale), "not a scale: left 1"),
        }
    }
    let known = ["address", "type", "decode", "encoding"];
    yaml::rest(register, &known, &here, &|_| "no profile equivalent".to_string(), draft);
    rest(map, &[], place, draft);
    draft.add(entry);
}

/// Lists the keys of a Modbus block the reader does not take.
fn rest(map: &Mapping, also: &[&str], place: &str, draft: &mut Draft) {
    let known: Vec<&str> = TAKEN.iter().chain(also).copied().collect();
    for (key, value) in entries(map) {
        if known.contains(&key.as_str()) {
            continue;
        }
        if CONNECTION.contains(&key.as_str()) {
            let why = "a connection setting, not part of the map: give it to ferrobus (--tcp HOST:PORT, --unit N, ...)";
            draft.unmapped_once(place, &key, &shown(value), why);
        } else {
            draft.unmapped(place, &key, &shown(value), "no profile equivalent");
        }
    }
}

/// A decoding's type, and whether its words are swapped.
fn decode_of(decode: &str) -> Option<(ValueType, bool)> {
    let decode = decode.trim().to_ascii_lowercase();
    let decode = decode.strip_suffix("nan").unwrap_or(&decode);
    let (name, swapped) = match decode.strip_suffix('s') {
        Some(name) if name.ends_with("32") => (name, true),
        _ => (decode, false),
    };
    let value_type = match name {
        "int16" => ValueType::I16,
        "uint16" => ValueType::U16,
        "int32" => ValueType::I32,
        "uint32" => ValueType::U32,
        "int64" => ValueType::I64,
        "uint64" => ValueType::U64,
        "float32" => ValueType::F32,
        "float64" => ValueType::F64,
        _ => return None,
    };
    Some((value_type, swapped))
}
