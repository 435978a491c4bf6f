//! Protocol data units: the function code and its data, independent of the transport.
//!
//! Spec: MODBUS Application Protocol V1.1b3 §4.1 (the PDU, at most 253 bytes) and §6 (one
//! section per function code). Read those first; each body type names its section.
//!
//! # Contract
//!
//! - [`Request::parse`] and [`Response::parse`] accept any byte slice and never panic. They
//!   return a value only if the whole slice is exactly one PDU that the spec allows: counts in
//!   range, byte counts consistent with counts, no bytes left over.
//! - Values that carry an invariant (a quantity range, a byte count) can only be built through
//!   constructors that check it, so [`Request::emit`] cannot produce a PDU the spec forbids.
//!   Emitting fails only when the output buffer is too small ([`BufferTooSmall`]); the length
//!   to reserve is [`Request::encoded_len`] (at most [`MAX_PDU_LEN`]).
//! - `parse(emit(x)) == x` for every value; the property tests in `tests.rs` check it for every
//!   function code. The other way round, `emit(parse(bytes)) == bytes` for every accepted PDU
//!   but 0x0F requests, which are emitted the spec's way: the unused bits of the last coil byte
//!   as zeros, and without the padding byte some inverters add to the byte count.
//! - Parsed values borrow their data from the input slice: nothing is copied or allocated.
//!
//! # Layout of the code
//!
//! Each function code's request and response is a type implementing the crate-private
//! `Body` trait (parse, emit, length, and the prediction of its length on the wire for RTU
//! framing). The single table in this file maps function codes to those types and generates
//! every dispatch from it, so the per-function logic is written exactly once.

mod bits;
mod data;
mod diag;
mod file;
mod mei;
mod registers;
mod span;
#[cfg(test)]
mod tests;

use core::fmt;

pub use bits::{ReadBits, WriteCoil, WriteCoils};
pub use data::{BitIter, Bits, RegisterIter, Registers};
pub use diag::{CommEventCounter, CommEventLog, Diagnostic, ExceptionStatus, ServerId};
pub use file::{
    FifoValues, FileRecordReads, FileRecordRef, FileRecordWrite, FileRecordWrites, FileSubResponses, REFERENCE_TYPE,
    ReadFifo,
};
pub use mei::{DeviceIdentification, DeviceObject, DeviceObjects, MeiRequest, MeiResponse, RawMei, ReadDeviceId};
pub use registers::{
    BitValues, MaskWrite, ReadRegisters, ReadWriteRegisters, RegisterValues, WriteRegister, WriteRegisters,
    WrittenCoils, WrittenRegisters,
};
pub use span::AddressRange;

use crate::codes::{ExceptionCode, FunctionCode};
use crate::cursor::{Reader, Writer};
use crate::error::{BufferTooSmall, PduError};

/// The largest PDU: 253 bytes, function code included (§4.1).
pub const MAX_PDU_LEN: usize = 253;

/// The largest data part of a PDU, after the function code.
pub const MAX_DATA_LEN: usize = MAX_PDU_LEN - 1;

/// What the bytes received so far say about the length of a PDU body on the wire. RTU has no
/// length field, so the receiver asks the function code (the same approach as every RTU
/// stack), and falls back to the silent interval where the code cannot tell.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum WireLen {
    /// The body is exactly this many bytes (after the function code).
    Known(usize),
    /// More bytes are needed before the length can be told.
    NeedMore,
    /// The body is usually this long, but a longer one is legal (0x08 Return Query Data
    /// echoes any data): accept this length if the checksum agrees, else wait for the gap.
    Probable(usize),
    /// Only the silent interval can tell (custom function codes, CANopen references).
    Unknown,
}

/// One function code's body (the PDU after its function code): parse, emit, length, and the
/// prediction of its length from its first bytes. Implemented once per body type; every
/// dispatch over function codes is generated from the table below.
pub(crate) trait Body<'a>: Sized {
    /// Parses the body. The caller checks that every byte was read.
    fn parse(r: &mut Reader<'a>) -> Result<Self, PduError>;
    /// Writes the body.
    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall>;
    /// Bytes [`Body::emit`] writes.
    fn body_len(&self) -> usize;
    /// The body length on the wire, from the body bytes received so far.
    fn wire_len(head: &[u8]) -> WireLen;
}

/// A length field at `offset` of the body, followed by that many bytes: the layout of every
/// response with a byte count.
pub(crate) fn counted_len(head: &[u8], offset: usize) -> WireLen {
    match head.get(offset) {
        Some(&n) => WireLen::Known(offset.saturating_add(1).saturating_add(usize::from(n))),
        None => WireLen::NeedMore,
    }
}

