//! Register access and the read responses: 0x03 Read Holding Registers, 0x04 Read Input
//! Registers, 0x06 Write Single Register, 0x10 Write Multiple Registers, 0x16 Mask Write
//! Register, 0x17 Read/Write Multiple Registers, and the data of the 0x01/0x02 responses
//! (MODBUS Application Protocol V1.1b3 §6.1–6.4, §6.6, §6.11, §6.12, §6.16, §6.17).

use super::{Bits, Body, Registers, WireLen, check_quantity, check_range, counted_len, range_body};
use crate::cursor::{Reader, Writer};
use crate::error::{BufferTooSmall, PduError};

range_body!(
    /// A read of `quantity` registers from `start` (0x03, 0x04): 1–125 registers (§6.3).
    ReadRegisters,
    125
);

/// The registers of a read response (0x03, 0x04, 0x17): a byte count, then 1–125 registers.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct RegisterValues<'a> {
    values: Registers<'a>,
}

impl<'a> RegisterValues<'a> {
    /// A response carrying `values` (1–125 registers).
    pub fn new(values: Registers<'a>) -> Result<Self, PduError> {
        check_quantity(values.len(), 1, usize::from(ReadRegisters::MAX))?;
        Ok(RegisterValues { values })
    }

    /// The registers.
    pub fn values(&self) -> Registers<'a> {
        self.values
    }
}

impl<'a> Body<'a> for RegisterValues<'a> {
    fn parse(r: &mut Reader<'a>) -> Result<Self, PduError> {
        let byte_count = usize::from(r.u8()?);
        let values = Registers::from_wire(r.bytes(byte_count)?)?;
        RegisterValues::new(values)
    }
    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        w.u8(u8::try_from(self.values.byte_len()).unwrap_or(u8::MAX))?;
        self.values.emit(w)
    }
    fn body_len(&self) -> usize {
        1usize.saturating_add(self.values.byte_len())
    }
    fn wire_len(head: &[u8]) -> WireLen {
        counted_len(head, 0)
    }
}

/// The bits of a read response (0x01, 0x02): a byte count, then 1–250 bytes of packed bits.
///
/// The response carries whole bytes; which of the bits count depends on the request. A parsed
/// response therefore holds `8 × byte count` bits, and the master trims it to the quantity it
/// asked for (see [`Bits::truncated`]). Two values are equal when they put the same bytes on
/// the wire: three bits `101` equal the eight bits `10100000` they are sent as.
#[derive(Clone, Copy, Debug)]
pub struct BitValues<'a> {
    values: Bits<'a>,
}

impl<'a> BitValues<'a> {
    /// A response carrying `values` (1–2000 bits).
    pub fn new(values: Bits<'a>) -> Result<Self, PduError> {
        check_quantity(values.len(), 1, usize::from(super::ReadBits::MAX))?;
        Ok(BitValues { values })
    }

    /// The bits: a whole number of bytes' worth when parsed from the wire.
    pub fn values(&self) -> Bits<'a> {
        self.values
    }
}

impl PartialEq for BitValues<'_> {
    fn eq(&self, other: &Self) -> bool {
        let (a, b) = (self.values, other.values);
        let bits = a.byte_len().saturating_mul(8);
        a.byte_len() == b.byte_len() && (0..bits).all(|i| a.get(i).unwrap_or(false) == b.get(i).unwrap_or(false))
    }
}

impl Eq for BitValues<'_> {}

impl<'a> Body<'a> for BitValues<'a> {
    fn parse(r: &mut Reader<'a>) -> Result<Self, PduError> {
        let byte_count = usize::from(r.u8()?);
        // 2000 bits need 250 bytes; a larger count cannot come from a valid request.
        let max = usize::from(super::ReadBits::MAX).div_ceil(8);
        check_quantity(byte_count, 1, max)?;
        let bytes = r.bytes(byte_count)?;
        Ok(BitValues { values: Bits::from_wire(bytes, byte_count.saturating_mul(8))? })
    }
    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        w.u8(u8::try_from(self.values.byte_len()).unwrap_or(u8::MAX))?;
        self.values.emit(w)
    }
    fn body_len(&self) -> usize {
        1usize.saturating_add(self.values.byte_len())
    }
    fn wire_len(head: &[u8]) -> WireLen {
        counted_len(head, 0)
    }
}

/// 0x06 Write Single Register (§6.6). The response echoes the request.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct WriteRegister {
    /// Register address.
    pub address: u16,
    /// Value to write.
    pub value: u16,
}

impl Body<'_> for WriteRegister {
    fn parse(r: &mut Reader<'_>) -> Result<Self, PduError> {
        Ok(WriteRegister { address: r.u16()?, value: r.u16()? })
    }
    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        w.u16(self.address)?;
        w.u16(self.value)
    }
    fn body_len(&self) -> usize {
        4
    }
    fn wire_len(_: &[u8]) -> WireLen {
        WireLen::Known(4)
    }
}

/// 0x10 Write Multiple Registers: 1–123 registers from `start` (§6.12).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct WriteRegisters<'a> {
    start: u16,
    values: Registers<'a>,
}

impl<'a> WriteRegisters<'a> {
    /// The most registers one request may write.
    pub const MAX: u16 = 123;

    /// A write of `values` (1–123 registers) from `start`, within the address space.
    pub fn new(start: u16, values: Registers<'a>) -> Result<Self, PduError> {
        check_quantity(values.len(), 1, usize::from(Self::MAX))?;
        check_range(start, u16::try_from(values.len()).unwrap_or(u16::MAX))?;
        Ok(WriteRegisters { start, values })
    }

