//! Limits: every quantity and count at min − 1, min, max and max + 1, through the constructors
//! and through parse, and every field with restricted values; each refusal with its exact error.
//!
//! Limits: MODBUS Application Protocol V1.1b3 §4.1 (253-byte PDU) and §6 per function code,
//! as listed in `reference/modbus-and-drives.md` §2.1–2.2.

use super::*;
use crate::codes::{MeiType, ReadDeviceIdCode};
use crate::error::PduError::{
    AddressOverflow, ByteCountMismatch, Empty, InvalidCoilValue, InvalidField, InvalidFunctionCode,
    InvalidReferenceType, QuantityOutOfRange, TooLong, TrailingBytes, Truncated,
};

/// min − 1 (when min > 0), min, max and max + 1, each with the error a quantity outside
/// `min..=max` gives (`None` inside).
fn edges(min: usize, max: usize) -> Vec<(usize, Option<PduError>)> {
    let out = |quantity| Some(QuantityOutOfRange { quantity, min, max });
    let mut cases = vec![(min, None), (max, None), (max + 1, out(max + 1))];
    if let Some(below) = min.checked_sub(1) {
        cases.insert(0, (below, out(below)));
    }
    cases
}

fn mismatch(declared: usize, expected: usize) -> PduError {
    ByteCountMismatch { declared, expected }
}

fn overflow(start: usize, quantity: usize) -> PduError {
    AddressOverflow { start: word(start), quantity: word(quantity) }
}

// ── Quantities ──────────────────────────────────────────────────────────────────────────────

#[test]
fn read_bits_quantity_is_1_to_2000() {
    for (q, err) in edges(1, 2000) {
        assert_eq!(ReadBits::new(0, word(q)).err(), err, "{q}");
        for fc in [0x01, 0x02] {
            assert_parse(Dir::Request, &Fields::new(fc).word(0).word(q), err);
        }
    }
}

#[test]
fn read_registers_quantity_is_1_to_125() {
    for (q, err) in edges(1, 125) {
        assert_eq!(ReadRegisters::new(0, word(q)).err(), err, "{q}");
        for fc in [0x03, 0x04] {
            assert_parse(Dir::Request, &Fields::new(fc).word(0).word(q), err);
        }
    }
}

#[test]
fn write_coils_quantity_is_1_to_1968() {
    for (q, err) in edges(1, 1968) {
        assert_eq!(WriteCoils::new(0, Bits::from_values(&vec![true; q])).err(), err, "{q}");
        // 1969 coils still fit in a PDU (253 bytes): the quantity itself is refused.
        let n = q.div_ceil(8);
        assert_parse(Dir::Request, &Fields::new(0x0F).word(0).word(q).byte(n).fill(n, 0x00), err);
    }
}

#[test]
fn write_registers_quantity_is_1_to_123() {
    for (q, err) in edges(1, 123) {
        assert_eq!(WriteRegisters::new(0, Registers::from_values(&vec![0x1234; q])).err(), err, "{q}");
        let header = Fields::new(0x10).word(0).word(q).byte(2 * q);
        match err {
            // The quantity is checked before the byte count and the data.
            Some(_) => assert_parse(Dir::Request, &header, err),
            None => assert_parse(Dir::Request, &header.fill(2 * q, 0x12), None),
        }
    }
    // With its data, a write of 124 registers does not fit in a PDU at all.
    let pdu = Fields::new(0x10).word(0).word(124).byte(248).fill(248, 0);
    assert_parse(Dir::Request, &pdu, Some(TooLong { len: 254 }));
}

#[test]
fn read_write_registers_read_1_to_125_and_write_1_to_121() {
    for (q, err) in edges(1, 125) {
        assert_eq!(ReadWriteRegisters::new(0, word(q), 0, Registers::from_values(&[7])).err(), err, "read {q}");
        let pdu = Fields::new(0x17).word(0).word(q).word(0).word(1).byte(2).word(7);
        assert_parse(Dir::Request, &pdu, err);
    }
    for (q, err) in edges(1, 121) {
        assert_eq!(ReadWriteRegisters::new(0, 1, 0, Registers::from_values(&vec![7; q])).err(), err, "write {q}");
        let header = Fields::new(0x17).word(0).word(1).word(0).word(q).byte(2 * q);
        match err {
            Some(_) => assert_parse(Dir::Request, &header, err),
            None => assert_parse(Dir::Request, &header.fill(2 * q, 0x07), None),
        }
    }
    let pdu = Fields::new(0x17).word(0).word(1).word(0).word(122).byte(244).fill(244, 0);
    assert_parse(Dir::Request, &pdu, Some(TooLong { len: 254 }));
}

