//! The slave (server) engine: answers its unit addresses on a shared line.
//!
//! Spec: MODBUS over Serial Line V1.02 §2.4.2 (slave state diagram), MODBUS Application
//! Protocol V1.1b3 §6.8–6.10 (diagnostics) and §7 (exceptions). Drive timing: the 3G3RX and
//! SJ700 manuals ("the inverter waits for the sum of the silent interval … and the
//! communication wait time (C078) before sending a response").
//!
//! - **Who it answers.** Only requests to one of its units. It stays silent on a frame with a
//!   bad checksum (the receiver never delivers one), on frames for other units, on other
//!   slaves' responses, and on broadcast — whose writes it still executes, once per unit.
//! - **When.** A reply is due t3.5 after the request's last byte plus the response wait
//!   (per unit: [`Handler::response_wait`], else [`SlaveConfig::response_wait`]), and never
//!   earlier: [`Slave::poll_transmit`] holds it until then.
//! - **What.** Data comes from one [`Handler`]; malformed requests get exception 03 (or 02, 01
//!   as the spec says), unsupported functions 01. The engine itself serves 0x08 Diagnostics,
//!   0x0B and 0x0C from its [`Counters`] and [`EventLog`], and keeps listen-only mode: after
//!   0x08/0x04 it answers nothing until 0x08/0x01.
//! - **How many at once.** A serial line carries one request at a time: a request arriving
//!   while a reply is pending gets none ([`Disposition::Silent`]). Modbus/TCP allows several
//!   outstanding transactions: up to [`REPLY_QUEUE`] replies wait, each with its own
//!   transaction id, and go out in the order of their requests. Past that, and whenever the
//!   event queue ([`EVENT_QUEUE`] events) has no room for what the next frame may report,
//!   [`Slave::on_bytes`] stops taking bytes and says how many it took: the driver keeps the
//!   rest, stops reading, and hands them in again once replies are written and events
//!   polled ([`Slave::is_blocked`]). Nothing is dropped; over TCP that is back-pressure.

mod connection;
mod deferred;
mod diag;
mod handler;
mod pending;
mod ring;
mod serve;
#[cfg(test)]
mod tests;

use core::time::Duration;

pub use connection::{Closed, ConnectionPolicy};
pub use deferred::{ANSWER_LIMIT, AnswerError, Incoming};
pub use diag::{Counters, EventLog, event};
pub use handler::{Admission, Handler};
pub use pending::RequestId;

use crate::codes::{DiagnosticCode, ExceptionCode, FunctionCode, unit};
use crate::error::DiscardReason;
use crate::frame::{Adu, Direction, Framing, RxEvent};
use crate::master::MAX_TX_LEN;
use crate::pdu::{AddressRange, CommEventLog, Diagnostic, ExceptionResponse, MAX_PDU_LEN, Request, Response};
use crate::time::{Instant, earliest};
use connection::Watch;
use diag::bump;
use pending::{Entry, Slots, State};
use ring::Ring;

/// A set of unit addresses.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug, Default)]
pub struct UnitSet {
    bits: [u64; 4],
}

impl UnitSet {
    /// No units.
    pub const EMPTY: UnitSet = UnitSet { bits: [0; 4] };

    /// Just `unit`.
    pub fn single(unit: u8) -> Self {
        let mut set = UnitSet::EMPTY;
        set.insert(unit);
        set
    }

    /// Adds `unit`.
    pub fn insert(&mut self, unit: u8) {
        if let Some(word) = self.bits.get_mut(usize::from(unit / 64)) {
            *word |= 1u64 << (unit % 64);
        }
    }

    /// Whether `unit` is in the set.
    pub fn contains(&self, unit: u8) -> bool {
        self.bits.get(usize::from(unit / 64)).is_some_and(|word| word & (1u64 << (unit % 64)) != 0)
    }

    /// Whether the set is empty.
    pub fn is_empty(&self) -> bool {
        self.bits == [0; 4]
    }

    /// The units in ascending order.
    pub fn iter(&self) -> impl Iterator<Item = u8> + '_ {
        (0..=u8::MAX).filter(|&u| self.contains(u))
    }
}

