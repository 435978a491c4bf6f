//! The bridge against a real mosquitto, started here on a free port: the births arrive, a stop
//! publishes NDEATH with the NBIRTH's bdSeq, and the next run takes the next bdSeq (kept in
//! the store's folder). Skipped with a message when mosquitto is missing, failed under CI=true.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};
use tokio::sync::{mpsc, oneshot};

use ferrobus_tools::poll::FailureKind;

use super::*;
use crate::edge::{Health, answered};
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

fn temporary_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("ferrobus-run-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("a temporary folder");
    dir
}

async fn start_broker(name: &str) -> Option<Broker> {
    start_broker_with(name, "").await
}

/// A mosquitto whose listener takes the lines `listener` too (its TLS files).
async fn start_broker_with(name: &str, listener: &str) -> Option<Broker> {
    start_broker_on(free_port(), name, listener).await
}

/// A mosquitto listening on `port`.
async fn start_broker_on(port: u16, name: &str, listener: &str) -> Option<Broker> {
    let program = mosquitto()?;
    let dir = temporary_dir(name);
    let conf = dir.join("mosquitto.conf");
    let text = format!("listener {port} 127.0.0.1\n{listener}allow_anonymous true\npersistence false\n");
    std::fs::write(&conf, text).expect("the broker's configuration");
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
    // Large enough for the oversized messages the tests publish.
    options.set_max_packet_size(16 << 20, 1 << 20);
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

/// Every message until the NDEATH of the bridge's stop (that one included): topic and
/// payload. The broker passes messages in order and the NDEATH is the bridge's last, so
/// nothing it published before is missed and no quiet spell is waited for.
async fn until_ndeath(rx: &mut mpsc::UnboundedReceiver<(String, Vec<u8>)>) -> Vec<(String, Vec<u8>)> {
    let wait = async {
        let mut seen = Vec::new();
        while let Some((topic, payload)) = rx.recv().await {
            let death = Topic::parse(&topic).is_some_and(|t| t.kind == MessageType::NDeath);
            seen.push((topic, payload));
            if death {
                return seen;
            }
        }
        panic!("the watcher stopped before the NDEATH: {seen:?}");
    };
    tokio::time::timeout(Duration::from_secs(20), wait).await.expect("the stop's NDEATH in 20 s")
}

/// Waits (20 s at most) until `done` holds for the poller's counters of every group.
async fn polled_until(
    poll: &ferrobus_tools::poll::PollHandle,
    done: impl Fn(&[ferrobus_tools::poll::Counters]) -> bool,
) {
    let wait = async {
        while !done(&poll.counters()) {
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    };
    tokio::time::timeout(Duration::from_secs(20), wait).await.expect("the poller got there in 20 s");
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

/// The status line the bridge says for a poll of a device that failed with `kind` (`None`:
/// values).
fn said(health: &mut Health, kind: Option<FailureKind>) -> Option<String> {
    let result = match kind {
        None => Ok(Vec::new()),
        Some(kind) => Err(ferrobus_tools::poll::Failure { kind, exception: None, diagnosis: format!("{kind:?}") }),
    };
    let sample = Sample {
        group: 0,
        seq: 0,
        time: SystemTime::UNIX_EPOCH,
        due: Duration::ZERO,
        started: Duration::ZERO,
        response_time: Duration::ZERO,
        overrun: false,
        result,
        traffic: ferrobus_tools::poll::Traffic::default(),
    };
    let liveness = health.observe(answered(&sample.result), 3);
    health_status(liveness, &sample, || "d".to_string()).map(|s| s.to_string())
}

#[test]
fn the_status_lines_follow_the_edges_liveness_rule_death_after_silent_polls_and_an_exception_is_a_reply() {
    let mut health = Health::default();
    assert_eq!(said(&mut health, Some(FailureKind::Timeout)), None);
    assert_eq!(said(&mut health, Some(FailureKind::Crc)), None);
    let never = said(&mut health, Some(FailureKind::Port)).expect("given up after 3 polls");
    assert!(never.starts_with("device d does not answer (3 polls: Port)"), "{never}");
    assert_eq!(said(&mut health, Some(FailureKind::Exception)).as_deref(), Some("device d answers at last"));
    assert_eq!(said(&mut health, Some(FailureKind::Timeout)), None);
    assert_eq!(said(&mut health, Some(FailureKind::Timeout)), None);
    assert_eq!(said(&mut health, None), None, "an answer resets the count, and is not said while alive");
    assert_eq!(said(&mut health, Some(FailureKind::Timeout)), None);
    assert_eq!(said(&mut health, Some(FailureKind::Garbage)), None);
    let died = said(&mut health, Some(FailureKind::Timeout)).expect("the third silent poll in a row");
    assert_eq!(died, "device d stopped answering (3 polls: Timeout)");
    assert_eq!(said(&mut health, Some(FailureKind::Timeout)), None, "said once");
    assert_eq!(said(&mut health, Some(FailureKind::BadReply)).as_deref(), Some("device d answers again"));
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
    let dir = temporary_dir("unreachable");
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

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_live_view_shows_the_lines_polling_and_the_store_filling_while_the_broker_is_away() {
    let port = free_port();
    let dir = temporary_dir("live");
    let plant = demo_plant(port, &dir.join("store"));
    let (ask_tx, ask_rx) = mpsc::channel(4);
    let options = Options { live: Some(ask_rx), ..Options::default() };
    let (stop_tx, stop_rx) = oneshot::channel::<()>();
    let bridge = tokio::spawn(run_with(plant, async move { drop(stop_rx.await) }, None, options));
    let ask = |readings: bool| {
        let ask_tx = ask_tx.clone();
        async move {
            let (answer, answered) = oneshot::channel();
            ask_tx.send(LiveAsk { readings, answer }).await.expect("the bridge takes questions");
            answered.await.expect("the bridge answers")
        }
    };
    let seen = tokio::time::timeout(Duration::from_secs(20), async {
        loop {
            tokio::time::sleep(Duration::from_millis(100)).await;
            let now = ask(true).await;
            if now.report.lines.first().is_some_and(|l| l.ok > 0) && now.stored_now > 0 {
                return now;
            }
        }
    })
    .await
    .expect("the live view shows polls and stored records");
    // Asked for the counters only, it formats no reading.
    let counted = ask(false).await;
    assert!(counted.readings.is_empty() && counted.report.lines[0].ok >= seen.report.lines[0].ok, "{counted:?}");
    assert!(!seen.online, "no broker listens on {port}");
    assert_eq!(seen.report.connections, 0);
    // The demo's inverter reads its points: each with its value as shown, none failed.
    let inverter: Vec<&crate::edge::Reading> = seen.readings.iter().filter(|r| r.device == "inverter").collect();
    assert!(inverter.iter().any(|r| r.point == "d001" && r.shown.ends_with(" Hz") && !r.failed), "{inverter:?}");
    assert!(seen.readings.iter().all(|r| !r.failed && r.time > std::time::UNIX_EPOCH), "{:?}", seen.readings);
    stop_tx.send(()).expect("the bridge runs");
    let report = bridge.await.expect("the bridge's task").expect("the bridge ran");
    assert!(report.lines[0].ok >= seen.report.lines[0].ok, "the report at the end is not behind the live view");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A CA and a certificate for `broker.test` signed by it, made by openssl in `dir`; `None`
/// (skipped) without openssl.
fn certificates(dir: &Path) -> Option<()> {
    let openssl = |args: &[&str]| {
        Command::new("openssl").args(args).current_dir(dir).stdout(Stdio::null()).stderr(Stdio::null()).status()
    };
    if openssl(&["version"]).is_err() {
        assert!(std::env::var("CI").as_deref() != Ok("true"), "openssl is missing (CI installs it)");
        eprintln!("skipped: openssl is not installed");
        return None;
    }
    let ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:P-256", "-nodes"];
    std::fs::write(dir.join("san.ext"), "subjectAltName=DNS:broker.test\n").expect("the extension file");
    let steps: [&[&str]; 3] = [
        &[&["req", "-x509"][..], &ec, &["-keyout", "ca.key", "-out", "ca.pem", "-days", "2", "-subj", "/CN=test CA"]]
            .concat(),
        &[&["req"][..], &ec, &["-keyout", "server.key", "-out", "server.csr", "-subj", "/CN=broker.test"]].concat(),
        &[
            "x509",
            "-req",
            "-in",
            "server.csr",
            "-CA",
            "ca.pem",
            "-CAkey",
            "ca.key",
            "-CAcreateserial",
            "-out",
            "server.pem",
            "-days",
            "2",
            "-extfile",
            "san.ext",
        ],
    ];
    for step in steps {
        assert!(openssl(step).expect("openssl runs").success(), "openssl {step:?} failed");
    }
    // mosquitto started as root reads its files as the user `mosquitto`.
    #[cfg(unix)]
    for file in ["ca.pem", "server.pem", "server.key"] {
        let _ = std::fs::set_permissions(dir.join(file), std::os::unix::fs::PermissionsExt::from_mode(0o644));
    }
    Some(())
}

/// The first Connected or BrokerLost status.
async fn first_outcome(statuses: &mut mpsc::Receiver<Status>) -> Status {
    loop {
        let status = tokio::time::timeout(Duration::from_secs(10), statuses.recv())
            .await
            .expect("a status in time")
            .expect("the bridge runs");
        if matches!(status, Status::Connected { .. } | Status::BrokerLost { .. }) {
            return status;
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tls_to_the_broker_checks_its_certificate_against_the_server_name() {
    if mosquitto().is_none() {
        return;
    }
    let certs = temporary_dir("tls-certificates");
    if certificates(&certs).is_none() {
        return;
    }
    let files = format!("cafile {0}/ca.pem\ncertfile {0}/server.pem\nkeyfile {0}/server.key\n", certs.display());
    let Some(broker) = start_broker_with("tls", &files).await else { return };
    for (server_name, connects) in [(Some("broker.test"), true), (None, false)] {
        let mut plant = demo_plant(broker.port, &broker.dir.join("store"));
        plant.broker.tls = Some(crate::config::BrokerTls {
            ca: certs.join("ca.pem"),
            cert: None,
            key: None,
            server_name: server_name.map(str::to_string),
        });
        let (status_tx, mut statuses) = mpsc::channel(256);
        let (stop_tx, stop_rx) = oneshot::channel::<()>();
        let bridge = tokio::spawn(run(plant, async move { drop(stop_rx.await) }, Some(status_tx)));
        let outcome = first_outcome(&mut statuses).await;
        if connects {
            assert!(matches!(outcome, Status::Connected { .. }), "{outcome}");
        } else {
            // 127.0.0.1 is not the name in the certificate.
            assert!(matches!(&outcome, Status::BrokerLost { error, .. } if error.contains("name")), "{outcome}");
        }
        stop_tx.send(()).expect("the bridge runs");
        bridge.await.expect("the bridge's task").expect("the bridge ran");
    }
    let _ = std::fs::remove_dir_all(&certs);
}

/// Waits for a status that `wanted` picks.
async fn status_where(statuses: &mut mpsc::Receiver<Status>, wanted: impl Fn(&Status) -> bool) -> Status {
    loop {
        let status = tokio::time::timeout(Duration::from_secs(20), statuses.recv())
            .await
            .expect("a status in time")
            .expect("the bridge runs");
        if wanted(&status) {
            return status;
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn while_the_broker_is_away_samples_are_stored_and_replayed_as_historical_after_the_next_births() {
    let Some(broker) = start_broker("outage").await else { return };
    let port = broker.port;
    let store = temporary_dir("outage-store");
    let plant = demo_plant(port, &store);
    let f001 = plant.lines[0].devices[0].profile.as_ref().and_then(|p| p.point("F001")).expect("F001").clone();
    // The inverter is the line's first device: its groups are the poller's first.
    let f001_group = plant.lines[0].devices[0]
        .groups
        .iter()
        .position(|g| g.cells.iter().any(|c| c.name == "F001"))
        .expect("F001's group");
    let mut watcher = subscribe(port).await;
    let (status_tx, mut statuses) = mpsc::channel(1024);
    let (stop_tx, stop_rx) = oneshot::channel::<()>();
    let (running_tx, running) = oneshot::channel();
    let options = Options { running: Some(running_tx), ..Options::default() };
    let bridge = tokio::spawn(run_with(plant, async move { drop(stop_rx.await) }, Some(status_tx), options));
    let running = running.await.expect("the running lines");
    let (client, poll) = (running[0].client.clone().expect("a client"), running[0].poll.clone().expect("a poller"));
    let (_, first) = next_of(&mut watcher, MessageType::NBirth).await;
    next_of(&mut watcher, MessageType::DBirth).await;

    drop(broker);
    status_where(&mut statuses, |s| matches!(s, Status::BrokerLost { was_online: true, .. })).await;
    // F001 moves while the broker is away: each poll of it is a record. A poll that ends after
    // the write has returned was sent after it (the client asks one at a time): it read the value.
    for centi_hz in [1000, 2000, 3000] {
        let words = f001.encode(&ferrobus_tools::poll::Value::Int(centi_hz)).expect("F001 words");
        client.write_multiple_registers(1, f001.address, &words).await.expect("written");
        let before = poll.counters()[f001_group].ok;
        polled_until(&poll, |c| c[f001_group].ok > before).await;
    }
    // The broker comes back just after a failed attempt, the next one at least 2 s later: the
    // watcher is subscribed before the bridge is.
    while statuses.try_recv().is_ok() {}
    status_where(
        &mut statuses,
        |s| matches!(s, Status::BrokerLost { was_online: false, retry_in, .. } if *retry_in >= Duration::from_secs(2)),
    )
    .await;
    let broker = start_broker_on(port, "outage-again", "").await.expect("mosquitto again");
    let mut watcher = subscribe(port).await;
    let (_, second) = next_of(&mut watcher, MessageType::NBirth).await;
    assert_eq!(bd_seq(&second), bd_seq(&first).map(|b| (b + 1) % 256), "the next session, the next bdSeq");
    let replayed = status_where(&mut statuses, |s| matches!(s, Status::Replayed { .. })).await;
    stop_tx.send(()).expect("the bridge runs");
    let report = bridge.await.expect("the bridge's task").expect("the bridge ran");
    let mut historical = Vec::new();
    for (topic, payload) in until_ndeath(&mut watcher).await {
        let payload = Payload::decode(&payload).expect("a Sparkplug payload");
        if Topic::parse(&topic).is_some_and(|t| t.kind == MessageType::DData) {
            historical
                .extend(payload.metrics.iter().filter(|m| m.is_historical == Some(true)).map(|m| m.value.clone()));
        }
    }
    assert!(report.stored >= 3, "a record per F001 poll at least: {report}");
    assert_eq!(report.replayed, report.stored, "every record replayed: {report} ({replayed})");
    assert_eq!(report.left, 0, "{report}");
    for hz in [10.0, 20.0, 30.0] {
        assert!(
            historical.contains(&Some(MetricValue::Double(hz))),
            "F001 {hz} Hz replayed as historical: {historical:?}"
        );
    }
    drop(broker);
    let _ = std::fs::remove_dir_all(&store);
}

/// Publishes `payload` on `topic` at QoS 1 (retained if `retain`) and returns once the broker
/// has acknowledged it.
async fn publish_to(port: u16, topic: &str, payload: Vec<u8>, retain: bool) {
    let mut options = MqttOptions::new(format!("publisher-{port}"), "127.0.0.1", port);
    options.set_max_packet_size(1 << 20, 16 << 20);
    let (client, mut eventloop) = AsyncClient::new(options, 4);
    client.publish(topic, QoS::AtLeastOnce, retain, payload).await.expect("publish queued");
    let acked = async {
        loop {
            match eventloop.poll().await {
                Ok(Event::Incoming(Packet::PubAck(_))) => return,
                Ok(_) => {}
                Err(e) => panic!("publishing on {topic}: {e}"),
            }
        }
    };
    tokio::time::timeout(Duration::from_secs(10), acked).await.expect("the broker acknowledged in time");
    let _ = client.disconnect().await;
}

/// A DCMD to the demo's inverter setting F001 to `hz`.
fn dcmd_f001(hz: f64) -> Vec<u8> {
    let metric = crate::sparkplug::payload::Metric::new(
        "F001",
        crate::sparkplug::payload::DataType::Double,
        Some(MetricValue::Double(hz)),
    );
    Payload { metrics: vec![metric], ..Payload::default() }.encode()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn retained_2_mib_commands_are_discarded_and_counted_and_the_one_session_still_takes_a_good_dcmd() {
    let Some(broker) = start_broker("oversized").await else { return };
    let port = broker.port;
    let dcmd = Topic::device("ferrobus-demo", MessageType::DCmd, "demo-edge", "inverter").to_string();
    let ncmd = Topic::node("ferrobus-demo", MessageType::NCmd, "demo-edge").to_string();
    // Retained: the broker hands them over at every subscription, so each session meets them.
    for topic in [&dcmd, &ncmd] {
        publish_to(port, topic, vec![0x0A; 2 << 20], true).await;
    }
    let mut watcher = subscribe(port).await;
    let plant = demo_plant(port, &broker.dir.join("store"));
    let (status_tx, mut statuses) = mpsc::channel(1024);
    let (stop_tx, stop_rx) = oneshot::channel::<()>();
    let bridge = tokio::spawn(run(plant, async move { drop(stop_rx.await) }, Some(status_tx)));
    let seen = |s: &Status| matches!(s, Status::Discarded { .. } | Status::BrokerLost { .. });
    for _ in 0..2 {
        let discarded = status_where(&mut statuses, seen).await;
        assert!(discarded.to_string().contains("discarded a 2097"), "{discarded}");
    }
    publish_to(port, &dcmd, dcmd_f001(45.5), false).await;
    let written =
        status_where(&mut statuses, |s| matches!(s, Status::Written { .. } | Status::BrokerLost { .. })).await;
    assert!(matches!(&written, Status::Written { point, result: Ok(()), .. } if point == "F001"), "{written}");
    stop_tx.send(()).expect("the bridge runs");
    let report = bridge.await.expect("the bridge's task").expect("the bridge ran");
    assert_eq!((report.connections, report.broker_lost), (1, 0), "one session, never lost: {report}");
    assert_eq!(report.discarded, 2, "{report}");
    assert_eq!(report.writes, 1, "{report}");
    let kinds: Vec<MessageType> =
        until_ndeath(&mut watcher).await.iter().filter_map(|(topic, _)| Topic::parse(topic).map(|t| t.kind)).collect();
    let count = |kind| kinds.iter().filter(|k| **k == kind).count();
    assert_eq!(count(MessageType::NBirth), 1, "one NBIRTH: {kinds:?}");
    assert_eq!(count(MessageType::NDeath), 1, "only the stop's NDEATH: {kinds:?}");
    assert_eq!(kinds.last(), Some(&MessageType::NDeath), "{kinds:?}");
}

/// A TCP proxy to the broker on `broker_port` that takes one connection and passes nothing
/// either way until `release` fires: the CONNACK waits for the test. Returns its port.
async fn held_proxy(broker_port: u16, release: oneshot::Receiver<()>) -> u16 {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.expect("a proxy port");
    let port = listener.local_addr().expect("the proxy's address").port();
    tokio::spawn(async move {
        let Ok((mut bridge, _)) = listener.accept().await else { return };
        let _ = release.await;
        let mut broker = tokio::net::TcpStream::connect(("127.0.0.1", broker_port)).await.expect("the broker");
        let _ = tokio::io::copy_bidirectional(&mut bridge, &mut broker).await;
    });
    port
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn samples_polled_before_the_first_connack_are_live_data_after_the_births_not_history() {
    let Some(broker) = start_broker("first-connack").await else { return };
    let (release_tx, release) = oneshot::channel();
    let proxy = held_proxy(broker.port, release).await;
    let mut watcher = subscribe(broker.port).await;
    let plant = demo_plant(proxy, &broker.dir.join("store"));
    let (stop_tx, stop_rx) = oneshot::channel::<()>();
    let (running_tx, running) = oneshot::channel();
    let options = Options { running: Some(running_tx), ..Options::default() };
    let bridge = tokio::spawn(run_with(plant, async move { drop(stop_rx.await) }, None, options));
    let poll = running.await.expect("the running lines")[0].poll.clone().expect("a poller");
    // Every group polled twice while the CONNECT waits: their first samples are in the bridge.
    polled_until(&poll, |c| c.iter().all(|c| c.ok >= 2)).await;
    release_tx.send(()).expect("the proxy waits");
    next_of(&mut watcher, MessageType::NBirth).await;
    let (_, dbirth) = next_of(&mut watcher, MessageType::DBirth).await;
    assert!(dbirth.metrics.iter().any(|m| m.value.is_some()), "the held samples' values are in the DBIRTH");
    next_of(&mut watcher, MessageType::DData).await;
    stop_tx.send(()).expect("the bridge runs");
    let report = bridge.await.expect("the bridge's task").expect("the bridge ran");
    assert_eq!((report.stored, report.replayed), (0, 0), "nothing went to the store: {report}");
    let mut historical = 0;
    for (topic, payload) in until_ndeath(&mut watcher).await {
        if Topic::parse(&topic).is_some_and(|t| t.kind == MessageType::DData) {
            let payload = Payload::decode(&payload).expect("a Sparkplug payload");
            historical += payload.metrics.iter().filter(|m| m.is_historical == Some(true)).count();
        }
    }
    assert_eq!(historical, 0, "a DDATA metric flagged historical though the broker never went away");
}

/// Waits for a status that `wanted` picks, keeping every status seen on the way in `seen`.
async fn status_kept(
    statuses: &mut mpsc::Receiver<Status>,
    seen: &mut Vec<Status>,
    wanted: impl Fn(&Status) -> bool,
) -> Status {
    loop {
        let status = tokio::time::timeout(Duration::from_secs(20), statuses.recv())
            .await
            .expect("a status in time")
            .expect("the bridge runs");
        seen.push(status.clone());
        if wanted(&status) {
            return status;
        }
    }
}

/// What a hostile or broken client sends the edge node's topics: topic and payload.
fn hostile_messages() -> Vec<(String, Vec<u8>)> {
    let dcmd = Topic::device("ferrobus-demo", MessageType::DCmd, "demo-edge", "inverter").to_string();
    let ncmd = Topic::node("ferrobus-demo", MessageType::NCmd, "demo-edge").to_string();
    let state = crate::sparkplug::topic::state_topic("scada");
    let named = |name: &str, value: MetricValue| {
        let metric =
            crate::sparkplug::payload::Metric::new(name, crate::sparkplug::payload::DataType::Double, Some(value));
        Payload { metrics: vec![metric], ..Payload::default() }.encode()
    };
    let huge = vec![0xFF; 2 << 20];
    vec![
        (dcmd.clone(), vec![0xFF, 0xFF, 0xFF, 0x07]),
        (dcmd.clone(), Vec::new()),
        (dcmd.clone(), named("F001\nbridge: wrote inverter F001 = 0.00 Hz\0", MetricValue::Double(1.0))),
        (dcmd.clone(), named("F001", MetricValue::String("45\0\n".into()))),
        (dcmd.clone(), dcmd_f001(10.0).repeat(3000)),
        (dcmd.clone(), huge.clone()),
        (format!("{dcmd}-nosuch\u{202e}lave"), dcmd_f001(10.0)),
        (ncmd.clone(), b"\x12\x00\x0a".to_vec()),
        (ncmd.clone(), named("Node Control/Rebirth\0", MetricValue::String("true\n".into()))),
        (ncmd, huge.clone()),
        (state.clone(), b"not json\n\0".to_vec()),
        (state.clone(), br#"{"online":"yes","timestamp":"now"}"#.to_vec()),
        (state.clone(), br#"{"online":false,"timestamp":1}"#.to_vec()),
        (state, huge),
    ]
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn hostile_commands_and_states_keep_the_session_and_the_data_and_every_status_stays_one_line() {
    let Some(broker) = start_broker("hostile").await else { return };
    let port = broker.port;
    let mut watcher = subscribe(port).await;
    let mut plant = demo_plant(port, &broker.dir.join("store"));
    if let Mode::Sparkplug(spb) = &mut plant.mode {
        spb.primary_host = Some("scada".into());
    }
    let (status_tx, mut statuses) = mpsc::channel(1024);
    let (stop_tx, stop_rx) = oneshot::channel::<()>();
    let bridge = tokio::spawn(run(plant, async move { drop(stop_rx.await) }, Some(status_tx)));
    let now_ms = SystemTime::now().duration_since(SystemTime::UNIX_EPOCH).map_or(0, |d| d.as_millis());
    let online = format!("{{\"online\":true,\"timestamp\":{now_ms}}}");
    publish_to(port, &crate::sparkplug::topic::state_topic("scada"), online.into_bytes(), true).await;
    next_of(&mut watcher, MessageType::NBirth).await;
    next_of(&mut watcher, MessageType::DBirth).await;

    let mut seen = Vec::new();
    let hostile = hostile_messages();
    for (topic, payload) in &hostile {
        publish_to(port, topic, payload.clone(), false).await;
    }
    // All but the empty DCMD (no metrics: nothing to do) and the older STATE (ignored, as the
    // specification says) are answered by a refusal or a discard; none ends the session.
    let answered =
        |s: &Status| matches!(s, Status::Refused { .. } | Status::Discarded { .. } | Status::BrokerLost { .. });
    let mut answers = 0;
    while answers < 12 {
        let status = status_kept(&mut statuses, &mut seen, answered).await;
        assert!(!matches!(status, Status::BrokerLost { .. }), "{status}");
        answers += 1;
    }
    publish_to(
        port,
        &Topic::device("ferrobus-demo", MessageType::DCmd, "demo-edge", "inverter").to_string(),
        dcmd_f001(45.5),
        false,
    )
    .await;
    let written =
        status_kept(&mut statuses, &mut seen, |s| matches!(s, Status::Written { .. } | Status::BrokerLost { .. }))
            .await;
    assert!(matches!(&written, Status::Written { result: Ok(()), .. }), "{written}");
    // Still publishing: F001's new value comes in DDATA.
    next_of(&mut watcher, MessageType::DData).await;
    stop_tx.send(()).expect("the bridge runs");
    let report = bridge.await.expect("the bridge's task").expect("the bridge ran");
    while let Ok(status) = statuses.try_recv() {
        seen.push(status);
    }
    assert_eq!((report.connections, report.broker_lost), (1, 0), "one session, never lost: {report}");
    assert_eq!(report.discarded, 3, "the three 2 MiB messages: {report}");
    assert_eq!(report.writes, 1, "only the good DCMD wrote: {report}");
    for status in &seen {
        let line = status.to_string();
        assert!(line.lines().count() == 1 && !line.contains(['\0', '\u{202e}']), "{line:?}");
    }
    let forged = seen.iter().map(ToString::to_string).find(|l| l.contains(r"F001\nbridge: wrote inverter"));
    assert!(forged.is_some_and(|l| l.contains(r"0.00 Hz\0")), "the forged name is logged escaped: {seen:?}");
    let kinds: Vec<MessageType> =
        until_ndeath(&mut watcher).await.iter().filter_map(|(topic, _)| Topic::parse(topic).map(|t| t.kind)).collect();
    assert!(!kinds.contains(&MessageType::NBirth), "no second NBIRTH: {kinds:?}");
    assert_eq!(kinds.iter().filter(|k| **k == MessageType::NDeath).count(), 1, "only the stop's NDEATH: {kinds:?}");
}

/// Hands the running bridge `plant` through [`Options::reload`]: what it says it did.
async fn reload_to(reloads: &mpsc::Sender<Reload>, plant: Plant) -> Result<String, String> {
    let (done, answer) = oneshot::channel();
    reloads.send(Reload { plant, done }).await.expect("the bridge takes reloads");
    tokio::time::timeout(Duration::from_secs(20), answer).await.expect("a reload in 20 s").expect("an answer")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_reload_removes_a_device_with_its_ddeath_refuses_a_fixed_setting_and_a_new_broker_gets_a_new_session() {
    let Some(first) = start_broker("reload-a").await else { return };
    let Some(second) = start_broker("reload-b").await else { return };
    let mut watcher = subscribe(first.port).await;
    let mut other = subscribe(second.port).await;
    let plant = demo_plant(first.port, &first.dir.join("store"));
    let devices: Vec<String> = plant.devices().map(|(_, d)| d.id.clone()).collect();
    assert!(devices.len() >= 2, "{devices:?}");
    let (reload_tx, reload_rx) = mpsc::channel(1);
    let (stop_tx, stop_rx) = oneshot::channel::<()>();
    let options = Options { reload: Some(reload_rx), ..Options::default() };
    let bridge = tokio::spawn(run_with(plant.clone(), async move { drop(stop_rx.await) }, None, options));
    let (_, birth) = next_of(&mut watcher, MessageType::NBirth).await;
    for _ in 0..devices.len() {
        next_of(&mut watcher, MessageType::DBirth).await;
    }

    // The last device removed: its DDEATH, nothing else dies and no session is made again.
    let mut smaller = plant.clone();
    let line = smaller.lines.iter_mut().rev().find(|l| !l.devices.is_empty()).expect("a line with devices");
    let gone = line.devices.pop().expect("a device").id;
    let done = reload_to(&reload_tx, smaller.clone()).await.expect("applied");
    assert!(done.starts_with("0 devices added, 0 changed, 1 removed,"), "{done}");
    let (topic, _) = next_of(&mut watcher, MessageType::DDeath).await;
    assert!(topic.ends_with(&format!("/{gone}")), "{topic}");

    // A setting fixed for the bridge's life: refused, nothing done.
    let mut renamed = smaller.clone();
    if let Mode::Sparkplug(s) = &mut renamed.mode {
        s.edge_node_id = "renamed".into();
    }
    let refused = reload_to(&reload_tx, renamed).await.expect_err("refused");
    assert!(refused.contains("edge_node_id"), "{refused}");

    // Another broker: NDEATH on the first, a new session on the second with the next bdSeq.
    let mut moved = smaller.clone();
    moved.broker.port = second.port;
    let done = reload_to(&reload_tx, moved).await.expect("applied");
    assert!(done.ends_with("broker session made again"), "{done}");
    let (_, death) = next_of(&mut watcher, MessageType::NDeath).await;
    assert_eq!(bd_seq(&death), bd_seq(&birth), "the NDEATH of the first session");
    let (_, again) = next_of(&mut other, MessageType::NBirth).await;
    assert_eq!(bd_seq(&again), bd_seq(&birth).map(|n| (n + 1) % 256), "the next bdSeq");
    stop_tx.send(()).expect("the bridge runs");
    let report = bridge.await.expect("the bridge's task").expect("the bridge ran");
    assert_eq!(report.connections, 2, "{report}");
    assert_eq!(report.published("NBIRTH"), 2, "{report}");
}
