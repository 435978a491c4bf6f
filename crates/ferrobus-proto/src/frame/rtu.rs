//! RTU framing: unit address, PDU, CRC-16 low byte first; at most 256 bytes.
//!
//! Spec: MODBUS over Serial Line V1.02 §2.5.1 (RTU transmission mode), §2.5.1.1 (framing:
//! t1.5 and t3.5) and §2.5.1.2 (CRC). Read them first.
//!
//! # How [`RtuCodec`] finds frames
//!
//! RTU has no length field and no start marker. The spec separates frames by 3.5 characters
//! of silence, but a PC rarely sees that silence: the OS and USB adapters deliver bytes in
//! bursts. So the receiver uses both, in this order:
//!
//! 1. **By length.** After each byte it asks the function code how long the frame is
//!    ([`Request::wire_len`], [`Response::wire_len`]): a read request is 8 bytes, a read
//!    response carries a byte count, and so on. When the bytes reach that length and the CRC
//!    agrees, the frame is complete — at once, without waiting for silence. Without knowing the
//!    direction it tries both layouts; the CRC tells which one fits, and the frame reports it
//!    as its [`Direction`].
//! 2. **By silence.** Where the code cannot tell (custom codes, 0x08 with long data), the
//!    frame ends at the t3.5 gap and is accepted if its CRC agrees.
//! 3. **Resync.** When every layout is ruled out (the CRC fails at the predicted length, the
//!    header is impossible, 256 bytes pass without a frame), the receiver drops one byte and
//!    looks for a frame starting at the next — so noise before a frame, or a frame cut short,
//!    costs only the bad bytes. At a gap, whatever is left is examined the same way and then
//!    dropped. Each run of dropped bytes is one [`RxEvent::Discarded`], counted in
//!    [`RxStats`]. Nothing here ends a session.
//! 4. **The silence has the last word.** A length field can itself be what is wrong: 0x10
//!    with a byte count that disagrees with its quantity is cut at the wrong length, and its
//!    CRC fails there. So when bytes from a clean start (after a frame or a gap) are dropped
//!    for a checksum error, the receiver remembers where they began (a frame cut short, one
//!    the gap ends before its length, gets no second chance). If no frame is found in them and, at the gap,
//!    the CRC agrees over the whole silence-delimited run, that run is the frame (not noise),
//!    with the direction whose length field it contradicts — and a slave answers it with
//!    exception 03, as over TCP, instead of staying silent on a "checksum error". A run that
//!    is exactly a frame of the other direction stays noise (a request is not a response with
//!    a bad byte count).
//!
//! Timestamps are per chunk: bytes that arrive together share one `now`, so gaps inside a
//! chunk are invisible. Strict t1.5 checking ([`RtuCodec::with_strict_t1_5`]) is off by
//! default for that reason; turn it on where timing is exact (the virtual line).

use core::time::Duration;

use super::{Adu, AduHeader, Direction, Expect, Framing, LineTiming, RxEvent, RxStats};
use crate::crc::{crc_ok, crc16_wire};
use crate::cursor::Writer;
use crate::error::{BufferTooSmall, DiscardReason};
use crate::pdu::{MAX_PDU_LEN, Request, Response, WireLen};
use crate::time::Instant;

/// The largest RTU frame: address, 253-byte PDU, CRC (§2.5.1).
pub const MAX_ADU_LEN: usize = 256;

/// The smallest RTU frame: address, function code, CRC.
pub const MIN_ADU_LEN: usize = 4;

/// Receive buffer: room for a whole frame behind a frame's worth of bytes being examined.
const BUF_LEN: usize = 2 * MAX_ADU_LEN;

/// Frames `pdu` for `unit`: address, PDU, CRC low byte first. Returns the frame length.
pub fn encode_pdu(unit: u8, pdu: &[u8], out: &mut [u8]) -> Result<usize, BufferTooSmall> {
    let needed = pdu.len().saturating_add(3);
    if out.len() < needed {
        return Err(BufferTooSmall { needed, available: out.len() });
    }
    let n = {
        let mut w = Writer::new(out);
        w.u8(unit)?;
        w.bytes(pdu)?;
        w.position()
    };
    let crc = crc16_wire(out.get(..n).unwrap_or_default());
    let mut w = Writer::new(out.get_mut(n..).unwrap_or_default());
    w.bytes(&crc)?;
    Ok(n.saturating_add(2))
}

