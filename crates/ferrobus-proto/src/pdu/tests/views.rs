//! `Bits` and `Registers`: a view of wire bytes and a view of a caller's values must be
//! interchangeable — equal when they carry the same values, packed the same way on the wire.

use proptest::collection::vec as vec_of;
use proptest::prelude::*;

use super::*;
use crate::cursor::Writer;

/// The spec's packing (§6.1), written independently of the code under test: bit `i` goes to
/// bit `i % 8` of byte `i / 8`, and the last byte is padded with zeros.
fn reference_pack(bits: &[bool]) -> Vec<u8> {
    let mut bytes = vec![0u8; bits.len().div_ceil(8)];
    for (i, &on) in bits.iter().enumerate() {
        if on {
            bytes[i / 8] |= 1 << (i % 8);
        }
    }
    bytes
}

/// What `bits` writes on the wire.
#[track_caller]
fn emitted(bits: Bits<'_>) -> Vec<u8> {
    let mut buf = [0xA5; 300];
    let mut w = Writer::new(&mut buf);
    bits.emit(&mut w).unwrap();
    let n = w.position();
    assert_eq!(n, bits.byte_len());
    buf[..n].to_vec()
}

/// Registers as big-endian bytes.
fn be_bytes(values: &[u16]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_be_bytes()).collect()
}

// ── Bits ────────────────────────────────────────────────────────────────────────────────────

#[test]
fn packing_1_to_16_bits_matches_the_reference_packing_for_every_pattern() {
    for n in 1..=16usize {
        for pattern in 0..(1u32 << n) {
            let bits: Vec<bool> = (0..n).map(|i| (pattern >> i) & 1 == 1).collect();
            let packed = reference_pack(&bits);
            let values = Bits::from_values(&bits);
            assert_eq!(emitted(values), packed, "{bits:?}");
            let wire = Bits::from_wire(&packed, n).unwrap();
            assert_eq!(wire, values, "{packed:02X?}");
            assert!(wire.iter().eq(bits.iter().copied()));
            assert_eq!((wire.get(n), values.get(n)), (None, None));
        }
    }
}

#[test]
fn wire_and_value_bits_compare_equal_exactly_when_they_carry_the_same_bits() {
    let bits = [true, false, true, true, false, false, true, true, true, false];
    let packed = reference_pack(&bits);
    let wire = Bits::from_wire(&packed, bits.len()).unwrap();
    assert_eq!(wire, Bits::from_values(&bits));
    assert_eq!(Bits::from_values(&bits), wire);
    // Padding bits are not part of the value.
    assert_eq!(Bits::from_wire(&[0xFF], 3).unwrap(), Bits::from_values(&[true; 3]));
    // A different bit, or a different count, is a different value.
    let mut flipped = bits;
    flipped[9] = true;
    assert_ne!(wire, Bits::from_values(&flipped));
    assert_ne!(wire, Bits::from_values(&bits[..9]));
    assert_ne!(Bits::from_wire(&packed, 16).unwrap(), wire);
    assert_eq!(Bits::from_wire(&[], 0).unwrap(), Bits::from_values(&[]));
}

#[test]
fn a_wire_view_needs_exactly_the_bytes_its_count_implies() {
    for count in 0..=24usize {
        for len in 0..=4usize {
            let result = Bits::from_wire(&[0u8; 4][..len], count);
            if len == count.div_ceil(8) {
                assert_eq!(result.map(|b| b.len()), Ok(count));
            } else {
                assert_eq!(
                    result.err(),
                    Some(PduError::ByteCountMismatch { declared: len, expected: count.div_ceil(8) })
                );
            }
        }
    }
}

#[test]
fn truncated_keeps_the_leading_bits_of_either_view() {
    let bits: Vec<bool> = (0..20).map(|i| i % 3 == 0).collect();
    let packed = reference_pack(&bits);
    for view in [Bits::from_values(&bits), Bits::from_wire(&packed, bits.len()).unwrap()] {
        for count in 0..=bits.len() {
            let t = view.truncated(count).unwrap();
            assert_eq!((t.len(), t.byte_len(), t.is_empty()), (count, count.div_ceil(8), count == 0));
            assert_eq!(t, Bits::from_values(&bits[..count]));
            assert_eq!(t.get(count), None);
        }
        assert_eq!(view.truncated(bits.len()), Some(view));
        assert_eq!(view.truncated(bits.len() + 1), None);
        assert_eq!(view.truncated(usize::MAX), None);
    }
    // A value view's truncation packs with zero padding.
    assert_eq!(emitted(Bits::from_values(&bits).truncated(4).unwrap()), [0b0000_1001]);
}

