//! `ferrobus bridge` in plain mode: JSON on `PREFIX/DEVICE/POINT` (value, unit, timestamp,
//! quality), the bridge's and the device's status, a write on `.../set` that changes the
//! drive, and the result on `.../set/result`, for a value in range and one out of it; with
//! `retain`, the last values for a subscriber that comes later.

use std::time::Duration;

use serde_json::Value;

use super::harness::{Bridge, Drive, Plant};
use super::spb::{self, Message, Recorder};
use crate::support::mosquitto::Broker;

const INVERTER: &str = "[[line.device]]\nid = \"inverter\"\nunit = 1\nprofile = \"omron-3g3rx\"\n\
                        every = \"200ms\"\npoints = [\"d001\", \"F001\"]\n";

/// The JSON of the messages on `topic`, in order.
fn json_on(messages: &[Message], topic: &str) -> Vec<Value> {
    messages.iter().filter(|m| m.topic == topic).filter_map(|m| serde_json::from_slice(&m.payload).ok()).collect()
}

fn f001(drive: &Drive) -> String {
    let out = drive.client(1).run(&["--device", "omron-3g3rx", "get", "F001", "--json"]).json();
    out.pointer("/points/0/value").and_then(Value::as_str).unwrap_or_default().to_string()
}

#[test]
fn plain_json_per_point_and_a_set_that_changes_the_drive_with_its_result() {
    let Some(_turn) = spb::require() else { return };
    let broker = Broker::start();
    let dir = spb::evidence_dir("plain-mode");
    let recorder = Recorder::start(&broker, &dir, &["plant1/#"]);
    let drive = Drive::start(&["--profile", "omron-3g3rx"]);
    let config = Plant::plain(broker.port(), "plant1", false).tcp_line("tcp", drive.address(), INVERTER).write(&dir);
    let mut bridge = Bridge::start(&config, &[]);
    let messages = recorder.wait_until("plant1/inverter/F001 and d001", Duration::from_secs(20), |m| {
        !json_on(m, "plant1/inverter/F001").is_empty() && !json_on(m, "plant1/inverter/d001").is_empty()
    });
    let first = &json_on(&messages, "plant1/inverter/d001")[0];
    assert_eq!(first["unit"], "Hz", "{first}");
    assert_eq!(first["quality"], "good", "{first}");
    assert!(first["value"].is_number(), "{first}");
    let stamp = first["timestamp"].as_str().unwrap_or_default();
    assert!(stamp.len() >= 20 && stamp.ends_with('Z') && stamp.contains('T'), "not an ISO 8601 UTC time: {first}");

    let status = |topic: &str| messages.iter().filter(|m| m.topic == topic).map(Message::text).collect::<Vec<_>>();
    assert_eq!(status("plant1/status"), ["online"], "the bridge's status:\n{}", spb::listing(&messages));
    assert_eq!(status("plant1/inverter/status"), ["online"], "the device's status:\n{}", spb::listing(&messages));

    spb::publish(&broker, &["text", "--topic", "plant1/inverter/F001/set", "--payload", "45"]);
    let results = |m: &[Message]| json_on(m, "plant1/inverter/F001/set/result");
    let messages = recorder.wait_until("the set's result", Duration::from_secs(10), |m| !results(m).is_empty());
    assert_eq!(results(&messages)[0]["ok"], true, "{:?}\nbridge:\n{}", results(&messages), bridge.output());
    assert_eq!(f001(&drive), "45.00 Hz", "bridge:\n{}", bridge.output());
    recorder.wait_until("F001 = 45 published", Duration::from_secs(10), |m| {
        json_on(m, "plant1/inverter/F001").iter().any(|j| j["value"].as_f64() == Some(45.0))
    });

    // Past F001's maximum (400 Hz): refused, said so, the drive untouched.
    spb::publish(&broker, &["text", "--topic", "plant1/inverter/F001/set", "--payload", "500"]);
    let messages = recorder.wait_until("the refusal", Duration::from_secs(10), |m| results(m).len() >= 2);
    let refusal = &results(&messages)[1];
    assert_eq!(refusal["ok"], false, "{refusal}");
    assert!(refusal["error"].as_str().is_some_and(|e| !e.is_empty()), "the refusal says why: {refusal}");
    assert_eq!(f001(&drive), "45.00 Hz", "a refused set changed F001");
    bridge.terminate();
    let all = recorder.messages();
    assert!(all.iter().all(|m| !m.topic.starts_with("spBv1.0/")), "Sparkplug in plain mode:\n{}", spb::listing(&all));
}

#[test]
fn with_retain_a_late_subscriber_gets_each_points_last_value_at_once() {
    let Some(_turn) = spb::require() else { return };
    let broker = Broker::start();
    let dir = spb::evidence_dir("plain-retained");
    let drive = Drive::start(&["--profile", "omron-3g3rx"]);
    let config = Plant::plain(broker.port(), "plant2", true).tcp_line("tcp", drive.address(), INVERTER).write(&dir);
    let mut bridge = Bridge::start(&config, &[]);
    let early = Recorder::start(&broker, &dir, &["plant2/#"]);
    early.wait_until("plant2/inverter/F001", Duration::from_secs(20), |m| {
        !json_on(m, "plant2/inverter/F001").is_empty()
    });
    drop(early);
    let late_dir = dir.join("late");
    std::fs::create_dir_all(&late_dir).expect("the late recorder's directory");
    let late = Recorder::start(&broker, &late_dir, &["plant2/#"]);
    let messages = late.wait_until("the retained F001 and d001", Duration::from_secs(5), |m| {
        ["plant2/inverter/F001", "plant2/inverter/d001"].iter().all(|t| m.iter().any(|m| m.topic == *t && m.retain))
    });
    let f001 = messages.iter().find(|m| m.topic == "plant2/inverter/F001" && m.retain).map(Message::text);
    assert!(f001.is_some_and(|t| t.contains("\"unit\":\"Hz\"")), "{}", spb::listing(&messages));
    bridge.terminate();
}
