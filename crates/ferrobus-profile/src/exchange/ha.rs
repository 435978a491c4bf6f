//! Home Assistant's `modbus:` configuration: hubs, each with sensors, binary sensors,
//! switches, lights, fans, climates and covers.
//!
//! The file may be a whole `configuration.yaml` (the `modbus:` key is read, the rest of the
//! file is not a map and is left alone), the list a `modbus: !include modbus.yaml` names, or
//! one hub. Each entity becomes a point named after it:
//!
//! | Home Assistant | profile |
//! |---|---|
//! | `sensors` (`input_type` holding, input) | a read-only register of `data_type`, `count`, `swap`, `scale`, `offset`, `unit_of_measurement` |
//! | `binary_sensors` (`input_type` coil, discrete_input, holding, input) | a read-only coil, discrete input or register |
//! | `switches`, `lights`, `fans` (`write_type` holding, coil) | a read/write register (`command_on`, `command_off` as its values) or coil; a `verify` elsewhere is a second, read-only point `NAME_state` |
//! | `climates` | `NAME_current` at `address`, `NAME_target` (read/write, `min_temp`/`max_temp` as its raw range) at `target_temp_register` |
//! | `covers` | a read/write register or coil with the `state_*` values; `status_register` is `NAME_status` |
//!
//! `swap`: none is ABCD, word CDAB, byte BADC, word_byte DCBA; a 16-bit value's byte swap has
//! no profile equivalent and is listed. Display and polling settings (`precision`,
//! `device_class`, `scan_interval`, ...), the hub's connection settings, and entities of
//! another unit than the one imported are listed as not mapped.

use serde_yaml_ng::{Mapping, Value};

use super::yaml::{self, entries, items, real, shown, text, unsigned};
use super::{Draft, Entry, ImportError, order_of};
use crate::model::{Access, Order, Table, ValueType};

/// Keys of a hub that say how to reach it, not what it holds.
const CONNECTION: &[&str] = &[
    "name",
    "type",
    "host",
    "port",
    "method",
    "baudrate",
    "bytesize",
    "parity",
    "stopbits",
    "delay",
    "timeout",
    "message_wait_milliseconds",
    "close_comm_on_error",
    "retries",
    "retry_on_empty",
    "handle_local_echo",
];

/// Keys every entity may have that say how Home Assistant shows or polls it.
const DISPLAY: &[&str] = &[
    "device_class",
    "state_class",
    "unique_id",
    "scan_interval",
    "lazy_error_count",
    "precision",
    "icon",
    "entity_category",
    "friendly_name",
];

/// The platforms of a hub.
const PLATFORMS: &[&str] = &["sensors", "binary_sensors", "switches", "lights", "fans", "climates", "covers"];

