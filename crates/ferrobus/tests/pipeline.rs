//! Several requests in flight on one Modbus/TCP connection (`ClientConfig::in_flight`): the
//! client's pipelined driver and the gateway's worker on a pipelined line, against a device
//! written here that holds requests back and answers them out of order. Each caller gets the
//! reply to its own request, a timeout ends only its own, a late reply goes to nobody, a
//! connection lost under the requests in flight sends those with retries again, and a line
//! whose device is down is tried by one request at a time.

use std::time::Duration;

use ferrobus::gateway::{AllowAll, Gateway, GatewayConfig, GatewayLine, Inbound, Routes, Timeouts};
use ferrobus::{Client, ClientConfig, Error, Transport};
use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};
use tokio::net::{TcpListener, TcpStream};

mod support;

use support::{mbap, read_mbap};

/// One request as the device reads it: its transaction id and the register it reads.
#[derive(Clone, Copy, Debug)]
struct Asked {
    tid: u16,
    register: u16,
}

/// Reads one request, a read of one holding register (0x03), from `stream`.
async fn asked(stream: &mut (impl AsyncReadExt + Unpin)) -> Asked {
    let (tid, pdu) = read_mbap(stream).await;
    assert_eq!((pdu.len(), pdu[0], &pdu[3..]), (5, 0x03, &[0x00, 0x01][..]), "{pdu:02X?}");
    Asked { tid, register: u16::from_be_bytes([pdu[1], pdu[2]]) }
}

/// What the device keeps in register `r`.
fn value(register: u16) -> u16 {
    register.wrapping_mul(7).wrapping_add(1)
}

/// The device's answer to `asked`: the register's value, under the request's id.
async fn answer(device: &mut TcpStream, asked: Asked) {
    let [hi, lo] = value(asked.register).to_be_bytes();
    device.write_all(&mbap(asked.tid, &[0x03, 0x02, hi, lo])).await.unwrap();
}

/// Reads `n` requests before answering any, then answers them newest first; returns them.
async fn hold_and_answer_backwards(device: &mut TcpStream, n: usize) -> Vec<Asked> {
    let mut held = Vec::new();
    for _ in 0..n {
        held.push(asked(device).await);
    }
    let ids: std::collections::HashSet<u16> = held.iter().map(|a| a.tid).collect();
    assert_eq!(ids.len(), n, "requests outstanding together have distinct transaction ids: {held:?}");
    for a in held.iter().rev() {
        answer(device, *a).await;
    }
    held
}

fn pipelined(in_flight: usize, timeout: Duration, retries: u32) -> ClientConfig {
    ClientConfig { in_flight, timeout, retries, backoff: None, ..ClientConfig::default() }
}

#[tokio::test]
async fn requests_go_out_without_waiting_for_replies_and_each_caller_gets_the_reply_to_its_own() {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let device = tokio::spawn(async move {
        let (mut device, _) = listener.accept().await.unwrap();
        // 12 requests, 4 at a time: the device hears 4 before it has answered any.
        let mut seen = Vec::new();
        for _ in 0..3 {
            seen.extend(hold_and_answer_backwards(&mut device, 4).await);
        }
        seen
    });
    let client = Client::connect(Transport::tcp(&addr), pipelined(4, Duration::from_secs(10), 0)).await.unwrap();
    let reads: Vec<_> = (0..12u16)
        .map(|r| {
            let client = client.clone();
            tokio::spawn(async move { (r, client.read_holding_registers(1, 100 + r, 1).await) })
        })
        .collect();
    for read in reads {
        let (r, result) = read.await.unwrap();
        assert_eq!(result.unwrap(), [value(100 + r)], "register {}", 100 + r);
    }
    let seen = device.await.unwrap();
    assert_eq!(seen.len(), 12);
    let stats = client.stats().master;
    assert_eq!((stats.requests, stats.responses, stats.timeouts, stats.ignored_frames), (12, 12, 0, 0), "{stats:?}");
}

