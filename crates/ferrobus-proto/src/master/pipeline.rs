//! The pipelined master engine for Modbus/TCP: up to [`MAX_IN_FLIGHT`] requests in flight on
//! one connection, each matched to its reply by the MBAP transaction id.
//!
//! Spec: MODBUS Messaging on TCP/IP Implementation Guide V1.0b §3.1.3 (the transaction
//! identifier of the MBAP header: set by the client, copied into the reply by the server, so
//! that a reply can be paired with its request).
//!
//! ```text
//!  submit ─▶ Queued ──poll_transmit──┬─ awaited ─▶ AwaitingReply ─┬─ its reply ─▶ Response / Raw / Exception / Failed
//!    (Ticket)                        │                            └─ timeout ───▶ Failed(Timeout)
//!                                    └─ 0x08/0x04 ─────────────────────────────▶ Sent
//!                          each ends into Ended ──poll_event──▶ (Ticket, Completion), slot free
//! ```
//!
//! [`Master`](super::Master) keeps one request in flight, as a serial line must. On TCP there
//! is no line to share and the transaction id tells replies apart, so a [`Pipeline`] keeps up
//! to its limit in flight on one connection and matches each reply to its request by the id
//! alone, in whatever order the server answers. What [`Master`](super::Master) decides about a
//! reply — whether it answers the request, what a timeout heard, what is counted — it decides
//! here the same way, per request.
//!
//! - **Slots and tickets.** A submitted request takes a slot and gets a [`Ticket`]: the slot
//!   and the transaction id it goes out under. A slot is held from `submit` until the
//!   completion has been taken from [`Pipeline::poll_event`]; a pipeline holding
//!   [`Pipeline::limit`] of them is full and refuses more with [`SubmitError::Full`]. A
//!   ticket's slot is always below the limit.
//! - **Transaction ids.** The first request goes out under id 1, each next one under the next
//!   id, wrapping from 0xFFFF to 0, skipping every id a request outstanding holds and every id
//!   remembered as timed out (below): two requests outstanding never share an id.
//! - **Transmission.** Requests go out in the order they were submitted, one frame per
//!   [`Pipeline::poll_transmit`]; a driver calls it until it says `None` and writes the
//!   frames together. A queued request is due at once: [`Pipeline::poll_timeout`] is its
//!   submission instant until it has gone out. The receiver is never reset on a transmission,
//!   since other requests' replies may be arriving.
//! - **Time.** Each request's response timeout is its own, given at `submit`, and runs from
//!   the end of its transmission. A timeout fails only its own request, with
//!   [`MasterError::Timeout`] naming what that request heard instead of its reply. The grace
//!   [`Master`](super::Master) gives a reply still arriving at the deadline — the time a whole
//!   frame takes — is the same rule here; the MBAP receiver ends frames by length, not by
//!   time, and TCP takes no time to carry our bytes, so on this framing it adds nothing.
//! - **Matching.** A frame is matched to the request awaiting its reply under the frame's
//!   transaction id. Under that id a frame that is a request (an echo, another client) is
//!   ignored; a frame from another unit, or with a function code that does not answer the
//!   request, is ignored, and the request keeps waiting and names it if it times out
//!   ([`HeardInstead::OtherUnit`], [`HeardInstead::WrongFunction`]). Any other frame under the
//!   id ends the request: a raw request's reply as it is ([`Completion::Raw`]) or its
//!   exception, a parsed request's reply checked against the request exactly as
//!   [`Master`](super::Master) checks it (bit reads trimmed to the quantity asked, a reply
//!   that does not answer the request a [`MasterError::Mismatch`] or
//!   [`MasterError::BadResponse`], an exception a [`Completion::Exception`]). A bad reply
//!   fails only its own request.
//! - **Late replies.** The id of a request that timed out is remembered with its unit for its
//!   late window: [`Pipeline::set_late_window`], by default twice the request's timeout,
//!   from the timeout on. Until then no new request takes the id, and a frame under it from
//!   that unit is the late reply: dropped, counted in [`MasterStats::late_replies`], and the
//!   id forgotten (so it may be used again). Nothing is owed and nothing waits for it: unlike
//!   a serial line, the id keeps it from ever being taken for another request's reply, however
//!   many requests time out meanwhile (ids wrap after 65,536 requests, which a fast line goes
//!   through within a long window). Up to [`LATE_IDS`] ids are remembered at once (with the
//!   default window and one timeout for every request, at most 3 × [`MAX_IN_FLIGHT`] windows
//!   are open at once); past that the id whose window ends soonest is forgotten first. No
//!   memory is allocated: the ids are a fixed array.
//! - **Other frames.** A frame under any other id (a request not yet sent, one answered
//!   already, one forgotten, or none) is dropped, and every request awaiting a reply from the
//!   frame's unit names it if it times out ([`HeardInstead::OtherTransaction`]). Bytes that
//!   make no frame are named by every request awaiting a reply ([`HeardInstead::Garbage`]).
//!   Of what one request heard, the one that tells most about its unit is kept, as by
//!   [`Master`](super::Master) ([`HeardInstead::weight`]).
//! - **No reply.** 0x08/0x04 Force Listen Only is never answered: it completes as
//!   [`Completion::Sent`] as soon as it has gone out (on TCP there is no line to keep quiet
//!   after it). Unit 0 is no broadcast on Modbus/TCP
//!   ([`unit::is_broadcast`](crate::codes::unit::is_broadcast)): a request to it is awaited
//!   like any other.
//! - **Completions** come from [`Pipeline::poll_event`] in the order the requests ended, each
//!   with its ticket, once; taking it frees the slot.
//! - **A lost connection** is [`Pipeline::abort`]: every request outstanding is dropped
//!   without a completion, the slots are free, and the receiver and the late ids are
//!   forgotten (no late reply comes on a new connection).
//! - **Counters** are [`MasterStats`]: requests transmitted, responses, exceptions, timeouts,
//!   bad replies, ignored frames (every frame that ended no request, late replies included)
//!   and late replies. Broadcasts, echo bytes and early replies do not exist here and stay 0.
//!
//! # Driving it
//!
//! ```text
//! loop {
//!     while pipeline.has_room() && a request is waiting { tickets.push(pipeline.submit(now, unit, &request, timeout)?) }
//!     let mut n = 0;
//!     while let Some(k) = pipeline.poll_transmit(now, &mut buf[n..]) { n += k }
//!     write(&buf[..n]);
//!     while let Some((ticket, completion)) = pipeline.poll_event() { deliver(ticket, completion) }
//!     wait for bytes or until pipeline.poll_timeout();
//!     on bytes:   pipeline.on_bytes(now, &bytes)
//!     on timeout: pipeline.handle_timeout(now)
//!     on a lost connection: pipeline.abort(), reconnect
//! }
//! ```