impl FromIterator<u8> for UnitSet {
    fn from_iter<I: IntoIterator<Item = u8>>(iter: I) -> Self {
        let mut set = UnitSet::EMPTY;
        for u in iter {
            set.insert(u);
        }
        set
    }
}

/// Settings of the slave engine.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct SlaveConfig {
    /// The unit addresses answered (unit 0, broadcast, is always listened to).
    pub units: UnitSet,
    /// The wait before a reply, on top of the t3.5 silent interval (3G3RX C078: 0–1000 ms).
    pub response_wait: Duration,
}

impl SlaveConfig {
    /// A slave answering `unit` with no extra wait.
    pub fn unit(unit: u8) -> Self {
        SlaveConfig { units: UnitSet::single(unit), response_wait: Duration::ZERO }
    }
}

/// What happened to a request addressed to this slave.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Disposition {
    /// A normal reply is due at this instant.
    Replied(Instant),
    /// An exception reply is due at this instant.
    Refused(ExceptionCode, Instant),
    /// Executed without a reply (broadcast).
    Executed,
    /// Neither served nor answered: listen-only mode, the handler's [`Admission::Ignore`], a
    /// request arriving while a reply is still pending, or a broadcast that is not executed.
    Silent,
}

/// Why a frame on the bus was not for this slave.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Ignored {
    /// A request to another unit.
    OtherUnit,
    /// Another slave's response.
    Response,
}

/// What the slave saw, for logs and monitors.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum SlaveEvent {
    /// A request to one of our units or to all.
    Request {
        /// The unit addressed (0 for broadcast).
        unit: u8,
        /// Its function code.
        function: FunctionCode,
        /// The addresses it touches ([`Request::address_ranges`]; none if it did not parse).
        addresses: [Option<AddressRange>; 2],
        /// When its last byte arrived.
        end: Instant,
        /// What became of it.
        disposition: Disposition,
    },
    /// A frame that was not for us.
    Ignored {
        /// The unit in the frame.
        unit: u8,
        /// Its function code.
        function: FunctionCode,
        /// Why it was ignored.
        why: Ignored,
    },
    /// Bytes the receiver dropped.
    Discarded {
        /// How many.
        bytes: usize,
        /// Why.
        reason: DiscardReason,
        /// When.
        at: Instant,
    },
    /// 0x08/0x01 restarted communications; an IO layer may reopen its port.
    Restart {
        /// Whether the event log was cleared too (data 0xFF00).
        clear_log: bool,
    },
}

/// The events the engine holds until they are polled. A frame reports at most two (a
/// restart and its request) and every request still waiting for its answer one more; the
/// engine takes no frame without room for all of them, so the queue holds a full set of
/// waiting requests and a frame's worth besides.
pub const EVENT_QUEUE: usize = REPLY_QUEUE + 8;

/// The requests that may be in the engine at once over a framing without broadcast
/// (Modbus/TCP): waiting for their answer or for their reply to go out, the one being sent
/// included (fewer with [`ConnectionPolicy::max_pending`]). A serial line holds one.
pub const REPLY_QUEUE: usize = 16;

/// The most events one frame can report.
const EVENTS_PER_FRAME: usize = 2;

