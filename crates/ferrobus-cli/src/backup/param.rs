//! A profile's point as backup, diff and restore see it: its registers (or bit) to a raw value
//! and back through the profile's codec, and that raw value as a backup file writes it.
//!
//! In the file a raw value is a TOML value: an integer for the integer types (a decimal
//! string for one TOML cannot hold, a `u64` past `i64::MAX`), a float for `f32`/`f64`, a string
//! for `string`, `true`/`false` for a coil. Two raw values are compared through the registers
//! they encode to, so `1.0` and `1` for an `f32` agree.

use ferrobus_profile::{Point, Value, ValueType};

/// The raw value of `words` read from the device (a bit as one word, 0 or 1).
pub(crate) fn decode(point: &Point, words: &[u16]) -> Result<Value, String> {
    if point.value_type == ValueType::Bit {
        return match words {
            [bit] => Ok(Value::Bool(*bit != 0)),
            _ => Err(format!("{}: {} items for one bit", point.code, words.len())),
        };
    }
    point.decode(words).map_err(|e| e.to_string())
}

/// The registers (a bit as one word, 0 or 1) that carry `raw`.
pub(crate) fn encode(point: &Point, raw: &Value) -> Result<Vec<u16>, String> {
    if point.value_type == ValueType::Bit {
        return match raw {
            Value::Bool(b) => Ok(vec![u16::from(*b)]),
            Value::Int(n @ (0 | 1)) => Ok(vec![u16::from(*n == 1)]),
            other => Err(format!("{}: {other} is not a bit value (true or false)", point.code)),
        };
    }
    point.encode(raw).map_err(|e| e.to_string())
}

/// A raw value as the backup file writes it.
pub(crate) fn to_toml(raw: &Value) -> toml::Value {
    match raw {
        Value::Bool(b) => toml::Value::Boolean(*b),
        Value::Int(n) => i64::try_from(*n).map_or_else(|_| toml::Value::String(n.to_string()), toml::Value::Integer),
        Value::Float(x) => toml::Value::Float(*x),
        Value::Text(s) => toml::Value::String(s.clone()),
    }
}

/// The raw value a backup file gives for `point`, checked against its type.
pub(crate) fn from_toml(point: &Point, raw: &toml::Value) -> Result<Value, String> {
    let value = match (point.value_type, raw) {
        (ValueType::String, toml::Value::String(s)) => Value::Text(s.clone()),
        (_, toml::Value::String(digits)) if point.value_type.is_integer() => {
            Value::Int(digits.trim().parse().map_err(|_| {
                format!("\"{digits}\" is not an integer ({} is a {})", point.code, point.value_type.name())
            })?)
        }
        (_, toml::Value::Integer(n)) => Value::Int(i128::from(*n)),
        (_, toml::Value::Float(x)) => Value::Float(*x),
        (_, toml::Value::Boolean(b)) => Value::Bool(*b),
        (ty, other) => return Err(format!("{} is not a {} value", shown_toml(other), ty.name())),
    };
    encode(point, &value)?;
    Ok(value)
}

/// The point's label for a comment or a table: its label, else its description.
pub(crate) fn label(point: &Point) -> &str {
    if point.label.is_empty() { &point.description } else { &point.label }
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
        assert!(from_toml(s, &toml::Value::String("three".into())).unwrap_err().contains("does not fit"), "too long");
        let big = profile.point("big").unwrap();
        assert_eq!(
            from_toml(big, &toml::Value::String("x".into())).unwrap_err(),
            "\"x\" is not an integer (big is a u64)"
        );
        assert!(from_toml(big, &toml::Value::Integer(-1)).unwrap_err().contains("does not fit a u64"));
        let coil = profile.point("c").unwrap();
        assert!(from_toml(coil, &toml::Value::Integer(2)).unwrap_err().contains("is not a bit value"));
    }
}
