//! Application data units: how a PDU travels on each transport, and the incremental receivers
//! that find frames in a byte stream.
//!
//! | module   | transport                  | frame                                   | boundaries by          |
//! |----------|----------------------------|-----------------------------------------|------------------------|
//! | [`rtu`]  | serial line, RTU over TCP  | unit, PDU, CRC-16 (≤ 256 bytes)         | function code, then t3.5 |
//! | [`ascii`]| serial line                | `:`, hex(unit, PDU, LRC), CR LF         | `:` and CR LF          |
//! | [`mbap`] | Modbus/TCP                 | 7-byte MBAP header, PDU (≤ 260 bytes)   | the header's length    |
//!
//! All three implement [`Framing`], the one interface the master and slave engines use: wrap
//! a PDU for sending, take received bytes with their arrival time, hand out frames and
//! discards as [`RxEvent`]s, and say when they next need a timeout. A receiver never fails:
//! bad bytes are counted in [`RxStats`], reported as a [`RxEvent::Discarded`], and skipped.

pub mod ascii;
pub mod mbap;
pub mod rtu;
pub mod timing;

use core::time::Duration;

use crate::error::{BufferTooSmall, DiscardReason};
use crate::time::Instant;

pub use timing::{DataBits, LineConfig, LineTiming, Parity, StopBits};

/// The header fields of an ADU around its PDU.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub struct AduHeader {
    /// Unit (slave) address; 0 is broadcast on a serial line.
    pub unit: u8,
    /// MBAP transaction identifier; always 0 on a serial line.
    pub transaction: u16,
}

impl AduHeader {
    /// A serial-line header for `unit`.
    pub const fn unit(unit: u8) -> Self {
        AduHeader { unit, transaction: 0 }
    }
}

/// Which way a frame went, as far as its bytes tell.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum Direction {
    /// Only a request has this layout.
    Request,
    /// Only a response has this layout.
    Response,
    /// Both could (a write echo, a custom code), or the transport does not say.
    Either,
}

/// Which frames a receiver looks for.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum Expect {
    /// Requests: a slave.
    Requests,
    /// Responses: a master.
    Responses,
    /// Both, told apart by their layout: a sniffer.
    Both,
}

impl Expect {
    pub(crate) const fn requests(self) -> bool {
        matches!(self, Expect::Requests | Expect::Both)
    }

    pub(crate) const fn responses(self) -> bool {
        matches!(self, Expect::Responses | Expect::Both)
    }
}

/// A frame found by a receiver.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Adu<'a> {
    /// Unit and transaction.
    pub header: AduHeader,
    /// The PDU, function code first.
    pub pdu: &'a [u8],
    /// When its last byte arrived.
    pub end: Instant,
    /// Request or response, as far as the layout tells.
    pub direction: Direction,
}

/// What a receiver reports.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum RxEvent<'a> {
    /// A complete frame with a correct checksum.
    Frame(Adu<'a>),
    /// Bytes thrown away.
    Discarded {
        /// How many.
        bytes: usize,
        /// Why (the first reason, if there were several).
        reason: DiscardReason,
        /// When the receiver decided.
        at: Instant,
        /// The first two bytes of the run as a frame's address and function code, when the
        /// run began where a frame could (RTU, ASCII): what a frame with a broken checksum
        /// said it was. Only a hint — the damage may be in these bytes too.
        head: Option<(u8, u8)>,
    },
}

/// What a receiver has seen since it was made (or its stats reset). Counters wrap at 2³².
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug, Default)]
pub struct RxStats {
    /// Frames delivered.
    pub frames: u32,
    /// Discard events (each covers a run of bad bytes).
    pub discards: u32,
    /// Discards because a checksum did not match.
    pub checksum_errors: u32,
    /// Discards because too many bytes came without a frame boundary.
    pub overruns: u32,
    /// Bytes thrown away in all.
    pub discarded_bytes: u32,
}