use core::time::Duration;

use super::{
    Completion, HeardInstead, MasterError, MasterStats, Outcome, SubmitError, keep_heard, reply_wait_end,
    reply_wait_is_over,
};
use crate::codes::{DiagnosticCode, FunctionCode};
use crate::error::BufferTooSmall;
use crate::frame::mbap::{HEADER_LEN, MAX_ADU_LEN, MbapCodec};
use crate::frame::{Adu, AduHeader, Direction, Framing, RxEvent, expire, feed};
use crate::pdu::{MAX_PDU_LEN, Request};
use crate::time::{Instant, earliest};

/// The most requests a Pipeline keeps in flight.
pub const MAX_IN_FLIGHT: usize = 16;

/// The most ids of timed-out requests remembered at once while their late reply may still
/// come (see the module docs).
pub const LATE_IDS: usize = 256;

/// Ids a new request may not take: those of the other requests outstanding and the
/// remembered timed-out ones (fewer than this). One more candidate than this is always
/// enough.
const TAKEN_IDS: usize = MAX_IN_FLIGHT + LATE_IDS;

/// The id of a request that timed out, from its unit, whose late reply may come until
/// `until`.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
struct Late {
    transaction: u16,
    unit: u8,
    until: Instant,
}

impl Late {
    /// Whether its late reply may still come at `now`.
    fn open(&self, now: Instant) -> bool {
        now < self.until
    }
}

/// A submitted request, to match its completion.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub struct Ticket {
    slot: u8,
    transaction: u16,
}

impl Ticket {
    /// The slot the request holds, below [`Pipeline::limit`] (and so below
    /// [`MAX_IN_FLIGHT`]). A slot is taken again only after the completion of the request
    /// that held it has been polled.
    pub fn slot(self) -> usize {
        usize::from(self.slot)
    }