/// Frames a request for `unit`. `out` needs [`MAX_ADU_LEN`] bytes at most.
pub fn encode_request(unit: u8, request: &Request<'_>, out: &mut [u8]) -> Result<usize, BufferTooSmall> {
    let mut pdu = [0u8; MAX_PDU_LEN];
    let n = request.emit(&mut pdu)?;
    encode_pdu(unit, pdu.get(..n).unwrap_or_default(), out)
}

/// Frames a response for `unit`. `out` needs [`MAX_ADU_LEN`] bytes at most.
pub fn encode_response(unit: u8, response: &Response<'_>, out: &mut [u8]) -> Result<usize, BufferTooSmall> {
    let mut pdu = [0u8; MAX_PDU_LEN];
    let n = response.emit(&mut pdu)?;
    encode_pdu(unit, pdu.get(..n).unwrap_or_default(), out)
}

/// A checked view of one complete RTU frame.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct RtuFrame<'a> {
    bytes: &'a [u8],
}

impl<'a> RtuFrame<'a> {
    /// Checks length (4–256 bytes) and CRC.
    pub fn new_checked(bytes: &'a [u8]) -> Result<Self, DiscardReason> {
        if bytes.len() < MIN_ADU_LEN {
            return Err(DiscardReason::TooShort);
        }
        if bytes.len() > MAX_ADU_LEN {
            return Err(DiscardReason::TooLong);
        }
        if !crc_ok(bytes) {
            return Err(DiscardReason::ChecksumMismatch);
        }
        Ok(RtuFrame { bytes })
    }

    /// The unit address.
    pub fn unit(&self) -> u8 {
        self.bytes.first().copied().unwrap_or_default()
    }

    /// The PDU, function code first.
    pub fn pdu(&self) -> &'a [u8] {
        self.bytes.get(1..self.bytes.len().saturating_sub(2)).unwrap_or_default()
    }

    /// The whole frame.
    pub fn as_bytes(&self) -> &'a [u8] {
        self.bytes
    }
}

/// Breaks the CRC of the whole RTU frame `frame` (for fault injection: a reply a master must
/// discard as a checksum error), leaving its unit and PDU as they are. Returns `false`, and
/// changes nothing, when `frame` is not a whole frame with a good CRC.
pub fn corrupt_crc(frame: &mut [u8]) -> bool {
    if RtuFrame::new_checked(frame).is_err() {
        return false;
    }
    // The CRC's high byte is last (§2.5.1.2); flipping bits in it changes the CRC alone.
    match frame.last_mut() {
        Some(high) => {
            *high ^= 0x5A;
            true
        }
        None => false,
    }
}

/// What the bytes from one candidate start say.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Verdict {
    /// A frame of this many bytes starts here.
    Complete(usize, Direction),
    /// It could still become a frame; `known` when some layout knows how long it will be.
    /// Nothing can be decided before `need` more bytes (at least one) have come.
    Wait { known: bool, need: usize },
    /// No frame starts here.
    Reject(DiscardReason),
}

/// A frame found and not yet consumed.
#[derive(Clone, Copy, Debug)]
struct Found {
    len: usize,
    direction: Direction,
    end: Instant,
    handed_out: bool,
}

/// A run of dropped bytes not yet reported.
#[derive(Clone, Copy, Debug)]
struct Noise {
    bytes: usize,
    reason: DiscardReason,
    at: Instant,
    /// The run's first two bytes.
    head: Option<(u8, u8)>,
}

