//! Pty endpoints of a [`Line`]: other programs open them like a serial port, and are held to
//! the settings they set on them (see the [line's docs](super)). Unix only: other platforms
//! have no ptys.

use std::io;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use ferrobus_proto::frame::{DataBits, LineConfig, Parity};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::mpsc;
use tokio::time::Instant;

use super::{Chunk, Cmd, Inbox, Line};
use crate::port::Pty;
use crate::sys::{PeerSettings, PtyWriter};
use crate::wire::{OnError, Receiver};

/// A tap as a pty ([`Line::tap`]): a sniffer opens `path`; what the tap heard comes on
/// `heard` too, run by run.
#[derive(Debug)]
pub struct Tap {
    /// The pty for a sniffer to open.
    pub path: PathBuf,
    /// What the tap heard, run by run. Dropping it is harmless.
    pub heard: mpsc::UnboundedReceiver<TapRun>,
}

/// A run of back-to-back characters a tap heard.
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct TapRun {
    /// The characters, as the wire carried them.
    pub bytes: Vec<u8>,
    /// When the last of them left the wire.
    pub end: Instant,
    /// When the line's write of them to the tap's pty returned: how late the line itself was
    /// (a reader on the other end may have been woken a little before).
    pub written: Instant,
}

impl Line {
    /// A new endpoint as a pty for another program to open; returns its path. The pty lives
    /// as long as the line. What crosses it is seen at the settings the program set on the
    /// pty (see the [module docs](super)).
    pub async fn pty(&self) -> io::Result<PathBuf> {
        self.pty_endpoint(None).await
    }

    /// A new tap as a pty: the program on it hears everything on the line (at the settings it
    /// set, as on any pty endpoint) and transmits nothing — what it writes is dropped and
    /// counted in [`EndpointStats::refused`](crate::wire::EndpointStats::refused).
    pub async fn tap(&self) -> io::Result<Tap> {
        let (record, heard) = mpsc::unbounded_channel();
        let path = self.pty_endpoint(Some(record)).await?;
        Ok(Tap { path, heard })
    }

    /// A pty endpoint; a tap when `record` is given, which gets what it heard. A tap's pty is
    /// written by the line's bus task itself, as soon as the wire delivers ([`TapSink`]);
    /// another endpoint's by its own task.
    async fn pty_endpoint(&self, record: Option<mpsc::UnboundedSender<TapRun>>) -> io::Result<PathBuf> {
        let mut pty = Pty::open()?;
        let path = pty.path.clone();
        let wire = self.options.config;
        let (to_pty, mut rx) = mpsc::unbounded_channel::<Out>();
        let queued = Arc::new(AtomicUsize::new(0));
        let inbox: Inbox = match &record {
            Some(record) => {
                let sink = TapSink {
                    writer: pty.writer()?,
                    wire,
                    record: record.clone(),
                    backlog: to_pty,
                    queued: Arc::clone(&queued),
                };
                Box::new(move |chunk| sink.deliver(chunk))
            }
            None => super::channel(to_pty),
        };
        let id = self.attach(path.display().to_string(), inbox, record.is_some()).await?;
        let cmds = self.cmds.clone();
        tokio::spawn(async move {
            // The whole pty, so that its other end stays open while the task runs.
            let mut buf = [0u8; 512];
            loop {
                tokio::select! {
                    read = pty.read(&mut buf) => match read {
                        Ok(n) if n > 0 => {
                            // A tap's writes reach the wire model too, which refuses and
                            // counts them.
                            let bytes = buf.get(..n).unwrap_or_default().to_vec();
                            let tx = pty.peer_settings().map(|peer| as_held(peer.line, wire));
                            let write = Cmd::Write { from: id, bytes, at: Instant::now(), tx };
                            if cmds.send(write).is_err() { return; }
                        }
                        _ => return,
                    },
                    out = rx.recv() => match out {
                        Some(Out::Heard(Chunk { bytes, tx, .. })) => {
                            // At the settings the program has when it is handed the bytes.
                            let heard = as_heard(pty.peer_settings(), wire, tx, bytes);
                            if pty.write_all(&heard).await.is_err() { return; }
                        }
                        Some(Out::Backlog { rest, run }) => {
                            if pty.write_all(&rest).await.is_err() { return; }
                            if let Some(record) = &record {
                                let _ = record.send(TapRun { written: Instant::now(), ..run });
                            }
                            queued.fetch_sub(1, Ordering::AcqRel);
                        }
                        None => return,
                    },
                }
            }
        });
        Ok(path)
    }
}

