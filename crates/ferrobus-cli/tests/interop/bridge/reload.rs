//! `ferrobus bridge` reloads its plant file on SIGHUP while its session goes on: with one
//! device added (on a line of its own) and one changed (a point more), the unchanged device
//! gets no new DBIRTH, the added one is born, the changed one gets its DDEATH and then its
//! DBIRTH with the new metric, and the node's NBIRTH is not repeated; pysparkplug finds the
//! whole recording clean.

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
