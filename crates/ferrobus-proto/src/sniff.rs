//! A passive decoder for an RTU line: what a listener that never transmits makes of the bytes
//! it hears, and when they were on the wire.
//!
//! Spec: MODBUS over Serial Line V1.02 §2.5.1.1 (frames separated by t3.5 of silence, no gap
//! over t1.5 inside one) and §2.5.1.2 (the CRC). Frame boundaries are found by
//! [`RtuCodec`] looking for both directions ([`Expect::Both`]): by the function code's
//! length first, by the silence second; nothing here parses a frame's layout again. What the
//! codec throws away is looked at once more, with the PDU tables' length predictions, to tell
//! a frame with a bad CRC (written out and shown, as a sniffer must) and a frame cut short
//! from noise.
//!
//! # Time
//!
//! The caller hands in each chunk with the instant it arrived. A chunk's last byte is taken to
//! have left the wire at that instant and the ones before it back to back, one character time
//! apart, but never earlier than a character time after the previous byte: a chunk holding a
//! whole frame (a pty, the virtual line) gives the frame's true start and end, and the silence
//! before it. Gaps inside one chunk are invisible: bytes that a USB adapter held back
//! (its latency timer, 16 ms on an FTDI by default) arrive together and look back to back.
//!
//! # Request or response
//!
//! Decided from the bytes: the layout that fits the length and the CRC, an exception bit. Where
//! both layouts fit (the echo of 0x05, 0x06, 0x08, 0x15, 0x16), a frame is the response when a
//! request of the same unit and function code is waiting for one, and a request otherwise. A
//! response is paired with the waiting request only if its unit and function code match; its
//! response time is from the request's end to its own. A request that comes while another is
//! still waiting ends that one as [`SniffEvent::Unanswered`] — unless the waiting one had a bad
//! CRC, which a slave rightly leaves unanswered. A broadcast (unit 0) waits for nothing. Noise
//! and partial frames change nothing in the pairing.

use core::time::Duration;

use crate::codes::{FunctionCode, unit};
use crate::crc::crc_ok;
use crate::error::PduError;
use crate::frame::rtu::{MAX_ADU_LEN, MIN_ADU_LEN, RtuCodec};
use crate::frame::{Direction, Expect, Framing, LineTiming, RxEvent};
use crate::pdu::{Request, Response, WireLen};
use crate::time::Instant;

/// Bytes held until the codec has said what they are: room for its receive buffer and a run
/// of noise being dropped. Noise beyond it is reported early, in pieces.
const RAW_LEN: usize = 1024;

/// Which way a frame went.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum Role {
    /// From the master.
    Request,
    /// From a slave.
    Response,
}

/// Where something heard was on the wire.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct WireTime {
    /// When its first character began.
    pub start: Instant,
    /// When its last character ended.
    pub end: Instant,
    /// The silence between the end of what was heard before it and its start; `None` for the
    /// first thing heard.
    pub silence_before: Option<Duration>,
    /// The longest silence between two of its characters.
    pub longest_gap: Duration,
    /// The silence before it was shorter than t3.5.
    pub t3_5_violation: bool,
    /// A silence inside it was longer than t1.5.
    pub t1_5_violation: bool,
}

impl WireTime {
    /// Something heard as if whole at `end`: it starts there too, no silence before it is
    /// known, and no gap or violation is in it (what a frame made by a test, or taken from a
    /// record without timing, carries).
    #[must_use]
    pub const fn at(end: Instant) -> WireTime {
        WireTime {
            start: end,
            end,
            silence_before: None,
            longest_gap: Duration::ZERO,
            t3_5_violation: false,
            t1_5_violation: false,
        }
    }
}

/// A response paired with its request.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Reply {
    /// When the request ended.
    pub request_end: Instant,
    /// From the end of the request to the end of the response.
    pub response_time: Duration,
}

