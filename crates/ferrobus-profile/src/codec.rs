//! Values: a point's registers or bit as a typed raw value, that value in engineering units
//! with its unit, enumeration or bit field, and a user's input ("45Hz", "12.5s", "0x10",
//! "modbus") back to a raw value, checked against the point's type, range and access.
//!
//! [`Point::decode`] and [`Point::encode`] are the project's one codec between registers and
//! values: get, set, backup, poll, monitor and the bridge use them on a profile's points,
//! read and write on a [`Point::raw`] of the type and word order typed. The layout of bytes
//! over registers is the core's [`Order`] (`ferrobus_proto::words`).

use crate::model::{Order, Point, Value, ValueType};
use crate::text::{self, Radix};

/// Whether a number read now, `now`, has moved beyond `deadband` from `last`, the one last
/// reported: the one deadband rule of report-by-exception (`poll --on-change`, the bridge).
///
/// - a NaN after a number, or a number after a NaN: moved (every change between NaN and a
///   number is reported);
/// - a NaN after a NaN: not moved (it is not repeated);
/// - equal numbers (an infinity after the same infinity too): not moved;
/// - otherwise moved when `|now − last|` is more than `deadband` (exactly `deadband` is not
///   beyond it); a deadband of 0 or below reports any change, a NaN deadband every one.
pub fn beyond_deadband(last: f64, now: f64, deadband: f64) -> bool {
    match (last.is_nan(), now.is_nan()) {
        (true, true) => false,
        (true, false) | (false, true) => true,
        #[allow(clippy::float_cmp)]
        (false, false) if last == now => false,
        (false, false) => {
            matches!((now - last).abs().partial_cmp(&deadband), Some(std::cmp::Ordering::Greater) | None)
        }
    }
}

/// Why a value could not be decoded, encoded, parsed or written.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ValueError {
    /// The registers given are not as many as the point takes.
    #[error("{code}: {got} registers for a {ty} of {want}")]
    Registers {
        /// The point.
        code: String,
        /// Registers given.
        got: usize,
        /// Registers it takes.
        want: u16,
        /// Its type.
        ty: &'static str,
    },
    /// A value of the wrong kind for the point (a text for a number, ...).
    #[error("{code}: {value} is not a {ty} value")]
    Kind {
        /// The point.
        code: String,
        /// The value.
        value: String,
        /// Its type.
        ty: &'static str,
    },
    /// The input is not a number (nor a name the point knows).
    #[error("{code}: {text:?} is not a number{}", choices_hint(choices))]
    NotANumber {
        /// The point.
        code: String,
        /// What was typed.
        text: String,
        /// The enumeration's names, if any.
        choices: Vec<String>,
    },
    /// The input carries a unit that is not the point's.
    #[error("{code}: {text:?} is not in {}", unit.as_deref().map_or("plain numbers (it has no unit)".to_string(), |u| format!("{u}, the unit of {code}")))]
    WrongUnit {
        /// The point.
        code: String,
        /// What was typed.
        text: String,
        /// The point's unit.
        unit: Option<String>,
    },
    /// The input is between two steps of the point's scale.
    #[error("{code}: {text} is not a multiple of its step {step}")]
    NotAStep {
        /// The point.
        code: String,
        /// What was typed.
        text: String,
        /// The step, with its unit.
        step: String,
    },
    /// The raw value does not fit the point's type.
    #[error("{code}: {text} does not fit a {ty}")]
    Overflow {
        /// The point.
        code: String,
        /// What was typed.
        text: String,
        /// The type.
        ty: &'static str,
    },
    /// A string longer than the point's registers hold, or not ASCII.
    #[error("{code}: {text:?} does not fit: at most {max} ASCII characters")]
    TooLong {
        /// The point.
        code: String,
        /// What was typed.
        text: String,
        /// The most characters.
        max: usize,
    },
    /// Outside the point's min/max.
    #[error("{code}: {text} is out of range: {min} to {max}")]
    OutOfRange {
        /// The point.
        code: String,
        /// What was typed (in the user's notation).
        text: String,
        /// The lowest value, in engineering units.
        min: String,
        /// The highest value, in engineering units.
        max: String,
    },
    /// The point is read-only.
    #[error("{code} is read-only")]
    ReadOnly {
        /// The point.
        code: String,
    },
}

