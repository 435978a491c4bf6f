//! The one driver loop: feeds an engine the bytes a port reads with the time they arrived,
//! sleeps until the earliest of the engine's deadline and the session's own, and writes
//! what the engine hands out through the one RS-485-aware writer.
//!
//! ```text
//!   port ──read, arrival time──▶ Engine::on_bytes   (what it did not take is kept, in order)
//!   sleep until min(Engine::poll_timeout, session's deadlines) ──▶ Engine::handle_timeout
//!   Engine::poll_transmit ──▶ write_frame (RTS raised around the frame) ──▶ port
//!   Engine::poll_event ──▶ the session: the client's completions, the server's observer
//! ```
//!
//! Who runs on the pump:
//!
//! ```text
//!   ferrobus_proto::master::Master ◀── Engine ──▶ ferrobus_proto::slave::Slave (deferred)
//!            │                                                  │ poll_request / respond
//!   driver::Transaction (a request)       server::Replies: authorize filter, then Service::answer
//!   driver::Between (between requests)
//!   driver::Linger (a reply owed at the end)
//!                                            ├─ server::serve, serve_tcp   (a Handler, a Shared one)
//!                                            ├─ the simulator              (Shared<Sim> + FaultFilter)
//!                                            └─ tls::serve_tls_with        (RoleCheck as the filter)
//!                                         ferrobus-tools, through the same Session:
//!                                            the gateway's front (serve_tcp, serve_tls,
//!                                            serve_connection): screen, Authorize, each request
//!                                            to its line's queue, the reply back (Session::wait)
//!                                            the reverse gateway: each request forwarded to its
//!                                            TCP server, the answer back (Session::wait)
//!   ferrobus_proto::scan::Survey   ◀── Engine (never transmits): scan's listen phase
//!   ferrobus_proto::sniff::Sniffer ◀── Engine (Sniffing, never transmits): the tools'
//!                                       sniff::Listener, each event to its caller
//! ```
//!
//! Every role is an [`Engine`] — the client's [`Master`], the server's [`Slave`] in its
//! deferred mode (it frames and admits requests and keeps their order and reply timing; the
//! session answers them) — driven by the one loop, [`Pump::run`], so reading, keeping what a
//! blocked engine did not take, sleeping and waking are written once. The role-specific parts
//! are a [`Session`] the loop calls at fixed points (serve the engine's output, add deadlines,
//! note a read, act on a wake before the engine, end with the port): the client's request
//! (`driver::Transaction`), the time between requests, when the client waits on its command
//! channel and the port at once (`driver::Between`, the pipelined driver's whole turn too),
//! and the server's replies with their filters and observer (`server::Replies`; when a
//! connection closes is the slave engine's own policy). Which codec a transport
//! takes is decided once too (`Codec::for_transport`). Echo suppression is the master
//! engine's own (it counts its echo off the bytes it is fed), so the pump feeds every byte
//! unchanged.
//!
//! Outside this crate, a program drives an engine of its own with [`Pump::new`] and
//! [`Pump::run`], writing its frames with [`write_frame`], and takes its codec with
//! [`Codec::for_transport`]: the tools crate's gateway front and reverse gateway, its
//! scanner and its sniffer do exactly that.

use std::collections::VecDeque;
use std::future::Future;
use std::io;
use std::time::Duration;

use ferrobus_proto::Instant;
use ferrobus_proto::error::BufferTooSmall;
use ferrobus_proto::frame::ascii::AsciiCodec;
use ferrobus_proto::frame::mbap::MbapCodec;
use ferrobus_proto::frame::rtu::RtuCodec;
use ferrobus_proto::frame::{AduHeader, Framing, LineTiming, RxEvent, RxStats};
use ferrobus_proto::master::pipeline::{Pipeline, Ticket};
use ferrobus_proto::master::{Completion, Master};
use ferrobus_proto::scan::Survey;
use ferrobus_proto::slave::{Slave, SlaveEvent};
use ferrobus_proto::sniff::{SniffEvent, Sniffer};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

use crate::clock::Clock;
use crate::log::Hex;
use crate::port::{BoxPort, Rs485, Transport};
use crate::timer::Sleeper;

/// The contract every engine the pump drives keeps: the five verbs of the sans-IO core.
pub trait Engine {
    /// What the engine reports.
    type Event<'a>
    where
        Self: 'a;

