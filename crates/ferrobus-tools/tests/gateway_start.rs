//! `Gateway::start`'s typed errors: a routing mistake is told apart from a port that fails.
//! A line to a Modbus/TCP device that is down is no error: the gateway starts, the line's
//! requests get 0x0A until the device is up, and it reconnects after the device drops it. A
//! Modbus/TCP line is not held quiet after a timeout: its transaction ids drop a late reply. A
//! Modbus/TCP line alone takes every unit id, 0 (no broadcast there) and 255 among them; with no
//! serial line, a broadcast has nowhere to go.

use ferrobus::server::ConnectionPolicy;
use ferrobus::{ClientConfig, Error, SerialConfig, Transport};
use ferrobus_proto::frame::LineConfig;
use ferrobus_tools::gateway::{AllowAll, Gateway, GatewayConfig, GatewayError, GatewayLine, Inbound, Route, Routes};
use tokio::io::{AsyncWriteExt, DuplexStream};
use tokio::net::{TcpListener, TcpStream};

// The transport crate's test support: one in-memory unit, MBAP by hand, its devices.
#[path = "../../ferrobus/tests/support/mod.rs"]
mod support;

use support::{mbap, read_mbap};

fn line(path: &str) -> GatewayLine {
    let serial = SerialConfig::new(path, LineConfig::new(9600).unwrap());
    GatewayLine::new(Transport::rtu(serial).with_reopen(false), ClientConfig::default())
}

fn config(lines: Vec<GatewayLine>, routes: Routes) -> GatewayConfig {
    GatewayConfig { lines, routes, broadcast_ack: false, cache_max_age: None }
}

#[tokio::test]
async fn a_unit_routed_to_a_line_that_does_not_exist_is_a_routing_error_before_any_port_is_opened() {
    let mut routes = Routes::all_on(0);
    routes.set(7, Route { line: 2, unit: 7 });
    // The port does not exist either: the routes are checked first.
    let Err(error) =
        Gateway::start(config(vec![line("/nonexistent/ferrobus-a"), line("/nonexistent/ferrobus-b")], routes)).await
    else {
        panic!("started");
    };
    assert!(matches!(error, GatewayError::Routing { unit: 7, line: 2, lines: 2 }), "{error:?}");
    assert_eq!(error.to_string(), "unit 7 is routed to line 2, but there are 2 lines (numbered from 0)");
}

#[tokio::test]
async fn a_port_that_cannot_be_opened_is_an_io_error_naming_its_line_and_port() {
    let mut routes = Routes::new();
    routes.set(1, Route { line: 0, unit: 1 });
    let Err(error) = Gateway::start(config(vec![line("/nonexistent/ferrobus-gw")], routes)).await else {
        panic!("started");
    };
    let GatewayError::Io { line: 0, source } = &error else { panic!("{error:?}") };
    assert!(matches!(source, Error::Io { .. }), "{source:?}");
    assert!(error.to_string().contains("/nonexistent/ferrobus-gw"), "{error}");
}

/// Sends a read of one register through `client` and returns the reply PDU.
async fn read(client: &mut DuplexStream, t: u16) -> Vec<u8> {
    client.write_all(&mbap(t, &[0x03, 0x00, 0x00, 0x00, 0x01])).await.unwrap();
    let (tid, pdu) = read_mbap(client).await;
    assert_eq!(tid, t, "the client's transaction id comes back");
    pdu
}

/// The device's side of one request: reads it and answers register 0 = `value`.
async fn answer(device: &mut TcpStream, value: u16) {
    let (tid, pdu) = read_mbap(device).await;
    assert_eq!(pdu, [0x03, 0x00, 0x00, 0x00, 0x01]);
    let [hi, lo] = value.to_be_bytes();
    device.write_all(&mbap(tid, &[0x03, 0x02, hi, lo])).await.unwrap();
}