fn choices_hint(choices: &[String]) -> String {
    if choices.is_empty() { String::new() } else { format!(" nor one of {}", choices.join(", ")) }
}

/// The raw start value of a register entry of type `ty` (checked to fit).
pub(crate) fn default_value(ty: ValueType, default: Option<&toml::Value>) -> Value {
    match (ty, default) {
        (ValueType::String, Some(toml::Value::String(s))) => Value::Text(s.clone()),
        (ValueType::String, _) => Value::Text(String::new()),
        #[allow(clippy::cast_precision_loss)]
        (t, Some(toml::Value::Integer(n))) if t.is_float() => Value::Float(*n as f64),
        (t, Some(toml::Value::Float(x))) if t.is_float() => Value::Float(*x),
        (t, _) if t.is_float() => Value::Float(0.0),
        (_, Some(toml::Value::Integer(n))) => Value::Int(i128::from(*n)),
        _ => Value::Int(0),
    }
}

/// Bytes in value order (big-endian) to registers in address order, by `order` (the core's
/// one layout, [`Order::to_registers`]).
fn to_registers(bytes: &[u8], order: Order) -> Vec<u16> {
    let mut words = vec![0; bytes.len().div_ceil(2)];
    order.to_registers(bytes, &mut words);
    words
}

/// Registers in address order to bytes in value order (big-endian), by `order`.
fn from_registers(words: &[u16], order: Order) -> Vec<u8> {
    let mut bytes = vec![0; words.len() * 2];
    order.from_registers(words, &mut bytes);
    bytes
}

/// The decimals a scale's step shows: 0.01 → 2, 0.5 → 1, 10 → 0.
fn decimals(step: f64) -> usize {
    let step = step.abs();
    (0..=9usize)
        .find(|&d| {
            let shifted = step * 10f64.powi(i32::try_from(d).unwrap_or(0));
            (shifted - shifted.round()).abs() < 1e-9 * shifted.max(1.0)
        })
        .unwrap_or(6)
}

/// How a value the device does not implement is shown to people (`get`, `poll`, `monitor`).
pub const NOT_IMPLEMENTED: &str = "n/a";

/// Whether raw values `a` and `b` are the same (a NaN is the same as a NaN).
fn same(a: &Value, b: &Value) -> bool {
    match (a, b) {
        (Value::Float(x), Value::Float(y)) => (x.is_nan() && y.is_nan()) || x.to_bits() == y.to_bits(),
        _ => a == b,
    }
}

impl Point {
    /// Whether raw value `raw` is a reading: false when the point is not implemented at all,
    /// or `raw` is its not-implemented value (SunSpec's 0xFFFF, 0x8000, NaN, ...). A value
    /// that is not a reading shows as [`NOT_IMPLEMENTED`] ([`Point::show`]), has no number
    /// ([`Point::number`] is empty, [`Point::engineering`] `None`) and no meaning.
    pub fn implemented(&self, raw: &Value) -> bool {
        self.implemented && !self.not_implemented.as_ref().is_some_and(|ni| same(ni, raw))
    }