    /// Bytes arrived at `now`; returns how many were taken (fewer only while blocked).
    fn on_bytes(&mut self, now: Instant, bytes: &[u8]) -> usize;
    /// The next instant [`Engine::handle_timeout`] is due.
    fn poll_timeout(&self) -> Option<Instant>;
    /// That instant has come.
    fn handle_timeout(&mut self, now: Instant);
    /// Bytes to write now, if any.
    fn poll_transmit(&mut self, now: Instant, buf: &mut [u8]) -> Option<usize>;
    /// The next report for the session.
    fn poll_event(&mut self) -> Option<Self::Event<'_>>;
    /// Whether the engine takes no bytes until the session has taken its output.
    fn is_blocked(&self) -> bool {
        false
    }
}

impl<F: Framing> Engine for Master<F> {
    type Event<'a>
        = Completion<'a>
    where
        F: 'a;

    fn on_bytes(&mut self, now: Instant, bytes: &[u8]) -> usize {
        Master::on_bytes(self, now, bytes);
        bytes.len()
    }
    fn poll_timeout(&self) -> Option<Instant> {
        Master::poll_timeout(self)
    }
    fn handle_timeout(&mut self, now: Instant) {
        Master::handle_timeout(self, now);
    }
    fn poll_transmit(&mut self, now: Instant, buf: &mut [u8]) -> Option<usize> {
        Master::poll_transmit(self, now, buf)
    }
    fn poll_event(&mut self) -> Option<Completion<'_>> {
        Master::poll_event(self)
    }
}

/// The pipelined master: several requests in flight on one Modbus/TCP connection, each
/// completion with the ticket of its request.
impl Engine for Pipeline {
    type Event<'a> = (Ticket, Completion<'a>);

    fn on_bytes(&mut self, now: Instant, bytes: &[u8]) -> usize {
        Pipeline::on_bytes(self, now, bytes);
        bytes.len()
    }
    fn poll_timeout(&self) -> Option<Instant> {
        Pipeline::poll_timeout(self)
    }
    fn handle_timeout(&mut self, now: Instant) {
        Pipeline::handle_timeout(self, now);
    }
    fn poll_transmit(&mut self, now: Instant, buf: &mut [u8]) -> Option<usize> {
        Pipeline::poll_transmit(self, now, buf)
    }
    fn poll_event(&mut self) -> Option<(Ticket, Completion<'_>)> {
        Pipeline::poll_event(self)
    }
}

/// The slave engine, deferred: it frames and admits requests, the session answers them
/// ([`Slave::poll_request`], then one of its answers), the engine keeps their order and timing.
impl<F: Framing> Engine for Slave<F> {
    type Event<'a>
        = SlaveEvent
    where
        F: 'a;

    fn on_bytes(&mut self, now: Instant, bytes: &[u8]) -> usize {
        self.receive(now, bytes)
    }
    fn poll_timeout(&self) -> Option<Instant> {
        Slave::poll_timeout(self)
    }
    fn handle_timeout(&mut self, now: Instant) {
        self.wake(now);
    }
    fn poll_transmit(&mut self, now: Instant, buf: &mut [u8]) -> Option<usize> {
        Slave::poll_transmit(self, now, buf)
    }
    fn poll_event(&mut self) -> Option<SlaveEvent> {
        Slave::poll_event(self)
    }
    fn is_blocked(&self) -> bool {
        Slave::is_blocked(self)
    }
}

/// The core's bus survey (scan's listen phase) is an engine that never transmits and reports nothing on the way: what
/// it heard is read once listening ends ([`Survey::heard`]).
impl Engine for Survey {
    type Event<'a> = ();

    fn on_bytes(&mut self, now: Instant, bytes: &[u8]) -> usize {
        Survey::on_bytes(self, now, bytes);
        bytes.len()
    }
    fn poll_timeout(&self) -> Option<Instant> {
        Survey::poll_timeout(self)
    }
    fn handle_timeout(&mut self, now: Instant) {
        Survey::handle_timeout(self, now);
    }
    fn poll_transmit(&mut self, _: Instant, _: &mut [u8]) -> Option<usize> {
        None
    }
    fn poll_event(&mut self) -> Option<()> {
        None
    }
}

/// The core's passive decoder (`ferrobus sniff`) as an engine: it never transmits, and what
/// it hears is kept, owned as `T`, until the session takes it ([`Engine::poll_event`]).
///
/// The decoder counts its instants from an epoch of the caller's (the tools' listener: the
/// Unix epoch, as pcapng does): the pump's instants, `epoch` later. The engine only shifts
/// them; each chunk's arrival is the pump's, from the port's [`Port::last_arrival`] when it
/// stamps its reads.
///
/// [`Port::last_arrival`]: crate::port::Port::last_arrival
#[derive(Debug)]
pub struct Sniffing<T> {
    sniffer: Sniffer,
    /// The decoder's instant at the pump's epoch.
    epoch: Duration,
    heard: VecDeque<T>,
}