    /// The MBAP transaction id the request goes out under.
    pub fn transaction(self) -> u16 {
        self.transaction
    }
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Phase {
    /// Holds no request.
    Free,
    /// Submitted at `since`; not transmitted yet.
    Queued { since: Instant },
    /// Transmitted, the last byte at `sent`; its reply is awaited until `deadline`.
    Awaiting { sent: Instant, deadline: Instant },
    /// Ended; the completion has not been polled yet.
    Ended { outcome: Outcome },
}

/// One request, from its submission until its completion has been polled.
#[derive(Clone, Debug)]
struct Slot {
    phase: Phase,
    /// When queued or awaiting: the submission's place in the order of submissions. When
    /// ended: the end's place in the order of ends.
    order: u64,
    unit: u8,
    transaction: u16,
    /// Submitted with `submit_raw`: the reply is not checked against the request.
    raw: bool,
    /// No reply is expected (0x08/0x04).
    no_reply: bool,
    timeout: Duration,
    /// The request's frame, MBAP header first: the PDU follows the header.
    tx: [u8; MAX_ADU_LEN],
    tx_len: usize,
    reply: [u8; MAX_PDU_LEN],
    reply_len: usize,
    /// What came instead of the reply while it was awaited.
    heard: Option<HeardInstead>,
}

impl Slot {
    const FREE: Slot = Slot {
        phase: Phase::Free,
        order: 0,
        unit: 0,
        transaction: 0,
        raw: false,
        no_reply: false,
        timeout: Duration::ZERO,
        tx: [0; MAX_ADU_LEN],
        tx_len: 0,
        reply: [0; MAX_PDU_LEN],
        reply_len: 0,
        heard: None,
    };

    /// The request's PDU, function code first.
    fn request(&self) -> &[u8] {
        self.tx.get(HEADER_LEN..self.tx_len).unwrap_or_default()
    }

    /// The function code asked.
    fn function(&self) -> u8 {
        self.request().first().copied().unwrap_or_default()
    }

    fn is_free(&self) -> bool {
        self.phase == Phase::Free
    }

    fn is_awaiting(&self) -> bool {
        matches!(self.phase, Phase::Awaiting { .. })
    }
}

/// The pipelined master engine over a Modbus/TCP connection (see the module docs).
#[derive(Clone, Debug)]
pub struct Pipeline {
    framing: MbapCodec,
    core: Core,
}

/// Everything but the framing, so that frames borrowed from the framing can be examined
/// while it is borrowed.
#[derive(Clone, Debug)]
struct Core {
    limit: usize,
    slots: [Slot; MAX_IN_FLIGHT],
    /// The transaction id given last.
    transaction: u16,
    /// The next place in the order of submissions and ends.
    seq: u64,
    /// The transaction ids and units of requests that timed out, while their late replies
    /// have not come and may still (an entry past its window is free).
    late: [Option<Late>; LATE_IDS],
    /// How long after its timeout a request's late reply may come; `None`: twice its timeout.
    late_window: Option<Duration>,
    stats: MasterStats,
}

impl Pipeline {
    /// A pipeline over `framing` that keeps up to `in_flight` requests outstanding (clamped
    /// to 1..=[`MAX_IN_FLIGHT`]).
    pub fn new(framing: MbapCodec, in_flight: usize) -> Self {
        Pipeline {
            framing,
            core: Core {
                limit: in_flight.clamp(1, MAX_IN_FLIGHT),
                slots: [Slot::FREE; MAX_IN_FLIGHT],
                transaction: 0,
                seq: 0,
                late: [None; LATE_IDS],
                late_window: None,
                stats: MasterStats::default(),
            },
        }
    }

    /// The most requests kept outstanding.
    pub fn limit(&self) -> usize {
        self.core.limit
    }

    /// The requests submitted whose completion has not been polled yet.
    pub fn outstanding(&self) -> usize {
        self.core.slots.iter().filter(|slot| !slot.is_free()).count()
    }

    /// Whether a request can be submitted: fewer than [`Pipeline::limit`] are outstanding.
    pub fn has_room(&self) -> bool {
        self.outstanding() < self.limit()
    }

    /// What the pipeline has done (see the module docs for what is counted).
    pub fn stats(&self) -> MasterStats {
        self.core.stats
    }