#[test]
fn a_read_coils_response_is_trimmed_to_the_quantity_asked_for() {
    // 3G3RX p.4-168: six coils asked for, one byte received.
    let request = body!(Request::parse(&[0x01, 0x00, 0x06, 0x00, 0x06]).unwrap(), Request::ReadCoils);
    let response = body!(Response::parse(&[0x01, 0x01, 0x17]).unwrap(), Response::ReadCoils);
    let coils = response.values().truncated(usize::from(request.quantity())).unwrap();
    let mut out = [false; 8];
    assert_eq!(coils.copy_to(&mut out), 6);
    assert_eq!(out, [true, true, true, false, true, false, false, false]);
}

#[test]
fn copy_to_copies_at_most_the_output_length() {
    let bits = Bits::from_wire(&[0b0000_0101], 3).unwrap();
    let mut short = [false; 2];
    assert_eq!(bits.copy_to(&mut short), 2);
    assert_eq!(short, [true, false]);
    let regs = Registers::from_wire(&[0x0B, 0xB8, 0x00, 0x01]).unwrap();
    let mut long = [0xFFFF; 4];
    assert_eq!(regs.copy_to(&mut long), 2);
    assert_eq!(long, [3000, 1, 0xFFFF, 0xFFFF]);
}

#[test]
fn iterators_know_their_exact_length() {
    let bits = Bits::from_wire(&[0xFF, 0x01], 9).unwrap();
    let mut it = bits.iter();
    assert_eq!(it.len(), 9);
    it.next();
    assert_eq!(it.len(), 8);
    assert_eq!(it.count(), 8);
    let regs = Registers::from_values(&[1, 2, 3]);
    let mut it = regs.into_iter();
    it.next();
    assert_eq!((it.len(), it.size_hint()), (2, (2, Some(2))));
}

#[test]
fn debug_shows_the_values_whatever_the_view() {
    use std::format;
    assert_eq!(format!("{:?}", Bits::from_wire(&[0b1111_0101], 3).unwrap()), "[101]");
    assert_eq!(format!("{:?}", Bits::from_values(&[true, false, true])), "[101]");
    assert_eq!(format!("{:?}", Registers::from_wire(&[0x0B, 0xB8, 0x00, 0x00]).unwrap()), "[3000, 0]");
    assert_eq!(format!("{:?}", Registers::from_values(&[3000, 0])), "[3000, 0]");
}

// ── Registers ───────────────────────────────────────────────────────────────────────────────

#[test]
fn wire_and_value_registers_compare_equal_exactly_when_they_carry_the_same_values() {
    for n in 0..=8u16 {
        let values: Vec<u16> = (0..n).map(|i| i.wrapping_mul(0x0102) ^ 0xA5A5).collect();
        let bytes = be_bytes(&values);
        let wire = Registers::from_wire(&bytes).unwrap();
        let view = Registers::from_values(&values);
        assert_eq!(wire, view);
        assert_eq!((wire.len(), wire.byte_len(), wire.is_empty()), (values.len(), bytes.len(), n == 0));
        assert!(wire.iter().eq(values.iter().copied()));
        assert_eq!((wire.get(values.len()), view.get(values.len()), wire.get(usize::MAX)), (None, None, None));
        if let Some((last, rest)) = values.split_last() {
            assert_ne!(wire, Registers::from_values(rest));
            let mut changed = values.clone();
            *changed.last_mut().unwrap() = !last;
            assert_ne!(wire, Registers::from_values(&changed));
        }
    }
    assert_eq!(Registers::EMPTY, Registers::from_wire(&[]).unwrap());
}

#[test]
fn register_wire_views_need_an_even_number_of_bytes() {
    for len in [1usize, 3, 251] {
        let bytes = vec![0; len];
        assert_eq!(
            Registers::from_wire(&bytes).err(),
            Some(PduError::ByteCountMismatch { declared: len, expected: len + 1 })
        );
    }
}

proptest! {
    #[test]
    fn any_bits_compare_equal_and_pack_alike_in_both_views(bits in vec_of(any::<bool>(), 0..=2000)) {
        let packed = reference_pack(&bits);
        let wire = Bits::from_wire(&packed, bits.len()).unwrap();
        prop_assert_eq!(wire, Bits::from_values(&bits));
        prop_assert_eq!(emitted(Bits::from_values(&bits)), packed.clone());
        prop_assert_eq!(emitted(wire), packed);
    }

    #[test]
    fn any_registers_compare_equal_and_emit_alike_in_both_views(values in vec_of(any::<u16>(), 0..=125)) {
        let bytes = be_bytes(&values);
        let wire = Registers::from_wire(&bytes).unwrap();
        prop_assert_eq!(wire, Registers::from_values(&values));
        let mut buf = [0u8; 250];
        let mut w = Writer::new(&mut buf);
        Registers::from_values(&values).emit(&mut w).unwrap();
        let n = w.position();
        prop_assert_eq!(&buf[..n], &bytes[..]);
    }
}