/// What a pty endpoint's task is handed.
enum Out {
    /// Characters to write at the settings the program has then.
    Heard(Chunk),
    /// What a tap's pty did not take at once: the rest of what the program hears, to write
    /// when there is room, and the run to record then.
    Backlog { rest: Vec<u8>, run: TapRun },
}

impl From<Chunk> for Out {
    fn from(chunk: Chunk) -> Out {
        Out::Heard(chunk)
    }
}

/// A tap's pty as the line's bus task writes it: at once, in the task that owns the wire,
/// without waking another task first (the line's lateness is what a sniffer's timestamps are
/// measured against). What the pty's buffer does not take (a sniffer that is not reading) goes
/// to the pty's task, which waits for room; while any is queued there, what follows is queued
/// behind it, so that the sniffer hears everything in order.
struct TapSink {
    writer: PtyWriter,
    wire: LineConfig,
    record: mpsc::UnboundedSender<TapRun>,
    backlog: mpsc::UnboundedSender<Out>,
    /// Backlog items the pty's task has not written yet.
    queued: Arc<AtomicUsize>,
}

impl TapSink {
    fn deliver(&self, chunk: Chunk) {
        let heard = as_heard(self.writer.peer_settings(), self.wire, chunk.tx, chunk.bytes.clone());
        let mut written = 0;
        if self.queued.load(Ordering::Acquire) == 0 {
            match self.writer.try_write(&heard) {
                Ok(n) => written = n,
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
                // The pty is gone: so is the sniffer.
                Err(_) => return,
            }
        }
        let run = TapRun { bytes: chunk.bytes, end: chunk.at, written: Instant::now() };
        if written >= heard.len() {
            let _ = self.record.send(run);
        } else {
            self.queued.fetch_add(1, Ordering::AcqRel);
            let rest = heard.get(written..).unwrap_or_default().to_vec();
            if self.backlog.send(Out::Backlog { rest, run }).is_err() {
                self.queued.fetch_sub(1, Ordering::AcqRel);
            }
        }
    }
}

/// What a program at `peer` (the line's settings if they cannot be read) hears of `bytes`
/// sent at `tx`.
fn as_heard(peer: Option<PeerSettings>, wire: LineConfig, tx: LineConfig, bytes: Vec<u8>) -> Vec<u8> {
    let rx = peer.map_or(Receiver { config: wire, on_error: OnError::Keep }, |peer| receiver(peer, wire));
    if rx.config == tx { bytes } else { crate::wire::heard(tx, rx, &bytes) }
}

/// A pty endpoint's settings with what a pty cannot hold taken from the `wire`: no parity
/// where the wire has parity, 8 data bits where it has 7.
fn as_held(peer: LineConfig, wire: LineConfig) -> LineConfig {
    let mut held = peer;
    if peer.parity == Parity::None {
        held = held.with_parity(wire.parity);
    }
    if peer.data_bits == DataBits::Eight {
        held = held.with_data_bits(wire.data_bits);
    }
    held
}

/// A pty endpoint's settings as the wire's UART model takes them.
fn receiver(peer: PeerSettings, wire: LineConfig) -> Receiver {
    let on_error = if peer.ignore_errors {
        OnError::Drop
    } else if peer.mark_errors {
        OnError::Mark
    } else if peer.check_parity {
        OnError::Zero
    } else {
        OnError::Keep
    };
    Receiver { config: as_held(peer.line, wire), on_error }
}
