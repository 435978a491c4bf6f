//! Reading a framed reply back into its header and PDU, and framing it again: what the fault
//! rules that change a reply's unit, transaction id or PDU do, with ferrobus-proto's framing
//! rather than byte offsets.

use ferrobus::Framing;
use ferrobus_proto::Instant;
use ferrobus_proto::frame::ascii::{self, AsciiCodec};
use ferrobus_proto::frame::mbap::{self, HEADER_LEN};
use ferrobus_proto::frame::rtu::{self, RtuFrame};
use ferrobus_proto::frame::{AduHeader, LineConfig, LineTiming, RxEvent, feed};

/// The header and PDU of the whole frame `frame`, if it is one.
pub(crate) fn unframe(framing: Framing, frame: &[u8]) -> Option<(AduHeader, Vec<u8>)> {
    match framing {
        Framing::Rtu => {
            let frame = RtuFrame::new_checked(frame).ok()?;
            Some((AduHeader::unit(frame.unit()), frame.pdu().to_vec()))
        }
        Framing::Mbap => {
            let head: &[u8; HEADER_LEN] = frame.get(..HEADER_LEN)?.try_into().ok()?;
            let (header, len) = mbap::parse_header(head).ok()?;
            let pdu = frame.get(HEADER_LEN..)?;
            (pdu.len() == len).then(|| (header, pdu.to_vec()))
        }
        Framing::Ascii => {
            let mut codec = AsciiCodec::new(LineTiming::new(&LineConfig::default()));
            let mut found = None;
            feed(&mut codec, Instant::ZERO, frame, |event| {
                if let RxEvent::Frame(adu) = event {
                    found = Some((adu.header, adu.pdu.to_vec()));
                }
            });
            found
        }
    }
}

/// The unit a whole framed reply comes from.
pub(crate) fn unit_of(framing: Framing, frame: &[u8]) -> Option<u8> {
    unframe(framing, frame).map(|(header, _)| header.unit)
}

/// Breaks the checksum of a whole framed reply: its CRC (RTU) or LRC (ASCII), through the
/// core's framing. Modbus/TCP has no checksum to break, and a frame already cut short has none
/// left: those pass unchanged.
pub(crate) fn corrupt_checksum(framing: Framing, frame: &mut [u8]) {
    match framing {
        Framing::Rtu => {
            rtu::corrupt_crc(frame);
        }
        Framing::Ascii => {
            ascii::corrupt_lrc(frame);
        }
        Framing::Mbap => {}
    }
}

/// `pdu` framed for `header`.
pub(crate) fn encode(framing: Framing, header: AduHeader, pdu: &[u8]) -> Option<Vec<u8>> {
    let mut out = vec![0u8; ascii::MAX_FRAME_CHARS.max(mbap::MAX_ADU_LEN).max(rtu::MAX_ADU_LEN)];
    let n = match framing {
        Framing::Rtu => rtu::encode_pdu(header.unit, pdu, &mut out),
        Framing::Ascii => ascii::encode_pdu(header.unit, pdu, &mut out),
        Framing::Mbap => mbap::encode_pdu(header, pdu, &mut out),
    }
    .ok()?;
    out.truncate(n);
    Some(out)
}

/// Rewrites the framed reply `frame` through `change`, which may alter its header and PDU.
/// A frame that does not read back (never the case for the engine's own) is left alone.
pub(crate) fn reframe(framing: Framing, frame: &mut Vec<u8>, change: impl FnOnce(&mut AduHeader, &mut Vec<u8>)) {
    let Some((mut header, mut pdu)) = unframe(framing, frame) else { return };
    change(&mut header, &mut pdu);
    if let Some(framed) = encode(framing, header, &pdu) {
        *frame = framed;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 01 03 02 00 2A: unit 1 answers one register, 42.
    const PDU: [u8; 4] = [0x03, 0x02, 0x00, 0x2A];

    #[test]
    fn a_corrupted_reply_keeps_its_unit_and_fails_only_its_checksum() {
        let header = AduHeader { unit: 7, transaction: 0 };
        for framing in [Framing::Rtu, Framing::Ascii] {
            let mut frame = encode(framing, header, &PDU).unwrap();
            assert_eq!(unit_of(framing, &frame), Some(7), "{framing:?}");
            corrupt_checksum(framing, &mut frame);
            assert_eq!(unframe(framing, &frame), None, "{framing:?}: the checksum no longer agrees");
        }
        let mut frame = encode(Framing::Mbap, header, &PDU).unwrap();
        let sent = frame.clone();
        assert_eq!(unit_of(Framing::Mbap, &frame), Some(7));
        corrupt_checksum(Framing::Mbap, &mut frame);
        assert_eq!(frame, sent, "Modbus/TCP has no checksum");
    }

    #[test]
    fn every_framing_reads_back_what_it_framed() {
        let header = AduHeader { unit: 1, transaction: 0 };
        for framing in [Framing::Rtu, Framing::Ascii] {
            let frame = encode(framing, header, &PDU).unwrap();
            assert_eq!(unframe(framing, &frame), Some((header, PDU.to_vec())), "{framing:?}");
        }
        let tcp = AduHeader { unit: 1, transaction: 0x1234 };
        let frame = encode(Framing::Mbap, tcp, &PDU).unwrap();
        assert_eq!(frame, [0x12, 0x34, 0, 0, 0, 5, 1, 0x03, 0x02, 0x00, 0x2A]);
        assert_eq!(unframe(Framing::Mbap, &frame), Some((tcp, PDU.to_vec())));
    }

    #[test]
    fn a_reframed_reply_has_a_valid_checksum_over_its_new_contents() {
        let mut frame = encode(Framing::Rtu, AduHeader::unit(1), &PDU).unwrap();
        reframe(Framing::Rtu, &mut frame, |header, pdu| {
            header.unit = 7;
            pdu.pop();
        });
        assert_eq!(frame, encode(Framing::Rtu, AduHeader::unit(7), &PDU[..3]).unwrap());
        assert!(RtuFrame::new_checked(&frame).is_ok());
    }

    #[test]
    fn bytes_that_are_not_a_frame_are_left_alone() {
        let mut junk = vec![0x01, 0x03, 0xFF];
        for framing in [Framing::Rtu, Framing::Ascii, Framing::Mbap] {
            reframe(framing, &mut junk, |header, _| header.unit = 9);
            assert_eq!(junk, [0x01, 0x03, 0xFF]);
        }
    }
}
