//! Extended memory: 0x14 Read File Record, 0x15 Write File Record, 0x18 Read FIFO Queue
//! (MODBUS Application Protocol V1.1b3 §6.14, §6.15, §6.18).
//!
//! A file record request is a list of sub-requests, each naming a file, a record (register)
//! number in it, and a length in registers. The reference type of every sub-request and
//! sub-response is 6. The limits here keep every request *and its response* within one PDU.

use core::fmt;

use super::{Body, Registers, WireLen, check_quantity, counted_len};
use crate::cursor::{Reader, Writer};
use crate::error::{BufferTooSmall, PduError};

/// The reference type every file sub-request and sub-response carries (§6.14).
pub const REFERENCE_TYPE: u8 = 6;

/// The largest byte count of a read request and of either response: 0xF5 (§6.14).
const MAX_READ_BYTES: usize = 0xF5;

/// The largest request data length of a write request: 0xFB (§6.15).
const MAX_WRITE_BYTES: usize = 0xFB;

fn reference_type(r: &mut Reader<'_>) -> Result<(), PduError> {
    match r.u8()? {
        REFERENCE_TYPE => Ok(()),
        other => Err(PduError::InvalidReferenceType(other)),
    }
}

/// One sub-request of 0x14: read `length` registers from `record` of `file`.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct FileRecordRef {
    /// File number.
    pub file: u16,
    /// First record (register) number in the file.
    pub record: u16,
    /// Number of registers.
    pub length: u16,
}

/// The sub-requests of a 0x14 Read File Record request.
#[derive(Clone, Copy)]
pub struct FileRecordReads<'a> {
    repr: ReadsRepr<'a>,
}

#[derive(Clone, Copy)]
enum ReadsRepr<'a> {
    /// Whole 7-byte sub-requests, already validated.
    Wire(&'a [u8]),
    Values(&'a [FileRecordRef]),
}

impl<'a> FileRecordReads<'a> {
    /// A request for `refs`: at least one, each of at least one register, with the request and
    /// its response each within 245 bytes.
    pub fn new(refs: &'a [FileRecordRef]) -> Result<Self, PduError> {
        let reads = FileRecordReads { repr: ReadsRepr::Values(refs) };
        reads.validate()?;
        Ok(reads)
    }

    fn validate(&self) -> Result<(), PduError> {
        check_quantity(self.byte_count(), 7, MAX_READ_BYTES)?;
        let mut response = 0usize;
        for r in self.iter() {
            check_quantity(usize::from(r.length), 1, MAX_READ_BYTES)?;
            response = response.saturating_add(2).saturating_add(usize::from(r.length).saturating_mul(2));
        }
        check_quantity(response, 1, MAX_READ_BYTES)
            .map_err(|_| PduError::ByteCountMismatch { declared: response, expected: MAX_READ_BYTES })
    }

    /// Number of sub-requests.
    pub fn len(&self) -> usize {
        match self.repr {
            ReadsRepr::Wire(b) => b.len() / 7,
            ReadsRepr::Values(v) => v.len(),
        }
    }

    /// Whether there are none (never true for a valid request).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn byte_count(&self) -> usize {
        self.len().saturating_mul(7)
    }

    /// The sub-request at `index`.
    pub fn get(&self, index: usize) -> Option<FileRecordRef> {
        match self.repr {
            ReadsRepr::Wire(b) => {
                let at = index.checked_mul(7)?;
                match *b.get(at..at.checked_add(7)?)? {
                    [_, f0, f1, r0, r1, l0, l1] => Some(FileRecordRef {
                        file: u16::from_be_bytes([f0, f1]),
                        record: u16::from_be_bytes([r0, r1]),
                        length: u16::from_be_bytes([l0, l1]),
                    }),
                    _ => None,
                }
            }
            ReadsRepr::Values(v) => v.get(index).copied(),
        }
    }

    /// The sub-requests in order.
    pub fn iter(&self) -> impl Iterator<Item = FileRecordRef> + 'a {
        let this = *self;
        (0..this.len()).filter_map(move |i| this.get(i))
    }
}

