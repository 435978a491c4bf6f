//! `ferrobus bridge` in Sparkplug B mode against a simulated 3G3RX (`ferrobus sim --tcp`; an
//! SDP servo on a pty beside it in the first test): births and data checked by pysparkplug and
//! `protoc --decode_raw` (and read alike by our own types), an NCMD Rebirth, the Will NDEATH
//! after a SIGKILL and the next bdSeq after a restart, DCMD writes to F001 (and one refused),
//! a drive that goes silent and comes back, and a primary host whose STATE gates the births.

use std::time::Duration;

use ferrobus_bridge::sparkplug::payload::Payload;

use super::harness::{Bridge, Drive, Plant};
use super::spb::{self, Message, Recorder, Verdict};
use crate::support::mosquitto::Broker;
use crate::support::sim_pty;

/// How long the bridge may take from its start to the births (connecting, the first polls).
const BIRTHS_WITHIN: Duration = Duration::from_secs(20);

/// The inverter as the plant publishes it: four points every 200 ms, dead after 3 silent polls.
const INVERTER: &str = "[[line.device]]\nid = \"inverter\"\nunit = 1\nprofile = \"omron-3g3rx\"\n\
                        every = \"200ms\"\npoints = [\"d001\", \"d002\", \"F001\", \"running\"]\ndeath_after = 3\n";

/// A broker, a recorder on it, a 3G3RX sim, and the plant that bridges them (not started).
struct Scene {
    broker: Broker,
    recorder: Recorder,
    drive: Drive,
    config: std::path::PathBuf,
}

fn scene(name: &str) -> Scene {
    let broker = Broker::start();
    let dir = spb::evidence_dir(name);
    let recorder = Recorder::start(&broker, &dir, &[]);
    let drive = Drive::start(&["--profile", "omron-3g3rx"]);
    let config = Plant::sparkplug(broker.port(), "plant", name)
        .with("[store]\ndir = \"store\"")
        .tcp_line("tcp", drive.address(), INVERTER)
        .write(&dir);
    Scene { broker, recorder, drive, config }
}

/// Waits for `n` messages of `kind` (of `device`) in the recording.
fn wait_for(recorder: &Recorder, kind: &str, device: Option<&str>, n: usize, within: Duration) -> Vec<Message> {
    let what = format!("{n} {kind}{}", device.map(|d| format!(" of {d}")).unwrap_or_default());
    recorder.wait_until(&what, within, |m| spb::count(m, kind, device) >= n)
}

fn set(drive: &Drive, point: &str, value: &str) {
    drive.client(1).run(&["--device", "omron-3g3rx", "set", point, value]).ok();
}

/// F001 as the drive has it, `"45.50 Hz"`.
fn f001(drive: &Drive) -> String {
    let out = drive.client(1).run(&["--device", "omron-3g3rx", "get", "F001", "--json"]).json();
    out.pointer("/points/0/value").and_then(|v| v.as_str()).unwrap_or_default().to_string()
}

/// Stops the bridge cleanly, waits for its NDEATH, and verifies the whole recording.
fn finish(scene: Scene, mut bridge: Bridge, ndeaths: usize, args: &[&str]) -> Verdict {
    bridge.terminate();
    wait_for(&scene.recorder, "NDEATH", None, ndeaths, Duration::from_secs(10));
    let path = scene.recorder.stop();
    drop(scene.broker);
    spb::verify(&path, args)
}

/// The lines of `protoc --decode_raw` output at `indent` spaces (2: inside a metric).
fn fields_at(text: &str, indent: usize) -> Vec<&str> {
    text.lines()
        .filter(|l| l.len() > indent && l[..indent].chars().all(|c| c == ' ') && !l[indent..].starts_with(' '))
        .map(|l| &l[indent..])
        .filter(|l| !l.starts_with('}'))
        .collect()
}

/// The servo on an RTU line: its monitor group every 300 ms.
const SERVO: &str = "[[line.device]]\nid = \"servo\"\nunit = 2\nprofile = \"sdp-servo\"\n\
                     every = \"300ms\"\ngroups = [\"monitor\"]\n";

