//! `ferrobus bridge --check` (every error as `file:line:col: message`, exit 2; the shipped
//! examples pass) and `ferrobus bridge --demo` against a broker of the test's own.

use std::process::Command;
use std::time::Duration;

use super::spb::{self, Recorder};
use crate::support::env;
use crate::support::mosquitto::Broker;
use crate::support::process::output_within;

/// A plant.toml with three mistakes, each on a line of its own.
const BROKEN: &str = r#"[broker]
address = "127.0.0.1:1883"

[sparkplug]
group_id = "plant"
edge_node_id = "edge+1"

[[line]]
name = "tcp"
tcp = "127.0.0.1:1502"

[[line.device]]
id = "inverter"
unit = 1
profile = "omron-3g3rx"
points = ["F00x"]

[[line.device]]
id = "servo"
unit = 2
profile = "sdp-servo"
colour = "red"
"#;

fn check(path: &std::path::Path) -> (i32, String) {
    let mut command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
    command.args(["bridge", "--check", "--config"]).arg(path);
    let output = output_within(&mut command, "", Duration::from_secs(30));
    let text = format!("{}{}", String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr));
    (output.status.code().unwrap_or(-1), text)
}

/// Whether `text` has a line `FILE:LINE:COL: ...` for this file and line.
fn points_at(text: &str, file: &str, line: usize) -> bool {
    let prefix = format!("{file}:{line}:");
    text.lines().any(|l| {
        l.strip_prefix(&prefix)
            .and_then(|rest| rest.split_once(": "))
            .is_some_and(|(col, message)| col.parse::<usize>().is_ok() && !message.is_empty())
    })
}

#[test]
fn check_prints_each_error_at_its_line_and_column_and_exits_2() {
    let Some(_turn) = env::require(&[]) else { return };
    let dir = spb::evidence_dir("check-broken");
    let path = dir.join("plant.toml");
    std::fs::write(&path, BROKEN).expect("writing plant.toml");
    let (code, text) = check(&path);
    assert_eq!(code, 2, "--check on a broken file exits 2:\n{text}");
    let file = path.display().to_string();
    for (line, what) in [(6, "the edge node id with a +"), (16, "the unknown point F00x"), (22, "the unknown key")] {
        assert!(points_at(&text, &file, line), "no `{file}:{line}:COL: ...` line for {what}:\n{text}");
    }
}

#[test]
fn check_passes_every_shipped_example() {
    let Some(_turn) = env::require(&[]) else { return };
    let examples = env::root().join("examples/bridge");
    let mut files: Vec<_> = std::fs::read_dir(&examples)
        .unwrap_or_else(|e| panic!("{}: {e}", examples.display()))
        .filter_map(|entry| entry.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    assert!(files.len() >= 3, "demo, plant and plain examples: {files:?}");
    for file in files {
        let (code, text) = check(&file);
        assert_eq!(code, 0, "--check {}:\n{text}", file.display());
    }
}

#[test]
fn the_demo_births_both_drives_and_publishes_changing_data() {
    let Some(_turn) = spb::require() else { return };
    let broker = Broker::start();
    let dir = spb::evidence_dir("demo");
    let recorder = Recorder::start(&broker, &dir, &[]);
    let mut command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
    command.args(["bridge", "--demo", "--broker", &broker.address(), "--duration", "10s"]);
    let output = output_within(&mut command, "", Duration::from_secs(40));
    let said = format!("{}{}", String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr));
    let _ = std::fs::write(dir.join("bridge.log"), &said);
    assert_eq!(output.status.code(), Some(0), "the demo stops cleanly after --duration:\n{said}");
    recorder.wait_until("the demo's NDEATH", Duration::from_secs(5), |m| spb::count(m, "NDEATH", None) >= 1);
    let verdict = spb::verify(&recorder.stop(), &["--no-historical", "--series", "inverter/d001"]);
    verdict.assert_clean();
    assert_eq!(verdict.messages_of("NBIRTH"), 1, "{verdict}");
    for device in ["inverter", "servo"] {
        assert!(verdict.summary["devices"][device]["dbirths"].as_u64() >= Some(1), "no DBIRTH of {device}:\n{verdict}");
    }
    let d001: Vec<String> = verdict.series("inverter", "d001").iter().map(|p| p["value"].to_string()).collect();
    let mut distinct = d001.clone();
    distinct.dedup();
    assert!(distinct.len() >= 2, "the inverter's output frequency does not move in DDATA: {d001:?}\n{verdict}");
    assert!(said.contains("spBv1.0"), "the demo says what to subscribe to:\n{said}");
}
