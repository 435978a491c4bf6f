//! Typed register values: how numbers are typed, encoded into registers and shown.
//!
//! A 32-bit value takes two registers. Which comes first differs by device: the Omron and
//! Hitachi drives put the high word at the lower address (reference §4.9), the SDP servo
//! example suggests the low word first (§5), others swap the bytes of each register; hence
//! `--word-order`, which takes the four orders of profiles (ABCD, CDAB, BADC, DCBA) by the
//! core's one parser.
//!
//! Typed text becomes a raw value here (decimal, `0x` hex and `0b` binary raw bits); raw
//! values become registers and back through the profile's one codec, [`Point::encode`] and
//! [`Point::decode`] on a [`Point::raw`] of the type and order: the codec get, set, poll and
//! the bridge use.

use std::fmt;

use clap::{Args, ValueEnum};
use ferrobus_profile::text::{self, Radix};
use ferrobus_profile::{Point, Table, Value};

use crate::exit::CliError;

/// How registers are interpreted.
#[derive(ValueEnum, Clone, Copy, PartialEq, Eq, Debug, Default)]
pub(crate) enum ValueType {
    // Unsigned 16-bit.
    #[default]
    U16,
    // Signed 16-bit.
    I16,
    // Unsigned 32-bit, two registers.
    U32,
    // Signed 32-bit, two registers.
    I32,
    // IEEE 754 single precision, two registers.
    F32,
    // 16-bit, shown and typed in hex.
    Hex,
    // 16-bit, shown and typed in binary.
    Bin,
}

impl ValueType {
    /// Registers per value.
    pub(crate) fn width(self) -> usize {
        match self {
            ValueType::U32 | ValueType::I32 | ValueType::F32 => 2,
            _ => 1,
        }
    }

    /// The name, as typed.
    pub(crate) fn name(self) -> &'static str {
        match self {
            ValueType::U16 => "u16",
            ValueType::I16 => "i16",
            ValueType::U32 => "u32",
            ValueType::I32 => "i32",
            ValueType::F32 => "f32",
            ValueType::Hex => "hex",
            ValueType::Bin => "bin",
        }
    }

    /// The profile's type of the same registers (hex and bin are u16 shown otherwise).
    fn profile(self) -> ferrobus_profile::ValueType {
        use ferrobus_profile::ValueType as P;
        match self {
            ValueType::U16 | ValueType::Hex | ValueType::Bin => P::U16,
            ValueType::I16 => P::I16,
            ValueType::U32 => P::U32,
            ValueType::I32 => P::I32,
            ValueType::F32 => P::F32,
        }
    }
}

/// The one word-order type (the core's, the profiles' `Order`).
pub(crate) use ferrobus_profile::Order as WordOrder;

/// `--word-order`: the one parser of word orders ([`WordOrder::from_name`]).
pub(crate) fn parse_word_order(text: &str) -> Result<WordOrder, String> {
    WordOrder::from_name(text).ok_or_else(|| format!("'{text}' is not a word order: use {}", WordOrder::NAMES))
}

/// A point no profile describes, of `ty` in `order`: what the one codec works on.
fn raw_point(ty: ferrobus_profile::ValueType, order: WordOrder) -> Point {
    Point { order, ..Point::raw(Table::Holding, 0, ty) }
}

/// The options that say how registers are typed.
#[derive(Args, Clone, Copy, Debug, Default)]
#[command(next_help_heading = "Values")]
pub(crate) struct ValueArgs {
    /// Value type: u16, i16, hex, bin (one register each); u32, i32, f32 (two registers each)
    #[arg(long = "type", short = 't', value_enum, default_value_t = ValueType::U16, hide_possible_values = true)]
    pub(crate) kind: ValueType,

    /// Byte order of 32-bit values over their two registers: ABCD or high-first
    /// (Omron/Hitachi drives), CDAB or low-first, BADC, DCBA (case-insensitive)
    /// [default: ABCD, or the --device profile's order]
    #[arg(long = "word-order", value_parser = parse_word_order)]
    pub(crate) word_order: Option<WordOrder>,

    /// Same as --word-order CDAB (low-first)
    #[arg(long, conflicts_with = "word_order")]
    pub(crate) swap: bool,
}

impl ValueArgs {
    /// The word order, with `--swap` applied.
    pub(crate) fn order(self) -> WordOrder {
        if self.swap { WordOrder::Cdab } else { self.word_order.unwrap_or_default() }
    }

    /// These options with `order` where neither --word-order nor --swap was given (a
    /// `--device` profile's order).
    pub(crate) fn or_order(mut self, order: Option<WordOrder>) -> Self {
        if !self.swap && self.word_order.is_none() {
            self.word_order = order;
        }
        self
    }