#[test]
fn births_and_data_pass_pysparkplug_and_protoc_shows_their_raw_structure() {
    let Some(_turn) = spb::require() else { return };
    let scene = scene("births-and-data");
    // A second line: the servo on a pty, RTU, beside the inverter on Modbus/TCP.
    let (_servo, pty) = sim_pty(&["--profile", "sdp-servo", "--unit", "2"]);
    let dir = scene.config.parent().map(std::path::Path::to_path_buf).unwrap_or_default();
    Plant::sparkplug(scene.broker.port(), "plant", "births-and-data")
        .tcp_line("tcp", scene.drive.address(), INVERTER)
        .rtu_line("rs485", &pty, SERVO)
        .write(&dir);
    let bridge = Bridge::start(&scene.config, &[]);
    wait_for(&scene.recorder, "DBIRTH", Some("inverter"), 1, BIRTHS_WITHIN);
    wait_for(&scene.recorder, "DBIRTH", Some("servo"), 1, BIRTHS_WITHIN);
    set(&scene.drive, "F001", "30");
    set(&scene.drive, "run", "on");
    let messages = wait_for(&scene.recorder, "DDATA", Some("inverter"), 3, Duration::from_secs(10));

    // The raw structure, with no schema: Payload.metrics is field 2, Payload.seq field 3;
    // Metric.name 1, alias 2, datatype 4; DDATA metrics by alias only, without datatype.
    let first = |kind: &str| messages.iter().find(|m| spb::is(m, kind, Some("inverter"))).cloned();
    let dbirth = decode_first(first("DBIRTH"), &dir, "dbirth");
    let top = fields_at(&dbirth, 0);
    assert!(top.contains(&"2 {") && top.iter().any(|l| l.starts_with("3: ")), "DBIRTH:\n{dbirth}");
    let inside = fields_at(&dbirth, 2);
    for field in ["1: \"d001\"", "1: \"F001\"", "4: 10", "4: 11"] {
        // d001 and F001 are scaled: Double (10); running is a bit: Boolean (11).
        assert!(inside.contains(&field), "DBIRTH has no metric field {field:?}:\n{dbirth}");
    }
    assert!(inside.iter().any(|l| l.starts_with("2: ")), "DBIRTH metrics have no alias (field 2):\n{dbirth}");
    // The property's key; its value "Hz" (48 7a) happens to parse as a message (field 9 = 122),
    // so decode_raw shows it as one: the value is pysparkplug's to check (--expect-unit).
    assert!(inside.contains(&"9 {") && dbirth.contains("1: \"engUnit\""), "no engUnit:\n{dbirth}");
    let ddata = decode_first(first("DDATA"), &dir, "ddata");
    let inside = fields_at(&ddata, 2);
    assert!(fields_at(&ddata, 0).iter().any(|l| l.starts_with("3: ")), "DDATA has no seq:\n{ddata}");
    assert!(inside.iter().any(|l| l.starts_with("2: ")), "DDATA metrics have no alias:\n{ddata}");
    assert!(
        !inside.iter().any(|l| l.starts_with("1: ") || l.starts_with("4: ")),
        "DDATA: a name or datatype:\n{ddata}"
    );

    // NCMD Rebirth: NBIRTH (seq 0, the same bdSeq) and both DBIRTHs again.
    spb::publish(&scene.broker, &["rebirth", "--group", "plant", "--node", "births-and-data"]);
    wait_for(&scene.recorder, "DBIRTH", Some("servo"), 2, Duration::from_secs(10));
    wait_for(&scene.recorder, "DBIRTH", Some("inverter"), 2, Duration::from_secs(10));

    let verdict = finish(
        scene,
        bridge,
        1,
        &[
            "--no-historical",
            "--expect-unit",
            "inverter/d001=Hz",
            "--expect-unit",
            "inverter/F001=Hz",
            "--expect-unit",
            "inverter/d002=A",
            "--expect-unit",
            "servo/motor-speed=r/min",
            "--series",
            "inverter/d001",
        ],
    );
    verdict.assert_clean();
    let sessions = verdict.sessions();
    assert_eq!(sessions.len(), 1, "a rebirth keeps the session and its bdSeq:\n{verdict}");
    assert_eq!(sessions[0]["rebirths"], 1, "{verdict}");
    assert_eq!((&sessions[0]["nbirth_qos"], &sessions[0]["nbirth_retain"]), (&0.into(), &false.into()), "{verdict}");
    assert_eq!(sessions[0]["ndeath_bdseq"], sessions[0]["bdseq"], "{verdict}");
    assert_eq!(verdict.metric("inverter", "d001", "datatype"), "DOUBLE", "{verdict}");
    assert_eq!(verdict.metric("inverter", "running", "datatype"), "BOOLEAN", "{verdict}");
    let d001: Vec<f64> = verdict.series("inverter", "d001").iter().filter_map(|p| p["value"].as_f64()).collect();
    assert!(d001.iter().any(|&f| f > 0.0), "the output frequency never rose in DDATA: {d001:?}\n{verdict}");
    same_as_our_types(&verdict);
}

