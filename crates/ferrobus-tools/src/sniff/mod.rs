//! The passive sniffer of an RTU line: listening without transmitting, with the core's
//! decoder ([`ferrobus_proto::sniff`]), and what is made of what was heard.
//!
//! ```text
//!   port ── reading thread (stamps each chunk) ──▶ Listener ── core Sniffer ──▶ BusEvent
//!                                                   (shared Clock, Sleeper)       │
//!                          Filter ─ Stats ─ SniffCapture (pcapng) ◀───────────────┘
//! ```
//!
//! - [`Listener`] opens the port and only ever reads it: nothing is written, so it cannot
//!   disturb the bus. A thread of its own reads the port and stamps each chunk the moment the
//!   read returns, so that whatever the caller does with an event never delays a timestamp.
//!   The decoder takes it from there (the chunk's last byte ended at that instant, the ones
//!   before it back to back); frames are found in both directions and a response is paired
//!   with its request there. The listener sleeps until the decoder's next deadline (a frame
//!   cut short, a silence that ends a frame) with the shared [`Clock`] and a
//!   [`Sleeper`], and hands out each event owned, as a [`BusEvent`].
//! - [`Filter`] decides which events are shown (by unit and function code), [`Stats`]
//!   counts them per unit, and [`SniffCapture`] writes them as pcapng that tshark and
//!   Wireshark decode, with what was wrong on the line as each packet's comment.
//!
//! Every instant of a [`BusEvent`] counts nanoseconds since the Unix epoch (as pcapng does).
//! The error of a timestamp is how late the OS hands over the bytes: on a pty (the virtual
//! line) tens of microseconds, more under load; behind a USB adapter up to its latency timer
//! (16 ms on an FTDI by default, 1 ms with `low_latency`), plus the USB poll interval. Bytes
//! delivered together look back to back, so behind an adapter a short silence before a frame
//! may be a delivery artefact.

mod capture;
mod stats;

use std::collections::VecDeque;
use std::io;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use ferrobus_proto::Instant;
use ferrobus_proto::frame::LineTiming;
use ferrobus_proto::frame::timing::PC_INCOMPLETE_TIMEOUT;
use ferrobus_proto::sniff::{FragmentKind, Role, SniffEvent, Sniffer, WireTime};
use tokio::io::AsyncReadExt;
use tokio::sync::mpsc;

pub use capture::SniffCapture;
pub use stats::{Filter, Stats, UnitStats};

use ferrobus::clock::Clock;
use ferrobus::timer::{Sleeper, Timer};
use ferrobus::{Error, SerialConfig};

/// What went wrong while listening.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SniffError {
    /// The port could not be opened (or its waiting bytes not dropped).
    #[error("opening {path} at {line}: {source}")]
    Open {
        /// The port's path, as given.
        path: String,
        /// The line settings it was opened with.
        line: ferrobus_proto::frame::LineConfig,
        /// The OS error.
        #[source]
        source: io::Error,
    },
    /// Reading the open port failed (an unplugged adapter, say).
    #[error("reading {path}: {source}")]
    Read {
        /// The port's path, as given.
        path: String,
        /// The OS error.
        #[source]
        source: io::Error,
    },
    /// The thread that reads the port could not be started.
    #[error("starting the reading thread: {source}")]
    Thread {
        /// The OS error.
        #[source]
        source: io::Error,
    },
}

impl SniffError {
    /// The OS error behind it.
    pub fn io_error(&self) -> &io::Error {
        match self {
            SniffError::Open { source, .. } | SniffError::Read { source, .. } | SniffError::Thread { source } => source,
        }
    }
}

/// The async layer's flat error, as a port failure: what was being done and the OS error.
impl From<SniffError> for Error {
    fn from(e: SniffError) -> Self {
        let context = match &e {
            SniffError::Open { path, line, .. } => format!("opening {path} at {line}"),
            SniffError::Read { path, .. } => format!("reading {path}"),
            SniffError::Thread { .. } => "starting the reading thread".to_string(),
        };
        let source = match e {
            SniffError::Open { source, .. } | SniffError::Read { source, .. } | SniffError::Thread { source } => source,
        };
        Error::io(context, source)
    }
}

