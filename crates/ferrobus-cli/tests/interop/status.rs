//! `--metrics` on `gateway`, `sim`, `poll` and `bridge`: the status endpoint read as its users
//! read it. Prometheus's own client library parses `/metrics` (`prometheus_client`'s
//! OpenMetrics parser, which refuses what Prometheus would), `/healthz` answers a probe, and
//! the status page is loaded in headless Chromium, whose script fills it from `/status.json`:
//! the gateway's units with their health, the values poll last read.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::process::Command;
use std::time::Duration;

use serde_json::Value;

use crate::support::env::require_tool;
use crate::support::mosquitto::{self, Broker};
use crate::support::peers::free_port;
use crate::support::process::{Proc, Stream, output_within};
use crate::support::{Link, Over, Parity, TempDir, require, sim};

const STEP: Duration = Duration::from_secs(20);

/// GET `path` on `addr`: the status code and the body.
fn get(addr: &str, path: &str) -> (u16, String) {
    let mut stream = TcpStream::connect(addr).unwrap();
    write!(stream, "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n").unwrap();
    let mut answer = String::new();
    stream.read_to_string(&mut answer).unwrap();
    let code = answer.split(' ').nth(1).and_then(|c| c.parse().ok()).unwrap_or(0);
    let body = answer.split_once("\r\n\r\n").map(|(_, b)| b.to_string()).unwrap_or_default();
    (code, body)
}

/// `ferrobus --tcp GATEWAY --unit UNIT read holding ADDRESS`, its exit status.
fn read(gateway: &str, unit: &str, address: &str) -> bool {
    let mut command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
    command.args(["--tcp", gateway, "--timeout", "2s", "--unit", unit, "read", "holding", address]);
    output_within(&mut command, "", STEP).status.success()
}

/// The samples of an OpenMetrics text as Prometheus's Python client parses them: one JSON
/// object per sample (name, labels, value), or the parser's error.
const PARSE: &str = r#"
import json, sys
from prometheus_client.openmetrics.parser import text_string_to_metric_families
for family in text_string_to_metric_families(sys.stdin.read()):
    for s in family.samples:
        print(json.dumps({"family": family.name, "type": family.type, "name": s.name, "labels": s.labels, "value": s.value}))
"#;

fn python_has_prometheus_client() -> bool {
    Command::new("python3").args(["-c", "import prometheus_client"]).output().is_ok_and(|o| o.status.success())
}

