//! Modbus/TCP framing: the 7-byte MBAP header, then the PDU; at most 260 bytes.
//!
//! Spec: MODBUS Messaging on TCP/IP Implementation Guide V1.0b §3.1.3. The header is, big
//! endian: transaction identifier (2 bytes, echoed by the server), protocol identifier (2,
//! always 0), length (2: the bytes that follow, unit identifier included), unit identifier
//! (1). There is no checksum; TCP carries one.
//!
//! A stream that breaks this layout (a protocol id other than 0, a length outside 2..=254)
//! has lost its framing, and a TCP stream has no silent interval to find it again by. The
//! receiver reports the bad header as a [`DiscardReason::BadHeader`] discard, then either
//! looks for a plausible header one byte further on ([`MbapCodec::new`], for a sniffer or a
//! client that will not act on a guess), or, made by [`MbapCodec::strict`] (a server),
//! discards everything after it until [`Framing::reset`]: a request hidden behind a corrupt
//! header is never executed, and the IO layer closes the connection.

use core::time::Duration;

use super::{Adu, AduHeader, Direction, Framing, RxEvent, RxStats};
use crate::cursor::Writer;
use crate::error::{BufferTooSmall, DiscardReason};
use crate::pdu::MAX_PDU_LEN;
use crate::time::Instant;

/// Bytes in the MBAP header, unit identifier included.
pub const HEADER_LEN: usize = 7;

/// The largest Modbus/TCP ADU.
pub const MAX_ADU_LEN: usize = HEADER_LEN + MAX_PDU_LEN;

/// The protocol identifier of Modbus.
pub const PROTOCOL_ID: u16 = 0;

/// The default Modbus/TCP port.
pub const DEFAULT_PORT: u16 = 502;

/// Frames `pdu` with an MBAP header. Returns the frame length.
pub fn encode_pdu(header: AduHeader, pdu: &[u8], out: &mut [u8]) -> Result<usize, BufferTooSmall> {
    let length = u16::try_from(pdu.len().saturating_add(1)).unwrap_or(u16::MAX);
    let mut w = Writer::new(out);
    w.u16(header.transaction)?;
    w.u16(PROTOCOL_ID)?;
    w.u16(length)?;
    w.u8(header.unit)?;
    w.bytes(pdu)?;
    Ok(w.position())
}

/// Checks an MBAP header and returns it with the length of the PDU that follows.
pub fn parse_header(header: &[u8; HEADER_LEN]) -> Result<(AduHeader, usize), DiscardReason> {
    let [t0, t1, p0, p1, l0, l1, unit] = *header;
    let length = usize::from(u16::from_be_bytes([l0, l1]));
    if u16::from_be_bytes([p0, p1]) != PROTOCOL_ID || !(2..=MAX_PDU_LEN + 1).contains(&length) {
        return Err(DiscardReason::BadHeader);
    }
    let transaction = u16::from_be_bytes([t0, t1]);
    Ok((AduHeader { unit, transaction }, length.saturating_sub(1)))
}

/// The incremental MBAP receiver and encoder.
#[derive(Clone, Debug)]
pub struct MbapCodec {
    buf: [u8; MAX_ADU_LEN],
    len: usize,
    /// A frame of this many bytes sits at the front of `buf`; `true` once handed out.
    found: Option<(usize, AduHeader, Instant, bool)>,
    bad: Option<(usize, Instant)>,
    report: Option<(usize, Instant)>,
    stats: RxStats,
    /// Whether a bad header ends the stream's framing ([`MbapCodec::strict`]).
    strict: bool,
    /// A strict receiver has seen a bad header: every byte is discarded until reset.
    lost: bool,
}

impl MbapCodec {
    /// A fresh receiver.
    pub fn new() -> Self {
        MbapCodec {
            buf: [0; MAX_ADU_LEN],
            len: 0,
            found: None,
            bad: None,
            report: None,
            stats: RxStats::default(),
            strict: false,
            lost: false,
        }
    }

    /// A receiver for which a bad header ends the framing: it and every byte after it are
    /// discarded (reported as [`DiscardReason::BadHeader`]) until [`Framing::reset`].
    pub fn strict() -> Self {
        MbapCodec { strict: true, ..MbapCodec::new() }
    }

    /// Whether a bad header has ended this strict receiver's framing.
    pub fn is_lost(&self) -> bool {
        self.lost
    }

    /// Throws away `n` bytes as part of the current run of bad ones.
    fn discard(&mut self, n: usize, now: Instant) {
        if n == 0 {
            return;
        }
        let bad = self.bad.get_or_insert((0, now));
        bad.0 = bad.0.saturating_add(n);
    }

    fn release(&mut self) {
        if let Some((n, _, _, true)) = self.found {
            self.shift(n);
            self.found = None;
        }
    }

    fn shift(&mut self, n: usize) {
        let n = n.min(self.len);
        self.buf.copy_within(n..self.len, 0);
        self.len = self.len.saturating_sub(n);
    }

