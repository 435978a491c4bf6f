//! The serial-line management functions: 0x07 Read Exception Status, 0x08 Diagnostics,
//! 0x0B Get Comm Event Counter, 0x0C Get Comm Event Log, 0x11 Report Server ID
//! (MODBUS Application Protocol V1.1b3 §6.7–6.10, §6.13).

use core::fmt;

use super::{Body, MAX_DATA_LEN, WireLen, check_quantity, counted_len};
use crate::codes::DiagnosticCode;
use crate::cursor::{Reader, Writer};
use crate::error::{BufferTooSmall, PduError};

/// The response to 0x07 Read Exception Status: eight device-specific status bits (§6.7).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct ExceptionStatus {
    /// The eight exception status outputs.
    pub status: u8,
}

impl Body<'_> for ExceptionStatus {
    fn parse(r: &mut Reader<'_>) -> Result<Self, PduError> {
        Ok(ExceptionStatus { status: r.u8()? })
    }
    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        w.u8(self.status)
    }
    fn body_len(&self) -> usize {
        1
    }
    fn wire_len(_: &[u8]) -> WireLen {
        WireLen::Known(1)
    }
}

/// A 0x08 Diagnostics request or response (§6.8): a sub-function and its data.
///
/// Every named sub-function but 0x00 carries one 16-bit word; 0x00 Return Query Data (and a
/// sub-function the spec does not name) carries any data, and its response echoes it, so on
/// RTU its length is found by the checksum or the gap.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct Diagnostic<'a> {
    sub_function: DiagnosticCode,
    data: DiagData<'a>,
}

#[derive(Clone, Copy, Debug)]
enum DiagData<'a> {
    Bytes(&'a [u8]),
    Word([u8; 2]),
}

impl DiagData<'_> {
    fn as_bytes(&self) -> &[u8] {
        match self {
            DiagData::Bytes(b) => b,
            DiagData::Word(w) => w,
        }
    }
}

impl PartialEq for DiagData<'_> {
    fn eq(&self, other: &Self) -> bool {
        self.as_bytes() == other.as_bytes()
    }
}

impl Eq for DiagData<'_> {}

impl<'a> Diagnostic<'a> {
    /// The most data bytes after the sub-function.
    pub const MAX_DATA: usize = MAX_DATA_LEN - 2;

    /// A sub-function with one data word: what every sub-function but 0x00 carries.
    pub const fn with_word(sub_function: DiagnosticCode, word: u16) -> Self {
        Diagnostic { sub_function, data: DiagData::Word(word.to_be_bytes()) }
    }

    /// A sub-function with its data: any data (at most 250 bytes) for 0x00 Return Query Data
    /// and for sub-functions the spec does not name; exactly one word for the others.
    pub fn with_data(sub_function: DiagnosticCode, data: &'a [u8]) -> Result<Self, PduError> {
        if takes_one_word(sub_function) && data.len() != 2 {
            return Err(if data.len() < 2 {
                PduError::Truncated { needed: 5, available: data.len().saturating_add(3) }
            } else {
                PduError::TrailingBytes { extra: data.len().saturating_sub(2) }
            });
        }
        check_quantity(data.len(), 0, Self::MAX_DATA)
            .map_err(|_| PduError::TooLong { len: data.len().saturating_add(3) })?;
        Ok(Diagnostic { sub_function, data: DiagData::Bytes(data) })
    }

    /// The sub-function.
    pub fn sub_function(&self) -> DiagnosticCode {
        self.sub_function
    }

    /// The data after the sub-function.
    pub fn data(&self) -> &[u8] {
        self.data.as_bytes()
    }

    /// The data as one word, if it is exactly two bytes.
    pub fn word(&self) -> Option<u16> {
        match *self.data() {
            [hi, lo] => Some(u16::from_be_bytes([hi, lo])),
            _ => None,
        }
    }
}

impl fmt::Debug for Diagnostic<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Diagnostic").field("sub_function", &self.sub_function).field("data", &self.data()).finish()
    }
}

impl<'a> Body<'a> for Diagnostic<'a> {
    fn parse(r: &mut Reader<'a>) -> Result<Self, PduError> {
        let sub_function = DiagnosticCode::from_u16(r.u16()?);
        Diagnostic::with_data(sub_function, r.rest())
    }
    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        w.u16(self.sub_function.value())?;
        w.bytes(self.data())
    }
    fn body_len(&self) -> usize {
        2usize.saturating_add(self.data().len())
    }
    fn wire_len(head: &[u8]) -> WireLen {
        match head {
            [hi, lo, ..] if takes_one_word(DiagnosticCode::from_u16(u16::from_be_bytes([*hi, *lo]))) => {
                WireLen::Known(4)
            }
            [_, _, ..] => WireLen::Probable(4),
            _ => WireLen::NeedMore,
        }
    }
}

