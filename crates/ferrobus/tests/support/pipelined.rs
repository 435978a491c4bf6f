//! A Modbus/TCP device that holds requests back and answers them out of order, for the
//! pipelined client and the pipelined gateway line.

use std::time::Duration;

use ferrobus::ClientConfig;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

use super::{mbap, read_mbap};

/// One request as the device reads it: its transaction id and the register it reads.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Asked {
    pub(crate) tid: u16,
    pub(crate) register: u16,
}

/// Reads one request, a read of one holding register (0x03), from `stream`.
pub(crate) async fn asked(stream: &mut (impl AsyncReadExt + Unpin)) -> Asked {
    let (tid, pdu) = read_mbap(stream).await;
    assert_eq!((pdu.len(), pdu[0], &pdu[3..]), (5, 0x03, &[0x00, 0x01][..]), "{pdu:02X?}");
    Asked { tid, register: u16::from_be_bytes([pdu[1], pdu[2]]) }
}

/// What the device keeps in register `r`.
pub(crate) fn value(register: u16) -> u16 {
    register.wrapping_mul(7).wrapping_add(1)
}

/// The device's answer to `asked`: the register's value, under the request's id.
pub(crate) async fn answer(device: &mut TcpStream, asked: Asked) {
    let [hi, lo] = value(asked.register).to_be_bytes();
    device.write_all(&mbap(asked.tid, &[0x03, 0x02, hi, lo])).await.unwrap();
}

/// Reads `n` requests before answering any, then answers them newest first; returns them.
pub(crate) async fn hold_and_answer_backwards(device: &mut TcpStream, n: usize) -> Vec<Asked> {
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

/// A client of `in_flight` requests at once, with `timeout` and `retries` and no backoff.
pub(crate) fn pipelined(in_flight: usize, timeout: Duration, retries: u32) -> ClientConfig {
    ClientConfig { in_flight, timeout, retries, backoff: None, ..ClientConfig::default() }
}
