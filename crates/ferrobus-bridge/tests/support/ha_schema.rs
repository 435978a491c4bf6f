//! Home Assistant's MQTT discovery schema, as its documentation writes it, for the tests of
//! the bridge's discovery configs (the bridge's unit tests and the interop test against
//! mosquitto include this file).
//!
//! Written from the documentation pages (home-assistant/home-assistant.io, read 2026-12):
//! - https://www.home-assistant.io/integrations/mqtt/ ("MQTT Discovery": the topic
//!   `<discovery_prefix>/<component>/[<node_id>/]<object_id>/config`, node_id and object_id
//!   of `[a-zA-Z0-9_-]`, the `origin` keys, the device registry keys, an empty retained
//!   payload removes a config);
//! - https://www.home-assistant.io/integrations/sensor.mqtt/, binary_sensor.mqtt/,
//!   number.mqtt/, select.mqtt/, switch.mqtt/ (each component's keys, which are required;
//!   `default_entity_id`, which replaces the deprecated `object_id`, from sensor.mqtt/);
//! - https://www.home-assistant.io/integrations/sensor/#device-class and
//!   https://www.home-assistant.io/integrations/number/#device-class (the units of each
//!   device class; only the classes the bridge may use are listed here).
//!
//! HA itself ignores unknown keys; a key that is not in this table is refused here all the
//! same, so that a misspelt key (`unit_of_measure`) cannot go unnoticed.

use serde_json::Value;

/// The keys every MQTT entity documents (availability, device, naming, QoS), and the
/// discovery payload's own (`origin`, the `~` base topic).
const COMMON: &[&str] = &[
    "availability",
    "availability_mode",
    "availability_template",
    "availability_topic",
    "default_entity_id",
    "device",
    "enabled_by_default",
    "encoding",
    "entity_category",
    "entity_picture",
    "icon",
    "json_attributes_template",
    "json_attributes_topic",
    "name",
    "object_id",
    "origin",
    "payload_available",
    "payload_not_available",
    "platform",
    "qos",
    "unique_id",
    "~",
];

/// A component's documented keys beyond [`COMMON`], and those it requires.
struct Component {
    name: &'static str,
    required: &'static [&'static str],
    keys: &'static [&'static str],
}

const COMPONENTS: &[Component] = &[
    Component {
        name: "sensor",
        required: &["state_topic"],
        keys: &[
            "device_class",
            "expire_after",
            "force_update",
            "last_reset_value_template",
            "options",
            "state_class",
            "state_topic",
            "suggested_display_precision",
            "unit_of_measurement",
            "value_template",
        ],
    },
    Component {
        name: "binary_sensor",
        required: &["state_topic"],
        keys: &[
            "device_class",
            "expire_after",
            "force_update",
            "off_delay",
            "payload_off",
            "payload_on",
            "state_topic",
            "value_template",
        ],
    },
    Component {
        name: "number",
        required: &["command_topic"],
        keys: &[
            "command_template",
            "command_topic",
            "device_class",
            "max",
            "min",
            "mode",
            "optimistic",
            "payload_reset",
            "retain",
            "state_topic",
            "step",
            "unit_of_measurement",
            "value_template",
        ],
    },
    Component {
        name: "select",
        required: &["command_topic", "options"],
        keys: &[
            "command_template",
            "command_topic",
            "optimistic",
            "options",
            "retain",
            "state_topic",
            "value_template",
        ],
    },
    Component {
        // The page marks command_topic optional (an optimistic switch); one the bridge writes needs it.
        name: "switch",
        required: &["command_topic"],
        keys: &[
            "command_topic",
            "device_class",
            "optimistic",
            "payload_off",
            "payload_on",
            "retain",
            "state_off",
            "state_on",
            "state_topic",
            "value_template",
        ],
    },
];

/// The device registry's keys.
const DEVICE: &[&str] = &[
    "configuration_url",
    "connections",
    "hw_version",
    "identifiers",
    "manufacturer",
    "model",
    "model_id",
    "name",
    "serial_number",
    "suggested_area",
    "sw_version",
    "via_device",
];

/// `origin`'s keys (`name` required).
const ORIGIN: &[&str] = &["name", "sw_version", "support_url"];

/// An `availability` entry's keys (`topic` required).
const AVAILABILITY: &[&str] = &["payload_available", "payload_not_available", "topic", "value_template"];

/// A sensor's device classes with their units (sensor/#device-class).
const SENSOR_UNITS: &[(&str, &[&str])] = &[
    ("apparent_power", &["mVA", "VA"]),
    ("current", &["A", "mA"]),
    ("duration", &["d", "h", "min", "s", "ms", "µs"]),
    ("energy", &["J", "kJ", "MJ", "GJ", "mWh", "Wh", "kWh", "MWh", "GWh", "TWh", "cal", "kcal", "Mcal", "Gcal"]),
    ("frequency", &["Hz", "kHz", "MHz", "GHz"]),
    ("power", &["mW", "W", "kW", "MW", "GW", "TW"]),
    ("pressure", &["Pa", "kPa", "hPa", "bar", "cbar", "mbar", "mmHg", "inHg", "psi"]),
    ("reactive_power", &["var", "kvar"]),
    ("temperature", &["°C", "°F", "K"]),
    ("voltage", &["V", "mV", "µV", "kV", "MV"]),
];