/// Whether a sub-function carries exactly one data word: every one the spec names but 0x00.
fn takes_one_word(sub: DiagnosticCode) -> bool {
    sub.name().is_some() && sub != DiagnosticCode::ReturnQueryData
}

/// The response to 0x0B Get Comm Event Counter (§6.9).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct CommEventCounter {
    /// 0xFFFF while a previous command is still being processed, else 0x0000.
    pub status: u16,
    /// Messages completed successfully since the last restart.
    pub event_count: u16,
}

impl Body<'_> for CommEventCounter {
    fn parse(r: &mut Reader<'_>) -> Result<Self, PduError> {
        Ok(CommEventCounter { status: r.u16()?, event_count: r.u16()? })
    }
    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        w.u16(self.status)?;
        w.u16(self.event_count)
    }
    fn body_len(&self) -> usize {
        4
    }
    fn wire_len(_: &[u8]) -> WireLen {
        WireLen::Known(4)
    }
}

/// The response to 0x0C Get Comm Event Log (§6.10): status, counters and up to 64 event
/// bytes, most recent first.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct CommEventLog<'a> {
    status: u16,
    event_count: u16,
    message_count: u16,
    events: &'a [u8],
}

impl<'a> CommEventLog<'a> {
    /// The most events a log response carries.
    pub const MAX_EVENTS: usize = 64;

    /// A log response; `events` holds at most 64 bytes, most recent first.
    pub fn new(status: u16, event_count: u16, message_count: u16, events: &'a [u8]) -> Result<Self, PduError> {
        check_quantity(events.len(), 0, Self::MAX_EVENTS)?;
        Ok(CommEventLog { status, event_count, message_count, events })
    }

    /// 0xFFFF while busy, else 0x0000.
    pub fn status(&self) -> u16 {
        self.status
    }

    /// The comm event counter (as 0x0B returns it).
    pub fn event_count(&self) -> u16 {
        self.event_count
    }

    /// Messages processed since the last restart (the bus message count).
    pub fn message_count(&self) -> u16 {
        self.message_count
    }

    /// The event bytes, most recent first.
    pub fn events(&self) -> &'a [u8] {
        self.events
    }
}

impl<'a> Body<'a> for CommEventLog<'a> {
    fn parse(r: &mut Reader<'a>) -> Result<Self, PduError> {
        let byte_count = usize::from(r.u8()?);
        check_quantity(byte_count, 6, 6 + Self::MAX_EVENTS)?;
        let status = r.u16()?;
        let event_count = r.u16()?;
        let message_count = r.u16()?;
        let events = r.bytes(byte_count.saturating_sub(6))?;
        CommEventLog::new(status, event_count, message_count, events)
    }
    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        w.u8(u8::try_from(self.events.len().saturating_add(6)).unwrap_or(u8::MAX))?;
        w.u16(self.status)?;
        w.u16(self.event_count)?;
        w.u16(self.message_count)?;
        w.bytes(self.events)
    }
    fn body_len(&self) -> usize {
        7usize.saturating_add(self.events.len())
    }
    fn wire_len(head: &[u8]) -> WireLen {
        counted_len(head, 0)
    }
}

/// The response to 0x11 Report Server ID (§6.13): a byte count, then device-specific bytes —
/// the server id, the run indicator (0x00 OFF, 0xFF ON), and any additional data. Where one
/// ends and the next begins is up to the device, so the bytes are kept whole.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct ServerId<'a> {
    data: &'a [u8],
}

impl<'a> ServerId<'a> {
    /// The most bytes after the byte count.
    pub const MAX: usize = MAX_DATA_LEN - 1;

    /// A response carrying `data` (1–251 bytes).
    pub fn new(data: &'a [u8]) -> Result<Self, PduError> {
        check_quantity(data.len(), 1, Self::MAX)?;
        Ok(ServerId { data })
    }

    /// The bytes after the byte count.
    pub fn data(&self) -> &'a [u8] {
        self.data
    }
}

impl<'a> Body<'a> for ServerId<'a> {
    fn parse(r: &mut Reader<'a>) -> Result<Self, PduError> {
        let byte_count = usize::from(r.u8()?);
        ServerId::new(r.bytes(byte_count)?)
    }
    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        w.u8(u8::try_from(self.data.len()).unwrap_or(u8::MAX))?;
        w.bytes(self.data)
    }
    fn body_len(&self) -> usize {
        1usize.saturating_add(self.data.len())
    }
    fn wire_len(head: &[u8]) -> WireLen {
        counted_len(head, 0)
    }
}