/// Reads the Home Assistant YAML `text` into `draft`.
pub(super) fn read(text: &str, draft: &mut Draft) -> Result<(), ImportError> {
    let root = yaml::parse(text, draft)?;
    let hubs = hubs(&root).ok_or_else(|| {
        draft.malformed("no Home Assistant modbus configuration: want a `modbus:` key, a list of hubs, or a hub with sensors, switches, ...")
    })?;
    let mut units: Vec<u8> = Vec::new();
    for (_, hub) in &hubs {
        if let Value::Mapping(map) = hub {
            for platform in PLATFORMS {
                for entity in
                    map.get(*platform).map(items).unwrap_or_default().into_iter().filter_map(Value::as_mapping)
                {
                    let Some(unit) = entity_unit(entity) else { continue };
                    if !units.contains(&unit) {
                        units.push(unit);
                    }
                }
            }
        }
    }
    units.sort_unstable();
    let unit = match draft.options.unit {
        Some(unit) => unit,
        None if units.len() > 1 => return Err(draft.several_units(&units)),
        None => units.first().copied().unwrap_or(0),
    };
    for (place, hub) in hubs {
        let Value::Mapping(map) = hub else {
            draft.unmapped(&place, "hub", &shown(hub), "a hub is a map of settings and entities: skipped");
            continue;
        };
        let at =
            |key: &str, i: usize| if place.is_empty() { format!("{key}[{i}]") } else { format!("{place}.{key}[{i}]") };
        for (key, value) in entries(map) {
            let platform = key.as_str();
            if PLATFORMS.contains(&platform) {
                for (i, entity) in items(value).into_iter().enumerate() {
                    let here = at(platform, i);
                    let Value::Mapping(entity) = entity else {
                        draft.unmapped(&here, platform, &shown(entity), "an entity is a map: skipped");
                        continue;
                    };
                    match entity_unit(entity) {
                        Some(of) if of != unit => {
                            let why = format!("an entity of unit {of}, not of unit {unit} (the one imported): skipped");
                            draft.unmapped(&here, "slave", &of.to_string(), &why);
                            continue;
                        }
                        Some(_) => {}
                        None => {
                            let (field, value) = written_unit(entity);
                            // An unresolved `!secret` was listed, naming it, when it was read.
                            if !yaml::unresolved(value) {
                                let why = format!("not a unit (0-255): imported with the entities of unit {unit}");
                                draft.unmapped(&here, field, &shown(value), &why);
                            }
                        }
                    }
                    entity_of(platform, entity, &here, draft);
                }
            } else if CONNECTION.contains(&platform) {
                let why = "a connection setting of the hub, not part of the map: give it to ferrobus \
                           (--tcp HOST:PORT, --port PATH, --baud, ...)";
                draft.unmapped_once(if place.is_empty() { "hub" } else { &place }, platform, &shown(value), why);
            } else {
                let why = "not a key of a Home Assistant modbus hub";
                draft.unmapped(if place.is_empty() { "hub" } else { &place }, platform, &shown(value), why);
            }
        }
    }
    Ok(())
}

/// The hubs of the file, each with its place.
fn hubs(root: &Value) -> Option<Vec<(String, &Value)>> {
    fn numbered<'a>(prefix: &str, list: &'a Value) -> Vec<(String, &'a Value)> {
        items(list).into_iter().enumerate().map(|(i, hub)| (format!("{prefix}[{i}]"), hub)).collect()
    }
    match root {
        Value::Mapping(map) => {
            if let Some(modbus) = map.get("modbus") {
                return Some(numbered("modbus", modbus));
            }
            PLATFORMS.iter().any(|p| map.contains_key(*p)).then(|| vec![(String::new(), root)])
        }
        Value::Sequence(list) => {
            let hub_like = |v: &Value| v.as_mapping().is_some_and(|m| PLATFORMS.iter().any(|p| m.contains_key(*p)));
            list.iter().any(hub_like).then(|| numbered("", root))
        }
        _ => None,
    }
}

/// An entity's unit: `slave` or `device_address`, 0 when neither is given (Home Assistant's
/// default); `None` when it is written but is no unit (an unresolved `!secret`, text): never
/// a silent 0.
fn entity_unit(entity: &Mapping) -> Option<u8> {
    match entity.get("slave").or_else(|| entity.get("device_address")) {
        None => Some(0),
        Some(value) => yaml::unit(value),
    }
}

/// The key and value an entity's unit is written with (`slave` first).
fn written_unit(entity: &Mapping) -> (&'static str, &Value) {
    match entity.get("slave") {
        Some(value) => ("slave", value),
        None => ("device_address", entity.get("device_address").unwrap_or(&Value::Null)),
    }
}

/// One entity of `platform` at `place`.
fn entity_of(platform: &str, m: &Mapping, place: &str, draft: &mut Draft) {
    let Some(name) = m.get("name").and_then(text).filter(|n| !n.is_empty()) else {
        draft.unmapped(place, "name", "", "an entity without a name: skipped");
        return;
    };
    let Some(address) = address(m, "address", place, draft) else {
        return;
    };
    match platform {
        "sensors" => sensor(m, &name, address, place, draft),
        "binary_sensors" => binary_sensor(m, &name, address, place, draft),
        "switches" | "lights" | "fans" => switch(m, &name, address, place, draft),
        "climates" => climate(m, &name, address, place, draft),
        _ => cover(m, &name, address, place, draft),
    }
}