/// What the sniffer heard, owned: the core's [`SniffEvent`] with its bytes copied, its
/// instants counted from the Unix epoch.
#[derive(Clone, PartialEq, Eq, Debug)]
pub enum BusEvent {
    /// A frame, with a good or a bad CRC.
    Frame {
        /// The whole ADU: unit, PDU, CRC.
        bytes: Vec<u8>,
        /// Request or response.
        role: Role,
        /// Whether its CRC is right.
        crc_ok: bool,
        /// When it was on the wire.
        time: WireTime,
        /// For a response paired with its request: from the request's end to its own.
        response_time: Option<Duration>,
    },
    /// Bytes that are no frame: the start of one cut short, or noise.
    Fragment {
        /// The bytes.
        bytes: Vec<u8>,
        /// Partial frame or noise.
        kind: FragmentKind,
        /// When they were on the wire.
        time: WireTime,
    },
    /// A request that got no response before the next request.
    Unanswered {
        /// Its unit.
        unit: u8,
        /// Its function code.
        function: u8,
        /// When it ended.
        request_end: Instant,
    },
}

impl BusEvent {
    /// The unit and function code (exception bit included) of a frame or an unanswered
    /// request; `None` for bytes that are no frame.
    pub fn unit_function(&self) -> Option<(u8, u8)> {
        match self {
            BusEvent::Frame { bytes, .. } => {
                Some((bytes.first().copied().unwrap_or_default(), bytes.get(1).copied().unwrap_or_default()))
            }
            BusEvent::Unanswered { unit, function, .. } => Some((*unit, *function)),
            BusEvent::Fragment { .. } => None,
        }
    }
}

impl From<SniffEvent<'_>> for BusEvent {
    fn from(event: SniffEvent<'_>) -> Self {
        match event {
            SniffEvent::Frame(f) => BusEvent::Frame {
                bytes: f.adu().to_vec(),
                role: f.role,
                crc_ok: f.crc_ok,
                time: f.time,
                response_time: f.reply.map(|r| r.response_time),
            },
            SniffEvent::Fragment(f) => BusEvent::Fragment { bytes: f.bytes.to_vec(), kind: f.kind, time: f.time },
            SniffEvent::Unanswered(u) => {
                BusEvent::Unanswered { unit: u.unit, function: u.function, request_end: u.request_end }
            }
        }
    }
}

/// What the reading thread sends.
#[derive(Debug)]
enum Chunk {
    /// Bytes, and the instant the read returned.
    Bytes(Vec<u8>, tokio::time::Instant),
    /// The port failed.
    Failed(io::Error),
}

/// The shared [`Clock`], its instants shifted to count from the Unix epoch: how a listener
/// stamps what it hears (and how a tap's record can be stamped alike). The system clock is
/// read once, at the epoch; later instants follow the monotonic clock.
#[derive(Clone, Copy, Debug)]
pub struct WallClock {
    clock: Clock,
    /// Nanoseconds since the Unix epoch at the clock's epoch.
    unix_at_epoch: u64,
}

impl WallClock {
    /// A clock whose epoch is now, with the system clock read now.
    pub fn now() -> Self {
        let clock = Clock::new();
        let unix = SystemTime::now().duration_since(UNIX_EPOCH).unwrap_or_default();
        WallClock { clock, unix_at_epoch: u64::try_from(unix.as_nanos()).unwrap_or(u64::MAX) }
    }

    /// A tokio instant (not earlier than the epoch), counted from the Unix epoch.
    pub fn unix(&self, t: tokio::time::Instant) -> Instant {
        Instant::from_nanos(self.clock.from_tokio(t).as_nanos().saturating_add(self.unix_at_epoch))
    }

    /// An instant counted from the Unix epoch, as a tokio instant (the clock's epoch if
    /// earlier).
    fn tokio(&self, t: Instant) -> tokio::time::Instant {
        self.clock.to_tokio(Instant::from_nanos(t.as_nanos().saturating_sub(self.unix_at_epoch)))
    }
}

