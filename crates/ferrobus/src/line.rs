//! A virtual RS-485 line on tokio's clock: the [`wire`](crate::wire) model, with endpoints.
//!
//! A pty pair has no wire: bytes arrive at once and no timing rule can be seen or broken. On
//! this line every character takes its character time (1.1458 ms at 9600 8E1) and reaches
//! every other endpoint when its last bit has left the wire; two endpoints transmitting at
//! once collide; frames begun less than t3.5 after the line was last busy are counted against
//! their sender; faults are drawn from a seed. All of that is decided by [`Wire`], a sans-IO
//! model that takes `now` in every call and is tested on explicit time. This module is the
//! thin adapter around it, and the only part of the line that reads a clock, sleeps or does
//! IO: a task owns the wire, stamps what endpoints write with the instant it was written,
//! sleeps until the wire's next event and hands out what it delivers, stamped with the
//! instant its last character left the wire — exactly what a receiver that stamps each
//! chunk with its arrival time needs, at one wake-up per frame instead of one per character.
//!
//! Endpoints are in-process ports ([`Line::endpoint`], for tests and the demo) or ptys that
//! other programs open like a serial port ([`Line::pty`]: a client, a peer stack, mbpoll).
//! A tap ([`Line::tap`], [`Line::tap_endpoint`]) is an endpoint for a sniffer: it hears every
//! character on the line and transmits nothing, and the line tells its owner what the tap
//! heard and when each run of characters ended on the wire — the reference a sniffer's
//! timestamps are measured against.
//!
//! A pty endpoint is held to its own settings, as a UART on a real wire would be: the line
//! reads the baud rate, data bits, parity and stop bits the program set on its pty (Linux
//! lets the master side read them), and what the program writes goes on the wire at those
//! settings, taking their character time ([`Wire::send_at`]); what the wire carries is
//! received at the program's settings through the wire's bit-level UART model
//! ([`Delivery::heard_by`](crate::wire::Delivery::heard_by)). A wire carries bits, not the
//! line's bytes: an endpoint at its sender's settings gets clean bytes, whatever the line's
//! (two programs at 9600 on a 19200 line understand each other), and in-process endpoints
//! are at the line's. One at another baud rate or parity than its sender gets garbage, with
//! parity and framing errors delivered as its terminal settings say (`IGNPAR` drops them,
//! `PARMRK` marks them `FF 00`, `INPCK` reads them as `00`, otherwise the garbled byte). The
//! characters of one write, or of one delivery, are taken to be back to back. Linux ptys
//! refuse parity (and on some kernels 7 data bits) with `EINVAL`, and ferrobus opens them
//! without it then: an endpoint that shows no parity, or 8 data bits, on a line with parity
//! or 7 is taken to have the line's — on a pty, only the baud rate, stop bits and a parity
//! that was accepted can be told.

use std::io;
use std::pin::Pin;
use std::sync::{Arc, Mutex, PoisonError};
use std::task::{Context, Poll};

use ferrobus_proto::frame::{LineConfig, LineTiming};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::sync::mpsc;
use tokio::time::Instant;

use crate::clock::Clock;
use crate::port::{BoxPort, ConnectWith, Connecting, Framing, Port, Transport};
use crate::timer::Timer;
pub use crate::wire::{EndpointStats, LineFaults, LineOptions, WireStats};
use crate::wire::{OnError, Receiver, Wire, heard};

/// Pty endpoints (Unix: other platforms have no ptys).
#[cfg(unix)]
mod pty;
#[cfg(unix)]
pub use pty::{Tap, TapRun};

/// Characters delivered to an endpoint.
struct Chunk {
    /// As the wire carried them.
    bytes: Vec<u8>,
    /// When the last of them left the wire.
    at: Instant,
    /// The settings they were sent at.
    tx: LineConfig,
}

enum Cmd {
    /// `bytes` written by `from` at `at`, at its settings `tx` (`None`: the line's).
    Write {
        from: usize,
        bytes: Vec<u8>,
        at: Instant,
        tx: Option<LineConfig>,
    },
    Attach {
        name: String,
        inbox: Inbox,
        id: tokio::sync::oneshot::Sender<usize>,
        tap: bool,
    },
    SetDead {
        id: usize,
        dead: bool,
    },
}

/// How the bus task hands an endpoint what it hears: a send on a channel, or (a tap's pty) a
/// write.
type Inbox = Box<dyn FnMut(Chunk) + Send>;