/// The address under `key`, or `None` with the entity listed.
fn address(m: &Mapping, key: &str, place: &str, draft: &mut Draft) -> Option<u16> {
    match m.get(key) {
        None => {
            draft.unmapped(place, key, "", "no address: skipped");
            None
        }
        Some(value) => {
            let address = unsigned(value).and_then(|a| u16::try_from(a).ok());
            if address.is_none() {
                draft.unmapped(place, key, &shown(value), "not an address (0-65535): skipped");
            }
            address
        }
    }
}

/// The keys every entity has that the profile takes or the reader lists itself.
const COMMON: &[&str] = &["name", "slave", "device_address", "address"];

/// Lists the rest of `m` (not in `COMMON`, `known`), display settings with their own reason.
fn rest(m: &Mapping, known: &[&str], place: &str, draft: &mut Draft) {
    let all: Vec<&str> = COMMON.iter().chain(known).copied().collect();
    let why = |key: &str| {
        if DISPLAY.contains(&key) {
            "how Home Assistant shows or polls it: a profile has no such setting".to_string()
        } else {
            "no profile equivalent".to_string()
        }
    };
    yaml::rest(m, &all, place, &why, draft);
}

/// The keys of a sensor or climate that say what its registers hold.
const VALUE_KEYS: &[&str] = &["data_type", "count", "swap", "reverse_order", "scale", "offset", "unit_of_measurement"];

/// Sets `entry`'s type, length, order, scale, offset and unit from [`VALUE_KEYS`] of `m`;
/// `false` (the entity listed) when its type has no profile equivalent.
fn value_of(m: &Mapping, entry: &mut Entry, place: &str, draft: &mut Draft) -> bool {
    let count = match m.get("count") {
        None => None,
        Some(value) => {
            let count = unsigned(value).and_then(|c| u16::try_from(c).ok()).filter(|c| *c > 0);
            if count.is_none() {
                draft.unmapped(place, "count", &shown(value), "not a number of registers: skipped");
                return false;
            }
            count
        }
    };
    let data_type = m.get("data_type").and_then(text).unwrap_or_else(|| "int16".to_string());
    let by_count = |signed: ValueType, two: ValueType, four: ValueType| match count.unwrap_or(1) {
        1 => Some(signed),
        2 => Some(two),
        4 => Some(four),
        _ => None,
    };
    let value_type = match data_type.as_str() {
        "int16" => Some(ValueType::I16),
        "uint16" => Some(ValueType::U16),
        "int32" => Some(ValueType::I32),
        "uint32" => Some(ValueType::U32),
        "int64" => Some(ValueType::I64),
        "uint64" => Some(ValueType::U64),
        "float32" => Some(ValueType::F32),
        "float64" => Some(ValueType::F64),
        "string" => Some(ValueType::String),
        // The old names take their width from `count`.
        "int" => by_count(ValueType::I16, ValueType::I32, ValueType::I64),
        "uint" => by_count(ValueType::U16, ValueType::U32, ValueType::U64),
        "float" => match count.unwrap_or(2) {
            2 => Some(ValueType::F32),
            4 => Some(ValueType::F64),
            _ => None,
        },
        _ => None,
    };
    let Some(value_type) = value_type else {
        let why = match data_type.as_str() {
            "float16" => "a half-precision float has no profile type: skipped".to_string(),
            "custom" => "a custom structure (a struct format) has no profile equivalent: skipped".to_string(),
            _ => format!(
                "not a Home Assistant data type{}: skipped",
                count.map(|c| format!(" of {c} registers")).unwrap_or_default()
            ),
        };
        draft.unmapped(place, "data_type", &data_type, &why);
        return false;
    };
    entry.value_type = value_type;
    if value_type == ValueType::String {
        entry.length = Some(count.unwrap_or(1));
    } else if let Some(count) = count.filter(|c| *c != value_type.registers())
        && !matches!(data_type.as_str(), "int" | "uint" | "float")
    {
        let why = format!("{data_type} takes {} registers: read as one {data_type}", value_type.registers());
        draft.unmapped(place, "count", &count.to_string(), &why);
    }
    let reverse = m.get("reverse_order").and_then(Value::as_bool).unwrap_or(false);
    let swap = m.get("swap").and_then(text).unwrap_or_else(|| "none".to_string());
    let (words, bytes) = match swap.as_str() {
        "none" => (false, false),
        "word" => (true, false),
        "byte" => (false, true),
        "word_byte" => (true, true),
        other => {
            draft.unmapped(place, "swap", other, "not a swap (none, byte, word, word_byte): read unswapped");
            (false, false)
        }
    };
    let words = words || reverse;
    if value_type.registers() > 1 && value_type != ValueType::String {
        entry.order = Some(order_of(words, bytes)).filter(|o| *o != Order::Abcd);
    } else if words || bytes {
        let why = if value_type == ValueType::String {
            "a string's bytes are read in the order they come: no swap"
        } else {
            "a 16-bit value's bytes are read high first: a profile has no byte swap of one register"
        };
        draft.unmapped(place, "swap", &swap, why);
    }
    for (key, field) in [("scale", &mut entry.scale), ("offset", &mut entry.offset)] {
        if let Some(value) = m.get(key) {
            match real(value) {
                Some(v) => *field = Some(v),
                None => draft.unmapped(place, key, &shown(value), "not a number"),
            }
        }
    }
    entry.scale = entry.scale.filter(|s| !super::is(*s, 1.0) && !super::is(*s, 0.0));
    entry.offset = entry.offset.filter(|o| !super::is(*o, 0.0));
    entry.unit = m.get("unit_of_measurement").and_then(text).filter(|u| !u.is_empty());
    true
}