    /// The raw value of the point's registers, `words` in address order (exactly its width).
    pub fn decode(&self, words: &[u16]) -> Result<Value, ValueError> {
        if words.len() != usize::from(self.width) || self.value_type == ValueType::Bit {
            return Err(ValueError::Registers {
                code: self.code.clone(),
                got: words.len(),
                want: self.width,
                ty: self.value_type.name(),
            });
        }
        let ty = self.value_type;
        if ty == ValueType::String {
            let bytes = from_registers(words, Order::Abcd);
            let text: String = bytes.iter().take_while(|b| **b != 0).map(|&b| char::from(b)).collect();
            return Ok(Value::Text(text));
        }
        let bytes = from_registers(words, self.order);
        let unsigned = bytes.iter().fold(0u128, |acc, &b| (acc << 8) | u128::from(b));
        Ok(match ty {
            ValueType::F32 => Value::Float(f64::from(f32::from_bits(u32::try_from(unsigned).unwrap_or(0)))),
            ValueType::F64 => Value::Float(f64::from_bits(u64::try_from(unsigned).unwrap_or(0))),
            ValueType::I16 => Value::Int(i128::from(u16::try_from(unsigned).unwrap_or(0).cast_signed())),
            ValueType::I32 => Value::Int(i128::from(u32::try_from(unsigned).unwrap_or(0).cast_signed())),
            ValueType::I64 => Value::Int(i128::from(u64::try_from(unsigned).unwrap_or(0).cast_signed())),
            _ => Value::Int(i128::try_from(unsigned).unwrap_or(0)),
        })
    }

    /// The registers of raw value `value`, in address order.
    pub fn encode(&self, value: &Value) -> Result<Vec<u16>, ValueError> {
        let ty = self.value_type;
        let kind = || ValueError::Kind { code: self.code.clone(), value: value.to_string(), ty: ty.name() };
        let bytes: Vec<u8> = match (ty, value) {
            (ValueType::Bit, _) => return Err(kind()),
            (ValueType::String, Value::Text(s)) => {
                let max = usize::from(self.width) * 2;
                if s.len() > max || !s.is_ascii() {
                    return Err(ValueError::TooLong { code: self.code.clone(), text: s.clone(), max });
                }
                let mut bytes = s.as_bytes().to_vec();
                bytes.resize(max, 0);
                return Ok(to_registers(&bytes, Order::Abcd));
            }
            (ValueType::F32, v) => {
                #[allow(clippy::cast_possible_truncation)]
                let x = v.as_f64().ok_or_else(kind)? as f32;
                x.to_bits().to_be_bytes().to_vec()
            }
            (ValueType::F64, v) => v.as_f64().ok_or_else(kind)?.to_bits().to_be_bytes().to_vec(),
            (t, Value::Int(n)) if t.is_integer() => {
                let (lo, hi) = t.integer_range();
                if *n < lo || *n > hi {
                    return Err(ValueError::Overflow { code: self.code.clone(), text: n.to_string(), ty: t.name() });
                }
                let all = n.cast_unsigned().to_be_bytes();
                let n_bytes = usize::from(t.registers()) * 2;
                all.get(all.len().saturating_sub(n_bytes)..).unwrap_or_default().to_vec()
            }
            _ => return Err(kind()),
        };
        Ok(to_registers(&bytes, self.order))
    }

    /// The engineering value of a numeric raw value, raw × scale + offset, at the point's
    /// resolution: the number [`Point::number`] writes, so that 3498 × 0.01 is 34.98, not
    /// 34.980000000000004, and an f32's 1.1 is 1.1, not 1.100000023841858. `None` for text.
    pub fn engineering(&self, raw: &Value) -> Option<f64> {
        let exact = self.exact(raw)?;
        Some(self.number(raw).parse().unwrap_or(exact))
    }

    /// raw × scale + offset, as computed; `None` for a value that is not a reading.
    fn exact(&self, raw: &Value) -> Option<f64> {
        if !self.implemented(raw) {
            return None;
        }
        raw.as_f64().map(|x| x * self.scale + self.offset)
    }

    /// The decimals the point's scale and offset show (0.01 → 2), or `None` for an unscaled
    /// point, whose value shows as it is.
    fn resolution(&self) -> Option<usize> {
        let unscaled = (self.scale - 1.0).abs() < f64::EPSILON && self.offset == 0.0;
        (!unscaled).then(|| decimals(self.scale).max(decimals(self.offset)))
    }

