//! `Gateway::reload` on lines to Modbus/TCP devices of the test's own: a changed line's request
//! on the wire when the reload comes is still answered to its client, the line's old connection
//! is closed once it has been, and the next request goes out on a new connection with the new
//! settings; an unchanged line keeps its connection and its counters; one client connection is
//! served throughout.

use std::time::Duration;

use ferrobus::server::ConnectionPolicy;
use ferrobus::{ClientConfig, Transport};
use ferrobus_tools::gateway::reload::{Fate, Plan};
use ferrobus_tools::gateway::{AllowAll, Gateway, GatewayConfig, GatewayLine, Inbound, Route, Routes};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};

// The transport crate's test support: MBAP by hand.
#[path = "../../ferrobus/tests/support/mod.rs"]
mod support;

use support::{mbap, read_mbap};

/// A line to the device at `addr` with a reply timeout of `timeout`.
fn line(addr: &str, timeout: Duration) -> GatewayLine {
    GatewayLine::new(Transport::tcp(addr), ClientConfig { timeout, ..ClientConfig::default() })
}

/// Unit 1 on line 0, unit 2 on line 1 as its unit 1 (each device answers as unit 1).
fn config(lines: Vec<GatewayLine>) -> GatewayConfig {
    let mut routes = Routes::new();
    routes.set(1, Route { line: 0, unit: 1 });
    routes.set(2, Route { line: 1, unit: 1 });
    GatewayConfig { lines, routes, broadcast_ack: false, cache_max_age: None }
}

/// The device's side of one request: reads it and answers register 0 = `value`.
async fn answer(device: &mut TcpStream, value: u16) {
    let (tid, pdu) = read_mbap(device).await;
    assert_eq!(pdu, [0x03, 0x00, 0x00, 0x00, 0x01]);
    let [hi, lo] = value.to_be_bytes();
    device.write_all(&mbap(tid, &[0x03, 0x02, hi, lo])).await.unwrap();
}

/// A read of register 0 of `unit` as a client sends it.
fn request(t: u16, unit: u8) -> Vec<u8> {
    let mut frame = mbap(t, &[0x03, 0x00, 0x00, 0x00, 0x01]);
    frame[6] = unit;
    frame
}

#[tokio::test]
async fn a_changed_line_answers_its_request_in_flight_then_reconnects_and_an_unchanged_line_keeps_its_connection() {
    let changed = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let kept = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let (a, b) = (changed.local_addr().unwrap().to_string(), kept.local_addr().unwrap().to_string());
    let long = Duration::from_secs(10);
    let gateway = Gateway::start(config(vec![line(&a, long), line(&b, long)])).await.unwrap();
    let (mut client, server) = tokio::io::duplex(4096);
    let serving = gateway.clone();
    tokio::spawn(async move {
        let mut authorize = AllowAll;
        serving.serve_connection(server, "test client", Inbound::Mbap, &mut authorize, ConnectionPolicy::TCP).await
    });

    // Unit 2's line connects and answers; it is to stay as it is.
    client.write_all(&request(1, 2)).await.unwrap();
    let (mut device_b, _) = kept.accept().await.unwrap();
    answer(&mut device_b, 0x0B0B).await;
    assert_eq!(read_mbap(&mut client).await, (1, vec![0x03, 0x02, 0x0B, 0x0B]));

    // Unit 1's request reaches its device, which holds the reply while the reload comes.
    client.write_all(&request(2, 1)).await.unwrap();
    let (mut device_a, _) = changed.accept().await.unwrap();
    let (tid, _) = read_mbap(&mut device_a).await;
    let plan = Plan {
        lines: vec![Fate::Changed { was: 0 }, Fate::Unchanged { was: 1 }],
        removed: vec![],
        routes_changed: false,
    };
    let reloading = {
        let gateway = gateway.clone();
        let lines = vec![line(&a, Duration::from_secs(3)), line(&b, long)];
        tokio::spawn(async move { gateway.reload(&plan, config(lines)).await.map(|started| started.len()) })
    };
    // The reload is under way, waiting for the line's driver: the line is being opened anew.
    for turn in 0.. {
        if gateway.stats()[0].name == "(reopening)" {
            break;
        }
        assert!(turn < 10_000, "the reload did not start");
        tokio::task::yield_now().await;
    }
    // The reply owed comes: the client has it, and only then is the old connection closed.
    device_a.write_all(&mbap(tid, &[0x03, 0x02, 0x0A, 0x0A])).await.unwrap();
    assert_eq!(read_mbap(&mut client).await, (2, vec![0x03, 0x02, 0x0A, 0x0A]));
    let mut rest = Vec::new();
    let closed = tokio::time::timeout(long, device_a.read_to_end(&mut rest)).await;
    assert!(matches!(closed, Ok(Ok(0))), "the old connection ends: {closed:?}");
    assert_eq!(reloading.await.unwrap().unwrap(), 1, "one line started anew");

    // The changed line connects again for its next request, with its new settings.
    client.write_all(&request(3, 1)).await.unwrap();
    let (mut device_a, _) = changed.accept().await.unwrap();
    answer(&mut device_a, 0x1111).await;
    assert_eq!(read_mbap(&mut client).await, (3, vec![0x03, 0x02, 0x11, 0x11]));
    // The unchanged line answers on its first connection, its counters running on.
    client.write_all(&request(4, 2)).await.unwrap();
    answer(&mut device_b, 0x2222).await;
    assert_eq!(read_mbap(&mut client).await, (4, vec![0x03, 0x02, 0x22, 0x22]));
    let stats = gateway.stats();
    assert_eq!((stats[1].connects, stats[1].total.replies), (1, 2), "{}", stats[1]);
    assert_eq!((stats[0].connects, stats[0].total.replies), (1, 1), "the changed line counts afresh: {}", stats[0]);
    assert_eq!(stats[0].late_window, None, "a Modbus/TCP line has no late window");
}
