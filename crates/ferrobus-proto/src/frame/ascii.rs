//! ASCII framing: `:`, the unit, PDU and LRC as pairs of hex digits, CR LF.
//!
//! Spec: MODBUS over Serial Line V1.02 §2.5.2 (ASCII transmission mode) and §6.2.1 (LRC).
//! The LRC is the two's complement of the 8-bit sum of the binary bytes, so the sum of the
//! bytes and their LRC is zero. A frame starts at `:` wherever it appears: a `:` inside a
//! frame abandons it and starts a new one (the spec's resync rule). The line feed that ends a
//! received frame can be changed with 0x08/0x03 ("Change ASCII *Input* Delimiter"); the
//! character before it must be CR. Frames we send always end in CR LF.
//!
//! An ASCII frame carries at most 513 characters: `:`, 2 × (1 + 253 + 1) hex digits, CR LF.
//! Silence longer than the inter-character timeout (one second by default, as the spec
//! suggests) abandons a frame in progress.

use core::time::Duration;

use super::{Adu, AduHeader, Direction, Framing, LineTiming, RxEvent, RxStats};
use crate::cursor::Writer;
use crate::error::{BufferTooSmall, DiscardReason};
use crate::pdu::MAX_PDU_LEN;
use crate::time::Instant;

/// The largest ASCII frame in characters.
pub const MAX_FRAME_CHARS: usize = 1 + 2 * (1 + MAX_PDU_LEN + 1) + 2;

/// The default end-of-frame character (LF).
pub const DEFAULT_DELIMITER: u8 = b'\n';

/// The default inter-character timeout (§2.5.2.1: "up to one second").
pub const DEFAULT_CHAR_TIMEOUT: Duration = Duration::from_secs(1);

const START: u8 = b':';
const CR: u8 = b'\r';
const HEX: &[u8; 16] = b"0123456789ABCDEF";

/// The LRC of `data`: the two's complement of its 8-bit sum.
///
/// ```
/// use ferrobus_proto::frame::ascii::lrc;
/// // Delta ASDA-A2 manual 9-13: the SDP/ASDA write example has LRC 0x13.
/// assert_eq!(lrc(&[0x01, 0x10, 0x01, 0x12, 0x00, 0x02, 0x04, 0x0B, 0xB8, 0x00, 0x00]), 0x13);
/// ```
pub fn lrc(data: &[u8]) -> u8 {
    data.iter().fold(0u8, |sum, &b| sum.wrapping_add(b)).wrapping_neg()
}

/// Breaks the LRC of the whole ASCII frame `frame` (`:` … LRC CR LF; for fault injection: a
/// reply a master must discard as a checksum error), leaving its unit and PDU as they are.
/// The LRC's high digit becomes another hex digit, so the frame still reads as hex. Returns
/// `false`, and changes nothing, when `frame` does not have that shape.
pub fn corrupt_lrc(frame: &mut [u8]) -> bool {
    // `:`, unit, function code and LRC as hex pairs, CR LF.
    const MIN_FRAME_CHARS: usize = 1 + 2 * 3 + 2;
    if frame.len() < MIN_FRAME_CHARS || frame.first() != Some(&START) || !frame.ends_with(&[CR, DEFAULT_DELIMITER]) {
        return false;
    }
    let Some(high) = frame.len().checked_sub(4).and_then(|i| frame.get_mut(i)) else { return false };
    if hex_value(*high).is_none() {
        return false;
    }
    *high = if *high == b'0' { b'1' } else { b'0' };
    true
}

fn hex_value(c: u8) -> Option<u8> {
    match c {
        b'0'..=b'9' => Some(c.wrapping_sub(b'0')),
        b'A'..=b'F' => Some(c.wrapping_sub(b'A').wrapping_add(10)),
        // The spec says upper case; accept lower case on receive, as most devices do.
        b'a'..=b'f' => Some(c.wrapping_sub(b'a').wrapping_add(10)),
        _ => None,
    }
}

