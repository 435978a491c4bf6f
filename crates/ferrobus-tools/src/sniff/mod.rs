//! The passive sniffer of an RTU line: listening without transmitting, with the core's
//! decoder ([`ferrobus_proto::sniff`]) driven by the one loop, and what is made of what was
//! heard.
//!
//! ```text
//!   port ── reading thread: read, stamp ──▶ Stamped (a Port: last_arrival = the stamp)
//!                                              │
//!            Pump::run ── Engine: Sniffing (the core Sniffer, never transmits) ──▶ BusEvent
//!            (session UntilHeard: ends the run with each event)                     │
//!                          Filter ─ Stats ─ SniffCapture (pcapng) ◀─────────────────┘
//! ```
//!
//! - [`Listener`] opens the port and only ever reads it: nothing is written, so it cannot
//!   disturb the bus (the port it hands the pump refuses writes, and the engine never has
//!   any). The decoding runs on the pump as every other role does ([`Pump::run`] with the
//!   [`Sniffing`] engine): each chunk goes to the decoder with its arrival, the pump sleeps
//!   until the decoder's next deadline (a frame cut short, a silence that ends a frame), and
//!   [`Listener::next`] returns each event owned, as a [`BusEvent`], as soon as the engine
//!   has one. The decoder takes each chunk's arrival as the end of its last byte, the ones
//!   before it back to back; frames are found in both directions and a response is paired
//!   with its request there.
//! - [`Filter`] decides which events are shown (by unit and function code), [`Stats`]
//!   counts them per unit, and [`SniffCapture`] writes them as pcapng that tshark and
//!   Wireshark decode, with what was wrong on the line as each packet's comment.
//! - [`Pairing`] turns a paired read reply or an acknowledged write into what the device's
//!   memory holds ([`Heard`]), decoded through a profile as the poller decodes its replies
//!   (`values.rs`): the passive second master of `sniff --device` and a bridge's listen line.
//!
//! # Timestamps
//!
//! The pump stamps a read with [`Port::last_arrival`] when the port has one, else with the
//! clock when the read returns. Read on the caller's task, that would be when the caller next
//! awaits [`Listener::next`]: whatever it does with an event (printing it, or writing to a
//! pipe that is full, as `sniff --pcap - | tshark` may be) would delay the stamps of the bytes
//! that came meanwhile. So the port is read by a thread of its own, which stamps each chunk
//! the moment its read returns and does nothing else; the pump reads the stamped chunks from
//! it (`reader::Stamped`, a port whose `last_arrival` is the thread's stamp). The stamps are
//! the thread's, as before the sniffer ran on the pump, and the caller's pace changes none of
//! them: `bench/SNIFF.md` measures both, back to back.
//!
//! Every instant of a [`BusEvent`] counts nanoseconds since the Unix epoch (as pcapng does):
//! the engine shifts the pump's instants by the Unix time at the pump's epoch ([`WallClock`]).
//! The error of a timestamp is how late the OS hands over the bytes: on a pty (the virtual
//! line) tens of microseconds, more under load; behind a USB adapter up to its latency timer
//! (16 ms on an FTDI by default, 1 ms with `low_latency`), plus the USB poll interval. Bytes
//! delivered together look back to back, so behind an adapter a short silence before a frame
//! may be a delivery artefact.
//!
//! [`Port::last_arrival`]: ferrobus::port::Port::last_arrival

mod capture;
mod reader;
mod stats;
mod values;

use std::io;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use futures_util::FutureExt;

use ferrobus_proto::Instant;
use ferrobus_proto::frame::LineTiming;
use ferrobus_proto::frame::timing::PC_INCOMPLETE_TIMEOUT;
use ferrobus_proto::sniff::{FragmentKind, Role, SniffEvent, Sniffer, WireTime};

pub use capture::SniffCapture;
pub use stats::{Filter, Stats, UnitStats};
pub use values::{Heard, Pairing};

use ferrobus::clock::Clock;
use ferrobus::port::BoxPort;
use ferrobus::pump::{Engine, Pump, Session, Sniffing};
use ferrobus::timer::Timer;
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

/// The shared [`Clock`], its instants shifted to count from the Unix epoch: how a listener
/// stamps what it hears (and how a tap's record can be stamped alike). The system clock is
/// read once, at the start; later instants follow the monotonic clock.
#[derive(Clone, Copy, Debug)]
pub struct WallClock {
    clock: Clock,
    /// Nanoseconds since the Unix epoch at the clock's epoch.
    unix_at_epoch: u64,
}

impl WallClock {
    /// A clock whose epoch is now, with the system clock read now.
    pub fn now() -> Self {
        WallClock::of(Clock::new())
    }

    /// `clock`, with the system clock read now.
    fn of(clock: Clock) -> Self {
        let unix = SystemTime::now().duration_since(UNIX_EPOCH).unwrap_or_default();
        let since_epoch = clock.now().since_epoch();
        let at_epoch = unix.saturating_sub(since_epoch);
        WallClock { clock, unix_at_epoch: u64::try_from(at_epoch.as_nanos()).unwrap_or(u64::MAX) }
    }