    /// The raw value as the device's documentation shows it: scaled with its unit
    /// (`50.00 Hz`), an enumeration's meaning (`run`), a bit field's set bits (`running,
    /// trip`; `none`), a string as is, a bit as 0 or 1.
    ///
    /// This is the one formatting of a value for people (get, set, backup, diff, restore,
    /// poll, monitor); scripts' formats take its parts: [`Point::number`] (with its `unit`
    /// beside it) and [`Point::meaning`].
    pub fn show(&self, raw: &Value) -> String {
        if !self.implemented(raw) {
            return NOT_IMPLEMENTED.to_string();
        }
        match raw {
            Value::Bool(b) => u8::from(*b).to_string(),
            // A device's text is shown, never obeyed: its control characters (an ESC that
            // would drive the terminal) are spelled out.
            Value::Text(s) if s.chars().any(char::is_control) => {
                s.chars().flat_map(|c| if c.is_control() { c.escape_default().collect() } else { vec![c] }).collect()
            }
            Value::Text(s) => s.clone(),
            number => self.meaning(number).unwrap_or_else(|| self.show_plain(number)),
        }
    }

    /// What an enumeration's or a bit field's raw value means (`run`; `running, trip`;
    /// `5 (not in the profile's list)`); `None` for a point that is neither.
    pub fn meaning(&self, raw: &Value) -> Option<String> {
        let Value::Int(n) = raw else { return None };
        if !self.implemented(raw) {
            return None;
        }
        if !self.values.is_empty() {
            return Some(match self.values.iter().find(|(k, _)| k == n) {
                Some((_, meaning)) => meaning.clone(),
                None => format!("{n} (not in the profile's list)"),
            });
        }
        (!self.bits.is_empty()).then(|| self.show_bits(*n))
    }

    fn show_bits(&self, n: i128) -> String {
        let width_bits = u32::from(self.width) * 16;
        let set: Vec<String> = (0..width_bits)
            .filter(|b| (n.cast_unsigned() >> b) & 1 == 1)
            .map(|b| match self.bits.iter().find(|(k, _)| u32::from(*k) == b) {
                Some((_, meaning)) => meaning.clone(),
                None => format!("bit {b}"),
            })
            .collect();
        if set.is_empty() { "none".to_string() } else { set.join(", ") }
    }

    /// The engineering number without unit, at the point's resolution: `50.00` for scale
    /// 0.01, `-3`, `1.5`, an f32 in its shortest form (`1.1`), a bit as `0`/`1`, a text as is.
    /// CSV and JSON write this (or [`Point::engineering`], the same number) as the value;
    /// empty for a value that is not a reading ([`Point::implemented`]).
    pub fn number(&self, raw: &Value) -> String {
        if !self.implemented(raw) {
            return String::new();
        }
        let Some(x) = self.exact(raw) else {
            return match raw {
                Value::Text(s) => s.clone(),
                other => other.to_string(),
            };
        };
        match (self.resolution(), raw) {
            (Some(d), _) => format!("{x:.d$}"),
            (None, Value::Int(n)) => n.to_string(),
            // Decoded from an f32, so exact as one: its shortest form is what was stored.
            #[allow(clippy::cast_possible_truncation)]
            (None, Value::Float(f)) if self.value_type == ValueType::F32 => format!("{}", *f as f32),
            (None, _) => format!("{x}"),
        }
    }

    /// A raw value as an engineering number with the point's unit, for messages.
    fn show_plain(&self, raw: &Value) -> String {
        let number = self.number(raw);
        match &self.unit {
            Some(unit) => format!("{number} {unit}"),
            None => number,
        }
    }

