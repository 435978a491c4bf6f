//! The front end's check of every request PDU, before it is authorized, routed or queued: a
//! request that no device could take is answered at once and never reaches a line.
//!
//! Spec: MODBUS Application Protocol V1.1b3 §5 (the ranges of function codes) and §7 (the
//! exception codes). The check is the core's parser ([`Request::parse`]) and its function-code
//! table ([`FunctionCode`]); nothing is judged here by hand.
//!
//! | the request | answer |
//! |---|---|
//! | function code 0x00, or one with the exception bit (0x80–0xFF) | 0x01 Illegal Function |
//! | a code the spec reserves or leaves unassigned (e.g. 0x09, 0x29, 0x5A, 0x7F) | 0x01 |
//! | a public code with its fields missing, extra bytes, a count out of range, a byte count that disagrees, a value the spec forbids | 0x03 Illegal Data Value |
//! | a public code whose range runs past address 0xFFFF | 0x02 Illegal Data Address |
//! | a user-defined code, 65–72 (0x41–0x48) or 100–110 (0x64–0x6E) | forwarded as it came |
//!
//! The exception codes are the core's ([`PduError::exception_code`]), so the gateway answers
//! a malformed request as a ferrobus device would. User-defined codes are forwarded raw: they
//! are there for vendors, and only the device knows their layout; a device that ignores one
//! costs its sender a 0x0B, and never puts the unit in backoff for the other clients (see
//! [`Outcome::UncheckedTimeout`](ferrobus_proto::retry::Outcome::UncheckedTimeout)).

use std::fmt;

use ferrobus_proto::pdu::Request;
use ferrobus_proto::{ExceptionCode, FunctionCode, PduError};

/// How a request the front end refused was malformed: one counter each in the gateway's stats.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Debug)]
pub enum Malformed {
    /// No function code, 0x00, or one with the exception bit set: not a request at all.
    NotARequest,
    /// A code the spec reserves or leaves unassigned (neither public nor user-defined).
    Reserved,
    /// The PDU ends before its function's fields do.
    Truncated,
    /// Bytes after the end of the function's fields.
    TrailingBytes,
    /// A quantity outside the function's range.
    Quantity,
    /// A byte count that disagrees with the quantity or the data.
    ByteCount,
    /// A range that runs past address 0xFFFF.
    Address,
    /// A field with a value the spec does not allow (a coil value, a reference type, ...).
    Value,
    /// Longer than the 253 bytes of a PDU.
    TooLong,
}

impl Malformed {
    /// Every reason, in the order the stats show them.
    pub const ALL: [Malformed; 9] = [
        Malformed::NotARequest,
        Malformed::Reserved,
        Malformed::Truncated,
        Malformed::TrailingBytes,
        Malformed::Quantity,
        Malformed::ByteCount,
        Malformed::Address,
        Malformed::Value,
        Malformed::TooLong,
    ];

    /// The reason a parse error gives.
    fn of(error: PduError) -> Malformed {
        match error {
            PduError::Empty | PduError::InvalidFunctionCode(_) => Malformed::NotARequest,
            PduError::Truncated { .. } => Malformed::Truncated,
            PduError::TrailingBytes { .. } => Malformed::TrailingBytes,
            PduError::QuantityOutOfRange { .. } => Malformed::Quantity,
            PduError::ByteCountMismatch { .. } => Malformed::ByteCount,
            PduError::AddressOverflow { .. } => Malformed::Address,
            PduError::TooLong { .. } => Malformed::TooLong,
            _ => Malformed::Value,
        }
    }

    /// The name the stats show.
    pub fn name(self) -> &'static str {
        match self {
            Malformed::NotARequest => "not-a-request",
            Malformed::Reserved => "reserved-function",
            Malformed::Truncated => "truncated",
            Malformed::TrailingBytes => "trailing-bytes",
            Malformed::Quantity => "quantity",
            Malformed::ByteCount => "byte-count",
            Malformed::Address => "address",
            Malformed::Value => "value",
            Malformed::TooLong => "too-long",
        }
    }
}

