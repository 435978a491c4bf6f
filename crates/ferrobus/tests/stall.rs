//! A Modbus/TCP device connection that stalls is made again: a device written here sends half
//! a reply on its first connection (or nothing at all) and then stays silent on it, but serves
//! every later connection. The client (one request at a time, and pipelined) and the gateway
//! in front of it get right answers again after the timeout(s), not timeouts (0x0B) for as
//! long as the device keeps the dead connection open.

use std::time::Duration;

use ferrobus::gateway::{AllowAll, Gateway, GatewayConfig, GatewayLine, Inbound, Routes, Timeouts};
use ferrobus::{Client, ClientConfig, Error, STALLED_AFTER_TIMEOUTS, Transport};
use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};
use tokio::net::{TcpListener, TcpStream};

mod support;

use support::{mbap, read_mbap};

/// What the device does on its first connection.
#[derive(Clone, Copy)]
enum First {
    /// Sends the first 5 bytes of the reply to the first request, then nothing.
    HalfReply,
    /// Reads every request and answers none.
    Silent,
}

/// The device: its first connection stalls as `first` says (held open, read, never answered
/// again); every later one is answered, register 0 holding 42.
async fn device(first: First) -> std::net::SocketAddr {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    tokio::spawn(async move {
        let (mut stalled, _) = listener.accept().await.unwrap();
        tokio::spawn(async move {
            let (tid, _) = read_mbap(&mut stalled).await;
            if let First::HalfReply = first {
                stalled.write_all(&mbap(tid, &[0x03, 0x02, 0x00, 0x2A])[..5]).await.unwrap();
            }
            let mut sink = [0u8; 256];
            while matches!(stalled.read(&mut sink).await, Ok(n) if n > 0) {}
        });
        loop {
            let (stream, _) = listener.accept().await.unwrap();
            tokio::spawn(serve(stream));
        }
    });
    addr
}

async fn serve(mut stream: TcpStream) {
    loop {
        let mut head = [0u8; 7];
        if stream.read_exact(&mut head).await.is_err() {
            return;
        }
        let mut pdu = vec![0u8; usize::from(u16::from_be_bytes([head[4], head[5]])) - 1];
        if stream.read_exact(&mut pdu).await.is_err() {
            return;
        }
        let tid = u16::from_be_bytes([head[0], head[1]]);
        if stream.write_all(&mbap(tid, &[0x03, 0x02, 0x00, 0x2A])).await.is_err() {
            return;
        }
    }
}

fn config(in_flight: usize) -> ClientConfig {
    ClientConfig {
        in_flight,
        timeout: Duration::from_millis(200),
        retries: 0,
        backoff: None,
        ..ClientConfig::default()
    }
}

#[tokio::test]
async fn after_half_a_reply_and_silence_the_next_request_goes_on_a_new_connection_and_is_answered() {
    for in_flight in [1, 4] {
        let addr = device(First::HalfReply).await;
        let client = Client::connect(Transport::tcp(addr.to_string()), config(in_flight)).await.unwrap();
        let first = client.read_holding_registers(1, 0, 1).await;
        assert!(matches!(first, Err(Error::Timeout { .. })), "in flight {in_flight}: {first:?}");
        for _ in 0..3 {
            assert_eq!(client.read_holding_registers(1, 0, 1).await.unwrap(), [42], "in flight {in_flight}");
        }
        let stats = client.stats();
        assert_eq!((stats.stalled, stats.connects, stats.disconnects), (1, 2, 0), "in flight {in_flight}: {stats:?}");
    }
}

#[tokio::test]
async fn after_timeouts_in_a_row_without_a_reply_the_connection_is_made_again() {
    for in_flight in [1, 4] {
        let addr = device(First::Silent).await;
        let client = Client::connect(Transport::tcp(addr.to_string()), config(in_flight)).await.unwrap();
        for i in 0..STALLED_AFTER_TIMEOUTS {
            let result = client.read_holding_registers(1, 0, 1).await;
            assert!(matches!(result, Err(Error::Timeout { .. })), "in flight {in_flight}, request {i}: {result:?}");
            // Not made again before the last of them.
            let expected = u64::from(i + 1 == STALLED_AFTER_TIMEOUTS);
            assert_eq!(client.stats().stalled, expected, "in flight {in_flight}, request {i}");
        }
        assert_eq!(client.read_holding_registers(1, 0, 1).await.unwrap(), [42], "in flight {in_flight}");
        let stats = client.stats();
        assert_eq!((stats.stalled, stats.connects), (1, 2), "in flight {in_flight}: {stats:?}");
    }
}

#[tokio::test]
async fn a_retry_after_half_a_reply_goes_on_the_new_connection_and_the_caller_gets_the_answer() {
    let addr = device(First::HalfReply).await;
    let config = ClientConfig { retries: 1, ..config(1) };
    let client = Client::connect(Transport::tcp(addr.to_string()), config).await.unwrap();
    assert_eq!(client.read_holding_registers(1, 0, 1).await.unwrap(), [42]);
    assert_eq!(client.stats().stalled, 1);
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

async fn read_through(client: &mut DuplexStream, t: u16) -> Vec<u8> {
    client.write_all(&mbap(t, &[0x03, 0x00, 0x00, 0x00, 0x01])).await.unwrap();
    let (tid, pdu) = read_mbap(client).await;
    assert_eq!(tid, t);
    pdu
}

#[tokio::test]
async fn the_gateway_answers_0x0b_once_then_the_device_on_a_new_connection() {
    let addr = device(First::HalfReply).await;
    let line = GatewayLine::new(Transport::tcp(addr.to_string()), config(1));
    let config =
        GatewayConfig { lines: vec![line], routes: Routes::all_on(0), broadcast_ack: false, cache_max_age: None };
    let gateway = Gateway::start(config).await.unwrap();
    let mut client = connect(&gateway);
    assert_eq!(read_through(&mut client, 1).await, [0x83, 0x0B]);
    for t in 2..5 {
        assert_eq!(read_through(&mut client, t).await, [0x03, 0x02, 0x00, 0x2A], "request {t}");
    }
    let line = &gateway.stats()[0];
    assert_eq!((line.stalled, line.connects, line.disconnects), (1, 2, 0), "{line}");
}