    fn flush_bad(&mut self) {
        if let Some((bytes, at)) = self.bad.take() {
            self.stats.count_discard(bytes, DiscardReason::BadHeader);
            self.report = Some((bytes, at));
        }
    }

    /// Looks for a frame at the front of the buffer, dropping bytes that cannot start one.
    fn evaluate(&mut self, now: Instant) {
        while self.found.is_none() {
            let Some(header) = self.buf.first_chunk::<HEADER_LEN>().filter(|_| self.len >= HEADER_LEN) else {
                return;
            };
            let Ok((adu, pdu_len)) = parse_header(header) else {
                if self.strict {
                    self.lost = true;
                    let n = self.len;
                    self.len = 0;
                    self.discard(n, now);
                    return;
                }
                self.shift(1);
                self.discard(1, now);
                continue;
            };
            let total = HEADER_LEN.saturating_add(pdu_len);
            if self.len >= total {
                self.flush_bad();
                self.stats.frames = self.stats.frames.wrapping_add(1);
                self.found = Some((total, adu, now, false));
            }
            return;
        }
    }
}

impl Default for MbapCodec {
    fn default() -> Self {
        Self::new()
    }
}

impl Framing for MbapCodec {
    fn encode(&self, header: AduHeader, pdu: &[u8], out: &mut [u8]) -> Result<usize, BufferTooSmall> {
        encode_pdu(header, pdu, out)
    }

    fn push(&mut self, now: Instant, bytes: &[u8]) -> usize {
        self.release();
        if self.lost {
            self.discard(bytes.len(), now);
            self.flush_bad();
            return bytes.len();
        }
        let mut consumed = 0usize;
        loop {
            self.evaluate(now);
            let rest = bytes.get(consumed..).unwrap_or_default();
            if self.found.is_some() {
                return consumed;
            }
            if self.lost {
                self.discard(rest.len(), now);
                self.flush_bad();
                return bytes.len();
            }
            if rest.is_empty() {
                // Report a run of bad bytes now, not when a good frame finally comes: a stream
                // that has lost its framing must show it.
                self.flush_bad();
                return consumed;
            }
            // Without a frame at the front, `evaluate` leaves less than a full frame buffered.
            let take = MAX_ADU_LEN.saturating_sub(self.len).min(rest.len());
            let (Some(dst), Some(src)) = (self.buf.get_mut(self.len..self.len.saturating_add(take)), rest.get(..take))
            else {
                return consumed;
            };
            dst.copy_from_slice(src);
            self.len = self.len.saturating_add(take);
            consumed = consumed.saturating_add(take);
        }
    }