/// A frame: a unit address, a PDU and two CRC bytes, the CRC right or wrong.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Frame<'a> {
    adu: &'a [u8],
    /// Request or response.
    pub role: Role,
    /// Whether the CRC agrees.
    pub crc_ok: bool,
    /// When it was on the wire.
    pub time: WireTime,
    /// For a response: the request it answers, if one of its unit and function code was
    /// waiting.
    pub reply: Option<Reply>,
}

impl<'a> Frame<'a> {
    /// The whole frame as heard, CRC included.
    pub fn adu(&self) -> &'a [u8] {
        self.adu
    }

    /// The unit address.
    pub fn unit(&self) -> u8 {
        self.adu.first().copied().unwrap_or_default()
    }

    /// The function code byte, with the exception bit of an exception response.
    pub fn function(&self) -> u8 {
        self.adu.get(1).copied().unwrap_or_default()
    }

    /// The PDU, function code first.
    pub fn pdu(&self) -> &'a [u8] {
        self.adu.get(1..self.adu.len().saturating_sub(2)).unwrap_or_default()
    }

    /// The two CRC bytes as they came (low byte first).
    pub fn crc(&self) -> u16 {
        match *self.adu {
            [.., low, high] if self.adu.len() >= MIN_ADU_LEN => u16::from_le_bytes([low, high]),
            _ => 0,
        }
    }

    /// Whether it is a request to unit 0, which no slave answers.
    pub fn is_broadcast(&self) -> bool {
        self.role == Role::Request && self.unit() == unit::BROADCAST
    }

    /// The PDU parsed as a request.
    pub fn request(&self) -> Result<Request<'a>, PduError> {
        Request::parse(self.pdu())
    }

    /// The PDU parsed as a response.
    pub fn response(&self) -> Result<Response<'a>, PduError> {
        Response::parse(self.pdu())
    }
}

/// What bytes that are not a frame are.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum FragmentKind {
    /// The start of a frame that the silence cut short: its unit and function code look
    /// right, and it needed `expected` bytes (`None` when even that was not yet told).
    Partial {
        /// How long the frame would have been.
        expected: Option<usize>,
    },
    /// Bytes that do not start a frame.
    Noise,
}

/// Bytes heard that are not a frame.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Fragment<'a> {
    /// The bytes.
    pub bytes: &'a [u8],
    /// Partial frame or noise.
    pub kind: FragmentKind,
    /// When they were on the wire.
    pub time: WireTime,
}

/// A request that got no response before the next request.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Unanswered {
    /// Its unit.
    pub unit: u8,
    /// Its function code.
    pub function: u8,
    /// When it ended.
    pub request_end: Instant,
}