impl<T: for<'a> From<SniffEvent<'a>>> Sniffing<T> {
    /// `sniffer`, its instants `epoch` after the pump's.
    pub fn new(sniffer: Sniffer, epoch: Duration) -> Self {
        Sniffing { sniffer, epoch, heard: VecDeque::new() }
    }

    /// The decoder.
    pub fn sniffer(&self) -> &Sniffer {
        &self.sniffer
    }

    /// Settles what the decoder holds (a frame not yet ended), as if the line had gone
    /// silent for good: the end of listening. What it completes is kept with the rest.
    pub fn finish(&mut self) {
        let heard = &mut self.heard;
        self.sniffer.finish(|e| heard.push_back(e.into()));
    }

    /// A pump instant as the decoder counts it.
    fn shifted(&self, now: Instant) -> Instant {
        now.saturating_add(self.epoch)
    }
}

impl<T: for<'a> From<SniffEvent<'a>>> Engine for Sniffing<T> {
    type Event<'a>
        = T
    where
        T: 'a;

    fn on_bytes(&mut self, now: Instant, bytes: &[u8]) -> usize {
        let (now, heard) = (self.shifted(now), &mut self.heard);
        self.sniffer.feed(now, bytes, |e| heard.push_back(e.into()));
        bytes.len()
    }
    fn poll_timeout(&self) -> Option<Instant> {
        self.sniffer.poll_timeout().map(|t| t.saturating_sub(self.epoch))
    }
    fn handle_timeout(&mut self, now: Instant) {
        let (now, heard) = (self.shifted(now), &mut self.heard);
        self.sniffer.expire(now, |e| heard.push_back(e.into()));
    }
    fn poll_transmit(&mut self, _: Instant, _: &mut [u8]) -> Option<usize> {
        None
    }
    fn poll_event(&mut self) -> Option<T> {
        self.heard.pop_front()
    }
}

/// What a role does around the pump, at the loop's fixed points ([`Pump::run`]).
#[expect(
    async_fn_in_trait,
    reason = "the sessions are driven in place by `Pump::run`; no caller needs to name the future's bounds"
)]
pub trait Session<E: Engine> {
    /// What the loop ends with.
    type Output;
    /// Takes the engine's events and writes what it hands out, at the top of every turn;
    /// `Some` ends the loop.
    async fn serve(&mut self, pump: &Pump, port: &mut BoxPort, engine: &mut E) -> Option<Self::Output>;
    /// The session's own earliest deadline, besides the engine's.
    fn deadline(&mut self, _engine: &E) -> Option<tokio::time::Instant> {
        None
    }
    /// Something else the session waits for besides the port and the deadlines (the
    /// gateway's line replies); when it finishes the loop turns, and [`Session::serve`]
    /// takes what it brought. It must be cancel-safe: a read or a deadline may come first.
    async fn wait(&mut self) {
        std::future::pending::<()>().await;
    }
    /// Bytes were read.
    fn on_read(&mut self) {}
    /// A deadline came, before the engine is told; `Some` ends the loop.
    fn on_wake(&mut self) -> Option<Self::Output> {
        None
    }
    /// The port reached its end (`None`) or reading failed.
    fn on_end(&mut self, error: Option<io::Error>) -> Self::Output;
}

/// What one [`Pump::step`] saw.
enum Step<T> {
    /// Bytes arrived and were handed to the engine (what it did not take is kept).
    Read,
    /// The port reached its end.
    Closed,
    /// Reading failed.
    Failed(io::Error),
    /// The deadline came; the engine has not been told yet ([`Pump::handle_timeout`]), so
    /// that the session may act first on a deadline of its own.
    Woke,
    /// The session's other future finished first.
    Other(T),
}

/// The loop's state that does not depend on the role: the clock, the sleeper, the read
/// buffer and the bytes a blocked engine has not taken yet.
pub struct Pump {
    clock: Clock,
    sleeper: Sleeper,
    rx: Box<[u8; 1024]>,
    /// Bytes read that the engine has not taken yet (it was blocked), with their arrival.
    kept: Vec<u8>,
    kept_at: Instant,
    /// The engine blocked while taking input: its receiver may hold frames not yet delivered.
    stalled: bool,
}