/// The incremental RTU receiver and encoder. See the [module docs](self) for how it finds
/// frames.
#[derive(Clone, Debug)]
pub struct RtuCodec {
    timing: LineTiming,
    expect: Expect,
    strict_t1_5: bool,
    /// The silence that ends a frame of unknown length (t3.5 unless overridden).
    frame_gap: Duration,
    /// How long to wait for the rest of a frame of known length.
    incomplete_timeout: Duration,
    buf: [u8; BUF_LEN],
    /// Where the candidate frame starts.
    start: usize,
    /// End of the buffered bytes.
    len: usize,
    /// Whether `start` follows a frame or a gap, rather than dropped bytes: frames of unknown
    /// length are only accepted from a clean start.
    clean: bool,
    last_rx: Option<Instant>,
    found: Option<Found>,
    noise: Option<Noise>,
    report: Option<Noise>,
    /// Where the run of bytes being dropped began, when it began at a clean start: at the gap,
    /// the whole run may still be one frame whose length field is wrong (rule 4).
    silence_from: Option<usize>,
    stats: RxStats,
}

impl RtuCodec {
    /// A receiver for a line with `timing`, looking for `expect` frames.
    pub fn new(timing: LineTiming, expect: Expect) -> Self {
        RtuCodec {
            timing,
            expect,
            strict_t1_5: false,
            frame_gap: timing.t3_5(),
            incomplete_timeout: timing.t3_5(),
            buf: [0; BUF_LEN],
            start: 0,
            len: 0,
            clean: true,
            last_rx: None,
            found: None,
            noise: None,
            report: None,
            silence_from: None,
            stats: RxStats::default(),
        }
    }

    /// Discard a frame in progress when a gap longer than t1.5 interrupts it, as the spec
    /// says. Only sensible where byte timestamps are exact.
    #[must_use]
    pub fn with_strict_t1_5(mut self, strict: bool) -> Self {
        self.strict_t1_5 = strict;
        self
    }

    /// The silence that ends a frame whose length the function code cannot tell (t3.5 by
    /// default). A byte stream without a line under it — RTU carried over TCP, an unpaced
    /// pty — has no t3.5 ([`LineTiming::unpaced`]) but still needs a silence to end such
    /// frames; a few tens of milliseconds suit it.
    #[must_use]
    pub fn with_frame_gap(mut self, gap: Duration) -> Self {
        self.frame_gap = gap;
        self.incomplete_timeout = self.incomplete_timeout.max(gap);
        self
    }

    /// How long to wait for the rest of a frame whose length is already known before giving
    /// up on it (at least the frame gap, the default). A PC behind a USB adapter sees gaps of
    /// several milliseconds inside a frame; a longer wait keeps such frames whole, and costs
    /// nothing on noise, which is resynced past anyway.
    #[must_use]
    pub fn with_incomplete_timeout(mut self, timeout: Duration) -> Self {
        self.incomplete_timeout = timeout.max(self.frame_gap);
        self
    }

    /// The line timing.
    pub fn timing(&self) -> &LineTiming {
        &self.timing
    }

    fn candidate(&self) -> &[u8] {
        self.buf.get(self.start..self.len).unwrap_or_default()
    }

    fn has_pending(&self) -> bool {
        self.start < self.len || self.noise.is_some()
    }

    /// Consumes a frame handed out by `poll_event`.
    fn release(&mut self) {
        if let Some(found) = self.found
            && found.handed_out
        {
            self.start = self.start.saturating_add(found.len).min(self.len);
            self.clean = true;
            self.found = None;
        }
    }