    /// The raw value `text` asks for: an engineering number with or without the point's unit
    /// (`45Hz`, `45 Hz`, `12.5`), a raw integer in hex or binary (`0x10`, `0b101`), an
    /// enumeration's meaning (`modbus`, case-insensitive), text for a string, `0`/`1`/`on`/
    /// `off`/`true`/`false` for a bit. Checked against the type, not yet the range.
    pub fn parse(&self, text: &str) -> Result<Value, ValueError> {
        let typed = text.trim();
        let not_a_number = || ValueError::NotANumber {
            code: self.code.clone(),
            text: typed.to_string(),
            choices: self.values.iter().map(|(_, m)| m.clone()).collect(),
        };
        match self.value_type {
            ValueType::Bit => {
                return match typed.to_ascii_lowercase().as_str() {
                    "1" | "on" | "true" => Ok(Value::Bool(true)),
                    "0" | "off" | "false" => Ok(Value::Bool(false)),
                    _ => Err(not_a_number()),
                };
            }
            ValueType::String => {
                let value = Value::Text(typed.to_string());
                self.encode(&value)?;
                return Ok(value);
            }
            _ => {}
        }
        if let Some((raw, _)) = self.values.iter().find(|(_, m)| fold(m) == fold(typed)) {
            return Ok(Value::Int(*raw));
        }
        if let Some((raw, Radix::Hex | Radix::Binary)) = text::integer(typed) {
            return self.fit(Value::Int(raw), typed);
        }
        let number = self.strip_unit(typed)?;
        let unscaled = (self.scale - 1.0).abs() < f64::EPSILON && self.offset == 0.0;
        if let (true, true, Ok(n)) = (unscaled, self.value_type.is_integer(), number.parse::<i128>()) {
            // Exactly, past the 53 bits a float holds (u64, i64).
            return self.fit(Value::Int(n), typed);
        }
        let x: f64 = number.parse().map_err(|_| not_a_number())?;
        if !x.is_finite() {
            return Err(not_a_number());
        }
        let raw = (x - self.offset) / self.scale;
        if self.value_type.is_float() {
            return self.fit(Value::Float(raw), typed);
        }
        let rounded = raw.round();
        if (raw - rounded).abs() > 1e-6 * rounded.abs().max(1.0) {
            let step_text = {
                let d = decimals(self.scale);
                let s = format!("{:.d$}", self.scale.abs());
                self.unit.as_ref().map_or(s.clone(), |u| format!("{s} {u}"))
            };
            return Err(ValueError::NotAStep { code: self.code.clone(), text: typed.to_string(), step: step_text });
        }
        let (lo, hi) = self.value_type.integer_range();
        #[allow(clippy::cast_precision_loss)]
        if rounded < lo as f64 || rounded > hi as f64 {
            return Err(ValueError::Overflow {
                code: self.code.clone(),
                text: typed.to_string(),
                ty: self.value_type.name(),
            });
        }
        #[allow(clippy::cast_possible_truncation)]
        self.fit(Value::Int(rounded as i128), typed)
    }

