//! Home Assistant MQTT discovery for plain mode (`[plain] discovery = true`): at each
//! connection, one retained config per published point, so that Home Assistant makes an
//! entity of it, grouped by device, available while the bridge and the device are.
//!
//! ```text
//!   DISCOVERY/sensor/NODE/OBJECT/config         a read-only register (its unit, device class, measurement)
//!   DISCOVERY/binary_sensor/NODE/OBJECT/config  a read-only bit
//!   DISCOVERY/number/NODE/OBJECT/config         a writable register: min, max and step in engineering units
//!   DISCOVERY/select/NODE/OBJECT/config         a writable enumeration: its meanings as the options
//!   DISCOVERY/switch/NODE/OBJECT/config         a writable coil: "on" / "off"
//! ```
//!
//! NODE is `PREFIX/DEVICE` and OBJECT the point's name, each with every character outside
//! `[a-zA-Z0-9_-]` (HA's rule) as `_` and, when one was, a hash of the original after it: the
//! same names give the same topics and `unique_id`s at every start. The state is the point's
//! plain topic (`value_template` takes `value`, an enumeration's `meaning`); a command goes to
//! its existing `.../set`, checked by the profile there (a select sends the meaning, a switch
//! `on`/`off`, a number the value); availability is `PREFIX/status` and `PREFIX/DEVICE/status`,
//! both `online` (`availability_mode: all`). Configs stay retained at the broker: a point
//! removed from the plant (or discovery turned off) leaves its config there until an empty
//! retained message is published on its topic.

use ferrobus_profile::{Point, Profile, Value, ValueType};
use ferrobus_tools::poll::Cell;
use serde_json::{Map, json};

use super::Publish;
use crate::config::{DeviceSpec, PlainConfig, Plant};

/// A sensor's device classes by unit: only units HA's sensor documentation lists for the class
/// (integrations/sensor/#device-class); a unit not here gets no device class.
const SENSOR_CLASSES: &[(&str, &[&str])] = &[
    ("apparent_power", &["mVA", "VA"]),
    ("current", &["A", "mA"]),
    ("duration", &["d", "h", "min", "s", "ms", "µs"]),
    ("energy", &["J", "kJ", "MJ", "GJ", "mWh", "Wh", "kWh", "MWh", "GWh", "TWh"]),
    ("frequency", &["Hz", "kHz", "MHz", "GHz"]),
    ("power", &["mW", "W", "kW", "MW", "GW", "TW"]),
    ("pressure", &["Pa", "kPa", "hPa", "bar", "cbar", "mbar", "mmHg", "inHg", "psi"]),
    ("reactive_power", &["var", "kvar"]),
    ("temperature", &["°C", "°F", "K"]),
    ("voltage", &["V", "mV", "µV", "kV", "MV"]),
];

/// A number's device classes by unit (integrations/number/#device-class).
const NUMBER_CLASSES: &[(&str, &[&str])] = &[
    ("apparent_power", &["VA"]),
    ("current", &["A", "mA"]),
    ("energy", &["Wh", "kWh", "MWh", "MJ", "GJ"]),
    ("frequency", &["Hz", "kHz", "MHz", "GHz"]),
    ("power", &["W", "kW"]),
    ("pressure", &["Pa", "kPa", "hPa", "bar", "cbar", "mbar", "mmHg", "inHg", "psi"]),
    ("reactive_power", &["var"]),
    ("temperature", &["°C", "°F", "K"]),
    ("voltage", &["V", "mV"]),
];

/// A bit's state for HA: `on`, `off`, or `None` (unknown) when the read failed.
const BIT_STATE: &str = "{% if value_json.value is none %}None{% elif value_json.value %}on{% else %}off{% endif %}";

/// The smallest step HA's number takes.
const MIN_STEP: f64 = 0.001;

/// The HA component a point becomes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Component {
    Sensor,
    BinarySensor,
    Number,
    Select,
    Switch,
}