impl Pump {
    /// A pump waiting with `sleeper`.
    pub fn new(sleeper: Sleeper) -> Self {
        Pump {
            clock: Clock::new(),
            sleeper,
            rx: Box::new([0; 1024]),
            kept: Vec::new(),
            kept_at: Instant::ZERO,
            stalled: false,
        }
    }

    /// The pump's clock.
    pub fn clock(&self) -> &Clock {
        &self.clock
    }

    /// The engine's next deadline on tokio's clock.
    fn deadline<E: Engine>(&self, engine: &E) -> Option<tokio::time::Instant> {
        engine.poll_timeout().map(|t| self.clock.to_tokio(t))
    }

    /// Hands the engine the bytes it did not take before, if it takes bytes again; returns
    /// whether it did (the session then serves the engine's output before the next step).
    fn feed_kept<E: Engine>(&mut self, engine: &mut E) -> bool {
        if engine.is_blocked() || (!self.stalled && self.kept.is_empty()) {
            return false;
        }
        let taken = engine.on_bytes(self.kept_at, &self.kept);
        self.kept.drain(..taken.min(self.kept.len()));
        self.stalled = engine.is_blocked();
        true
    }

    /// Hands the engine, as arrived now, every byte `port` holds unread, without waiting;
    /// returns how many (at most 64 KiB, so that a line that never stops cannot hold it).
    pub(crate) fn drain<E: Engine>(&mut self, port: &mut BoxPort, engine: &mut E) -> io::Result<usize> {
        const MAX: usize = 64 * 1024;
        let mut total = 0;
        while total < MAX {
            let n = port.read_buffered(&mut self.rx[..])?;
            let Some(bytes) = self.rx.get(..n).filter(|b| !b.is_empty()) else { break };
            tracing::trace!("rx (waiting before the request) {}", Hex(bytes));
            engine.on_bytes(self.clock.now(), bytes);
            total += n;
        }
        Ok(total)
    }

    /// Tells the engine that its deadline has come.
    fn handle_timeout<E: Engine>(&mut self, engine: &mut E) {
        engine.handle_timeout(self.clock.now());
        self.stalled |= engine.is_blocked();
    }

    /// The one driver loop: serves the engine's output through `session`, hands the engine
    /// the bytes it did not take before, then reads or sleeps until the earliest of the
    /// engine's and the session's deadlines; until the session or the port ends it.
    pub async fn run<E: Engine, S: Session<E>>(
        &mut self,
        port: &mut BoxPort,
        engine: &mut E,
        session: &mut S,
    ) -> S::Output {
        loop {
            if let Some(output) = session.serve(self, port, engine).await {
                return output;
            }
            if self.feed_kept(engine) {
                continue;
            }
            let deadline = [self.deadline(engine), session.deadline(engine)].into_iter().flatten().min();
            match self.step(port, engine, deadline, session.wait()).await {
                Step::Read => session.on_read(),
                Step::Closed => return session.on_end(None),
                Step::Failed(e) => return session.on_end(Some(e)),
                Step::Other(()) => {}
                Step::Woke => {
                    if let Some(output) = session.on_wake() {
                        return output;
                    }
                    self.handle_timeout(engine);
                }
            }
        }
    }

    /// Waits for the first of: bytes from `port` (read only while the engine takes them and
    /// nothing is kept), `deadline`, and `other`.
    async fn step<E: Engine, T>(
        &mut self,
        port: &mut BoxPort,
        engine: &mut E,
        deadline: Option<tokio::time::Instant>,
        other: impl Future<Output = T>,
    ) -> Step<T> {
        // While the engine is blocked (its replies or events are full) nothing is read: the
        // peer is held back by TCP, and no byte is dropped.
        let reading = !engine.is_blocked() && self.kept.is_empty();
        tokio::select! {
            read = port.read(&mut self.rx[..]), if reading => match read {
                Ok(0) => Step::Closed,
                Ok(n) => {
                    let at = port.last_arrival().map_or_else(|| self.clock.now(), |t| self.clock.from_tokio(t));
                    let bytes = self.rx.get(..n).unwrap_or_default();
                    tracing::trace!("rx {}", Hex(bytes));
                    let taken = engine.on_bytes(at, bytes);
                    self.stalled = engine.is_blocked();
                    self.kept_at = at;
                    if let Some(rest) = bytes.get(taken..) {
                        self.kept.extend_from_slice(rest);
                    }
                    Step::Read
                }
                Err(e) => Step::Failed(e),
            },
            () = self.sleeper.sleep_until(deadline) => Step::Woke,
            t = other => Step::Other(t),
        }
    }
}