    fn poll_event(&mut self) -> Option<RxEvent<'_>> {
        if let Some((bytes, at)) = self.report.take() {
            return Some(RxEvent::Discarded { bytes, reason: DiscardReason::BadHeader, at, head: None });
        }
        let (total, header, end, handed_out) = self.found.as_mut()?;
        if *handed_out {
            return None;
        }
        *handed_out = true;
        let pdu = self.buf.get(HEADER_LEN..*total)?;
        Some(RxEvent::Frame(Adu { header: *header, pdu, end: *end, direction: Direction::Either }))
    }

    fn poll_timeout(&self) -> Option<Instant> {
        None
    }

    fn handle_timeout(&mut self, _now: Instant) {}

    fn inter_frame_gap(&self) -> Duration {
        Duration::ZERO
    }

    fn transmit_time(&self, _n: usize) -> Duration {
        Duration::ZERO
    }

    fn reset(&mut self) {
        self.len = 0;
        self.found = None;
        self.bad = None;
        self.report = None;
        self.lost = false;
    }

    fn stats(&self) -> RxStats {
        self.stats
    }

    fn supports_broadcast(&self) -> bool {
        false
    }

    fn is_mid_frame(&self) -> bool {
        let held = match self.found {
            Some((n, _, _, true)) => self.len.saturating_sub(n),
            Some(_) => 0,
            None => self.len,
        };
        held > 0 && !self.lost
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::vec::Vec;

    use super::*;
    use crate::frame::feed;

    fn run(codec: &mut MbapCodec, input: &[u8], chunk: usize) -> (Vec<(AduHeader, Vec<u8>)>, Vec<usize>) {
        let mut frames = Vec::new();
        let mut bad = Vec::new();
        for piece in input.chunks(chunk.max(1)) {
            feed(codec, Instant::ZERO, piece, |ev| match ev {
                RxEvent::Frame(adu) => frames.push((adu.header, adu.pdu.to_vec())),
                RxEvent::Discarded { bytes, .. } => bad.push(bytes),
            });
        }
        (frames, bad)
    }

    /// Read holding registers 0x006B × 3 from unit 0x11, transaction 0x0001.
    const REQUEST: &[u8] = &[
        0x00, 0x01, // transaction id
        0x00, 0x00, // protocol id
        0x00, 0x06, // length: unit + 5 PDU bytes
        0x11, // unit id
        0x03, 0x00, 0x6B, 0x00, 0x03, // PDU
    ];

    #[test]
    fn encodes_a_golden_request() {
        let mut out = [0xA5u8; 16];
        let n = encode_pdu(AduHeader { unit: 0x11, transaction: 1 }, &REQUEST[7..], &mut out).unwrap();
        assert_eq!(&out[..n], REQUEST);
        assert_eq!(out[n], 0xA5);
    }

    #[test]
    fn decodes_whole_byte_by_byte_and_two_in_one_chunk() {
        let mut two = REQUEST.to_vec();
        two.extend_from_slice(REQUEST);
        for (input, chunk, count) in [(REQUEST, REQUEST.len(), 1), (REQUEST, 1, 1), (&two[..], two.len(), 2)] {
            let (frames, bad) = run(&mut MbapCodec::new(), input, chunk);
            assert_eq!(frames.len(), count);
            assert!(bad.is_empty());
            assert_eq!(frames[0].0, AduHeader { unit: 0x11, transaction: 1 });
            assert_eq!(frames[0].1, &REQUEST[7..]);
        }
    }

    #[test]
    fn bad_headers_are_skipped_to_the_next_plausible_one() {
        let mut input = std::vec![0x00, 0x07, 0x12, 0x34, 0xFF]; // junk: protocol id 0x1234
        input.extend_from_slice(REQUEST);
        let mut codec = MbapCodec::new();
        let (frames, bad) = run(&mut codec, &input, 3);
        assert_eq!(frames.len(), 1);
        // Fed three bytes at a time, the junk is reported as it is ruled out.
        assert_eq!(bad.iter().sum::<usize>(), 5);
        assert_eq!(codec.stats().discarded_bytes, 5);
    }

    #[test]
    fn noise_is_reported_as_it_comes_not_when_a_frame_follows() {
        let mut codec = MbapCodec::new();
        let (frames, bad) = run(&mut codec, &[0xEB; 1000], 100);
        assert!(frames.is_empty());
        assert_eq!(bad.iter().sum::<usize>(), 1000 - (HEADER_LEN - 1), "all but a possible header's worth");
        assert!(codec.stats().discards > 0);
    }

    #[test]
    fn a_strict_receiver_discards_everything_after_a_bad_header_and_finds_no_frame_behind_it() {
        let mut header_65535 = std::vec![0x00, 0x31, 0x00, 0x00, 0xFF, 0xFF, 0x01];
        let mut hidden = REQUEST.to_vec();
        hidden[1] = 0x32; // transaction 0x0032, the request the lenient receiver would find
        header_65535.extend_from_slice(&hidden);
        let six_zeros = [&[0u8; 6][..], REQUEST, REQUEST].concat();
        for input in [header_65535, six_zeros] {
            for chunk in [1, 5, input.len()] {
                let mut codec = MbapCodec::strict();
                let (frames, bad) = run(&mut codec, &input, chunk);
                assert!(frames.is_empty(), "chunk {chunk}: frames {frames:?} found behind a bad header");
                assert_eq!(bad.iter().sum::<usize>(), input.len(), "chunk {chunk}: every byte is discarded");
                assert!(codec.is_lost());
                codec.reset();
                let (frames, _) = run(&mut codec, REQUEST, REQUEST.len());
                assert_eq!(frames.len(), 1, "a reset receiver frames again");
            }
        }
    }

    #[test]
    fn a_receiver_is_mid_frame_from_a_frames_first_byte_until_it_is_complete() {
        let mut codec = MbapCodec::strict();
        assert!(!codec.is_mid_frame());
        let (frames, _) = run(&mut codec, &REQUEST[..3], 3);
        assert!(frames.is_empty() && codec.is_mid_frame(), "a truncated header");
        let (frames, _) = run(&mut codec, &REQUEST[3..], 9);
        assert_eq!(frames.len(), 1);
        assert!(!codec.is_mid_frame(), "the frame is complete");
    }

    #[test]
    fn a_strict_receiver_frames_good_requests_like_the_lenient_one() {
        let two = [REQUEST, REQUEST].concat();
        let (frames, bad) = run(&mut MbapCodec::strict(), &two, 5);
        assert_eq!(frames.len(), 2);
        assert!(bad.is_empty());
    }

    #[test]
    fn header_lengths_outside_2_to_254_are_refused() {
        for (len, ok) in [(0u16, false), (1, false), (2, true), (254, true), (255, false), (0xFFFF, false)] {
            let [hi, lo] = len.to_be_bytes();
            assert_eq!(parse_header(&[0, 0, 0, 0, hi, lo, 1]).is_ok(), ok, "length {len}");
        }
        assert_eq!(parse_header(&[0, 0, 0, 1, 0, 6, 1]), Err(DiscardReason::BadHeader));
    }

    #[test]
    fn the_largest_frame_fits() {
        let pdu = [0x41u8; MAX_PDU_LEN];
        let mut out = [0u8; MAX_ADU_LEN];
        let n = encode_pdu(AduHeader { unit: 1, transaction: 9 }, &pdu, &mut out).unwrap();
        assert_eq!(n, 260);
        let (frames, _) = run(&mut MbapCodec::new(), &out, 7);
        assert_eq!(frames[0].1.len(), MAX_PDU_LEN);
    }
}