impl Component {
    /// Read-only register → sensor, read-only bit → binary_sensor; writable: coil → switch,
    /// enumeration → select, other numbers → number (a writable text stays a sensor).
    pub(crate) fn of(point: &Point) -> Component {
        let bit = point.value_type == ValueType::Bit;
        match (point.writable() && point.value_type != ValueType::String, bit) {
            (false, true) => Component::BinarySensor,
            (false, false) => Component::Sensor,
            (true, true) => Component::Switch,
            (true, false) if !point.values.is_empty() => Component::Select,
            (true, false) => Component::Number,
        }
    }

    /// Its name in topics and HA's documentation.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Component::Sensor => "sensor",
            Component::BinarySensor => "binary_sensor",
            Component::Number => "number",
            Component::Select => "select",
            Component::Switch => "switch",
        }
    }
}

/// The retained config of every point of every device of `plant`, each once, under
/// `discovery_prefix`.
pub(crate) fn configs(plant: &Plant, config: &PlainConfig, discovery_prefix: &str) -> Vec<Publish> {
    let mut out = Vec::new();
    for (_, device) in plant.devices() {
        let mut seen: Vec<&str> = Vec::new();
        for cell in device.groups.iter().flat_map(|g| &g.cells) {
            if seen.contains(&cell.name.as_str()) {
                continue;
            }
            seen.push(&cell.name);
            let (topic, payload) = entity(config, discovery_prefix, device, cell);
            out.push(Publish { topic, payload: payload.to_string().into_bytes(), qos: 1, retain: true });
        }
    }
    out
}

/// The config topic and payload of `cell` of `device`.
pub(crate) fn entity(
    config: &PlainConfig,
    discovery_prefix: &str,
    device: &DeviceSpec,
    cell: &Cell,
) -> (String, serde_json::Value) {
    let point = &cell.point;
    let component = Component::of(point);
    let prefix = &config.prefix;
    let node = id(&format!("{prefix}/{}", device.id));
    let object = id(&cell.name);
    let state_topic = format!("{prefix}/{}/{}", device.id, cell.name);
    let mut fields = Map::new();
    let name = if point.label.is_empty() { &cell.name } else { &point.label };
    fields.insert("name".into(), json!(name));
    fields.insert("unique_id".into(), json!(format!("ferrobus_{node}_{object}")));
    let entity_id = entity_slug(&format!("{prefix}_{}_{}", device.id, cell.name));
    fields.insert("default_entity_id".into(), json!(format!("{}.{entity_id}", component.name())));
    fields.insert("state_topic".into(), json!(state_topic));
    fields.insert("availability".into(), availability(prefix, &device.id));
    fields.insert("availability_mode".into(), json!("all"));
    fields.insert("qos".into(), json!(config.qos));
    fields.insert("device".into(), device_block(&node, &device.id, device.profile.as_deref()));
    fields.insert("origin".into(), origin());
    if component != Component::Sensor && component != Component::BinarySensor {
        fields.insert("command_topic".into(), json!(format!("{state_topic}/set")));
    }
    match component {
        Component::Sensor => sensor(&mut fields, point),
        Component::BinarySensor | Component::Switch => {
            fields.insert("value_template".into(), json!(BIT_STATE));
            fields.insert("payload_on".into(), json!("on"));
            fields.insert("payload_off".into(), json!("off"));
        }
        Component::Number => number(&mut fields, point),
        Component::Select => {
            let mut options: Vec<&str> = Vec::new();
            for (_, meaning) in &point.values {
                if !options.contains(&meaning.as_str()) {
                    options.push(meaning);
                }
            }
            fields.insert("options".into(), json!(options));
            fields.insert("value_template".into(), json!("{{ value_json.meaning | default(None) }}"));
        }
    }
    let topic = format!("{discovery_prefix}/{}/{node}/{object}/config", component.name());
    (topic, serde_json::Value::Object(fields))
}

/// A sensor: a number with its unit, device class and `measurement` (energy: a meter,
/// `total_increasing`); an enumeration's or bit field's meaning; a text as it is.
fn sensor(fields: &mut Map<String, serde_json::Value>, point: &Point) {
    if !point.values.is_empty() || !point.bits.is_empty() {
        fields.insert("value_template".into(), json!("{{ value_json.meaning | default(None) }}"));
        return;
    }
    fields.insert("value_template".into(), json!("{{ value_json.value }}"));
    if point.value_type == ValueType::String {
        return;
    }
    let class = unit(fields, point, SENSOR_CLASSES);
    let state_class = if class == Some("energy") { "total_increasing" } else { "measurement" };
    fields.insert("state_class".into(), json!(state_class));
}