/// The slave engine over a framing `F`.
///
/// # One engine, two ways to answer
///
/// Every request the engine admits (addressed to one of its units, not refused by
/// listen-only mode or a busy serial line) takes a slot, in request order, and is answered
/// one of two ways:
///
/// - **Deferred.** [`Slave::receive`] takes bytes, [`Slave::poll_request`] hands each request
///   out ([`Incoming`]: an id, the unit, the broadcast flag and the PDU), and
///   [`Slave::respond`], [`Slave::refuse`], [`Slave::ignore`] or [`Slave::answer_with`]
///   finish it, whenever the answer is ready. A gateway forwards the PDU and responds with
///   the line's reply; a server locks its handler once per request and calls `answer_with`.
/// - **At once.** [`Slave::on_bytes`] and [`Slave::handle_timeout`] take a [`Handler`] and
///   answer every request through [`Slave::answer_with`] as soon as it is framed: the same
///   slots, the same timing, no request ever waits.
///
/// Either way the engine keeps the timing: a reply goes out no earlier than t3.5 after the
/// request plus the response wait, and replies go out in request order (pipelined
/// Modbus/TCP). A request not finished within the answer limit ([`ANSWER_LIMIT`] unless
/// [`Slave::set_answer_limit`]) gets no reply, and its id is refused from then on.
///
/// # Driving it
///
/// ```text
/// loop {
///     while let Some(n) = slave.poll_transmit(now, &mut buf) { write(&buf[..n]) }
///     while let Some(event) = slave.poll_event() { report(event) }
///     if bytes are kept and !slave.is_blocked(): taken = slave.on_bytes(at, &kept, &mut handler)
///     wait for bytes (only while !slave.is_blocked()) or until slave.poll_timeout();
///     on bytes:   taken = slave.on_bytes(now, &bytes, &mut handler); keep bytes[taken..]
///     on timeout: slave.handle_timeout(now, &mut handler)
/// }
/// ```
///
/// Deferred, `receive` and `wake` take the place of `on_bytes` and `handle_timeout`, and
/// after each of them `while let Some(request) = slave.poll_request() { … }` hands the
/// requests on.
#[derive(Clone, Debug)]
pub struct Slave<F> {
    framing: F,
    core: Core,
}

#[derive(Clone, Debug)]
struct Core {
    config: SlaveConfig,
    /// Whether unit 0 is a broadcast (a serial framing).
    serial: bool,
    /// The silent interval before a reply (t3.5).
    gap: Duration,
    /// How long a request handed out may wait for its answer.
    answer_limit: Option<Duration>,
    /// The connection's policy, and what applying it needs.
    watch: Watch,
    counters: Counters,
    /// The comm event counter of 0x0B.
    comm_events: u16,
    log: EventLog,
    listen_only: bool,
    diagnostic_register: u16,
    /// The requests admitted and not yet sent, in request order.
    slots: Slots,
    /// The id of the next request admitted.
    next_id: u32,
    /// The reply framed for sending, due at `tx_due`.
    tx: [u8; MAX_TX_LEN],
    tx_len: usize,
    tx_due: Option<Instant>,
    tx_exception: Option<ExceptionCode>,
    /// Actions on the framing decided while it was borrowed.
    new_delimiter: Option<u8>,
    restart: bool,
    events: Ring<SlaveEvent, EVENT_QUEUE>,
    events_dropped: u32,
}

/// How a request was finished.
#[derive(Clone, Copy, Debug)]
enum Outcome<'a> {
    /// This reply PDU (a broadcast's is not sent: the broadcast counts as executed).
    Reply(&'a [u8]),
    /// This exception (none for a broadcast).
    Exception(ExceptionCode),
    /// Executed without a reply (a broadcast).
    Executed,
    /// No reply.
    Silent,
}

impl<F: Framing> Slave<F> {
    /// A slave over `framing`.
    pub fn new(framing: F, config: SlaveConfig) -> Self {
        let serial = framing.supports_broadcast();
        let gap = framing.inter_frame_gap();
        Slave {
            framing,
            core: Core {
                config,
                serial,
                gap,
                answer_limit: Some(ANSWER_LIMIT),
                watch: Watch::new(),
                counters: Counters::default(),
                comm_events: 0,
                log: EventLog::default(),
                listen_only: false,
                diagnostic_register: 0,
                slots: Slots::new(),
                next_id: 0,
                tx: [0; MAX_TX_LEN],
                tx_len: 0,
                tx_due: None,
                tx_exception: None,
                new_delimiter: None,
                restart: false,
                events: Ring::new(),
                events_dropped: 0,
            },
        }
    }

    /// The settings.
    pub fn config(&self) -> &SlaveConfig {
        &self.core.config
    }

    /// Changes the settings (for the next request).
    pub fn set_config(&mut self, config: SlaveConfig) {
        self.core.config = config;
    }

    /// How long a request may wait for its answer after its last byte arrived (`None`: as
    /// long as it takes). Past it the engine finishes the request without a reply, counts it
    /// in [`Counters::server_no_response`], and refuses its id. Applies to requests admitted
    /// from now on.
    pub fn set_answer_limit(&mut self, limit: Option<Duration>) {
        self.core.answer_limit = limit;
    }

