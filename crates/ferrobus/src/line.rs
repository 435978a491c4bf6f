//! A virtual RS-485 line: half-duplex, multidrop, with real wire timing and seeded faults.
//!
//! A pty pair has no wire: bytes arrive at once and no timing rule can be seen or broken. On
//! this line every character takes its character time (1.1458 ms at 9600 8E1) and reaches
//! every other endpoint when its last bit has left the wire. Two endpoints transmitting at
//! once collide: their characters are garbled and the collision is counted. The line watches
//! the silent intervals and counts, for each endpoint, every frame it began less than t3.5
//! after the previous one ended — who broke the rule.
//!
//! Endpoints are in-process ports ([`Line::endpoint`], for tests and the demo) or ptys that
//! other programs open like a serial port ([`Line::pty`]: a client, a peer stack, mbpoll).
//!
//! A pty endpoint is held to its own settings, as a UART on a real wire would be: the line
//! reads the baud rate, data bits, parity and stop bits the program set on its pty (Linux
//! lets the master side read them), and what the program writes is sent at those settings and
//! received at the line's, what the line carries is received at the program's — both through
//! a bit-level UART model. An endpoint at the line's settings gets clean bytes; one at the
//! wrong baud rate or parity gets garbage, with parity and framing errors delivered as its
//! terminal settings say (`IGNPAR` drops them, `PARMRK` marks them `FF 00`, `INPCK` reads them
//! as `00`, otherwise the garbled byte). The characters of one write, or of one delivery, are
//! taken to be back to back. Linux ptys refuse parity (and on some kernels 7 data bits) with
//! `EINVAL`, and ferrobus opens them without it then: an endpoint that shows no parity, or 8
//! data bits, on a line with parity or 7 is taken to have the line's — on a pty, only the baud
//! rate, stop bits and a parity that was accepted can be told.
//!
//! Faults are drawn from a seeded generator, so a run can be repeated: bit errors, lost
//! characters, gaps stretched inside a frame, noise bursts, and endpoints that go dead.
//!
//! Delivery is in bursts: the characters an endpoint sends back to back reach the others
//! together, at the time the last of them leaves the wire — exactly what a receiver that
//! stamps each chunk with its arrival time needs, at one wake-up per frame instead of one
//! per character.

use std::collections::BTreeMap;
use std::io;
use std::path::PathBuf;
use std::pin::Pin;
use std::sync::{Arc, Mutex, PoisonError};
use std::task::{Context, Poll};
use std::time::Duration;

use ferrobus_proto::frame::rtu::RtuCodec;
use ferrobus_proto::frame::{DataBits, Expect, LineConfig, LineTiming, Parity, RxEvent, feed};
use rand::rngs::SmallRng;
use rand::{RngExt, SeedableRng};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt, ReadBuf};
use tokio::sync::mpsc;
use tokio::time::Instant;

use crate::clock::Clock;
use crate::port::{BoxPort, ConnectWith, Connecting, Framing, Port, Pty, Transport};
use crate::sys::PeerSettings;
use crate::timer::Timer;
use crate::uart;

/// What goes wrong on the wire, drawn per character from a seeded generator.
#[derive(Clone, Copy, PartialEq, Debug, Default)]
pub struct LineFaults {
    /// The chance that a bit is flipped (per data bit).
    pub bit_error_rate: f64,
    /// The chance that a character is replaced by a random one.
    pub corrupt_rate: f64,
    /// The chance that a character is lost.
    pub drop_rate: f64,
    /// The chance that a gap of `stretch_by` opens before a character inside a frame.
    pub stretch_rate: f64,
    /// How long a stretched gap is.
    pub stretch_by: Duration,
    /// Noise bursts per second, at random times.
    pub noise_per_second: f64,
    /// The most characters in one noise burst (each burst has 1 to this many).
    pub noise_len: usize,
}