#[test]
fn the_gateways_and_the_sims_metrics_parse_as_openmetrics_and_the_page_shows_each_units_health_in_a_browser() {
    let Some(_turn) = require(&[]) else { return };
    if !readers() {
        return;
    }
    let sim_status = format!("127.0.0.1:{}", free_port());
    let drive = sim(Over::Tcp, Parity::Even, &["--profile", "omron-3g3rx", "--metrics", &sim_status]);
    let Link::Tcp(device) = &drive.link else { unreachable!("a TCP sim") };
    let listen = format!("127.0.0.1:{}", free_port());
    let status = format!("127.0.0.1:{}", free_port());
    let mut command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
    command.args(["--tcp", device, "--timeout", "300ms", "gateway", "--listen", &listen, "--metrics", &status]);
    let gateway = Proc::spawn("ferrobus gateway --metrics", &mut command);
    let said = gateway.wait_for(Stream::Err, |l| l.starts_with("gateway: status on"), STEP);
    assert!(said.contains(&format!("http://{status}/")), "{said}");

    // The window of the units' health starts at the first look.
    assert_eq!(get(&status, "/status.json").0, 200);
    for _ in 0..3 {
        assert!(read(&listen, "1", "0"), "unit 1 answers through the gateway");
    }
    assert!(!read(&listen, "1", "60000"), "an address the drive does not have: 0x02");
    assert!(!read(&listen, "9", "0"), "no unit 9 behind it: 0x0B");

    let (code, text) = get(&status, "/metrics");
    assert_eq!(code, 200);
    let samples = parsed(&text);
    let value = |name: &str, labels: &[(&str, &str)]| value_of(&samples, name, labels);
    let unit1 = [("line", "0"), ("unit", "1")];
    assert_eq!(value("ferrobus_gateway_requests_total", &unit1), Some(4.0), "{text}");
    assert_eq!(value("ferrobus_gateway_replies_total", &unit1), Some(3.0), "{text}");
    assert_eq!(value("ferrobus_gateway_exceptions_total", &[("unit", "1"), ("code", "0x02")]), Some(1.0), "{text}");
    assert_eq!(value("ferrobus_gateway_timeouts_total", &[("unit", "9")]), Some(1.0), "{text}");
    assert_eq!(value("ferrobus_gateway_response_seconds_count", &unit1), Some(4.0), "{text}");
    assert_eq!(value("ferrobus_gateway_response_seconds_bucket", &[("unit", "1"), ("le", "+Inf")]), Some(4.0));
    assert_eq!(value("ferrobus_tcp_connections_accepted_total", &[]), Some(5.0), "five clients: {text}");
    let families: std::collections::BTreeSet<&str> = samples.iter().filter_map(|s| s["family"].as_str()).collect();
    assert!(families.contains("ferrobus_gateway_response_seconds"), "{families:?}");

    // The simulator behind it counts what reached it, over the gateway's one connection.
    let (code, text) = get(&sim_status, "/metrics");
    assert_eq!(code, 200);
    let samples = parsed(&text);
    let sim = |name: &str| value_of(&samples, name, &[]);
    assert!(sim("ferrobus_sim_requests_total") >= Some(4.0), "{text}");
    assert_eq!(sim("ferrobus_sim_reply_lateness_seconds_count"), sim("ferrobus_sim_replies_total"), "{text}");
    assert_eq!(sim("ferrobus_tcp_connections_accepted_total"), Some(1.0), "the gateway's one line: {text}");

    // The health of the window: let it pass, then the browser's first look shows it.
    std::thread::sleep(Duration::from_millis(2100));
    let dom = page(&status);
    assert!(dom.contains("<span id=\"health\" class=\"ok\">healthy</span>"), "{dom}");
    assert!(dom.contains("ferrobus gateway"), "{dom}");
    let table = dom.split("data-title=\"Units\"").nth(1).unwrap_or_default();
    assert!(table.contains("<td>1</td><td class=\"ok\">ok</td>"), "unit 1 answered: {table}");
    assert!(table.contains("<td>9</td><td class=\"silent\">silent</td>"), "unit 9 never did: {table}");
    // Healthy: one unit answered in the window (a probe after the page: the same window).
    assert_eq!(get(&status, "/healthz"), (200, "ok\n".to_string()));
    drop(gateway);
}

/// The status page at `status` as headless Chromium shows it once its script has run: the DOM.
fn page(status: &str) -> String {
    let profile = TempDir::new();
    let mut browser = Command::new("chromium");
    browser.args([
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--virtual-time-budget=3000",
    ]);
    browser.arg(format!("--user-data-dir={}", profile.path().display()));
    browser.args(["--dump-dom", &format!("http://{status}/")]);
    let page = output_within(&mut browser, "", Duration::from_secs(60));
    String::from_utf8_lossy(&page.stdout).into_owned()
}

/// Whether the tools these tests read the endpoint with are here (`SKIPPED` or, under CI, a
/// failure when not).
fn readers() -> bool {
    require_tool(
        python_has_prometheus_client(),
        "python3 prometheus_client",
        "pip install prometheus-client (or .ci/setup-peers.sh)",
    ) && require_tool(which("chromium"), "chromium", "apt install chromium (or .ci/setup-peers.sh)")
}