#[test]
fn read_register_responses_carry_1_to_125_registers() {
    for (n, err) in edges(1, 125) {
        assert_eq!(RegisterValues::new(Registers::from_values(&vec![0xBEEF; n])).err(), err, "{n}");
        for fc in [0x03, 0x04, 0x17] {
            let pdu = Fields::new(fc).byte(2 * n).fill(2 * n, 0xBE);
            // 126 registers make a 254-byte PDU.
            let err = if pdu.len() > MAX_PDU_LEN { Some(TooLong { len: pdu.len() }) } else { err };
            assert_parse(Dir::Response, &pdu, err);
        }
    }
}

#[test]
fn read_bit_responses_carry_1_to_2000_bits_in_1_to_250_bytes() {
    for (q, err) in edges(1, 2000) {
        assert_eq!(BitValues::new(Bits::from_values(&vec![false; q])).err(), err, "{q}");
    }
    for (n, err) in edges(1, 250) {
        for fc in [0x01, 0x02] {
            assert_parse(Dir::Response, &Fields::new(fc).byte(n).fill(n, 0x5A), err);
        }
    }
}

#[test]
fn fifo_responses_carry_at_most_31_values() {
    for (n, err) in edges(0, 31) {
        assert_eq!(FifoValues::new(Registers::from_values(&vec![1; n])).err(), err, "{n}");
        let pdu = Fields::new(0x18).word(2 + 2 * n).word(n).fill(2 * n, 0x01);
        assert_parse(Dir::Response, &pdu, err);
    }
}

#[test]
fn comm_event_logs_carry_at_most_64_events() {
    for (n, err) in edges(0, 64) {
        assert_eq!(CommEventLog::new(0, 0, 0, &vec![0; n]).err(), err, "{n}");
    }
    // On the wire the byte count covers the three words too: 6 + events.
    for (count, err) in edges(6, 70) {
        assert_parse(Dir::Response, &Fields::new(0x0C).byte(count).fill(count, 0), err);
    }
}

#[test]
fn report_server_id_responses_carry_1_to_251_bytes() {
    for (n, err) in edges(1, 251) {
        assert_eq!(ServerId::new(&vec![0x2A; n]).err(), err, "{n}");
        let pdu = Fields::new(0x11).byte(n).fill(n, 0x2A);
        let err = if pdu.len() > MAX_PDU_LEN { Some(TooLong { len: pdu.len() }) } else { err };
        assert_parse(Dir::Response, &pdu, err);
    }
}

#[test]
fn device_objects_hold_at_most_255_objects_of_at_most_255_bytes() {
    let object = DeviceObject { id: 0, value: &[] };
    for (n, err) in edges(0, 255) {
        assert_eq!(DeviceObjects::new(&vec![object; n]).err(), err, "{n}");
    }
    for (n, err) in edges(0, 255) {
        let value = vec![b'x'; n];
        assert_eq!(DeviceObjects::new(&[DeviceObject { id: 0, value: &value }]).err(), err, "{n}");
    }
}

// ── Addresses ───────────────────────────────────────────────────────────────────────────────

