//! A listen line (`mode = "listen"`) in plain mode: `ferrobus line --tap` with a simulated
//! 3G3RX on one drop, `ferrobus set` and `ferrobus get` as the bus's own master on another,
//! and the bridge on the tap, transmitting nothing. What it publishes is what `get` read, at
//! the time the reply was on the wire; a `.../set` to its device is refused, and the line's
//! statistics show that only the master and the drive sent a byte. In Sparkplug mode the
//! values written and read back come as DDATA that pysparkplug's checker passes, each metric
//! stamped with its wire time.

use std::process::Command;
use std::time::{Duration, SystemTime};

use ferrobus_tools::poll::iso8601_ms;
use serde_json::Value;

use super::harness::{Bridge, Plant};
use super::spb::{self, Message, Recorder};
use crate::support::mosquitto::Broker;
use crate::support::process::{Proc, Stream};

const PREFIX: &str = "listening";

/// The points published, and what `get` reads of them.
const POINTS: [&str; 3] = ["F001", "F002", "A004"];

fn ferrobus(args: &[&str]) -> Value {
    let out = Command::new(env!("CARGO_BIN_EXE_ferrobus")).args(args).output().expect("ferrobus runs");
    assert!(out.status.success(), "ferrobus {args:?}: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap_or(Value::Null)
}

/// The JSON of the messages on `topic`, in order.
fn json_on(messages: &[Message], topic: &str) -> Vec<Value> {
    messages.iter().filter(|m| m.topic == topic).filter_map(|m| serde_json::from_slice(&m.payload).ok()).collect()
}

#[test]
fn a_listen_line_publishes_what_the_buss_own_master_read_at_its_wire_time_and_refuses_a_set() {
    let Some(_turn) = spb::require() else { return };
    let broker = Broker::start();
    let dir = spb::evidence_dir("listen-line");
    let recorder = Recorder::start(&broker, &dir, &[&format!("{PREFIX}/#")]);
    let mut bus = Bus::start(&dir);
    let config = Plant::plain(broker.port(), PREFIX, false).with(&bus.listen_line()).write(&dir);
    let mut bridge = Bridge::start(&config, &[]);
    recorder.wait_until("the bridge online", Duration::from_secs(20), |m| {
        m.iter().any(|m| m.topic == format!("{PREFIX}/status") && m.text() == "online")
    });

    // The bus's master: a write of F001, then reads of all three.
    let before = iso8601_ms(SystemTime::now() - Duration::from_millis(1));
    bus.master(&["set", "F001", "45.5Hz"]);
    let read = bus.master(&[&["get", "--json"], &POINTS[..]].concat());
    let after = iso8601_ms(SystemTime::now() + Duration::from_millis(1));
    let topic = |code: &str| format!("{PREFIX}/inverter/{code}");
    let messages = recorder.wait_until("the three points published", Duration::from_secs(20), |m| {
        POINTS.iter().all(|code| !json_on(m, &topic(code)).is_empty())
    });
    for point in read["points"].as_array().expect("get's points") {
        let code = point["code"].as_str().unwrap_or_default();
        let published = json_on(&messages, &topic(code));
        let last = published.last().unwrap_or_else(|| panic!("{code}:\n{}", spb::listing(&messages)));
        assert_eq!(last["value"].as_f64(), point["engineering"].as_f64(), "{code}: {last} against get's {point}");
        assert_eq!(last["unit"], point["unit"], "{code}: {last}");
        assert_eq!(last["quality"], "good", "{code}: {last}");
        // Seen between the master's first request and get's return (ISO 8601 to the
        // millisecond, which sorts as text).
        let stamp = last["timestamp"].as_str().unwrap_or_default();
        assert!((before.as_str()..=after.as_str()).contains(&stamp), "{code} at {stamp}, not in {before}..{after}");
    }
    assert_eq!(read["points"][0]["value"], "45.50 Hz");

    // A set to a device of a listen line: refused, nothing sent.
    spb::publish(&broker, &["text", "--topic", &format!("{}/set", topic("F002")), "--payload", "20"]);
    let results = |m: &[Message]| json_on(m, &format!("{}/set/result", topic("F002")));
    let messages = recorder.wait_until("the set's refusal", Duration::from_secs(10), |m| !results(m).is_empty());
    let refusal = &results(&messages)[0];
    assert_eq!(refusal["ok"], false, "{refusal}");
    assert!(refusal["error"].as_str().is_some_and(|e| e.contains("only listens")), "{refusal}");
    bridge.terminate();
    bus.assert_tap_silent();
}

#[test]
fn a_listen_line_publishes_sparkplug_ddata_of_what_the_master_wrote_and_read_at_its_wire_time() {
    let Some(_turn) = spb::require() else { return };
    let broker = Broker::start();
    let dir = spb::evidence_dir("listen-line-sparkplug");
    let recorder = Recorder::start(&broker, &dir, &[]);
    let mut bus = Bus::start(&dir);
    let config = Plant::sparkplug(broker.port(), "listen-g", "listen-edge").with(&bus.listen_line()).write(&dir);
    let mut bridge = Bridge::start(&config, &[]);
    recorder.wait_until("the NBIRTH", Duration::from_secs(20), |m| spb::count(m, "NBIRTH", None) >= 1);
    // The master's first reads: the device is heard, and born with what they read.
    bus.master(&[&["get", "--json"], &POINTS[..]].concat());
    recorder.wait_until("the DBIRTH", Duration::from_secs(20), |m| spb::count(m, "DBIRTH", Some("inverter")) >= 1);
    // Then it writes two of them and reads them back: DDATA with the values written.
    let millis = |t: SystemTime| t.duration_since(SystemTime::UNIX_EPOCH).unwrap_or_default().as_millis();
    let before = millis(SystemTime::now());
    bus.master(&["set", "F001", "45.5Hz"]);
    bus.master(&["set", "F002", "12.5s"]);
    let read = bus.master(&[&["get", "--json"], &POINTS[..]].concat());
    let after = millis(SystemTime::now());
    recorder
        .wait_until("the DDATA of both", Duration::from_secs(20), |m| spb::count(m, "DDATA", Some("inverter")) >= 2);
    bridge.terminate();
    recorder.wait_until("the NDEATH", Duration::from_secs(10), |m| spb::count(m, "NDEATH", None) >= 1);
    let path = recorder.stop();
    let verdict = spb::verify(&path, &["--series", "inverter/F001", "--series", "inverter/F002"]);
    verdict.assert_clean();
    for code in ["F001", "F002"] {
        let engineering = read["points"].as_array().and_then(|p| p.iter().find(|p| p["code"] == code));
        let engineering = engineering.and_then(|p| p["engineering"].as_f64()).unwrap_or_else(|| panic!("{read}"));
        let series = verdict.series("inverter", code);
        let last = series.last().unwrap_or_else(|| panic!("no DDATA of {code}:\n{verdict}"));
        assert_eq!(last["value"].as_f64(), Some(engineering), "{code}: {last}\n{verdict}");
        let stamp = u128::from(last["timestamp"].as_u64().unwrap_or_default());
        assert!((before..=after).contains(&stamp), "{code} seen at {stamp}, not in {before}..{after}: {last}");
    }
    assert_eq!(read["points"][1]["value"], "12.50 s", "{read}");
    bus.assert_tap_silent();
}

/// `ferrobus line --tap` with a simulated 3G3RX (unit 1) on its second drop: the master's
/// drop, the tap, and the line's statistics.
struct Bus {
    line: Proc,
    _sim: Proc,
    master: String,
    tap: String,
    stats: std::path::PathBuf,
}

impl Bus {
    fn start(dir: &std::path::Path) -> Bus {
        let stats = dir.join("line-stats.json");
        let mut line_command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
        line_command.args(["line", "--tap", "--stats-json"]).arg(&stats);
        let line = Proc::spawn("ferrobus line --tap", &mut line_command);
        let ready = Duration::from_secs(20);
        let [master, drive, tap] =
            [(); 3].map(|()| line.wait_for(Stream::Out, |l| l.starts_with('/'), ready).trim().to_string());
        let mut sim_command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
        sim_command.args(["--port", &drive, "sim", "--profile", "omron-3g3rx"]);
        let sim = Proc::spawn("ferrobus sim", &mut sim_command);
        sim.wait_for(Stream::Err, |l| l.contains("serving on"), ready);
        Bus { line, _sim: sim, master, tap, stats }
    }

    /// A listen line on the tap with the drive as device `inverter`, its [`POINTS`] published.
    fn listen_line(&self) -> String {
        format!(
            "[[line]]\nname = \"plc\"\nport = \"{}\"\nmode = \"listen\"\n\n\
             [[line.device]]\nid = \"inverter\"\nunit = 1\nprofile = \"omron-3g3rx\"\n\
             points = [\"F001\", \"F002\", \"A004\"]\n",
            self.tap
        )
    }

    /// `ferrobus --port MASTER --device omron-3g3rx ARGS`, the bus's own master; its JSON, if any.
    fn master(&self, args: &[&str]) -> Value {
        ferrobus(&[&["--port", self.master.as_str(), "--device", "omron-3g3rx"][..], args].concat())
    }

    /// Stops the line and asserts that the tap (its third endpoint) was given no byte to send:
    /// the bridge transmitted nothing.
    fn assert_tap_silent(&mut self) {
        self.line.terminate();
        let text = std::fs::read_to_string(&self.stats).expect("the line's statistics");
        let stats: Value = serde_json::from_str(&text).expect("the statistics are JSON");
        let tap = &stats["endpoints"][2];
        assert_eq!(
            (&tap["tap"], &tap["refused"], &tap["characters"]),
            (&Value::Bool(true), &0.into(), &0.into()),
            "{stats}"
        );
    }
}