    /// Takes a serial framing's requests as a stream's: several may be outstanding (up to
    /// [`ConnectionPolicy::max_pending`]) and unit 0 is a unit like any other, handed out without
    /// the broadcast flag — RTU frames over TCP to a gateway, which decides itself what unit 0
    /// means. Without it (the default) a serial framing keeps the line's rules: one request
    /// at a time, unit 0 a broadcast.
    pub fn set_stream(&mut self, stream: bool) {
        self.core.serial = !stream && self.framing.supports_broadcast();
    }

    /// The diagnostic counters.
    pub fn counters(&self) -> Counters {
        self.core.counters
    }

    /// The comm event log.
    pub fn event_log(&self) -> &EventLog {
        &self.core.log
    }

    /// Whether the slave is in listen-only mode.
    pub fn is_listen_only(&self) -> bool {
        self.core.listen_only
    }

    /// The framing (for its statistics).
    pub fn framing(&self) -> &F {
        &self.framing
    }

    /// Events dropped because nobody polled them. [`Slave::on_bytes`] and
    /// [`Slave::handle_timeout`] take no frame without room for its events, so this stays 0
    /// unless an event would otherwise be lost; it is counted, never silent.
    pub fn dropped_events(&self) -> u32 {
        self.core.events_dropped
    }

    /// The requests in the engine: waiting for their answer, or answered and not yet handed
    /// out by [`Slave::poll_transmit`].
    pub fn pending_replies(&self) -> usize {
        self.core.pending_replies()
    }

    /// Whether the engine takes no more bytes until replies are sent ([`Slave::poll_transmit`])
    /// or events polled ([`Slave::poll_event`]): the reply queue (over Modbus/TCP) or the event
    /// queue is full.
    pub fn is_blocked(&self) -> bool {
        let core = &self.core;
        let waiting = core.slots.iter().filter(|e| e.is_waiting()).count();
        core.events.len().saturating_add(EVENTS_PER_FRAME).saturating_add(waiting) > EVENT_QUEUE
            || (!core.serial && core.pending_replies() >= core.watch.policy.max_pending)
    }

    /// Bytes arrived at `now`; returns how many were taken. Every request framed is answered
    /// through `handler` at once ([`Slave::answer_with`]). Fewer than `bytes.len()` means the
    /// engine is blocked ([`Slave::is_blocked`]): hand the rest in again, with the same `now`,
    /// once replies are sent or events polled. A call with no bytes also delivers frames the
    /// receiver already holds.
    pub fn on_bytes<H: Handler + ?Sized>(&mut self, now: Instant, bytes: &[u8], handler: &mut H) -> usize {
        self.feed(now, bytes, Some(handler))
    }

    /// Takes bytes into the receiver, frame by frame, while the engine has room; with a
    /// handler, answers each request through it as soon as it is framed.
    fn feed<H: Handler + ?Sized>(&mut self, now: Instant, bytes: &[u8], mut handler: Option<&mut H>) -> usize {
        let mut consumed = 0usize;
        // Frames a previous call left in the receiver come first.
        self.drain(handler.as_deref_mut());
        loop {
            if self.is_blocked() {
                break;
            }
            let rest = bytes.get(consumed..).unwrap_or_default();
            let n = self.framing.push(now, rest);
            consumed = consumed.saturating_add(n).min(bytes.len());
            let any = self.drain(handler.as_deref_mut());
            if !any && (consumed >= bytes.len() || n == 0) {
                break;
            }
        }
        if consumed > 0 {
            self.core.watch.active(now);
        }
        self.core.watch.track_frame(self.framing.is_mid_frame(), now, false);
        consumed
    }

    /// Hands the receiver's events to the engine while it has room for them; returns whether
    /// it handed any.
    fn drain<H: Handler + ?Sized>(&mut self, mut handler: Option<&mut H>) -> bool {
        let mut any = false;
        if let Some(handler) = handler.as_deref_mut() {
            self.answer_queued(handler);
        }
        while !self.is_blocked() {
            let Slave { framing, core } = self;
            let Some(event) = framing.poll_event() else { break };
            core.on_event(&event);
            any = true;
            self.apply();
            if let Some(handler) = handler.as_deref_mut() {
                self.answer_queued(handler);
            }
        }
        any
    }

