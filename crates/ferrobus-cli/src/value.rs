//! Typed register values: how numbers are typed, encoded into registers and shown.
//!
//! A 32-bit value takes two registers. Which comes first differs by device: the Omron and
//! Hitachi drives put the high word at the lower address (reference §4.9), the SDP servo
//! example suggests the low word first (§5); hence `--word-order`.

use std::fmt;

use clap::{Args, ValueEnum};

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
}

pub(crate) use ferrobus_proto::words::WordOrder;

/// `--word-order`: a name of the core's [`WordOrder`].
fn parse_word_order(text: &str) -> Result<WordOrder, String> {
    WordOrder::from_name(text).ok_or_else(|| format!("'{text}' is not a word order: use high-first or low-first"))
}

/// The options that say how registers are typed.
#[derive(Args, Clone, Copy, Debug, Default)]
#[command(next_help_heading = "Values")]
pub(crate) struct ValueArgs {
    /// Value type: u16, i16, hex, bin (one register each); u32, i32, f32 (two registers each)
    #[arg(long = "type", short = 't', value_enum, default_value_t = ValueType::U16, hide_possible_values = true)]
    pub(crate) kind: ValueType,

    /// Register order of 32-bit values: high-first (Omron/Hitachi drives) or low-first
    /// [default: high-first, or the --device profile's order]
    #[arg(long = "word-order", value_parser = parse_word_order)]
    pub(crate) word_order: Option<WordOrder>,

    /// Same as --word-order low-first
    #[arg(long, conflicts_with = "word_order")]
    pub(crate) swap: bool,
}

impl ValueArgs {
    /// The word order, with `--swap` applied.
    pub(crate) fn order(self) -> WordOrder {
        if self.swap { WordOrder::LowFirst } else { self.word_order.unwrap_or_default() }
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
        registers.chunks_exact(self.kind.width()).map(|regs| decode(self.kind, self.order(), regs)).collect()
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

fn split_word(value: u32, order: WordOrder) -> [u16; 2] {
    order.split(value)
}

/// The 32-bit value of two registers in `order`.
pub(crate) fn join_words(regs: [u16; 2], order: WordOrder) -> u32 {
    order.join(regs)
}

/// Decodes one value from its registers (`kind.width()` of them).
pub(crate) fn decode(kind: ValueType, order: WordOrder, regs: &[u16]) -> Decoded {
    let first = regs.first().copied().unwrap_or_default();
    let word = || join_words([first, regs.get(1).copied().unwrap_or_default()], order);
    match kind {
        ValueType::U16 => Decoded::Int(i64::from(first)),
        ValueType::I16 => Decoded::Int(i64::from(i16::from_ne_bytes(first.to_ne_bytes()))),
        ValueType::U32 => Decoded::Int(i64::from(word())),
        ValueType::I32 => Decoded::Int(i64::from(i32::from_ne_bytes(word().to_ne_bytes()))),
        ValueType::F32 => Decoded::Float(f32::from_bits(word())),
        ValueType::Hex => Decoded::Hex(first),
        ValueType::Bin => Decoded::Bin(first),
    }
}

/// An integer as typed: decimal with an optional sign, `0x` hex or `0b` binary; `_` ignored.
/// Returns the value and whether it was written in hex or binary (raw bits).
fn parse_int(text: &str) -> Option<(i128, bool)> {
    let cleaned: String = text.trim().chars().filter(|&c| c != '_').collect();
    let (negative, body) = match cleaned.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, cleaned.strip_prefix('+').unwrap_or(&cleaned)),
    };
    let (radix, digits) = if let Some(h) = body.strip_prefix("0x").or_else(|| body.strip_prefix("0X")) {
        (16, h)
    } else if let Some(b) = body.strip_prefix("0b").or_else(|| body.strip_prefix("0B")) {
        (2, b)
    } else {
        (10, body)
    };
    if digits.is_empty() || digits.len() > 40 || digits.starts_with(['+', '-']) {
        return None;
    }
    let value = i128::from_str_radix(digits, radix).ok()?;
    Some((if negative { -value } else { value }, radix != 10))
}

fn bad(text: &str, kind: ValueType, why: &str) -> CliError {
    CliError::Usage(format!("value '{text}' is not a valid {}: {why}", kind.name()))
}

