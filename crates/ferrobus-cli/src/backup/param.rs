//! A parameter as backup, diff and restore see it: where it lives, how its registers encode
//! its raw value, and how that value is shown in the profile's unit.
//!
//! The raw value is kept as a TOML value, the form it takes in a backup file: an integer for
//! the integer types (a decimal string for a `u64` above `i64::MAX`, which TOML cannot hold), a
//! float for `f32`/`f64`, a string for `string`, a boolean for a coil. Two raw values are
//! compared through the registers they encode to, so `1.0` and `1` for an `f32` agree.

use std::fmt::Write as _;

/// The table a parameter lives in.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Debug)]
pub(crate) enum Table {
    /// Holding registers (FC03, FC06, FC10).
    Holding,
    /// Input registers (FC04).
    Input,
    /// Coils (FC01, FC05).
    Coils,
    /// Discrete inputs (FC02).
    Discrete,
}

impl Table {
    /// Whether the table holds bits.
    pub(crate) fn is_bits(self) -> bool {
        matches!(self, Table::Coils | Table::Discrete)
    }
}

/// How the registers of a parameter encode its raw value.
#[allow(dead_code, reason = "i64, f32 and f64 come with the profile crate's types")]
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Kind {
    /// Unsigned 16-bit.
    U16,
    /// Signed 16-bit.
    I16,
    /// Unsigned 32-bit.
    U32,
    /// Signed 32-bit.
    I32,
    /// Unsigned 64-bit.
    U64,
    /// Signed 64-bit.
    I64,
    /// IEEE 754 single precision.
    F32,
    /// IEEE 754 double precision.
    F64,
    /// Characters, two per register, high byte first, NUL padded.
    Text,
    /// A coil or discrete input.
    Bit,
}

impl Kind {
    /// The name, as a profile writes it.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Kind::U16 => "u16",
            Kind::I16 => "i16",
            Kind::U32 => "u32",
            Kind::I32 => "i32",
            Kind::U64 => "u64",
            Kind::I64 => "i64",
            Kind::F32 => "f32",
            Kind::F64 => "f64",
            Kind::Text => "string",
            Kind::Bit => "bit",
        }
    }

    fn is_signed(self) -> bool {
        matches!(self, Kind::I16 | Kind::I32 | Kind::I64)
    }
}

/// The order of the bytes of a multi-register value, as integrators name it: the letters are
/// the value's bytes from the most significant (A) down, in the order they travel.
#[allow(dead_code, reason = "BADC and DCBA come with the profile crate's orders")]
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub(crate) enum Order {
    /// Big-endian: the high word first, each word high byte first.
    #[default]
    Abcd,
    /// The low word first, each word high byte first.
    Cdab,
    /// The high word first, the bytes of each word swapped.
    Badc,
    /// Fully little-endian.
    Dcba,
}

impl Order {
    fn words_reversed(self) -> bool {
        matches!(self, Order::Cdab | Order::Dcba)
    }

    fn bytes_swapped(self) -> bool {
        matches!(self, Order::Badc | Order::Dcba)
    }

    /// The registers, in wire order, of big-endian `bytes`.
    pub(crate) fn words_of(self, bytes: &[u8]) -> Vec<u16> {
        let mut words: Vec<u16> = bytes
            .chunks(2)
            .map(|pair| {
                let (hi, lo) = (pair.first().copied().unwrap_or(0), pair.get(1).copied().unwrap_or(0));
                if self.bytes_swapped() { u16::from_le_bytes([hi, lo]) } else { u16::from_be_bytes([hi, lo]) }
            })
            .collect();
        if self.words_reversed() {
            words.reverse();
        }
        words
    }

    /// The big-endian bytes of registers in wire order (the inverse of [`Order::words_of`]).
    pub(crate) fn bytes_of(self, words: &[u16]) -> Vec<u8> {
        let mut words = words.to_vec();
        if self.words_reversed() {
            words.reverse();
        }
        words.iter().flat_map(|w| if self.bytes_swapped() { w.to_le_bytes() } else { w.to_be_bytes() }).collect()
    }
}

/// Who may read and write a parameter.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Access {
    /// Read only.
    Ro,
    /// Read and write.
    Rw,
    /// Write only.
    Wo,
}

