//! The sniffer's port: read in a thread of its own that stamps each chunk the moment its read
//! returns, and handed to the pump as a [`Port`] whose [`Port::last_arrival`] is that stamp.
//!
//! The thread only reads and stamps; the decoding, the deadlines and the end are the pump's
//! ([`Pump::run`](ferrobus::pump::Pump::run)). The port refuses every write: nothing can reach
//! the bus through it.

use std::io;
use std::pin::Pin;
use std::task::{Context, Poll};

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, ReadBuf};
use tokio::sync::mpsc;

use ferrobus::SerialConfig;
use ferrobus::port::Port;

use super::SniffError;

/// What the reading thread sends.
#[derive(Debug)]
pub(super) enum Chunk {
    /// Bytes, and the instant the read returned.
    Bytes(Vec<u8>, tokio::time::Instant),
    /// The port failed.
    Failed(io::Error),
}

/// The chunks the reading thread stamped, as a read-only port (a test feeds one by hand).
#[derive(Debug)]
pub(super) struct Stamped {
    chunks: mpsc::UnboundedReceiver<Chunk>,
    /// The chunk being read, and how much of it was.
    pending: Vec<u8>,
    read: usize,
    /// When the chunk being read arrived.
    arrival: Option<tokio::time::Instant>,
}

impl Stamped {
    /// The port of `chunks`; it ends when their sender is dropped.
    pub(super) fn new(chunks: mpsc::UnboundedReceiver<Chunk>) -> Self {
        Stamped { chunks, pending: Vec::new(), read: 0, arrival: None }
    }
}

impl AsyncRead for Stamped {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        let this = &mut *self;
        while this.read >= this.pending.len() {
            match this.chunks.poll_recv(cx) {
                Poll::Ready(Some(Chunk::Bytes(bytes, at))) => {
                    (this.pending, this.read, this.arrival) = (bytes, 0, Some(at));
                }
                Poll::Ready(Some(Chunk::Failed(e))) => return Poll::Ready(Err(e)),
                Poll::Ready(None) => return Poll::Ready(Ok(())),
                Poll::Pending => return Poll::Pending,
            }
        }
        let rest = this.pending.get(this.read..).unwrap_or_default();
        let n = rest.len().min(buf.remaining());
        buf.put_slice(rest.get(..n).unwrap_or_default());
        this.read = this.read.saturating_add(n);
        Poll::Ready(Ok(()))
    }
}

/// Read only: every write fails, and nothing is written.
impl AsyncWrite for Stamped {
    fn poll_write(self: Pin<&mut Self>, _: &mut Context<'_>, _: &[u8]) -> Poll<io::Result<usize>> {
        Poll::Ready(Err(io::Error::new(io::ErrorKind::PermissionDenied, "the sniffer's port is read only")))
    }

    fn poll_flush(self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<io::Result<()>> {
        Poll::Ready(Ok(()))
    }

    fn poll_shutdown(self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<io::Result<()>> {
        Poll::Ready(Ok(()))
    }
}

/// The instant the thread's read returned is when the bytes arrived.
impl Port for Stamped {
    fn last_arrival(&self) -> Option<tokio::time::Instant> {
        self.arrival
    }
}

/// Opens the port in a thread of its own that only reads it, stamping each chunk as the read
/// returns; also returns how many bytes were waiting in the port when it opened, which are
/// dropped. An error opening it is returned here. The thread ends, closing the port, at the
/// port's end, at a read error, or as soon as the returned port is dropped.
pub(super) fn read_in_thread(config: SerialConfig) -> Result<(Stamped, usize), SniffError> {
    let (tx, rx) = mpsc::unbounded_channel();
    let (opened_tx, opened_rx) = std::sync::mpsc::channel::<io::Result<usize>>();
    let (path, line) = (config.path.display().to_string(), config.line);
    std::thread::Builder::new()
        .name("sniff-reader".into())
        .spawn(move || {
            let runtime = match tokio::runtime::Builder::new_current_thread().enable_all().build() {
                Ok(r) => r,
                Err(e) => {
                    let _ = opened_tx.send(Err(e));
                    return;
                }
            };
            runtime.block_on(async move {
                // Read only: nothing is ever written to the port.
                let opened = ferrobus::port::open_serial(&config)
                    .and_then(|mut port| port.discard_input().map(|stale| (port, stale)));
                let mut port = match opened {
                    Ok((port, stale)) => {
                        let _ = opened_tx.send(Ok(stale));
                        port
                    }
                    Err(e) => {
                        let _ = opened_tx.send(Err(e));
                        return;
                    }
                };
                let mut buf = [0u8; 1024];
                loop {
                    let read = tokio::select! {
                        read = port.read(&mut buf) => read,
                        // The listener is gone: the port is closed at once, not at the next chunk.
                        () = tx.closed() => return,
                    };
                    match read {
                        Ok(0) => return,
                        Ok(n) => {
                            let at = tokio::time::Instant::now();
                            let bytes = buf.get(..n).unwrap_or_default().to_vec();
                            if tx.send(Chunk::Bytes(bytes, at)).is_err() {
                                return;
                            }
                        }
                        Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                        Err(e) => {
                            let _ = tx.send(Chunk::Failed(e));
                            return;
                        }
                    }
                }
            });
        })
        .map_err(|source| SniffError::Thread { source })?;
    match opened_rx.recv() {
        Ok(Ok(stale)) => Ok((Stamped::new(rx), stale)),
        Ok(Err(source)) => Err(SniffError::Open { path, line, source }),
        Err(_) => Err(SniffError::Open { path, line, source: io::Error::other("the reading thread ended") }),
    }
}