/// Checks that `start + quantity - 1` stays within the 16-bit address space.
pub(crate) fn check_range(start: u16, quantity: u16) -> Result<(), PduError> {
    if u32::from(start).saturating_add(u32::from(quantity)) > 0x1_0000 {
        return Err(PduError::AddressOverflow { start, quantity });
    }
    Ok(())
}

/// Checks `min <= quantity <= max`.
pub(crate) fn check_quantity(quantity: usize, min: usize, max: usize) -> Result<(), PduError> {
    if quantity < min || quantity > max {
        return Err(PduError::QuantityOutOfRange { quantity, min, max });
    }
    Ok(())
}

/// Generates a body of a start address and a quantity of 1 to `$max` items within the address
/// space: the reads of 0x01–0x04 and the responses of 0x0F and 0x10.
macro_rules! range_body {
    ($(#[$meta:meta])* $name:ident, $max:literal) => {
        $(#[$meta])*
        #[derive(Clone, Copy, PartialEq, Eq, Debug)]
        pub struct $name {
            start: u16,
            quantity: u16,
        }

        impl $name {
            #[doc = concat!("The most items one PDU may carry: ", stringify!($max), ".")]
            pub const MAX: u16 = $max;

            #[doc = concat!("`quantity` (1–", stringify!($max), ") items from `start`, within the address space.")]
            pub fn new(start: u16, quantity: u16) -> Result<Self, PduError> {
                check_quantity(usize::from(quantity), 1, usize::from(Self::MAX))?;
                check_range(start, quantity)?;
                Ok($name { start, quantity })
            }

            /// First address.
            pub fn start(&self) -> u16 {
                self.start
            }

            /// Number of items.
            pub fn quantity(&self) -> u16 {
                self.quantity
            }
        }

        impl Body<'_> for $name {
            fn parse(r: &mut Reader<'_>) -> Result<Self, PduError> {
                let start = r.u16()?;
                $name::new(start, r.u16()?)
            }
            fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
                w.u16(self.start)?;
                w.u16(self.quantity)
            }
            fn body_len(&self) -> usize {
                4
            }
            fn wire_len(_: &[u8]) -> WireLen {
                WireLen::Known(4)
            }
        }
    };
}
pub(crate) use range_body;

/// A body with no data: the requests of 0x07, 0x0B, 0x0C and 0x11.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct NoData;

impl Body<'_> for NoData {
    fn parse(_: &mut Reader<'_>) -> Result<Self, PduError> {
        Ok(NoData)
    }
    fn emit(&self, _: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        Ok(())
    }
    fn body_len(&self) -> usize {
        0
    }
    fn wire_len(_: &[u8]) -> WireLen {
        WireLen::Known(0)
    }
}

/// A PDU with a function code the spec does not define, carried as raw bytes.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Custom<'a> {
    function: u8,
    data: &'a [u8],
}

impl<'a> Custom<'a> {
    /// A custom PDU. The function code must be 0x01–0x7F and not a public one, and the data at
    /// most [`MAX_DATA_LEN`] bytes.
    pub fn new(function: u8, data: &'a [u8]) -> Result<Self, PduError> {
        let code = FunctionCode::from_u8(function);
        if code.is_public() || !code.is_valid_request_code() {
            return Err(PduError::InvalidFunctionCode(function));
        }
        if data.len() > MAX_DATA_LEN {
            return Err(PduError::TooLong { len: data.len().saturating_add(1) });
        }
        Ok(Custom { function, data })
    }

    /// The function code.
    pub fn function(&self) -> u8 {
        self.function
    }

    /// The data after the function code.
    pub fn data(&self) -> &'a [u8] {
        self.data
    }
}

/// The response a server sends instead of a normal one (§7): the function code with bit 7
/// set, then one exception code.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct ExceptionResponse {
    function: FunctionCode,
    code: ExceptionCode,
}

impl ExceptionResponse {
    /// A refusal of a request with `function` (0x01–0x7F).
    pub fn new(function: FunctionCode, code: ExceptionCode) -> Result<Self, PduError> {
        if !function.is_valid_request_code() {
            return Err(PduError::InvalidFunctionCode(function.value()));
        }
        Ok(ExceptionResponse { function, code })
    }

    /// The function code of the request (without the exception bit).
    pub fn function(&self) -> FunctionCode {
        self.function
    }

    /// Why the server refused.
    pub fn code(&self) -> ExceptionCode {
        self.code
    }
}

impl fmt::Display for ExceptionResponse {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "exception {} to {}", self.code, self.function)
    }
}