#[tokio::test]
async fn a_tcp_device_down_at_start_gets_0a_then_is_connected_once_up_and_reconnected_after_it_drops_the_line() {
    // A port that was free a moment ago, and nobody listening on it.
    let addr = TcpListener::bind("127.0.0.1:0").await.unwrap().local_addr().unwrap();
    let line = GatewayLine::new(Transport::tcp(addr.to_string()), ClientConfig::default());
    let gateway = Gateway::start(config(vec![line], Routes::all_on(0))).await.expect("started with the device down");
    let (mut client, server) = tokio::io::duplex(4096);
    let serving = gateway.clone();
    tokio::spawn(async move {
        let mut authorize = AllowAll;
        serving.serve_connection(server, "test client", Inbound::Mbap, &mut authorize, ConnectionPolicy::TCP).await
    });
    assert_eq!(read(&mut client, 1).await, [0x83, 0x0A], "the device is down: gateway path unavailable");
    let down = &gateway.stats()[0];
    assert_eq!((down.connects, down.connect_failures, down.total.line_errors), (0, 1, 1), "{down}");
    // While it is down, requests are answered at once, not each after its own attempt: a
    // burst of 50 makes a few attempts (one per hold of 10 ms doubling), not 50.
    for t in 100..150 {
        assert_eq!(read(&mut client, t).await, [0x83, 0x0A]);
    }
    let burst = &gateway.stats()[0];
    assert_eq!(burst.total.line_errors, 51, "{burst}");
    assert!(burst.connect_failures < 10, "one attempt per hold, not per request: {burst}");

    // The device comes up: a request after the hold connects.
    let listener = TcpListener::bind(addr).await.unwrap();
    let device = tokio::spawn(async move {
        let (mut device, _) = listener.accept().await.unwrap();
        answer(&mut device, 0x1234).await;
        // It drops the connection, and takes the next one.
        drop(device);
        let (mut device, _) = listener.accept().await.unwrap();
        answer(&mut device, 0x5678).await;
        device
    });
    // Requests within the hold still get 0x0A; the first after it is served.
    let mut t = 2;
    let answered = loop {
        let reply = read(&mut client, t).await;
        if reply != [0x83, 0x0A] {
            break reply;
        }
        assert!(t < 1000, "not connected after {t} requests");
        t += 1;
        tokio::time::sleep(std::time::Duration::from_millis(5)).await;
    };
    assert_eq!(answered, [0x03, 0x02, 0x12, 0x34]);
    // A request sent before the gateway has seen the drop may get 0x0A, and so do those within
    // the hold after it; one after is served.
    let mut t = 1000;
    let answered = loop {
        let reply = read(&mut client, t).await;
        if reply != [0x83, 0x0A] {
            break reply;
        }
        assert!(t < 2000, "not reconnected after {} requests", t - 1000);
        t += 1;
        tokio::time::sleep(std::time::Duration::from_millis(5)).await;
    };
    assert_eq!(answered, [0x03, 0x02, 0x56, 0x78]);
    let _device = device.await.unwrap();
    let stats = &gateway.stats()[0];
    assert_eq!((stats.connects, stats.disconnects), (2, 1), "{stats}");
    assert!(stats.to_string().contains("connects 2 connect-failures"), "{stats}");
}

#[tokio::test]
async fn a_modbus_tcp_line_is_not_held_quiet_after_a_timeout_and_drops_the_late_reply_by_its_id() {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let client = ClientConfig { timeout: std::time::Duration::from_millis(50), retries: 0, ..ClientConfig::default() };
    let line = GatewayLine {
        // A guard this long would stall the test: a TCP line must not keep it.
        late_guard: std::time::Duration::from_secs(30),
        ..GatewayLine::new(Transport::tcp(addr.to_string()), client)
    };
    let gateway = Gateway::start(config(vec![line], Routes::all_on(0))).await.unwrap();
    let device = tokio::spawn(async move {
        let (mut device, _) = listener.accept().await.unwrap();
        // The first request is answered only after the gateway gave up on it, and after the
        // second has come: the late reply, under the first one's transaction id, comes first.
        let (late_tid, _) = read_mbap(&mut device).await;
        let (tid, _) = read_mbap(&mut device).await;
        device.write_all(&mbap(late_tid, &[0x03, 0x02, 0xDE, 0xAD])).await.unwrap();
        device.write_all(&mbap(tid, &[0x03, 0x02, 0x00, 0x07])).await.unwrap();
        device
    });
    let (mut client, server) = tokio::io::duplex(4096);
    let serving = gateway.clone();
    tokio::spawn(async move {
        let mut authorize = AllowAll;
        serving.serve_connection(server, "test client", Inbound::Mbap, &mut authorize, ConnectionPolicy::TCP).await
    });
    assert_eq!(read(&mut client, 1).await, [0x83, 0x0B], "no reply within the timeout");
    let second = tokio::time::timeout(std::time::Duration::from_secs(10), read(&mut client, 2)).await;
    assert_eq!(
        second.expect("served without the 30 s guard"),
        [0x03, 0x02, 0x00, 0x07],
        "its own reply, not the late one"
    );
    let _device = device.await.unwrap();
}