impl PartialEq for FileRecordReads<'_> {
    fn eq(&self, other: &Self) -> bool {
        self.len() == other.len() && self.iter().eq(other.iter())
    }
}

impl Eq for FileRecordReads<'_> {}

impl fmt::Debug for FileRecordReads<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

impl<'a> Body<'a> for FileRecordReads<'a> {
    fn parse(r: &mut Reader<'a>) -> Result<Self, PduError> {
        let byte_count = usize::from(r.u8()?);
        check_quantity(byte_count, 7, MAX_READ_BYTES)?;
        if byte_count % 7 != 0 {
            return Err(PduError::ByteCountMismatch {
                declared: byte_count,
                expected: byte_count.saturating_sub(byte_count % 7),
            });
        }
        let bytes = r.bytes(byte_count)?;
        let mut check = Reader::new(bytes, 2);
        while check.remaining() > 0 {
            reference_type(&mut check)?;
            check.bytes(6)?;
        }
        let reads = FileRecordReads { repr: ReadsRepr::Wire(bytes) };
        reads.validate()?;
        Ok(reads)
    }
    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        w.u8(u8::try_from(self.byte_count()).unwrap_or(u8::MAX))?;
        for r in self.iter() {
            w.u8(REFERENCE_TYPE)?;
            w.u16(r.file)?;
            w.u16(r.record)?;
            w.u16(r.length)?;
        }
        Ok(())
    }
    fn body_len(&self) -> usize {
        1usize.saturating_add(self.byte_count())
    }
    fn wire_len(head: &[u8]) -> WireLen {
        counted_len(head, 0)
    }
}

/// The sub-responses of a 0x14 Read File Record response: one register list per sub-request.
#[derive(Clone, Copy)]
pub struct FileSubResponses<'a> {
    repr: SubResponsesRepr<'a>,
}

#[derive(Clone, Copy)]
enum SubResponsesRepr<'a> {
    /// Whole sub-responses (length, reference type, data), already validated.
    Wire(&'a [u8]),
    Values(&'a [Registers<'a>]),
}

impl<'a> FileSubResponses<'a> {
    /// A response carrying one register list (of at least one register) per sub-request,
    /// within 245 bytes in all.
    pub fn new(records: &'a [Registers<'a>]) -> Result<Self, PduError> {
        let mut total = 0usize;
        for r in records {
            check_quantity(r.len(), 1, MAX_READ_BYTES)?;
            total = total.saturating_add(2).saturating_add(r.byte_len());
        }
        check_quantity(total, 2, MAX_READ_BYTES)?;
        Ok(FileSubResponses { repr: SubResponsesRepr::Values(records) })
    }

    fn byte_count(&self) -> usize {
        match self.repr {
            SubResponsesRepr::Wire(b) => b.len(),
            SubResponsesRepr::Values(v) => {
                v.iter().fold(0usize, |n, r| n.saturating_add(2).saturating_add(r.byte_len()))
            }
        }
    }

    /// The register lists in order.
    pub fn iter(&self) -> impl Iterator<Item = Registers<'a>> + 'a {
        let mut rest = match self.repr {
            SubResponsesRepr::Wire(b) => b,
            SubResponsesRepr::Values(_) => &[],
        };
        let values = match self.repr {
            SubResponsesRepr::Values(v) => v,
            SubResponsesRepr::Wire(_) => &[],
        };
        let wire = core::iter::from_fn(move || {
            // Validated at parse: each sub-response is `len, 6, data[len - 1]`.
            let (&len, tail) = rest.split_first()?;
            let body = tail.get(..usize::from(len))?;
            rest = tail.get(usize::from(len)..)?;
            Registers::from_wire(body.get(1..)?).ok()
        });
        wire.chain(values.iter().copied())
    }

    /// Number of sub-responses.
    pub fn len(&self) -> usize {
        self.iter().count()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

impl PartialEq for FileSubResponses<'_> {
    fn eq(&self, other: &Self) -> bool {
        self.iter().eq(other.iter())
    }
}

impl Eq for FileSubResponses<'_> {}

impl fmt::Debug for FileSubResponses<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

