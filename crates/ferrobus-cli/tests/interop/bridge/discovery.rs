//! `ferrobus bridge` in plain mode with Home Assistant discovery: the retained configs under
//! `homeassistant/` (seen by a subscriber that comes after they were published), each checked
//! against HA's documented schema (the bridge's own table, `ferrobus-bridge/tests/support/
//! ha_schema.rs`), the sensor's state topic carrying values, and HA's commands (a number's
//! value, a select's option) on their `command_topic` changing the drive through `.../set`.

use std::collections::BTreeMap;
use std::time::Duration;

use serde_json::Value;

use super::harness::{Bridge, Drive, Plant};
use super::spb::{self, Message, Recorder};
use crate::support::mosquitto::Broker;

#[path = "../../../../ferrobus-bridge/tests/support/ha_schema.rs"]
mod ha_schema;

const INVERTER: &str = "[[line.device]]\nid = \"inverter\"\nunit = 1\nprofile = \"omron-3g3rx\"\n\
                        every = \"200ms\"\npoints = [\"d001\", \"F001\", \"A019\", \"run\", \"running\"]\n";

/// What each point becomes.
const EXPECTED: [(&str, &str); 5] =
    [("d001", "sensor"), ("F001", "number"), ("A019", "select"), ("run", "switch"), ("running", "binary_sensor")];

/// The value of `point` as `get` reads it from the drive.
fn get(drive: &Drive, point: &str) -> String {
    let out = drive.client(1).run(&["--device", "omron-3g3rx", "get", point, "--json"]).json();
    out.pointer("/points/0/value").and_then(Value::as_str).unwrap_or_default().to_string()
}

/// The retained configs, by the point their state topic names: (component, config).
fn configs(messages: &[Message]) -> BTreeMap<String, (String, Value)> {
    let mut out = BTreeMap::new();
    for m in messages.iter().filter(|m| m.retain && m.topic.ends_with("/config")) {
        let config: Value =
            serde_json::from_slice(&m.payload).unwrap_or_else(|e| panic!("{}: {e}: {}", m.topic, m.text()));
        let component = ha_schema::topic_component(&m.topic, "homeassistant").unwrap_or_else(|e| panic!("{e}"));
        let point = config["state_topic"].as_str().and_then(|t| t.rsplit('/').next()).unwrap_or_default().to_string();
        out.insert(point, (component.to_string(), config));
    }
    out
}

#[test]
fn home_assistant_configs_are_retained_pass_its_schema_and_its_commands_change_the_drive() {
    let Some(_turn) = spb::require() else { return };
    let broker = Broker::start();
    let dir = spb::evidence_dir("plain-discovery");
    let recorder = Recorder::start(&broker, &dir, &["plant3/#"]);
    let drive = Drive::start(&["--profile", "omron-3g3rx"]);
    let config =
        Plant::plain(broker.port(), "plant3", false).discovery().tcp_line("tcp", drive.address(), INVERTER).write(&dir);
    let mut bridge = Bridge::start(&config, &[]);
    let values = |m: &[Message]| m.iter().filter(|m| m.topic == "plant3/inverter/d001").count();
    recorder.wait_until("plant3/inverter/d001", Duration::from_secs(20), |m| values(m) > 0);

    // A subscriber that comes after: what it gets at once was retained.
    let ha_dir = dir.join("homeassistant");
    std::fs::create_dir_all(&ha_dir).expect("the late recorder's directory");
    let ha = Recorder::start(&broker, &ha_dir, &["homeassistant/#", "plant3/status", "plant3/inverter/status"]);
    let messages = ha.wait_until("the five retained configs", Duration::from_secs(10), |m| configs(m).len() == 5);
    let found = configs(&messages);
    for (point, component) in EXPECTED {
        let (got, config) =
            found.get(point).unwrap_or_else(|| panic!("no config for {point}:\n{}", spb::listing(&messages)));
        assert_eq!(got, component, "{point}: {config}");
        let problems = ha_schema::problems(got, config);
        assert!(problems.is_empty(), "{point}: {problems:?}\n{config:#}");
        assert_eq!(config["device"]["manufacturer"], "OMRON", "{config}");
        let availability: Vec<&str> =
            config["availability"].as_array().into_iter().flatten().filter_map(|a| a["topic"].as_str()).collect();
        assert_eq!(availability, ["plant3/status", "plant3/inverter/status"], "{config}");
    }
    let retained =
        |topic: &str| messages.iter().filter(|m| m.topic == topic && m.retain).map(Message::text).collect::<Vec<_>>();
    assert_eq!(retained("plant3/status"), ["online"], "{}", spb::listing(&messages));
    assert_eq!(retained("plant3/inverter/status"), ["online"], "{}", spb::listing(&messages));

    // The sensor's state topic carries the value its value_template takes.
    let (_, d001) = &found["d001"];
    assert_eq!(
        (&d001["value_template"], &d001["device_class"]),
        (&Value::from("{{ value_json.value }}"), &Value::from("frequency"))
    );
    let state_topic = d001["state_topic"].as_str().unwrap_or_default().to_string();
    let states = recorder.wait_until("a d001 value on its state topic", Duration::from_secs(10), |m| {
        m.iter().any(|m| {
            m.topic == state_topic && serde_json::from_slice::<Value>(&m.payload).is_ok_and(|j| j["value"].is_number())
        })
    });
    assert!(states.iter().any(|m| m.topic == state_topic), "{state_topic}");

    // What HA sends: a number's value, a select's option, on their command topics.
    let results = |m: &[Message], point: &str| {
        let topic = format!("plant3/inverter/{point}/set/result");
        m.iter()
            .filter(|m| m.topic == topic)
            .filter_map(|m| serde_json::from_slice::<Value>(&m.payload).ok())
            .collect::<Vec<_>>()
    };
    for (point, payload, shown) in [("F001", "45.5", "45.50 Hz"), ("A019", "single-bit", "single-bit")] {
        let command_topic = found[point].1["command_topic"].as_str().unwrap_or_default().to_string();
        assert_eq!(command_topic, format!("plant3/inverter/{point}/set"));
        spb::publish(&broker, &["text", "--topic", &command_topic, "--payload", payload]);
        let m = recorder
            .wait_until(&format!("{point}'s result"), Duration::from_secs(10), |m| !results(m, point).is_empty());
        assert_eq!(results(&m, point)[0]["ok"], true, "{:?}\nbridge:\n{}", results(&m, point), bridge.output());
        assert_eq!(get(&drive, point), shown, "bridge:\n{}", bridge.output());
    }
    bridge.terminate();
}