    /// Encodes each typed value into registers.
    pub(crate) fn encode_all<S: AsRef<str>>(self, texts: &[S]) -> Result<Vec<u16>, CliError> {
        let mut out = Vec::with_capacity(texts.len() * self.kind.width());
        for text in texts {
            out.extend(encode(self.kind, self.order(), text.as_ref())?);
        }
        Ok(out)
    }

    /// Decodes registers, `width` at a time; a trailing partial value is left out.
    pub(crate) fn decode_all(self, registers: &[u16]) -> Vec<Decoded> {
        registers.chunks_exact(self.kind.width()).filter_map(|regs| decode(self.kind, self.order(), regs)).collect()
    }
}

/// A decoded value.
#[derive(Clone, Copy, PartialEq, Debug)]
pub(crate) enum Decoded {
    /// An integer type.
    Int(i64),
    /// f32.
    Float(f32),
    /// A 16-bit value to show in hex.
    Hex(u16),
    /// A 16-bit value to show in binary.
    Bin(u16),
}

impl fmt::Display for Decoded {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Decoded::Int(v) => write!(f, "{v}"),
            // As Python's repr: an exponent for the very large and the very small, so that
            // -4.9502034e32 does not print as -495020340000000000000000000000000.
            Decoded::Float(v) if v != 0.0 && v.is_finite() && !(1e-4..1e16).contains(&v.abs()) => write!(f, "{v:e}"),
            Decoded::Float(v) => write!(f, "{v}"),
            Decoded::Hex(v) => write!(f, "0x{v:04X}"),
            Decoded::Bin(v) => {
                let b = format!("{v:016b}");
                write!(f, "0b{}_{}_{}_{}", &b[0..4], &b[4..8], &b[8..12], &b[12..16])
            }
        }
    }
}

impl Decoded {
    /// The value in JSON: a number, or a string for hex and binary (NaN and infinities: null).
    pub(crate) fn to_json(self) -> serde_json::Value {
        match self {
            Decoded::Int(v) => v.into(),
            Decoded::Float(v) => serde_json::Number::from_f64(f64::from(v)).map_or(serde_json::Value::Null, Into::into),
            Decoded::Hex(_) | Decoded::Bin(_) => self.to_string().into(),
        }
    }
}

/// Decodes one value from its registers (exactly `kind.width()` of them; `None` otherwise),
/// by the one codec.
pub(crate) fn decode(kind: ValueType, order: WordOrder, regs: &[u16]) -> Option<Decoded> {
    let value = raw_point(kind.profile(), order).decode(regs).ok()?;
    Some(match (kind, value) {
        (ValueType::Hex, Value::Int(n)) => Decoded::Hex(u16::try_from(n).ok()?),
        (ValueType::Bin, Value::Int(n)) => Decoded::Bin(u16::try_from(n).ok()?),
        (_, Value::Int(n)) => Decoded::Int(i64::try_from(n).ok()?),
        // Decoded from an f32: exact as one.
        #[allow(clippy::cast_possible_truncation)]
        (_, Value::Float(x)) => Decoded::Float(x as f32),
        (_, Value::Bool(_) | Value::Text(_)) => return None,
    })
}

/// An integer as typed, in the one grammar of integers ([`text::integer`]); with whether it
/// was written in hex or binary (raw bits).
fn parse_int(text: &str) -> Option<(i128, bool)> {
    text::integer(text).map(|(value, radix)| (value, radix != Radix::Decimal))
}

fn bad(text: &str, kind: ValueType, why: &str) -> CliError {
    CliError::Usage(format!("value '{text}' is not a valid {}: {why}", kind.name()))
}