#[test]
fn ranges_past_address_0xffff_are_address_overflow() {
    let read = |fc, start, q| Fields::new(fc).word(start).word(q);
    for (fc, q) in [(0x01, 2), (0x01, 2000), (0x02, 2), (0x03, 2), (0x03, 125), (0x04, 125)] {
        let last = 0x1_0000 - q; // the highest start at which `q` items fit
        assert_parse(Dir::Request, &read(fc, last, q), None);
        assert_parse(Dir::Request, &read(fc, last + 1, q), Some(overflow(last + 1, q)));
    }
    assert_parse(Dir::Request, &read(0x03, 0xFFFF, 2), Some(overflow(0xFFFF, 2)));
    assert_parse(Dir::Request, &read(0x01, 0xFFFF, 1), None);
    assert_eq!(ReadBits::new(0xFFFF, 2).err(), Some(overflow(0xFFFF, 2)));
    assert_eq!(ReadRegisters::new(0xFFFF, 2).err(), Some(overflow(0xFFFF, 2)));
    assert_eq!(ReadRegisters::new(0xFFFF, 1).err(), None);

    let two = Registers::from_values(&[1, 2]);
    assert_eq!(WriteCoils::new(0xFFFF, Bits::from_values(&[true, true])).err(), Some(overflow(0xFFFF, 2)));
    assert_eq!(WriteRegisters::new(0xFFFF, two).err(), Some(overflow(0xFFFF, 2)));
    assert_eq!(ReadWriteRegisters::new(0xFFFF, 2, 0, two).err(), Some(overflow(0xFFFF, 2)));
    assert_eq!(ReadWriteRegisters::new(0, 2, 0xFFFF, two).err(), Some(overflow(0xFFFF, 2)));
    assert_eq!(ReadWriteRegisters::new(0xFFFE, 2, 0xFFFE, two).err(), None);

    let coils = |start| Fields::new(0x0F).word(start).word(2).byte(1).byte(0b11);
    assert_parse(Dir::Request, &coils(0xFFFE), None);
    assert_parse(Dir::Request, &coils(0xFFFF), Some(overflow(0xFFFF, 2)));
    let registers = |start| Fields::new(0x10).word(start).word(2).byte(4).word(1).word(2);
    assert_parse(Dir::Request, &registers(0xFFFE), None);
    assert_parse(Dir::Request, &registers(0xFFFF), Some(overflow(0xFFFF, 2)));
    let read_write = |read, write| Fields::new(0x17).word(read).word(2).word(write).word(2).byte(4).word(1).word(2);
    assert_parse(Dir::Request, &read_write(0xFFFE, 0xFFFE), None);
    assert_parse(Dir::Request, &read_write(0xFFFF, 0), Some(overflow(0xFFFF, 2)));
    assert_parse(Dir::Request, &read_write(0, 0xFFFF), Some(overflow(0xFFFF, 2)));
}

// ── Byte counts ─────────────────────────────────────────────────────────────────────────────

#[test]
fn write_byte_counts_must_match_the_quantity() {
    // 0x0F: ceil(quantity / 8) bytes. One more, padding an odd count to a whole word as the
    // Hitachi/Omron inverters send it, is accepted too (`regressions`; it re-emits without the
    // pad, so it is not in this table); two more are not.
    for (q, count, err) in [
        (6, 1, None),
        (6, 0, Some(mismatch(0, 1))),
        (6, 3, Some(mismatch(3, 1))),
        (8, 1, None),
        (16, 3, Some(mismatch(3, 2))),
        (9, 1, Some(mismatch(1, 2))),
    ] {
        assert_parse(Dir::Request, &Fields::new(0x0F).word(0).word(q).byte(count).fill(count, 0), err);
    }
    // 0x10: 2 × quantity bytes.
    for (q, count, err) in
        [(2, 4, None), (2, 3, Some(mismatch(3, 4))), (2, 5, Some(mismatch(5, 4))), (1, 0, Some(mismatch(0, 2)))]
    {
        assert_parse(Dir::Request, &Fields::new(0x10).word(0).word(q).byte(count).fill(count, 0), err);
    }
    // 0x17: 2 × write quantity bytes.
    for (q, count, err) in [(2, 4, None), (2, 5, Some(mismatch(5, 4))), (2, 2, Some(mismatch(2, 4)))] {
        let pdu = Fields::new(0x17).word(0).word(1).word(0).word(q).byte(count).fill(count, 0);
        assert_parse(Dir::Request, &pdu, err);
    }
}

#[test]
fn register_responses_with_an_odd_byte_count_are_refused() {
    for fc in [0x03, 0x04, 0x17] {
        for count in [1, 3, 249, 251] {
            assert_parse(Dir::Response, &Fields::new(fc).byte(count).fill(count, 0), Some(mismatch(count, count + 1)));
        }
    }
    // 0x18: the byte count is 2 + 2 × the FIFO count.
    assert_parse(Dir::Response, &Fields::new(0x18).word(5).word(2).fill(4, 0), Some(mismatch(5, 6)));
    assert_parse(Dir::Response, &Fields::new(0x18).word(2).word(1).fill(2, 0), Some(mismatch(2, 4)));
}

