//! Register and bit lists that are either a view of wire bytes or a caller's slice.
//!
//! A parsed PDU borrows its data from the receive buffer ([`Registers::from_wire`]); a PDU
//! built by a program borrows the program's values ([`Registers::from_values`]). Both compare,
//! iterate and emit the same way, so `parse(emit(x)) == x` holds without copying or allocating.

use core::fmt;

use crate::cursor::Writer;
use crate::error::{BufferTooSmall, PduError};

/// A list of 16-bit registers.
#[derive(Clone, Copy)]
pub struct Registers<'a> {
    repr: RegistersRepr<'a>,
}

#[derive(Clone, Copy)]
enum RegistersRepr<'a> {
    /// Big-endian register pairs as they travel; the length is even.
    Wire(&'a [u8]),
    Values(&'a [u16]),
}

impl<'a> Registers<'a> {
    /// No registers.
    pub const EMPTY: Registers<'static> = Registers { repr: RegistersRepr::Values(&[]) };

    /// A view of big-endian register bytes; fails on an odd length.
    pub fn from_wire(bytes: &'a [u8]) -> Result<Self, PduError> {
        if !bytes.len().is_multiple_of(2) {
            return Err(PduError::ByteCountMismatch { declared: bytes.len(), expected: bytes.len().saturating_add(1) });
        }
        Ok(Registers { repr: RegistersRepr::Wire(bytes) })
    }

    /// A view of register values.
    pub const fn from_values(values: &'a [u16]) -> Self {
        Registers { repr: RegistersRepr::Values(values) }
    }

    /// Number of registers.
    pub fn len(&self) -> usize {
        match self.repr {
            RegistersRepr::Wire(b) => b.len() / 2,
            RegistersRepr::Values(v) => v.len(),
        }
    }

    /// Whether there are no registers.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bytes on the wire (two per register).
    pub fn byte_len(&self) -> usize {
        self.len().saturating_mul(2)
    }

    /// The register at `index`.
    pub fn get(&self, index: usize) -> Option<u16> {
        match self.repr {
            RegistersRepr::Wire(b) => {
                let at = index.checked_mul(2)?;
                match b.get(at..at.checked_add(2)?)? {
                    [hi, lo] => Some(u16::from_be_bytes([*hi, *lo])),
                    _ => None,
                }
            }
            RegistersRepr::Values(v) => v.get(index).copied(),
        }
    }

    /// The registers in order.
    pub fn iter(&self) -> RegisterIter<'a> {
        RegisterIter { regs: *self, next: 0 }
    }

    /// Copies the registers into `out` and returns how many were copied (at most `out.len()`).
    pub fn copy_to(&self, out: &mut [u16]) -> usize {
        out.iter_mut().zip(self.iter()).map(|(slot, v)| *slot = v).count()
    }

    pub(crate) fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        match self.repr {
            RegistersRepr::Wire(b) => w.bytes(b),
            RegistersRepr::Values(v) => {
                // One bounds check for the whole list: the hot path of every read response.
                let dst = w.reserve(v.len().saturating_mul(2))?;
                for (pair, r) in dst.chunks_exact_mut(2).zip(v) {
                    pair.copy_from_slice(&r.to_be_bytes());
                }
                Ok(())
            }
        }
    }
}

impl PartialEq for Registers<'_> {
    fn eq(&self, other: &Self) -> bool {
        self.len() == other.len() && self.iter().eq(other.iter())
    }
}

impl Eq for Registers<'_> {}

impl fmt::Debug for Registers<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

impl<'a> IntoIterator for &Registers<'a> {
    type Item = u16;
    type IntoIter = RegisterIter<'a>;
    fn into_iter(self) -> RegisterIter<'a> {
        self.iter()
    }
}

impl<'a> IntoIterator for Registers<'a> {
    type Item = u16;
    type IntoIter = RegisterIter<'a>;
    fn into_iter(self) -> RegisterIter<'a> {
        self.iter()
    }
}

/// Iterator over [`Registers`].
#[derive(Clone, Debug)]
pub struct RegisterIter<'a> {
    regs: Registers<'a>,
    next: usize,
}

