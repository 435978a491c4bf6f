//! A Modbus/TCP server with a cap of its own, and connections to it from many source
//! addresses (all of 127/8 is loopback, and a client bound to 127.0.0.N is another host as far
//! as the per-source limit goes).

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use ferrobus::server::{
    ConnectionPolicy, ServerOptions, Shared, TcpCounts, TcpLimits, TcpServeConfig, TcpStats, serve_tcp_with,
};
use ferrobus::{Timer, Transport};
use ferrobus_proto::ExceptionCode;
use ferrobus_proto::frame::LineTiming;
use ferrobus_proto::slave::{Handler, SlaveConfig};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpSocket, TcpStream};

/// Holding registers that all read 7.
pub(crate) struct Device;

impl Handler for Device {
    fn read_holding_registers(&mut self, _: u8, _: u16, out: &mut [u16]) -> Result<(), ExceptionCode> {
        out.fill(7);
        Ok(())
    }
}

/// The server's cap, and each source's.
pub(crate) const MAX: usize = 20;
pub(crate) const PER_SOURCE: usize = 2;

pub(crate) async fn server() -> (SocketAddr, Arc<TcpStats>) {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let limits = TcpLimits {
        max_connections: MAX,
        max_per_source: PER_SOURCE,
        connection: ConnectionPolicy { idle: None, ..ConnectionPolicy::TCP },
        ..TcpLimits::default()
    };
    let stats = Arc::clone(&limits.stats);
    let options = || ServerOptions::new(LineTiming::unpaced(), Timer::Tokio);
    let serve =
        TcpServeConfig { limits, ..TcpServeConfig::new(Transport::tcp(addr.to_string()), SlaveConfig::unit(1)) };
    tokio::spawn(serve_tcp_with(listener, serve, Shared::new(Device), options));
    (addr, stats)
}

/// A connection to `server` from 127.0.0.`host`.
pub(crate) async fn connect_from(host: u8, server: SocketAddr) -> TcpStream {
    let socket = TcpSocket::new_v4().unwrap();
    socket.bind(SocketAddr::from(([127, 0, 0, host], 0))).unwrap();
    socket.connect(server).await.unwrap()
}

/// Whether a read of holding register 0 on `stream` is answered with 7.
pub(crate) async fn polled(stream: &mut TcpStream, t: u16) -> bool {
    let [hi, lo] = t.to_be_bytes();
    if stream.write_all(&[hi, lo, 0, 0, 0, 6, 1, 0x03, 0, 0, 0, 1]).await.is_err() {
        return false;
    }
    let mut reply = [0u8; 11];
    stream.read_exact(&mut reply).await.is_ok() && reply == [hi, lo, 0, 0, 0, 5, 1, 0x03, 2, 0, 7]
}

/// Whether the server closed `stream` (EOF or a reset) within a bound that is only there to
/// fail rather than hang: the server has no idle timeout, so nothing else closes it.
pub(crate) async fn closed(stream: &mut TcpStream) -> bool {
    let mut byte = [0u8; 1];
    let read = tokio::time::timeout(Duration::from_secs(20), stream.read(&mut byte)).await;
    matches!(read, Ok(Ok(0) | Err(_)))
}

/// The counts once `done` holds (no time bound of its own: the test harness's is the bound).
pub(crate) async fn until(stats: &TcpStats, done: impl Fn(&TcpCounts) -> bool) -> TcpCounts {
    loop {
        let counts = stats.counts();
        if done(&counts) {
            return counts;
        }
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
}