/// Writes `frame` and flushes it, raising RTS around it for [`Rs485::Rts`]: the one writer
/// of every role.
pub async fn write_frame(port: &mut BoxPort, frame: &[u8], rs485: Rs485, timing: &LineTiming) -> io::Result<()> {
    tracing::trace!("tx {}", Hex(frame));
    let rts = rs485 == Rs485::Rts;
    if rts {
        port.set_rts(true)?;
    }
    port.write_all(frame).await?;
    port.flush().await?;
    if rts {
        // The OS buffers the frame; hold RTS until its last character has left.
        tokio::time::sleep(timing.transmit_time(frame.len()).saturating_add(timing.char_time())).await;
        port.set_rts(false)?;
    }
    Ok(())
}

/// Which side of the bus an engine is on: it decides how strict the MBAP receiver is.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Role {
    /// A master: its MBAP receiver resyncs on a bad header.
    Client,
    /// A slave: its MBAP receiver is strict, a stream whose framing is lost is closed.
    Server,
}

/// The codec a [`Transport`] takes, chosen once ([`Codec::for_transport`]) for every role.
#[derive(Debug)]
#[expect(clippy::large_enum_variant, reason = "one codec per engine, held inline: no indirection on each byte")]
pub enum Codec {
    /// RTU, on a serial line or over TCP.
    Rtu(RtuCodec),
    /// ASCII.
    Ascii(AsciiCodec),
    /// Modbus/TCP.
    Mbap(MbapCodec),
}

impl Codec {
    /// The codec of `transport`'s framing and timing for `role`.
    pub fn for_transport(transport: &Transport, role: Role) -> Codec {
        match transport.framing() {
            crate::port::Framing::Rtu => Codec::Rtu(transport.rtu_codec()),
            crate::port::Framing::Ascii => Codec::Ascii(transport.ascii_codec()),
            crate::port::Framing::Mbap => Codec::Mbap(match role {
                Role::Client => Transport::mbap_codec(),
                Role::Server => MbapCodec::strict(),
            }),
        }
    }

    fn framing(&self) -> &dyn Framing {
        match self {
            Codec::Rtu(c) => c,
            Codec::Ascii(c) => c,
            Codec::Mbap(c) => c,
        }
    }

    fn framing_mut(&mut self) -> &mut dyn Framing {
        match self {
            Codec::Rtu(c) => c,
            Codec::Ascii(c) => c,
            Codec::Mbap(c) => c,
        }
    }
}

impl Framing for Codec {
    fn encode(&self, header: AduHeader, pdu: &[u8], out: &mut [u8]) -> Result<usize, BufferTooSmall> {
        self.framing().encode(header, pdu, out)
    }
    fn push(&mut self, now: Instant, bytes: &[u8]) -> usize {
        self.framing_mut().push(now, bytes)
    }
    fn poll_event(&mut self) -> Option<RxEvent<'_>> {
        self.framing_mut().poll_event()
    }
    fn poll_timeout(&self) -> Option<Instant> {
        self.framing().poll_timeout()
    }
    fn handle_timeout(&mut self, now: Instant) {
        self.framing_mut().handle_timeout(now);
    }
    fn inter_frame_gap(&self) -> std::time::Duration {
        self.framing().inter_frame_gap()
    }
    fn transmit_time(&self, n: usize) -> std::time::Duration {
        self.framing().transmit_time(n)
    }
    fn reset(&mut self) {
        self.framing_mut().reset();
    }
    fn stats(&self) -> RxStats {
        self.framing().stats()
    }
    fn supports_broadcast(&self) -> bool {
        self.framing().supports_broadcast()
    }
    fn is_mid_frame(&self) -> bool {
        self.framing().is_mid_frame()
    }
    fn set_delimiter(&mut self, delimiter: u8) {
        self.framing_mut().set_delimiter(delimiter);
    }
}

#[cfg(test)]
mod tests {
    use std::pin::Pin;
    use std::sync::{Arc, Mutex};
    use std::task::{Context, Poll};
    use std::time::Duration;

    use ferrobus_proto::frame::LineConfig;
    use tokio::io::{AsyncRead, AsyncWrite, DuplexStream, ReadBuf};

    use super::*;
    use crate::port::Port;
    use crate::timer::Timer;

