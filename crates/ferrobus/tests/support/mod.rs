//! What the library's tests share, and the tools crate's with them: a unit on an in-memory
//! line, served by the server engine (the bytes are paced by the server's pump only as far as
//! t3.5 goes; the pipe itself is instant), MBAP frames written and read by hand, and the
//! Modbus/TCP devices written here ([`pipelined`], [`stalling`], [`sources`]). Each test crate
//! takes what it needs of it.
#![allow(dead_code)]

pub(crate) mod pipelined;
pub(crate) mod sources;
pub(crate) mod stalling;

use std::time::Duration;

use ferrobus::Transport;
use ferrobus::port::{BoxPort, ConnectWith, Connecting};
use ferrobus::server::{ServerOptions, Shared, serve};
use ferrobus_proto::frame::rtu::RtuCodec;
use ferrobus_proto::frame::{Expect, LineConfig, LineTiming};
use ferrobus_proto::slave::{Handler, Slave, SlaveConfig, UnitSet};
use tokio::io::AsyncReadExt;

/// The line's timing: 19200 baud.
pub(crate) fn timing() -> LineTiming {
    LineTiming::new(&LineConfig::new(19_200).unwrap())
}

/// An RTU transport to `device` answering unit 1, each connection a new in-memory line.
pub(crate) fn in_memory<H: Handler + Send + 'static>(name: &str, device: Shared<H>) -> Transport {
    let connector = ConnectWith::new(name.to_string(), move || -> Connecting {
        let mut device = device.clone();
        Box::pin(async move {
            let (client_end, server_end) = tokio::io::duplex(4096);
            tokio::spawn(async move {
                let units: UnitSet = [1u8].into_iter().collect();
                let config = SlaveConfig { units, response_wait: Duration::ZERO };
                let slave = Slave::new(RtuCodec::new(timing(), Expect::Both), config);
                let mut options = ServerOptions::new(timing(), ferrobus::Timer::Tokio);
                let _ = serve(slave, Box::new(server_end), &mut device, &mut options).await;
            });
            Ok(Box::new(client_end) as BoxPort)
        })
    });
    Transport::custom(ferrobus::Framing::Rtu, timing(), connector)
}

/// An MBAP frame: transaction `t`, unit 1, `pdu`.
pub(crate) fn mbap(t: u16, pdu: &[u8]) -> Vec<u8> {
    let mut frame = t.to_be_bytes().to_vec();
    frame.extend_from_slice(&[0, 0]);
    frame.extend_from_slice(&u16::try_from(pdu.len() + 1).unwrap().to_be_bytes());
    frame.push(1);
    frame.extend_from_slice(pdu);
    frame
}

/// Reads one MBAP frame from `stream`: (transaction, PDU).
pub(crate) async fn read_mbap(stream: &mut (impl AsyncReadExt + Unpin)) -> (u16, Vec<u8>) {
    let mut head = [0u8; 7];
    stream.read_exact(&mut head).await.unwrap();
    let mut pdu = vec![0u8; usize::from(u16::from_be_bytes([head[4], head[5]])) - 1];
    stream.read_exact(&mut pdu).await.unwrap();
    (u16::from_be_bytes([head[0], head[1]]), pdu)
}