/// A number: the range the profile lets a write set (the type's when it gives none), in
/// engineering units, its resolution as the step, a box to type in.
fn number(fields: &mut Map<String, serde_json::Value>, point: &Point) {
    fields.insert("value_template".into(), json!("{{ value_json.value }}"));
    let (lo, hi) = raw_range(point);
    let (a, b) = (engineering(point, lo), engineering(point, hi));
    fields.insert("min".into(), json!(a.min(b)));
    fields.insert("max".into(), json!(a.max(b)));
    let step = if point.value_type.is_integer() { point.scale.abs() } else { MIN_STEP };
    fields.insert("step".into(), json!(step.max(MIN_STEP)));
    fields.insert("mode".into(), json!("box"));
    unit(fields, point, NUMBER_CLASSES);
}

/// The point's unit, and its device class when `classes` has one for it.
fn unit(
    fields: &mut Map<String, serde_json::Value>,
    point: &Point,
    classes: &[(&'static str, &[&str])],
) -> Option<&'static str> {
    let unit = point.unit.as_deref().filter(|u| !u.is_empty())?;
    fields.insert("unit_of_measurement".into(), json!(unit));
    let class = classes.iter().find(|(_, units)| units.contains(&unit)).map(|(class, _)| *class)?;
    fields.insert("device_class".into(), json!(class));
    Some(class)
}

/// The raw values a write may set: the profile's min and max, else the type's range.
#[allow(clippy::cast_precision_loss)] // 64-bit bounds as floats: HA's min and max are floats
fn raw_range(point: &Point) -> (f64, f64) {
    let (lo, hi) = if point.value_type.is_integer() {
        let (lo, hi) = point.value_type.integer_range();
        (lo as f64, hi as f64)
    } else {
        (-f64::from(f32::MAX), f64::from(f32::MAX))
    };
    (point.min.unwrap_or(lo), point.max.unwrap_or(hi))
}

/// Raw `raw` in engineering units, at the point's resolution (400, not 400.00000000000006).
fn engineering(point: &Point, raw: f64) -> f64 {
    #[allow(clippy::cast_possible_truncation)] // a raw integer bound, whole already
    let value = if point.value_type.is_integer() { Value::Int(raw as i128) } else { Value::Float(raw) };
    let exact = raw * point.scale + point.offset;
    point.engineering(&value).filter(|x| x.is_finite()).unwrap_or(exact)
}

/// Available while the bridge and the device both say `online`.
fn availability(prefix: &str, device: &str) -> serde_json::Value {
    let entry =
        |topic: String| json!({"topic": topic, "payload_available": "online", "payload_not_available": "offline"});
    json!([entry(format!("{prefix}/status")), entry(format!("{prefix}/{device}/status"))])
}

/// The device: its id as name, the profile's vendor and product code.
fn device_block(node: &str, id: &str, profile: Option<&Profile>) -> serde_json::Value {
    let mut block = Map::new();
    block.insert("identifiers".into(), json!([format!("ferrobus_{node}")]));
    block.insert("name".into(), json!(id));
    if let Some(profile) = profile {
        let d = &profile.device;
        if !d.vendor.is_empty() {
            block.insert("manufacturer".into(), json!(d.vendor));
        }
        if !d.product_code.is_empty() {
            block.insert("model".into(), json!(d.product_code));
        }
    }
    serde_json::Value::Object(block)
}

/// What published the config.
fn origin() -> serde_json::Value {
    json!({
        "name": "ferrobus",
        "sw_version": env!("CARGO_PKG_VERSION"),
        "support_url": env!("CARGO_PKG_REPOSITORY"),
    })
}

/// `text` as a node_id or object_id: `[a-zA-Z0-9_-]` kept, anything else `_`, and when
/// anything was, `_` and a hash of `text` after it (so that `a/b` and `a_b` stay apart).
pub(crate) fn id(text: &str) -> String {
    let kept: String =
        text.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' || c == '-' { c } else { '_' }).collect();
    if kept == text && !kept.is_empty() { kept } else { format!("{kept}_{:08x}", fnv1a(text)) }
}

/// An entity id's object part as HA forms them: lower case `[a-z0-9_]`, no `_` doubled or
/// at either end.
fn entity_slug(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        let c = if c.is_ascii_alphanumeric() { c.to_ascii_lowercase() } else { '_' };
        if c != '_' || !(out.is_empty() || out.ends_with('_')) {
            out.push(c);
        }
    }
    let trimmed = out.trim_end_matches('_');
    if trimmed.is_empty() { "point".to_string() } else { trimmed.to_string() }
}

