//! Store and forward, end to end: the broker is stopped for 30 s while the bridge polls a
//! register that changes all the time, then started again. Every value the bridge sampled
//! meanwhile must arrive once, in order, marked historical, with its original timestamp, and
//! live data must follow.
//!
//! The register is holding register 0 of a `generic` sim, which the test itself counts up
//! every 300 ms (`ferrobus write register`); the bridge polls it every 100 ms, so each value
//! is sampled at least once and published once (by exception). The broker keeps its
//! sessions across the restart (persistence on), so the recorder misses nothing the bridge
//! sends before the recorder itself is back.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use serde_json::Value;

use super::harness::{Bridge, Drive, Plant};
use super::spb::{self, Recorder};
use crate::support::mosquitto::Broker;

/// How long the broker stays away.
const OUTAGE: Duration = Duration::from_secs(30);
/// How often the test changes the register.
const STEP: Duration = Duration::from_millis(300);

const COUNTER: &str = "[[line.device]]\nid = \"counter\"\nunit = 1\nprofile = \"generic\"\n\
                       [[line.device.raw]]\ntable = \"holding\"\naddress = 0\ncount = 1\ntype = \"u16\"\n\
                       name = \"counter\"\nevery = \"100ms\"\n";

fn now_ms() -> u64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| u64::try_from(d.as_millis()).unwrap_or(u64::MAX))
}

/// Counts holding register 0 of `drive` up from 1 every [`STEP`] until `stop`; returns the
/// last value written.
fn count_up(drive: &Drive, stop: &Arc<AtomicBool>) -> thread::JoinHandle<u64> {
    let client = drive.client(1);
    let stop = Arc::clone(stop);
    thread::spawn(move || {
        let mut n = 0u64;
        while !stop.load(Ordering::Relaxed) {
            n += 1;
            client.run(&["write", "register", "0", &n.to_string()]).ok();
            thread::sleep(STEP);
        }
        n
    })
}

/// One DDATA value of the counter, from verify.py's series.
#[derive(Debug, Clone, Copy)]
struct Sample {
    value: u64,
    timestamp: u64,
    historical: bool,
}

fn samples(series: &[Value]) -> Vec<Sample> {
    series
        .iter()
        .filter_map(|p| {
            Some(Sample {
                value: p["value"].as_u64()?,
                timestamp: p["timestamp"].as_u64()?,
                historical: p["historical"].as_bool()?,
            })
        })
        .collect()
}

/// Strictly increasing values and timestamps.
fn strictly_increasing(samples: &[&Sample]) -> bool {
    samples.windows(2).all(|w| w[0].value < w[1].value && w[0].timestamp < w[1].timestamp)
}

#[test]
fn samples_taken_while_the_broker_is_away_for_30s_arrive_once_in_order_marked_historical() {
    let Some(_turn) = spb::require() else { return };
    let mut broker = Broker::start_persistent();
    let dir = spb::evidence_dir("broker-outage");
    let recorder = Recorder::start(&broker, &dir, &[]);
    let drive = Drive::start(&["--profile", "generic"]);
    let config = Plant::sparkplug(broker.port(), "plant", "outage")
        .with("[store]\ndir = \"store\"\nmemory = \"1MiB\"")
        .tcp_line("tcp", drive.address(), COUNTER)
        .write(&dir);
    let mut bridge = Bridge::start(&config, &[]);
    recorder.wait_until("the counter's DBIRTH", Duration::from_secs(20), |m| spb::count(m, "DBIRTH", None) >= 1);

    let stop = Arc::new(AtomicBool::new(false));
    let writer = count_up(&drive, &stop);
    thread::sleep(Duration::from_secs(2));
    let away = now_ms();
    broker.stop();
    thread::sleep(OUTAGE);
    broker.start_again();
    let back = now_ms();
    // The bridge's next attempt comes within its backoff (at most 30 s), then it replays.
    recorder.wait_until("a second NBIRTH", Duration::from_secs(45), |m| spb::count(m, "NBIRTH", None) >= 2);
    thread::sleep(Duration::from_secs(3));
    stop.store(true, Ordering::Relaxed);
    let last = writer.join().unwrap_or(0);
    thread::sleep(Duration::from_millis(500)); // the last value's poll and DDATA
    bridge.terminate();
    recorder.wait_until("the NDEATH", Duration::from_secs(10), |m| spb::count(m, "NDEATH", None) >= 1);
    let verdict = spb::verify(&recorder.stop(), &["--series", "counter/counter"]);
    verdict.assert_clean();
    let context = format!("broker away at {away} ms, back at {back} ms, last value written {last}\n{verdict}");

    let all = samples(&verdict.series("counter", "counter"));
    let historical: Vec<&Sample> = all.iter().filter(|s| s.historical).collect();
    let live: Vec<&Sample> = all.iter().filter(|s| !s.historical).collect();
    assert!(historical.len() >= 50, "{} historical samples for a 30 s outage at 300 ms:\n{context}", historical.len());
    assert!(strictly_increasing(&historical), "historical samples out of order or repeated:\n{context}");
    assert!(strictly_increasing(&live), "live samples out of order or repeated:\n{context}");
    let (first, last_historical) = (historical[0], historical[historical.len() - 1]);
    assert!(first.timestamp <= away + 1000, "the first historical sample is later than the outage:\n{context}");
    assert!(last_historical.timestamp >= back, "historical samples end before the broker was back:\n{context}");
    let widest = historical.windows(2).map(|w| w[1].timestamp - w[0].timestamp).max().unwrap_or(0);
    assert!(widest <= 1500, "a gap of {widest} ms between historical samples:\n{context}");
    assert!(
        live.iter().any(|s| s.value > last_historical.value),
        "no live data after the historical samples:\n{context}"
    );

    // Every value from the first to the last is there once: none lost, none twice. One
    // exception: a live DDATA (QoS 0, as Sparkplug wants) written in the moment the broker
    // went down, before the bridge knew, is lost with the connection; that can only be the
    // value just before the first historical one.
    let mut values: Vec<u64> = all.iter().map(|s| s.value).filter(|&v| v > 0).collect();
    values.sort_unstable();
    let (lowest, highest) = (values[0], values[values.len() - 1]);
    let missing: Vec<u64> = (lowest..=highest).filter(|v| values.binary_search(v).is_err()).collect();
    let in_flight = [first.value.saturating_sub(1)];
    let repeated = values.windows(2).filter(|w| w[0] == w[1]).count();
    assert!(
        (missing.is_empty() || missing == in_flight) && repeated == 0,
        "values missing {missing:?}, {repeated} repeated:\n{context}"
    );
    assert_eq!(verdict.historical_count(), historical.len(), "{context}");
}