    /// A tokio instant (not earlier than the epoch), counted from the Unix epoch.
    pub fn unix(&self, t: tokio::time::Instant) -> Instant {
        Instant::from_nanos(self.clock.from_tokio(t).as_nanos().saturating_add(self.unix_at_epoch))
    }
}

/// A port being listened to: the core's decoder as an engine ([`Sniffing`]) on the one loop
/// ([`Pump::run`]), fed by the port's reading thread.
pub struct Listener {
    /// `None` once the port has ended or failed, or listening has finished.
    port: Option<BoxPort>,
    pump: Pump,
    engine: Sniffing<BusEvent>,
    clock: WallClock,
    /// The port's path, for errors.
    path: String,
    /// Bytes waiting in the port when it was opened.
    predating: usize,
}

impl std::fmt::Debug for Listener {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Listener")
            .field("path", &self.path)
            .field("predating", &self.predating)
            .field("ended", &self.port.is_none())
            .field("clock", &self.clock)
            .finish_non_exhaustive()
    }
}

impl Listener {
    /// Opens the port of `serial` for reading only, in a thread of its own, and decodes what
    /// it hears with `timing` (the port's, or with t1.5 and t3.5 overridden). The bytes
    /// waiting in the port when it opens predate the listening: they are dropped and counted
    /// ([`Listener::predating`]). Needs a tokio runtime with time enabled.
    pub fn open(serial: SerialConfig, timing: LineTiming) -> Result<Listener, SniffError> {
        let path = serial.path.display().to_string();
        let (port, predating) = reader::read_in_thread(serial)?;
        Ok(Listener::over(Box::new(port), timing, path, predating))
    }

    /// A listener on `port` (the reading thread's, or a test's).
    fn over(port: BoxPort, timing: LineTiming, path: String, predating: usize) -> Self {
        let pump = Pump::new(Timer::Tokio.sleeper());
        // The decoder counts from the Unix epoch, the pump from its own: the engine shifts.
        let clock = WallClock::of(*pump.clock());
        let sniffer = Sniffer::new(timing).with_incomplete_timeout(PC_INCOMPLETE_TIMEOUT);
        let engine = Sniffing::new(sniffer, Duration::from_nanos(clock.unix_at_epoch));
        Listener { port: Some(port), pump, engine, clock, path, predating }
    }

    /// How many bytes were waiting in the port when it opened (dropped: they came before).
    pub fn predating(&self) -> usize {
        self.predating
    }

    /// The line timing the decoder uses.
    pub fn timing(&self) -> &LineTiming {
        self.engine.sniffer().timing()
    }

    /// The next thing heard, in the order it was on the wire; `Ok(None)` once the port has
    /// ended (end of file). A read error is returned once, after every event before it; the
    /// listener ends with it. Cancel-safe: dropped while waiting, it loses nothing (the pump
    /// hands the engine a chunk in the same poll that reads it, and the engine keeps what it
    /// heard until it is taken).
    pub async fn next(&mut self) -> Result<Option<BusEvent>, SniffError> {
        if let Some(event) = self.engine.poll_event() {
            return Ok(Some(event));
        }
        let Some(port) = self.port.as_mut() else { return Ok(None) };
        match self.pump.run(port, &mut self.engine, &mut UntilHeard).await {
            Turn::Heard(event) => Ok(Some(event)),
            Turn::Ended => {
                self.port = None;
                Ok(None)
            }
            Turn::Failed(source) => {
                self.port = None;
                Err(SniffError::Read { path: self.path.clone(), source })
            }
        }
    }

    /// The end of listening: hears what the port has already read (a reply that came as
    /// listening was stopped is not lost in the reading thread's queue), without waiting for
    /// more; closes the port; settles what the decoder holds (a frame not yet ended, a request
    /// still waiting); and returns it with every event not yet taken, in order. A read error
    /// among what was already read ends the draining and is returned beside the events before it.
    pub fn finish(&mut self) -> (Vec<BusEvent>, Option<SniffError>) {
        let mut events = Vec::new();
        let mut failure = None;
        // `next` is cancel-safe: a poll that would wait is dropped and loses nothing.
        while let Some(heard) = self.next().now_or_never() {
            match heard {
                Ok(Some(event)) => events.push(event),
                Ok(None) => break,
                Err(e) => {
                    failure = Some(e);
                    break;
                }
            }
        }
        self.port = None;
        self.engine.finish();
        events.extend(std::iter::from_fn(|| self.engine.poll_event()));
        (events, failure)
    }
}

/// How one run of the pump ended for the listener.
enum Turn {
    /// The engine heard something (its first event; the rest wait in the engine).
    Heard(BusEvent),
    /// The port ended.
    Ended,
    /// Reading failed.
    Failed(io::Error),
}

/// The listener's session on the pump: nothing to write, no deadline of its own; it ends the
/// run with the first thing the engine heard, or with the port.
struct UntilHeard;

impl Session<Sniffing<BusEvent>> for UntilHeard {
    type Output = Turn;

    async fn serve(&mut self, _: &Pump, _: &mut BoxPort, engine: &mut Sniffing<BusEvent>) -> Option<Turn> {
        engine.poll_event().map(Turn::Heard)
    }
    fn on_end(&mut self, error: Option<io::Error>) -> Turn {
        error.map_or(Turn::Ended, Turn::Failed)
    }
}

#[cfg(test)]
mod tests;