/// A number's device classes with their units (number/#device-class).
const NUMBER_UNITS: &[(&str, &[&str])] = &[
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

/// Whether `id` is a node_id or object_id HA takes: `[a-zA-Z0-9_-]+`.
fn is_id(id: &str) -> bool {
    !id.is_empty() && id.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
}

/// Whether `topic` is `<discovery_prefix>/<component>/<node_id>/<object_id>/config` with a
/// node_id and an object_id of `[a-zA-Z0-9_-]`; its component when it is.
pub(crate) fn topic_component<'t>(topic: &'t str, discovery_prefix: &str) -> Result<&'t str, String> {
    let rest = topic
        .strip_prefix(discovery_prefix)
        .and_then(|r| r.strip_prefix('/'))
        .and_then(|r| r.strip_suffix("/config"))
        .ok_or_else(|| format!("{topic}: not {discovery_prefix}/…/config"))?;
    match rest.split('/').collect::<Vec<_>>().as_slice() {
        [component, node, object] if is_id(node) && is_id(object) => Ok(component),
        _ => Err(format!("{topic}: not <component>/<node_id>/<object_id> of [a-zA-Z0-9_-]")),
    }
}

/// What is wrong with `config` as a discovery config of `component` by HA's documented
/// schema: a missing required key, a key it does not document, a unit its device class does
/// not take, a device or origin block without what it needs. Empty when nothing is.
pub(crate) fn problems(component: &str, config: &Value) -> Vec<String> {
    let Some(spec) = COMPONENTS.iter().find(|c| c.name == component) else {
        return vec![format!("{component}: not a component of this table")];
    };
    let Some(fields) = config.as_object() else { return vec![format!("{component}: {config} is not an object")] };
    let mut out = Vec::new();
    for key in spec.required {
        if !fields.contains_key(*key) {
            out.push(format!("{component}: no {key}, which it requires"));
        }
    }
    for key in fields.keys() {
        if !COMMON.contains(&key.as_str()) && !spec.keys.contains(&key.as_str()) {
            out.push(format!("{component}: {key} is not a documented key"));
        }
    }
    out.extend(unit_problems(component, fields));
    out.extend(block_problems(fields.get("device"), "device", DEVICE, &[]));
    if fields.get("device").is_some_and(|d| d.get("identifiers").is_none() && d.get("connections").is_none()) {
        out.push("device: neither identifiers nor connections".to_string());
    }
    out.extend(block_problems(fields.get("origin"), "origin", ORIGIN, &["name"]));
    if let Some(entries) = fields.get("availability") {
        match entries.as_array() {
            Some(list) => {
                for entry in list {
                    out.extend(block_problems(Some(entry), "availability", AVAILABILITY, &["topic"]));
                }
            }
            None => out.push("availability: not a list".to_string()),
        }
    }
    if let Some(mode) = fields.get("availability_mode").and_then(Value::as_str)
        && !["all", "any", "latest"].contains(&mode)
    {
        out.push(format!("availability_mode {mode:?}: all, any or latest"));
    }
    out.extend(value_problems(component, fields));
    out
}

/// The device class's documented units.
fn unit_problems(component: &str, fields: &serde_json::Map<String, Value>) -> Vec<String> {
    let Some(class) = fields.get("device_class").and_then(Value::as_str) else { return Vec::new() };
    let table = match component {
        "sensor" => SENSOR_UNITS,
        "number" => NUMBER_UNITS,
        _ => return vec![format!("{component}: device_class {class:?} not checked here")],
    };
    let Some((_, units)) = table.iter().find(|(c, _)| *c == class) else {
        return vec![format!("{component}: device_class {class:?} is not in this table")];
    };
    match fields.get("unit_of_measurement").and_then(Value::as_str) {
        Some(unit) if units.contains(&unit) => Vec::new(),
        unit => vec![format!("{component}: device_class {class} takes {units:?}, not {unit:?}")],
    }
}

/// A block (`device`, `origin`, an `availability` entry): an object of known keys, with those
/// it requires.
fn block_problems(block: Option<&Value>, what: &str, keys: &[&str], required: &[&str]) -> Vec<String> {
    let Some(block) = block else { return Vec::new() };
    let Some(fields) = block.as_object() else { return vec![format!("{what}: {block} is not an object")] };
    let mut out: Vec<String> = fields
        .keys()
        .filter(|k| !keys.contains(&k.as_str()))
        .map(|k| format!("{what}: {k} is not a documented key"))
        .collect();
    out.extend(required.iter().filter(|k| !fields.contains_key(**k)).map(|k| format!("{what}: no {k}")));
    out
}

/// Values HA validates: a number's min below its max, its step at least 0.001 and its mode,
/// a select's options, a sensor's state class.
fn value_problems(component: &str, fields: &serde_json::Map<String, Value>) -> Vec<String> {
    let number = |key: &str| fields.get(key).and_then(Value::as_f64);
    let mut out = Vec::new();
    match component {
        "number" => {
            if let (Some(min), Some(max)) = (number("min"), number("max"))
                && min >= max
            {
                out.push(format!("number: min {min} is not below max {max}"));
            }
            if number("step").is_some_and(|s| s < 0.001) {
                out.push("number: step below 0.001, the smallest HA takes".to_string());
            }
            if let Some(mode) = fields.get("mode").and_then(Value::as_str)
                && !["auto", "box", "slider"].contains(&mode)
            {
                out.push(format!("number: mode {mode:?}: auto, box or slider"));
            }
        }
        "select" => {
            let options = fields.get("options").and_then(Value::as_array);
            if !options.is_some_and(|o| !o.is_empty() && o.iter().all(Value::is_string)) {
                out.push("select: options is not a list of texts".to_string());
            }
        }
        "sensor" => {
            if let Some(class) = fields.get("state_class").and_then(Value::as_str)
                && !["measurement", "total", "total_increasing"].contains(&class)
            {
                out.push(format!("sensor: state_class {class:?}"));
            }
        }
        _ => {}
    }
    out
}
