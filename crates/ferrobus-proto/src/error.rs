//! The errors of the core: small `Copy` enums that carry the data needed to explain them.
//!
//! "The device answered with an exception" is never an error here: it is a
//! [`Response::Exception`](crate::pdu::Response::Exception) on the wire and a
//! [`Completion::Exception`](crate::master::Completion::Exception) in the master.
//! These types describe what *we* could not do: parse a PDU, fit it in a buffer, frame it.

use core::fmt;

use crate::codes::ExceptionCode;

/// Why a PDU could not be parsed or built.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[non_exhaustive]
pub enum PduError {
    /// The PDU is empty: not even a function code.
    Empty,
    /// The PDU ends before its layout does.
    Truncated {
        /// Bytes the layout needs (counting from the function code).
        needed: usize,
        /// Bytes present.
        available: usize,
    },
    /// Bytes follow the end of the layout.
    TrailingBytes {
        /// How many.
        extra: usize,
    },
    /// Zero, or a code with the exception bit set, where a request function code belongs.
    InvalidFunctionCode(u8),
    /// A quantity outside the spec's range for this function code.
    QuantityOutOfRange {
        /// The quantity given.
        quantity: usize,
        /// The smallest allowed.
        min: usize,
        /// The largest allowed.
        max: usize,
    },
    /// A byte count that disagrees with the quantity or the data present.
    ByteCountMismatch {
        /// The byte count declared (or implied by the data).
        declared: usize,
        /// The byte count the quantity calls for.
        expected: usize,
    },
    /// Start address + quantity runs past address 0xFFFF.
    AddressOverflow {
        /// First address.
        start: u16,
        /// Number of items.
        quantity: u16,
    },
    /// A 0x05 Write Single Coil value other than 0xFF00 (ON) or 0x0000 (OFF).
    InvalidCoilValue(u16),
    /// A file-record reference type other than 6 (§6.14).
    InvalidReferenceType(u8),
    /// A field holds a value the spec does not allow; the name says which field.
    InvalidField {
        /// The field, e.g. `"more follows"`.
        field: &'static str,
        /// The value found.
        value: u16,
    },
    /// The PDU would exceed 253 bytes (MODBUS Application Protocol V1.1b3 §4.1).
    TooLong {
        /// Its length.
        len: usize,
    },
}

impl PduError {
    /// The exception a server answers this malformed request with (§7, "exception code 03 for
    /// a quantity or byte count out of range", 02 for an address past the end).
    pub const fn exception_code(self) -> ExceptionCode {
        match self {
            PduError::InvalidFunctionCode(_) => ExceptionCode::IllegalFunction,
            PduError::AddressOverflow { .. } => ExceptionCode::IllegalDataAddress,
            _ => ExceptionCode::IllegalDataValue,
        }
    }
}

impl fmt::Display for PduError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            PduError::Empty => f.write_str("empty PDU"),
            PduError::Truncated { needed, available } => {
                write!(f, "PDU truncated: {available} bytes, the layout needs {needed}")
            }
            PduError::TrailingBytes { extra } => {
                write!(f, "{extra} unexpected bytes after the PDU")
            }
            PduError::InvalidFunctionCode(code) => {
                write!(f, "0x{code:02X} is not a request function code")
            }
            PduError::QuantityOutOfRange { quantity, min, max } => {
                write!(f, "quantity {quantity} outside {min}..={max}")
            }
            PduError::ByteCountMismatch { declared, expected } => {
                write!(f, "byte count {declared}, expected {expected}")
            }
            PduError::AddressOverflow { start, quantity } => {
                write!(f, "{quantity} items from address {start} run past 65535")
            }
            PduError::InvalidCoilValue(v) => {
                write!(f, "coil value 0x{v:04X} is neither 0xFF00 nor 0x0000")
            }
            PduError::InvalidReferenceType(t) => write!(f, "file reference type {t}, must be 6"),
            PduError::InvalidField { field, value } => write!(f, "invalid {field}: 0x{value:02X}"),
            PduError::TooLong { len } => write!(f, "PDU of {len} bytes exceeds 253"),
        }
    }
}

impl core::error::Error for PduError {}

/// An output buffer too small for what was to be written into it.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct BufferTooSmall {
    /// Bytes needed.
    pub needed: usize,
    /// Bytes available.
    pub available: usize,
}

impl fmt::Display for BufferTooSmall {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "buffer of {} bytes, {} needed", self.available, self.needed)
    }
}

impl core::error::Error for BufferTooSmall {}

/// Why a receiver threw bytes away. Never fatal: the receiver counts it and resyncs.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[non_exhaustive]
pub enum DiscardReason {
    /// The CRC (RTU) or LRC (ASCII) did not match.
    ChecksumMismatch,
    /// A silent interval came before the frame was long enough to be one.
    TooShort,
    /// More bytes than the largest frame, with no frame boundary found.
    TooLong,
    /// A gap longer than t1.5 inside a frame (strict RTU timing only).
    InterCharacterGap,
    /// Bytes that could not start a frame: noise before a frame or between frames, or an
    /// ASCII frame without its `:`.
    Noise,
    /// An ASCII frame with a character that is not a hex digit, or an odd number of them.
    BadEncoding,
    /// An MBAP header with a non-zero protocol id or an impossible length.
    BadHeader,
}

impl fmt::Display for DiscardReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            DiscardReason::ChecksumMismatch => "checksum mismatch",
            DiscardReason::TooShort => "frame too short",
            DiscardReason::TooLong => "frame too long",
            DiscardReason::InterCharacterGap => "gap longer than t1.5 inside a frame",
            DiscardReason::Noise => "noise between frames",
            DiscardReason::BadEncoding => "invalid ASCII encoding",
            DiscardReason::BadHeader => "invalid MBAP header",
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn malformed_requests_map_to_the_spec_exceptions() {
        let quantity = PduError::QuantityOutOfRange { quantity: 0, min: 1, max: 125 };
        assert_eq!(quantity.exception_code(), ExceptionCode::IllegalDataValue);
        let overflow = PduError::AddressOverflow { start: 0xFFFF, quantity: 2 };
        assert_eq!(overflow.exception_code(), ExceptionCode::IllegalDataAddress);
        assert_eq!(PduError::InvalidFunctionCode(0).exception_code(), ExceptionCode::IllegalFunction);
        assert_eq!(PduError::Truncated { needed: 5, available: 3 }.exception_code(), ExceptionCode::IllegalDataValue);
    }
}