    /// Answers through `handler` every request not yet handed out.
    fn answer_queued<H: Handler + ?Sized>(&mut self, handler: &mut H) {
        while let Some(id) = self.poll_request().map(|r| r.id) {
            let _ = self.answer_with(id, handler);
        }
    }

    /// The next instant [`Slave::handle_timeout`] (or [`Slave::wake`]) must be called.
    pub fn poll_timeout(&self) -> Option<Instant> {
        let limit = self.core.slots.iter().filter(|e| e.is_waiting()).filter_map(|e| e.limit).min();
        let engine = earliest(earliest(self.framing.poll_timeout(), self.core.tx_due), limit);
        earliest(engine, self.connection_deadline())
    }

    /// `now` has come: ends silent intervals and answers, through `handler`, the requests the
    /// receiver then frames. Spurious calls do nothing.
    pub fn handle_timeout<H: Handler + ?Sized>(&mut self, now: Instant, handler: &mut H) {
        self.expire(now);
        self.framing.handle_timeout(now);
        // A frame found at the gap may leave buffered bytes behind it; let them be examined.
        self.on_bytes(now, &[], handler);
    }

    /// Finishes, without a reply, the requests whose answer limit has passed at `now`, then
    /// closes the connection if its policy says so.
    fn expire(&mut self, now: Instant) {
        loop {
            let expired = self.core.slots.iter().find(|e| e.is_waiting() && e.limit.is_some_and(|l| now >= l));
            let Some(id) = expired.map(|e| e.id) else { break };
            let _ = self.core.complete(id, Outcome::Silent, Duration::ZERO);
        }
        self.apply();
        self.check_connection(now);
    }

    /// When the pending reply is due, if there is one.
    pub fn reply_due(&self) -> Option<Instant> {
        self.core.tx_due
    }

    /// The reply to write now, if one is due: copies it into `buf` (which should hold
    /// [`MAX_TX_LEN`] bytes) and returns its length.
    pub fn poll_transmit(&mut self, now: Instant, buf: &mut [u8]) -> Option<usize> {
        if self.core.tx_due.is_none_or(|due| now < due) {
            return None;
        }
        let held_back = self.is_blocked();
        let core = &mut self.core;
        core.tx_due = None;
        core.watch.active(now);
        let n = core.tx_len;
        let copied = match (buf.get_mut(..n), core.tx.get(..n)) {
            (Some(dst), Some(src)) => {
                dst.copy_from_slice(src);
                core.log.push(EventLog::send_event(core.tx_exception, core.listen_only));
                Some(n)
            }
            _ => None,
        };
        self.load_next();
        if held_back && !self.is_blocked() {
            // The engine reads again: a frame begun is timed from now.
            self.core.watch.track_frame(self.framing.is_mid_frame(), now, true);
        }
        copied
    }

    /// Frames the oldest answered reply into `tx` if nothing is there; requests finished
    /// without a reply leave their place. A request still waiting holds back those behind it.
    fn load_next(&mut self) {
        let core = &mut self.core;
        while core.tx_due.is_none() {
            let Some(front) = core.slots.front() else { return };
            let (due, exception) = match front.state {
                State::Answered { due, exception } => (due, exception),
                State::Finished => {
                    let _ = core.slots.pop();
                    continue;
                }
                State::Queued | State::HandedOut => return,
            };
            let Some(reply) = core.slots.pop() else { return };
            if let Ok(n) = self.framing.encode(reply.header, reply.pdu(), &mut core.tx) {
                core.tx_len = n;
                core.tx_due = Some(due);
                core.tx_exception = exception;
            }
        }
    }

    /// The next event, if any.
    pub fn poll_event(&mut self) -> Option<SlaveEvent> {
        self.core.events.pop()
    }

    /// Frames the replies now at the front, and applies 0x08 actions decided while the
    /// framing was borrowed.
    fn apply(&mut self) {
        self.load_next();
        let core = &mut self.core;
        if let Some(delimiter) = core.new_delimiter.take() {
            self.framing.set_delimiter(delimiter);
        }
        if core.restart {
            core.restart = false;
            self.framing.reset();
        }
    }
}