#[tokio::test]
async fn a_timeout_ends_only_its_own_request_and_its_late_reply_is_handed_to_nobody() {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let (timed_out, timed_out_rx) = tokio::sync::oneshot::channel::<()>();
    let device = tokio::spawn(async move {
        let (mut device, _) = listener.accept().await.unwrap();
        let mut three = Vec::new();
        for _ in 0..3 {
            three.push(asked(&mut device).await);
        }
        // Register 1's request is answered only after the client gave up on it; the two
        // others at once.
        let (slow, rest): (Vec<Asked>, Vec<Asked>) = three.into_iter().partition(|a| a.register == 1);
        for a in rest {
            answer(&mut device, a).await;
        }
        timed_out_rx.await.unwrap();
        // The late reply comes just before the answer to the next request: only the next
        // request's own reply may end it.
        let next = asked(&mut device).await;
        answer(&mut device, slow[0]).await;
        answer(&mut device, next).await;
        device
    });
    let client = Client::connect(Transport::tcp(&addr), pipelined(3, Duration::from_millis(300), 0)).await.unwrap();
    let reads: Vec<_> = (1..=3u16)
        .map(|r| {
            let client = client.clone();
            tokio::spawn(async move { (r, client.read_holding_registers(1, r, 1).await) })
        })
        .collect();
    for read in reads {
        match read.await.unwrap() {
            (1, Err(Error::Timeout { heard: None, attempts: 1, .. })) => {}
            (1, other) => panic!("register 1 was never answered in time: {other:?}"),
            (r, result) => assert_eq!(result.unwrap(), [value(r)], "register {r}"),
        }
    }
    timed_out.send(()).unwrap();
    assert_eq!(client.read_holding_registers(1, 9, 1).await.unwrap(), [value(9)], "its own reply, not the late one");
    let _device = device.await.unwrap();
    let stats = client.stats().master;
    assert_eq!((stats.responses, stats.timeouts, stats.late_replies), (3, 1, 1), "{stats:?}");
}

#[tokio::test]
async fn a_connection_lost_under_requests_in_flight_sends_those_with_retries_again_and_fails_the_others() {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let device = tokio::spawn(async move {
        // Hears 4 requests and drops the connection without a word; then serves the next.
        let (mut first, _) = listener.accept().await.unwrap();
        let mut lost = Vec::new();
        for _ in 0..4 {
            lost.push(asked(&mut first).await.register);
        }
        drop(first);
        let (mut second, _) = listener.accept().await.unwrap();
        let again = hold_and_answer_backwards(&mut second, 4).await;
        let mut again: Vec<u16> = again.iter().map(|a| a.register).collect();
        lost.sort_unstable();
        again.sort_unstable();
        assert_eq!(lost, again, "the same requests, sent again");
        second
    });
    let client = Client::connect(Transport::tcp(&addr), pipelined(4, Duration::from_secs(10), 1)).await.unwrap();
    let reads: Vec<_> = (0..4u16)
        .map(|r| {
            let client = client.clone();
            tokio::spawn(async move { (r, client.read_holding_registers(1, r, 1).await) })
        })
        .collect();
    for read in reads {
        let (r, result) = read.await.unwrap();
        assert_eq!(result.unwrap(), [value(r)], "register {r}, on the second connection");
    }
    let _device = device.await.unwrap();
    let stats = client.stats();
    assert_eq!((stats.connects, stats.disconnects), (2, 1), "{stats:?}");

    // Without retries, a loss fails every request in flight with the IO error.
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let device = tokio::spawn(async move {
        let (mut device, _) = listener.accept().await.unwrap();
        for _ in 0..3 {
            asked(&mut device).await;
        }
    });
    let client = Client::connect(Transport::tcp(&addr), pipelined(4, Duration::from_secs(10), 0)).await.unwrap();
    let reads: Vec<_> = (0..3u16)
        .map(|r| {
            let client = client.clone();
            tokio::spawn(async move { client.read_holding_registers(1, r, 1).await })
        })
        .collect();
    device.await.unwrap();
    for read in reads {
        let result = read.await.unwrap();
        assert!(matches!(result, Err(Error::Io { .. })), "{result:?}");
    }
}

/// A client connection to `gateway`, served as a TCP connection would be.
fn connect(gateway: &Gateway) -> DuplexStream {
    let (client, server) = tokio::io::duplex(4096);
    let serving = gateway.clone();
    tokio::spawn(async move {
        let mut authorize = AllowAll;
        serving.serve_connection(server, "test client", Inbound::Mbap, &mut authorize, Timeouts::default()).await
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