/// FNV-1a, 32 bits: a hash that is the same in every build and on every machine.
fn fnv1a(text: &str) -> u32 {
    text.bytes().fold(0x811c_9dc5, |h, b| (h ^ u32::from(b)).wrapping_mul(0x0100_0193))
}

#[cfg(test)]
#[path = "../../tests/support/ha_schema.rs"]
mod ha_schema;

#[cfg(test)]
mod tests {
    use std::sync::Arc;
    use std::time::Duration;

    use ferrobus_profile::{Access, BitDef, DeviceSection, Profile, RegisterDef, ValueType};
    use ferrobus_tools::poll::Group;

    use super::*;

    fn config() -> PlainConfig {
        PlainConfig { prefix: "plant/1".into(), retain: false, qos: 1, discovery: Some("homeassistant".into()) }
    }

    fn device(profile: Profile, points: &[&str]) -> DeviceSpec {
        let names: Vec<String> = points.iter().map(ToString::to_string).collect();
        let groups = Group::points(&profile, 1, &names, &[], Duration::from_secs(1)).expect("the points");
        let deadbands = groups.iter().map(|g| vec![0.0; g.cells.len()]).collect();
        DeviceSpec {
            id: "inverter".into(),
            unit: 1,
            profile: Some(Arc::new(profile)),
            groups,
            deadbands,
            death_after: 3,
        }
    }

    /// The topic and config of point `name` of the 3G3RX, checked against HA's schema.
    fn rx(name: &str) -> (String, serde_json::Value) {
        let device = device(Profile::builtin("omron-3g3rx").expect("built in"), &[name]);
        let cell = device.groups.iter().flat_map(|g| &g.cells).find(|c| c.name == name).expect("the cell");
        let (topic, payload) = entity(&config(), "homeassistant", &device, cell);
        checked(&topic, &payload);
        (topic, payload)
    }

    /// Asserts that `payload` on `topic` is what HA's documentation describes.
    fn checked(topic: &str, payload: &serde_json::Value) {
        let component = ha_schema::topic_component(topic, "homeassistant").unwrap_or_else(|e| panic!("{e}"));
        let problems = ha_schema::problems(component, payload);
        assert!(problems.is_empty(), "{topic}: {problems:?}\n{payload:#}");
    }

    #[test]
    fn a_read_only_hz_register_is_a_frequency_sensor_measured_in_hz() {
        let (topic, c) = rx("d001");
        let node = id("plant/1/inverter");
        assert_eq!(topic, format!("homeassistant/sensor/{node}/d001/config"));
        assert_eq!(c["state_topic"], "plant/1/inverter/d001");
        assert_eq!(c["value_template"], "{{ value_json.value }}");
        assert_eq!((&c["unit_of_measurement"], &c["device_class"]), (&json!("Hz"), &json!("frequency")));
        assert_eq!(c["state_class"], "measurement");
        assert_eq!(c["name"], "output frequency");
        assert_eq!(c["unique_id"], format!("ferrobus_{node}_d001"));
        assert_eq!(c["default_entity_id"], "sensor.plant_1_inverter_d001");
        assert!(c.get("command_topic").is_none(), "{c}");
        let availability: Vec<&str> =
            c["availability"].as_array().unwrap().iter().map(|a| a["topic"].as_str().unwrap()).collect();
        assert_eq!(availability, ["plant/1/status", "plant/1/inverter/status"]);
        assert_eq!(c["availability_mode"], "all");
        assert_eq!(
            c["device"],
            json!({"identifiers": [format!("ferrobus_{node}")], "name": "inverter", "manufacturer": "OMRON", "model": "3G3RX"})
        );
        assert_eq!(c["origin"]["name"], "ferrobus");
    }