impl Core {
    /// Queues `event`. The engine takes no frame without room for its events, so the queue
    /// is never full here; if it were, the oldest event goes and is counted.
    fn push_event(&mut self, event: SlaveEvent) {
        if self.events.is_full() {
            let _ = self.events.pop();
            self.events_dropped = self.events_dropped.wrapping_add(1);
        }
        let _ = self.events.push(event);
    }

    /// Requests in the engine, and the reply being sent.
    fn pending_replies(&self) -> usize {
        self.slots.len().saturating_add(usize::from(self.tx_due.is_some()))
    }

    fn on_event(&mut self, event: &RxEvent<'_>) {
        match *event {
            RxEvent::Discarded { bytes, reason, at, .. } => {
                let flag = match reason {
                    DiscardReason::ChecksumMismatch => {
                        bump(&mut self.counters.bus_comm_errors);
                        event::RECEIVE_COMM_ERROR
                    }
                    DiscardReason::TooLong => {
                        bump(&mut self.counters.bus_char_overruns);
                        event::RECEIVE_OVERRUN
                    }
                    DiscardReason::BadHeader => {
                        self.watch.closed = self.watch.closed.or(Some(Closed::BadHeader));
                        0
                    }
                    _ => 0,
                };
                if flag != 0 {
                    self.log.push(event::RECEIVE | flag | self.listen_flag());
                }
                self.push_event(SlaveEvent::Discarded { bytes, reason, at });
            }
            RxEvent::Frame(ref frame) => self.on_frame(frame),
        }
    }

    fn listen_flag(&self) -> u8 {
        if self.listen_only { event::RECEIVE_LISTEN_ONLY } else { 0 }
    }

    /// A frame: ignored, finished at once (listen-only mode, a busy serial line), or
    /// admitted into a slot to wait for its answer.
    fn on_frame(&mut self, frame: &Adu<'_>) {
        bump(&mut self.counters.bus_messages);
        let unit = frame.header.unit;
        let function = FunctionCode::from_u8(frame.pdu.first().copied().unwrap_or_default());
        let broadcast = unit::is_broadcast(unit, self.serial);
        if frame.direction == Direction::Response {
            self.push_event(SlaveEvent::Ignored { unit, function, why: Ignored::Response });
            return;
        }
        if !broadcast && !self.config.units.contains(unit) {
            self.push_event(SlaveEvent::Ignored { unit, function, why: Ignored::OtherUnit });
            return;
        }
        bump(&mut self.counters.server_messages);
        let broadcast_flag = if broadcast { event::RECEIVE_BROADCAST } else { 0 };
        self.log.push(event::RECEIVE | self.listen_flag() | broadcast_flag);
        let request = Request::parse(frame.pdu);
        let addresses = request.as_ref().map(Request::address_ranges).unwrap_or_default();
        let silent = |core: &mut Core| {
            bump(&mut core.counters.server_no_response);
            let disposition = Disposition::Silent;
            core.push_event(SlaveEvent::Request { unit, function, addresses, end: frame.end, disposition });
        };
        if self.listen_only {
            // Only 0x08/0x01 is heard; it leaves listen-only mode without a reply.
            if let Ok(Request::Diagnostics(d)) = request
                && d.sub_function() == DiagnosticCode::RestartCommunications
                && !broadcast
            {
                self.restart(d.word() == Some(0xFF00));
            }
            return silent(self);
        }
        let busy = if self.serial {
            self.pending_replies() > 0
        } else {
            self.pending_replies() >= self.watch.policy.max_pending
        };
        // A serial line: still answering the previous request, a master that does not wait.
        // Over TCP the queue is full, which `Slave::is_blocked` prevents. A PDU longer than
        // any valid one cannot be held.
        let mut pdu = [0u8; MAX_PDU_LEN];
        let Some(held) = pdu.get_mut(..frame.pdu.len()).filter(|_| !busy) else { return silent(self) };
        held.copy_from_slice(frame.pdu);
        let id = RequestId(self.next_id);
        self.next_id = self.next_id.wrapping_add(1);
        let entry = Entry {
            id,
            header: frame.header,
            broadcast,
            end: frame.end,
            function,
            addresses,
            limit: self.answer_limit.map(|d| frame.end.saturating_add(d)),
            pdu,
            len: frame.pdu.len(),
            state: State::Queued,
        };
        if !self.slots.push(&entry) {
            silent(self);
        }
    }