/// What the sniffer reports, in the order it was on the wire.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum SniffEvent<'a> {
    /// A frame, with a good or a bad CRC.
    Frame(Frame<'a>),
    /// A partial frame or noise.
    Fragment(Fragment<'a>),
    /// The request waiting for a response got none: another request came first.
    Unanswered(Unanswered),
}

/// The request waiting for its response.
#[derive(Clone, Copy, Debug)]
struct Pending {
    unit: u8,
    function: u8,
    end: Instant,
    crc_ok: bool,
}

/// What the codec said about the oldest bytes held.
#[derive(Clone, Copy, Debug)]
enum Verdict {
    /// A frame of this many bytes with a good CRC, its layout telling this direction.
    Frame(usize, Direction),
    /// This many bytes thrown away.
    Discard(usize),
}

/// What a run of discarded bytes starts with.
#[derive(Clone, Copy, Debug)]
enum Shape {
    /// A whole frame of this length whose CRC failed, in this role.
    Frame(usize, Role),
    /// A frame cut short.
    Partial(Option<usize>),
    /// Noise.
    Noise,
}

/// The passive RTU decoder. See the [module docs](self).
#[derive(Clone, Debug)]
pub struct Sniffer {
    codec: RtuCodec,
    timing: LineTiming,
    raw: [u8; RAW_LEN],
    ends: [Instant; RAW_LEN],
    /// Bytes held in `raw`.
    len: usize,
    /// Bytes already reported as noise that the codec has not discarded yet.
    ahead: usize,
    /// When the last thing reported ended.
    last_end: Option<Instant>,
    /// When the last byte received ended, as estimated.
    last_byte: Option<Instant>,
    pending: Option<Pending>,
}

impl Sniffer {
    /// A sniffer for a line with `timing` (character time, t1.5, t3.5). Frames of unknown
    /// length end at t3.5 of silence, frames of known length are waited for as long.
    pub fn new(timing: LineTiming) -> Self {
        Sniffer {
            codec: RtuCodec::new(timing, Expect::Both),
            timing,
            raw: [0; RAW_LEN],
            ends: [Instant::ZERO; RAW_LEN],
            len: 0,
            ahead: 0,
            last_end: None,
            last_byte: None,
            pending: None,
        }
    }

    /// Waits `timeout` (at least t3.5) for the rest of a frame whose length is known, as a PC
    /// behind a USB adapter needs ([`RtuCodec::with_incomplete_timeout`]).
    #[must_use]
    pub fn with_incomplete_timeout(mut self, timeout: Duration) -> Self {
        self.codec = self.codec.with_incomplete_timeout(timeout);
        self
    }

    /// The line timing.
    pub fn timing(&self) -> &LineTiming {
        &self.timing
    }

    /// Takes `bytes` that arrived at `now` and hands every event they complete to `on_event`.
    pub fn feed(&mut self, now: Instant, bytes: &[u8], mut on_event: impl FnMut(SniffEvent<'_>)) {
        let total = bytes.len();
        let mut taken = 0usize;
        loop {
            let rest = bytes.get(taken..).unwrap_or_default();
            let consumed = self.codec.push(now, rest).min(rest.len());
            for (k, &byte) in rest.get(..consumed).unwrap_or_default().iter().enumerate() {
                let after = total.saturating_sub(taken.saturating_add(k).saturating_add(1));
                let end = self.byte_end(now, after);
                self.hold(byte, end, &mut on_event);
            }
            taken = taken.saturating_add(consumed);
            let any = self.drain(&mut on_event);
            if !any && (taken >= total || consumed == 0) {
                break;
            }
        }
    }

    /// When the sniffer next needs [`Sniffer::expire`]: the silence that ends a frame.
    pub fn poll_timeout(&self) -> Option<Instant> {
        self.codec.poll_timeout()
    }

    /// Tells the sniffer that `now` has come; hands out what the silence completed.
    pub fn expire(&mut self, now: Instant, mut on_event: impl FnMut(SniffEvent<'_>)) {
        self.codec.handle_timeout(now);
        self.drain(&mut on_event);
        // What the gap settled may leave bytes behind it to look at.
        self.feed(now, &[], &mut on_event);
    }

    /// Settles everything held, as if the line had gone silent for good (the end of a
    /// capture). A request still waiting is not reported as unanswered.
    pub fn finish(&mut self, mut on_event: impl FnMut(SniffEvent<'_>)) {
        let end = Instant::from_nanos(u64::MAX);
        // Twice: a frame found at the gap may leave bytes to settle at the next.
        for _ in 0..2 {
            self.expire(end, &mut on_event);
        }
    }

    /// The end of the byte of a chunk that arrived at `now` with `after` bytes behind it.
    fn byte_end(&mut self, now: Instant, after: usize) -> Instant {
        let char_time = self.timing.char_time();
        let back_to_back = now.saturating_sub(self.timing.transmit_time(after));
        let end = match self.last_byte {
            Some(last) => back_to_back.max(last.saturating_add(char_time)).min(now),
            None => back_to_back,
        };
        self.last_byte = Some(end);
        end
    }

    /// Keeps a byte the codec took; when full, reports the oldest half as noise ahead of the
    /// codec (only a long run of noise can fill it).
    fn hold(&mut self, byte: u8, end: Instant, on_event: &mut impl FnMut(SniffEvent<'_>)) {
        if self.len >= RAW_LEN {
            let early = RAW_LEN / 2;
            self.report(0, early, Shape::Noise, None, on_event);
            self.remove(early);
            self.ahead = self.ahead.saturating_add(early);
        }
        if let (Some(slot), Some(at)) = (self.raw.get_mut(self.len), self.ends.get_mut(self.len)) {
            *slot = byte;
            *at = end;
            self.len = self.len.saturating_add(1);
        }
    }

    /// Hands out the codec's events; whether there were any.
    fn drain(&mut self, on_event: &mut impl FnMut(SniffEvent<'_>)) -> bool {
        let mut any = false;
        loop {
            let verdict = match self.codec.poll_event() {
                Some(RxEvent::Frame(adu)) => Verdict::Frame(adu.pdu.len().saturating_add(3), adu.direction),
                Some(RxEvent::Discarded { bytes, .. }) => Verdict::Discard(bytes),
                None => return any,
            };
            any = true;
            match verdict {
                Verdict::Frame(len, direction) => {
                    let len = len.min(self.len);
                    let role = self.role(direction);
                    self.report(0, len, Shape::Frame(len, role), Some(true), on_event);
                    self.remove(len);
                }
                Verdict::Discard(bytes) => {
                    let early = bytes.min(self.ahead);
                    self.ahead = self.ahead.saturating_sub(early);
                    let len = bytes.saturating_sub(early).min(self.len);
                    self.discarded(len, on_event);
                    self.remove(len);
                }
            }
        }
    }

    /// Reports the first `len` held bytes, which the codec discarded: frames with a bad CRC,
    /// a frame cut short, noise.
    fn discarded(&mut self, len: usize, on_event: &mut impl FnMut(SniffEvent<'_>)) {
        let mut at = 0usize;
        while at < len {
            let run = self.raw.get(at..len).unwrap_or_default();
            let shape = self.shape(run);
            let n = match shape {
                Shape::Frame(n, _) => n.min(run.len()).max(1),
                Shape::Partial(_) | Shape::Noise => run.len(),
            };
            self.report(at, n, shape, None, on_event);
            at = at.saturating_add(n);
        }
    }

    /// What a run of discarded bytes starts with, by the PDU tables' length predictions.
    fn shape(&self, run: &[u8]) -> Shape {
        let (Some(&unit), Some(&fc), Some(body)) = (run.first(), run.get(1), run.get(2..)) else {
            return Shape::Noise;
        };
        // Only a public code tells a length: bytes that name another are noise.
        let code = FunctionCode::from_u8(fc & !FunctionCode::EXCEPTION_BIT);
        if !code.is_public() {
            return Shape::Noise;
        }
        let responds = self.pending.is_some_and(|p| p.unit == unit && p.function == code.value());
        let roles = match (fc & FunctionCode::EXCEPTION_BIT != 0, responds) {
            (true, _) => [Role::Response, Role::Response],
            (false, true) => [Role::Response, Role::Request],
            (false, false) => [Role::Request, Role::Response],
        };
        // A role whose length fits and whose PDU parses is the frame; failing that, a frame
        // cut short; failing that, a length that fits (a frame whose data is damaged too).
        let mut partial = None;
        let mut fits = None;
        for role in roles {
            let wire = match role {
                Role::Request => Request::wire_len(fc, body),
                Role::Response => Response::wire_len(fc, body),
            };
            match wire {
                WireLen::Known(n) | WireLen::Probable(n) => {
                    let total = n.saturating_add(MIN_ADU_LEN);
                    if total > MAX_ADU_LEN {
                        continue;
                    }
                    if total > run.len() {
                        partial = partial.or(Some(Some(total)));
                        continue;
                    }
                    let pdu = run.get(1..total.saturating_sub(2)).unwrap_or_default();
                    let parses = match role {
                        Role::Request => Request::parse(pdu).is_ok(),
                        Role::Response => Response::parse(pdu).is_ok(),
                    };
                    if parses {
                        return Shape::Frame(total, role);
                    }
                    fits = fits.or(Some(Shape::Frame(total, role)));
                }
                WireLen::NeedMore => partial = partial.or(Some(None)),
                WireLen::Unknown => {}
            }
        }
        partial.map(Shape::Partial).or(fits).unwrap_or(Shape::Noise)
    }

    /// Request or response, for a frame with a good CRC whose layout says `direction`.
    fn role(&self, direction: Direction) -> Role {
        match direction {
            Direction::Request => Role::Request,
            Direction::Response => Role::Response,
            Direction::Either => {
                let (unit, fc) = (self.raw.first().copied(), self.raw.get(1).copied());
                let responds = self.pending.is_some_and(|p| Some(p.unit) == unit && Some(p.function) == fc);
                if responds { Role::Response } else { Role::Request }
            }
        }
    }

    /// Where the held bytes `from..from + len` were on the wire.
    fn wire_time(&self, from: usize, len: usize) -> Option<WireTime> {
        let ends = self.ends.get(from..from.saturating_add(len))?;
        let (&first, &last) = (ends.first()?, ends.last()?);
        let char_time = self.timing.char_time();
        let start = first.saturating_sub(char_time);
        let longest_gap = ends
            .windows(2)
            .filter_map(|w| match *w {
                [a, b] => Some(b.saturating_duration_since(a).saturating_sub(char_time)),
                _ => None,
            })
            .max()
            .unwrap_or_default();
        let silence_before = self.last_end.map(|l| start.saturating_duration_since(l));
        Some(WireTime {
            start,
            end: last,
            silence_before,
            longest_gap,
            t3_5_violation: silence_before.is_some_and(|s| s < self.timing.t3_5()),
            t1_5_violation: longest_gap > self.timing.t1_5(),
        })
    }

    /// Reports the held bytes `from..from + len` as `shape` (a frame's CRC is checked unless
    /// `crc` says it), pairing requests and responses.
    fn report(
        &mut self,
        from: usize,
        len: usize,
        shape: Shape,
        crc: Option<bool>,
        on_event: &mut impl FnMut(SniffEvent<'_>),
    ) {
        let Some(time) = self.wire_time(from, len) else { return };
        self.last_end = Some(time.end);
        let Some(bytes) = self.raw.get(from..from.saturating_add(len)) else { return };
        let (role, kind) = match shape {
            Shape::Frame(_, role) => (role, None),
            Shape::Partial(expected) => (Role::Request, Some(FragmentKind::Partial { expected })),
            Shape::Noise => (Role::Request, Some(FragmentKind::Noise)),
        };
        if let Some(kind) = kind {
            on_event(SniffEvent::Fragment(Fragment { bytes, kind, time }));
            return;
        }
        let crc_ok = crc.unwrap_or_else(|| crc_ok(bytes));
        let (unit, fc) = (bytes.first().copied().unwrap_or_default(), bytes.get(1).copied().unwrap_or_default());
        let function = fc & !FunctionCode::EXCEPTION_BIT;
        let mut reply = None;
        match role {
            Role::Request => {
                if let Some(p) = self.pending.take().filter(|p| p.crc_ok) {
                    on_event(SniffEvent::Unanswered(Unanswered {
                        unit: p.unit,
                        function: p.function,
                        request_end: p.end,
                    }));
                }
                self.pending = (unit != unit::BROADCAST).then_some(Pending { unit, function, end: time.end, crc_ok });
            }
            Role::Response => {
                if let Some(p) = self.pending.filter(|p| p.unit == unit && p.function == function) {
                    self.pending = None;
                    reply =
                        Some(Reply { request_end: p.end, response_time: time.end.saturating_duration_since(p.end) });
                }
            }
        }
        on_event(SniffEvent::Frame(Frame { adu: bytes, role, crc_ok, time, reply }));
    }

    /// Forgets the first `n` held bytes.
    fn remove(&mut self, n: usize) {
        let n = n.min(self.len);
        self.raw.copy_within(n..self.len, 0);
        self.ends.copy_within(n..self.len, 0);
        self.len = self.len.saturating_sub(n);
    }
}

#[cfg(test)]
mod tests;
