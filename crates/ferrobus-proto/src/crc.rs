//! CRC-16/MODBUS, the error check of an RTU frame.
//!
//! Spec: MODBUS over Serial Line V1.02 §2.5.1.2 and §6.2.2. Catalogue parameters: width 16,
//! polynomial 0x8005 (0xA001 reflected), init 0xFFFF, reflected in and out, no final XOR,
//! check value 0x4B37 over `"123456789"`, residue 0x0000.
//!
//! On the wire the **low byte goes first**. Vendor manuals often label the two bytes
//! "MSB"/"LSB" the wrong way round; trust the byte order of a verified example, never a label.
//!
//! The computation comes from the `crc` crate with its 16-lane table (slicing-by-16, 8 KiB of
//! tables in flash), which is what keeps a 256-byte frame well under 100 ns on a PC.

use crc::{CRC_16_MODBUS, Crc, Table};

const MODBUS: Crc<u16, Table<16>> = Crc::<u16, Table<16>>::new(&CRC_16_MODBUS);

/// CRC-16/MODBUS of `data`.
///
/// ```
/// use ferrobus_proto::crc::crc16;
/// assert_eq!(crc16(b"123456789"), 0x4B37);
/// // SDP servo manual p.413: the CRC of this reply goes on the wire as E0 31.
/// assert_eq!(crc16(&[0x01, 0x10, 0x01, 0x12, 0x00, 0x02]).to_le_bytes(), [0xE0, 0x31]);
/// ```
pub fn crc16(data: &[u8]) -> u16 {
    MODBUS.checksum(data)
}

/// The two CRC bytes of `data` in wire order (low byte first).
pub fn crc16_wire(data: &[u8]) -> [u8; 2] {
    crc16(data).to_le_bytes()
}

/// Whether `frame` ends with a correct CRC (the residue over data + CRC is zero).
///
/// # Fuzzing
/// Built with `--cfg fuzzing` (as cargo-fuzz does), this returns `true` for every frame of at
/// least two bytes, so that fuzz inputs get past the check and reach the parsers behind it.
pub fn crc_ok(frame: &[u8]) -> bool {
    if cfg!(fuzzing) {
        return frame.len() >= 2;
    }
    frame.len() >= 2 && crc16(frame) == 0
}

/// An incremental CRC-16/MODBUS, for data that arrives in pieces.
#[derive(Clone)]
pub struct Crc16 {
    digest: crc::Digest<'static, u16, Table<16>>,
}

impl Crc16 {
    /// A fresh CRC register (preset to 0xFFFF).
    pub fn new() -> Self {
        Crc16 { digest: MODBUS.digest() }
    }

    /// Feed more bytes.
    pub fn update(&mut self, data: &[u8]) {
        self.digest.update(data);
    }

    /// The CRC of everything fed so far.
    pub fn finish(self) -> u16 {
        self.digest.finalize()
    }
}

impl Default for Crc16 {
    fn default() -> Self {
        Self::new()
    }
}

