//! A profile point's values to and from Sparkplug metrics: the datatype a point is born with,
//! the metric value a raw sample publishes, and the raw value a DCMD's metric asks to write.
//!
//! A scaled point (scale ≠ 1 or offset ≠ 0) is published as its engineering value, a Double;
//! a command's Double (or Float, or integer) is scaled back and rounded to the raw type. An
//! unscaled point keeps its type: Int8/16/32 and UInt8/16/32 travel in `int_value`, Int64,
//! UInt64 and DateTime in `long_value`, signed values as two's complement. UInt8/16/32 go in
//! `int_value` as the specification says, or in `long_value` with [`UintEncoding::LongValue`]
//! (Eclipse Tahu and Ignition read them there); on input both fields are accepted for every
//! integer type.

use ferrobus_profile::{Point, Value, ValueType};

use super::payload::{DataType, MetricValue, PropertySet, PropertyValue, PropertyValueKind};

/// The property key of a metric's engineering unit (Eclipse Tahu's and Ignition's `engUnit`).
pub const ENG_UNIT: &str = "engUnit";

/// Where UInt8, UInt16 and UInt32 values are written.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum UintEncoding {
    /// As the specification says: UInt8/16/32 in `int_value`, UInt64 in `long_value`.
    #[default]
    Spec,
    /// UInt8/16/32 (and UInt64) in `long_value`, as Eclipse Tahu and Ignition read them.
    LongValue,
}

/// A metric value that cannot be written to a point.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct ConvertError(String);

impl ConvertError {
    /// What was given and what the point takes.
    pub fn message(&self) -> &str {
        &self.0
    }
}

/// Whether the point publishes an engineering value (raw × scale + offset) rather than its raw one.
pub fn is_scaled(point: &Point) -> bool {
    #[allow(clippy::float_cmp)]
    let scaled = point.scale != 1.0 || point.offset != 0.0;
    scaled && (point.value_type.is_integer() || point.value_type.is_float())
}

/// The datatype the point's metric is born with: Double for a scaled point (its engineering
/// value), else its value type's.
pub fn datatype_of(point: &Point) -> DataType {
    if is_scaled(point) {
        return DataType::Double;
    }
    match point.value_type {
        ValueType::U16 => DataType::UInt16,
        ValueType::I16 => DataType::Int16,
        ValueType::U32 => DataType::UInt32,
        ValueType::I32 => DataType::Int32,
        ValueType::U64 => DataType::UInt64,
        ValueType::I64 => DataType::Int64,
        ValueType::F32 => DataType::Float,
        ValueType::F64 => DataType::Double,
        ValueType::Bit => DataType::Boolean,
        ValueType::String => DataType::String,
    }
}

/// The properties of the point's metric in a birth: its engineering unit, if it has one.
pub fn properties_of(point: &Point) -> Option<PropertySet> {
    let unit = point.unit.as_deref().filter(|unit| !unit.is_empty())?;
    Some(PropertySet {
        keys: vec![ENG_UNIT.to_owned()],
        values: vec![PropertyValue {
            r#type: Some(DataType::String.number()),
            is_null: None,
            value: Some(PropertyValueKind::String(unit.to_owned())),
        }],
    })
}

/// The value the point's metric publishes for raw value `raw`: the engineering value for a
/// scaled point, else the raw value in the field its datatype takes. None when `raw` is not a
/// value of the point's type (a text for a number, an integer out of its range).
pub fn metric_value(point: &Point, raw: &Value, encoding: UintEncoding) -> Option<MetricValue> {
    let datatype = datatype_of(point);
    match (datatype, raw) {
        (DataType::Double, raw) => point.engineering(raw).map(MetricValue::Double),
        #[allow(clippy::cast_possible_truncation)]
        (DataType::Float, raw) => raw.as_f64().map(|x| MetricValue::Float(x as f32)),
        (DataType::Boolean, raw) => raw.as_int().map(|n| MetricValue::Boolean(n != 0)),
        (DataType::String, Value::Text(text)) => Some(MetricValue::String(text.clone())),
        (datatype, Value::Int(n)) => integer_value(datatype, *n, encoding),
        _ => None,
    }
}

/// An integer of that datatype in its field: two's complement for the signed types.
fn integer_value(datatype: DataType, n: i128, encoding: UintEncoding) -> Option<MetricValue> {
    let in_long = encoding == UintEncoding::LongValue;
    Some(match datatype {
        DataType::Int8 => MetricValue::Int(i32::from(i8::try_from(n).ok()?).cast_unsigned()),
        DataType::Int16 => MetricValue::Int(i32::from(i16::try_from(n).ok()?).cast_unsigned()),
        DataType::Int32 => MetricValue::Int(i32::try_from(n).ok()?.cast_unsigned()),
        DataType::Int64 | DataType::DateTime => MetricValue::Long(i64::try_from(n).ok()?.cast_unsigned()),
        DataType::UInt8 | DataType::UInt16 | DataType::UInt32 => {
            let (_, max) = unsigned_range(datatype);
            let v = u32::try_from(n).ok().filter(|v| u64::from(*v) <= max)?;
            if in_long { MetricValue::Long(u64::from(v)) } else { MetricValue::Int(v) }
        }
        DataType::UInt64 => MetricValue::Long(u64::try_from(n).ok()?),
        _ => return None,
    })
}

fn unsigned_range(datatype: DataType) -> (u64, u64) {
    match datatype {
        DataType::UInt8 => (0, u64::from(u8::MAX)),
        DataType::UInt16 => (0, u64::from(u16::MAX)),
        DataType::UInt32 => (0, u64::from(u32::MAX)),
        _ => (0, u64::MAX),
    }
}

