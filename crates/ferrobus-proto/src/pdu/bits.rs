//! Bit access: 0x01 Read Coils, 0x02 Read Discrete Inputs, 0x05 Write Single Coil,
//! 0x0F Write Multiple Coils (MODBUS Application Protocol V1.1b3 §6.1, §6.2, §6.5, §6.11).

use super::{Bits, Body, WireLen, check_quantity, check_range, counted_len, range_body};
use crate::cursor::{Reader, Writer};
use crate::error::{BufferTooSmall, PduError};

range_body!(
    /// A read of `quantity` bits from `start` (0x01, 0x02): 1–2000 bits (§6.1).
    ReadBits,
    2000
);

impl ReadBits {
    /// Bytes of bit data in the response.
    pub fn response_byte_count(&self) -> usize {
        usize::from(self.quantity).div_ceil(8)
    }
}

/// 0x05 Write Single Coil: one coil ON (0xFF00 on the wire) or OFF (0x0000). Any other value
/// is refused with exception 03 (§6.5). The response echoes the request.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct WriteCoil {
    /// Coil address.
    pub address: u16,
    /// ON or OFF.
    pub value: bool,
}

impl WriteCoil {
    /// The wire value of ON.
    pub const ON: u16 = 0xFF00;
    /// The wire value of OFF.
    pub const OFF: u16 = 0x0000;
}

impl Body<'_> for WriteCoil {
    fn parse(r: &mut Reader<'_>) -> Result<Self, PduError> {
        let address = r.u16()?;
        let value = match r.u16()? {
            WriteCoil::ON => true,
            WriteCoil::OFF => false,
            other => return Err(PduError::InvalidCoilValue(other)),
        };
        Ok(WriteCoil { address, value })
    }
    fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        w.u16(self.address)?;
        w.u16(if self.value { WriteCoil::ON } else { WriteCoil::OFF })
    }
    fn body_len(&self) -> usize {
        4
    }
    fn wire_len(_: &[u8]) -> WireLen {
        WireLen::Known(4)
    }
}

/// 0x0F Write Multiple Coils: 1–1968 coils from `start` (§6.11). Parsing also accepts the
/// word-padded byte count of the Hitachi/Omron inverters; emitting always uses the spec's.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct WriteCoils<'a> {
    start: u16,
    values: Bits<'a>,
}

impl<'a> WriteCoils<'a> {
    /// The most coils one request may write.
    pub const MAX: u16 = 1968;

    /// A write of `values` (1–1968 coils) from `start`, within the address space.
    pub fn new(start: u16, values: Bits<'a>) -> Result<Self, PduError> {
        check_quantity(values.len(), 1, usize::from(Self::MAX))?;
        let quantity = u16::try_from(values.len()).unwrap_or(u16::MAX);
        check_range(start, quantity)?;
        Ok(WriteCoils { start, values })
    }

    /// First address.
    pub fn start(&self) -> u16 {
        self.start
    }

    /// The coil values.
    pub fn values(&self) -> Bits<'a> {
        self.values
    }

    /// Number of coils (fits in `u16`: at most 1968).
    pub fn quantity(&self) -> u16 {
        u16::try_from(self.values.len()).unwrap_or(u16::MAX)
    }
}

impl<'a> Body<'a> for WriteCoils<'a> {
    fn parse(r: &mut Reader<'a>) -> Result<Self, PduError> {
        let start = r.u16()?;
        let quantity = r.u16()?;
        check_quantity(usize::from(quantity), 1, usize::from(Self::MAX))?;
        let byte_count = usize::from(r.u8()?);
        let expected = usize::from(quantity).div_ceil(8);
        // The Hitachi/Omron inverters pad coil data to whole 16-bit words (3G3RX p.4-172:
        // six coils with byte count 2). Accept that one padding byte and drop it.
        let padded = expected % 2 == 1 && byte_count == expected.saturating_add(1);
        if byte_count != expected && !padded {
            return Err(PduError::ByteCountMismatch { declared: byte_count, expected });
        }
        let data = r.bytes(byte_count)?;
        let values = Bits::from_wire(data.get(..expected).unwrap_or_default(), usize::from(quantity))?;
        WriteCoils::new(start, values)
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
