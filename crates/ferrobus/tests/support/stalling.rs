//! A Modbus/TCP device whose first connection stalls and whose later ones are served, for the
//! client and the gateway that must make the connection again.

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};

use super::{mbap, read_mbap};

/// What the device does on its first connection.
#[derive(Clone, Copy)]
pub(crate) enum First {
    /// Sends the first 5 bytes of the reply to the first request, then nothing.
    HalfReply,
    /// Reads every request and answers none.
    Silent,
}

/// The device: its first connection stalls as `first` says (held open, read, never answered
/// again); every later one is answered, register 0 holding 42.
pub(crate) async fn stalling(first: First) -> std::net::SocketAddr {
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