    /// First address.
    pub fn start(&self) -> u16 {
        self.start
    }

    /// The values.
    pub fn values(&self) -> Registers<'a> {
        self.values
    }

    /// Number of registers (at most 123).
    pub fn quantity(&self) -> u16 {
        u16::try_from(self.values.len()).unwrap_or(u16::MAX)
    }
}

impl<'a> Body<'a> for WriteRegisters<'a> {
    fn parse(r: &mut Reader<'a>) -> Result<Self, PduError> {
        let start = r.u16()?;
        let quantity = r.u16()?;
        check_quantity(usize::from(quantity), 1, usize::from(Self::MAX))?;
        let byte_count = usize::from(r.u8()?);
        let expected = usize::from(quantity).saturating_mul(2);
        if byte_count != expected {
            return Err(PduError::ByteCountMismatch { declared: byte_count, expected });
        }
        WriteRegisters::new(start, Registers::from_wire(r.bytes(byte_count)?)?)
    }
    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        w.u16(self.start)?;
        w.u16(self.quantity())?;
        w.u8(u8::try_from(self.values.byte_len()).unwrap_or(u8::MAX))?;
        self.values.emit(w)
    }
    fn body_len(&self) -> usize {
        5usize.saturating_add(self.values.byte_len())
    }
    fn wire_len(head: &[u8]) -> WireLen {
        counted_len(head, 4)
    }
}

range_body!(
    /// The response to 0x0F Write Multiple Coils (§6.11): 1–1968 coils from `start`.
    WrittenCoils,
    1968
);

range_body!(
    /// The response to 0x10 Write Multiple Registers (§6.12): 1–123 registers from `start`.
    WrittenRegisters,
    123
);

/// 0x16 Mask Write Register (§6.16): `result = (current AND and_mask) OR (or_mask AND NOT
/// and_mask)`. The response echoes the request.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct MaskWrite {
    /// Register address.
    pub address: u16,
    /// Bits to keep.
    pub and_mask: u16,
    /// Bits to set among those not kept.
    pub or_mask: u16,
}

impl MaskWrite {
    /// The register value after applying the masks to `current`.
    pub const fn apply(&self, current: u16) -> u16 {
        (current & self.and_mask) | (self.or_mask & !self.and_mask)
    }
}

impl Body<'_> for MaskWrite {
    fn parse(r: &mut Reader<'_>) -> Result<Self, PduError> {
        Ok(MaskWrite { address: r.u16()?, and_mask: r.u16()?, or_mask: r.u16()? })
    }
    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        w.u16(self.address)?;
        w.u16(self.and_mask)?;
        w.u16(self.or_mask)
    }
    fn body_len(&self) -> usize {
        6
    }
    fn wire_len(_: &[u8]) -> WireLen {
        WireLen::Known(6)
    }
}

/// 0x17 Read/Write Multiple Registers (§6.17): write 1–121 registers, then read 1–125. The
/// write is performed before the read.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct ReadWriteRegisters<'a> {
    read: ReadRegisters,
    write_start: u16,
    values: Registers<'a>,
}

impl<'a> ReadWriteRegisters<'a> {
    /// The most registers the write part may carry.
    pub const MAX_WRITE: u16 = 121;

    /// A read of `read_quantity` (1–125) from `read_start` after writing `values` (1–121) from
    /// `write_start`.
    pub fn new(read_start: u16, read_quantity: u16, write_start: u16, values: Registers<'a>) -> Result<Self, PduError> {
        let read = ReadRegisters::new(read_start, read_quantity)?;
        check_quantity(values.len(), 1, usize::from(Self::MAX_WRITE))?;
        check_range(write_start, u16::try_from(values.len()).unwrap_or(u16::MAX))?;
        Ok(ReadWriteRegisters { read, write_start, values })
    }

    /// The read part.
    pub fn read(&self) -> ReadRegisters {
        self.read
    }

    /// First address written.
    pub fn write_start(&self) -> u16 {
        self.write_start
    }

    /// The values written.
    pub fn values(&self) -> Registers<'a> {
        self.values
    }
}

impl<'a> Body<'a> for ReadWriteRegisters<'a> {
    fn parse(r: &mut Reader<'a>) -> Result<Self, PduError> {
        let read_start = r.u16()?;
        let read_quantity = r.u16()?;
        let write_start = r.u16()?;
        let write_quantity = r.u16()?;
        check_quantity(usize::from(write_quantity), 1, usize::from(Self::MAX_WRITE))?;
        let byte_count = usize::from(r.u8()?);
        let expected = usize::from(write_quantity).saturating_mul(2);
        if byte_count != expected {
            return Err(PduError::ByteCountMismatch { declared: byte_count, expected });
        }
        let values = Registers::from_wire(r.bytes(byte_count)?)?;
        ReadWriteRegisters::new(read_start, read_quantity, write_start, values)
    }
    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        self.read.emit(w)?;
        w.u16(self.write_start)?;
        w.u16(u16::try_from(self.values.len()).unwrap_or(u16::MAX))?;
        w.u8(u8::try_from(self.values.byte_len()).unwrap_or(u8::MAX))?;
        self.values.emit(w)
    }
    fn body_len(&self) -> usize {
        9usize.saturating_add(self.values.byte_len())
    }
    fn wire_len(head: &[u8]) -> WireLen {
        counted_len(head, 8)
    }
}
