//! Bugs this suite found when it was written, now fixed: each test pins the fix.

use super::*;
use crate::codes::ExceptionCode;
use crate::error::PduError::{self, AddressOverflow, InvalidField, QuantityOutOfRange, TrailingBytes, Truncated};

#[test]
fn the_3g3rx_manual_write_coils_frame_with_a_word_padded_byte_count_parses() {
    // reference §4.10: `05 0F 00 06 00 06 02 17 00 DB 3E`, without unit and CRC. The Hitachi
    // family pads coil data to whole 16-bit words; the spec says ceil(6 / 8) = 1 byte.
    #[rustfmt::skip]
    let pdu = [
        0x0F,       // function code: 0x0F Write Multiple Coils
        0x00, 0x06, // starting address: 6 (coil 7)
        0x00, 0x06, // quantity of coils: 6
        0x02,       // byte count: 2, a whole word
        0x17,       // coils 12…7: 01_0111
        0x00,       // padding byte
    ];
    let request = Request::parse(&pdu).expect("the manual's own frame parses");
    let w = body!(request, Request::WriteMultipleCoils);
    assert_eq!((w.start(), w.quantity()), (6, 6));
    assert!(w.values().iter().eq([true, true, true, false, true, false]));
    assert_eq!(
        Pdu::Request(request).to_bytes(),
        [0x0F, 0x00, 0x06, 0x00, 0x06, 0x01, 0x17],
        "re-emitted as the spec has it"
    );
}

#[test]
fn bit_responses_of_a_count_not_a_multiple_of_8_round_trip() {
    let x = Response::ReadCoils(BitValues::new(Bits::from_values(&[true, false, true])).unwrap());
    let bytes = Pdu::Response(x).to_bytes();
    assert_eq!(bytes, [0x01, 0x01, 0b0000_0101]);
    assert_eq!(Response::parse(&bytes), Ok(x));
}

#[test]
fn exception_responses_can_only_be_built_for_request_function_codes() {
    for function in [0x00, 0x83] {
        // Only request function codes can be refused: the others are not built at all.
        let x = ExceptionResponse::new(FunctionCode::from_u8(function), ExceptionCode::IllegalFunction);
        assert_eq!(x, Err(PduError::InvalidFunctionCode(function)));
    }
}

#[test]
fn diagnostic_sub_functions_other_than_00_take_exactly_one_word() {
    for dir in Dir::BOTH {
        // 0x000A Clear Counters without its data word, then with half of it.
        assert_eq!(dir.parse(&[0x08, 0x00, 0x0A]), Err(Truncated { needed: 5, available: 3 }));
        assert_eq!(dir.parse(&[0x08, 0x00, 0x0A, 0x00]), Err(Truncated { needed: 5, available: 4 }));
        // 0x000B Return Bus Message Count with a byte too many.
        assert_eq!(dir.parse(&[0x08, 0x00, 0x0B, 0x00, 0x00, 0x00]), Err(TrailingBytes { extra: 1 }));
    }
    assert!(Diagnostic::with_data(DiagnosticCode::BusMessageCount, &[1, 2, 3]).is_err());
    // Return Query Data and unnamed sub-functions keep taking any data.
    assert!(Request::parse(&[0x08, 0x00, 0x00, 0x01]).is_ok());
    assert!(Request::parse(&[0x08, 0x00, 0x15, 0x00, 0x03, 0x00]).is_ok());
}

#[test]
fn device_identification_responses_with_an_invalid_read_code_are_refused() {
    for code in [0x00, 0x05, 0xFF] {
        let pdu = [0x2B, 0x0E, code, 0x01, 0x00, 0x00, 0x00];
        let err = InvalidField { field: "read device id code", value: u16::from(code) };
        assert_eq!(Response::parse(&pdu), Err(err), "{pdu:02X?}");
    }
}

#[test]
fn write_multiple_responses_with_an_impossible_range_are_refused() {
    let coils = |quantity| Err(QuantityOutOfRange { quantity, min: 1, max: 1968 });
    assert_eq!(Response::parse(&[0x0F, 0x00, 0x00, 0x00, 0x00]), coils(0));
    assert_eq!(Response::parse(&[0x0F, 0x00, 0x00, 0x07, 0xB1]), coils(1969));
    let registers = Err(QuantityOutOfRange { quantity: 124, min: 1, max: 123 });
    assert_eq!(Response::parse(&[0x10, 0x00, 0x00, 0x00, 0x7C]), registers);
    let overflow = Err(AddressOverflow { start: 0xFFFF, quantity: 2 });
    assert_eq!(Response::parse(&[0x10, 0xFF, 0xFF, 0x00, 0x02]), overflow);
}

#[test]
fn coils_trimmed_from_a_response_are_written_with_zero_padding() {
    // A master reads 8 coils, keeps 3, and writes them to another device.
    let response = body!(Response::parse(&[0x01, 0x01, 0xFF]).unwrap(), Response::ReadCoils);
    let coils = response.values().truncated(3).unwrap();
    let request = Request::WriteMultipleCoils(WriteCoils::new(0, coils).unwrap());
    assert_eq!(Pdu::Request(request).to_bytes(), [0x0F, 0x00, 0x00, 0x00, 0x03, 0x01, 0b0000_0111]);
}