    fn assess(&self, cand: &[u8], at_gap: bool) -> Verdict {
        let (Some(&fc), Some(body)) = (cand.get(1), cand.get(2..)) else {
            let need = 2usize.saturating_sub(cand.len()).max(1);
            return if at_gap {
                Verdict::Reject(DiscardReason::TooShort)
            } else {
                Verdict::Wait { known: false, need }
            };
        };
        let mut complete: Option<(usize, Direction)> = None;
        let mut wait = false;
        let mut known = false;
        // The fewest bytes after which some layout's verdict may change; past the largest frame
        // every layout is settled.
        let mut need = MAX_ADU_LEN.saturating_add(1).saturating_sub(cand.len()).max(1);
        let mut reason = DiscardReason::Noise;
        let roles = [
            (self.expect.requests() && fc != 0 && fc < 0x80, Direction::Request),
            (self.expect.responses() && fc != 0 && fc != 0x80, Direction::Response),
        ];
        for (possible, direction) in roles {
            if !possible {
                continue;
            }
            let wire = match direction {
                Direction::Request => Request::wire_len(fc, body),
                _ => Response::wire_len(fc, body),
            };
            let outcome = match wire {
                WireLen::Known(n) => {
                    let total = n.saturating_add(MIN_ADU_LEN);
                    if total > MAX_ADU_LEN {
                        Err(DiscardReason::TooLong)
                    } else if cand.len() < total {
                        if at_gap {
                            Err(DiscardReason::TooShort)
                        } else {
                            known = true;
                            need = need.min(total.saturating_sub(cand.len()));
                            Ok(None)
                        }
                    } else if cand.get(..total).is_some_and(crc_ok) {
                        Ok(Some(total))
                    } else {
                        Err(DiscardReason::ChecksumMismatch)
                    }
                }
                WireLen::NeedMore if at_gap => Err(DiscardReason::TooShort),
                WireLen::NeedMore if cand.len() >= MAX_ADU_LEN => Err(DiscardReason::TooLong),
                WireLen::NeedMore => {
                    known = true;
                    need = 1;
                    Ok(None)
                }
                WireLen::Probable(n) if cand.len() == n.saturating_add(MIN_ADU_LEN) && crc_ok(cand) => {
                    Ok(Some(cand.len()))
                }
                WireLen::Probable(_) | WireLen::Unknown if !at_gap && cand.len() <= MAX_ADU_LEN => {
                    // Only the silence can end it — but a probable length is worth a look.
                    if let WireLen::Probable(n) = wire {
                        let total = n.saturating_add(MIN_ADU_LEN);
                        if cand.len() < total {
                            need = need.min(total.saturating_sub(cand.len()));
                        }
                    }
                    Ok(None)
                }
                WireLen::Probable(_) | WireLen::Unknown => {
                    if cand.len() > MAX_ADU_LEN {
                        Err(DiscardReason::TooLong)
                    } else if self.clean && cand.len() >= MIN_ADU_LEN && crc_ok(cand) {
                        Ok(Some(cand.len()))
                    } else if cand.len() < MIN_ADU_LEN {
                        Err(DiscardReason::TooShort)
                    } else {
                        Err(DiscardReason::ChecksumMismatch)
                    }
                }
            };
            match outcome {
                Ok(Some(total)) => {
                    complete = Some(match complete {
                        Some((other, _)) if other == total => (total, Direction::Either),
                        Some((other, d)) if other < total => (other, d),
                        _ => (total, direction),
                    });
                }
                Ok(None) => wait = true,
                Err(r) => {
                    // The most telling reason wins: a checksum over a plausible length.
                    if reason == DiscardReason::Noise || r == DiscardReason::ChecksumMismatch {
                        reason = r;
                    }
                }
            }
        }
        match complete {
            Some((total, direction)) => Verdict::Complete(total, direction),
            None if wait => Verdict::Wait { known, need },
            None => Verdict::Reject(reason),
        }
    }

    /// Examines the buffered bytes: finds a frame, waits for more, or drops bytes until one
    /// of those. At a gap, nothing waits: every byte ends up in a frame or dropped.
    fn evaluate(&mut self, now: Instant, at_gap: bool) {
        while self.found.is_none() && self.start < self.len {
            match self.assess(self.candidate(), at_gap) {
                Verdict::Complete(len, direction) => {
                    if let Some(noise) = self.noise.take() {
                        self.report_noise(noise);
                    }
                    self.silence_from = None;
                    self.stats.frames = self.stats.frames.wrapping_add(1);
                    // A frame found at a gap ended with the last byte, not at the gap.
                    let end = if at_gap { self.last_rx.unwrap_or(now) } else { now };
                    self.found = Some(Found { len, direction, end, handed_out: false });
                }
                Verdict::Wait { .. } => return,
                Verdict::Reject(reason) => {
                    if reason == DiscardReason::ChecksumMismatch && self.clean && self.silence_from.is_none() {
                        self.silence_from = Some(self.start);
                    }
                    self.drop_bytes(1, reason, now);
                }
            }
        }
        if at_gap && self.found.is_none() {
            if let Some(from) = self.silence_from.take() {
                let run = self.buf.get(from..self.len).unwrap_or_default();
                if let Some(direction) = self.silence_frame(run) {
                    // The dropped bytes were this frame, not noise: nothing to report.
                    self.noise = None;
                    self.stats.frames = self.stats.frames.wrapping_add(1);
                    let end = self.last_rx.unwrap_or(now);
                    self.found = Some(Found { len: run.len(), direction, end, handed_out: false });
                    self.start = from;
                    return;
                }
            }
            if let Some(noise) = self.noise.take() {
                self.report_noise(noise);
            }
            self.start = 0;
            self.len = 0;
            self.clean = true;
        }
    }

