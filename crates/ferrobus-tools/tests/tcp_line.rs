//! The gateway in front of Modbus/TCP devices written here (the transport crate's test
//! support): a pipelined line keeps several clients' requests on the device at once and a
//! line whose device is down is tried by one request at a time; a stalled device connection is
//! made again after one 0x0B; and its front end, which shares the server's accept loop, serves
//! a new client while many addresses fill its cap.

use std::sync::Arc;
use std::time::Duration;

use ferrobus::server::{ConnectionPolicy, TcpLimits};
use ferrobus::{ClientConfig, Transport};
use ferrobus_tools::gateway::{AllowAll, Authorize, FrontConfig, Gateway, GatewayConfig, GatewayLine, Inbound, Routes};
use tokio::io::{AsyncWriteExt, DuplexStream};
use tokio::net::TcpListener;

// The transport crate's test support: one in-memory unit, MBAP by hand, its devices.
#[path = "../../ferrobus/tests/support/mod.rs"]
mod support;

use support::pipelined::{answer, asked, hold_and_answer_backwards, pipelined, value};
use support::sources::{PER_SOURCE, connect_from, polled, server, until};
use support::stalling::{First, stalling};
use support::{mbap, read_mbap};

/// A client connection to `gateway`, served as a TCP connection would be.
fn connect(gateway: &Gateway) -> DuplexStream {
    let (client, server) = tokio::io::duplex(4096);
    let serving = gateway.clone();
    tokio::spawn(async move {
        let mut authorize = AllowAll;
        serving.serve_connection(server, "test client", Inbound::Mbap, &mut authorize, ConnectionPolicy::TCP).await
    });
    client
}

/// Sends a read of `register` through the gateway connection `client`; returns the reply PDU.
async fn read_through(client: &mut DuplexStream, t: u16, register: u16) -> Vec<u8> {
    let [hi, lo] = register.to_be_bytes();
    client.write_all(&mbap(t, &[0x03, hi, lo, 0x00, 0x01])).await.unwrap();
    let (tid, pdu) = read_mbap(client).await;
    assert_eq!(tid, t, "the client's own transaction id comes back");
    pdu
}

/// A gateway with one line, to the Modbus/TCP device at `addr`, `in_flight` requests at once.
async fn gateway(addr: std::net::SocketAddr, in_flight: usize) -> Gateway {
    let line = GatewayLine::new(Transport::tcp(addr.to_string()), pipelined(in_flight, Duration::from_secs(10), 0));
    let config =
        GatewayConfig { lines: vec![line], routes: Routes::all_on(0), broadcast_ack: false, cache_max_age: None };
    Gateway::start(config).await.unwrap()
}

#[tokio::test]
async fn a_pipelined_gateway_line_keeps_several_clients_requests_on_the_device_at_once_each_answered_its_own() {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let device = tokio::spawn(async move {
        let (mut device, _) = listener.accept().await.unwrap();
        // The line is tried by one request until the device has answered; then six clients'
        // requests, six at a time, answered newest first, twice over.
        let first = asked(&mut device).await;
        answer(&mut device, first).await;
        hold_and_answer_backwards(&mut device, 6).await;
        hold_and_answer_backwards(&mut device, 6).await;
        device
    });
    let gateway = gateway(addr, 6).await;
    let [hi, lo] = value(7).to_be_bytes();
    assert_eq!(read_through(&mut connect(&gateway), 1, 7).await, [0x03, 0x02, hi, lo]);
    let clients: Vec<_> = (0..6u16)
        .map(|c| {
            let mut client = connect(&gateway);
            tokio::spawn(async move {
                for round in 0..2u16 {
                    let register = c * 10 + round;
                    let [hi, lo] = value(register).to_be_bytes();
                    assert_eq!(read_through(&mut client, 500 + c, register).await, [0x03, 0x02, hi, lo]);
                }
            })
        })
        .collect();
    for client in clients {
        client.await.unwrap();
    }
    let _device = device.await.unwrap();
    let stats = &gateway.stats()[0];
    assert_eq!((stats.total.replies, stats.connects), (13, 1), "{stats}");
}