/// The `input_type`s of a sensor and a climate's current temperature, the default first.
const REGISTERS: &[(&str, Table)] = &[("holding", Table::Holding), ("input", Table::Input)];

/// The `input_type`s of a binary sensor, the default first.
const BINARY: &[(&str, Table)] = &[
    ("coil", Table::Coils),
    ("discrete_input", Table::DiscreteInputs),
    ("holding", Table::Holding),
    ("input", Table::Input),
];

/// The table `m`'s `input_type` names among `known` (the first when it names none); `None`,
/// with the entity listed for `why`, when it names another.
fn input_table(m: &Mapping, known: &[(&str, Table)], place: &str, why: &str, draft: &mut Draft) -> Option<Table> {
    let Some(given) = m.get("input_type").and_then(text) else {
        return known.first().map(|(_, table)| *table);
    };
    let table = known.iter().find(|(name, _)| *name == given).map(|(_, table)| *table);
    if table.is_none() {
        draft.unmapped(place, "input_type", &given, why);
    }
    table
}

/// A sensor: a read-only holding or input register.
fn sensor(m: &Mapping, name: &str, address: u16, place: &str, draft: &mut Draft) {
    let why = "a sensor reads holding or input registers: skipped";
    let Some(table) = input_table(m, REGISTERS, place, why, draft) else {
        return;
    };
    let mut entry = Entry::new(table, address, name, place.to_string());
    if !value_of(m, &mut entry, place, draft) {
        return;
    }
    let mut known = VALUE_KEYS.to_vec();
    known.push("input_type");
    for key in ["min_value", "max_value"] {
        if let Some(value) = m.get(key) {
            let why = "Home Assistant clamps what it shows; a profile's min and max bound what may be written";
            draft.unmapped(place, key, &shown(value), why);
            known.push(key);
        }
    }
    for key in ["slave_count", "virtual_count"] {
        if let Some(value) = m.get(key) {
            let why = "more sensors at the addresses that follow, named by Home Assistant: not imported";
            draft.unmapped(place, key, &shown(value), why);
            known.push(key);
        }
    }
    rest(m, &known, place, draft);
    draft.add(entry);
}

/// A binary sensor: a read-only coil, discrete input or register.
fn binary_sensor(m: &Mapping, name: &str, address: u16, place: &str, draft: &mut Draft) {
    let why = "not an input type (coil, discrete_input, holding, input): skipped";
    let Some(table) = input_table(m, BINARY, place, why, draft) else {
        return;
    };
    let mut entry = Entry::new(table, address, name, place.to_string());
    if !table.is_bits() {
        entry.description = "on when not 0 (a Home Assistant binary sensor)".to_string();
    }
    for key in ["slave_count", "virtual_count"] {
        if let Some(value) = m.get(key) {
            let why = "more binary sensors at the addresses that follow, named by Home Assistant: not imported";
            draft.unmapped(place, key, &shown(value), why);
        }
    }
    rest(m, &["input_type", "slave_count", "virtual_count"], place, draft);
    draft.add(entry);
}

