//! The Modbus/TCP server with its cap filled from many addresses (all of 127/8 is loopback,
//! and a client bound to 127.0.0.N is another host as far as the per-source limit goes): a
//! new client is served, the connection least worth keeping closed to make room (one never
//! answered, then the one idle longest, from the source holding the most first), and a
//! client that polls keeps its session. The gateway's front end, which shares the accept loop,
//! too.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use ferrobus::gateway::{AllowAll, Authorize, FrontConfig, Gateway, GatewayConfig, GatewayLine, Routes};
use ferrobus::server::{ServerOptions, Shared, TcpCounts, TcpLimits, TcpServeConfig, TcpStats, serve_tcp_with};
use ferrobus::{ClientConfig, Timer, Transport};
use ferrobus_proto::ExceptionCode;
use ferrobus_proto::frame::LineTiming;
use ferrobus_proto::slave::{Handler, SlaveConfig};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpSocket, TcpStream};

struct Device;

impl Handler for Device {
    fn read_holding_registers(&mut self, _: u8, _: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        out.fill(7);
        Ok(())
    }
}

/// The server's cap, and each source's.
const MAX: usize = 20;
const PER_SOURCE: usize = 2;

async fn server() -> (SocketAddr, Arc<TcpStats>) {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let limits =
        TcpLimits { max_connections: MAX, max_per_source: PER_SOURCE, idle_timeout: None, ..TcpLimits::default() };
    let stats = Arc::clone(&limits.stats);
    let options = || ServerOptions::new(LineTiming::unpaced(), Timer::Tokio);
    let serve =
        TcpServeConfig { limits, ..TcpServeConfig::new(Transport::tcp(addr.to_string()), SlaveConfig::unit(1)) };
    tokio::spawn(serve_tcp_with(listener, serve, Shared::new(Device), options));
    (addr, stats)
}

/// A connection to `server` from 127.0.0.`host`.
async fn connect_from(host: u8, server: SocketAddr) -> TcpStream {
    let socket = TcpSocket::new_v4().unwrap();
    socket.bind(SocketAddr::from(([127, 0, 0, host], 0))).unwrap();
    socket.connect(server).await.unwrap()
}

/// Whether a read of holding register 0 on `stream` is answered with 7.
async fn polled(stream: &mut TcpStream, t: u16) -> bool {
    let [hi, lo] = t.to_be_bytes();
    if stream.write_all(&[hi, lo, 0, 0, 0, 6, 1, 0x03, 0, 0, 0, 1]).await.is_err() {
        return false;
    }
    let mut reply = [0u8; 11];
    stream.read_exact(&mut reply).await.is_ok() && reply == [hi, lo, 0, 0, 0, 5, 1, 0x03, 2, 0, 7]
}

/// Whether the server closed `stream` (EOF or a reset) within a bound that is only there to
/// fail rather than hang: the server has no idle timeout, so nothing else closes it.
async fn closed(stream: &mut TcpStream) -> bool {
    let mut byte = [0u8; 1];
    let read = tokio::time::timeout(Duration::from_secs(20), stream.read(&mut byte)).await;
    matches!(read, Ok(Ok(0) | Err(_)))
}

/// The counts once `done` holds (no time bound of its own: the test harness's is the bound).
async fn until(stats: &TcpStats, done: impl Fn(&TcpCounts) -> bool) -> TcpCounts {
    loop {
        let counts = stats.counts();
        if done(&counts) {
            return counts;
        }
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
}

#[tokio::test]
async fn with_the_cap_filled_by_idle_connections_from_eleven_addresses_a_new_client_is_served_and_a_poller_kept() {
    let (server, stats) = server().await;
    // An operator, answered once.
    let mut operator = connect_from(200, server).await;
    assert!(polled(&mut operator, 1).await);
    // 11 addresses, 2 connections each (their share), that never send a request: 22 against
    // the 19 slots left.
    let mut flood = Vec::new();
    for host in 10..21 {
        for _ in 0..PER_SOURCE {
            flood.push(connect_from(host, server).await);
        }
    }
    let counts = until(&stats, |c| c.accepted == 23).await;
    assert_eq!((counts.refused, counts.refused_source, counts.evicted_unanswered), (0, 0, 3), "{counts:?}");
    // The three closed to make room were never answered, the oldest of a source holding two
    // each time: the first of 127.0.0.10, of .11 and of .12 (flood[0], [2], [4]).
    for i in [0, 2, 4] {
        assert!(closed(&mut flood[i]).await, "flood[{i}]");
    }
    // A new client gets in, and so does the operator's next poll; the first of .13 made room.
    let mut newcomer = connect_from(100, server).await;
    assert!(polled(&mut newcomer, 1).await);
    assert!(polled(&mut operator, 2).await);
    assert!(closed(&mut flood[6]).await);
    let counts = until(&stats, |c| c.open == MAX as u64).await;
    assert_eq!((counts.evicted_unanswered, counts.evicted_idle, counts.refused), (4, 0, 0), "{counts:?}");

    // Now every flooding connection left is answered once, in order, and stays idle: each
    // next newcomer closes the one idle longest of a source holding two (the first of .14,
    // then of .15, ...), never the operator, who polls.
    for i in [1, 3, 5].into_iter().chain(7..flood.len()) {
        assert!(polled(&mut flood[i], u16::try_from(i).unwrap()).await, "flood[{i}]");
    }
    let mut lates = Vec::new();
    for (i, host) in (101..108).enumerate() {
        assert!(polled(&mut operator, 10 + u16::try_from(i).unwrap()).await);
        let mut late = connect_from(host, server).await;
        assert!(polled(&mut late, 1).await, "newcomer {i}");
        lates.push(late);
        assert!(closed(&mut flood[8 + 2 * i]).await, "the one idle longest, newcomer {i}");
    }
    assert!(polled(&mut operator, 99).await);
    assert!(polled(&mut newcomer, 2).await);
    let counts = until(&stats, |c| c.open == MAX as u64).await;
    assert_eq!((counts.evicted_unanswered, counts.evicted_idle, counts.refused), (4, 7, 0), "{counts:?}");
}

#[tokio::test]
async fn a_source_holding_many_loses_one_before_a_source_holding_one() {
    let (server, stats) = server().await;
    // 10 sources hold one idle, answered connection each, opened first; then 5 sources fill
    // the rest with two each, also answered.
    let mut single = Vec::new();
    for host in 10..20 {
        let mut stream = connect_from(host, server).await;
        assert!(polled(&mut stream, 1).await);
        single.push(stream);
    }
    let mut double = Vec::new();
    for host in 30..35 {
        for _ in 0..PER_SOURCE {
            let mut stream = connect_from(host, server).await;
            assert!(polled(&mut stream, 1).await);
            double.push(stream);
        }
    }
    // The singles are idle longest, yet a newcomer closes a double source's first.
    let mut newcomer = connect_from(100, server).await;
    assert!(polled(&mut newcomer, 1).await);
    assert!(closed(&mut double[0]).await);
    for stream in &mut single {
        assert!(polled(stream, 2).await);
    }
    assert_eq!(until(&stats, |c| c.evicted_idle == 1).await.refused, 0);
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
    let limits =
        TcpLimits { max_connections: 6, max_per_source: PER_SOURCE, idle_timeout: None, ..TcpLimits::default() };
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