impl core::fmt::Debug for Crc16 {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Crc16").finish_non_exhaustive()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// CRC vectors in wire order, from `shared/reference/modbus-and-drives.md` §6 (each checked
    /// there against the manual that prints the frame).
    const VECTORS: &[(&[u8], [u8; 2])] = &[
        (b"123456789", [0x37, 0x4B]),
        (&[0x01, 0x10, 0x01, 0x12, 0x00, 0x02, 0x04, 0x0B, 0xB8, 0x00, 0x00], [0xFC, 0xEB]),
        (&[0x01, 0x10, 0x01, 0x12, 0x00, 0x02], [0xE0, 0x31]),
        (&[0x01, 0x03, 0x02, 0x00, 0x00, 0x02], [0xC5, 0xB3]),
        (&[0x01, 0x03, 0x04, 0x00, 0xB1, 0x1F, 0x40], [0xA3, 0xD4]),
        (&[0x08, 0x01, 0x00, 0x06, 0x00, 0x06], [0x5C, 0x90]),
        (&[0x08, 0x01, 0x01, 0x17], [0x12, 0x1A]),
        (&[0x0A, 0x05, 0x00, 0x00, 0xFF, 0x00], [0x8D, 0x41]),
        (&[0x05, 0x03, 0x00, 0x11, 0x00, 0x02], [0x95, 0x8A]),
        (&[0x05, 0x06, 0x12, 0x02, 0x00, 0x32], [0xAD, 0x23]),
        (&[0x01, 0x10, 0x11, 0x02, 0x00, 0x02, 0x04, 0x00, 0x04, 0x93, 0xE0], [0x9E, 0x9F]),
        (&[0x01, 0x10, 0x11, 0x02, 0x00, 0x02], [0xE5, 0x34]),
        (&[0x05, 0x0F, 0x00, 0x06, 0x00, 0x06, 0x02, 0x17, 0x00], [0xDB, 0x3E]),
        (&[0x05, 0x0F, 0x00, 0x06, 0x00, 0x06], [0x34, 0x4C]),
        (&[0x01, 0x03, 0x00, 0x11, 0x00, 0x06], [0x95, 0xCD]),
        (&[0x01, 0x03, 0x0C, 0x00, 0x03, 0x00, 0x00, 0x00, 0x63, 0x00, 0x00, 0x00, 0x1E, 0x01, 0x1C], [0xAF, 0x6D]),
        (&[0x08, 0x05, 0x00, 0x00, 0xFF, 0x00], [0x8C, 0xA3]),
        (&[0x08, 0x10, 0x10, 0x13, 0x00, 0x02, 0x04, 0x00, 0x04, 0x93, 0xE0], [0x7D, 0x53]),
        (&[0x01, 0x17, 0x10, 0x00, 0x00, 0x02, 0x00, 0x00, 0x00, 0x02, 0x04, 0x00, 0x00, 0x13, 0x88], [0xF4, 0x86]),
        (&[0x01, 0x08, 0x00, 0x00, 0x1F, 0x34], [0xE9, 0xEC]),
        (&[0x01, 0x88, 0x03], [0x06, 0x01]),
        (&[0x01, 0x08, 0x00, 0x00, 0xA5, 0x37], [0xDA, 0x8D]),
        (&[0x11, 0x03, 0x00, 0x6B, 0x00, 0x03], [0x76, 0x87]),
        (&[0x11, 0x03, 0x06, 0xAE, 0x41, 0x56, 0x52, 0x43, 0x40], [0x49, 0xAD]),
        (&[0x11, 0x01, 0x00, 0x13, 0x00, 0x25], [0x0E, 0x84]),
        (&[0x11, 0x02, 0x00, 0xC4, 0x00, 0x16], [0xBA, 0xA9]),
        (&[0x11, 0x04, 0x00, 0x08, 0x00, 0x01], [0xB2, 0x98]),
        (&[0x01, 0x03, 0x00, 0x00, 0x00, 0x0A], [0xC5, 0xCD]),
        (&[0x01, 0x03, 0x00, 0x02, 0x00, 0x01], [0x25, 0xCA]),
        (&[0x01, 0x06, 0x00, 0x11, 0x00, 0x64], [0xD8, 0x24]),
        (&[0x01, 0x10, 0x11, 0x02, 0x00, 0x02, 0x04, 0x00, 0x00, 0x03, 0xE8], [0xB2, 0x98]),
        // Omega i-Series prints "BE B8" for this loopback; the correct wire order is B8 BE.
        (&[0x01, 0x08, 0x00, 0x00, 0x22, 0x33], [0xB8, 0xBE]),
    ];

    #[test]
    fn every_reference_vector_matches_in_wire_order() {
        for (data, wire) in VECTORS {
            assert_eq!(crc16_wire(data), *wire, "CRC of {data:02X?}");
        }
    }

    #[test]
    fn catalogue_check_value_is_4b37() {
        assert_eq!(crc16(b"123456789"), 0x4B37);
    }

    #[test]
    fn residue_over_frame_with_its_crc_is_zero() {
        for (data, wire) in VECTORS {
            let mut frame = [0u8; 32];
            let n = data.len();
            frame[..n].copy_from_slice(data);
            frame[n..n + 2].copy_from_slice(wire);
            assert_eq!(crc16(&frame[..n + 2]), 0);
            assert!(crc_ok(&frame[..n + 2]));
            frame[0] ^= 0x01;
            assert!(!crc_ok(&frame[..n + 2]), "a flipped bit must fail the check");
        }
    }

    #[test]
    fn too_short_frames_never_pass() {
        assert!(!crc_ok(&[]));
        assert!(!crc_ok(&[0x00]));
    }

    #[test]
    fn incremental_equals_one_shot_for_every_split() {
        let data: &[u8] = VECTORS[1].0;
        for split in 0..=data.len() {
            let mut c = Crc16::new();
            c.update(&data[..split]);
            c.update(&data[split..]);
            assert_eq!(c.finish(), crc16(data));
        }
    }

    /// The bitwise algorithm exactly as the SDP and 3G3RX manuals print it (preset FFFFh,
    /// XOR a byte in, eight shifts right with XOR A001h on a carried-out 1), as an oracle.
    fn manual_crc(data: &[u8]) -> u16 {
        let mut crc = 0xFFFFu16;
        for &b in data {
            crc ^= u16::from(b);
            for _ in 0..8 {
                let carry = crc & 1 != 0;
                crc >>= 1;
                if carry {
                    crc ^= 0xA001;
                }
            }
        }
        crc
    }

    proptest::proptest! {
        #[test]
        fn table_crc_equals_the_manuals_bitwise_procedure(data in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..300)) {
            proptest::prop_assert_eq!(crc16(&data), manual_crc(&data));
        }
    }
}