/// Scrapes `status` until `ready` holds of the parsed samples (at most 20 s); the last text.
fn scrape_until(status: &str, what: &str, ready: impl Fn(&[Value]) -> bool) -> (Vec<Value>, String) {
    let deadline = std::time::Instant::now() + STEP;
    loop {
        let (code, text) = get(status, "/metrics");
        assert_eq!(code, 200, "{text}");
        let samples = parsed(&text);
        if ready(&samples) {
            return (samples, text);
        }
        assert!(std::time::Instant::now() < deadline, "the metrics never showed {what}:\n{text}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn polls_metrics_export_the_values_it_reads_equal_to_get_and_its_page_shows_them_in_a_browser() {
    let Some(_turn) = require(&[]) else { return };
    if !readers() {
        return;
    }
    let drive = sim(Over::Tcp, Parity::Even, &["--profile", "omron-3g3rx"]);
    let Link::Tcp(device) = &drive.link else { unreachable!("a TCP sim") };
    let ferrobus = |args: &[&str]| {
        let mut command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
        command.args(["--tcp", device, "--timeout", "300ms", "--device", "omron-3g3rx"]).args(args);
        command
    };
    assert!(output_within(&mut ferrobus(&["set", "F001", "12.5"]), "", STEP).status.success());
    let status = format!("127.0.0.1:{}", free_port());
    // Unit 9 is not there: its group fails while unit 1's give values.
    let mut command =
        ferrobus(&["poll", "--every", "200ms", "--unit", "9", "holding", "1", "--unit", "1", "F001", "A004"]);
    command.args(["--jsonl", "--metrics", &status]);
    let poll = Proc::spawn("ferrobus poll --metrics", &mut command);
    let said = poll.wait_for(Stream::Err, |l| l.starts_with("poll: status on"), STEP);
    assert!(said.contains(&format!("http://{status}/")), "{said}");

    let up = |samples: &[Value], unit: &str| value_of(samples, "ferrobus_poll_up", &[("unit", unit)]);
    let (samples, text) =
        scrape_until(&status, "both units polled", |s| up(s, "1") == Some(1.0) && up(s, "9") == Some(0.0));
    let got = output_within(&mut ferrobus(&["get", "F001", "A004", "--json"]), "", STEP);
    let got: Value = serde_json::from_slice(&got.stdout).unwrap();
    for point in got["points"].as_array().unwrap() {
        let code = point["code"].as_str().unwrap();
        let exported = value_of(&samples, "ferrobus_poll_value", &[("point", code), ("unit", "1")]);
        assert_eq!(exported, point["engineering"].as_f64(), "{code}: poll exports what get reads\n{text}");
    }
    assert_eq!(value_of(&samples, "ferrobus_poll_value", &[("point", "F001")]), Some(12.5), "{text}");
    assert!(!text.contains("ferrobus_poll_value{group=\"u9"), "a failing group exports no value:\n{text}");
    let failed = value_of(&samples, "ferrobus_poll_failures_total", &[("unit", "9"), ("kind", "timeout")]);
    assert!(failed >= Some(1.0), "{text}");
    assert!(value_of(&samples, "ferrobus_poll_response_seconds_count", &[("unit", "1")]) >= Some(2.0), "{text}");
    // One group gives values: healthy.
    assert_eq!(get(&status, "/healthz"), (200, "ok\n".to_string()));

    let dom = page(&status);
    assert!(dom.contains("ferrobus poll"), "{dom}");
    let values = dom.split("data-title=\"Values\"").nth(1).unwrap_or_default();
    assert!(values.contains("<td>F001</td><td>12.50 Hz</td>"), "the last value read, as shown: {values}");
    let groups = dom.split("data-title=\"Groups\"").nth(1).unwrap_or_default();
    assert!(groups.contains("timeout: no reply from unit 9"), "how unit 9's group fails: {groups}");
    drop(poll);
}

#[test]
fn the_bridges_metrics_follow_its_broker_away_and_back_and_healthz_says_so() {
    let Some(_turn) = mosquitto::require() else { return };
    if !readers() {
        return;
    }
    let mut broker = Broker::start();
    let status = format!("127.0.0.1:{}", free_port());
    let mut command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
    command.args(["bridge", "--demo", "--broker", &broker.address(), "--metrics", &status]);
    let bridge = Proc::spawn("ferrobus bridge --demo --metrics", &mut command);
    bridge.wait_for(Stream::Err, |l| l.starts_with("bridge: status on"), STEP);

    let value = |samples: &[Value], name: &str, labels: &[(&str, &str)]| value_of(samples, name, labels);
    let (samples, text) = scrape_until(&status, "the session and the line's polls", |s| {
        value(s, "ferrobus_bridge_broker_connected", &[]) == Some(1.0)
            && value(s, "ferrobus_bridge_polls_total", &[("line", "rs485-demo")]) >= Some(4.0)
    });
    assert_eq!(value(&samples, "ferrobus_bridge_published_total", &[("type", "NBIRTH")]), Some(1.0), "{text}");
    assert_eq!(value(&samples, "ferrobus_bridge_published_total", &[("type", "DBIRTH")]), Some(2.0), "{text}");
    assert_eq!(value(&samples, "ferrobus_bridge_broker_sessions_total", &[]), Some(1.0), "{text}");
    assert_eq!(get(&status, "/healthz"), (200, "ok\n".to_string()));
    // The page shows every point's latest reading, as the bridge shows it.
    let dom = page(&status);
    let values = dom.split("data-title=\"Values\"").nth(1).unwrap_or_default();
    assert!(values.contains("<td>inverter</td><td>d001</td>"), "the inverter's d001: {values}");
    assert!(values.contains(" Hz</td>"), "a frequency as shown: {values}");

    // The broker goes: what is read is stored, and the probe fails saying why.
    broker.stop();
    let (samples, text) = scrape_until(&status, "the broker lost and records stored", |s| {
        value(s, "ferrobus_bridge_broker_connected", &[]) == Some(0.0)
            && value(s, "ferrobus_bridge_stored_total", &[]) >= Some(1.0)
    });
    assert_eq!(value(&samples, "ferrobus_bridge_broker_lost_total", &[]), Some(1.0), "{text}");
    let (code, why) = get(&status, "/healthz");
    assert_eq!(code, 503, "{why}");
    assert!(why.contains("not connected to the broker"), "{why}");

    // Back: a second session, the store replayed, healthy again.
    broker.start_again();
    let (samples, text) = scrape_until(&status, "a second session and the store replayed", |s| {
        value(s, "ferrobus_bridge_broker_sessions_total", &[]) == Some(2.0)
            && value(s, "ferrobus_bridge_replayed_total", &[]) >= Some(1.0)
    });
    assert!(value(&samples, "ferrobus_bridge_store_depth", &[]).is_some(), "{text}");
    assert_eq!(get(&status, "/healthz"), (200, "ok\n".to_string()));
    drop(bridge);
}

/// The samples of `text` as Prometheus's Python client parses them; a text it refuses fails.
fn parsed(text: &str) -> Vec<Value> {
    let mut parse = Command::new("python3");
    parse.args(["-c", PARSE]);
    let parsed = output_within(&mut parse, text, STEP);
    let refused = String::from_utf8_lossy(&parsed.stderr);
    assert!(parsed.status.success(), "prometheus_client refused it: {refused}\n{text}");
    String::from_utf8_lossy(&parsed.stdout).lines().map(|l| serde_json::from_str(l).unwrap()).collect()
}

/// The value of the first sample `name` with `labels`.
fn value_of(samples: &[Value], name: &str, labels: &[(&str, &str)]) -> Option<f64> {
    samples
        .iter()
        .find(|s| s["name"] == name && labels.iter().all(|(k, v)| s["labels"][*k] == *v))
        .and_then(|s| s["value"].as_f64())
}

fn which(program: &str) -> bool {
    Command::new(program).arg("--version").output().is_ok_and(|o| o.status.success())
}
