//! Values wider than a register: the order of their bytes over the registers.
//!
//! The spec defines only 16-bit registers, big-endian on the wire (MODBUS Application Protocol
//! V1.1b3 §4.2); how a device lays a 32- or 64-bit value over several registers is its own
//! choice. Integrators name the four layouts by where the bytes A B C D of a big-endian
//! 32-bit value land: ABCD, CDAB, BADC, DCBA. This is the one word-order type of the project
//! and [`WordOrder::from_name`] its one parser: profiles, the command line and the bridge all
//! take the same names.

/// The order of a multi-register value's bytes over its registers, by the names integrators
/// use. For 64-bit values the same four generalise: ABCD is big-endian, words high first;
/// CDAB words low first (bytes big-endian in each); BADC bytes swapped in each word, words
/// high first; DCBA fully little-endian.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug, Default)]
pub enum WordOrder {
    /// Big-endian, "high-first": high word at the lower address, high byte first (Omron and
    /// Hitachi drives).
    #[default]
    Abcd,
    /// "low-first": low word at the lower address, high byte first in each word (some servos,
    /// the SDP examples).
    Cdab,
    /// High word first, low byte first in each word.
    Badc,
    /// Little-endian: low word first, low byte first.
    Dcba,
}

impl WordOrder {
    /// All four, the default first.
    pub const ALL: [WordOrder; 4] = [WordOrder::Abcd, WordOrder::Cdab, WordOrder::Badc, WordOrder::Dcba];

    /// The names [`WordOrder::from_name`] takes, for help texts and error messages.
    pub const NAMES: &'static str = "ABCD (or high-first), CDAB (or low-first), BADC, DCBA";

    /// The name: `ABCD`, `CDAB`, `BADC`, `DCBA`.
    pub const fn name(self) -> &'static str {
        match self {
            WordOrder::Abcd => "ABCD",
            WordOrder::Cdab => "CDAB",
            WordOrder::Badc => "BADC",
            WordOrder::Dcba => "DCBA",
        }
    }

    /// The order named `name`, ignoring ASCII case and surrounding spaces: one of the four
    /// names, or `high-first` (ABCD) or `low-first` (CDAB). `None` for anything else.
    pub fn from_name(name: &str) -> Option<Self> {
        let name = name.trim();
        if name.eq_ignore_ascii_case("high-first") {
            return Some(WordOrder::Abcd);
        }
        if name.eq_ignore_ascii_case("low-first") {
            return Some(WordOrder::Cdab);
        }
        WordOrder::ALL.into_iter().find(|order| order.name().eq_ignore_ascii_case(name))
    }

    /// Whether the words run low first (CDAB, DCBA).
    pub const fn words_low_first(self) -> bool {
        matches!(self, WordOrder::Cdab | WordOrder::Dcba)
    }

    /// Whether the bytes in each word are swapped (BADC, DCBA).
    pub const fn bytes_swapped(self) -> bool {
        matches!(self, WordOrder::Badc | WordOrder::Dcba)
    }

    /// Lays `bytes`, a value in big-endian order, over `registers` in address order. Each
    /// register takes two bytes; a byte missing at the end counts as zero, and registers past
    /// the bytes are zero.
    pub fn to_registers(self, bytes: &[u8], registers: &mut [u16]) {
        registers.fill(0);
        // Value words in value order (most significant first), then in address order.
        for (register, pair) in registers.iter_mut().zip(bytes.chunks(2)) {
            let (hi, lo) = (pair.first().copied().unwrap_or(0), pair.get(1).copied().unwrap_or(0));
            *register = if self.bytes_swapped() { u16::from_be_bytes([lo, hi]) } else { u16::from_be_bytes([hi, lo]) };
        }
        if self.words_low_first() {
            registers.reverse();
        }
    }

    /// The value of `registers` (address order) as big-endian bytes into `bytes`, the
    /// inverse of [`WordOrder::to_registers`]. Bytes past twice the registers are zero;
    /// registers past half the bytes are left out.
    pub fn from_registers(self, registers: &[u16], bytes: &mut [u8]) {
        bytes.fill(0);
        let put = |pair: &mut [u8], register: &u16| {
            let [hi, lo] = register.to_be_bytes();
            let word = if self.bytes_swapped() { [lo, hi] } else { [hi, lo] };
            for (b, w) in pair.iter_mut().zip(word) {
                *b = w;
            }
        };
        if self.words_low_first() {
            bytes.chunks_mut(2).zip(registers.iter().rev()).for_each(|(pair, r)| put(pair, r));
        } else {
            bytes.chunks_mut(2).zip(registers).for_each(|(pair, r)| put(pair, r));
        }
    }

    /// `value` as two registers in address order.
    pub fn split(self, value: u32) -> [u16; 2] {
        let mut registers = [0; 2];
        self.to_registers(&value.to_be_bytes(), &mut registers);
        registers
    }

    /// The 32-bit value of two registers in address order.
    pub fn join(self, registers: [u16; 2]) -> u32 {
        let mut bytes = [0; 4];
        self.from_registers(&registers, &mut bytes);
        u32::from_be_bytes(bytes)
    }
}