/// Encodes one typed value into registers.
pub(crate) fn encode(kind: ValueType, order: WordOrder, text: &str) -> Result<Vec<u16>, CliError> {
    use ferrobus_profile::ValueType as P;
    let int = |text: &str| parse_int(text).ok_or_else(|| bad(text, kind, "expected a number (decimal, 0x hex)"));
    let range = |v: i128, min: i128, max: i128, hint: &str| {
        if (min..=max).contains(&v) {
            Ok(v)
        } else {
            Err(bad(text, kind, &format!("out of range {min}..={max}{hint}")))
        }
    };
    let (ty, value) = match kind {
        ValueType::U16 => {
            let (v, _) = int(text)?;
            let hint = if v < 0 { "; use --type i16 for negative values" } else { "" };
            (P::U16, range(v, 0, 0xFFFF, hint)?)
        }
        // Hex and binary are the raw bits: 0xFFFF is -1.
        ValueType::I16 => match int(text)? {
            (v, true) => (P::U16, range(v, 0, 0xFFFF, "")?),
            (v, false) => (P::I16, range(v, -0x8000, 0x7FFF, "")?),
        },
        ValueType::U32 => {
            let (v, _) = int(text)?;
            let hint = if v < 0 { "; use --type i32 for negative values" } else { "" };
            (P::U32, range(v, 0, 0xFFFF_FFFF, hint)?)
        }
        ValueType::I32 => match int(text)? {
            (v, true) => (P::U32, range(v, 0, 0xFFFF_FFFF, "")?),
            (v, false) => (P::I32, range(v, -0x8000_0000, 0x7FFF_FFFF, "")?),
        },
        // Its raw bits, whether typed as a number or as 0x hex: a u32 in the same order.
        ValueType::F32 => (P::U32, i128::from(parse_f32(text)?)),
        ValueType::Hex => {
            let t = text.trim();
            let digits = t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")).unwrap_or(t);
            let v = parse_int(&format!("0x{digits}")).ok_or_else(|| bad(text, kind, "expected hex digits"))?.0;
            (P::U16, range(v, 0, 0xFFFF, "")?)
        }
        ValueType::Bin => {
            let t = text.trim();
            let digits = t.strip_prefix("0b").or_else(|| t.strip_prefix("0B")).unwrap_or(t);
            let v = parse_int(&format!("0b{digits}")).ok_or_else(|| bad(text, kind, "expected binary digits"))?.0;
            (P::U16, range(v, 0, 0xFFFF, "")?)
        }
    };
    raw_point(ty, order).encode(&Value::Int(value)).map_err(|e| bad(text, kind, &e.to_string()))
}

/// An f32 as typed, or its raw bits as `0x` hex.
fn parse_f32(text: &str) -> Result<u32, CliError> {
    let t = text.trim();
    if t.starts_with("0x") || t.starts_with("0X") {
        return match parse_int(t) {
            Some((v, _)) if (0..=0xFFFF_FFFF).contains(&v) => Ok(u32::try_from(v).unwrap_or_default()),
            _ => Err(bad(text, ValueType::F32, "raw bits must be 0x0-0xFFFFFFFF")),
        };
    }
    let v: f32 = t.parse().map_err(|_| bad(text, ValueType::F32, "expected a number such as 12.5 or -3e2"))?;
    if v.is_infinite() && !t.to_ascii_lowercase().contains("inf") {
        return Err(bad(text, ValueType::F32, "too large for f32"));
    }
    Ok(v.to_bits())
}