/// `entry`, a second point of one entity: its code gets `_WHAT`, its label `, WHAT`.
fn suffixed(mut entry: Entry, what: &str) -> Entry {
    entry.name = format!("{}_{what}", entry.name);
    entry.label = entry.label.map(|label| format!("{label}, {what}"));
    entry
}

/// The table a `write_type` (switch, light, fan) or a cover's `input_type` names.
fn written_table(value: Option<&Value>) -> Option<Table> {
    match value.and_then(text).as_deref() {
        None | Some("holding" | "holdings") => Some(Table::Holding),
        Some("coil" | "coils") => Some(Table::Coils),
        _ => None,
    }
}

/// A raw value key (`command_on`, `state_open`, ...) of `m`, or `default`.
fn raw(m: &Mapping, key: &str, default: u64, place: &str, draft: &mut Draft) -> u64 {
    match m.get(key) {
        None => default,
        Some(value) => unsigned(value).unwrap_or_else(|| {
            draft.unmapped(place, key, &shown(value), &format!("not a register value: {default} is used"));
            default
        }),
    }
}

/// A switch, light or fan: a read/write register or coil, and its verify point.
fn switch(m: &Mapping, name: &str, address: u16, place: &str, draft: &mut Draft) {
    let Some(table) = written_table(m.get("write_type")) else {
        let shown_type = m.get("write_type").map(shown).unwrap_or_default();
        draft.unmapped(place, "write_type", &shown_type, "not a write type (holding, coil): skipped");
        return;
    };
    let mut entry = Entry::new(table, address, name, place.to_string());
    entry.access = Access::Rw;
    let mut known = vec!["write_type", "verify"];
    if table == Table::Holding {
        let on = raw(m, "command_on", 1, place, draft);
        let off = raw(m, "command_off", 0, place, draft);
        entry.values = vec![(off.to_string(), "off".to_string()), (on.to_string(), "on".to_string())];
        entry.values.dedup_by(|a, b| a.0 == b.0);
        known.extend(["command_on", "command_off"]);
    }
    let verify = m.get("verify").and_then(Value::as_mapping).cloned();
    draft.add(entry);
    rest(m, &known, place, draft);
    let Some(verify) = verify else {
        return;
    };
    let here = format!("{place}.verify");
    let state_address = match verify.get("address") {
        None => address,
        Some(value) => {
            let Some(a) = unsigned(value).and_then(|a| u16::try_from(a).ok()) else {
                draft.unmapped(&here, "address", &shown(value), "not an address: the state is not imported");
                return;
            };
            a
        }
    };
    let state_table = match verify.get("input_type").and_then(text).as_deref() {
        None => table,
        Some("coil") => Table::Coils,
        Some("discrete" | "discrete_input") => Table::DiscreteInputs,
        Some("holding") => Table::Holding,
        Some("input") => Table::Input,
        Some(other) => {
            draft.unmapped(&here, "input_type", other, "not an input type: the state is not imported");
            return;
        }
    };
    let mut known = vec!["address", "input_type", "state_on", "state_off"];
    if (state_table, state_address) == (table, address) {
        known.retain(|k| !k.starts_with("state_"));
    } else {
        let mut state = suffixed(Entry::new(state_table, state_address, name, here.clone()), "state");
        if !state_table.is_bits() {
            let on = raw(&verify, "state_on", 1, &here, draft);
            let off = raw(&verify, "state_off", 0, &here, draft);
            state.values = vec![(off.to_string(), "off".to_string()), (on.to_string(), "on".to_string())];
            state.values.dedup_by(|a, b| a.0 == b.0);
        }
        draft.add(state);
    }
    known.push("delay");
    if let Some(delay) = verify.get("delay") {
        draft.unmapped(
            &here,
            "delay",
            &shown(delay),
            "how long Home Assistant waits before it verifies: no profile equivalent",
        );
    }
    yaml::rest(&verify, &known, &here, &|_| "no profile equivalent".to_string(), draft);
}