    /// `typed` without the point's unit; an error for another unit.
    fn strip_unit<'a>(&self, typed: &'a str) -> Result<&'a str, ValueError> {
        let number_end = typed
            .char_indices()
            .find(|&(i, c)| !(c.is_ascii_digit() || matches!(c, '.' | '+' | '-') || (matches!(c, 'e' | 'E') && i > 0)))
            .map_or(typed.len(), |(i, _)| i);
        let (number, suffix) = typed.split_at(number_end);
        let suffix = suffix.trim();
        if suffix.is_empty() || !number.chars().any(|c| c.is_ascii_digit()) {
            // No unit, or no number before it: the number's parse says what is wrong.
            return Ok(if suffix.is_empty() { number.trim() } else { typed });
        }
        match &self.unit {
            Some(unit) if unit.eq_ignore_ascii_case(suffix) => Ok(number.trim()),
            _ => {
                Err(ValueError::WrongUnit { code: self.code.clone(), text: typed.to_string(), unit: self.unit.clone() })
            }
        }
    }

    fn fit(&self, value: Value, typed: &str) -> Result<Value, ValueError> {
        self.encode(&value).map_err(|e| match e {
            ValueError::Overflow { code, ty, .. } => ValueError::Overflow { code, text: typed.to_string(), ty },
            other => other,
        })?;
        Ok(value)
    }

    /// Whether raw value `raw` may be written: the point is writable and `raw` is within its
    /// min and max. `typed` is how the user wrote it, for the message.
    pub fn check_write(&self, raw: &Value, typed: &str) -> Result<(), ValueError> {
        if !self.writable() {
            return Err(ValueError::ReadOnly { code: self.code.clone() });
        }
        let Some(x) = raw.as_f64() else { return Ok(()) };
        let below = self.min.is_some_and(|m| x < m);
        let above = self.max.is_some_and(|m| x > m);
        if below || above {
            let (lo, hi) = self.value_type.integer_range();
            #[allow(clippy::cast_precision_loss)]
            let (lo, hi) = if self.value_type.is_float() { (f64::MIN, f64::MAX) } else { (lo as f64, hi as f64) };
            let bound = |b: Option<f64>, default: f64| {
                let b = b.unwrap_or(default);
                #[allow(clippy::cast_possible_truncation)]
                let raw = if self.value_type.is_float() { Value::Float(b) } else { Value::Int(b as i128) };
                self.show_plain(&raw)
            };
            return Err(ValueError::OutOfRange {
                code: self.code.clone(),
                text: typed.trim().to_string(),
                min: bound(self.min, lo),
                max: bound(self.max, hi),
            });
        }
        Ok(())
    }

    /// [`Point::parse`] then [`Point::check_write`]: the raw value to write for `text`.
    pub fn prepare_write(&self, text: &str) -> Result<Value, ValueError> {
        let raw = self.parse(text)?;
        self.check_write(&raw, text)?;
        Ok(raw)
    }
}