/// Our own payload types (ferrobus_bridge::sparkplug) read every recorded edge message, and
/// the last DBIRTH of each device has the names and aliases pysparkplug read.
fn same_as_our_types(verdict: &Verdict) {
    let recorded = spb::messages_in(&verdict.recording);
    for m in recorded.iter().filter(|m| m.topic.starts_with("spBv1.0/") && !m.topic.contains("/STATE/")) {
        let decoded = Payload::decode(&m.payload);
        assert!(decoded.is_ok(), "ferrobus_bridge cannot decode {}: {decoded:?}", m.topic);
    }
    for device in ["inverter", "servo"] {
        let Some(birth) = recorded.iter().rev().find(|m| spb::is(m, "DBIRTH", Some(device))) else {
            panic!("no DBIRTH of {device}")
        };
        let ours = Payload::decode(&birth.payload).unwrap_or_default();
        assert!(!ours.metrics.is_empty(), "{device}: no metrics in its DBIRTH");
        for metric in &ours.metrics {
            let name = metric.name.clone().unwrap_or_default();
            let theirs = verdict.metric(device, &name, "alias").as_u64();
            assert_eq!(metric.alias, theirs, "{device}/{name}: our alias and pysparkplug's:\n{verdict}");
        }
    }
}

fn decode_first(message: Option<Message>, dir: &std::path::Path, name: &str) -> String {
    let Some(message) = message else { panic!("no {name} recorded") };
    spb::decode_raw(&message.payload, dir, name)
}

#[test]
fn a_sigkill_brings_the_will_ndeath_with_the_nbirth_bdseq_and_a_restart_the_next_bdseq() {
    let Some(_turn) = spb::require() else { return };
    let scene = scene("sigkill-restart");
    let mut bridge = Bridge::start(&scene.config, &[]);
    wait_for(&scene.recorder, "DBIRTH", Some("inverter"), 1, BIRTHS_WITHIN);
    bridge.kill();
    wait_for(&scene.recorder, "NDEATH", None, 1, Duration::from_secs(10));
    let bridge = Bridge::start(&scene.config, &[]);
    wait_for(&scene.recorder, "DBIRTH", Some("inverter"), 2, BIRTHS_WITHIN);
    let verdict = finish(scene, bridge, 2, &["--no-historical"]);
    verdict.assert_clean();
    let sessions = verdict.sessions();
    assert_eq!(sessions.len(), 2, "one session per run:\n{verdict}");
    let (first, second) = (&sessions[0], &sessions[1]);
    assert_eq!(first["ndeath_bdseq"], first["bdseq"], "the Will's bdSeq is the NBIRTH's:\n{verdict}");
    assert_eq!(first["ndeath_qos"], 1, "the Will is QoS 1:\n{verdict}");
    assert_eq!(first["ndeath_retain"], false, "{verdict}");
    let next = first["bdseq"].as_u64().map(|b| (b + 1) % 256);
    assert_eq!(second["bdseq"].as_u64(), next, "the restart takes the next bdSeq:\n{verdict}");
    assert_eq!(second["ndeath_bdseq"], second["bdseq"], "{verdict}");
}