impl core::fmt::Display for WordOrder {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 0x11223344 as A=11 B=22 C=33 D=44: the table every user of an order is tested against.
    const TABLE: [(WordOrder, [u16; 2]); 4] = [
        (WordOrder::Abcd, [0x1122, 0x3344]),
        (WordOrder::Cdab, [0x3344, 0x1122]),
        (WordOrder::Badc, [0x2211, 0x4433]),
        (WordOrder::Dcba, [0x4433, 0x2211]),
    ];

    #[test]
    fn the_four_orders_lay_a_32_bit_value_over_two_registers_as_integrators_name_them() {
        for (order, registers) in TABLE {
            assert_eq!(order.split(0x1122_3344), registers, "{order}");
            assert_eq!(order.join(registers), 0x1122_3344, "{order}");
        }
        // 3G3RX F002 = 300000, high word first; SDP 3000, low word first.
        assert_eq!(WordOrder::Abcd.split(0x0004_93E0), [0x0004, 0x93E0]);
        assert_eq!(WordOrder::Cdab.split(3000), [0x0BB8, 0x0000]);
    }

    #[test]
    fn sixty_four_bit_values_generalise_the_same_four() {
        let bytes = 0x1122_3344_5566_7788u64.to_be_bytes();
        for (order, want) in [
            (WordOrder::Abcd, [0x1122, 0x3344, 0x5566, 0x7788]),
            (WordOrder::Cdab, [0x7788, 0x5566, 0x3344, 0x1122]),
            (WordOrder::Badc, [0x2211, 0x4433, 0x6655, 0x8877]),
            (WordOrder::Dcba, [0x8877, 0x6655, 0x4433, 0x2211]),
        ] {
            let mut registers = [0xA5A5; 4];
            order.to_registers(&bytes, &mut registers);
            assert_eq!(registers, want, "{order}");
            let mut back = [0xA5; 8];
            order.from_registers(&registers, &mut back);
            assert_eq!(back, bytes, "{order}");
        }
    }

    #[test]
    fn join_undoes_split_in_every_order() {
        for value in [0, 1, 0xFFFF, 0x1_0000, 0x8000_0001, u32::MAX, 0xDEAD_BEEF] {
            for order in WordOrder::ALL {
                assert_eq!(order.join(order.split(value)), value, "{order:?} {value:#010x}");
            }
        }
    }

    #[test]
    fn short_inputs_pad_with_zero_and_never_panic() {
        let mut registers = [0xA5A5; 3];
        WordOrder::Dcba.to_registers(&[0x11, 0x22, 0x33], &mut registers);
        // Value words 0x1122, 0x3300, 0x0000; low word first, bytes swapped.
        assert_eq!(registers, [0x0000, 0x0033, 0x2211]);
        let mut bytes = [0xA5; 3];
        WordOrder::Abcd.from_registers(&[0x1122, 0x3344], &mut bytes);
        assert_eq!(bytes, [0x11, 0x22, 0x33]);
        WordOrder::Cdab.to_registers(&[], &mut []);
    }

    #[test]
    fn names_and_aliases_read_back_in_any_case_and_nothing_else_is_a_name() {
        for order in WordOrder::ALL {
            assert_eq!(WordOrder::from_name(order.name()), Some(order));
            assert_eq!(WordOrder::from_name(&order.name().to_ascii_lowercase()), Some(order));
        }
        assert_eq!(WordOrder::from_name("high-first"), Some(WordOrder::Abcd));
        assert_eq!(WordOrder::from_name(" Low-First "), Some(WordOrder::Cdab));
        assert_eq!(WordOrder::from_name("swap"), None);
        assert_eq!(WordOrder::from_name("ABCDE"), None);
        assert_eq!(WordOrder::from_name(""), None);
    }
}