/// Generates `Request` and `Response` and every dispatch over function codes from one table:
/// `Variant = FunctionCode => RequestBody, ResponseBody;`.
macro_rules! pdu_table {
    ($lt:lifetime; $( $(#[$meta:meta])* $variant:ident = $code:ident => $req:ty, $resp:ty; )+) => {
        /// A request PDU: one variant per public function code, plus [`Request::Custom`].
        #[derive(Clone, Copy, PartialEq, Eq, Debug)]
        pub enum Request<$lt> {
            $( $(#[$meta])* $variant($req), )+
            /// A function code the spec does not define.
            Custom(Custom<$lt>),
        }

        /// A response PDU: one variant per public function code, [`Response::Custom`], and
        /// [`Response::Exception`] for a refusal.
        #[derive(Clone, Copy, PartialEq, Eq, Debug)]
        pub enum Response<$lt> {
            $( $(#[$meta])* $variant($resp), )+
            /// A function code the spec does not define.
            Custom(Custom<$lt>),
            /// The server refused the request (§7).
            Exception(ExceptionResponse),
        }

        impl<$lt> Request<$lt> {
            /// The function code.
            pub fn function(&self) -> FunctionCode {
                match self {
                    $( Request::$variant(_) => FunctionCode::$code, )+
                    Request::Custom(c) => FunctionCode::from_u8(c.function),
                }
            }

            /// Parses a whole request PDU (function code first).
            pub fn parse(pdu: &$lt [u8]) -> Result<Self, PduError> {
                let (&fc, body) = pdu.split_first().ok_or(PduError::Empty)?;
                if pdu.len() > MAX_PDU_LEN {
                    return Err(PduError::TooLong { len: pdu.len() });
                }
                let mut r = Reader::new(body, 1);
                let request = match FunctionCode::from_u8(fc) {
                    $( FunctionCode::$code => Request::$variant(<$req as Body>::parse(&mut r)?), )+
                    FunctionCode::Custom(code) => Request::Custom(Custom::new(code, r.rest())?),
                };
                r.finish()?;
                Ok(request)
            }

            /// Bytes [`Request::emit`] writes, function code included.
            pub fn encoded_len(&self) -> usize {
                let body = match self {
                    $( Request::$variant(b) => b.body_len(), )+
                    Request::Custom(c) => c.data.len(),
                };
                body.saturating_add(1)
            }

            /// Writes the PDU into `out` and returns its length.
            pub fn emit(&self, out: &mut [u8]) -> Result<usize, BufferTooSmall> {
                let mut w = Writer::new(out);
                w.u8(self.function().value())?;
                match self {
                    $( Request::$variant(b) => b.emit(&mut w)?, )+
                    Request::Custom(c) => w.bytes(c.data)?,
                }
                Ok(w.position())
            }

            /// The body length on the wire of a request with function code `function`, from the
            /// body bytes received so far.
            pub fn wire_len(function: u8, head: &[u8]) -> WireLen {
                match FunctionCode::from_u8(function) {
                    $( FunctionCode::$code => <$req as Body>::wire_len(head), )+
                    FunctionCode::Custom(_) => WireLen::Unknown,
                }
            }
        }

        impl<$lt> Response<$lt> {
            /// The function code (of the request, for an exception).
            pub fn function(&self) -> FunctionCode {
                match self {
                    $( Response::$variant(_) => FunctionCode::$code, )+
                    Response::Custom(c) => FunctionCode::from_u8(c.function),
                    Response::Exception(e) => e.function,
                }
            }

            /// Parses a whole response PDU (function code first). A code with bit 7 set is an
            /// exception response.
            pub fn parse(pdu: &$lt [u8]) -> Result<Self, PduError> {
                let (&fc, body) = pdu.split_first().ok_or(PduError::Empty)?;
                if pdu.len() > MAX_PDU_LEN {
                    return Err(PduError::TooLong { len: pdu.len() });
                }
                let mut r = Reader::new(body, 1);
                let response = if fc & FunctionCode::EXCEPTION_BIT != 0 {
                    let function = FunctionCode::from_u8(fc & !FunctionCode::EXCEPTION_BIT);
                    if !function.is_valid_request_code() {
                        return Err(PduError::InvalidFunctionCode(fc));
                    }
                    Response::Exception(ExceptionResponse { function, code: ExceptionCode::from_u8(r.u8()?) })
                } else {
                    match FunctionCode::from_u8(fc) {
                        $( FunctionCode::$code => Response::$variant(<$resp as Body>::parse(&mut r)?), )+
                        FunctionCode::Custom(code) => Response::Custom(Custom::new(code, r.rest())?),
                    }
                };
                r.finish()?;
                Ok(response)
            }

            /// Bytes [`Response::emit`] writes, function code included.
            pub fn encoded_len(&self) -> usize {
                let body = match self {
                    $( Response::$variant(b) => b.body_len(), )+
                    Response::Custom(c) => c.data.len(),
                    Response::Exception(_) => 1,
                };
                body.saturating_add(1)
            }

            /// Writes the PDU into `out` and returns its length.
            pub fn emit(&self, out: &mut [u8]) -> Result<usize, BufferTooSmall> {
                let mut w = Writer::new(out);
                match self {
                    Response::Exception(e) => {
                        w.u8(e.function.value() | FunctionCode::EXCEPTION_BIT)?;
                        w.u8(e.code.value())?;
                    }
                    $( Response::$variant(b) => {
                        w.u8(FunctionCode::$code.value())?;
                        b.emit(&mut w)?;
                    } )+
                    Response::Custom(c) => {
                        w.u8(c.function)?;
                        w.bytes(c.data)?;
                    }
                }
                Ok(w.position())
            }

            /// The body length on the wire of a response with function code `function` (bit 7
            /// set for an exception), from the body bytes received so far.
            pub fn wire_len(function: u8, head: &[u8]) -> WireLen {
                if function & FunctionCode::EXCEPTION_BIT != 0 {
                    return WireLen::Known(1);
                }
                match FunctionCode::from_u8(function) {
                    $( FunctionCode::$code => <$resp as Body>::wire_len(head), )+
                    FunctionCode::Custom(_) => WireLen::Unknown,
                }
            }
        }
    };
}

pdu_table! { 'a;
    /// 0x01 Read Coils.
    ReadCoils = ReadCoils => ReadBits, BitValues<'a>;
    /// 0x02 Read Discrete Inputs.
    ReadDiscreteInputs = ReadDiscreteInputs => ReadBits, BitValues<'a>;
    /// 0x03 Read Holding Registers.
    ReadHoldingRegisters = ReadHoldingRegisters => ReadRegisters, RegisterValues<'a>;
    /// 0x04 Read Input Registers.
    ReadInputRegisters = ReadInputRegisters => ReadRegisters, RegisterValues<'a>;
    /// 0x05 Write Single Coil; the response echoes the request.
    WriteSingleCoil = WriteSingleCoil => WriteCoil, WriteCoil;
    /// 0x06 Write Single Register; the response echoes the request.
    WriteSingleRegister = WriteSingleRegister => WriteRegister, WriteRegister;
    /// 0x07 Read Exception Status.
    ReadExceptionStatus = ReadExceptionStatus => NoData, ExceptionStatus;
    /// 0x08 Diagnostics.
    Diagnostics = Diagnostics => Diagnostic<'a>, Diagnostic<'a>;
    /// 0x0B Get Comm Event Counter.
    GetCommEventCounter = GetCommEventCounter => NoData, CommEventCounter;
    /// 0x0C Get Comm Event Log.
    GetCommEventLog = GetCommEventLog => NoData, CommEventLog<'a>;
    /// 0x0F Write Multiple Coils.
    WriteMultipleCoils = WriteMultipleCoils => WriteCoils<'a>, WrittenCoils;
    /// 0x10 Write Multiple Registers.
    WriteMultipleRegisters = WriteMultipleRegisters => WriteRegisters<'a>, WrittenRegisters;
    /// 0x11 Report Server ID.
    ReportServerId = ReportServerId => NoData, ServerId<'a>;
    /// 0x14 Read File Record.
    ReadFileRecord = ReadFileRecord => FileRecordReads<'a>, FileSubResponses<'a>;
    /// 0x15 Write File Record; the response echoes the request.
    WriteFileRecord = WriteFileRecord => FileRecordWrites<'a>, FileRecordWrites<'a>;
    /// 0x16 Mask Write Register; the response echoes the request.
    MaskWriteRegister = MaskWriteRegister => MaskWrite, MaskWrite;
    /// 0x17 Read/Write Multiple Registers.
    ReadWriteMultipleRegisters = ReadWriteMultipleRegisters => ReadWriteRegisters<'a>, RegisterValues<'a>;
    /// 0x18 Read FIFO Queue.
    ReadFifoQueue = ReadFifoQueue => ReadFifo, FifoValues<'a>;
    /// 0x2B Encapsulated Interface Transport (0x0E Read Device Identification, 0x0D CANopen).
    EncapsulatedInterface = EncapsulatedInterface => MeiRequest<'a>, MeiResponse<'a>;
}

impl Response<'_> {
    /// The exception, if this is an exception response.
    pub fn exception(&self) -> Option<ExceptionResponse> {
        match self {
            Response::Exception(e) => Some(*e),
            _ => None,
        }
    }
}

/// `0x03 Read Holding Registers` and the like: the function code, for logs.
impl fmt::Display for Request<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(&self.function(), f)
    }
}