#[tokio::test]
async fn a_pipelined_line_whose_device_is_down_is_tried_by_one_request_at_a_time_the_others_get_0a_at_once() {
    // A port that was free a moment ago, and nobody listening on it.
    let addr = TcpListener::bind("127.0.0.1:0").await.unwrap().local_addr().unwrap();
    let gateway = gateway(addr, 8).await;
    // Eight clients at once, ten requests each: were eight in flight, each would make a
    // connect attempt of its own.
    let clients: Vec<_> = (0..8u16)
        .map(|c| {
            let mut client = connect(&gateway);
            tokio::spawn(async move {
                for t in 0..10u16 {
                    assert_eq!(read_through(&mut client, c * 100 + t, t).await, [0x83, 0x0A], "the device is down");
                }
            })
        })
        .collect();
    for client in clients {
        client.await.unwrap();
    }
    let stats = &gateway.stats()[0];
    assert_eq!((stats.total.line_errors, stats.connects), (80, 0), "{stats}");
    assert!(stats.connect_failures < 8, "one attempt per hold, not one per request in flight: {stats}");
}

#[tokio::test]
async fn the_gateway_answers_0x0b_once_then_the_device_on_a_new_connection() {
    let addr = stalling(First::HalfReply).await;
    let line = GatewayLine::new(
        Transport::tcp(addr.to_string()),
        ClientConfig { timeout: Duration::from_millis(200), retries: 0, backoff: None, ..ClientConfig::default() },
    );
    let config =
        GatewayConfig { lines: vec![line], routes: Routes::all_on(0), broadcast_ack: false, cache_max_age: None };
    let gateway = Gateway::start(config).await.unwrap();
    let mut client = connect(&gateway);
    assert_eq!(read_through(&mut client, 1, 0).await, [0x83, 0x0B]);
    for t in 2..5 {
        assert_eq!(read_through(&mut client, t, 0).await, [0x03, 0x02, 0x00, 0x2A], "request {t}");
    }
    let line = &gateway.stats()[0];
    assert_eq!((line.stalled, line.connects, line.disconnects), (1, 2, 0), "{line}");
}

#[tokio::test]
async fn the_gateway_serves_a_new_client_while_many_addresses_fill_its_cap_and_keeps_its_poller() {
    let (device, _) = server().await;
    let line =
        GatewayLine::new(Transport::tcp(device.to_string()), ClientConfig { retries: 0, ..ClientConfig::default() });
    let config =
        GatewayConfig { lines: vec![line], routes: Routes::all_on(0), broadcast_ack: false, cache_max_age: None };
    let gateway = Gateway::start(config).await.unwrap();
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let limits = TcpLimits {
        max_connections: 6,
        max_per_source: PER_SOURCE,
        connection: ConnectionPolicy { idle: None, ..ConnectionPolicy::TCP },
        ..TcpLimits::default()
    };
    let stats = Arc::clone(&limits.stats);
    let front = FrontConfig { limits, ..FrontConfig::default() };
    let allow = |_| Box::new(AllowAll) as Box<dyn Authorize>;
    tokio::spawn(async move { gateway.serve_tcp(listener, front, allow).await });
    let mut operator = connect_from(200, addr).await;
    assert!(polled(&mut operator, 1).await);
    // 4 addresses, 2 each, that never send a request: 8 against the 5 slots left.
    let mut flood = Vec::new();
    for host in 10..14 {
        for _ in 0..PER_SOURCE {
            flood.push(connect_from(host, addr).await);
        }
    }
    let counts = until(&stats, |c| c.accepted == 9).await;
    assert_eq!((counts.evicted_unanswered, counts.refused, counts.refused_source), (3, 0, 0), "{counts:?}");
    let mut newcomer = connect_from(100, addr).await;
    assert!(polled(&mut newcomer, 1).await);
    assert!(polled(&mut operator, 2).await);
    let counts = until(&stats, |c| c.open == 6).await;
    assert_eq!((counts.evicted_unanswered, counts.evicted_idle), (4, 0), "{counts:?}");
}