impl<'a> Body<'a> for FileSubResponses<'a> {
    fn parse(r: &mut Reader<'a>) -> Result<Self, PduError> {
        let byte_count = usize::from(r.u8()?);
        check_quantity(byte_count, 2, MAX_READ_BYTES)?;
        let bytes = r.bytes(byte_count)?;
        let mut check = Reader::new(bytes, 2);
        while check.remaining() > 0 {
            let len = usize::from(check.u8()?);
            // Reference type + at least one register: an odd length of 3 or more.
            if len % 2 == 0 || len < 3 {
                return Err(PduError::ByteCountMismatch { declared: len, expected: len.max(2).saturating_add(1) });
            }
            reference_type(&mut check)?;
            check.bytes(len.saturating_sub(1))?;
        }
        Ok(FileSubResponses { repr: SubResponsesRepr::Wire(bytes) })
    }
    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        w.u8(u8::try_from(self.byte_count()).unwrap_or(u8::MAX))?;
        match self.repr {
            SubResponsesRepr::Wire(b) => w.bytes(b),
            SubResponsesRepr::Values(v) => v.iter().try_for_each(|regs| {
                w.u8(u8::try_from(regs.byte_len().saturating_add(1)).unwrap_or(u8::MAX))?;
                w.u8(REFERENCE_TYPE)?;
                regs.emit(w)
            }),
        }
    }
    fn body_len(&self) -> usize {
        1usize.saturating_add(self.byte_count())
    }
    fn wire_len(head: &[u8]) -> WireLen {
        counted_len(head, 0)
    }
}

/// One sub-request of 0x15: write `data` from `record` of `file`.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct FileRecordWrite<'a> {
    /// File number.
    pub file: u16,
    /// First record (register) number in the file.
    pub record: u16,
    /// The registers to write (at least one).
    pub data: Registers<'a>,
}

/// The sub-requests of a 0x15 Write File Record request, and of its echo.
#[derive(Clone, Copy)]
pub struct FileRecordWrites<'a> {
    repr: WritesRepr<'a>,
}

#[derive(Clone, Copy)]
enum WritesRepr<'a> {
    /// Whole sub-requests (type, file, record, length, data), already validated.
    Wire(&'a [u8]),
    Values(&'a [FileRecordWrite<'a>]),
}

impl<'a> FileRecordWrites<'a> {
    /// A request writing `writes`: at least one, each of at least one register, within 251
    /// bytes in all.
    pub fn new(writes: &'a [FileRecordWrite<'a>]) -> Result<Self, PduError> {
        for w in writes {
            check_quantity(w.data.len(), 1, MAX_WRITE_BYTES)?;
        }
        let this = FileRecordWrites { repr: WritesRepr::Values(writes) };
        check_quantity(this.byte_count(), 9, MAX_WRITE_BYTES)?;
        Ok(this)
    }

    fn byte_count(&self) -> usize {
        match self.repr {
            WritesRepr::Wire(b) => b.len(),
            WritesRepr::Values(v) => {
                v.iter().fold(0usize, |n, w| n.saturating_add(7).saturating_add(w.data.byte_len()))
            }
        }
    }

    /// The sub-requests in order.
    pub fn iter(&self) -> impl Iterator<Item = FileRecordWrite<'a>> + 'a {
        let mut rest = match self.repr {
            WritesRepr::Wire(b) => b,
            WritesRepr::Values(_) => &[],
        };
        let values = match self.repr {
            WritesRepr::Values(v) => v,
            WritesRepr::Wire(_) => &[],
        };
        let wire = core::iter::from_fn(move || {
            // Validated at parse: `6, file, record, length, data[2 × length]`.
            let mut r = Reader::new(rest, 0);
            r.u8().ok()?;
            let file = r.u16().ok()?;
            let record = r.u16().ok()?;
            let length = usize::from(r.u16().ok()?);
            let data = Registers::from_wire(r.bytes(length.checked_mul(2)?).ok()?).ok()?;
            rest = r.rest();
            Some(FileRecordWrite { file, record, data })
        });
        wire.chain(values.iter().copied())
    }

    /// Number of sub-requests.
    pub fn len(&self) -> usize {
        self.iter().count()
    }

    /// Whether there are none (never true for a valid request).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