    #[test]
    fn a_writable_register_with_a_range_is_a_number_in_engineering_units() {
        let (topic, c) = rx("F001");
        assert!(topic.starts_with("homeassistant/number/"), "{topic}");
        assert_eq!(c["command_topic"], "plant/1/inverter/F001/set");
        assert_eq!((c["min"].as_f64(), c["max"].as_f64(), c["step"].as_f64()), (Some(0.0), Some(400.0), Some(0.01)));
        assert_eq!((&c["unit_of_measurement"], &c["device_class"]), (&json!("Hz"), &json!("frequency")));
        assert_eq!(c["mode"], "box");
        let (_, a003) = rx("A003");
        assert_eq!(
            (a003["min"].as_f64(), a003["max"].as_f64(), a003["step"].as_f64()),
            (Some(30.0), Some(400.0), Some(1.0))
        );
    }

    #[test]
    fn a_writable_enumeration_is_a_select_of_its_meanings_and_a_read_only_one_a_sensor_of_them() {
        let (topic, c) = rx("A019");
        assert!(topic.starts_with("homeassistant/select/"), "{topic}");
        assert_eq!(c["options"], json!(["binary", "single-bit"]));
        assert_eq!(c["value_template"], "{{ value_json.meaning | default(None) }}");
        assert_eq!(c["command_topic"], "plant/1/inverter/A019/set");
        // What HA sends is a meaning, which the point's own parser takes for its raw value.
        let point = Profile::builtin("omron-3g3rx").unwrap().point("A019").unwrap().clone();
        assert_eq!(point.prepare_write("single-bit").ok(), Some(Value::Int(1)));
        let (topic, d003) = rx("d003");
        assert!(topic.starts_with("homeassistant/sensor/"), "{topic}");
        assert!(d003.get("state_class").is_none() && d003.get("unit_of_measurement").is_none(), "{d003}");
    }

    #[test]
    fn a_writable_coil_is_a_switch_of_on_and_off_and_a_read_only_one_a_binary_sensor() {
        let (topic, c) = rx("run");
        assert!(topic.starts_with("homeassistant/switch/"), "{topic}");
        assert_eq!((&c["payload_on"], &c["payload_off"]), (&json!("on"), &json!("off")));
        assert_eq!(c["command_topic"], "plant/1/inverter/run/set");
        let point = Profile::builtin("omron-3g3rx").unwrap().point("run").unwrap().clone();
        assert_eq!(point.prepare_write("on").ok(), Some(Value::Bool(true)));
        assert_eq!(point.prepare_write("off").ok(), Some(Value::Bool(false)));
        let (topic, running) = rx("running");
        assert!(topic.starts_with("homeassistant/binary_sensor/"), "{topic}");
        assert!(running.get("command_topic").is_none(), "{running}");
    }