impl RxStats {
    pub(crate) fn count_discard(&mut self, bytes: usize, reason: DiscardReason) {
        self.discards = self.discards.wrapping_add(1);
        self.discarded_bytes = self.discarded_bytes.wrapping_add(u32::try_from(bytes).unwrap_or(u32::MAX));
        match reason {
            DiscardReason::ChecksumMismatch => self.checksum_errors = self.checksum_errors.wrapping_add(1),
            DiscardReason::TooLong => self.overruns = self.overruns.wrapping_add(1),
            _ => {}
        }
    }
}

/// A transport's framing: encoding for sending, an incremental receiver for receiving.
///
/// The receiver contract, shared by every implementation:
/// - [`Framing::push`] takes bytes that arrived at `now` and returns how many it consumed. It
///   stops early when a frame is ready; the caller takes the events with
///   [`Framing::poll_event`] and pushes the rest. [`feed`] does this loop.
/// - A frame handed out by `poll_event` borrows the receiver's buffer and stays valid until
///   the next `push` or `handle_timeout`.
/// - [`Framing::poll_timeout`] is the instant the receiver must be told about
///   (with [`Framing::handle_timeout`]) even if no byte arrives: the end of a silent
///   interval. Spurious calls are harmless.
/// - Nothing here fails or panics on any input: bad bytes become discard events.
pub trait Framing {
    /// Wraps `pdu` into a frame for `header` and returns its length.
    fn encode(&self, header: AduHeader, pdu: &[u8], out: &mut [u8]) -> Result<usize, BufferTooSmall>;

    /// Takes bytes received at `now`; returns how many were consumed.
    fn push(&mut self, now: Instant, bytes: &[u8]) -> usize;

    /// The next event, if any.
    fn poll_event(&mut self) -> Option<RxEvent<'_>>;

    /// When the receiver next needs [`Framing::handle_timeout`].
    fn poll_timeout(&self) -> Option<Instant>;

    /// Tells the receiver that `now` has come.
    fn handle_timeout(&mut self, now: Instant);

    /// The silence the line needs between two frames: t3.5 on a serial line, zero on TCP.
    fn inter_frame_gap(&self) -> Duration;

    /// The time the line takes to carry `n` of our own bytes (zero where there is no line).
    fn transmit_time(&self, n: usize) -> Duration;

    /// Forgets any partial frame (pending events are dropped too).
    fn reset(&mut self);

    /// What the receiver has seen.
    fn stats(&self) -> RxStats;

    /// Whether unit 0 is a broadcast that no slave answers: true on serial lines (and RTU
    /// carried over TCP to a gateway), false on Modbus/TCP, where unit 0 is an ordinary id.
    fn supports_broadcast(&self) -> bool {
        true
    }

    /// Whether the receiver holds the start of a frame not yet complete: a driver may close a
    /// stream whose frame never ends. Framings that end frames by time say false.
    fn is_mid_frame(&self) -> bool {
        false
    }

    /// Changes the end-of-frame character, as 0x08/0x03 asks of an ASCII device. Other
    /// framings have none and ignore it.
    fn set_delimiter(&mut self, _delimiter: u8) {}
}

/// Pushes all of `bytes` into `framing` and hands every event to `on_event`, in order.
pub fn feed<F: Framing + ?Sized>(framing: &mut F, now: Instant, bytes: &[u8], mut on_event: impl FnMut(RxEvent<'_>)) {
    let mut rest = bytes;
    loop {
        let consumed = framing.push(now, rest);
        rest = rest.get(consumed..).unwrap_or_default();
        let mut any = false;
        while let Some(event) = framing.poll_event() {
            on_event(event);
            any = true;
        }
        if !any && (rest.is_empty() || consumed == 0) {
            break;
        }
    }
}

/// Tells `framing` that `now` has come and hands every resulting event to `on_event`.
pub fn expire<F: Framing + ?Sized>(framing: &mut F, now: Instant, mut on_event: impl FnMut(RxEvent<'_>)) {
    framing.handle_timeout(now);
    while let Some(event) = framing.poll_event() {
        on_event(event);
    }
    // A frame found at the gap may leave buffered bytes behind it; let them be examined.
    feed(framing, now, &[], on_event);
}