/// One parameter of a profile.
#[derive(Clone, Debug)]
pub(crate) struct Param {
    /// The manual's code (`F002`) or the profile's name.
    pub(crate) code: String,
    /// A short description.
    pub(crate) label: String,
    /// Its table.
    pub(crate) table: Table,
    /// The address of its first register or bit, as the frame carries it.
    pub(crate) wire: u16,
    /// Registers (1 for a bit).
    pub(crate) width: u16,
    /// Its encoding.
    pub(crate) kind: Kind,
    /// Its byte order, for more than one register.
    pub(crate) order: Order,
    /// Engineering value = raw × scale + offset.
    pub(crate) scale: f64,
    /// See `scale`.
    pub(crate) offset: f64,
    /// The engineering unit.
    pub(crate) unit: Option<String>,
    /// The lowest raw value a write may carry.
    pub(crate) min: Option<i64>,
    /// The highest raw value a write may carry.
    pub(crate) max: Option<i64>,
    /// Access.
    pub(crate) access: Access,
    /// Whether it may be written while the drive runs.
    pub(crate) while_running: bool,
    /// Parameters a restore writes before this one.
    pub(crate) depends_on: Vec<String>,
    /// Whether a backup saves it.
    pub(crate) backup: bool,
    /// An enumeration: raw value → meaning.
    pub(crate) values: Vec<(i64, String)>,
}

impl Param {
    /// The raw value of the registers (or the bit, as 0 or 1) read from the device; `words`
    /// holds [`Param::width`] of them.
    pub(crate) fn decode(&self, words: &[u16]) -> toml::Value {
        let bytes = self.order.bytes_of(words);
        let int = |signed: bool| -> toml::Value {
            let mut unsigned: u64 = 0;
            for b in &bytes {
                unsigned = (unsigned << 8) | u64::from(*b);
            }
            let bits = u32::try_from(bytes.len().saturating_mul(8)).unwrap_or(64).min(64);
            if signed && bits > 0 && bits < 64 && unsigned >> (bits - 1) & 1 == 1 {
                // Sign-extend from `bits`.
                let extended = unsigned | (u64::MAX << bits);
                return toml::Value::Integer(extended.cast_signed());
            }
            if signed {
                return toml::Value::Integer(unsigned.cast_signed());
            }
            i64::try_from(unsigned).map_or_else(|_| toml::Value::String(unsigned.to_string()), toml::Value::Integer)
        };
        match self.kind {
            Kind::Bit => toml::Value::Boolean(words.first().is_some_and(|w| *w != 0)),
            Kind::F32 => {
                let four: [u8; 4] = bytes.get(..4).and_then(|b| b.try_into().ok()).unwrap_or_default();
                toml::Value::Float(f64::from(f32::from_be_bytes(four)))
            }
            Kind::F64 => {
                let eight: [u8; 8] = bytes.get(..8).and_then(|b| b.try_into().ok()).unwrap_or_default();
                toml::Value::Float(f64::from_be_bytes(eight))
            }
            Kind::Text => {
                let text: String = bytes.iter().take_while(|b| **b != 0).map(|b| char::from(*b)).collect();
                toml::Value::String(text)
            }
            kind => int(kind.is_signed()),
        }
    }

    /// The registers (or the bit as 0 or 1) that carry `raw`, or why `raw` cannot be this
    /// parameter's value.
    pub(crate) fn encode(&self, raw: &toml::Value) -> Result<Vec<u16>, String> {
        let width = usize::from(self.width);
        let bytes = usize::from(self.width).saturating_mul(2);
        match (self.kind, raw) {
            (Kind::Bit, toml::Value::Boolean(b)) => Ok(vec![u16::from(*b)]),
            (Kind::Bit, toml::Value::Integer(n @ (0 | 1))) => Ok(vec![u16::try_from(*n).unwrap_or(0)]),
            (Kind::F32, toml::Value::Float(f)) => {
                #[expect(clippy::cast_possible_truncation, reason = "an f32 parameter holds an f32")]
                let single = *f as f32;
                Ok(self.order.words_of(&single.to_be_bytes()))
            }
            (Kind::F64, toml::Value::Float(f)) => Ok(self.order.words_of(&f.to_be_bytes())),
            #[expect(clippy::cast_precision_loss, reason = "an integer typed for a float parameter")]
            (Kind::F32 | Kind::F64, toml::Value::Integer(n)) => self.encode(&toml::Value::Float(*n as f64)),
            (Kind::Text, toml::Value::String(text)) => {
                if !text.is_ascii() || text.contains('\0') {
                    return Err(format!("\"{text}\" is not plain ASCII text"));
                }
                if text.len() > bytes {
                    return Err(format!("\"{text}\" has {} characters; {} hold {bytes}", text.len(), self.width));
                }
                let mut padded = text.as_bytes().to_vec();
                padded.resize(bytes, 0);
                Ok(Order::Abcd.words_of(&padded))
            }
            (Kind::U64, toml::Value::String(digits)) => {
                let n: u64 = digits.parse().map_err(|_| format!("\"{digits}\" is not an unsigned integer"))?;
                Ok(self.order.words_of(&n.to_be_bytes()))
            }
            (kind, toml::Value::Integer(n)) if !matches!(kind, Kind::Bit | Kind::Text) => {
                let bits = u32::try_from(width.saturating_mul(16)).unwrap_or(64).min(64);
                let fits = if kind.is_signed() {
                    bits >= 64 || (-(1_i128 << (bits - 1))..(1_i128 << (bits - 1))).contains(&i128::from(*n))
                } else {
                    *n >= 0 && (bits >= 64 || i128::from(*n) < (1_i128 << bits))
                };
                if !fits {
                    return Err(format!("{n} does not fit a {}", kind.name()));
                }
                let all = n.to_be_bytes();
                let tail = all.get(8_usize.saturating_sub(bytes)..).unwrap_or(&all);
                Ok(self.order.words_of(tail))
            }
            (kind, other) => Err(format!("{} is not a {} value", shown_toml(other), kind.name())),
        }
    }