/// Lower case, spaces, dashes and underscores alike.
fn fold(text: &str) -> String {
    text.trim().to_lowercase().replace([' ', '_'], "-")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Profile;

    fn point(spec: &str) -> Point {
        let text = format!(
            "[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\n[[registers]]\nnumber=0\nname='p'\n{spec}\n"
        );
        Profile::parse(&text, "test.toml").unwrap().points()[0].clone()
    }

    /// (last, now, deadband, reported): the table both users (poll, the bridge) are tested with.
    const DEADBAND: [(f64, f64, f64, bool); 11] = [
        (1.0, f64::NAN, 5.0, true),
        (f64::NAN, 1.0, 5.0, true),
        (f64::NAN, f64::NAN, 5.0, false),
        (f64::NAN, f64::NAN, 0.0, false),
        (10.0, 10.5, 0.5, false),
        (10.0, 10.6, 0.5, true),
        (10.0, 9.4, 0.5, true),
        (10.0, 10.0, 0.0, false),
        (10.0, 10.001, 0.0, true),
        (f64::INFINITY, f64::INFINITY, 0.5, false),
        (f64::NEG_INFINITY, f64::INFINITY, 0.5, true),
    ];

    #[test]
    fn the_deadband_reports_every_change_between_nan_and_a_number_and_never_repeats_nan() {
        for (last, now, deadband, reported) in DEADBAND {
            assert_eq!(beyond_deadband(last, now, deadband), reported, "{last} -> {now} (deadband {deadband})");
        }
    }

    #[test]
    fn the_four_orders_lay_a_32_bit_value_over_two_registers_as_integrators_name_them() {
        // 0x11223344 as A=11 B=22 C=33 D=44.
        for (order, words) in [
            ("ABCD", [0x1122, 0x3344]),
            ("CDAB", [0x3344, 0x1122]),
            ("BADC", [0x2211, 0x4433]),
            ("DCBA", [0x4433, 0x2211]),
        ] {
            let p = point(&format!("type='u32'\norder='{order}'"));
            assert_eq!(p.encode(&Value::Int(0x1122_3344)).unwrap(), words, "{order}");
            assert_eq!(p.decode(&words).unwrap(), Value::Int(0x1122_3344), "{order}");
        }
    }

    #[test]
    fn sixty_four_bit_orders_generalise_the_same_four() {
        let v = Value::Int(0x1122_3344_5566_7788);
        let p = |o: &str| point(&format!("type='u64'\norder='{o}'"));
        assert_eq!(p("ABCD").encode(&v).unwrap(), [0x1122, 0x3344, 0x5566, 0x7788]);
        assert_eq!(p("CDAB").encode(&v).unwrap(), [0x7788, 0x5566, 0x3344, 0x1122]);
        assert_eq!(p("BADC").encode(&v).unwrap(), [0x2211, 0x4433, 0x6655, 0x8877]);
        assert_eq!(p("DCBA").encode(&v).unwrap(), [0x8877, 0x6655, 0x4433, 0x2211]);
        let i = point("type='i64'");
        assert_eq!(i.decode(&[0xFFFF, 0xFFFF, 0xFFFF, 0xFFFE]).unwrap(), Value::Int(-2));
        let u = point("type='u64'");
        assert_eq!(u.parse("18446744073709551615").unwrap(), Value::Int(i128::from(u64::MAX)), "exact past 2^53");
        assert!(matches!(u.parse("18446744073709551616"), Err(ValueError::Overflow { .. })));
    }

    #[test]
    fn floats_and_signed_values_round_trip() {
        let f = point("type='f32'");
        assert_eq!(f.encode(&Value::Float(1.5)).unwrap(), [0x3FC0, 0x0000]);
        assert_eq!(f.decode(&[0x3FC0, 0x0000]).unwrap(), Value::Float(1.5));
        let d = point("type='f64'\norder='DCBA'");
        let words = d.encode(&Value::Float(-2.25)).unwrap();
        assert_eq!(d.decode(&words).unwrap(), Value::Float(-2.25));
        let s = point("type='i16'");
        assert_eq!(s.decode(&[0xFFFF]).unwrap(), Value::Int(-1));
        assert_eq!(s.encode(&Value::Int(-1)).unwrap(), [0xFFFF]);
        assert!(matches!(s.encode(&Value::Int(40000)), Err(ValueError::Overflow { .. })));
    }

    #[test]
    fn strings_are_two_characters_a_register_high_byte_first_nul_padded() {
        let p = point("type='string'\nlength=3");
        assert_eq!(p.encode(&Value::Text("ABC".into())).unwrap(), [0x4142, 0x4300, 0x0000]);
        // What a device sends is shown, its control characters spelled out.
        let hostile = p.decode(&[0x1B5B, 0x324A, 0x0700]).unwrap();
        assert_eq!(hostile, Value::Text("\u{1b}[2J\u{7}".into()));
        assert_eq!(p.show(&hostile), "\\u{1b}[2J\\u{7}");
        assert_eq!(p.decode(&[0x4142, 0x4300, 0x0000]).unwrap(), Value::Text("ABC".into()));
        assert!(matches!(p.parse("ABCDEFG"), Err(ValueError::TooLong { max: 6, .. })));
    }

    #[test]
    fn values_show_scaled_with_their_unit_and_enumerations_and_bits_decoded() {
        let f = point("type='u32'\nscale=0.01\nunit='Hz'");
        assert_eq!(f.show(&Value::Int(5000)), "50.00 Hz");
        let o = point("scale=0.1\noffset=-40\nunit='°C'");
        assert_eq!(o.show(&Value::Int(650)), "25.0 °C");
        let e = point("values={ '0' = 'initial', '2' = 'stop', '3' = 'run' }");
        assert_eq!(e.show(&Value::Int(3)), "run");
        assert_eq!(e.show(&Value::Int(5)), "5 (not in the profile's list)");
        let b = point("bits={ '0' = 'running', '3' = 'trip' }");
        assert_eq!(b.show(&Value::Int(0b1001)), "running, trip");
        assert_eq!(b.show(&Value::Int(0b0100)), "bit 2");
        assert_eq!(b.show(&Value::Int(0)), "none");
        assert_eq!(point("type='i16'").show(&Value::Int(-3)), "-3");
    }

    #[test]
    fn numbers_carry_the_points_resolution_and_no_float_noise() {
        let f = point("type='u32'\nscale=0.01\nunit='Hz'");
        // 3498 × 0.01 computes to 34.980000000000004.
        assert_eq!((f.number(&Value::Int(3498)), f.engineering(&Value::Int(3498))), ("34.98".into(), Some(34.98)));
        assert_eq!(f.number(&Value::Int(5000)), "50.00");
        let o = point("scale=0.1\noffset=-40");
        assert_eq!((o.number(&Value::Int(653)), o.engineering(&Value::Int(653))), ("25.3".into(), Some(25.3)));
        let single = point("type='f32'");
        let stored = Value::Float(f64::from(1.1f32));
        assert_eq!((single.number(&stored), single.engineering(&stored)), ("1.1".into(), Some(1.1)));
        let double = point("type='f64'");
        assert_eq!(double.number(&Value::Float(0.1 + 0.2)), "0.30000000000000004", "an f64 is shown whole");
        assert_eq!(point("type='i16'").engineering(&Value::Int(-3)), Some(-3.0));
        assert_eq!(point("type='string'\nlength=2").number(&Value::Text("AB".into())), "AB");
    }

    #[test]
    fn only_enumerations_and_bit_fields_have_a_meaning() {
        let e = point("values={ '2' = 'stop', '3' = 'run' }");
        assert_eq!(e.meaning(&Value::Int(3)).as_deref(), Some("run"));
        assert_eq!(e.number(&Value::Int(3)), "3");
        let b = point("bits={ '0' = 'running', '3' = 'trip' }");
        assert_eq!(b.meaning(&Value::Int(0b1001)).as_deref(), Some("running, trip"));
        assert_eq!(point("scale=0.1").meaning(&Value::Int(3)), None);
    }

    #[test]
    fn input_with_units_is_converted_by_the_scale() {
        let f = point("type='u32'\nscale=0.01\nunit='Hz'\nmin=0\nmax=40000\naccess='rw'");
        assert_eq!(f.parse("45Hz").unwrap(), Value::Int(4500));
        assert_eq!(f.parse("45 hz").unwrap(), Value::Int(4500));
        assert_eq!(f.parse("60.00").unwrap(), Value::Int(6000));
        assert_eq!(f.parse("0x10").unwrap(), Value::Int(16), "hex is the raw value");
        assert_eq!(f.parse("45s").unwrap_err().to_string(), "p: \"45s\" is not in Hz, the unit of p");
        assert_eq!(f.parse("45.005").unwrap_err().to_string(), "p: 45.005 is not a multiple of its step 0.01 Hz");
        assert_eq!(f.prepare_write("500Hz").unwrap_err().to_string(), "p: 500Hz is out of range: 0.00 Hz to 400.00 Hz");
        assert_eq!(
            f.prepare_write("0x9C41").unwrap_err().to_string(),
            "p: 0x9C41 is out of range: 0.00 Hz to 400.00 Hz"
        );
        let e = point("values={ '3' = 'modbus', '1' = 'terminal' }\naccess='rw'");
        assert_eq!(e.parse("Modbus").unwrap(), Value::Int(3));
        assert_eq!(e.parse("fast").unwrap_err().to_string(), "p: \"fast\" is not a number nor one of terminal, modbus");
        let ro = point("");
        assert_eq!(ro.prepare_write("1").unwrap_err().to_string(), "p is read-only");
    }
}
