//! A listen line (`mode = "listen"`) in plain mode: `ferrobus line --tap` with a simulated
//! 3G3RX on one drop, `ferrobus set` and `ferrobus get` as the bus's own master on another,
//! and the bridge on the tap, transmitting nothing. What it publishes is what `get` read, at
//! the time the reply was on the wire; a `.../set` to its device is refused, and the line's
//! statistics show that only the master and the drive sent a byte.

use std::process::Command;
use std::time::{Duration, SystemTime};

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

fn seconds(t: SystemTime) -> f64 {
    t.duration_since(SystemTime::UNIX_EPOCH).unwrap_or_default().as_secs_f64()
}

#[test]
fn a_listen_line_publishes_what_the_buss_own_master_read_at_its_wire_time_and_refuses_a_set() {
    let Some(_turn) = spb::require() else { return };
    let broker = Broker::start();
    let dir = spb::evidence_dir("listen-line");
    let recorder = Recorder::start(&broker, &dir, &[&format!("{PREFIX}/#")]);
    let stats = dir.join("line-stats.json");
    let mut line_command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
    line_command.args(["line", "--tap", "--stats-json"]).arg(&stats);
    let mut line = Proc::spawn("ferrobus line --tap", &mut line_command);
    let ready = Duration::from_secs(20);
    let [master, drive, tap] =
        [(); 3].map(|()| line.wait_for(Stream::Out, |l| l.starts_with('/'), ready).trim().to_string());
    let mut sim_command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
    sim_command.args(["--port", &drive, "sim", "--profile", "omron-3g3rx"]);
    let sim = Proc::spawn("ferrobus sim", &mut sim_command);
    sim.wait_for(Stream::Err, |l| l.contains("serving on"), ready);

    let devices = "[[line.device]]\nid = \"inverter\"\nunit = 1\nprofile = \"omron-3g3rx\"\n\
                   points = [\"F001\", \"F002\", \"A004\"]\n";
    let config = Plant::plain(broker.port(), PREFIX, false)
        .with(&format!("[[line]]\nname = \"plc\"\nport = \"{tap}\"\nmode = \"listen\"\n\n{devices}"))
        .write(&dir);
    let mut bridge = Bridge::start(&config, &[]);
    recorder.wait_until("the bridge online", Duration::from_secs(20), |m| {
        m.iter().any(|m| m.topic == format!("{PREFIX}/status") && m.text() == "online")
    });

    // The bus's master: a write of F001, then reads of all three.
    let device = ["--port", master.as_str(), "--device", "omron-3g3rx"];
    let before = SystemTime::now();
    ferrobus(&[&device[..], &["set", "F001", "45.5Hz"]].concat());
    let read = ferrobus(&[&device[..], &["get", "--json"], &POINTS[..]].concat());
    let after = SystemTime::now();
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
        // Seen between the master's first request and get's return.
        let stamp = last["timestamp"].as_str().unwrap_or_default();
        let at = stamp_seconds(stamp).unwrap_or_else(|| panic!("{code}: not an ISO 8601 time: {last}"));
        assert!(at >= seconds(before) - 0.001 && at <= seconds(after) + 0.001, "{code} at {stamp}: {last}");
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
    line.terminate();
    let stats: Value = serde_json::from_str(&std::fs::read_to_string(&stats).expect("the line's statistics"))
        .expect("the statistics are JSON");
    // The bridge transmitted nothing: the tap (the third endpoint) was given no byte to send.
    let tap = &stats["endpoints"][2];
    assert_eq!(
        (&tap["tap"], &tap["refused"], &tap["characters"]),
        (&Value::Bool(true), &0.into(), &0.into()),
        "{stats}"
    );
    drop(sim);
}

/// Seconds since 1970 of `YYYY-MM-DDTHH:MM:SS.fffZ`.
fn stamp_seconds(stamp: &str) -> Option<f64> {
    let (date, time) = stamp.strip_suffix('Z')?.split_once('T')?;
    let mut d = date.split('-').map(|p| p.parse::<i64>().ok());
    let (y, m, day) = (d.next()??, d.next()??, d.next()??);
    let mut t = time.split(':');
    let (h, min, s) = (t.next()?.parse::<f64>().ok()?, t.next()?.parse::<f64>().ok()?, t.next()?.parse::<f64>().ok()?);
    // Days from civil (Howard Hinnant).
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let doy = (153 * (m + if m > 2 { -3 } else { 9 }) + 2) / 5 + day - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    let days = era * 146_097 + doe - 719_468;
    #[allow(clippy::cast_precision_loss)]
    Some(days as f64 * 86_400.0 + h * 3600.0 + min * 60.0 + s)
}