#[test]
fn a_byte_count_past_the_end_of_the_pdu_is_truncated() {
    let truncated = |needed, available| Some(Truncated { needed, available });
    assert_parse(Dir::Response, &Fields::new(0x03).byte(4).word(1), truncated(6, 4));
    assert_parse(Dir::Response, &Fields::new(0x01).byte(2).byte(0xFF), truncated(4, 3));
    assert_parse(Dir::Request, &Fields::new(0x10).word(0).word(2).byte(4).word(1), truncated(10, 8));
    assert_parse(Dir::Response, &Fields::new(0x11).byte(3).byte(0x2A), truncated(5, 3));
}

// ── Fields with restricted values ───────────────────────────────────────────────────────────

#[test]
fn write_single_coil_values_other_than_ff00_and_0000_are_refused() {
    for value in 0..=u16::MAX {
        let pdu = Fields::new(0x05).word(0x00AC).word(usize::from(value));
        let err = (value != 0xFF00 && value != 0x0000).then_some(InvalidCoilValue(value));
        for dir in Dir::BOTH {
            assert_parse(dir, &pdu, err);
        }
    }
}

#[test]
fn file_record_reference_types_other_than_6_are_refused() {
    for t in (0..=u8::MAX).filter(|&t| t != REFERENCE_TYPE) {
        let err = Some(InvalidReferenceType(t));
        let t = usize::from(t);
        // 0x14 request: in the first and in the second sub-request.
        assert_parse(Dir::Request, &Fields::new(0x14).byte(7).byte(t).word(4).word(1).word(2), err);
        let second = Fields::new(0x14).byte(14).byte(6).word(4).word(1).word(2).byte(t).word(3).word(9).word(2);
        assert_parse(Dir::Request, &second, err);
        // 0x14 response: a sub-response of one register.
        assert_parse(Dir::Response, &Fields::new(0x14).byte(4).byte(3).byte(t).word(0x1234), err);
        // 0x15 request and its echo.
        for dir in Dir::BOTH {
            assert_parse(dir, &Fields::new(0x15).byte(9).byte(t).word(4).word(7).word(1).word(0x06AF), err);
        }
    }
}

#[test]
fn read_file_record_byte_count_is_a_multiple_of_7_from_7_to_245() {
    // Sub-requests of one register each, cut to `count` bytes.
    let sub_requests = |count: usize| [6u8, 0, 4, 0, 1, 0, 1].into_iter().cycle().take(count).collect::<Vec<u8>>();
    let range = |count| Some(QuantityOutOfRange { quantity: count, min: 7, max: 245 });
    let cases = [
        (0, range(0)),
        (6, range(6)),
        (7, None),
        (8, Some(mismatch(8, 7))),
        (13, Some(mismatch(13, 7))),
        (14, None),
        (244, Some(mismatch(244, 238))),
        (245, None), // 35 sub-requests
        (246, range(246)),
    ];
    for (count, err) in cases {
        assert_parse(Dir::Request, &Fields::new(0x14).byte(count).bytes(&sub_requests(count)), err);
    }
    let one = FileRecordRef { file: 4, record: 1, length: 1 };
    assert_eq!(FileRecordReads::new(&[]).err(), range(0));
    assert_eq!(FileRecordReads::new(&[one; 35]).err(), None);
    assert_eq!(FileRecordReads::new(&[one; 36]).err(), range(252));
    assert_eq!(
        FileRecordReads::new(&[FileRecordRef { length: 0, ..one }]).err(),
        Some(QuantityOutOfRange { quantity: 0, min: 1, max: 245 })
    );
}

#[test]
fn read_file_record_requests_whose_response_exceeds_245_bytes_are_refused() {
    // Each sub-response takes 2 + 2 × length bytes of the response's 245.
    let too_big = |total| Some(mismatch(total, 245));
    let cases: [(&[u16], Option<PduError>); 4] =
        [(&[121], None), (&[122], too_big(246)), (&[60, 60], None), (&[60, 61], too_big(246))];
    for (lengths, err) in cases {
        let refs: Vec<FileRecordRef> =
            lengths.iter().map(|&length| FileRecordRef { file: 1, record: 0, length }).collect();
        assert_eq!(FileRecordReads::new(&refs).err(), err, "{lengths:?}");
        let mut pdu = Fields::new(0x14).byte(7 * lengths.len());
        for &length in lengths {
            pdu = pdu.byte(6).word(1).word(0).word(usize::from(length));
        }
        assert_parse(Dir::Request, &pdu, err);
    }
}