impl fmt::Display for Malformed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A request the front end does not forward: why, and the exception that answers it.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) struct Refused {
    pub(crate) reason: Malformed,
    pub(crate) code: ExceptionCode,
}

/// Checks a request PDU (function code first): `Ok` forwards it, `Err` says why not and with
/// which exception it is answered instead.
pub(crate) fn check(pdu: &[u8]) -> Result<(), Refused> {
    match Request::parse(pdu) {
        Ok(request) => {
            if forwarded(request.function()) {
                Ok(())
            } else {
                Err(Refused { reason: Malformed::Reserved, code: ExceptionCode::IllegalFunction })
            }
        }
        // No function code at all is no request either: 01, like 0x00.
        Err(PduError::Empty) => Err(Refused { reason: Malformed::NotARequest, code: ExceptionCode::IllegalFunction }),
        Err(error) => Err(Refused { reason: Malformed::of(error), code: error.exception_code() }),
    }
}

/// Whether `function` is one the front end lets through when its PDU parses.
fn forwarded(function: FunctionCode) -> bool {
    function.is_public() || function.is_user_defined()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn refused(pdu: &[u8]) -> Option<(Malformed, u8)> {
        check(pdu).err().map(|r| (r.reason, r.code.value()))
    }

    #[test]
    fn over_all_256_function_codes_only_public_and_user_defined_ones_can_pass() {
        for v in 0..=u8::MAX {
            let code = FunctionCode::from_u8(v);
            // A body the public parsers reject or take; a user code takes anything.
            let outcome = refused(&[v, 0x00, 0x00, 0x00, 0x01]);
            if !code.is_valid_request_code() {
                assert_eq!(outcome, Some((Malformed::NotARequest, 0x01)), "{v:#04x}");
            } else if !forwarded(code) {
                assert_eq!(outcome, Some((Malformed::Reserved, 0x01)), "{v:#04x}");
            } else if code.is_user_defined() {
                assert_eq!(outcome, None, "{v:#04x}");
            } else {
                assert_ne!(outcome.map(|(r, _)| r), Some(Malformed::Reserved), "{v:#04x}");
            }
        }
    }

    #[test]
    fn malformed_public_requests_get_03_and_a_range_past_ffff_02() {
        assert_eq!(refused(&[0x03, 0x00, 0x00]), Some((Malformed::Truncated, 0x03)));
        assert_eq!(refused(&[0x03]), Some((Malformed::Truncated, 0x03)));
        assert_eq!(refused(&[0x03, 0x00, 0x00, 0x00, 0x01, 0x00]), Some((Malformed::TrailingBytes, 0x03)));
        assert_eq!(refused(&[0x03, 0x00, 0x00, 0x00, 0x00]), Some((Malformed::Quantity, 0x03)));
        assert_eq!(refused(&[0x03, 0x00, 0x00, 0x00, 0x7E]), Some((Malformed::Quantity, 0x03)));
        assert_eq!(refused(&[0x10, 0x00, 0x00, 0x00, 0x01, 0x04, 0x00, 0x01]), Some((Malformed::ByteCount, 0x03)));
        assert_eq!(refused(&[0x05, 0x00, 0x00, 0x12, 0x34]), Some((Malformed::Value, 0x03)));
        assert_eq!(refused(&[0x03, 0xFF, 0xFF, 0x00, 0x02]), Some((Malformed::Address, 0x02)));
        assert_eq!(refused(&[]), Some((Malformed::NotARequest, 0x01)));
        assert_eq!(refused(&[0x83, 0x02]), Some((Malformed::NotARequest, 0x01)));
        assert_eq!(refused(&[0x03, 0x00, 0x00, 0x00, 0x7D]), None);
        assert_eq!(refused(&[0x41]), None, "a user-defined code, even empty, is the device's to judge");
        assert_eq!(refused(&[0x6E, 1, 2, 3]), None);
    }

    #[test]
    fn every_reason_has_its_own_name() {
        let names: std::collections::BTreeSet<_> = Malformed::ALL.iter().map(|r| r.name()).collect();
        assert_eq!(names.len(), Malformed::ALL.len());
    }
}