fn put_hex(w: &mut Writer<'_>, byte: u8) -> Result<(), BufferTooSmall> {
    let hi = HEX.get(usize::from(byte >> 4)).copied().unwrap_or(b'0');
    let lo = HEX.get(usize::from(byte & 0x0F)).copied().unwrap_or(b'0');
    w.bytes(&[hi, lo])
}

/// Frames `pdu` for `unit` in ASCII. `out` needs
/// [`MAX_FRAME_CHARS`] bytes at most.
pub fn encode_pdu(unit: u8, pdu: &[u8], out: &mut [u8]) -> Result<usize, BufferTooSmall> {
    let mut w = Writer::new(out);
    w.u8(START)?;
    put_hex(&mut w, unit)?;
    for &b in pdu {
        put_hex(&mut w, b)?;
    }
    let sum = pdu.iter().fold(unit, |s, &b| s.wrapping_add(b));
    put_hex(&mut w, sum.wrapping_neg())?;
    w.bytes(&[CR, DEFAULT_DELIMITER])?;
    Ok(w.position())
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum State {
    /// Waiting for `:`, counting what is skipped.
    Idle,
    /// Inside a frame: the binary bytes decoded so far, maybe half a byte.
    Frame,
}

/// A run of discarded characters not yet reported.
#[derive(Clone, Copy, Debug)]
struct Discard {
    bytes: usize,
    reason: DiscardReason,
    at: Instant,
    /// The address and function code of the frame they began, if they did.
    head: Option<(u8, u8)>,
}

/// The incremental ASCII receiver and encoder.
#[derive(Clone, Debug)]
pub struct AsciiCodec {
    timing: LineTiming,
    char_timeout: Duration,
    delimiter: u8,
    state: State,
    /// Decoded bytes: unit, PDU, LRC.
    buf: [u8; MAX_PDU_LEN + 2],
    len: usize,
    high_nibble: Option<u8>,
    saw_cr: bool,
    chars: usize,
    bad_encoding: bool,
    skipped: usize,
    last_rx: Option<Instant>,
    found: Option<(Instant, bool)>,
    report: Option<Discard>,
    stats: RxStats,
}

impl AsciiCodec {
    /// A receiver for a line with `timing` (its character time paces our transmissions).
    pub fn new(timing: LineTiming) -> Self {
        AsciiCodec {
            timing,
            char_timeout: DEFAULT_CHAR_TIMEOUT,
            delimiter: DEFAULT_DELIMITER,
            state: State::Idle,
            buf: [0; MAX_PDU_LEN + 2],
            len: 0,
            high_nibble: None,
            saw_cr: false,
            chars: 0,
            bad_encoding: false,
            skipped: 0,
            last_rx: None,
            found: None,
            report: None,
            stats: RxStats::default(),
        }
    }

    /// The same receiver with another inter-character timeout.
    #[must_use]
    pub fn with_char_timeout(mut self, timeout: Duration) -> Self {
        self.char_timeout = timeout;
        self
    }

    fn discard(&mut self, bytes: usize, reason: DiscardReason, at: Instant, head: Option<(u8, u8)>) {
        if bytes == 0 {
            return;
        }
        self.stats.count_discard(bytes, reason);
        self.report = Some(match self.report {
            Some(prev) => Discard { bytes: prev.bytes.saturating_add(bytes), ..prev },
            None => Discard { bytes, reason, at, head },
        });
    }

    /// The address and function code decoded so far in the current frame.
    fn head(&self) -> Option<(u8, u8)> {
        match *self.buf.get(..self.len).unwrap_or_default() {
            [unit, function, ..] => Some((unit, function)),
            _ => None,
        }
    }

    fn start_frame(&mut self) {
        self.state = State::Frame;
        self.len = 0;
        self.high_nibble = None;
        self.saw_cr = false;
        self.chars = 1;
        self.bad_encoding = false;
    }

    fn abandon_frame(&mut self, reason: DiscardReason, at: Instant) {
        if self.state == State::Frame {
            self.discard(self.chars, reason, at, self.head());
        }
        self.state = State::Idle;
    }

    fn flush_skipped(&mut self, at: Instant) {
        let skipped = core::mem::take(&mut self.skipped);
        self.discard(skipped, DiscardReason::Noise, at, None);
    }

    /// Takes one character; returns whether a frame is complete.
    fn take(&mut self, c: u8, now: Instant) -> bool {
        if c == START {
            self.flush_skipped(now);
            self.abandon_frame(DiscardReason::TooShort, now);
            self.start_frame();
            return false;
        }
        if self.state == State::Idle {
            self.skipped = self.skipped.saturating_add(1);
            return false;
        }
        self.chars = self.chars.saturating_add(1);
        if self.chars > MAX_FRAME_CHARS {
            self.abandon_frame(DiscardReason::TooLong, now);
            return false;
        }
        if self.saw_cr && c == self.delimiter {
            return self.finish_frame(now);
        }
        if c == CR {
            self.saw_cr = true;
            return false;
        }
        if self.saw_cr {
            // CR must be followed by the delimiter.
            self.bad_encoding = true;
            self.saw_cr = false;
        }
        match (hex_value(c), self.high_nibble) {
            (None, _) => self.bad_encoding = true,
            (Some(hi), None) => self.high_nibble = Some(hi),
            (Some(lo), Some(hi)) => {
                self.high_nibble = None;
                match self.buf.get_mut(self.len) {
                    Some(slot) => {
                        *slot = (hi << 4) | lo;
                        self.len = self.len.saturating_add(1);
                    }
                    None => self.bad_encoding = true,
                }
            }
        }
        false
    }

    fn finish_frame(&mut self, now: Instant) -> bool {
        self.state = State::Idle;
        let data = self.buf.get(..self.len).unwrap_or_default();
        let reason = if self.bad_encoding || self.high_nibble.is_some() {
            Some(DiscardReason::BadEncoding)
        } else if self.len < 3 {
            Some(DiscardReason::TooShort)
        } else if data.iter().fold(0u8, |s, &b| s.wrapping_add(b)) != 0 && !cfg!(fuzzing) {
            Some(DiscardReason::ChecksumMismatch)
        } else {
            None
        };
        if let Some(reason) = reason {
            self.discard(self.chars, reason, now, self.head());
            return false;
        }
        self.stats.frames = self.stats.frames.wrapping_add(1);
        self.found = Some((now, false));
        true
    }
}

impl Framing for AsciiCodec {
    fn encode(&self, header: AduHeader, pdu: &[u8], out: &mut [u8]) -> Result<usize, BufferTooSmall> {
        encode_pdu(header.unit, pdu, out)
    }

    fn push(&mut self, now: Instant, bytes: &[u8]) -> usize {
        if self.found.is_some_and(|(_, handed_out)| handed_out) {
            self.found = None;
        }
        if self.found.is_some() || self.report.is_some() {
            return 0;
        }
        if self.poll_timeout().is_some_and(|deadline| now >= deadline) {
            self.handle_timeout(now);
        }
        if !bytes.is_empty() {
            self.last_rx = Some(now);
        }
        let mut consumed = 0usize;
        for &c in bytes {
            consumed = consumed.saturating_add(1);
            // Stop at every event, so that each is polled before the next one happens.
            if self.take(c, now) || self.report.is_some() {
                break;
            }
        }
        consumed
    }

    fn poll_event(&mut self) -> Option<RxEvent<'_>> {
        if let Some(Discard { bytes, reason, at, head }) = self.report.take() {
            return Some(RxEvent::Discarded { bytes, reason, at, head });
        }
        let (end, handed_out) = self.found.as_mut()?;
        if *handed_out {
            return None;
        }
        *handed_out = true;
        let end = *end;
        let data = self.buf.get(..self.len)?;
        let (&unit, rest) = data.split_first()?;
        let pdu = rest.get(..rest.len().saturating_sub(1))?;
        Some(RxEvent::Frame(Adu { header: AduHeader::unit(unit), pdu, end, direction: Direction::Either }))
    }

    fn poll_timeout(&self) -> Option<Instant> {
        if self.state == State::Idle && self.skipped == 0 {
            return None;
        }
        Some(self.last_rx?.saturating_add(self.char_timeout))
    }

    fn handle_timeout(&mut self, now: Instant) {
        if self.poll_timeout().is_some_and(|deadline| now >= deadline) {
            self.flush_skipped(now);
            self.abandon_frame(DiscardReason::TooShort, now);
        }
    }

    fn inter_frame_gap(&self) -> Duration {
        Duration::ZERO
    }

    fn transmit_time(&self, n: usize) -> Duration {
        self.timing.transmit_time(n)
    }

    fn reset(&mut self) {
        self.state = State::Idle;
        self.skipped = 0;
        self.found = None;
        self.report = None;
    }

    fn stats(&self) -> RxStats {
        self.stats
    }

    fn set_delimiter(&mut self, delimiter: u8) {
        self.delimiter = delimiter;
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::vec::Vec;

    use super::*;
    use crate::frame::{LineConfig, feed};

    fn codec() -> AsciiCodec {
        AsciiCodec::new(LineTiming::new(&LineConfig::default()))
    }

    /// Feeds `input` in chunks of `chunk` bytes and returns (frames as unit + PDU, discards).
    fn run(codec: &mut AsciiCodec, input: &[u8], chunk: usize) -> (Vec<Vec<u8>>, Vec<(usize, DiscardReason)>) {
        let mut frames = Vec::new();
        let mut discards = Vec::new();
        for piece in input.chunks(chunk) {
            feed(codec, Instant::ZERO, piece, |ev| match ev {
                RxEvent::Frame(adu) => {
                    let mut f = std::vec![adu.header.unit];
                    f.extend_from_slice(adu.pdu);
                    frames.push(f);
                }
                RxEvent::Discarded { bytes, reason, .. } => discards.push((bytes, reason)),
            });
        }
        (frames, discards)
    }

    #[test]
    fn a_corrupted_lrc_is_discarded_as_a_checksum_mismatch_with_unit_and_pdu_kept() {
        for good in [&b":010302000002F8\r\n"[..], b":011001120002040BB8000013\r\n"] {
            assert_eq!(run(&mut codec(), good, good.len()).0.len(), 1, "the good frame is read");
            let mut frame = good.to_vec();
            assert!(corrupt_lrc(&mut frame));
            assert_eq!(frame[..frame.len() - 4], good[..good.len() - 4]);
            assert_ne!(frame, good);
            let (frames, discards) = run(&mut codec(), &frame, frame.len());
            assert!(frames.is_empty());
            assert_eq!(discards, [(frame.len(), DiscardReason::ChecksumMismatch)]);
        }
        for not_a_frame in [&b"010302000002F8\r\n"[..], b":010302000002F8", b":01\r\n", b":0103020000G8\r\n", b""] {
            let mut bytes = not_a_frame.to_vec();
            assert!(!corrupt_lrc(&mut bytes));
            assert_eq!(bytes, not_a_frame);
        }
    }

    #[test]
    fn reference_lrc_vectors() {
        // shared/reference/modbus-and-drives.md §1.8 (Delta ASDA-A2 pp. 9-10, 9-13).
        assert_eq!(lrc(&[0x01, 0x03, 0x02, 0x00, 0x00, 0x02]), 0xF8);
        assert_eq!(lrc(&[0x01, 0x10, 0x01, 0x12, 0x00, 0x02, 0x04, 0x0B, 0xB8, 0x00, 0x00]), 0x13);
        assert_eq!(lrc(&[0x01, 0x10, 0x01, 0x12, 0x00, 0x02]), 0xDA);
        assert_eq!(lrc(&[0x01, 0x03, 0x04, 0x00, 0xB1, 0x1F, 0x40]), 0xE8);
    }

    #[test]
    fn encodes_the_sdp_write_example() {
        let mut out = [0xA5u8; MAX_FRAME_CHARS];
        let n = encode_pdu(0x01, &[0x10, 0x01, 0x12, 0x00, 0x02, 0x04, 0x0B, 0xB8, 0x00, 0x00], &mut out).unwrap();
        assert_eq!(&out[..n], b":011001120002040BB8000013\r\n");
        assert_eq!(out[n], 0xA5, "nothing written past the frame");
    }

    #[test]
    fn decodes_whole_byte_by_byte_and_two_in_one_chunk() {
        let one: &[u8] = b":010300000002FA\r\n";
        let mut two = one.to_vec();
        two.extend_from_slice(b":0110011200020A\r\n".as_slice());
        let expected = std::vec![0x01, 0x03, 0x00, 0x00, 0x00, 0x02];
        for chunk in [one.len(), 1] {
            let (frames, discards) = run(&mut codec(), one, chunk);
            assert_eq!(frames, core::slice::from_ref(&expected));
            assert!(discards.is_empty());
        }
        // The second frame has a bad LRC (0A instead of DA).
        let (frames, discards) = run(&mut codec(), &two, two.len());
        assert_eq!(frames, [expected]);
        assert_eq!(discards, [(17, DiscardReason::ChecksumMismatch)]);
    }

    #[test]
    fn a_colon_restarts_and_noise_outside_frames_is_counted() {
        let input = b"xx:0103\r:010300000002FA\r\n";
        let mut c = codec();
        let (frames, discards) = run(&mut c, input, 3);
        assert_eq!(frames.len(), 1);
        assert_eq!(discards, [(2, DiscardReason::Noise), (6, DiscardReason::TooShort)]);
        assert_eq!(c.stats().frames, 1);
        assert_eq!(c.stats().discarded_bytes, 8);
    }

    #[test]
    fn bad_hex_lower_case_and_changed_delimiter() {
        let (frames, discards) = run(&mut codec(), b":01G300000002FA\r\n", 64);
        assert!(frames.is_empty());
        assert_eq!(discards, [(17, DiscardReason::BadEncoding)]);
        let (frames, _) = run(&mut codec(), b":010300000002fa\r\n", 64);
        assert_eq!(frames.len(), 1);
        let mut c = codec();
        c.set_delimiter(b'!');
        let (frames, _) = run(&mut c, b":010300000002FA\r!", 64);
        assert_eq!(frames.len(), 1);
    }

    #[test]
    fn silence_abandons_a_frame_after_the_char_timeout() {
        let mut c = codec().with_char_timeout(Duration::from_millis(5));
        feed(&mut c, Instant::ZERO, b":0103", |_| panic!("no event yet"));
        assert_eq!(c.poll_timeout(), Some(Instant::from_millis(5)));
        c.handle_timeout(Instant::from_millis(5));
        assert_eq!(
            c.poll_event(),
            Some(RxEvent::Discarded {
                bytes: 5,
                reason: DiscardReason::TooShort,
                at: Instant::from_millis(5),
                head: Some((0x01, 0x03))
            })
        );
        assert_eq!(c.poll_timeout(), None);
    }

    #[test]
    fn an_overlong_frame_is_dropped_and_the_next_one_found() {
        let mut input = std::vec![b':'];
        input.extend(core::iter::repeat_n(b'0', MAX_FRAME_CHARS));
        input.extend_from_slice(b":010300000002FA\r\n");
        let (frames, discards) = run(&mut codec(), &input, 100);
        assert_eq!(frames.len(), 1);
        assert_eq!(discards[0].1, DiscardReason::TooLong);
    }
}
