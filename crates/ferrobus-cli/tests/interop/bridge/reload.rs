//! `ferrobus bridge` reloads its plant file on SIGHUP while its session goes on: with one
//! device added (on a line of its own) and one changed (a point more), the unchanged device
//! gets no new DBIRTH, the added one is born, the changed one gets its DDEATH and then its
//! DBIRTH with the new metric, and the node's NBIRTH is not repeated; pysparkplug finds the
//! whole recording clean. In plain mode with discovery: a removed device's status goes
//! offline and its configs are removed (empty, retained), the added one's are published, and
//! the bridge's status is not said online again.

#![cfg(unix)]

use std::time::Duration;

use super::harness::{Bridge, Drive, Plant};
use super::spb::{self, Message};

/// How long the bridge may take to the births, and to carry out a reload.
const WITHIN: Duration = Duration::from_secs(20);

fn device(id: &str, points: &str) -> String {
    format!(
        "[[line.device]]\nid = \"{id}\"\nunit = 1\nprofile = \"omron-3g3rx\"\nevery = \"200ms\"\n\
         points = [{points}]\ndeath_after = 3\n"
    )
}

fn topics(messages: &[Message]) -> Vec<&str> {
    messages.iter().map(|m| m.topic.as_str()).collect()
}

#[test]
fn sighup_adds_and_changes_devices_without_a_new_nbirth_and_the_unchanged_one_is_not_born_again() {
    let Some(_turn) = spb::require() else { return };
    let dir = spb::evidence_dir("reload");
    let broker = crate::support::mosquitto::Broker::start();
    let recorder = spb::Recorder::start(&broker, &dir, &[]);
    let (a, b) = (Drive::start(&["--profile", "omron-3g3rx"]), Drive::start(&["--profile", "omron-3g3rx"]));
    let base = || Plant::sparkplug(broker.port(), "plant", "reload");
    let config = base()
        .tcp_line("a", a.address(), &device("kept", "\"d001\", \"F001\""))
        .tcp_line("b", b.address(), &device("changed", "\"d001\""))
        .write(&dir);
    let mut bridge = Bridge::start(&config, &[]);
    recorder.wait_until("the births of kept and changed", WITHIN, |m| {
        spb::count(m, "DBIRTH", Some("kept")) == 1 && spb::count(m, "DBIRTH", Some("changed")) == 1
    });

    base()
        .tcp_line("a", a.address(), &device("kept", "\"d001\", \"F001\""))
        .tcp_line("b", b.address(), &device("changed", "\"d001\", \"d002\""))
        .tcp_line("c", a.address(), &device("added", "\"d001\""))
        .write(&dir);
    bridge.hangup();
    let messages = recorder.wait_until("added born, changed born again", WITHIN, |m| {
        spb::count(m, "DBIRTH", Some("added")) == 1 && spb::count(m, "DBIRTH", Some("changed")) == 2
    });
    let listing = spb::listing(&messages);
    assert_eq!(spb::count(&messages, "NBIRTH", None), 1, "no new session:\n{listing}");
    assert_eq!(spb::count(&messages, "DBIRTH", Some("kept")), 1, "kept is not born again:\n{listing}");
    assert_eq!(spb::count(&messages, "DDEATH", Some("kept")), 0, "{listing}");
    assert_eq!(spb::count(&messages, "DDEATH", Some("changed")), 1, "{listing}");
    let at = |kind: &str, n: usize| {
        let mut found = messages.iter().enumerate().filter(|(_, m)| spb::is(m, kind, Some("changed")));
        found.nth(n).map_or_else(|| panic!("no {kind} of changed #{n}: {:?}", topics(&messages)), |(i, _)| i)
    };
    assert!(at("DBIRTH", 0) < at("DDEATH", 0) && at("DDEATH", 0) < at("DBIRTH", 1), "{listing}");
    let reborn = ferrobus_bridge::sparkplug::payload::Payload::decode(&messages[at("DBIRTH", 1)].payload).unwrap();
    let names: Vec<_> = reborn.metrics.iter().filter_map(|m| m.name.clone()).collect();
    assert!(names.contains(&"d002".to_string()), "the new metric in the new DBIRTH: {names:?}");
    // kept's data goes on after the reload (the line kept polling).
    let reload_at = at("DDEATH", 0);
    a.client(1).run(&["--device", "omron-3g3rx", "set", "F001", "12"]).ok();
    recorder.wait_until("kept's data after the reload", WITHIN, |m| {
        m.iter().skip(reload_at).any(|m| spb::is(m, "DDATA", Some("kept")))
    });
    let log = bridge.output();
    assert!(log.contains("reload: 1 device added, 1 changed, 0 removed, 1 unchanged"), "{log}");

    bridge.terminate();
    recorder.wait_until("the NDEATH", Duration::from_secs(10), |m| spb::count(m, "NDEATH", None) >= 1);
    let path = recorder.stop();
    drop(broker);
    spb::verify(&path, &[]).assert_clean();
}

#[test]
fn sighup_in_plain_mode_removes_a_devices_discovery_configs_and_publishes_the_added_ones() {
    let Some(_turn) = spb::require() else { return };
    let dir = spb::evidence_dir("reload-plain");
    let broker = crate::support::mosquitto::Broker::start();
    let recorder = spb::Recorder::start(&broker, &dir, &["plant4/#", "homeassistant/#"]);
    let drive = Drive::start(&["--profile", "omron-3g3rx"]);
    let base = || Plant::plain(broker.port(), "plant4", false).discovery();
    let config = base()
        .tcp_line("a", drive.address(), &device("kept", "\"d001\""))
        .tcp_line("b", drive.address(), &device("gone", "\"d001\""))
        .write(&dir);
    let mut bridge = Bridge::start(&config, &[]);
    let values = |m: &[Message], id: &str| m.iter().any(|m| m.topic == format!("plant4/{id}/d001"));
    recorder.wait_until("values of kept and gone", WITHIN, |m| values(m, "kept") && values(m, "gone"));
    let gone_configs: Vec<String> = recorder
        .messages()
        .iter()
        .filter(|m| m.topic.starts_with("homeassistant/") && m.topic.contains("gone") && !m.payload.is_empty())
        .map(|m| m.topic.clone())
        .collect();
    assert!(!gone_configs.is_empty(), "the configs of gone");

    base()
        .tcp_line("a", drive.address(), &device("kept", "\"d001\""))
        .tcp_line("c", drive.address(), &device("added", "\"d001\""))
        .write(&dir);
    bridge.hangup();
    let messages = recorder.wait_until("gone offline and removed, added's values", WITHIN, |m| {
        let removed = gone_configs.iter().all(|t| m.iter().any(|m| &m.topic == t && m.payload.is_empty()));
        let offline = m.iter().any(|m| m.topic == "plant4/gone/status" && m.payload == b"offline");
        removed && offline && values(m, "added")
    });
    let added = messages.iter().filter(|m| m.topic.starts_with("homeassistant/") && m.topic.contains("added"));
    assert!(added.count() > 0, "added's config:\n{}", spb::listing(&messages));
    let online = messages.iter().filter(|m| m.topic == "plant4/status" && m.payload == b"online").count();
    assert_eq!(online, 1, "no new session:\n{}", spb::listing(&messages));
    bridge.terminate();
}