/// A handle to a running line. Cheap to clone; the line runs until every handle and endpoint
/// is dropped.
#[derive(Clone)]
pub struct Line {
    cmds: mpsc::UnboundedSender<Cmd>,
    stats: Arc<Mutex<WireStats>>,
    timing: LineTiming,
    options: LineOptions,
}

impl Line {
    /// Starts a line on the current tokio runtime.
    pub fn start(options: LineOptions) -> Line {
        let timing = LineTiming::new(&options.config);
        let (cmds, rx) = mpsc::unbounded_channel();
        let stats = Arc::new(Mutex::new(WireStats::default()));
        let bus = Bus::new(options, Arc::clone(&stats));
        tokio::spawn(bus.run(rx));
        Line { cmds, stats, timing, options }
    }

    /// The line timing (character time, t1.5, t3.5).
    pub fn timing(&self) -> LineTiming {
        if self.options.paced { self.timing } else { LineTiming::unpaced() }
    }

    /// The options the line was started with.
    pub fn options(&self) -> &LineOptions {
        &self.options
    }

    /// A new in-process endpoint.
    pub async fn endpoint(&self, name: impl Into<String>) -> io::Result<Endpoint> {
        let (inbox, rx) = mpsc::unbounded_channel::<Chunk>();
        let id = self.attach(name.into(), channel(inbox), false).await?;
        Ok(self.in_process(id, rx))
    }

    /// A new in-process tap: an endpoint that hears everything on the line and transmits
    /// nothing (what is written to it is counted in [`EndpointStats::refused`] and dropped).
    pub async fn tap_endpoint(&self, name: impl Into<String>) -> io::Result<Endpoint> {
        let (inbox, rx) = mpsc::unbounded_channel::<Chunk>();
        let id = self.attach(name.into(), channel(inbox), true).await?;
        Ok(self.in_process(id, rx))
    }

    /// A transport whose every connection is a new endpoint named `name`: RTU at the line's
    /// timing, waiting with a spinning timer on a paced line.
    pub fn transport(&self, name: &str) -> Transport {
        let line = self.clone();
        let name = name.to_string();
        let describe = format!("virtual line ({name})");
        let connector = ConnectWith::new(describe, move || -> Connecting {
            let (line, name) = (line.clone(), name.clone());
            Box::pin(async move { Ok(Box::new(line.endpoint(name).await?) as BoxPort) })
        });
        let timer = if self.options.paced { Timer::Spin } else { Timer::Tokio };
        Transport::custom(Framing::Rtu, self.timing(), connector).with_timer(timer)
    }

    fn in_process(&self, id: usize, inbox: mpsc::UnboundedReceiver<Chunk>) -> Endpoint {
        let config = self.options.config;
        Endpoint { id, to_bus: self.cmds.clone(), inbox, pending: Vec::new(), read: 0, arrival: None, config }
    }

    async fn attach(&self, name: String, inbox: Inbox, tap: bool) -> io::Result<usize> {
        let (tx, rx) = tokio::sync::oneshot::channel();
        let closed = || io::Error::new(io::ErrorKind::BrokenPipe, "the line has stopped");
        self.cmds.send(Cmd::Attach { name, inbox, id: tx, tap }).map_err(|_| closed())?;
        rx.await.map_err(|_| closed())
    }

    /// Makes endpoint `id` dead (it neither sends nor hears) or alive again.
    pub fn set_dead(&self, id: usize, dead: bool) {
        let _ = self.cmds.send(Cmd::SetDead { id, dead });
    }

    /// What the line has seen so far.
    pub fn stats(&self) -> WireStats {
        self.stats.lock().unwrap_or_else(PoisonError::into_inner).clone()
    }
}

/// An inbox that sends on `inbox`.
fn channel<T: From<Chunk> + Send + 'static>(inbox: mpsc::UnboundedSender<T>) -> Inbox {
    Box::new(move |chunk| {
        let _ = inbox.send(T::from(chunk));
    })
}

/// An in-process endpoint of a [`Line`]: a port.
pub struct Endpoint {
    id: usize,
    to_bus: mpsc::UnboundedSender<Cmd>,
    inbox: mpsc::UnboundedReceiver<Chunk>,
    pending: Vec<u8>,
    read: usize,
    arrival: Option<Instant>,
    /// Its settings: the line's.
    config: LineConfig,
}

impl Endpoint {
    /// Its id on the line (an index into [`WireStats::endpoints`]).
    pub fn id(&self) -> usize {
        self.id
    }
}