/// A coil value: on/off, 1/0, true/false.
pub(crate) fn parse_coil(text: &str) -> Result<bool, CliError> {
    match text.trim().to_ascii_lowercase().as_str() {
        "1" | "on" | "true" => Ok(true),
        "0" | "off" | "false" => Ok(false),
        _ => Err(CliError::Usage(format!("coil value '{text}' must be on/off, 1/0 or true/false"))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn word_order_takes_the_four_names_and_the_aliases_and_says_what_a_wrong_one_should_be() {
        assert_eq!(parse_word_order("high-first"), Ok(WordOrder::Abcd));
        assert_eq!(parse_word_order("low-first"), Ok(WordOrder::Cdab));
        for order in WordOrder::ALL {
            assert_eq!(parse_word_order(&order.name().to_lowercase()), Ok(order));
        }
        assert_eq!(
            parse_word_order("swap"),
            Err("'swap' is not a word order: use ABCD (or high-first), CDAB (or low-first), BADC, DCBA".into())
        );
    }

    #[test]
    fn the_four_order_table_through_read_and_write() {
        // 0x11223344 as A=11 B=22 C=33 D=44: the table of ferrobus_proto::words, get/set and poll.
        for (order, registers) in [
            (WordOrder::Abcd, [0x1122, 0x3344]),
            (WordOrder::Cdab, [0x3344, 0x1122]),
            (WordOrder::Badc, [0x2211, 0x4433]),
            (WordOrder::Dcba, [0x4433, 0x2211]),
        ] {
            let values = ValueArgs { kind: ValueType::U32, word_order: Some(order), swap: false };
            assert_eq!(values.encode_all(&["0x11223344"]).unwrap(), registers, "write {order}");
            assert_eq!(values.decode_all(&registers), [Decoded::Int(0x1122_3344)], "read {order}");
        }
        let swap = ValueArgs { kind: ValueType::U32, word_order: None, swap: true };
        assert_eq!(swap.order(), WordOrder::Cdab);
    }

    fn enc(kind: ValueType, order: WordOrder, text: &str) -> Vec<u16> {
        encode(kind, order, text).unwrap()
    }

    #[test]
    fn sixteen_bit_values_take_decimal_hex_and_signs() {
        use WordOrder::Abcd as H;
        assert_eq!(enc(ValueType::U16, H, "3000"), [3000]);
        assert_eq!(enc(ValueType::U16, H, "0x0BB8"), [0x0BB8]);
        assert_eq!(enc(ValueType::I16, H, "-1"), [0xFFFF]);
        assert_eq!(enc(ValueType::I16, H, "0xFFFF"), [0xFFFF]);
        assert_eq!(enc(ValueType::Hex, H, "0bb8"), [0x0BB8]);
        assert_eq!(enc(ValueType::Bin, H, "0b1010"), [10]);
        assert_eq!(enc(ValueType::Bin, H, "1111_0000"), [0xF0]);
        for (kind, text) in [
            (ValueType::U16, "-1"),
            (ValueType::U16, "65536"),
            (ValueType::I16, "32768"),
            (ValueType::U16, "abc"),
            (ValueType::U16, ""),
            (ValueType::U16, "--1"),
            (ValueType::Hex, "0x10000"),
            (ValueType::Bin, "2"),
            (ValueType::U16, "99999999999999999999999999999999999999999999"),
        ] {
            assert!(encode(kind, H, text).is_err(), "{text}");
        }
    }

    #[test]
    fn thirty_two_bit_values_follow_the_word_order() {
        // 3G3RX F002 = 300000 = 0x000493E0, high word first (reference §4.9).
        assert_eq!(enc(ValueType::U32, WordOrder::Abcd, "300000"), [0x0004, 0x93E0]);
        // SDP example: 0BB8 at 0x0112, 0000 at 0x0113: 3000 low word first.
        assert_eq!(enc(ValueType::U32, WordOrder::Cdab, "3000"), [0x0BB8, 0x0000]);
        assert_eq!(enc(ValueType::I32, WordOrder::Abcd, "-2"), [0xFFFF, 0xFFFE]);
        assert_eq!(enc(ValueType::F32, WordOrder::Abcd, "1.0"), [0x3F80, 0x0000]);
        assert_eq!(enc(ValueType::F32, WordOrder::Cdab, "0x3F800000"), [0x0000, 0x3F80]);
        assert!(encode(ValueType::U32, WordOrder::Abcd, "4294967296").is_err());
        assert!(encode(ValueType::F32, WordOrder::Abcd, "1e40").is_err());
        assert!(encode(ValueType::F32, WordOrder::Abcd, "pi").is_err());
    }

    #[test]
    fn decoding_inverts_encoding() {
        for (kind, text) in [
            (ValueType::U32, "300000"),
            (ValueType::I32, "-123456"),
            (ValueType::F32, "-2.5"),
            (ValueType::I16, "-300"),
        ] {
            for order in WordOrder::ALL {
                let regs = enc(kind, order, text);
                assert_eq!(decode(kind, order, &regs).unwrap().to_string(), text, "{order}");
            }
        }
        let one = |kind, regs: &[u16]| decode(kind, WordOrder::Abcd, regs).unwrap();
        assert_eq!(one(ValueType::Hex, &[0x0A]).to_string(), "0x000A");
        assert_eq!(one(ValueType::Bin, &[0x0A]).to_string(), "0b0000_0000_0000_1010");
        assert_eq!(one(ValueType::F32, &[0x7FC0, 0]).to_json(), serde_json::Value::Null);
        assert_eq!(decode(ValueType::U32, WordOrder::Abcd, &[1]), None, "one register is not a u32");
    }

    #[test]
    fn coils_take_words_and_digits() {
        assert!(parse_coil("ON").unwrap());
        assert!(!parse_coil("false").unwrap());
        assert!(parse_coil("2").is_err());
    }

    #[test]
    fn floats_use_an_exponent_when_very_large_or_very_small() {
        let show = |v: f32| Decoded::Float(v).to_string();
        assert_eq!(show(-4.950_203_4e32), "-4.9502034e32");
        assert_eq!(show(1e16), "1e16");
        assert_eq!(show(9_999_999_000_000_000.0), "9999999000000000");
        assert_eq!(show(1.5e-5), "1.5e-5");
        assert_eq!(show(0.0001), "0.0001");
        assert_eq!(show(-2.5), "-2.5");
        assert_eq!(show(0.0), "0");
        assert_eq!(show(f32::NAN), "NaN");
        assert_eq!(show(f32::NEG_INFINITY), "-inf");
        assert_eq!(show(f32::MIN_POSITIVE), "1.1754944e-38");
    }
}
