//! Checked big-endian cursors over byte slices: the only way the PDU code touches bytes.
//!
//! Every read returns `Err(PduError::Truncated)` past the end and every write returns
//! `Err(BufferTooSmall)` past the end, so that parse and emit never index out of bounds.

use crate::error::{BufferTooSmall, PduError};

/// Reads fields from a PDU. Positions count from the start of the slice it was made from,
/// which for PDU bodies is the byte after the function code (`base` = 1 makes the numbers in
/// errors count from the function code).
#[derive(Clone, Debug)]
pub(crate) struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
    base: usize,
}

impl<'a> Reader<'a> {
    /// A reader over `data`, whose first byte is at offset `base` of the PDU.
    pub(crate) fn new(data: &'a [u8], base: usize) -> Self {
        Reader { data, pos: 0, base }
    }

    /// Bytes not read yet.
    pub(crate) fn remaining(&self) -> usize {
        self.data.len().saturating_sub(self.pos)
    }

    fn truncated(&self, want: usize) -> PduError {
        PduError::Truncated {
            needed: self.base.saturating_add(self.pos).saturating_add(want),
            available: self.base.saturating_add(self.data.len()),
        }
    }

    /// The next `n` bytes.
    pub(crate) fn bytes(&mut self, n: usize) -> Result<&'a [u8], PduError> {
        let end = self.pos.checked_add(n).ok_or_else(|| self.truncated(n))?;
        let out = self.data.get(self.pos..end).ok_or_else(|| self.truncated(n))?;
        self.pos = end;
        Ok(out)
    }

    /// Everything not read yet.
    pub(crate) fn rest(&mut self) -> &'a [u8] {
        let out = self.data.get(self.pos..).unwrap_or_default();
        self.pos = self.data.len();
        out
    }

    pub(crate) fn u8(&mut self) -> Result<u8, PduError> {
        match self.bytes(1)? {
            [b] => Ok(*b),
            _ => Err(self.truncated(1)),
        }
    }

    pub(crate) fn u16(&mut self) -> Result<u16, PduError> {
        match self.bytes(2)? {
            [hi, lo] => Ok(u16::from_be_bytes([*hi, *lo])),
            _ => Err(self.truncated(2)),
        }
    }

    /// Succeeds only if every byte has been read.
    pub(crate) fn finish(&self) -> Result<(), PduError> {
        match self.remaining() {
            0 => Ok(()),
            extra => Err(PduError::TrailingBytes { extra }),
        }
    }
}

/// Writes fields into an output buffer.
#[derive(Debug)]
pub(crate) struct Writer<'b> {
    buf: &'b mut [u8],
    pos: usize,
}

impl<'b> Writer<'b> {
    pub(crate) fn new(buf: &'b mut [u8]) -> Self {
        Writer { buf, pos: 0 }
    }

    /// Bytes written so far.
    pub(crate) fn position(&self) -> usize {
        self.pos
    }

    /// The next `n` bytes of the buffer, to fill in place, checked once.
    pub(crate) fn reserve(&mut self, n: usize) -> Result<&mut [u8], BufferTooSmall> {
        let needed = self.pos.saturating_add(n);
        let available = self.buf.len();
        let dst = self.buf.get_mut(self.pos..needed).ok_or(BufferTooSmall { needed, available })?;
        self.pos = needed;
        Ok(dst)
    }

    pub(crate) fn bytes(&mut self, data: &[u8]) -> Result<(), BufferTooSmall> {
        let needed = self.pos.saturating_add(data.len());
        let available = self.buf.len();
        let dst = self.buf.get_mut(self.pos..needed).ok_or(BufferTooSmall { needed, available })?;
        dst.copy_from_slice(data);
        self.pos = needed;
        Ok(())
    }

    pub(crate) fn u8(&mut self, v: u8) -> Result<(), BufferTooSmall> {
        self.bytes(&[v])
    }

    pub(crate) fn u16(&mut self, v: u16) -> Result<(), BufferTooSmall> {
        self.bytes(&v.to_be_bytes())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_past_the_end_report_how_much_was_needed() {
        let mut r = Reader::new(&[0x12, 0x34, 0x56], 1);
        assert_eq!(r.u16(), Ok(0x1234));
        assert_eq!(r.u16(), Err(PduError::Truncated { needed: 5, available: 4 }));
        assert_eq!(r.u8(), Ok(0x56));
        assert_eq!(r.finish(), Ok(()));
        assert_eq!(r.bytes(usize::MAX).map(<[u8]>::len), Err(PduError::Truncated { needed: usize::MAX, available: 4 }));
    }

    #[test]
    fn unread_bytes_are_trailing() {
        let mut r = Reader::new(&[1, 2, 3], 0);
        r.u8().unwrap();
        assert_eq!(r.finish(), Err(PduError::TrailingBytes { extra: 2 }));
        assert_eq!(r.rest(), &[2, 3]);
        assert_eq!(r.finish(), Ok(()));
    }

    #[test]
    fn writes_past_the_end_fail_without_writing() {
        let mut buf = [0xA5u8; 3];
        let mut w = Writer::new(&mut buf);
        w.u16(0xBEEF).unwrap();
        assert_eq!(w.u16(0x1234), Err(BufferTooSmall { needed: 4, available: 3 }));
        assert_eq!(w.position(), 2);
        assert_eq!(buf, [0xBE, 0xEF, 0xA5]);
    }
}
