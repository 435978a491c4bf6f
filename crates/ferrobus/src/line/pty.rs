//! Pty endpoints of a [`Line`]: other programs open them like a serial port, and are held to
//! the settings they set on them (see the [line's docs](super)). Unix only: other platforms
//! have no ptys.

use std::io;
use std::path::PathBuf;

use ferrobus_proto::frame::{DataBits, LineConfig, Parity};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::mpsc;
use tokio::time::Instant;

use super::{Chunk, Cmd, Line};
use crate::port::Pty;
use crate::sys::PeerSettings;
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

    /// A pty endpoint; a tap when `record` is given, which gets what it heard.
    async fn pty_endpoint(&self, record: Option<mpsc::UnboundedSender<TapRun>>) -> io::Result<PathBuf> {
        let mut pty = Pty::open()?;
        let path = pty.path.clone();
        let (inbox, mut rx) = mpsc::unbounded_channel::<Chunk>();
        let id = self.attach(path.display().to_string(), inbox, record.is_some()).await?;
        let cmds = self.cmds.clone();
        let wire = self.options.config;
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
                    chunk = rx.recv() => match chunk {
                        Some(Chunk { bytes, at, tx }) => {
                            // At the settings the program has when it is handed the bytes
                            // (the line's if they cannot be read).
                            let rx = pty.peer_settings().map_or(
                                Receiver { config: wire, on_error: OnError::Keep },
                                |peer| receiver(peer, wire),
                            );
                            let heard = if rx.config == tx {
                                bytes.clone()
                            } else {
                                crate::wire::heard(tx, rx, &bytes)
                            };
                            if pty.write_all(&heard).await.is_err() { return; }
                            if let Some(record) = &record {
                                let _ = record.send(TapRun { bytes, end: at, written: Instant::now() });
                            }
                        }
                        None => return,
                    },
                }
            }
        });
        Ok(path)
    }
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