    /// The framing (for its statistics).
    pub fn framing(&self) -> &MbapCodec {
        &self.framing
    }

    /// How long after a request's timeout its late reply may still come, and its id is kept
    /// out of use: `window`, or (`None`, the default) twice the request's own timeout. Applies
    /// to the timeouts from now on.
    pub fn set_late_window(&mut self, window: Option<Duration>) {
        self.core.late_window = window;
    }

    /// Queues `request` for `unit`, to be transmitted at once and its reply awaited for
    /// `timeout` after that. 0x08/0x04 Force Listen Only is never answered: it completes as
    /// [`Completion::Sent`] once transmitted.
    pub fn submit(
        &mut self,
        now: Instant,
        unit: u8,
        request: &Request<'_>,
        timeout: Duration,
    ) -> Result<Ticket, SubmitError> {
        if !self.has_room() {
            return Err(SubmitError::Full { limit: self.limit() });
        }
        let mut pdu = [0u8; MAX_PDU_LEN];
        let len = request.emit(&mut pdu).map_err(SubmitError::Encode)?;
        let listen_only =
            matches!(request, Request::Diagnostics(d) if d.sub_function() == DiagnosticCode::ForceListenOnly);
        let queued =
            NewRequest { unit, pdu: pdu.get(..len).unwrap_or_default(), timeout, raw: false, no_reply: listen_only };
        self.core.queue(&self.framing, now, &queued)
    }

    /// Queues any PDU for `unit`, valid or not: for probing devices and testing servers. The
    /// reply is matched by transaction id, unit and function code only and handed back
    /// unparsed as [`Completion::Raw`] (an exception as [`Completion::Exception`]).
    pub fn submit_raw(&mut self, now: Instant, unit: u8, pdu: &[u8], timeout: Duration) -> Result<Ticket, SubmitError> {
        if !self.has_room() {
            return Err(SubmitError::Full { limit: self.limit() });
        }
        if pdu.is_empty() || pdu.len() > MAX_PDU_LEN {
            return Err(SubmitError::Encode(BufferTooSmall { needed: pdu.len().max(1), available: MAX_PDU_LEN }));
        }
        self.core.queue(&self.framing, now, &NewRequest { unit, pdu, timeout, raw: true, no_reply: false })
    }

    /// The next queued request's frame, if one is due: copies it into `buf` (which should
    /// hold [`MAX_ADU_LEN`] bytes) and returns its length. One frame per call, in the order
    /// the requests were submitted. A request whose frame does not fit `buf` fails with
    /// [`MasterError::TransmitBuffer`] and the next one is tried.
    pub fn poll_transmit(&mut self, now: Instant, buf: &mut [u8]) -> Option<usize> {
        // Each round transmits a request or fails one.
        for _ in 0..MAX_IN_FLIGHT {
            let core = &mut self.core;
            let (index, slot) = core
                .slots
                .iter_mut()
                .enumerate()
                .filter(|(_, slot)| matches!(slot.phase, Phase::Queued { .. }))
                .min_by_key(|(_, slot)| slot.order)?;
            let Phase::Queued { since } = slot.phase else { return None };
            if now < since {
                return None;
            }
            let n = slot.tx_len;
            let (Some(dst), Some(src)) = (buf.get_mut(..n), slot.tx.get(..n)) else {
                let e = BufferTooSmall { needed: n, available: buf.len() };
                core.end(index, Outcome::Failed(MasterError::TransmitBuffer(e)));
                continue;
            };
            dst.copy_from_slice(src);
            core.stats.requests = core.stats.requests.wrapping_add(1);
            let sent = now.saturating_add(self.framing.transmit_time(n));
            if slot.no_reply {
                core.end(index, Outcome::Sent);
            } else {
                slot.phase = Phase::Awaiting { sent, deadline: sent.saturating_add(slot.timeout) };
            }
            return Some(n);
        }
        None
    }

    /// Bytes arrived at `now`.
    pub fn on_bytes(&mut self, now: Instant, bytes: &[u8]) {
        if bytes.is_empty() {
            return;
        }
        let Pipeline { framing, core } = self;
        feed(framing, now, bytes, |event| core.on_event(now, &event));
    }