impl Iterator for RegisterIter<'_> {
    type Item = u16;
    fn next(&mut self) -> Option<u16> {
        let v = self.regs.get(self.next)?;
        self.next = self.next.saturating_add(1);
        Some(v)
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let n = self.regs.len().saturating_sub(self.next);
        (n, Some(n))
    }
}

impl ExactSizeIterator for RegisterIter<'_> {}

/// A list of bits (coils or discrete inputs).
///
/// On the wire bits are packed eight to a byte, the first bit in the least significant bit of
/// the first byte, and the last byte padded with zeros (MODBUS Application Protocol §6.1).
#[derive(Clone, Copy)]
pub struct Bits<'a> {
    repr: BitsRepr<'a>,
}

#[derive(Clone, Copy)]
enum BitsRepr<'a> {
    /// Packed bytes and how many bits of them count; `bytes.len() == count.div_ceil(8)`.
    Wire {
        bytes: &'a [u8],
        count: usize,
    },
    Values(&'a [bool]),
}

impl<'a> Bits<'a> {
    /// A view of `count` packed bits; fails unless `bytes` holds exactly `count.div_ceil(8)`
    /// bytes.
    pub fn from_wire(bytes: &'a [u8], count: usize) -> Result<Self, PduError> {
        let expected = count.div_ceil(8);
        if bytes.len() != expected {
            return Err(PduError::ByteCountMismatch { declared: bytes.len(), expected });
        }
        Ok(Bits { repr: BitsRepr::Wire { bytes, count } })
    }

    /// A view of bit values.
    pub const fn from_values(values: &'a [bool]) -> Self {
        Bits { repr: BitsRepr::Values(values) }
    }

    /// Number of bits.
    pub fn len(&self) -> usize {
        match self.repr {
            BitsRepr::Wire { count, .. } => count,
            BitsRepr::Values(v) => v.len(),
        }
    }

    /// Whether there are no bits.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bytes on the wire.
    pub fn byte_len(&self) -> usize {
        self.len().div_ceil(8)
    }

    /// The bit at `index`.
    pub fn get(&self, index: usize) -> Option<bool> {
        match self.repr {
            BitsRepr::Wire { bytes, count } => {
                if index >= count {
                    return None;
                }
                let byte = bytes.get(index / 8)?;
                Some(byte & (1 << (index % 8)) != 0)
            }
            BitsRepr::Values(v) => v.get(index).copied(),
        }
    }

    /// The first `count` bits, or `None` if there are fewer. A read-coils response carries
    /// whole bytes; the master trims it to the quantity it asked for.
    pub fn truncated(&self, count: usize) -> Option<Bits<'a>> {
        if count > self.len() {
            return None;
        }
        Some(match self.repr {
            BitsRepr::Wire { bytes, .. } => {
                Bits { repr: BitsRepr::Wire { bytes: bytes.get(..count.div_ceil(8))?, count } }
            }
            BitsRepr::Values(v) => Bits::from_values(v.get(..count)?),
        })
    }

    /// The bits in order.
    pub fn iter(&self) -> BitIter<'a> {
        BitIter { bits: *self, next: 0 }
    }

    /// Copies the bits into `out` and returns how many were copied (at most `out.len()`).
    pub fn copy_to(&self, out: &mut [bool]) -> usize {
        out.iter_mut().zip(self.iter()).map(|(slot, v)| *slot = v).count()
    }

    pub(crate) fn emit(&self, w: &mut Writer<'_>) -> Result<(), BufferTooSmall> {
        match self.repr {
            BitsRepr::Wire { bytes, count } => {
                // Bits past `count` in the last byte (left over from a longer view that was
                // truncated) go out as zeros, as the spec pads.
                let (last, whole) = bytes.split_last().map_or((None, bytes), |(l, w)| (Some(*l), w));
                w.bytes(whole)?;
                let used = u32::try_from(count % 8).unwrap_or(0);
                match last {
                    Some(l) if used == 0 => w.u8(l),
                    Some(l) => w.u8(l & 1u8.checked_shl(used).unwrap_or(0).wrapping_sub(1)),
                    None => Ok(()),
                }
            }
            BitsRepr::Values(v) => v.chunks(8).try_for_each(|chunk| {
                let byte = chunk.iter().enumerate().fold(0u8, |acc, (i, &on)| if on { acc | (1 << i) } else { acc });
                w.u8(byte)
            }),
        }
    }
}