/// How a line behaves.
#[derive(Clone, Copy, PartialEq, Debug)]
pub struct LineOptions {
    /// Baud, data bits, parity, stop bits: the character time.
    pub config: LineConfig,
    /// Pace characters at the character time. Off, every write reaches the others at once:
    /// a pure software-overhead bench.
    pub paced: bool,
    /// Every endpoint also hears its own transmission (adapters without echo cancellation).
    pub echo: bool,
    /// Faults.
    pub faults: LineFaults,
    /// Seed of the fault generator.
    pub seed: u64,
}

impl LineOptions {
    /// A clean, paced line at `config`.
    pub fn new(config: LineConfig) -> Self {
        LineOptions { config, paced: true, echo: false, faults: LineFaults::default(), seed: 1 }
    }
}

/// What a line has seen. Per-endpoint figures are indexed by endpoint id.
#[derive(Clone, PartialEq, Eq, Debug, Default)]
pub struct LineStats {
    /// Characters put on the wire (noise included).
    pub characters: u64,
    /// Frames a sniffer on the wire decoded.
    pub frames: u64,
    /// Byte runs the sniffer threw away (noise, broken frames).
    pub discards: u64,
    /// Characters garbled by two endpoints transmitting at once.
    pub collisions: u64,
    /// Bits flipped.
    pub bit_errors: u64,
    /// Characters replaced.
    pub corrupted: u64,
    /// Characters lost.
    pub dropped: u64,
    /// Gaps stretched inside frames.
    pub stretched: u64,
    /// Noise characters injected.
    pub noise: u64,
    /// Each endpoint: name, characters sent, frames begun less than t3.5 after the line was
    /// last busy.
    pub endpoints: Vec<EndpointStats>,
}

/// One endpoint's figures.
#[derive(Clone, PartialEq, Eq, Debug, Default)]
pub struct EndpointStats {
    /// Its name (the pty path, or the name given).
    pub name: String,
    /// Characters it sent.
    pub characters: u64,
    /// Frames it began before the line had been silent for t3.5.
    pub gap_violations: u64,
    /// Whether it is dead (deaf and mute).
    pub dead: bool,
}

/// Characters delivered to an endpoint, and when the last of them left the wire.
type Chunk = (Vec<u8>, Instant);

enum Cmd {
    /// `bytes` written by `from` at `at`.
    Write {
        from: usize,
        bytes: Vec<u8>,
        at: Instant,
    },
    Attach {
        name: String,
        inbox: mpsc::UnboundedSender<Chunk>,
        id: tokio::sync::oneshot::Sender<usize>,
    },
    SetDead {
        id: usize,
        dead: bool,
    },
}

/// A handle to a running line. Cheap to clone; the line runs until every handle and endpoint
/// is dropped.
#[derive(Clone)]
pub struct Line {
    cmds: mpsc::UnboundedSender<Cmd>,
    stats: Arc<Mutex<LineStats>>,
    timing: LineTiming,
    options: LineOptions,
}