/// Encodes one typed value into registers.
pub(crate) fn encode(kind: ValueType, order: WordOrder, text: &str) -> Result<Vec<u16>, CliError> {
    let int = |text: &str| parse_int(text).ok_or_else(|| bad(text, kind, "expected a number (decimal, 0x hex)"));
    let range = |v: i128, min: i128, max: i128, hint: &str| {
        if (min..=max).contains(&v) {
            Ok(v)
        } else {
            Err(bad(text, kind, &format!("out of range {min}..={max}{hint}")))
        }
    };
    let regs = match kind {
        ValueType::U16 => {
            let (v, _) = int(text)?;
            let hint = if v < 0 { "; use --type i16 for negative values" } else { "" };
            vec![u16::try_from(range(v, 0, 0xFFFF, hint)?).unwrap_or_default()]
        }
        ValueType::I16 => {
            let v = match int(text)? {
                (v, true) => range(v, 0, 0xFFFF, "")?,
                (v, false) => range(v, -0x8000, 0x7FFF, "")? & 0xFFFF,
            };
            vec![u16::try_from(v).unwrap_or_default()]
        }
        ValueType::U32 => {
            let (v, _) = int(text)?;
            let hint = if v < 0 { "; use --type i32 for negative values" } else { "" };
            split_word(u32::try_from(range(v, 0, 0xFFFF_FFFF, hint)?).unwrap_or_default(), order).to_vec()
        }
        ValueType::I32 => {
            let v = match int(text)? {
                (v, true) => range(v, 0, 0xFFFF_FFFF, "")?,
                (v, false) => range(v, -0x8000_0000, 0x7FFF_FFFF, "")? & 0xFFFF_FFFF,
            };
            split_word(u32::try_from(v).unwrap_or_default(), order).to_vec()
        }
        ValueType::F32 => split_word(parse_f32(text)?, order).to_vec(),
        ValueType::Hex => {
            let t = text.trim();
            let digits = t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")).unwrap_or(t);
            let v = parse_int(&format!("0x{digits}")).ok_or_else(|| bad(text, kind, "expected hex digits"))?.0;
            vec![u16::try_from(range(v, 0, 0xFFFF, "")?).unwrap_or_default()]
        }
        ValueType::Bin => {
            let t = text.trim();
            let digits = t.strip_prefix("0b").or_else(|| t.strip_prefix("0B")).unwrap_or(t);
            let v = parse_int(&format!("0b{digits}")).ok_or_else(|| bad(text, kind, "expected binary digits"))?.0;
            vec![u16::try_from(range(v, 0, 0xFFFF, "")?).unwrap_or_default()]
        }
    };
    Ok(regs)
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
    fn word_order_takes_the_cores_names_and_says_what_a_wrong_one_should_be() {
        assert_eq!(parse_word_order("high-first"), Ok(WordOrder::HighFirst));
        assert_eq!(parse_word_order("low-first"), Ok(WordOrder::LowFirst));
        assert_eq!(parse_word_order("abcd"), Err("'abcd' is not a word order: use high-first or low-first".into()));
    }

    fn enc(kind: ValueType, order: WordOrder, text: &str) -> Vec<u16> {
        encode(kind, order, text).unwrap()
    }

    #[test]
    fn sixteen_bit_values_take_decimal_hex_and_signs() {
        use WordOrder::HighFirst as H;
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
        assert_eq!(enc(ValueType::U32, WordOrder::HighFirst, "300000"), [0x0004, 0x93E0]);
        // SDP example: 0BB8 at 0x0112, 0000 at 0x0113: 3000 low word first.
        assert_eq!(enc(ValueType::U32, WordOrder::LowFirst, "3000"), [0x0BB8, 0x0000]);
        assert_eq!(enc(ValueType::I32, WordOrder::HighFirst, "-2"), [0xFFFF, 0xFFFE]);
        assert_eq!(enc(ValueType::F32, WordOrder::HighFirst, "1.0"), [0x3F80, 0x0000]);
        assert_eq!(enc(ValueType::F32, WordOrder::LowFirst, "0x3F800000"), [0x0000, 0x3F80]);
        assert!(encode(ValueType::U32, WordOrder::HighFirst, "4294967296").is_err());
        assert!(encode(ValueType::F32, WordOrder::HighFirst, "1e40").is_err());
        assert!(encode(ValueType::F32, WordOrder::HighFirst, "pi").is_err());
    }

    #[test]
    fn decoding_inverts_encoding() {
        for (kind, text) in [
            (ValueType::U32, "300000"),
            (ValueType::I32, "-123456"),
            (ValueType::F32, "-2.5"),
            (ValueType::I16, "-300"),
        ] {
            for order in [WordOrder::HighFirst, WordOrder::LowFirst] {
                let regs = enc(kind, order, text);
                assert_eq!(decode(kind, order, &regs).to_string(), text);
            }
        }
        assert_eq!(decode(ValueType::Hex, WordOrder::HighFirst, &[0x0A]).to_string(), "0x000A");
        assert_eq!(decode(ValueType::Bin, WordOrder::HighFirst, &[0x0A]).to_string(), "0b0000_0000_0000_1010");
        assert_eq!(decode(ValueType::F32, WordOrder::HighFirst, &[0x7FC0, 0]).to_json(), serde_json::Value::Null);
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