    /// The next instant [`Pipeline::handle_timeout`] must be called (or, for a queued
    /// request, [`Pipeline::poll_transmit`]).
    pub fn poll_timeout(&self) -> Option<Instant> {
        let own = (self.core.slots.iter())
            .filter_map(|slot| match slot.phase {
                Phase::Queued { since } => Some(since),
                Phase::Awaiting { deadline, .. } => Some(reply_wait_end(&self.framing, deadline)),
                Phase::Free | Phase::Ended { .. } => None,
            })
            .min();
        earliest(own, self.framing.poll_timeout())
    }

    /// `now` has come: fails the requests whose timeout has passed, earliest deadline first.
    /// Spurious calls do nothing.
    pub fn handle_timeout(&mut self, now: Instant) {
        let Pipeline { framing, core } = self;
        expire(framing, now, |event| core.on_event(now, &event));
        // Each round ends a request.
        for _ in 0..MAX_IN_FLIGHT {
            let due = (core.slots.iter().enumerate())
                .filter_map(|(index, slot)| match slot.phase {
                    Phase::Awaiting { sent, deadline } if reply_wait_is_over(framing, now, deadline) => {
                        Some((deadline, slot.order, index, sent))
                    }
                    _ => None,
                })
                .min();
            let Some((_, _, index, sent)) = due else { return };
            let Some(slot) = core.slots.get(index) else { return };
            let waited = now.saturating_duration_since(sent);
            let (heard, transaction, unit) = (slot.heard, slot.transaction, slot.unit);
            let window = core.late_window.unwrap_or(slot.timeout.saturating_mul(2));
            core.remember_late(Late { transaction, unit, until: now.saturating_add(window) }, now);
            core.end(index, Outcome::Failed(MasterError::Timeout { waited, heard }));
        }
    }

    /// How the request that ended first, of those whose completion has not been polled, ended,
    /// with its ticket; its slot is free from now on. The reply borrows the pipeline until the
    /// next call.
    pub fn poll_event(&mut self) -> Option<(Ticket, Completion<'_>)> {
        let (slot_index, slot) = (0u8..)
            .zip(self.core.slots.iter_mut())
            .filter(|(_, slot)| matches!(slot.phase, Phase::Ended { .. }))
            .min_by_key(|(_, slot)| slot.order)?;
        let Phase::Ended { outcome } = slot.phase else { return None };
        slot.phase = Phase::Free;
        let ticket = Ticket { slot: slot_index, transaction: slot.transaction };
        Some((ticket, outcome.completion(slot.reply.get(..slot.reply_len).unwrap_or_default())))
    }

    /// The connection is gone: every request outstanding is dropped without a completion,
    /// every slot is free, the receiver forgets what it held, and the ids of requests that
    /// timed out are forgotten. The counters and the transaction ids go on.
    pub fn abort(&mut self) {
        for slot in &mut self.core.slots {
            slot.phase = Phase::Free;
        }
        self.core.late = [None; LATE_IDS];
        self.framing.reset();
    }

    /// Makes `last` the transaction id given last, as if that many requests had gone.
    #[cfg(test)]
    fn set_last_transaction(&mut self, last: u16) {
        self.core.transaction = last;
    }
}

/// A request to queue.
struct NewRequest<'a> {
    unit: u8,
    pdu: &'a [u8],
    timeout: Duration,
    raw: bool,
    no_reply: bool,
}

impl Core {
    /// Takes the lowest free slot and the next free transaction id for `request`.
    fn queue(&mut self, framing: &MbapCodec, now: Instant, request: &NewRequest<'_>) -> Result<Ticket, SubmitError> {
        let transaction = self.next_transaction(now);
        let full = SubmitError::Full { limit: self.limit };
        let (slot_index, slot) = (0u8..).zip(self.slots.iter_mut()).find(|(_, slot)| slot.is_free()).ok_or(full)?;
        let header = AduHeader { unit: request.unit, transaction };
        slot.tx_len = framing.encode(header, request.pdu, &mut slot.tx).map_err(SubmitError::Encode)?;
        slot.phase = Phase::Queued { since: now };
        slot.order = self.seq;
        slot.unit = request.unit;
        slot.transaction = transaction;
        slot.raw = request.raw;
        slot.no_reply = request.no_reply;
        slot.timeout = request.timeout;
        slot.reply_len = 0;
        slot.heard = None;
        self.seq = self.seq.wrapping_add(1);
        self.transaction = transaction;
        Ok(Ticket { slot: slot_index, transaction })
    }