/// The raw value a DCMD metric's value asks to write to the point: `int_value` or
/// `long_value` for an integer point (signed values as two's complement of their own width,
/// of 32 or of 64 bits); a Double, Float or integer engineering value for a scaled point,
/// scaled back and rounded; a Boolean for a bit; a String for a string. The caller then runs
/// [`Point::check_write`]: access and the profile's range stay the profile's.
///
/// # Errors
/// The value is of a kind the point does not take, not finite, or out of its raw type's range;
/// the message says what was given and what the point takes.
pub fn to_raw(point: &Point, value: &MetricValue) -> Result<Value, ConvertError> {
    if is_scaled(point) {
        return scaled_to_raw(point, value);
    }
    let datatype = datatype_of(point);
    let refuse = |takes: &str| {
        ConvertError(format!("{}: {} given; the point ({datatype}) takes {takes}", point.code, describe(value)))
    };
    match (point.value_type, value) {
        (ValueType::Bit, MetricValue::Boolean(b)) => Ok(Value::Bool(*b)),
        (ValueType::Bit, _) => Err(refuse("a Boolean")),
        (ValueType::String, MetricValue::String(text)) => Ok(Value::Text(text.clone())),
        (ValueType::String, _) => Err(refuse("a String")),
        (ValueType::F32 | ValueType::F64, value) => {
            let x = number(value).ok_or_else(|| refuse("a Float or Double"))?;
            let f32_range = point.value_type == ValueType::F32 && x.abs() > f64::from(f32::MAX);
            if !x.is_finite() || f32_range {
                return Err(refuse("a finite number of its range"));
            }
            Ok(Value::Float(x))
        }
        (ty, MetricValue::Int(v)) => integer_raw(ty, u64::from(*v)).ok_or_else(|| refuse(&integer_takes(ty))),
        (ty, MetricValue::Long(v)) => integer_raw(ty, *v).ok_or_else(|| refuse(&integer_takes(ty))),
        (ty, _) => Err(refuse(&integer_takes(ty))),
    }
}

/// What an integer point takes, for a message.
fn integer_takes(ty: ValueType) -> String {
    let (lo, hi) = ty.integer_range();
    format!("int_value or long_value {lo} to {hi}")
}

/// The raw integer of a wire value for an integer point: unsigned as is; signed as two's
/// complement of 64, 32 or the type's own bits, whichever lands in the type's range.
fn integer_raw(ty: ValueType, wire: u64) -> Option<Value> {
    let (lo, hi) = ty.integer_range();
    let in_range = |n: i128| (lo..=hi).contains(&n).then_some(Value::Int(n));
    if lo == 0 {
        return in_range(i128::from(wire));
    }
    let as_64 = i128::from(wire.cast_signed());
    let as_32 = u32::try_from(wire).ok().map(|w| i128::from(w.cast_signed()));
    let as_16 = u16::try_from(wire).ok().map(|w| i128::from(w.cast_signed()));
    [Some(as_64), as_32, as_16].into_iter().flatten().find_map(in_range)
}

/// A scaled point's raw value for an engineering value: (value − offset) / scale, rounded for
/// an integer point.
fn scaled_to_raw(point: &Point, value: &MetricValue) -> Result<Value, ConvertError> {
    let refuse = |why: String| ConvertError(format!("{}: {} given; {why}", point.code, describe(value)));
    let engineering = number(value).ok_or_else(|| refuse("the point (scaled, a Double) takes a number".to_owned()))?;
    if !engineering.is_finite() {
        return Err(refuse("the point takes a finite number".to_owned()));
    }
    let raw = (engineering - point.offset) / point.scale;
    let ty = point.value_type;
    if ty.is_float() {
        let f32_range = ty == ValueType::F32 && raw.abs() > f64::from(f32::MAX);
        return if raw.is_finite() && !f32_range {
            Ok(Value::Float(raw))
        } else {
            Err(refuse(format!("its raw value {raw} is out of {}'s range", ty.name())))
        };
    }
    let rounded = raw.round();
    let (lo, hi) = ty.integer_range();
    #[allow(clippy::cast_precision_loss)]
    let fits = rounded.is_finite() && rounded >= lo as f64 && rounded <= hi as f64;
    if !fits {
        return Err(refuse(format!("its raw value {rounded} is out of {}'s range {lo} to {hi}", ty.name())));
    }
    #[allow(clippy::cast_possible_truncation)]
    Ok(Value::Int((rounded as i128).clamp(lo, hi)))
}

/// A numeric metric value as a number (integers unsigned).
#[allow(clippy::cast_precision_loss)]
fn number(value: &MetricValue) -> Option<f64> {
    match value {
        MetricValue::Int(v) => Some(f64::from(*v)),
        MetricValue::Long(v) => Some(*v as f64),
        MetricValue::Float(x) => Some(f64::from(*x)),
        MetricValue::Double(x) => Some(*x),
        _ => None,
    }
}

/// A metric value as a message shows it: its field and value.
pub fn describe(value: &MetricValue) -> String {
    match value {
        MetricValue::Int(v) => format!("int_value {v}"),
        MetricValue::Long(v) => format!("long_value {v}"),
        MetricValue::Float(x) => format!("float_value {x}"),
        MetricValue::Double(x) => format!("double_value {x}"),
        MetricValue::Boolean(b) => format!("boolean_value {b}"),
        MetricValue::String(s) => format!("string_value {s:?}"),
        MetricValue::Bytes(b) => format!("bytes_value of {} bytes", b.len()),
        MetricValue::DataSet(_) => "a data set".to_owned(),
        MetricValue::Template(_) => "a template".to_owned(),
        MetricValue::Extension(_) => "an extension value".to_owned(),
    }
}