#[test]
fn read_file_record_responses_hold_2_to_245_bytes_of_odd_length_sub_responses() {
    let range = |count| Some(QuantityOutOfRange { quantity: count, min: 2, max: 245 });
    assert_parse(Dir::Response, &Fields::new(0x14).byte(0), range(0));
    assert_parse(Dir::Response, &Fields::new(0x14).byte(1).byte(1), range(1));
    assert_parse(Dir::Response, &Fields::new(0x14).byte(246).fill(246, 1), range(246));
    // A sub-response's length counts its reference type and whole registers: it is odd.
    assert_parse(Dir::Response, &Fields::new(0x14).byte(5).byte(4).byte(6).fill(3, 0), Some(mismatch(4, 5)));
    assert_parse(Dir::Response, &Fields::new(0x14).byte(4).byte(3).byte(6).word(1), None);
    // The largest sub-response: 121 registers, 2 + 242 bytes; 122 registers would be 246.
    let full = Fields::new(0x14).byte(244).byte(243).byte(6).fill(242, 0x11);
    assert_parse(Dir::Response, &full, None);
    let regs = vec![0u16; 122];
    assert_eq!(FileSubResponses::new(&[Registers::from_values(&regs)]).err(), range(246));
    assert_eq!(FileSubResponses::new(&[]).err(), range(0));
}

#[test]
fn write_file_record_byte_count_is_9_to_251() {
    let range = |count| Some(QuantityOutOfRange { quantity: count, min: 9, max: 251 });
    let write =
        |count| Fields::new(0x15).byte(count).byte(6).word(4).word(7).word((count - 7) / 2).fill(count - 7, 0x5A);
    assert_parse(Dir::Request, &Fields::new(0x15).byte(8).fill(8, 0), range(8));
    assert_parse(Dir::Request, &write(9), None);
    assert_parse(Dir::Request, &write(251), None); // 122 registers
    assert_parse(Dir::Request, &Fields::new(0x15).byte(252).fill(252, 0), Some(TooLong { len: 254 }));
    // A sub-request writes at least one register.
    let empty = Fields::new(0x15).byte(9).byte(6).word(4).word(7).word(0).word(0);
    assert_parse(Dir::Request, &empty, Some(QuantityOutOfRange { quantity: 0, min: 1, max: 251 }));
    // A record length that runs past the byte count is an error (today: Truncated inside the count).
    let overrun = Fields::new(0x15).byte(9).byte(6).word(4).word(7).word(2).word(0);
    assert!(Request::parse(&overrun).is_err());

    let sub = |data| FileRecordWrite { file: 4, record: 7, data };
    let (r122, r123) = (vec![1u16; 122], vec![1u16; 123]);
    assert_eq!(FileRecordWrites::new(&[sub(Registers::from_values(&r122))]).err(), None);
    assert_eq!(FileRecordWrites::new(&[sub(Registers::from_values(&r123))]).err(), range(253));
    assert_eq!(FileRecordWrites::new(&[]).err(), range(0));
    assert_eq!(
        FileRecordWrites::new(&[sub(Registers::EMPTY)]).err(),
        Some(QuantityOutOfRange { quantity: 0, min: 1, max: 251 })
    );
}

#[test]
fn read_device_id_codes_other_than_1_to_4_are_invalid() {
    for code in 0..=u8::MAX {
        let err =
            (!(1..=4).contains(&code)).then_some(InvalidField { field: "read device id code", value: code.into() });
        assert_parse(Dir::Request, &[0x2B, 0x0E, code, 0x00], err);
        assert_eq!(ReadDeviceId::new(ReadDeviceIdCode::from_u8(code), 0).err(), err);
    }
}

#[test]
fn more_follows_is_00_or_ff() {
    for value in 0..=u8::MAX {
        let err =
            (value != 0x00 && value != 0xFF).then_some(InvalidField { field: "more follows", value: value.into() });
        assert_parse(Dir::Response, &[0x2B, 0x0E, 0x01, 0x01, value, 0x00, 0x00], err);
    }
}

