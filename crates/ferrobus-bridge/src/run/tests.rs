//! The bridge against a real mosquitto, started here on a free port: the births arrive, a stop
//! publishes NDEATH with the NBIRTH's bdSeq, and the next run takes the next bdSeq (kept in
//! the store's folder). Skipped with a message when mosquitto is missing, failed under CI=true.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};
use tokio::sync::{mpsc, oneshot};

use super::*;
use crate::sparkplug::payload::{MetricValue, Payload};

/// A mosquitto of this test, stopped when dropped.
struct Broker {
    child: Child,
    port: u16,
    dir: PathBuf,
}

impl Drop for Broker {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

fn mosquitto() -> Option<PathBuf> {
    let candidates = [PathBuf::from("/usr/sbin/mosquitto"), PathBuf::from("/usr/local/sbin/mosquitto")];
    let found = candidates.into_iter().find(|p| p.exists()).or_else(|| {
        std::env::var_os("PATH")
            .and_then(|paths| std::env::split_paths(&paths).map(|d| d.join("mosquitto")).find(|p| p.exists()))
    });
    if found.is_none() {
        assert!(std::env::var("CI").as_deref() != Ok("true"), "mosquitto is missing (CI installs it: apt mosquitto)");
        eprintln!("skipped: mosquitto is not installed (apt install mosquitto)");
    }
    found
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").and_then(|l| l.local_addr()).map(|a| a.port()).expect("a free port")
}

async fn start_broker(name: &str) -> Option<Broker> {
    let program = mosquitto()?;
    let port = free_port();
    let dir = std::env::temp_dir().join(format!("ferrobus-run-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("a temporary folder");
    let conf = dir.join("mosquitto.conf");
    std::fs::write(&conf, format!("listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\n"))
        .expect("the broker's configuration");
    let child = Command::new(program)
        .arg("-c")
        .arg(&conf)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("mosquitto starts");
    let broker = Broker { child, port, dir };
    for _ in 0..100 {
        if tokio::net::TcpStream::connect(("127.0.0.1", port)).await.is_ok() {
            return Some(broker);
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    panic!("mosquitto did not listen on {port}");
}

/// Every message on `spBv1.0/#`, once subscribed.
async fn subscribe(port: u16) -> mpsc::UnboundedReceiver<(String, Vec<u8>)> {
    let mut options = MqttOptions::new(format!("watcher-{port}"), "127.0.0.1", port);
    options.set_max_packet_size(1 << 20, 1 << 20);
    let (client, mut eventloop) = AsyncClient::new(options, 16);
    client.subscribe("spBv1.0/#", QoS::AtLeastOnce).await.expect("subscribe queued");
    let (tx, rx) = mpsc::unbounded_channel();
    let (subscribed_tx, subscribed) = oneshot::channel();
    tokio::spawn(async move {
        let _client = client;
        let mut subscribed_tx = Some(subscribed_tx);
        while let Ok(event) = eventloop.poll().await {
            match event {
                Event::Incoming(Packet::SubAck(_)) => {
                    if let Some(s) = subscribed_tx.take() {
                        let _ = s.send(());
                    }
                }
                Event::Incoming(Packet::Publish(p)) => {
                    let _ = tx.send((p.topic.clone(), p.payload.to_vec()));
                }
                _ => {}
            }
        }
    });
    tokio::time::timeout(Duration::from_secs(5), subscribed).await.expect("subscribed in time").expect("subscribed");
    rx
}

/// Waits for a message whose topic has `kind` at its message type's place.
async fn next_of(rx: &mut mpsc::UnboundedReceiver<(String, Vec<u8>)>, kind: MessageType) -> (String, Payload) {
    let wait = async {
        while let Some((topic, payload)) = rx.recv().await {
            if Topic::parse(&topic).is_some_and(|t| t.kind == kind) {
                return (topic, Payload::decode(&payload).expect("a Sparkplug payload"));
            }
        }
        panic!("the watcher stopped");
    };
    tokio::time::timeout(Duration::from_secs(20), wait).await.unwrap_or_else(|_| panic!("no {} in 20 s", kind.as_str()))
}

fn bd_seq(payload: &Payload) -> Option<u64> {
    payload.metrics.iter().find(|m| m.name.as_deref() == Some("bdSeq")).and_then(|m| match m.value {
        Some(MetricValue::Long(n)) => Some(n),
        Some(MetricValue::Int(n)) => Some(u64::from(n)),
        _ => None,
    })
}

fn demo_plant(port: u16, store: &Path) -> Plant {
    let mut plant = Plant::demo(&format!("127.0.0.1:{port}")).expect("the demo plant");
    plant.store.dir = Some(store.to_path_buf());
    plant
}

/// One run of the demo plant until its births are seen; stopped, it returns the NBIRTH's and
/// the NDEATH's bdSeq and the report.
async fn one_run(port: u16, store: &Path) -> (u64, u64, Report) {
    let mut watcher = subscribe(port).await;
    let plant = demo_plant(port, store);
    let devices = plant.lines.iter().map(|l| l.devices.len()).sum::<usize>();
    let (stop_tx, stop_rx) = oneshot::channel::<()>();
    let bridge = tokio::spawn(run(plant, async move { drop(stop_rx.await) }, None));
    let (_, birth) = next_of(&mut watcher, MessageType::NBirth).await;
    assert_eq!(birth.seq, Some(0), "NBIRTH has seq 0");
    for _ in 0..devices {
        next_of(&mut watcher, MessageType::DBirth).await;
    }
    stop_tx.send(()).expect("the bridge runs");
    let report = bridge.await.expect("the bridge's task").expect("the bridge ran");
    let (_, death) = next_of(&mut watcher, MessageType::NDeath).await;
    (bd_seq(&birth).expect("NBIRTH has a bdSeq"), bd_seq(&death).expect("NDEATH has a bdSeq"), report)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn births_arrive_a_stop_publishes_ndeath_and_the_next_run_takes_the_next_bd_seq() {
    let Some(broker) = start_broker("births").await else { return };
    let store = broker.dir.join("store");
    let (birth, death, report) = one_run(broker.port, &store).await;
    assert_eq!(birth, death, "NDEATH carries the NBIRTH's bdSeq");
    assert_eq!(report.published("NBIRTH"), 1, "{report}");
    assert_eq!(report.published("NDEATH"), 1, "{report}");
    assert_eq!(report.connections, 1, "{report}");
    let kept = std::fs::read_to_string(store.join(state::FILE_NAME)).expect("the bdSeq file");
    assert_eq!(kept.trim(), birth.to_string(), "the bdSeq of the CONNECT is kept");
    let (again, _, _) = one_run(broker.port, &store).await;
    assert_eq!(again, (birth + 1) % 256, "a restart takes the next bdSeq");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unreachable_broker_is_retried_with_backoff_while_the_lines_poll() {
    let port = free_port();
    let dir = std::env::temp_dir().join(format!("ferrobus-run-unreachable-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let plant = demo_plant(port, &dir.join("store"));
    let (status_tx, mut statuses) = mpsc::channel(256);
    let (stop_tx, stop_rx) = oneshot::channel::<()>();
    let bridge = tokio::spawn(run(plant, async move { drop(stop_rx.await) }, Some(status_tx)));
    let mut waits = Vec::new();
    while waits.len() < 2 {
        let status = tokio::time::timeout(Duration::from_secs(10), statuses.recv()).await.expect("a status");
        if let Some(Status::BrokerLost { retry_in, was_online: false, .. }) = status {
            waits.push(retry_in);
        }
    }
    assert_eq!(waits[1], waits[0] * 2, "the backoff doubles: {waits:?}");
    stop_tx.send(()).expect("the bridge runs");
    let report = bridge.await.expect("the bridge's task").expect("the bridge ran");
    assert_eq!(report.connections, 0);
    assert!(report.lines[0].ok > 0, "the line polls while the broker is away: {report}");
    assert_eq!(report.left, report.stored, "what was taken while the broker was away is kept: {report}");
    let _ = std::fs::remove_dir_all(&dir);
}