/// A climate: its current temperature and its target.
fn climate(m: &Mapping, name: &str, address: u16, place: &str, draft: &mut Draft) {
    let why = "the current temperature is a holding or input register: skipped";
    let Some(table) = input_table(m, REGISTERS, place, why, draft) else {
        return;
    };
    let mut current = Entry::new(table, address, name, place.to_string());
    if !value_of(m, &mut current, place, draft) {
        return;
    }
    let unit = match m.get("temperature_unit").and_then(text).as_deref() {
        Some("F") => "°F",
        Some("K") => "K",
        _ => "°C",
    };
    current.unit = Some(current.unit.clone().unwrap_or_else(|| unit.to_string()));
    let mut known = VALUE_KEYS.to_vec();
    known.extend(["input_type", "temperature_unit", "target_temp_register", "min_temp", "max_temp"]);
    let target = match m.get("target_temp_register") {
        Some(Value::Sequence(list)) => {
            let why = "a target register per HVAC mode: the first is imported as NAME_target";
            draft.unmapped(place, "target_temp_register", &format!("a list of {}", list.len()), why);
            list.first().and_then(unsigned)
        }
        Some(value) => unsigned(value),
        None => None,
    };
    let mut entries = vec![suffixed(current.clone(), "current")];
    if let Some(target) = target.and_then(|t| u16::try_from(t).ok()) {
        let entry = Entry { table: Table::Holding, address: target, access: Access::Rw, ..current };
        let mut entry = suffixed(entry, "target");
        // Home Assistant's limits are temperatures; a profile's are raw values.
        let scale = entry.scale.unwrap_or(1.0);
        let offset = entry.offset.unwrap_or(0.0);
        for (key, field) in [("min_temp", &mut entry.min), ("max_temp", &mut entry.max)] {
            if let Some(value) = m.get(key).and_then(real) {
                let raw = (value - offset) / scale;
                if raw.is_finite() {
                    *field = Some(raw);
                } else {
                    draft.unmapped(
                        place,
                        key,
                        &value.to_string(),
                        "no raw value of the register gives it at this scale",
                    );
                }
            }
        }
        if let (Some(min), Some(max)) = (entry.min, entry.max)
            && min > max
        {
            entry.min = Some(max);
            entry.max = Some(min);
        }
        entries.push(entry);
    }
    for entry in entries {
        draft.add(entry);
    }
    rest(m, &known, place, draft);
}

/// A cover: its register or coil, and its status register.
fn cover(m: &Mapping, name: &str, address: u16, place: &str, draft: &mut Draft) {
    let Some(table) = written_table(m.get("input_type")) else {
        let shown_type = m.get("input_type").map(shown).unwrap_or_default();
        draft.unmapped(place, "input_type", &shown_type, "a cover is a holding register or a coil: skipped");
        return;
    };
    let mut entry = Entry::new(table, address, name, place.to_string());
    entry.access = Access::Rw;
    let mut values = Vec::new();
    if table == Table::Holding {
        for (key, default, meaning) in [
            ("state_closed", 0, "closed"),
            ("state_open", 1, "open"),
            ("state_opening", 2, "opening"),
            ("state_closing", 3, "closing"),
        ] {
            let raw = raw(m, key, default, place, draft);
            if !values.iter().any(|(k, _): &(String, String)| *k == raw.to_string()) {
                values.push((raw.to_string(), meaning.to_string()));
            }
        }
        entry.values.clone_from(&values);
    }
    draft.add(entry);
    if let Some(status) = m.get("status_register") {
        match unsigned(status).and_then(|a| u16::try_from(a).ok()) {
            Some(status) => {
                let status_table = match m.get("status_register_type").and_then(text).as_deref() {
                    Some("input") => Table::Input,
                    _ => Table::Holding,
                };
                let mut entry = suffixed(Entry::new(status_table, status, name, place.to_string()), "status");
                entry.values = values;
                draft.add(entry);
            }
            None => draft.unmapped(place, "status_register", &shown(status), "not an address"),
        }
    }
    let known = [
        "input_type",
        "state_closed",
        "state_open",
        "state_opening",
        "state_closing",
        "status_register",
        "status_register_type",
    ];
    rest(m, &known, place, draft);
}