    /// Why `raw` may not be written: outside `min`..=`max`. Floats and text have no limits here.
    pub(crate) fn out_of_range(&self, raw: &toml::Value) -> Option<String> {
        let n = match raw {
            toml::Value::Integer(n) => i128::from(*n),
            toml::Value::String(digits) if self.kind == Kind::U64 => digits.parse::<u64>().ok().map(i128::from)?,
            _ => return None,
        };
        let below = self.min.is_some_and(|min| n < i128::from(min));
        let above = self.max.is_some_and(|max| n > i128::from(max));
        if !below && !above {
            return None;
        }
        let limit = |l: Option<i64>| l.map_or_else(|| "-".to_string(), |v| self.show(&toml::Value::Integer(v)));
        Some(format!("{} is outside its range {} to {}", self.show(raw), limit(self.min), limit(self.max)))
    }

    /// The raw value in the profile's unit: `50.00 Hz`, an enumeration's meaning (`3 (modbus)`),
    /// `on`/`off` for a bit, the text of a string.
    pub(crate) fn show(&self, raw: &toml::Value) -> String {
        match raw {
            toml::Value::Boolean(b) => (if *b { "on" } else { "off" }).to_string(),
            toml::Value::String(text) if self.kind == Kind::Text => format!("\"{text}\""),
            toml::Value::Integer(n) => {
                if let Some((_, meaning)) = self.values.iter().find(|(v, _)| v == n) {
                    return format!("{n} ({meaning})");
                }
                #[expect(clippy::cast_precision_loss, reason = "shown in engineering units")]
                self.engineering(*n as f64)
            }
            toml::Value::Float(f) => self.engineering(*f),
            other => shown_toml(other),
        }
    }

    fn engineering(&self, raw: f64) -> String {
        let value = raw * self.scale + self.offset;
        let mut text = if (self.scale - 1.0).abs() < f64::EPSILON && self.offset == 0.0 && raw.fract() == 0.0 {
            format!("{value}")
        } else {
            format!("{value:.*}", decimals(self.scale))
        };
        if let Some(unit) = &self.unit {
            let _ = write!(text, " {unit}");
        }
        text
    }

    /// Whether a write may carry it.
    pub(crate) fn writable(&self) -> bool {
        self.access != Access::Ro && matches!(self.table, Table::Holding | Table::Coils)
    }
}

/// The decimals a scale shows: 0.01 → 2, 0.1 → 1, 1 or more → 0.
fn decimals(scale: f64) -> usize {
    let mut decimals = 0;
    let mut step = scale.abs();
    while step > 0.0 && step < 0.999_999 && decimals < 9 {
        step *= 10.0;
        decimals += 1;
    }
    decimals
}