/// A port being listened to: the decoder, fed by the reading thread, woken at its deadlines.
#[derive(Debug)]
pub struct Listener {
    chunks: mpsc::UnboundedReceiver<Chunk>,
    sniffer: Sniffer,
    clock: WallClock,
    sleeper: Sleeper,
    ready: VecDeque<BusEvent>,
    /// The port's path, for errors.
    path: String,
    /// Bytes waiting in the port when it was opened.
    predating: usize,
    ended: bool,
}

impl Listener {
    /// Opens the port of `serial` for reading only, in a thread of its own, and decodes what
    /// it hears with `timing` (the port's, or with t1.5 and t3.5 overridden). The bytes
    /// waiting in the port when it opens predate the listening: they are dropped and counted
    /// ([`Listener::predating`]). Needs a tokio runtime with time enabled.
    pub fn open(serial: SerialConfig, timing: LineTiming) -> Result<Listener, SniffError> {
        let path = serial.path.display().to_string();
        let (chunks, predating) = read_in_thread(serial)?;
        Ok(Listener::over(chunks, timing, path, predating))
    }

    /// A listener fed by `chunks` (the reading thread, or a test).
    fn over(chunks: mpsc::UnboundedReceiver<Chunk>, timing: LineTiming, path: String, predating: usize) -> Self {
        Listener {
            chunks,
            sniffer: Sniffer::new(timing).with_incomplete_timeout(PC_INCOMPLETE_TIMEOUT),
            clock: WallClock::now(),
            sleeper: Timer::Tokio.sleeper(),
            ready: VecDeque::new(),
            path,
            predating,
            ended: false,
        }
    }

    /// How many bytes were waiting in the port when it opened (dropped: they came before).
    pub fn predating(&self) -> usize {
        self.predating
    }

    /// The line timing the decoder uses.
    pub fn timing(&self) -> &LineTiming {
        self.sniffer.timing()
    }

    /// The next thing heard, in the order it was on the wire; `Ok(None)` once the port has
    /// ended (end of file). A read error is returned once, after every event before it; the
    /// listener ends with it. Cancel-safe: dropped while waiting, it loses nothing.
    pub async fn next(&mut self) -> Result<Option<BusEvent>, SniffError> {
        loop {
            if let Some(event) = self.ready.pop_front() {
                return Ok(Some(event));
            }
            if self.ended {
                return Ok(None);
            }
            let deadline = self.sniffer.poll_timeout();
            let wake = deadline.map(|d| self.clock.tokio(d));
            let chunk = tokio::select! {
                () = self.sleeper.sleep_until(wake) => None,
                chunk = self.chunks.recv() => Some(chunk),
            };
            let ready = &mut self.ready;
            match chunk {
                None => {
                    if let Some(d) = deadline {
                        self.sniffer.expire(d, |e| ready.push_back(e.into()));
                    }
                }
                Some(Some(Chunk::Bytes(bytes, at))) => {
                    self.sniffer.feed(self.clock.unix(at), &bytes, |e| ready.push_back(e.into()));
                }
                Some(Some(Chunk::Failed(source))) => {
                    self.ended = true;
                    return Err(SniffError::Read { path: self.path.clone(), source });
                }
                Some(None) => self.ended = true,
            }
        }
    }

    /// Settles what the decoder holds (a frame not yet ended, a request still waiting) and
    /// returns it with every event not yet taken: the end of listening.
    pub fn finish(&mut self) -> Vec<BusEvent> {
        let ready = &mut self.ready;
        self.sniffer.finish(|e| ready.push_back(e.into()));
        self.ended = true;
        self.ready.drain(..).collect()
    }
}

/// Opens the port in a thread of its own that only reads it, stamping each chunk as the read
/// returns; also returns how many bytes were waiting in the port when it opened, which are
/// dropped. An error opening it is returned here.
fn read_in_thread(config: SerialConfig) -> Result<(mpsc::UnboundedReceiver<Chunk>, usize), SniffError> {
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
                    match port.read(&mut buf).await {
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
        Ok(Ok(stale)) => Ok((rx, stale)),
        Ok(Err(source)) => Err(SniffError::Open { path, line, source }),
        Err(_) => Err(SniffError::Open { path, line, source: io::Error::other("the reading thread ended") }),
    }
}

#[cfg(test)]
mod tests;
