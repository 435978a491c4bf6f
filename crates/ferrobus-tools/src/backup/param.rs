//! A profile's point as backup, diff and restore see it: its registers (or bit) to a raw value
//! and back through the profile's codec, and that raw value as a backup file writes it.
//!
//! In the file a raw value is a TOML value: an integer for the integer types (a decimal
//! string for one TOML cannot hold, a `u64` past `i64::MAX`), a float for `f32`/`f64`, a string
//! for `string`, `true`/`false` for a coil. Two raw values are compared through the registers
//! they encode to, so `1.0` and `1` for an `f32` agree.

use ferrobus_profile::{Point, Value, ValueError, ValueType};

/// Why registers or a file's value do not make a raw value of a point.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ParamError {
    /// The profile's codec refuses it (the wrong number of registers, a value that does not fit).
    #[error(transparent)]
    Value(#[from] ValueError),
    /// A bit read as more or fewer than one item.
    #[error("{code}: {items} items for one bit")]
    Bit {
        /// The point.
        code: String,
        /// The items read.
        items: usize,
    },
    /// A value for a coil that is neither true nor false (nor 1 nor 0).
    #[error("{code}: {value} is not a bit value (true or false)")]
    NotABit {
        /// The point.
        code: String,
        /// The value given.
        value: String,
    },
    /// A decimal string for an integer point that is not an integer.
    #[error("\"{digits}\" is not an integer ({code} is a {ty})")]
    NotAnInteger {
        /// The point.
        code: String,
        /// The string given.
        digits: String,
        /// The point's type.
        ty: &'static str,
    },
    /// A file's value of another kind than the point's type.
    #[error("{value} is not a {ty} value")]
    WrongKind {
        /// The value, as the file writes it.
        value: String,
        /// The point's type.
        ty: &'static str,
    },
}

/// The raw value of `words` read from the device (a bit as one word, 0 or 1).
pub fn decode(point: &Point, words: &[u16]) -> Result<Value, ParamError> {
    if point.value_type == ValueType::Bit {
        return match words {
            [bit] => Ok(Value::Bool(*bit != 0)),
            _ => Err(ParamError::Bit { code: point.code.clone(), items: words.len() }),
        };
    }
    Ok(point.decode(words)?)
}

/// The registers (a bit as one word, 0 or 1) that carry `raw`.
pub fn encode(point: &Point, raw: &Value) -> Result<Vec<u16>, ParamError> {
    if point.value_type == ValueType::Bit {
        return match raw {
            Value::Bool(b) => Ok(vec![u16::from(*b)]),
            Value::Int(n @ (0 | 1)) => Ok(vec![u16::from(*n == 1)]),
            other => Err(ParamError::NotABit { code: point.code.clone(), value: other.to_string() }),
        };
    }
    Ok(point.encode(raw)?)
}

/// A raw value as the backup file writes it.
pub fn to_toml(raw: &Value) -> toml::Value {
    match raw {
        Value::Bool(b) => toml::Value::Boolean(*b),
        Value::Int(n) => i64::try_from(*n).map_or_else(|_| toml::Value::String(n.to_string()), toml::Value::Integer),
        Value::Float(x) => toml::Value::Float(*x),
        Value::Text(s) => toml::Value::String(s.clone()),
    }
}

/// The raw value a backup file gives for `point`, checked against its type.
pub fn from_toml(point: &Point, raw: &toml::Value) -> Result<Value, ParamError> {
    let value = match (point.value_type, raw) {
        (ValueType::String, toml::Value::String(s)) => Value::Text(s.clone()),
        (_, toml::Value::String(digits)) if point.value_type.is_integer() => {
            Value::Int(digits.trim().parse().map_err(|_| ParamError::NotAnInteger {
                code: point.code.clone(),
                digits: digits.clone(),
                ty: point.value_type.name(),
            })?)
        }
        (_, toml::Value::Integer(n)) => Value::Int(i128::from(*n)),
        (_, toml::Value::Float(x)) => Value::Float(*x),
        (_, toml::Value::Boolean(b)) => Value::Bool(*b),
        (ty, other) => return Err(ParamError::WrongKind { value: shown_toml(other), ty: ty.name() }),
    };
    encode(point, &value)?;
    Ok(value)
}

/// The point's label for a comment or a table: its label, else its description.
pub fn label(point: &Point) -> &str {
    if point.label.is_empty() { &point.description } else { &point.label }
}

/// A TOML value as it is written.
pub fn shown_toml(value: &toml::Value) -> String {
    match value {
        toml::Value::String(s) => format!("\"{s}\""),
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ferrobus_profile::Profile;

    const PROFILE: &str = r#"
[device]
name = "t"
vendor = "t"
product_code = "t"
revision = "1"

[[registers]]
number = 0
name = "big"
type = "u64"

[[registers]]
number = 4
name = "f"
type = "f32"
order = "CDAB"

[[registers]]
number = 6
name = "s"
type = "string"
length = 2

[[coils]]
number = 0
name = "c"
access = "rw"
"#;

    fn points() -> Profile {
        Profile::parse(PROFILE, "t.toml").unwrap()
    }

    #[test]
    fn raw_values_go_to_the_file_and_back_through_their_registers() {
        let profile = points();
        for (code, words) in [("big", vec![0xFFFF; 4]), ("f", vec![0x0000, 0xC020]), ("s", vec![0x5258, 0x3200])] {
            let point = profile.point(code).unwrap();
            let raw = decode(point, &words).unwrap();
            let toml = to_toml(&raw);
            let back = from_toml(point, &toml).unwrap();
            assert_eq!(encode(point, &back).unwrap(), words, "{code}: {toml}");
        }
        let big = profile.point("big").unwrap();
        assert_eq!(to_toml(&decode(big, &[0xFFFF; 4]).unwrap()), toml::Value::String(u64::MAX.to_string()));
        assert_eq!(to_toml(&decode(profile.point("f").unwrap(), &[0, 0xC020]).unwrap()), toml::Value::Float(-2.5));
        let coil = profile.point("c").unwrap();
        assert_eq!(decode(coil, &[1]).unwrap(), Value::Bool(true));
        assert_eq!(encode(coil, &from_toml(coil, &toml::Value::Boolean(false)).unwrap()).unwrap(), [0]);
    }

    #[test]
    fn a_file_value_of_the_wrong_kind_is_refused_with_the_type() {
        let profile = points();
        let s = profile.point("s").unwrap();
        let long = from_toml(s, &toml::Value::String("three".into())).unwrap_err();
        assert!(matches!(long, ParamError::Value(_)) && long.to_string().contains("does not fit"), "too long: {long}");
        let big = profile.point("big").unwrap();
        assert_eq!(
            from_toml(big, &toml::Value::String("x".into())).unwrap_err().to_string(),
            "\"x\" is not an integer (big is a u64)"
        );
        assert!(from_toml(big, &toml::Value::Integer(-1)).unwrap_err().to_string().contains("does not fit a u64"));
        let coil = profile.point("c").unwrap();
        let two = from_toml(coil, &toml::Value::Integer(2)).unwrap_err();
        assert!(matches!(two, ParamError::NotABit { .. }), "{two}");
    }
}