/// A TOML value as it is written.
pub(crate) fn shown_toml(value: &toml::Value) -> String {
    match value {
        toml::Value::String(s) => format!("\"{s}\""),
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn param(kind: Kind, width: u16, order: Order) -> Param {
        Param {
            code: "P".into(),
            label: String::new(),
            table: if kind == Kind::Bit { Table::Coils } else { Table::Holding },
            wire: 0,
            width,
            kind,
            order,
            scale: 1.0,
            offset: 0.0,
            unit: None,
            min: None,
            max: None,
            access: Access::Rw,
            while_running: true,
            depends_on: Vec::new(),
            backup: true,
            values: Vec::new(),
        }
    }

    #[test]
    fn the_four_orders_place_the_bytes_of_0x11223344_as_named() {
        let value = toml::Value::Integer(0x1122_3344);
        for (order, words) in [
            (Order::Abcd, [0x1122, 0x3344]),
            (Order::Cdab, [0x3344, 0x1122]),
            (Order::Badc, [0x2211, 0x4433]),
            (Order::Dcba, [0x4433, 0x2211]),
        ] {
            let p = param(Kind::U32, 2, order);
            assert_eq!(p.encode(&value).unwrap(), words, "{order:?}");
            assert_eq!(p.decode(&words), value, "{order:?}");
        }
    }

    #[test]
    fn signed_and_wide_integers_round_trip_through_their_registers() {
        let cases = [
            (Kind::I16, 1, -2_i64),
            (Kind::I32, 2, -100_000),
            (Kind::I64, 4, i64::MIN),
            (Kind::U64, 4, i64::MAX),
            (Kind::U16, 1, 65_535),
        ];
        for (kind, width, n) in cases {
            let p = param(kind, width, Order::Cdab);
            let words = p.encode(&toml::Value::Integer(n)).unwrap();
            assert_eq!(words.len(), usize::from(width));
            assert_eq!(p.decode(&words), toml::Value::Integer(n), "{kind:?}");
        }
        let big = param(Kind::U64, 4, Order::Abcd);
        assert_eq!(big.decode(&[0xFFFF; 4]), toml::Value::String(u64::MAX.to_string()));
        assert_eq!(big.encode(&toml::Value::String(u64::MAX.to_string())).unwrap(), [0xFFFF; 4]);
    }

    #[test]
    fn a_value_that_does_not_fit_its_type_is_refused_with_the_type() {
        assert_eq!(
            param(Kind::U16, 1, Order::Abcd).encode(&toml::Value::Integer(65_536)).unwrap_err(),
            "65536 does not fit a u16"
        );
        assert_eq!(
            param(Kind::U32, 2, Order::Abcd).encode(&toml::Value::Integer(-1)).unwrap_err(),
            "-1 does not fit a u32"
        );
        assert_eq!(
            param(Kind::I16, 1, Order::Abcd).encode(&toml::Value::Integer(32_768)).unwrap_err(),
            "32768 does not fit a i16"
        );
        let text = param(Kind::U16, 1, Order::Abcd).encode(&toml::Value::String("x".into())).unwrap_err();
        assert_eq!(text, "\"x\" is not a u16 value");
    }

    #[test]
    fn floats_and_strings_round_trip() {
        let f = param(Kind::F32, 2, Order::Cdab);
        let words = f.encode(&toml::Value::Float(-2.5)).unwrap();
        assert_eq!(words, [0x0000, 0xC020]);
        assert_eq!(f.decode(&words), toml::Value::Float(-2.5));
        let d = param(Kind::F64, 4, Order::Dcba);
        assert_eq!(d.decode(&d.encode(&toml::Value::Float(0.1)).unwrap()), toml::Value::Float(0.1));
        let s = param(Kind::Text, 3, Order::Abcd);
        let words = s.encode(&toml::Value::String("RX2".into())).unwrap();
        assert_eq!(words, [0x5258, 0x3200, 0x0000]);
        assert_eq!(s.decode(&words), toml::Value::String("RX2".into()));
        assert!(s.encode(&toml::Value::String("seven c".into())).unwrap_err().contains("has 7 characters"));
    }

    #[test]
    fn values_are_shown_scaled_with_their_unit_and_enumerations_named() {
        let mut p = param(Kind::U32, 2, Order::Abcd);
        p.scale = 0.01;
        p.unit = Some("Hz".into());
        assert_eq!(p.show(&toml::Value::Integer(5000)), "50.00 Hz");
        p.scale = 0.1;
        p.offset = -40.0;
        p.unit = Some("°C".into());
        assert_eq!(p.show(&toml::Value::Integer(652)), "25.2 °C");
        let mut e = param(Kind::U16, 1, Order::Abcd);
        e.values = vec![(3, "modbus".into())];
        assert_eq!(e.show(&toml::Value::Integer(3)), "3 (modbus)");
        assert_eq!(e.show(&toml::Value::Integer(4)), "4");
        assert_eq!(param(Kind::Bit, 1, Order::Abcd).show(&toml::Value::Boolean(true)), "on");
    }

    #[test]
    fn a_raw_value_outside_min_max_is_named_with_the_range_in_units() {
        let mut p = param(Kind::U16, 1, Order::Abcd);
        p.scale = 0.01;
        p.unit = Some("s".into());
        p.min = Some(1);
        p.max = Some(360_000);
        assert_eq!(p.out_of_range(&toml::Value::Integer(1000)), None);
        assert_eq!(
            p.out_of_range(&toml::Value::Integer(0)).unwrap(),
            "0.00 s is outside its range 0.01 s to 3600.00 s"
        );
    }
}