/// An MBAP frame to `unit`.
fn mbap_to(t: u16, unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut frame = mbap(t, pdu);
    frame[6] = unit;
    frame
}

/// Reads one MBAP frame: (transaction, unit, PDU).
async fn adu(stream: &mut (impl tokio::io::AsyncReadExt + Unpin)) -> (u16, u8, Vec<u8>) {
    let mut head = [0u8; 7];
    stream.read_exact(&mut head).await.unwrap();
    let mut pdu = vec![0u8; usize::from(u16::from_be_bytes([head[4], head[5]])) - 1];
    stream.read_exact(&mut pdu).await.unwrap();
    (u16::from_be_bytes([head[0], head[1]]), head[6], pdu)
}

#[tokio::test]
async fn a_modbus_tcp_line_alone_takes_every_unit_id_and_unit_0_there_is_the_devices_not_a_broadcast() {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let device = tokio::spawn(async move {
        let (mut device, _) = listener.accept().await.unwrap();
        // Answers each request with its own unit id in the register, or echoes a write.
        let mut heard = Vec::new();
        for _ in 0..3 {
            let (tid, unit, pdu) = adu(&mut device).await;
            let reply = if pdu[0] == 0x06 { pdu.clone() } else { vec![0x03, 0x02, 0x00, unit] };
            device.write_all(&mbap_to(tid, unit, &reply)).await.unwrap();
            heard.push(unit);
        }
        heard
    });
    let line = GatewayLine::new(Transport::tcp(addr.to_string()), ClientConfig::default());
    let gateway = Gateway::start(config(vec![line], Routes::every_id_on(0))).await.unwrap();
    let (mut client, server) = tokio::io::duplex(4096);
    tokio::spawn(async move {
        let mut authorize = AllowAll;
        gateway.serve_connection(server, "test client", Inbound::Mbap, &mut authorize, ConnectionPolicy::TCP).await
    });
    for (t, unit, pdu, reply) in [
        (1, 255, vec![0x03, 0x00, 0x00, 0x00, 0x01], vec![0x03, 0x02, 0x00, 255]),
        (2, 0, vec![0x03, 0x00, 0x00, 0x00, 0x01], vec![0x03, 0x02, 0x00, 0]),
        // A write to unit 0 is answered by the device, not sent as a broadcast.
        (3, 0, vec![0x06, 0x00, 0x05, 0x00, 0x09], vec![0x06, 0x00, 0x05, 0x00, 0x09]),
    ] {
        client.write_all(&mbap_to(t, unit, &pdu)).await.unwrap();
        assert_eq!(adu(&mut client).await, (t, unit, reply), "unit {unit}");
    }
    assert_eq!(device.await.unwrap(), [255, 0, 0]);
}

#[tokio::test]
async fn with_no_serial_line_a_write_to_an_unrouted_unit_0_has_no_broadcast_to_go_to_and_gets_0a() {
    // Nobody listens: nothing may be sent anywhere.
    let addr = TcpListener::bind("127.0.0.1:0").await.unwrap().local_addr().unwrap();
    let line = GatewayLine::new(Transport::tcp(addr.to_string()), ClientConfig::default());
    let mut routes = Routes::new();
    routes.set(100, Route { line: 0, unit: 1 });
    let gateway = Gateway::start(config(vec![line], routes)).await.unwrap();
    let (mut client, server) = tokio::io::duplex(4096);
    let serving = gateway.clone();
    tokio::spawn(async move {
        let mut authorize = AllowAll;
        serving.serve_connection(server, "test client", Inbound::Mbap, &mut authorize, ConnectionPolicy::TCP).await
    });
    client.write_all(&mbap_to(1, 0, &[0x06, 0x00, 0x05, 0x00, 0x09])).await.unwrap();
    assert_eq!(adu(&mut client).await, (1, 0, vec![0x86, 0x0A]));
    let stats = &gateway.stats()[0];
    assert_eq!((stats.total.requests, stats.connect_failures), (0, 0), "nothing reached the line: {stats}");
}