impl PartialEq for Bits<'_> {
    fn eq(&self, other: &Self) -> bool {
        self.len() == other.len() && self.iter().eq(other.iter())
    }
}

impl Eq for Bits<'_> {}

impl fmt::Debug for Bits<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("[")?;
        for b in self {
            f.write_str(if b { "1" } else { "0" })?;
        }
        f.write_str("]")
    }
}

impl<'a> IntoIterator for &Bits<'a> {
    type Item = bool;
    type IntoIter = BitIter<'a>;
    fn into_iter(self) -> BitIter<'a> {
        self.iter()
    }
}

impl<'a> IntoIterator for Bits<'a> {
    type Item = bool;
    type IntoIter = BitIter<'a>;
    fn into_iter(self) -> BitIter<'a> {
        self.iter()
    }
}

/// Iterator over [`Bits`].
#[derive(Clone, Debug)]
pub struct BitIter<'a> {
    bits: Bits<'a>,
    next: usize,
}

impl Iterator for BitIter<'_> {
    type Item = bool;
    fn next(&mut self) -> Option<bool> {
        let v = self.bits.get(self.next)?;
        self.next = self.next.saturating_add(1);
        Some(v)
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let n = self.bits.len().saturating_sub(self.next);
        (n, Some(n))
    }
}

impl ExactSizeIterator for BitIter<'_> {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wire_and_value_registers_compare_equal() {
        let wire = Registers::from_wire(&[0x0B, 0xB8, 0x00, 0x00]).unwrap();
        assert_eq!(wire, Registers::from_values(&[3000, 0]));
        assert_ne!(wire, Registers::from_values(&[3000]));
        assert_eq!(wire.get(0), Some(3000));
        assert_eq!(wire.get(2), None);
        assert_eq!(wire.get(usize::MAX), None);
        assert_eq!(wire.byte_len(), 4);
    }

    #[test]
    fn odd_register_bytes_are_rejected() {
        assert!(Registers::from_wire(&[1, 2, 3]).is_err());
    }

    #[test]
    fn bits_pack_lsb_first_and_pad_with_zeros() {
        // SJ700-2 B-25: coils 7..12 = 1,1,1,0,1,0 are sent as 0x17.
        let on = [true, true, true, false, true, false];
        let mut buf = [0xA5u8; 2];
        let mut w = Writer::new(&mut buf);
        Bits::from_values(&on).emit(&mut w).unwrap();
        assert_eq!(w.position(), 1);
        assert_eq!(buf, [0x17, 0xA5]);
        assert_eq!(Bits::from_wire(&[0x17], 6).unwrap(), Bits::from_values(&on));
    }

    #[test]
    fn bit_views_need_exactly_the_bytes_their_count_implies() {
        assert!(Bits::from_wire(&[0xFF], 9).is_err());
        assert!(Bits::from_wire(&[0xFF, 0x01], 8).is_err());
        assert_eq!(Bits::from_wire(&[], 0).unwrap().len(), 0);
        let bits = Bits::from_wire(&[0xFF, 0x01], 9).unwrap();
        assert_eq!(bits.get(8), Some(true));
        assert_eq!(bits.get(9), None);
    }

    #[test]
    fn truncation_keeps_the_leading_bits() {
        let bits = Bits::from_wire(&[0b1010_1010, 0b0000_0001], 16).unwrap();
        let t = bits.truncated(9).unwrap();
        assert_eq!(t.len(), 9);
        assert_eq!(t.byte_len(), 2);
        assert_eq!(t.get(8), Some(true));
        assert!(bits.truncated(17).is_none());
    }
}
