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

impl Line {
    /// A new endpoint as a pty for another program to open; returns its path. The pty lives
    /// as long as the line. What crosses it is seen at the settings the program set on the
    /// pty (see the [module docs](super)).
    pub async fn pty(&self) -> io::Result<PathBuf> {
        let mut pty = Pty::open()?;
        let path = pty.path.clone();
        let (inbox, mut rx) = mpsc::unbounded_channel::<Chunk>();
        let id = self.attach(path.display().to_string(), inbox).await?;
        let cmds = self.cmds.clone();
        let wire = self.options.config;
        tokio::spawn(async move {
            // The whole pty, so that its other end stays open while the task runs.
            let mut buf = [0u8; 512];
            loop {
                tokio::select! {
                    read = pty.read(&mut buf) => match read {
                        Ok(n) if n > 0 => {
                            let bytes = buf.get(..n).unwrap_or_default().to_vec();
                            let tx = pty.peer_settings().map(|peer| as_held(peer.line, wire));
                            let write = Cmd::Write { from: id, bytes, at: Instant::now(), tx };
                            if cmds.send(write).is_err() { return; }
                        }
                        _ => return,
                    },
                    chunk = rx.recv() => match chunk {
                        Some((bytes, _)) => {
                            // At the settings the program has when it is handed the bytes.
                            let heard = match pty.peer_settings() {
                                Some(peer) => crate::wire::heard(wire, receiver(peer, wire), &bytes),
                                None => bytes,
                            };
                            if pty.write_all(&heard).await.is_err() { return; }
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