impl Line {
    /// Starts a line on the current tokio runtime.
    pub fn start(options: LineOptions) -> Line {
        let timing = LineTiming::new(&options.config);
        let (cmds, rx) = mpsc::unbounded_channel();
        let stats = Arc::new(Mutex::new(LineStats::default()));
        let bus = Bus::new(options, timing, Arc::clone(&stats));
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
        let id = self.attach(name.into(), inbox).await?;
        Ok(Endpoint { id, to_bus: self.cmds.clone(), inbox: rx, pending: Vec::new(), read: 0, arrival: None })
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

    /// A new endpoint as a pty for another program to open; returns its path. The pty lives
    /// as long as the line. What crosses it is seen at the settings the program set on the
    /// pty (see the [module docs](self)).
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
                            let bytes = buf.get(..n).unwrap_or_default();
                            let sent = match pty.peer_settings() {
                                Some(peer) => uart_bytes(as_held(peer.line, wire), wire, bytes, None),
                                None => bytes.to_vec(),
                            };
                            if sent.is_empty() { continue; }
                            let write = Cmd::Write { from: id, bytes: sent, at: Instant::now() };
                            if cmds.send(write).is_err() { return; }
                        }
                        _ => return,
                    },
                    chunk = rx.recv() => match chunk {
                        Some((bytes, _)) => {
                            let heard = match pty.peer_settings() {
                                Some(peer) => uart_bytes(wire, as_held(peer.line, wire), &bytes, Some(peer)),
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

    async fn attach(&self, name: String, inbox: mpsc::UnboundedSender<Chunk>) -> io::Result<usize> {
        let (tx, rx) = tokio::sync::oneshot::channel();
        let closed = || io::Error::new(io::ErrorKind::BrokenPipe, "the line has stopped");
        self.cmds.send(Cmd::Attach { name, inbox, id: tx }).map_err(|_| closed())?;
        rx.await.map_err(|_| closed())
    }

    /// Makes endpoint `id` dead (it neither sends nor hears) or alive again.
    pub fn set_dead(&self, id: usize, dead: bool) {
        let _ = self.cmds.send(Cmd::SetDead { id, dead });
    }

    /// What the line has seen so far.
    pub fn stats(&self) -> LineStats {
        self.stats.lock().unwrap_or_else(PoisonError::into_inner).clone()
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

/// What a receiver at `rx` makes of `bytes` sent at `tx`. Characters with an error are
/// delivered as `terminal` says (see [`PeerSettings`]); without one (the wire's own receiver,
/// which has no terminal), as the garbled byte.
fn uart_bytes(tx: LineConfig, rx: LineConfig, bytes: &[u8], terminal: Option<PeerSettings>) -> Vec<u8> {
    let mut out = Vec::with_capacity(bytes.len());
    for c in uart::receive(tx, rx, bytes) {
        match terminal {
            Some(t) if !c.is_clean() && t.ignore_errors => {}
            Some(t) if !c.is_clean() && t.mark_errors => out.extend([0xFF, 0x00, c.byte]),
            Some(t) if !c.is_clean() && t.check_parity => out.push(0x00),
            _ => out.push(c.byte),
        }
    }
    out
}

/// An in-process endpoint of a [`Line`]: a port.
pub struct Endpoint {
    id: usize,
    to_bus: mpsc::UnboundedSender<Cmd>,
    inbox: mpsc::UnboundedReceiver<Chunk>,
    pending: Vec<u8>,
    read: usize,
    arrival: Option<Instant>,
}

impl Endpoint {
    /// Its id on the line (an index into [`LineStats::endpoints`]).
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
                Poll::Ready(Some((chunk, at))) => {
                    this.pending = chunk;
                    this.read = 0;
                    this.arrival = Some(at);
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
        match self.to_bus.send(Cmd::Write { from: self.id, bytes: data.to_vec(), at: Instant::now() }) {
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

/// The sender of injected noise.
const NOISE: usize = usize::MAX;

/// A character on the wire.
#[derive(Clone, Copy, Debug)]
struct OnWire {
    start: Instant,
    from: usize,
    byte: u8,
    garbled: bool,
}

struct EndpointState {
    inbox: mpsc::UnboundedSender<Chunk>,
    /// When its last scheduled character leaves the wire.
    busy_until: Option<Instant>,
}

struct Bus {
    options: LineOptions,
    timing: LineTiming,
    char_time: Duration,
    rng: SmallRng,
    stats: Arc<Mutex<LineStats>>,
    local: LineStats,
    endpoints: Vec<EndpointState>,
    /// Characters scheduled, by the time their last bit leaves the wire.
    wire: BTreeMap<(Instant, u64), OnWire>,
    seq: u64,
    /// When the wire was last busy (the end of the last character scheduled on it).
    last_end: Option<Instant>,
    next_noise: Option<Instant>,
    sniffer: RtuCodec,
    clock: Clock,
}

impl Bus {
    fn new(options: LineOptions, timing: LineTiming, stats: Arc<Mutex<LineStats>>) -> Self {
        let char_time = if options.paced { timing.char_time() } else { Duration::ZERO };
        let mut bus = Bus {
            options,
            timing,
            char_time,
            rng: SmallRng::seed_from_u64(options.seed),
            stats,
            local: LineStats::default(),
            endpoints: Vec::new(),
            wire: BTreeMap::new(),
            seq: 0,
            last_end: None,
            next_noise: None,
            sniffer: RtuCodec::new(timing, Expect::Both),
            clock: Clock::new(),
        };
        bus.schedule_noise(Instant::now());
        bus
    }

    async fn run(mut self, mut cmds: mpsc::UnboundedReceiver<Cmd>) {
        let mut sleeper = if self.options.paced { Timer::Spin } else { Timer::Tokio }.sleeper();
        loop {
            let deadline = [self.next_delivery(), self.next_noise].into_iter().flatten().min();
            tokio::select! {
                cmd = cmds.recv() => match cmd {
                    Some(cmd) => self.command(cmd),
                    None => return,
                },
                () = sleeper.sleep_until(deadline) => {
                    let now = Instant::now();
                    if self.next_noise.is_some_and(|t| t <= now) {
                        self.noise(now);
                    }
                    self.deliver(now);
                }
            }
            self.publish();
        }
    }

    fn command(&mut self, cmd: Cmd) {
        match cmd {
            Cmd::Write { from, bytes, at } => {
                let dead = self.local.endpoints.get(from).is_none_or(|e| e.dead);
                if !dead {
                    self.schedule(from, &bytes, at);
                }
                if !self.options.paced {
                    self.deliver(Instant::now());
                }
            }
            Cmd::Attach { name, inbox, id } => {
                self.endpoints.push(EndpointState { inbox, busy_until: None });
                self.local.endpoints.push(EndpointStats { name, ..EndpointStats::default() });
                let _ = id.send(self.endpoints.len() - 1);
            }
            Cmd::SetDead { id, dead } => {
                if let Some(e) = self.local.endpoints.get_mut(id) {
                    e.dead = dead;
                }
            }
        }
    }

    /// Puts `bytes` from `from` on the wire, back to back from `now` or from the end of what
    /// it is already sending, with stretched gaps drawn; marks collisions; checks the gap
    /// before a new frame.
    fn schedule(&mut self, from: usize, bytes: &[u8], now: Instant) {
        let c = self.char_time;
        let busy = self.endpoints.get(from).and_then(|e| e.busy_until).filter(|t| *t > now);
        let mut start = busy.unwrap_or(now);
        // A frame begins when this sender was not already transmitting (or within t1.5 of
        // its last character): the line must then have been silent for t3.5.
        let continuing =
            self.endpoints.get(from).and_then(|e| e.busy_until).is_some_and(|t| t + self.timing.t1_5() > now);
        if !continuing && self.options.paced && from != NOISE {
            if let Some(last) = self.last_end {
                if start < last + self.timing.t3_5() {
                    if let Some(e) = self.local.endpoints.get_mut(from) {
                        e.gap_violations += 1;
                    }
                }
            }
        }
        for (i, &byte) in bytes.iter().enumerate() {
            if i > 0 && self.options.faults.stretch_rate > 0.0 && self.rng.random_bool(self.options.faults.stretch_rate)
            {
                start += self.options.faults.stretch_by;
                self.local.stretched += 1;
            }
            let end = start + c;
            // Another sender's character overlapping this one: both are garbled.
            let mut garbled = false;
            let overlapping = self.wire.range((start, 0)..(end + c, u64::MAX));
            let hits: Vec<(Instant, u64)> = overlapping
                .filter(|(_, w)| w.from != from && w.start < end && start < w.start + c)
                .map(|(k, _)| *k)
                .collect();
            for key in hits {
                if let Some(w) = self.wire.get_mut(&key) {
                    if !w.garbled {
                        w.garbled = true;
                        self.local.collisions += 1;
                    }
                    garbled = true;
                }
            }
            if garbled {
                self.local.collisions += 1;
            }
            self.seq += 1;
            self.wire.insert((end, self.seq), OnWire { start, from, byte, garbled });
            self.last_end = Some(self.last_end.map_or(end, |l| l.max(end)));
            start = end;
            self.local.characters += 1;
            if let Some(e) = self.local.endpoints.get_mut(from) {
                e.characters += 1;
            }
        }
        if let Some(e) = self.endpoints.get_mut(from) {
            e.busy_until = Some(start);
        }
    }

    /// When the first run of back-to-back characters leaves the wire.
    fn next_delivery(&self) -> Option<Instant> {
        let mut run_end: Option<Instant> = None;
        for ((end, _), w) in &self.wire {
            match run_end {
                Some(r) if w.start > r => break,
                _ => run_end = Some(run_end.map_or(*end, |r| r.max(*end))),
            }
        }
        run_end
    }

    /// Hands every character that has left the wire by `now` to every endpoint that hears it.
    fn deliver(&mut self, now: Instant) {
        let mut chunks: Vec<Vec<u8>> = vec![Vec::new(); self.endpoints.len()];
        let mut sniffed = Vec::new();
        let mut last = now;
        while let Some(entry) = self.wire.first_entry() {
            if entry.key().0 > now {
                break;
            }
            last = entry.key().0;
            let w = entry.remove();
            let Some(byte) = self.on_the_wire(w) else { continue };
            sniffed.push(byte);
            for (id, chunk) in chunks.iter_mut().enumerate() {
                let hears = id != w.from || self.options.echo;
                let dead = self.local.endpoints.get(id).is_some_and(|e| e.dead);
                if hears && !dead {
                    chunk.push(byte);
                }
            }
        }
        for (endpoint, chunk) in self.endpoints.iter().zip(chunks) {
            if !chunk.is_empty() {
                let _ = endpoint.inbox.send((chunk, last));
            }
        }
        if !sniffed.is_empty() {
            let local = &mut self.local;
            feed(&mut self.sniffer, self.clock.from_tokio(now), &sniffed, |event| match event {
                RxEvent::Frame(_) => local.frames += 1,
                RxEvent::Discarded { .. } => local.discards += 1,
            });
        }
        let local = &mut self.local;
        ferrobus_proto::frame::expire(&mut self.sniffer, self.clock.from_tokio(now), |event| match event {
            RxEvent::Frame(_) => local.frames += 1,
            RxEvent::Discarded { .. } => local.discards += 1,
        });
    }

    /// The character receivers get, after collisions and faults; `None` if it is lost.
    fn on_the_wire(&mut self, w: OnWire) -> Option<u8> {
        let faults = self.options.faults;
        if faults.drop_rate > 0.0 && self.rng.random_bool(faults.drop_rate.clamp(0.0, 1.0)) {
            self.local.dropped += 1;
            return None;
        }
        let mut byte = if w.garbled { self.rng.random::<u8>() } else { w.byte };
        if faults.corrupt_rate > 0.0 && self.rng.random_bool(faults.corrupt_rate.clamp(0.0, 1.0)) {
            byte ^= self.rng.random_range(1..=u8::MAX);
            self.local.corrupted += 1;
        }
        if faults.bit_error_rate > 0.0 {
            for bit in 0..8 {
                if self.rng.random_bool(faults.bit_error_rate.clamp(0.0, 1.0)) {
                    byte ^= 1 << bit;
                    self.local.bit_errors += 1;
                }
            }
        }
        Some(byte)
    }

    fn noise(&mut self, now: Instant) {
        let n = self.rng.random_range(1..=self.options.faults.noise_len.max(1));
        let bytes: Vec<u8> = (0..n).map(|_| self.rng.random()).collect();
        self.local.noise += n as u64;
        self.schedule(NOISE, &bytes, now);
        self.schedule_noise(now);
    }

    fn schedule_noise(&mut self, now: Instant) {
        let rate = self.options.faults.noise_per_second;
        self.next_noise = (rate > 0.0).then(|| {
            // Exponential gaps: a Poisson process of `rate` bursts per second.
            let u: f64 = self.rng.random_range(f64::MIN_POSITIVE..1.0);
            now + Duration::from_secs_f64((-u.ln() / rate).min(3600.0))
        });
    }

    fn publish(&self) {
        *self.stats.lock().unwrap_or_else(PoisonError::into_inner) = self.local.clone();
    }
}