    /// The id after the last one given that no request outstanding holds and whose late
    /// reply may not come any more at `now`.
    fn next_transaction(&self, now: Instant) -> u16 {
        let mut id = self.transaction;
        // At most `TAKEN_IDS` ids are taken, so one of this many candidates is free.
        for _ in 0..=TAKEN_IDS {
            id = id.wrapping_add(1);
            let held = self.slots.iter().any(|slot| !slot.is_free() && slot.transaction == id);
            let late = self.late.iter().flatten().any(|late| late.transaction == id && late.open(now));
            if !held && !late {
                break;
            }
        }
        id
    }

    /// Remembers the id of a request that timed out at `now`: in a free entry (one whose
    /// window has passed), or, with every window open, over the one that ends soonest.
    fn remember_late(&mut self, late: Late, now: Instant) {
        let free = self.late.iter().position(|entry| entry.is_none_or(|entry| !entry.open(now)));
        let soonest = || {
            (self.late.iter().enumerate())
                .min_by_key(|(_, entry)| entry.map(|entry| entry.until))
                .map(|(index, _)| index)
        };
        if let Some(entry) = free.or_else(soonest).and_then(|index| self.late.get_mut(index)) {
            *entry = Some(late);
        }
    }

    /// Counts the outcome and ends the request in slot `index`.
    fn end(&mut self, index: usize, outcome: Outcome) {
        let Some(slot) = self.slots.get_mut(index) else { return };
        self.stats.count(outcome);
        slot.phase = Phase::Ended { outcome };
        slot.order = self.seq;
        self.seq = self.seq.wrapping_add(1);
    }

    fn ignore(&mut self) {
        self.stats.ignored_frames = self.stats.ignored_frames.wrapping_add(1);
    }

    fn on_event(&mut self, now: Instant, event: &RxEvent<'_>) {
        let frame = match *event {
            RxEvent::Frame(frame) => frame,
            RxEvent::Discarded { bytes, reason, .. } => {
                for slot in self.slots.iter_mut().filter(|slot| slot.is_awaiting()) {
                    keep_heard(&mut slot.heard, HeardInstead::Garbage { bytes, reason });
                }
                return;
            }
        };
        if frame.direction == Direction::Request {
            self.ignore();
            return;
        }
        let AduHeader { unit, transaction } = frame.header;
        let awaiting = self.slots.iter().position(|slot| slot.is_awaiting() && slot.transaction == transaction);
        if let Some(index) = awaiting {
            self.on_reply(index, &frame);
            return;
        }
        self.ignore();
        let late = |entry: &&mut Option<Late>| {
            entry.is_some_and(|late| late.transaction == transaction && late.unit == unit && late.open(now))
        };
        if let Some(entry) = self.late.iter_mut().find(late) {
            *entry = None;
            self.stats.late_replies = self.stats.late_replies.wrapping_add(1);
            return;
        }
        for slot in self.slots.iter_mut().filter(|slot| slot.is_awaiting() && slot.unit == unit) {
            keep_heard(&mut slot.heard, HeardInstead::OtherTransaction { transaction, expected: slot.transaction });
        }
    }

    /// A frame under the id of the request in slot `index`, which awaits its reply.
    fn on_reply(&mut self, index: usize, frame: &Adu<'_>) {
        let Some(slot) = self.slots.get_mut(index) else { return };
        let function = frame.pdu.first().copied().unwrap_or_default();
        let asked = slot.function();
        if frame.header.unit != slot.unit || function & !FunctionCode::EXCEPTION_BIT != asked {
            // Not its reply, but worth naming if the wait ends without one.
            let heard = if frame.header.unit == slot.unit {
                HeardInstead::WrongFunction { function, expected: asked }
            } else {
                HeardInstead::OtherUnit { unit: frame.header.unit, function }
            };
            keep_heard(&mut slot.heard, heard);
            self.ignore();
            return;
        }
        let outcome = Outcome::of_reply(slot.request(), slot.raw, frame.pdu);
        if let Some(len) = outcome.keep_reply(&mut slot.reply, frame.pdu) {
            slot.reply_len = len;
        }
        self.end(index, outcome);
    }
}

#[cfg(test)]
mod tests;