#[test]
fn mei_type_0e_cannot_be_carried_raw() {
    let err = Err(InvalidField { field: "MEI type", value: 0x0E });
    assert_eq!(RawMei::new(MeiType::ReadDeviceIdentification, &[]), err);
    assert!(RawMei::new(MeiType::CanOpenGeneralReference, &[]).is_ok());
}

#[test]
fn exception_responses_carry_exactly_one_code() {
    assert_parse(Dir::Response, &[0x83], Some(Truncated { needed: 2, available: 1 }));
    assert_parse(Dir::Response, &[0x83, 0x02, 0x00], Some(TrailingBytes { extra: 1 }));
    for code in 0..=u8::MAX {
        assert_parse(Dir::Response, &[0x83, code], None);
    }
}

// ── Function codes, lengths ─────────────────────────────────────────────────────────────────

#[test]
fn request_function_code_zero_and_codes_with_bit_7_are_invalid() {
    for fc in core::iter::once(0).chain(0x80..=u8::MAX) {
        for body in [&[][..], &[0x00, 0x01, 0x00, 0x01]] {
            assert_parse(Dir::Request, &Fields::new(fc).bytes(body), Some(InvalidFunctionCode(fc)));
        }
        assert_eq!(Custom::new(fc, &[]), Err(InvalidFunctionCode(fc)));
        assert_eq!(Request::wire_len(fc, &[]), WireLen::Unknown);
    }
}

#[test]
fn response_function_code_zero_and_a_bare_exception_bit_are_invalid() {
    assert_parse(Dir::Response, &[0x00], Some(InvalidFunctionCode(0x00)));
    assert_parse(Dir::Response, &[0x00, 0x01], Some(InvalidFunctionCode(0x00)));
    assert_parse(Dir::Response, &[0x80], Some(InvalidFunctionCode(0x80)));
    assert_parse(Dir::Response, &[0x80, 0x01], Some(InvalidFunctionCode(0x80)));
}

#[test]
fn custom_pdus_refuse_the_public_codes() {
    for code in FunctionCode::ALL {
        assert_eq!(Custom::new(code.value(), &[]), Err(InvalidFunctionCode(code.value())));
    }
    for code in (0x01..=0x7F).filter(|&c| !FunctionCode::from_u8(c).is_public()) {
        assert!(Custom::new(code, &[]).is_ok(), "0x{code:02X}");
    }
}

#[test]
fn pdus_longer_than_253_bytes_are_too_long() {
    let codes = FunctionCode::ALL.iter().map(|c| c.value()).chain([0x00, 0x41, 0x83, 0xFF]);
    for fc in codes {
        for len in [254, 255, 300] {
            for dir in Dir::BOTH {
                assert_parse(dir, &Fields::new(fc).fill(len - 1, 0), Some(TooLong { len }));
            }
        }
    }
    // 253 bytes are fine where the layout allows.
    for dir in Dir::BOTH {
        assert_parse(dir, &Fields::new(0x41).fill(252, 0xAB), None);
    }
    let too_long = Some(TooLong { len: 254 });
    assert_eq!(Custom::new(0x41, &[0; 253]).err(), too_long);
    assert_eq!(Diagnostic::with_data(DiagnosticCode::ReturnQueryData, &[0; 251]).err(), too_long);
    assert!(Diagnostic::with_data(DiagnosticCode::ReturnQueryData, &[0; 250]).is_ok());
    assert_eq!(RawMei::new(MeiType::CanOpenGeneralReference, &[0; 252]).err(), too_long);
    assert!(RawMei::new(MeiType::CanOpenGeneralReference, &[0; 251]).is_ok());
    let identification = |n: usize| {
        let value = vec![b'x'; n];
        let list = [DeviceObject { id: 0x80, value: &value }];
        let objects = DeviceObjects::new(&list).unwrap();
        DeviceIdentification::new(ReadDeviceIdCode::Extended, 0x83, false, 0, objects).err()
    };
    assert_eq!(identification(244), None); // 7 + 2 + 244 = 253
    assert_eq!(identification(245), too_long);
}

#[test]
fn an_empty_pdu_is_empty() {
    for dir in Dir::BOTH {
        assert_parse(dir, &[], Some(Empty));
    }
}