    #[test]
    fn a_profile_built_here_scaled_power_and_energy_a_unit_ha_does_not_list_and_a_coil() {
        let mut profile = Profile::new(DeviceSection::new("meter", "ACME", "M-1", "2"));
        let mut power = RegisterDef::new(1, "P", ValueType::I16);
        power.unit = Some("kW".into());
        power.scale = Some(0.1);
        let mut energy = RegisterDef::new(2, "E", ValueType::U32);
        energy.unit = Some("kWh".into());
        let mut speed = RegisterDef::new(4, "speed.set", ValueType::U16);
        (speed.unit, speed.access, speed.scale) = (Some("r/min".into()), Access::Rw, Some(0.0001));
        let mut relay = BitDef::new(1, "relay");
        relay.access = Access::Rw;
        profile.registers = vec![power, energy, speed];
        profile.coils = vec![relay];
        let profile = profile.build("meter.toml").expect("the profile builds");
        let device = device(profile, &["P", "E", "speed.set", "relay"]);
        let all = configs(&plant(device), &config(), "homeassistant");
        let by_name = |n: &str| {
            let p = all
                .iter()
                .find(|p| p.topic.contains(&format!("/{n}/")) || p.topic.contains(&format!("/{n}_")))
                .unwrap();
            (p.topic.clone(), serde_json::from_slice::<serde_json::Value>(&p.payload).unwrap())
        };
        assert_eq!(all.len(), 4);
        for p in &all {
            assert!(p.retain && p.qos == 1, "{}", p.topic);
            checked(&p.topic, &serde_json::from_slice(&p.payload).unwrap());
        }
        let (_, p) = by_name("P");
        assert_eq!((&p["device_class"], &p["state_class"]), (&json!("power"), &json!("measurement")));
        let (_, e) = by_name("E");
        assert_eq!((&e["device_class"], &e["state_class"]), (&json!("energy"), &json!("total_increasing")));
        let (topic, s) = by_name("speed_set");
        assert!(
            topic.starts_with("homeassistant/number/") && topic.ends_with(&format!("/{}/config", id("speed.set"))),
            "{topic}"
        );
        assert_eq!(s["unit_of_measurement"], "r/min");
        assert!(s.get("device_class").is_none(), "r/min is no class's unit: {s}");
        assert_eq!((s["min"].as_f64(), s["max"].as_f64(), s["step"].as_f64()), (Some(0.0), Some(6.5535), Some(0.001)));
        let (topic, _) = by_name("relay");
        assert!(topic.starts_with("homeassistant/switch/"), "{topic}");
    }

    fn plant(device: DeviceSpec) -> Plant {
        let mut plant = Plant::demo("127.0.0.1").expect("the demo");
        plant.mode = crate::config::Mode::Plain(config());
        plant.lines.truncate(1);
        if let Some(line) = plant.lines.first_mut() {
            line.devices = vec![device];
        }
        plant
    }

    #[test]
    fn the_schema_check_refuses_a_missing_required_key_an_unknown_key_and_a_unit_of_another_class() {
        let (topic, number) = rx("F001");
        let broken = |change: &dyn Fn(&mut Map<String, serde_json::Value>)| {
            let mut c = number.as_object().unwrap().clone();
            change(&mut c);
            ha_schema::problems("number", &serde_json::Value::Object(c))
        };
        assert!(!broken(&|c| drop(c.remove("command_topic"))).is_empty());
        assert!(!broken(&|c| drop(c.insert("unit_of_measure".into(), json!("Hz")))).is_empty());
        assert!(!broken(&|c| drop(c.insert("unit_of_measurement".into(), json!("V")))).is_empty());
        assert!(!broken(&|c| drop(c.insert("step".into(), json!(0.0001)))).is_empty());
        assert!(
            !broken(&|c| drop(c["device"].as_object_mut().unwrap().insert("vendor".into(), json!("x")))).is_empty()
        );
        assert!(ha_schema::topic_component(&topic.replace("/F001/", "/F0.01/"), "homeassistant").is_err());
        assert!(ha_schema::topic_component(&topic, "homeassistant").is_ok());
    }

    #[test]
    fn ids_keep_has_allowed_characters_and_hash_the_rest_stably() {
        assert_eq!(id("d001"), "d001");
        assert_eq!(id("status-a"), "status-a");
        let node = id("plant/1/inverter");
        assert!(node.starts_with("plant_1_inverter_") && node.len() == "plant_1_inverter_".len() + 8, "{node}");
        assert_eq!(node, id("plant/1/inverter"), "stable");
        assert_ne!(id("a/b"), id("a_b"));
        assert_ne!(id("a/b"), id("a.b"));
        for text in ["plant/1/inverter", "a b", "x+y#", "°C", ""] {
            let id = id(text);
            assert!(!id.is_empty() && id.chars().all(|c| c.is_ascii_alphanumeric() || "_-".contains(c)), "{id}");
        }
        assert_eq!(entity_slug("plant/1_inverter_A--b_"), "plant_1_inverter_a_b");
    }
}
