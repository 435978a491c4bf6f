//! A raw Modbus/TCP client over `std::net::TcpStream`, for the tests that send what no client
//! library would (pipelined requests, corrupt headers, half frames) to a server or a gateway.

use std::io::{ErrorKind, Read, Write};
use std::net::TcpStream;
use std::time::Duration;

/// A bound on how long one read may take before the test fails (not a timing claim).
const READ_BOUND: Duration = Duration::from_secs(20);

/// An MBAP frame: transaction `t`, unit `unit`, `pdu`.
pub(crate) fn mbap(t: u16, unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut frame = Vec::new();
    frame.extend_from_slice(&t.to_be_bytes());
    frame.extend_from_slice(&[0, 0]);
    frame.extend_from_slice(&u16::try_from(pdu.len() + 1).unwrap().to_be_bytes());
    frame.push(unit);
    frame.extend_from_slice(pdu);
    frame
}

/// A connection to `addr` whose reads fail after [`READ_BOUND`].
pub(crate) fn connect_to(addr: &str) -> TcpStream {
    let stream = TcpStream::connect(addr).unwrap_or_else(|e| panic!("connecting to {addr}: {e}"));
    stream.set_read_timeout(Some(READ_BOUND)).unwrap();
    stream
}

/// Reads one MBAP frame, or `None` if the server closed the connection.
pub(crate) fn read_frame(stream: &mut TcpStream) -> Option<Vec<u8>> {
    let mut header = [0u8; 7];
    match stream.read_exact(&mut header) {
        Ok(()) => {}
        Err(e) if matches!(e.kind(), ErrorKind::UnexpectedEof | ErrorKind::ConnectionReset) => return None,
        Err(e) => panic!("reading a reply: {e}"),
    }
    let len = usize::from(u16::from_be_bytes([header[4], header[5]]));
    let mut rest = vec![0u8; len.saturating_sub(1)];
    stream.read_exact(&mut rest).unwrap_or_else(|e| panic!("reading the reply after {header:02X?}: {e}"));
    Some([&header[..], &rest].concat())
}

/// Sends `pdu` to `unit` and returns the reply PDU (the transaction is checked).
pub(crate) fn ask(stream: &mut TcpStream, t: u16, unit: u8, pdu: &[u8]) -> Vec<u8> {
    stream.write_all(&mbap(t, unit, pdu)).unwrap();
    let reply = read_frame(stream).unwrap_or_else(|| panic!("connection closed instead of a reply to {pdu:02X?}"));
    assert_eq!(&reply[..2], &t.to_be_bytes(), "the transaction id is echoed");
    assert_eq!(reply[6], unit, "the reply comes from the unit asked");
    reply[7..].to_vec()
}

/// Whether the server closes `stream` without sending anything.
pub(crate) fn closed_silently(stream: &mut TcpStream) -> bool {
    let mut byte = [0u8; 1];
    match stream.read(&mut byte) {
        Ok(0) => true,
        Err(e) if e.kind() == ErrorKind::ConnectionReset => true,
        Ok(_) => false,
        Err(e) => panic!("waiting for the server to close: {e}"),
    }
}