impl PartialEq for FileRecordWrites<'_> {
    fn eq(&self, other: &Self) -> bool {
        self.iter().eq(other.iter())
    }
}

impl Eq for FileRecordWrites<'_> {}

impl fmt::Debug for FileRecordWrites<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

impl<'a> Body<'a> for FileRecordWrites<'a> {
    fn parse(r: &mut Reader<'a>) -> Result<Self, PduError> {
        let byte_count = usize::from(r.u8()?);
        check_quantity(byte_count, 9, MAX_WRITE_BYTES)?;
        let bytes = r.bytes(byte_count)?;
        let mut check = Reader::new(bytes, 2);
        while check.remaining() > 0 {
            reference_type(&mut check)?;
            check.bytes(4)?;
            let length = usize::from(check.u16()?);
            check_quantity(length, 1, MAX_WRITE_BYTES)?;
            check.bytes(length.saturating_mul(2))?;
        }
        Ok(FileRecordWrites { repr: WritesRepr::Wire(bytes) })
    }
    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        w.u8(u8::try_from(self.byte_count()).unwrap_or(u8::MAX))?;
        match self.repr {
            WritesRepr::Wire(b) => w.bytes(b),
            WritesRepr::Values(v) => v.iter().try_for_each(|s| {
                w.u8(REFERENCE_TYPE)?;
                w.u16(s.file)?;
                w.u16(s.record)?;
                w.u16(u16::try_from(s.data.len()).unwrap_or(u16::MAX))?;
                s.data.emit(w)
            }),
        }
    }
    fn body_len(&self) -> usize {
        1usize.saturating_add(self.byte_count())
    }
    fn wire_len(head: &[u8]) -> WireLen {
        counted_len(head, 0)
    }
}

/// 0x18 Read FIFO Queue request: the FIFO pointer address (§6.18).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct ReadFifo {
    /// The FIFO pointer address.
    pub address: u16,
}

impl Body<'_> for ReadFifo {
    fn parse(r: &mut Reader<'_>) -> Result<Self, PduError> {
        Ok(ReadFifo { address: r.u16()? })
    }
    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        w.u16(self.address)
    }
    fn body_len(&self) -> usize {
        2
    }
    fn wire_len(_: &[u8]) -> WireLen {
        WireLen::Known(2)
    }
}

/// The response to 0x18: a two-byte byte count, the FIFO count (0–31), and the values.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct FifoValues<'a> {
    values: Registers<'a>,
}

impl<'a> FifoValues<'a> {
    /// The most values a FIFO response carries (§6.18: a count above 31 is exception 03).
    pub const MAX: usize = 31;

    /// A response carrying `values` (0–31 registers).
    pub fn new(values: Registers<'a>) -> Result<Self, PduError> {
        check_quantity(values.len(), 0, Self::MAX)?;
        Ok(FifoValues { values })
    }

    /// The queued values, oldest first.
    pub fn values(&self) -> Registers<'a> {
        self.values
    }
}

impl<'a> Body<'a> for FifoValues<'a> {
    fn parse(r: &mut Reader<'a>) -> Result<Self, PduError> {
        let byte_count = usize::from(r.u16()?);
        let count = usize::from(r.u16()?);
        check_quantity(count, 0, Self::MAX)?;
        let expected = count.saturating_mul(2).saturating_add(2);
        if byte_count != expected {
            return Err(PduError::ByteCountMismatch { declared: byte_count, expected });
        }
        FifoValues::new(Registers::from_wire(r.bytes(count.saturating_mul(2))?)?)
    }
    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        let count = u16::try_from(self.values.len()).unwrap_or(u16::MAX);
        w.u16(count.saturating_mul(2).saturating_add(2))?;
        w.u16(count)?;
        self.values.emit(w)
    }
    fn body_len(&self) -> usize {
        4usize.saturating_add(self.values.byte_len())
    }
    fn wire_len(head: &[u8]) -> WireLen {
        match head {
            [hi, lo, ..] => WireLen::Known(2usize.saturating_add(usize::from(u16::from_be_bytes([*hi, *lo])))),
            _ => WireLen::NeedMore,
        }
    }
}