/// An endpoint knows when its bytes left the wire, and stamps what it writes with the instant
/// it was written: timing on the line does not depend on how soon tasks are scheduled.
impl Port for Endpoint {
    fn last_arrival(&self) -> Option<Instant> {
        self.arrival
    }
}

impl AsyncRead for Endpoint {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        let this = &mut *self;
        if this.read >= this.pending.len() {
            match this.inbox.poll_recv(cx) {
                Poll::Ready(Some(chunk)) => {
                    this.pending = if chunk.tx == this.config {
                        chunk.bytes
                    } else {
                        heard(chunk.tx, Receiver { config: this.config, on_error: OnError::Keep }, &chunk.bytes)
                    };
                    this.read = 0;
                    this.arrival = Some(chunk.at);
                }
                Poll::Ready(None) => return Poll::Ready(Ok(())),
                Poll::Pending => return Poll::Pending,
            }
        }
        let rest = this.pending.get(this.read..).unwrap_or_default();
        let n = rest.len().min(buf.remaining());
        buf.put_slice(&rest[..n]);
        this.read += n;
        Poll::Ready(Ok(()))
    }
}

impl AsyncWrite for Endpoint {
    fn poll_write(self: Pin<&mut Self>, _: &mut Context<'_>, data: &[u8]) -> Poll<io::Result<usize>> {
        match self.to_bus.send(Cmd::Write { from: self.id, bytes: data.to_vec(), at: Instant::now(), tx: None }) {
            Ok(()) => Poll::Ready(Ok(data.len())),
            Err(_) => Poll::Ready(Err(io::Error::new(io::ErrorKind::BrokenPipe, "the line has stopped"))),
        }
    }

    fn poll_flush(self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<io::Result<()>> {
        Poll::Ready(Ok(()))
    }

    fn poll_shutdown(self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<io::Result<()>> {
        Poll::Ready(Ok(()))
    }
}

/// The task that owns the wire: it takes commands, sleeps until the wire's next event on
/// tokio's clock, and hands out deliveries.
struct Bus {
    wire: Wire,
    inboxes: Vec<Inbox>,
    stats: Arc<Mutex<WireStats>>,
    clock: Clock,
}

impl Bus {
    fn new(options: LineOptions, stats: Arc<Mutex<WireStats>>) -> Self {
        let clock = Clock::new();
        Bus { wire: Wire::new(options, clock.now()), inboxes: Vec::new(), stats, clock }
    }

    async fn run(mut self, mut cmds: mpsc::UnboundedReceiver<Cmd>) {
        let paced = self.wire.options().paced;
        let mut sleeper = if paced { Timer::Spin } else { Timer::Tokio }.sleeper();
        loop {
            let deadline = self.wire.next_wake().map(|t| self.clock.to_tokio(t));
            tokio::select! {
                cmd = cmds.recv() => match cmd {
                    Some(cmd) => self.command(cmd, paced),
                    None => return,
                },
                () = sleeper.sleep_until(deadline) => self.deliver(),
            }
            self.publish();
        }
    }

    fn publish(&self) {
        *self.stats.lock().unwrap_or_else(PoisonError::into_inner) = self.wire.stats().clone();
    }

    fn command(&mut self, cmd: Cmd, paced: bool) {
        match cmd {
            Cmd::Write { from, bytes, at, tx } => {
                let at = self.clock.from_tokio(at);
                match tx {
                    Some(tx) => self.wire.send_at(from, tx, &bytes, at),
                    None => self.wire.send(from, &bytes, at),
                }
                if !paced {
                    self.deliver();
                }
            }
            Cmd::Attach { name, inbox, id, tap } => {
                self.inboxes.push(inbox);
                let _ = id.send(if tap { self.wire.attach_tap(name) } else { self.wire.attach(name) });
            }
            Cmd::SetDead { id, dead } => self.wire.set_dead(id, dead),
        }
    }

    /// Hands out what the wire has delivered by now.
    /// The stats are published first: an endpoint that has read something finds it counted.
    fn deliver(&mut self) {
        let deliveries = self.wire.advance(self.clock.now());
        self.publish();
        for delivery in deliveries {
            if let Some(inbox) = self.inboxes.get_mut(delivery.to) {
                let at = self.clock.to_tokio(delivery.at);
                inbox(Chunk { bytes: delivery.bytes, at, tx: delivery.tx });
            }
        }
    }
}