    /// Whether `run`, a whole silence-delimited run from a clean start in which no frame was
    /// found, is one frame whose length field is wrong (rule 4), and if so in which direction.
    fn silence_frame(&self, run: &[u8]) -> Option<Direction> {
        if run.len() < MIN_ADU_LEN || run.len() > MAX_ADU_LEN || !crc_ok(run) {
            return None;
        }
        let (&fc, body) = (run.get(1)?, run.get(2..)?);
        let mut direction: Option<Direction> = None;
        let roles = [
            (self.expect.requests(), fc != 0 && fc < 0x80, Direction::Request),
            (self.expect.responses(), fc != 0 && fc != 0x80, Direction::Response),
        ];
        for (expected, possible, role) in roles {
            if !possible {
                continue;
            }
            let wire = match role {
                Direction::Request => Request::wire_len(fc, body),
                _ => Response::wire_len(fc, body),
            };
            if let WireLen::Known(n) = wire {
                if n.saturating_add(MIN_ADU_LEN) == run.len() {
                    // A well-formed frame of this layout: if it were expected it would have
                    // been found, so it is the other direction's, and noise here.
                    return None;
                }
                if expected {
                    direction = Some(match direction {
                        Some(_) => Direction::Either,
                        None => role,
                    });
                }
            }
        }
        direction
    }

    fn drop_bytes(&mut self, n: usize, reason: DiscardReason, at: Instant) {
        let n = n.min(self.len.saturating_sub(self.start));
        let head = match *self.candidate() {
            [unit, function, ..] => Some((unit, function)),
            _ => None,
        };
        self.start = self.start.saturating_add(n);
        self.clean = false;
        match &mut self.noise {
            Some(noise) => noise.bytes = noise.bytes.saturating_add(n),
            None => self.noise = Some(Noise { bytes: n, reason, at, head }),
        }
    }

    fn report_noise(&mut self, noise: Noise) {
        self.stats.count_discard(noise.bytes, noise.reason);
        self.report = Some(match self.report {
            // Two runs before anyone polled: report them as one.
            Some(prev) => Noise { bytes: prev.bytes.saturating_add(noise.bytes), ..prev },
            None => noise,
        });
    }

    /// Buffers as much of `data` as fits (all of it: a candidate never passes 257 bytes, nor
    /// a run), moving the candidate to the front first if needed. Returns how much.
    fn append(&mut self, data: &[u8]) -> usize {
        if self.silence_from.is_some_and(|from| self.len.saturating_add(data.len()).saturating_sub(from) > MAX_ADU_LEN)
        {
            // Longer than any frame: the run being dropped is noise whatever the gap says.
            self.silence_from = None;
        }
        if self.len.saturating_add(data.len()) > BUF_LEN {
            // Keep the run being dropped (at most one frame) with the candidate.
            let from = self.silence_from.map_or(self.start, |from| from.min(self.start));
            self.buf.copy_within(from..self.len, 0);
            self.len = self.len.saturating_sub(from);
            self.start = self.start.saturating_sub(from);
            self.silence_from = self.silence_from.map(|f| f.saturating_sub(from));
        }
        let n = data.len().min(BUF_LEN.saturating_sub(self.len));
        let (Some(dst), Some(src)) = (self.buf.get_mut(self.len..self.len.saturating_add(n)), data.get(..n)) else {
            return 0;
        };
        dst.copy_from_slice(src);
        self.len = self.len.saturating_add(n);
        n
    }