    /// A stream that logs each RTS change with its time.
    struct RtsPort {
        stream: DuplexStream,
        rts: Arc<Mutex<Vec<(bool, tokio::time::Instant)>>>,
    }

    impl AsyncRead for RtsPort {
        fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
            Pin::new(&mut self.stream).poll_read(cx, buf)
        }
    }

    impl AsyncWrite for RtsPort {
        fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
            Pin::new(&mut self.stream).poll_write(cx, buf)
        }
        fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
            Pin::new(&mut self.stream).poll_flush(cx)
        }
        fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
            Pin::new(&mut self.stream).poll_shutdown(cx)
        }
    }

    impl Port for RtsPort {
        fn set_rts(&mut self, on: bool) -> io::Result<()> {
            self.rts.lock().unwrap().push((on, tokio::time::Instant::now()));
            Ok(())
        }
    }

    /// An engine that takes at most `room` bytes, and is blocked while it has none.
    struct Taker {
        took: Vec<u8>,
        room: usize,
    }

    impl Engine for Taker {
        type Event<'a> = ();
        fn on_bytes(&mut self, _now: Instant, bytes: &[u8]) -> usize {
            let n = bytes.len().min(self.room);
            self.took.extend_from_slice(&bytes[..n]);
            self.room -= n;
            n
        }
        fn poll_timeout(&self) -> Option<Instant> {
            None
        }
        fn handle_timeout(&mut self, _now: Instant) {}
        fn poll_transmit(&mut self, _now: Instant, _buf: &mut [u8]) -> Option<usize> {
            None
        }
        fn poll_event(&mut self) -> Option<()> {
            None
        }
        fn is_blocked(&self) -> bool {
            self.room == 0
        }
    }

    #[tokio::test(start_paused = true)]
    async fn the_writer_raises_rts_before_the_frame_and_drops_it_once_its_last_character_has_left() {
        let (ours, mut theirs) = tokio::io::duplex(64);
        let rts = Arc::new(Mutex::new(Vec::new()));
        let mut port: BoxPort = Box::new(RtsPort { stream: ours, rts: Arc::clone(&rts) });
        let timing = LineTiming::new(&LineConfig::new(9600).unwrap());
        let frame = [0x01, 0x03, 0x00, 0x00, 0x00, 0x01, 0x84, 0x0A];
        let start = tokio::time::Instant::now();
        write_frame(&mut port, &frame, Rs485::Rts, &timing).await.unwrap();
        let mut got = [0u8; 8];
        theirs.read_exact(&mut got).await.unwrap();
        assert_eq!(got, frame, "the peer got other bytes than the frame");
        let held = timing.transmit_time(frame.len()) + timing.char_time();
        let changes = rts.lock().unwrap().clone();
        let [(true, on), (false, off)] = changes[..] else { panic!("RTS changes (on/off, when): {changes:?}") };
        assert_eq!(on, start, "RTS was not raised before the frame");
        // tokio's timer rounds up to the millisecond: never early is the contract.
        assert!(off >= start + held, "RTS dropped {:?} after the frame began, before {held:?}", off - start);
    }

    #[tokio::test(start_paused = true)]
    async fn the_writer_leaves_rts_alone_unless_asked() {
        let (ours, _theirs) = tokio::io::duplex(64);
        let rts = Arc::new(Mutex::new(Vec::new()));
        let mut port: BoxPort = Box::new(RtsPort { stream: ours, rts: Arc::clone(&rts) });
        let timing = LineTiming::new(&LineConfig::new(9600).unwrap());
        write_frame(&mut port, &[1, 2, 3], Rs485::Auto, &timing).await.unwrap();
        assert!(rts.lock().unwrap().is_empty(), "RTS was switched: {:?}", rts.lock().unwrap());
    }

    #[tokio::test(start_paused = true)]
    async fn bytes_a_blocked_engine_did_not_take_are_kept_not_read_past_and_fed_in_order_later() {
        let (ours, mut theirs) = tokio::io::duplex(64);
        let mut port: BoxPort = Box::new(ours);
        let mut pump = Pump::new(Timer::Tokio.sleeper());
        let mut engine = Taker { took: Vec::new(), room: 2 };
        theirs.write_all(&[1, 2, 3, 4, 5, 6]).await.unwrap();
        let step = pump.step(&mut port, &mut engine, None, std::future::pending::<()>()).await;
        assert!(matches!(step, Step::Read), "the first step did not read");
        assert_eq!(engine.took, [1, 2], "a blocked engine took more than it had room for");
        // Blocked: the next step reads nothing, even with bytes waiting, and wakes at its deadline.
        theirs.write_all(&[7, 8]).await.unwrap();
        assert!(!pump.feed_kept(&mut engine), "bytes were fed to a blocked engine");
        let deadline = Some(tokio::time::Instant::now() + Duration::from_millis(1));
        let step = pump.step(&mut port, &mut engine, deadline, std::future::pending::<()>()).await;
        assert!(matches!(step, Step::Woke), "a step read while the engine was blocked");
        engine.room = 3;
        assert!(pump.feed_kept(&mut engine), "kept bytes were not fed once the engine had room");
        assert_eq!(engine.took, [1, 2, 3, 4, 5], "kept bytes fed out of order");
        engine.room = 10;
        assert!(pump.feed_kept(&mut engine), "the last kept byte was not fed");
        assert_eq!(engine.took, [1, 2, 3, 4, 5, 6]);
        let step = pump.step(&mut port, &mut engine, None, std::future::pending::<()>()).await;
        assert!(matches!(step, Step::Read), "the step after the kept bytes did not read");
        assert_eq!(engine.took, [1, 2, 3, 4, 5, 6, 7, 8], "bytes read after the kept ones came out of order");
    }

    /// An engine due once at `due`.
    struct Due {
        due: Option<Instant>,
        told: Vec<&'static str>,
    }

    impl Engine for Due {
        type Event<'a> = ();
        fn on_bytes(&mut self, _now: Instant, bytes: &[u8]) -> usize {
            bytes.len()
        }
        fn poll_timeout(&self) -> Option<Instant> {
            self.due
        }
        fn handle_timeout(&mut self, now: Instant) {
            if self.due.is_some_and(|due| now >= due) {
                self.due = None;
                self.told.push("engine woken");
            }
        }
        fn poll_transmit(&mut self, _now: Instant, _buf: &mut [u8]) -> Option<usize> {
            None
        }
        fn poll_event(&mut self) -> Option<()> {
            None
        }
    }

    /// Ends once the engine has been woken, or at its own deadline.
    struct Until {
        deadline: Option<tokio::time::Instant>,
    }

    impl Session<Due> for Until {
        type Output = &'static str;
        async fn serve(&mut self, _pump: &Pump, _port: &mut BoxPort, engine: &mut Due) -> Option<&'static str> {
            engine.due.is_none().then_some("served after the engine's deadline")
        }
        fn deadline(&mut self, _engine: &Due) -> Option<tokio::time::Instant> {
            self.deadline
        }
        fn on_wake(&mut self) -> Option<&'static str> {
            self.deadline.is_some_and(|d| tokio::time::Instant::now() >= d).then_some("the session's deadline")
        }
        fn on_end(&mut self, _error: Option<io::Error>) -> &'static str {
            "the port ended"
        }
    }

    #[tokio::test(start_paused = true)]
    async fn the_loop_wakes_the_engine_at_its_deadline_never_early_and_the_session_serves_after() {
        let (ours, _theirs) = tokio::io::duplex(64);
        let mut port: BoxPort = Box::new(ours);
        let mut pump = Pump::new(Timer::Tokio.sleeper());
        let due = pump.clock().now().saturating_add(Duration::from_millis(5));
        let mut engine = Due { due: Some(due), told: Vec::new() };
        let ended = pump.run(&mut port, &mut engine, &mut Until { deadline: None }).await;
        assert_eq!(ended, "served after the engine's deadline");
        assert_eq!(engine.told, ["engine woken"]);
        assert!(pump.clock().now() >= due, "the engine was woken before its deadline");
    }

    #[tokio::test(start_paused = true)]
    async fn a_session_deadline_before_the_engines_ends_the_loop_without_waking_the_engine() {
        let (ours, _theirs) = tokio::io::duplex(64);
        let mut port: BoxPort = Box::new(ours);
        let mut pump = Pump::new(Timer::Tokio.sleeper());
        let mut engine = Due { due: Some(pump.clock().now().saturating_add(Duration::from_secs(1))), told: Vec::new() };
        let deadline = tokio::time::Instant::now() + Duration::from_millis(5);
        let ended = pump.run(&mut port, &mut engine, &mut Until { deadline: Some(deadline) }).await;
        assert_eq!(ended, "the session's deadline");
        assert!(engine.told.is_empty(), "the engine was woken: {:?}", engine.told);
        assert!(tokio::time::Instant::now() >= deadline, "the session's deadline came early");
    }

    #[tokio::test(start_paused = true)]
    async fn the_loop_ends_with_the_sessions_word_when_the_port_ends() {
        let (ours, theirs) = tokio::io::duplex(64);
        drop(theirs);
        let mut port: BoxPort = Box::new(ours);
        let mut pump = Pump::new(Timer::Tokio.sleeper());
        // Due far off, so that the session does not end the loop first.
        let mut engine =
            Due { due: Some(pump.clock().now().saturating_add(Duration::from_secs(3600))), told: Vec::new() };
        let ended = pump.run(&mut port, &mut engine, &mut Until { deadline: None }).await;
        assert_eq!(ended, "the port ended");
    }

    #[tokio::test(start_paused = true)]
    async fn a_step_ends_with_the_sessions_future_when_it_finishes_first() {
        let (ours, _theirs) = tokio::io::duplex(64);
        let mut port: BoxPort = Box::new(ours);
        let mut pump = Pump::new(Timer::Tokio.sleeper());
        let mut engine = Taker { took: Vec::new(), room: 8 };
        let step = pump.step(&mut port, &mut engine, None, std::future::ready(7)).await;
        assert!(matches!(step, Step::Other(7)), "the session's future did not end the step");
    }

    /// What the sniffing engine heard, owned: the bytes and when they ended.
    #[derive(PartialEq, Debug)]
    struct Heard(Vec<u8>, Instant);

    impl From<SniffEvent<'_>> for Heard {
        fn from(event: SniffEvent<'_>) -> Self {
            match event {
                SniffEvent::Frame(f) => Heard(f.adu().to_vec(), f.time.end),
                SniffEvent::Fragment(f) => Heard(f.bytes.to_vec(), f.time.end),
                SniffEvent::Unanswered(u) => Heard(Vec::new(), u.request_end),
            }
        }
    }

    #[test]
    fn the_sniffing_engine_never_transmits_and_counts_its_instants_epoch_after_the_pumps() {
        let timing = LineTiming::new(&LineConfig::new(9600).unwrap());
        let epoch = Duration::from_secs(1_700_000_000);
        let mut engine = Sniffing::<Heard>::new(Sniffer::new(timing), epoch);
        let request = [0x01, 0x03, 0x00, 0x00, 0x00, 0x01, 0x84, 0x0A];
        let at = Instant::from_millis(5);
        assert_eq!(engine.on_bytes(at, &request), request.len(), "the engine left bytes untaken");
        // Whatever deadline it has is on the pump's clock, soon after the frame.
        for _ in 0..4 {
            let Some(due) = engine.poll_timeout() else { break };
            assert!(due >= at && due.saturating_duration_since(at) < Duration::from_secs(1), "due at {due:?}");
            engine.handle_timeout(due);
        }
        assert_eq!(engine.poll_event(), Some(Heard(request.to_vec(), at.saturating_add(epoch))));
        assert_eq!(engine.poll_event(), None);
        assert_eq!(engine.poll_transmit(at, &mut [0; 256]), None, "the sniffing engine transmitted");
        assert!(!engine.is_blocked());
        engine.finish();
        assert_eq!(engine.poll_event(), None, "finishing an idle decoder made something up");
    }

    #[test]
    fn a_server_over_modbus_tcp_takes_the_strict_mbap_codec_and_a_client_the_resyncing_one() {
        let transport = Transport::tcp("127.0.0.1:502");
        let Codec::Mbap(server) = Codec::for_transport(&transport, Role::Server) else {
            panic!("a Modbus/TCP transport took a codec other than MBAP");
        };
        let Codec::Mbap(client) = Codec::for_transport(&transport, Role::Client) else {
            panic!("a Modbus/TCP transport took a codec other than MBAP");
        };
        assert_eq!(format!("{server:?}"), format!("{:?}", MbapCodec::strict()));
        assert_eq!(format!("{client:?}"), format!("{:?}", MbapCodec::new()));
        assert!(!Codec::Mbap(MbapCodec::new()).supports_broadcast(), "unit 0 is ordinary on Modbus/TCP");
    }

    #[test]
    fn rtu_over_tcp_takes_the_rtu_codec_for_both_roles() {
        let transport = Transport::rtu_over_tcp("127.0.0.1:502");
        assert!(matches!(Codec::for_transport(&transport, Role::Server), Codec::Rtu(_)));
        assert!(matches!(Codec::for_transport(&transport, Role::Client), Codec::Rtu(_)));
    }
}