/// The alias of `metric` in the device's DBIRTH, from what has been recorded so far.
fn alias_of(recorder: &Recorder, device: &str, metric: &str) -> u64 {
    let verdict = spb::verify(recorder.path(), &[]);
    verdict.metric(device, metric, "alias").as_u64().unwrap_or_else(|| panic!("no alias of {metric}:\n{verdict}"))
}

/// Waits until the drive's F001 reads `expected`.
fn wait_f001(drive: &Drive, expected: &str, bridge: &Bridge) {
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    let mut seen = f001(drive);
    while seen != expected && std::time::Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(100));
        seen = f001(drive);
    }
    assert_eq!(seen, expected, "F001 on the drive after the DCMD; the bridge said:\n{}", bridge.output());
}

#[test]
fn a_dcmd_sets_f001_on_the_drive_by_name_or_alias_and_one_out_of_range_is_refused() {
    let Some(_turn) = spb::require() else { return };
    let scene = scene("dcmd-f001");
    let bridge = Bridge::start(&scene.config, &[]);
    wait_for(&scene.recorder, "DBIRTH", Some("inverter"), 1, BIRTHS_WITHIN);
    let broker = &scene.broker;
    let to_inverter = ["dcmd", "--group", "plant", "--node", "dcmd-f001", "--device", "inverter"];
    let dcmd = |how: &[&str]| spb::publish(broker, &[&to_inverter[..], how].concat());

    dcmd(&["--metric", "F001", "--datatype", "DOUBLE", "--value", "45.5"]);
    wait_f001(&scene.drive, "45.50 Hz", &bridge);
    let alias = alias_of(&scene.recorder, "inverter", "F001").to_string();
    dcmd(&["--alias", &alias, "--datatype", "DOUBLE", "--value", "12.25"]);
    wait_f001(&scene.drive, "12.25 Hz", &bridge);

    // 500 Hz is past F001's maximum (400.00 Hz); d001 is read-only: both refused, nothing written.
    dcmd(&["--metric", "F001", "--datatype", "DOUBLE", "--value", "500"]);
    dcmd(&["--metric", "d001", "--datatype", "DOUBLE", "--value", "10"]);
    // A name that would forge a status line if it were printed raw: refused, on one line.
    dcmd(&["--metric", FORGED, "--datatype", "DOUBLE", "--value", "0"]);
    std::thread::sleep(Duration::from_secs(1));
    assert_eq!(f001(&scene.drive), "12.25 Hz", "a refused DCMD changed F001; the bridge said:\n{}", bridge.output());
    wait_for(&scene.recorder, "DDATA", Some("inverter"), 2, Duration::from_secs(5));
    std::thread::sleep(Duration::from_millis(600)); // the next poll's DDATA
    let output = bridge.output();

    let verdict = finish(scene, bridge, 1, &["--no-historical", "--series", "inverter/F001"]);
    verdict.assert_clean();
    assert_eq!(verdict.summary["commands"], 5, "{verdict}");
    let f001: Vec<f64> = verdict.series("inverter", "F001").iter().filter_map(|p| p["value"].as_f64()).collect();
    // Before the writes, F001's first poll may give a DDATA of its own (the DBIRTH can come first).
    let written: Vec<f64> = f001.iter().copied().skip_while(|&f| (f - 45.5).abs() > 1e-9).collect();
    assert_eq!(written, [45.5, 12.25], "F001 in DDATA: the two writes, never 500:\n{verdict}");
    assert!(f001.len() <= 3, "F001 changed more often than written:\n{verdict}");
    let said = |what: &str| output.lines().any(|l| l.contains("refused") && l.contains(what));
    assert!(said("F001") && said("out of range") && said("d001 is read-only"), "the refusals are not said:\n{output}");
    assert!(
        !output.lines().any(|l| l.starts_with("bridge: wrote inverter F001 = 0.00 Hz")),
        "a forged line:\n{output}"
    );
    assert!(said(r"F001\nbridge: wrote inverter F001 = 0.00 Hz\r"), "the forged name is not escaped:\n{output}");
}

