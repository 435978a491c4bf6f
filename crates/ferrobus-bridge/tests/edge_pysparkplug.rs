//! A whole edge session, read by a decoder the team did not write: pysparkplug 0.6.1 (through
//! `tests/peers/sparkplug/decode.py`) decodes the NDEATH Will, the NBIRTH, the demo plant's
//! DBIRTHs, alias-only DDATA (resolved from the DBIRTH, as a host does), historical DDATA
//! replayed from the store, and a DDEATH.
//!
//! The peer: pysparkplug in `target/peers/sparkplug-venv` (`.ci/setup-peers.sh`). Under
//! `CI=true` a missing peer fails the test; elsewhere it passes with a `SKIPPED` line.

use std::path::PathBuf;
use std::process::Command;
use std::time::{Duration, SystemTime};

use ferrobus_bridge::config::Plant;
use ferrobus_bridge::edge::{DeviceRef, Edge, Output, Publish};
use ferrobus_tools::poll::{Failure, FailureKind, Reading, Sample, Traffic};
use serde_json::Value as Json;

mod support;

/// pysparkplug's python and decode.py, or None (after a `SKIPPED` line) outside CI.
fn peer(test: &str) -> Option<(PathBuf, PathBuf)> {
    support::present(test, &support::missing_pysparkplug()).then(support::pysparkplug)
}

/// What pysparkplug decoded of `message` (its type from the topic), aliases resolved by `birth`.
fn decoded(peer: &(PathBuf, PathBuf), message: &Publish, birth: Option<&Publish>) -> Json {
    let dir = std::env::temp_dir().join(format!("ferrobus-edge-spb-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let kind = message.topic.split('/').nth(2).unwrap();
    let file = dir.join(format!("{kind}-{}.bin", message.payload.len()));
    std::fs::write(&file, &message.payload).unwrap();
    let mut command = Command::new(&peer.0);
    command.arg(&peer.1).arg(kind).arg(&file);
    if let Some(birth) = birth {
        let born = dir.join(format!("birth-{}.bin", birth.payload.len()));
        std::fs::write(&born, &birth.payload).unwrap();
        command.arg("--birth").arg(&born);
    }
    let out = command.output().unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "pysparkplug refused the {kind} on {}: {stderr}", message.topic);
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| panic!("decode.py printed no JSON ({e}): {stderr}"))
}

fn t(ms: u64) -> SystemTime {
    SystemTime::UNIX_EPOCH + Duration::from_millis(1_764_633_600_000 + ms)
}

fn sample(group: usize, time: SystemTime, result: Result<Vec<Reading>, Failure>) -> Sample {
    Sample {
        group,
        seq: 0,
        time,
        due: Duration::ZERO,
        started: Duration::ZERO,
        response_time: Duration::ZERO,
        overrun: false,
        result,
        traffic: Traffic::default(),
    }
}

/// Every group of every device of the plant answered, each cell's default raw value plus `bump`
/// (integers).
fn poll_all(edge: &mut Edge, plant: &Plant, time: SystemTime, bump: i128) -> Vec<Output> {
    let mut out = Vec::new();
    for (l, line) in plant.lines.iter().enumerate() {
        for (d, device) in line.devices.iter().enumerate() {
            for (g, group) in device.groups.iter().enumerate() {
                let readings = group
                    .cells
                    .iter()
                    .enumerate()
                    .map(|(cell, c)| {
                        let raw = match &c.point.default {
                            ferrobus_profile::Value::Int(n) => ferrobus_profile::Value::Int(n + bump),
                            other => other.clone(),
                        };
                        Reading { cell, raw: Ok(raw), scaled: None, shown: String::new() }
                    })
                    .collect();
                out.extend(edge.sample(DeviceRef { line: l, device: d }, g, &sample(g, time, Ok(readings))));
            }
        }
    }
    out
}

fn publishes(outputs: Vec<Output>) -> Vec<Publish> {
    outputs.into_iter().filter_map(|o| if let Output::Publish(p) = o { Some(p) } else { None }).collect()
}