    /// Finishes the waiting request `id` with `outcome`, its reply due t3.5 plus `wait`
    /// after its end; reports it and counts it.
    fn complete(&mut self, id: RequestId, outcome: Outcome<'_>, wait: Duration) -> Result<Disposition, AnswerError> {
        let gap = self.gap;
        let entry = self.slots.get_mut(id).filter(|e| e.is_waiting()).ok_or(AnswerError::Unknown(id))?;
        let due = entry.end.saturating_add(gap).saturating_add(wait);
        let mut exception_pdu = [0u8; 2];
        let (disposition, state, reply): (_, _, Option<&[u8]>) = match outcome {
            Outcome::Reply(_) | Outcome::Executed if entry.broadcast => (Disposition::Executed, State::Finished, None),
            Outcome::Exception(code) if !entry.broadcast => {
                let function = FunctionCode::from_u8(
                    entry.pdu.first().copied().unwrap_or_default() & !FunctionCode::EXCEPTION_BIT,
                );
                match ExceptionResponse::new(function, code) {
                    Ok(exception) => {
                        let _ = Response::Exception(exception).emit(&mut exception_pdu);
                    }
                    // Function code 0x00 is no valid request code, yet it is refused like any
                    // unknown one: 0x80, then the exception code.
                    Err(_) => exception_pdu = [function.value() | FunctionCode::EXCEPTION_BIT, code.value()],
                }
                let answered = State::Answered { due, exception: Some(code) };
                (Disposition::Refused(code, due), answered, Some(&exception_pdu[..]))
            }
            Outcome::Reply(pdu) => {
                let function = pdu.first().copied().unwrap_or_default();
                let exception = pdu
                    .get(1)
                    .filter(|_| function & FunctionCode::EXCEPTION_BIT != 0)
                    .map(|&code| ExceptionCode::from_u8(code));
                let disposition = exception.map_or(Disposition::Replied(due), |code| Disposition::Refused(code, due));
                (disposition, State::Answered { due, exception }, Some(pdu))
            }
            Outcome::Exception(_) | Outcome::Silent | Outcome::Executed => (Disposition::Silent, State::Finished, None),
        };
        if let Some(pdu) = reply {
            let dst = entry.pdu.get_mut(..pdu.len()).ok_or(AnswerError::BadLength(pdu.len()))?;
            dst.copy_from_slice(pdu);
            entry.len = pdu.len();
        }
        entry.state = state;
        let (unit, function, addresses, end) = (entry.header.unit, entry.function, entry.addresses, entry.end);
        match disposition {
            Disposition::Refused(code, _) => self.counters.count_exception(code),
            Disposition::Silent | Disposition::Executed => bump(&mut self.counters.server_no_response),
            Disposition::Replied(_) => {}
        }
        self.push_event(SlaveEvent::Request { unit, function, addresses, end, disposition });
        Ok(disposition)
    }

