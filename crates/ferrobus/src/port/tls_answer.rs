//! A Modbus/TCP connection that a Modbus/TCP Security (mbaps) server answered: the server
//! sees no TLS ClientHello and sends a TLS alert record (`15 03 03 00 02 02 32`), or, for
//! some servers, its own handshake record. To an MBAP reader those bytes are a header with
//! protocol id 0x03xx — garbage, then the connection closes, and the user is told only that
//! the server hung up. [`FirstBytes`] reads the first three bytes of the connection and turns
//! a TLS record there into a [`TlsAnswer`] error that says what the server speaks.
//!
//! A TLS record begins with its type (0x15 an alert, 0x16 a handshake) and its version
//! (0x03 0x01-0x04: TLS 1.0 to 1.3's record version). As an MBAP header that is transaction
//! id 0x1503 or 0x1603 with a protocol id 0x01xx-0x04xx, which Modbus never sends (its
//! protocol id is 0): the check has no false alarm on a Modbus/TCP stream. (SSL 3.0's 0x0300
//! would be protocol id 0: it is not taken for TLS, and no server sends it now.) RTU over TCP is not checked: `15 03 04 ...` is an RTU reply.

use std::fmt;
use std::io;
use std::pin::Pin;
use std::task::{Context, Poll};

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

/// What a plain Modbus/TCP client got from a TLS server: the first bytes of a TLS record.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TlsAnswer {
    /// The record's type: 0x15 (an alert) or 0x16 (a handshake).
    pub record: u8,
}

impl fmt::Display for TlsAnswer {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let what = if self.record == ALERT { "an alert" } else { "a handshake" };
        write!(
            f,
            "the server answered with a TLS record ({what}): it speaks Modbus/TCP Security (mbaps), not plain Modbus/TCP"
        )
    }
}

impl std::error::Error for TlsAnswer {}

const ALERT: u8 = 0x15;
const HANDSHAKE: u8 = 0x16;

/// Whether `head` (the first three bytes a server sent) begin a TLS record.
fn is_tls_record(head: [u8; 3]) -> bool {
    matches!(head, [ALERT | HANDSHAKE, 0x03, 0x01..=0x04])
}

/// A stream whose first three bytes are checked for a TLS record ([`TlsAnswer`]).
#[derive(Debug)]
pub(crate) struct FirstBytes<S> {
    inner: S,
    /// The first bytes read, until three have been.
    head: [u8; 3],
    seen: usize,
}

impl<S> FirstBytes<S> {
    pub(crate) fn new(inner: S) -> Self {
        FirstBytes { inner, head: [0; 3], seen: 0 }
    }
}

impl<S: AsyncRead + Unpin> AsyncRead for FirstBytes<S> {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        let before = buf.filled().len();
        let this = &mut *self;
        let polled = Pin::new(&mut this.inner).poll_read(cx, buf);
        if this.seen < this.head.len()
            && let Poll::Ready(Ok(())) = polled
        {
            for &byte in buf.filled().get(before..).unwrap_or_default() {
                if let Some(slot) = this.head.get_mut(this.seen) {
                    *slot = byte;
                    this.seen += 1;
                }
            }
            if this.seen == this.head.len() && is_tls_record(this.head) {
                // A read that fails hands over no bytes.
                buf.set_filled(before);
                return Poll::Ready(Err(io::Error::new(
                    io::ErrorKind::InvalidData,
                    TlsAnswer { record: this.head[0] },
                )));
            }
        }
        polled
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for FirstBytes<S> {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.inner).poll_write(cx, buf)
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    use super::*;

    /// What reading the bytes written in `pieces` through [`FirstBytes`] gives.
    async fn read(pieces: &[&[u8]]) -> io::Result<Vec<u8>> {
        let (mut server, client) = tokio::io::duplex(64);
        for piece in pieces {
            server.write_all(piece).await.unwrap();
        }
        drop(server);
        let mut out = Vec::new();
        FirstBytes::new(client).read_to_end(&mut out).await.map(|_| out)
    }

    #[tokio::test]
    async fn a_tls_alert_is_told_as_such_and_modbus_passes_untouched() {
        let alert = read(&[&[0x15, 0x03, 0x03, 0x00, 0x02, 0x02, 0x32]]).await.unwrap_err();
        let answer = alert.get_ref().and_then(|e| e.downcast_ref::<TlsAnswer>()).copied();
        assert_eq!(answer, Some(TlsAnswer { record: 0x15 }));
        assert!(alert.to_string().contains("TLS record (an alert)"), "{alert}");
        // Byte by byte, as a slow link may deliver it.
        let split = read(&[&[0x16], &[0x03], &[0x01, 0x00]]).await.unwrap_err();
        assert_eq!(split.kind(), io::ErrorKind::InvalidData);
        // A Modbus/TCP reply, whatever its transaction id, is read as it came.
        let reply = [0x15, 0x03, 0x00, 0x00, 0x00, 0x05, 0x01, 0x03, 0x02, 0x12, 0x34];
        assert_eq!(read(&[&reply]).await.unwrap(), reply);
        assert_eq!(read(&[&[0x16, 0x03]]).await.unwrap(), [0x16, 0x03], "two bytes are no record");
    }
}