fn metric<'a>(decoded: &'a Json, name: &str) -> &'a Json {
    decoded["metrics"].as_array().unwrap().iter().find(|m| m["name"] == name).unwrap_or_else(|| panic!("no {name}"))
}

#[test]
fn pysparkplug_reads_a_whole_edge_session_of_the_demo_plant() {
    let Some(peer) = peer("pysparkplug_reads_a_whole_edge_session_of_the_demo_plant") else { return };
    let plant = Plant::demo("127.0.0.1:1883").unwrap();
    let mut edge = Edge::new(&plant);
    edge.set_bd_seq(41);

    let will = edge.will().unwrap();
    let ndeath = decoded(&peer, &will, None);
    assert_eq!(metric(&ndeath, "bdSeq")["value"], 41, "{ndeath}");

    // Offline first: the samples become records.
    let stored: Vec<Vec<u8>> = poll_all(&mut edge, &plant, t(10), 0)
        .into_iter()
        .filter_map(|o| if let Output::Store(r) = o { Some(r) } else { None })
        .collect();
    assert!(!stored.is_empty());

    let births = edge.connected(t(100));
    let nbirth = decoded(&peer, &births[0], None);
    assert_eq!((nbirth["type"].as_str(), nbirth["seq"].as_u64()), (Some("NBIRTH"), Some(0)));
    assert_eq!(metric(&nbirth, "bdSeq")["value"], 41);
    assert_eq!(metric(&nbirth, "Node Control/Rebirth")["value"], false);
    let inverter_birth = births.iter().find(|p| p.topic.ends_with("/DBIRTH/demo-edge/inverter")).unwrap();
    let dbirth = decoded(&peer, inverter_birth, None);
    let f001 = metric(&dbirth, "F001");
    assert_eq!(f001["datatype"], "DOUBLE", "{dbirth}");
    assert_eq!(f001["properties"]["engUnit"]["value"], "Hz", "{dbirth}");

    // Historical DDATA, aliases only, resolved by pysparkplug from the DBIRTH.
    for record in &stored {
        for message in edge.replay_all(record, t(110)).unwrap() {
            let birth = births.iter().find(|b| b.topic == message.topic.replace("/DDATA/", "/DBIRTH/")).unwrap();
            let data = decoded(&peer, &message, Some(birth));
            for m in data["metrics"].as_array().unwrap() {
                assert_eq!(m["is_historical"], true, "{data}");
                assert!(m["name"].is_string(), "the alias resolves: {data}");
                assert_eq!(m["timestamp"], 1_764_633_600_010_u64, "the sample's time: {data}");
            }
        }
    }

    // Live DDATA after a change.
    let live = publishes(poll_all(&mut edge, &plant, t(200), 7));
    let changes: Vec<&Publish> = live.iter().filter(|p| p.topic.contains("/DDATA/")).collect();
    assert!(!changes.is_empty());
    for message in changes {
        let birth = births.iter().find(|b| b.topic == message.topic.replace("/DDATA/", "/DBIRTH/")).unwrap();
        let data = decoded(&peer, message, Some(birth));
        assert!(
            data["metrics"].as_array().unwrap().iter().all(|m| m["is_historical"] == false && m["name"].is_string())
        );
    }

    // The inverter goes silent: DDEATH after death_after polls.
    let dead = (0..10)
        .flat_map(|i| {
            let failure = Failure { kind: FailureKind::Timeout, exception: None, diagnosis: "no reply".into() };
            edge.sample(DeviceRef { line: 0, device: 0 }, 0, &sample(0, t(300 + i), Err(failure)))
        })
        .collect::<Vec<_>>();
    let ddeath = publishes(dead);
    assert_eq!(ddeath.len(), 1);
    let decoded_death = decoded(&peer, &ddeath[0], None);
    assert_eq!(decoded_death["type"], "DDEATH", "{decoded_death}");
    assert!(decoded_death["seq"].is_u64());
}