/// A DCMD metric name holding a newline, a forged status line and a carriage return (a command
/// line cannot carry a NUL; the library's hostile-input test sends those).
const FORGED: &str = "F001\nbridge: wrote inverter F001 = 0.00 Hz\r";

#[test]
fn a_drive_that_goes_silent_gets_a_ddeath_and_a_dbirth_when_it_answers_again() {
    let Some(_turn) = spb::require() else { return };
    let mut scene = scene("ddeath-dbirth");
    let bridge = Bridge::start(&scene.config, &[]);
    wait_for(&scene.recorder, "DBIRTH", Some("inverter"), 1, BIRTHS_WITHIN);
    scene.drive.stop();
    wait_for(&scene.recorder, "DDEATH", Some("inverter"), 1, Duration::from_secs(15));
    scene.drive.start_again();
    wait_for(&scene.recorder, "DBIRTH", Some("inverter"), 2, Duration::from_secs(30));
    let verdict = finish(scene, bridge, 1, &["--no-historical"]);
    verdict.assert_clean();
    assert_eq!(verdict.sessions().len(), 1, "the node's session goes on:\n{verdict}");
    assert_eq!(verdict.summary["devices"]["inverter"]["ddeaths"], 1, "{verdict}");
    assert_eq!(verdict.summary["devices"]["inverter"]["dbirths"], 2, "{verdict}");
}

/// `spBv1.0/STATE/scada` as a Sparkplug host application publishes it (QoS 1, retained).
fn host_state(broker: &Broker, online: bool) {
    let payload = format!("{{\"online\":{online},\"timestamp\":{}}}", now_ms());
    spb::publish(broker, &["text", "--topic", "spBv1.0/STATE/scada", "--payload", &payload, "--retain"]);
}

fn now_ms() -> u128 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_millis())
}

#[test]
fn with_a_primary_host_the_births_wait_for_its_state_online_and_end_when_it_goes_offline() {
    let Some(_turn) = spb::require() else { return };
    let scene = scene("primary-host");
    let dir = scene.config.parent().map(std::path::Path::to_path_buf).unwrap_or_default();
    Plant::sparkplug(scene.broker.port(), "plant", "primary-host")
        .primary_host("scada")
        .with("[store]\ndir = \"store\"")
        .tcp_line("tcp", scene.drive.address(), INVERTER)
        .write(&dir);
    let bridge = Bridge::start(&scene.config, &[]);
    std::thread::sleep(Duration::from_secs(2));
    assert_eq!(spb::count(&scene.recorder.messages(), "NBIRTH", None), 0, "births before the host is online");

    host_state(&scene.broker, true);
    wait_for(&scene.recorder, "DBIRTH", Some("inverter"), 1, BIRTHS_WITHIN);
    host_state(&scene.broker, false);
    wait_for(&scene.recorder, "NDEATH", None, 1, Duration::from_secs(10));
    host_state(&scene.broker, true);
    wait_for(&scene.recorder, "DBIRTH", Some("inverter"), 2, BIRTHS_WITHIN);
    let verdict = finish(scene, bridge, 2, &[]);
    verdict.assert_clean();
    // What was polled while the host was away comes after the births, as history.
    assert!(verdict.historical_count() > 0, "the samples before the host was online:\n{verdict}");
    let sessions = verdict.sessions();
    assert_eq!(sessions.len(), 2, "the host offline ends the session, online again starts one:\n{verdict}");
    assert_eq!(sessions[0]["ndeath_bdseq"], sessions[0]["bdseq"], "{verdict}");
    let next = sessions[0]["bdseq"].as_u64().map(|b| (b + 1) % 256);
    assert_eq!(sessions[1]["bdseq"].as_u64(), next, "{verdict}");
}