    /// Executes a broadcast on every unit whose handler admits it.
    fn broadcast<H: Handler + ?Sized>(&mut self, request: &Request<'_>, handler: &mut H) -> Outcome<'static> {
        if matches!(request, Request::Diagnostics(_) | Request::GetCommEventCounter(_) | Request::GetCommEventLog(_)) {
            return Outcome::Silent;
        }
        let mut executed = false;
        let mut scratch = [0u8; MAX_PDU_LEN];
        let units = self.config.units;
        for unit in units.iter() {
            if handler.admit(unit, true, request) == Admission::Serve {
                // The outcome of each unit goes nowhere: a broadcast gets no reply.
                let _ = serve::serve(handler, unit, request, &mut scratch);
                executed = true;
            }
        }
        if executed {
            bump(&mut self.comm_events);
            Outcome::Executed
        } else {
            Outcome::Silent
        }
    }

    /// Serves 0x08. `Ok(None)` means no reply (0x04 Force Listen Only).
    fn diagnostics(&mut self, d: &Diagnostic<'_>, out: &mut [u8; MAX_PDU_LEN]) -> Result<Option<usize>, ExceptionCode> {
        let sub = d.sub_function();
        let word = d.word();
        let echo = |out: &mut [u8; MAX_PDU_LEN]| {
            Response::Diagnostics(*d).emit(out).map(Some).map_err(|_| ExceptionCode::ServerDeviceFailure)
        };
        let reply_word = |out: &mut [u8; MAX_PDU_LEN], value: u16| {
            let reply = Diagnostic::with_word(sub, value);
            Response::Diagnostics(reply).emit(out).map(Some).map_err(|_| ExceptionCode::ServerDeviceFailure)
        };
        match sub {
            DiagnosticCode::ReturnQueryData => echo(out),
            DiagnosticCode::RestartCommunications => {
                let clear_log = match word {
                    Some(0x0000) => false,
                    Some(0xFF00) => true,
                    _ => return Err(ExceptionCode::IllegalDataValue),
                };
                // The reply goes out before the restart takes effect.
                let reply = echo(out);
                self.restart(clear_log);
                reply
            }
            DiagnosticCode::ForceListenOnly => {
                Self::require_zero(word)?;
                self.listen_only = true;
                self.log.push(event::ENTERED_LISTEN_ONLY);
                Ok(None)
            }
            DiagnosticCode::ChangeAsciiDelimiter => {
                let [delimiter, 0] = word.ok_or(ExceptionCode::IllegalDataValue)?.to_be_bytes() else {
                    return Err(ExceptionCode::IllegalDataValue);
                };
                self.new_delimiter = Some(delimiter);
                echo(out)
            }
            DiagnosticCode::ReturnDiagnosticRegister => {
                Self::require_zero(word)?;
                reply_word(out, self.diagnostic_register)
            }
            DiagnosticCode::ClearCounters => {
                Self::require_zero(word)?;
                self.counters = Counters::default();
                self.diagnostic_register = 0;
                echo(out)
            }
            DiagnosticCode::ClearOverrunCounter => {
                Self::require_zero(word)?;
                self.counters.bus_char_overruns = 0;
                echo(out)
            }
            other => {
                let value = self.counters.get(other).ok_or(ExceptionCode::IllegalFunction)?;
                Self::require_zero(word)?;
                reply_word(out, value)
            }
        }
    }

    /// Sub-functions other than 0x00 carry one data word, 0x0000 unless they say otherwise.
    fn require_zero(word: Option<u16>) -> Result<(), ExceptionCode> {
        if word == Some(0) { Ok(()) } else { Err(ExceptionCode::IllegalDataValue) }
    }

    fn restart(&mut self, clear_log: bool) {
        self.listen_only = false;
        self.counters = Counters::default();
        self.comm_events = 0;
        self.diagnostic_register = 0;
        if clear_log {
            self.log.clear();
        }
        self.log.push(event::RESTART);
        self.restart = true;
        self.push_event(SlaveEvent::Restart { clear_log });
    }

    fn event_log_reply(&self, out: &mut [u8; MAX_PDU_LEN]) -> Result<usize, ExceptionCode> {
        let mut events = [0u8; EventLog::CAPACITY];
        let n = self.log.copy_recent_first(&mut events);
        let log =
            CommEventLog::new(0, self.comm_events, self.counters.bus_messages, events.get(..n).unwrap_or_default())
                .map_err(|_| ExceptionCode::ServerDeviceFailure)?;
        Response::GetCommEventLog(log).emit(out).map_err(|_| ExceptionCode::ServerDeviceFailure)
    }
}

#[cfg(test)]
mod unit_set_tests {
    use super::UnitSet;

    #[test]
    fn unit_sets_hold_any_of_the_256_addresses() {
        let set: UnitSet = [0u8, 1, 63, 64, 247, 255].into_iter().collect();
        assert!(set.contains(0) && set.contains(64) && set.contains(255));
        assert!(!set.contains(2) && !set.contains(128));
        assert_eq!(set.iter().count(), 6);
        assert!(UnitSet::EMPTY.is_empty());
    }
}