    /// How many more bytes the candidate needs before its verdict can change.
    fn need(&self) -> usize {
        match self.assess(self.candidate(), false) {
            Verdict::Wait { need, .. } => need,
            _ => 1,
        }
    }

    /// The instant the current partial frame or noise run is settled by silence.
    fn gap_deadline(&self) -> Option<Instant> {
        if !self.has_pending() || self.found.is_some() {
            return None;
        }
        let last = self.last_rx?;
        let known = matches!(self.assess(self.candidate(), false), Verdict::Wait { known: true, .. });
        let wait = if known { self.incomplete_timeout } else { self.frame_gap };
        Some(last.saturating_add(wait))
    }
}

impl Framing for RtuCodec {
    fn encode(&self, header: AduHeader, pdu: &[u8], out: &mut [u8]) -> Result<usize, BufferTooSmall> {
        encode_pdu(header.unit, pdu, out)
    }

    fn push(&mut self, now: Instant, bytes: &[u8]) -> usize {
        self.release();
        if self.found.is_some() {
            return 0;
        }
        if self.gap_deadline().is_some_and(|deadline| now >= deadline) {
            self.evaluate(now, true);
            if self.found.is_some() {
                return 0;
            }
        }
        if bytes.is_empty() {
            self.evaluate(now, false);
            return 0;
        }
        if self.strict_t1_5
            && self.start < self.len
            && let Some(last) = self.last_rx
            && now.saturating_duration_since(last) > self.timing.t1_5()
        {
            self.silence_from = None;
            let n = self.len.saturating_sub(self.start);
            self.drop_bytes(n, DiscardReason::InterCharacterGap, now);
        }
        self.last_rx = Some(now);
        let mut consumed = 0usize;
        // Take bytes in runs up to the next point where a verdict can change (a predicted
        // length, say): the same frames as byte by byte, at one evaluation per run.
        while self.found.is_none() {
            let rest = bytes.get(consumed..).unwrap_or_default();
            if rest.is_empty() {
                break;
            }
            let run = rest.get(..self.need().min(rest.len())).unwrap_or_default();
            let taken = self.append(run);
            if taken == 0 {
                break;
            }
            consumed = consumed.saturating_add(taken);
            self.evaluate(now, false);
        }
        consumed
    }

    fn poll_event(&mut self) -> Option<RxEvent<'_>> {
        if let Some(noise) = self.report.take() {
            return Some(RxEvent::Discarded {
                bytes: noise.bytes,
                reason: noise.reason,
                at: noise.at,
                head: noise.head,
            });
        }
        let found = self.found.as_mut().filter(|f| !f.handed_out)?;
        found.handed_out = true;
        let found = *found;
        let frame = self.buf.get(self.start..self.start.saturating_add(found.len))?;
        let (&unit, rest) = frame.split_first()?;
        let pdu = rest.get(..rest.len().saturating_sub(2))?;
        Some(RxEvent::Frame(Adu { header: AduHeader::unit(unit), pdu, end: found.end, direction: found.direction }))
    }

    fn poll_timeout(&self) -> Option<Instant> {
        self.gap_deadline()
    }

    fn handle_timeout(&mut self, now: Instant) {
        self.release();
        if self.gap_deadline().is_some_and(|deadline| now >= deadline) {
            self.evaluate(now, true);
        }
    }

    fn inter_frame_gap(&self) -> Duration {
        self.timing.t3_5()
    }

    fn transmit_time(&self, n: usize) -> Duration {
        self.timing.transmit_time(n)
    }

    fn reset(&mut self) {
        self.start = 0;
        self.len = 0;
        self.clean = true;
        self.found = None;
        self.noise = None;
        self.report = None;
        self.silence_from = None;
    }

    fn stats(&self) -> RxStats {
        self.stats
    }
}

#[cfg(test)]
mod tests;
