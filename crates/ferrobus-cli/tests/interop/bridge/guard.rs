//! The bridge's writers go through the profile's one write guard: a Sparkplug DCMD and a plain
//! `.../set` of the run-locked A003 are written to a stopped simulated 3G3RX, and refused with
//! the words `set`, `restore` and `monitor` use (and nothing written) once the run command
//! makes it run; a metric that may change while running is still written.

use std::time::{Duration, Instant};

use serde_json::Value;

use super::harness::{Bridge, Drive, Plant};
use super::spb::{self, Message, Recorder};
use crate::support::mosquitto::Broker;

/// The guard's words for A003 while the drive runs (as in the CLI tests).
const REFUSAL: &str = "A003 cannot change while the drive runs (running = 1); stop it first";

const INVERTER: &str = "[[line.device]]\nid = \"inverter\"\nunit = 1\nprofile = \"omron-3g3rx\"\n\
                        every = \"200ms\"\npoints = [\"F001\", \"A003\", \"running\"]\n";

fn get(drive: &Drive, point: &str) -> String {
    let out = drive.client(1).run(&["--device", "omron-3g3rx", "get", point, "--json"]).json();
    out.pointer("/points/0/value").and_then(Value::as_str).unwrap_or_default().to_string()
}

/// F001 = 10 Hz and the run command; waits (a failure deadline) until the drive says it runs.
fn make_it_run(drive: &Drive) {
    drive.client(1).run(&["--device", "omron-3g3rx", "set", "F001", "10Hz"]).ok();
    drive.client(1).run(&["--device", "omron-3g3rx", "set", "run", "1"]).ok();
    let deadline = Instant::now() + Duration::from_secs(10);
    while get(drive, "running") != "1" {
        assert!(Instant::now() < deadline, "the drive never ran");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Waits (a failure deadline) until the drive's `point` reads `expected`.
fn wait_for_value(drive: &Drive, point: &str, expected: &str, bridge: &Bridge) {
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut seen = get(drive, point);
    while seen != expected && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(100));
        seen = get(drive, point);
    }
    assert_eq!(seen, expected, "{point} on the drive; the bridge said:\n{}", bridge.output());
}

/// Waits (a failure deadline) for a line of the bridge's output that holds `text`.
fn wait_for_output(bridge: &Bridge, text: &str) -> String {
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let output = bridge.output();
        if let Some(line) = output.lines().find(|l| l.contains(text)) {
            return line.to_string();
        }
        assert!(Instant::now() < deadline, "the bridge never said {text:?}:\n{output}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn a_dcmd_of_a_run_locked_metric_is_written_stopped_and_refused_running_with_the_guards_words() {
    let Some(_turn) = spb::require() else { return };
    let broker = Broker::start();
    let dir = spb::evidence_dir("guard-dcmd");
    let drive = Drive::start(&["--profile", "omron-3g3rx"]);
    let config =
        Plant::sparkplug(broker.port(), "plant", "guard-dcmd").tcp_line("tcp", drive.address(), INVERTER).write(&dir);
    let recorder = Recorder::start(&broker, &dir, &[]);
    let bridge = Bridge::start(&config, &[]);
    recorder.wait_until("the inverter's DBIRTH", Duration::from_secs(20), |m| {
        spb::count(m, "DBIRTH", Some("inverter")) >= 1
    });
    let to_inverter = ["dcmd", "--group", "plant", "--node", "guard-dcmd", "--device", "inverter"];
    let dcmd = |metric: &str, datatype: &str, value: &str| {
        let metric = ["--metric", metric, "--datatype", datatype, "--value", value];
        spb::publish(&broker, &[&to_inverter[..], &metric].concat());
    };

    dcmd("A003", "UINT16", "50");
    wait_for_value(&drive, "A003", "50 Hz", &bridge);

    make_it_run(&drive);
    dcmd("A003", "UINT16", "55");
    let refused = wait_for_output(&bridge, "command refused");
    assert!(refused.contains(&format!("inverter: {REFUSAL}: nothing written")), "{refused}");
    dcmd("F001", "DOUBLE", "12");
    wait_for_value(&drive, "F001", "12.00 Hz", &bridge);
    assert_eq!(get(&drive, "A003"), "50 Hz", "a refused DCMD changed A003; the bridge said:\n{}", bridge.output());
    drop(recorder);
}

#[test]
fn a_plain_set_of_a_run_locked_point_is_written_stopped_and_refused_running_with_the_guards_words() {
    let Some(_turn) = spb::require() else { return };
    let broker = Broker::start();
    let dir = spb::evidence_dir("guard-plain");
    let recorder = Recorder::start(&broker, &dir, &["plant3/#"]);
    let drive = Drive::start(&["--profile", "omron-3g3rx"]);
    let config = Plant::plain(broker.port(), "plant3", false).tcp_line("tcp", drive.address(), INVERTER).write(&dir);
    let mut bridge = Bridge::start(&config, &[]);
    recorder.wait_until("plant3/inverter/A003", Duration::from_secs(20), |m| {
        m.iter().any(|m| m.topic == "plant3/inverter/A003")
    });
    let results = |m: &[Message]| -> Vec<Value> {
        m.iter()
            .filter(|m| m.topic == "plant3/inverter/A003/set/result")
            .filter_map(|m| serde_json::from_slice(&m.payload).ok())
            .collect()
    };
    let set = |value: &str| spb::publish(&broker, &["text", "--topic", "plant3/inverter/A003/set", "--payload", value]);

    set("50");
    let messages = recorder.wait_until("the first result", Duration::from_secs(10), |m| !results(m).is_empty());
    assert_eq!(results(&messages)[0]["ok"], true, "{:?}\nbridge:\n{}", results(&messages), bridge.output());
    wait_for_value(&drive, "A003", "50 Hz", &bridge);

    make_it_run(&drive);
    set("55");
    let messages = recorder.wait_until("the second result", Duration::from_secs(10), |m| results(m).len() >= 2);
    let refusal = &results(&messages)[1];
    assert_eq!(refusal["ok"], false, "{refusal}");
    assert_eq!(refusal["error"], format!("inverter: {REFUSAL}: nothing written"), "{refusal}");
    assert_eq!(get(&drive, "A003"), "50 Hz", "a refused set changed A003");
    bridge.terminate();
}
