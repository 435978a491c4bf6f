//! A profile point's values to and from Sparkplug metrics: the datatype a point is born with,
//! the metric value a raw sample publishes, and the raw value a DCMD's metric asks to write.
//!
//! A scaled point (scale ≠ 1 or offset ≠ 0) is published as its engineering value, a Double;
//! a command's Double (or Float, or integer) is scaled back and rounded to the raw type. An
//! unscaled point keeps its type: Int8/16/32 and UInt8/16/32 travel in `int_value`, Int64,
//! UInt64 and DateTime in `long_value`. By default ([`UintEncoding::Spec`]) that is the
//! specification's layout with signed values as two's complement of their own width (Int16 −5
//! is 65531, the only form pysparkplug reads); [`UintEncoding::LongValue`] is Eclipse Tahu's
//! and Ignition's convention instead: UInt32 in `long_value`, Int8/16 sign-extended to 32 bits
//! (Int16 −5 is 4294967291), which is what Tahu's codecs write and read;
//! on input both fields are accepted for every integer type.

use ferrobus_profile::{Point, Value, ValueType};

use super::payload::{DataType, MetricValue, PropertySet, PropertyValue, PropertyValueKind};

/// The property key of a metric's engineering unit (Eclipse Tahu's and Ignition's `engUnit`).
pub const ENG_UNIT: &str = "engUnit";

/// How the integer types are laid out in a metric: the specification's way, or Eclipse Tahu's
/// and Ignition's (`uint_in_long_value` in plant.toml).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum UintEncoding {
    /// As the specification says: UInt8/16/32 in `int_value`, UInt64 in `long_value`; Int8/16
    /// as two's complement of their own width (pysparkplug reads only that).
    #[default]
    Spec,
    /// As Eclipse Tahu and Ignition write and read them: UInt32 in `long_value` (UInt8/16 stay
    /// in `int_value`, where Tahu reads them), Int8/16 sign-extended to 32 bits.
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
/// value of the point's type (a text for a number, an integer out of its range), or is the
/// device's value for "not implemented" ([`Point::implemented`]): the metric is then sent with
/// `is_null` and no value, as Sparkplug B says a null value is sent.
pub fn metric_value(point: &Point, raw: &Value, encoding: UintEncoding) -> Option<MetricValue> {
    if !point.implemented(raw) {
        // The device's "not implemented" value (SunSpec's 0xFFFF, ...): no value, a null metric.
        return None;
    }
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

/// An integer of that datatype in its field, as `encoding` lays it out: a signed Int8/16 as
/// two's complement of its own width (Int16 −5 is `int_value` 65531: pysparkplug reads only
/// that, a 32-bit sign extension fails there) or, in Tahu's convention, sign-extended to 32 bits
/// (4294967291: Tahu reads only that, our own width shows there as a large positive number);
/// UInt32 in `int_value` or, in Tahu's convention, in `long_value`.
fn integer_value(datatype: DataType, n: i128, encoding: UintEncoding) -> Option<MetricValue> {
    let tahu = encoding == UintEncoding::LongValue;
    let small_signed = |n: i32, own_width: u32| if tahu { n.cast_unsigned() } else { own_width };
    Some(match datatype {
        DataType::Int8 => {
            let n = i8::try_from(n).ok()?;
            MetricValue::Int(small_signed(i32::from(n), u32::from(n.cast_unsigned())))
        }
        DataType::Int16 => {
            let n = i16::try_from(n).ok()?;
            MetricValue::Int(small_signed(i32::from(n), u32::from(n.cast_unsigned())))
        }
        DataType::Int32 => MetricValue::Int(i32::try_from(n).ok()?.cast_unsigned()),
        DataType::Int64 | DataType::DateTime => MetricValue::Long(i64::try_from(n).ok()?.cast_unsigned()),
        DataType::UInt8 | DataType::UInt16 | DataType::UInt32 => {
            let v = u32::try_from(n).ok().filter(|v| *v <= unsigned_max(datatype))?;
            if tahu && datatype == DataType::UInt32 { MetricValue::Long(u64::from(v)) } else { MetricValue::Int(v) }
        }
        DataType::UInt64 => MetricValue::Long(u64::try_from(n).ok()?),
        _ => return None,
    })
}

/// The largest value of an unsigned datatype that travels in `int_value`.
fn unsigned_max(datatype: DataType) -> u32 {
    match datatype {
        DataType::UInt8 => u32::from(u8::MAX),
        DataType::UInt16 => u32::from(u16::MAX),
        _ => u32::MAX,
    }
}

/// The raw value a DCMD metric's value asks to write to the point: `int_value` or
/// `long_value` for an integer point (signed values as two's complement of their own width,
/// of 32 or of 64 bits); a Double, Float or integer engineering value for a scaled point,
/// scaled back and rounded; a Boolean for a bit; a String (ASCII, as many characters as its
/// registers hold) for a string. The caller then runs [`Point::check_write`]: access and the
/// profile's range stay the profile's.
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
        (ValueType::String, MetricValue::String(text)) => {
            let max = usize::from(point.width) * 2;
            if text.len() > max || !text.is_ascii() {
                return Err(refuse(&format!("a String of at most {max} ASCII characters")));
            }
            Ok(Value::Text(text.clone()))
        }
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

#[cfg(test)]
mod tests {
    use ferrobus_profile::Table;
    use proptest::prelude::*;

    use super::*;

    const TYPES: [ValueType; 10] = [
        ValueType::U16,
        ValueType::I16,
        ValueType::U32,
        ValueType::I32,
        ValueType::U64,
        ValueType::I64,
        ValueType::F32,
        ValueType::F64,
        ValueType::String,
        ValueType::Bit,
    ];

    fn point(value_type: ValueType, scale: f64, offset: f64) -> Point {
        let table = if value_type == ValueType::Bit { Table::Coils } else { Table::Holding };
        Point {
            code: "P1".into(),
            width: if value_type == ValueType::String { 4 } else { value_type.registers() },
            unit: Some("Hz".into()),
            scale,
            offset,
            ..Point::raw(table, 0, value_type)
        }
    }

    fn plain(value_type: ValueType) -> Point {
        point(value_type, 1.0, 0.0)
    }

    fn raw_err(point: &Point, value: &MetricValue) -> String {
        to_raw(point, value).unwrap_err().to_string()
    }

    #[test]
    fn a_point_is_born_with_its_types_datatype() {
        use DataType as D;
        let born: Vec<DataType> = TYPES.into_iter().map(|ty| datatype_of(&plain(ty))).collect();
        let want =
            [D::UInt16, D::Int16, D::UInt32, D::Int32, D::UInt64, D::Int64, D::Float, D::Double, D::String, D::Boolean];
        assert_eq!(born, want);
    }

    #[test]
    fn a_scaled_point_is_born_a_double() {
        assert_eq!(datatype_of(&point(ValueType::U16, 0.01, 0.0)), DataType::Double);
        assert_eq!(datatype_of(&point(ValueType::I16, 1.0, -40.0)), DataType::Double);
        assert_eq!(datatype_of(&point(ValueType::F32, 0.5, 0.0)), DataType::Double);
        assert!(!is_scaled(&point(ValueType::Bit, 2.0, 0.0)), "a bit has no engineering value");
        assert!(!is_scaled(&point(ValueType::String, 2.0, 1.0)));
    }

    #[test]
    fn a_value_the_device_does_not_implement_publishes_no_value() {
        let spec = UintEncoding::Spec;
        let sentinel = Point { not_implemented: Some(Value::Int(0xFFFF)), ..plain(ValueType::U16) };
        assert_eq!(metric_value(&sentinel, &Value::Int(0xFFFF), spec), None);
        assert_eq!(metric_value(&sentinel, &Value::Int(7), spec), Some(MetricValue::Int(7)));
        let scaled = Point { not_implemented: Some(Value::Int(-32768)), ..point(ValueType::I16, 0.1, 0.0) };
        assert_eq!(metric_value(&scaled, &Value::Int(-32768), spec), None);
        let nan = Point { not_implemented: Some(Value::Float(f64::NAN)), ..plain(ValueType::F32) };
        assert_eq!(metric_value(&nan, &Value::Float(f64::NAN), spec), None);
        let never = Point { implemented: false, ..plain(ValueType::U16) };
        assert_eq!(metric_value(&never, &Value::Int(7), spec), None);
    }

    #[test]
    fn the_unit_is_the_engunit_property() {
        let properties = properties_of(&plain(ValueType::U16)).expect("a unit");
        assert_eq!(properties.keys, ["engUnit"]);
        let value = properties.values.first().expect("one value");
        assert_eq!(value.r#type, Some(DataType::String.number()));
        assert_eq!(value.value, Some(PropertyValueKind::String("Hz".into())));
        let mut bare = plain(ValueType::U16);
        bare.unit = None;
        assert_eq!(properties_of(&bare), None);
        bare.unit = Some(String::new());
        assert_eq!(properties_of(&bare), None);
    }

    #[test]
    fn values_go_in_the_field_of_their_datatype() {
        let spec = UintEncoding::Spec;
        let value = |ty, raw: Value| metric_value(&plain(ty), &raw, spec);
        assert_eq!(value(ValueType::U16, Value::Int(5000)), Some(MetricValue::Int(5000)));
        assert_eq!(value(ValueType::U32, Value::Int(19200)), Some(MetricValue::Int(19200)));
        assert_eq!(value(ValueType::U64, Value::Int(1 << 40)), Some(MetricValue::Long(1 << 40)));
        assert_eq!(value(ValueType::I16, Value::Int(-5)), Some(MetricValue::Int(65531)));
        assert_eq!(value(ValueType::I32, Value::Int(-5)), Some(MetricValue::Int(u32::MAX - 4)));
        assert_eq!(value(ValueType::I64, Value::Int(-5)), Some(MetricValue::Long(u64::MAX - 4)));
        assert_eq!(value(ValueType::F32, Value::Float(1.5)), Some(MetricValue::Float(1.5)));
        assert_eq!(value(ValueType::F64, Value::Float(-2.25)), Some(MetricValue::Double(-2.25)));
        assert_eq!(value(ValueType::Bit, Value::Bool(true)), Some(MetricValue::Boolean(true)));
        assert_eq!(value(ValueType::String, Value::Text("3G3RX".into())), Some(MetricValue::String("3G3RX".into())));
    }

    #[test]
    fn tahus_convention_puts_uint32_in_long_value_and_sign_extends_int8_16() {
        let tahu = UintEncoding::LongValue;
        let value = |ty, n| metric_value(&plain(ty), &Value::Int(n), tahu);
        assert_eq!(value(ValueType::U16, 5000), Some(MetricValue::Int(5000)), "UInt16 stays in int_value");
        assert_eq!(value(ValueType::U32, 19200), Some(MetricValue::Long(19200)));
        assert_eq!(value(ValueType::I16, -5), Some(MetricValue::Int(u32::MAX - 4)), "32-bit sign extension");
        assert_eq!(value(ValueType::I16, 300), Some(MetricValue::Int(300)));
        assert_eq!(value(ValueType::I32, 7), Some(MetricValue::Int(7)));
    }

    #[test]
    fn a_scaled_point_publishes_its_engineering_value() {
        let hz = point(ValueType::U16, 0.01, 0.0);
        assert_eq!(metric_value(&hz, &Value::Int(5000), UintEncoding::Spec), Some(MetricValue::Double(50.0)));
        let celsius = point(ValueType::I16, 0.1, -40.0);
        assert_eq!(metric_value(&celsius, &Value::Int(-5), UintEncoding::Spec), Some(MetricValue::Double(-40.5)));
    }

    #[test]
    fn a_value_not_of_the_points_type_publishes_nothing() {
        let spec = UintEncoding::Spec;
        assert_eq!(metric_value(&plain(ValueType::U16), &Value::Int(70000), spec), None);
        assert_eq!(metric_value(&plain(ValueType::I16), &Value::Int(40000), spec), None);
        assert_eq!(metric_value(&plain(ValueType::U32), &Value::Int(-1), spec), None);
        assert_eq!(metric_value(&plain(ValueType::U16), &Value::Text("x".into()), spec), None);
        assert_eq!(metric_value(&plain(ValueType::String), &Value::Int(1), spec), None);
        assert_eq!(metric_value(&point(ValueType::U16, 0.1, 0.0), &Value::Text("x".into()), spec), None);
    }

    #[test]
    fn a_command_may_use_either_integer_field() {
        let u16 = plain(ValueType::U16);
        assert_eq!(to_raw(&u16, &MetricValue::Int(5000)), Ok(Value::Int(5000)));
        assert_eq!(to_raw(&u16, &MetricValue::Long(5000)), Ok(Value::Int(5000)));
        let u32 = plain(ValueType::U32);
        assert_eq!(to_raw(&u32, &MetricValue::Long(u64::from(u32::MAX))), Ok(Value::Int(i128::from(u32::MAX))));
        let u64 = plain(ValueType::U64);
        assert_eq!(to_raw(&u64, &MetricValue::Long(u64::MAX)), Ok(Value::Int(i128::from(u64::MAX))));
        assert_eq!(to_raw(&u64, &MetricValue::Int(7)), Ok(Value::Int(7)));
    }

    #[test]
    fn a_negative_command_is_read_at_every_width_it_may_come_in() {
        let i16 = plain(ValueType::I16);
        for wire in [MetricValue::Int(65531), MetricValue::Int(u32::MAX - 4), MetricValue::Long(u64::MAX - 4)] {
            assert_eq!(to_raw(&i16, &wire), Ok(Value::Int(-5)), "{wire:?}");
        }
        assert_eq!(to_raw(&i16, &MetricValue::Long(65531)), Ok(Value::Int(-5)));
        let i32 = plain(ValueType::I32);
        assert_eq!(to_raw(&i32, &MetricValue::Int(u32::MAX)), Ok(Value::Int(-1)));
        assert_eq!(to_raw(&i32, &MetricValue::Long(u64::MAX)), Ok(Value::Int(-1)));
        let i64 = plain(ValueType::I64);
        assert_eq!(to_raw(&i64, &MetricValue::Long(u64::MAX)), Ok(Value::Int(-1)));
        let as_is = Value::Int(i128::from(u32::MAX));
        assert_eq!(to_raw(&i64, &MetricValue::Int(u32::MAX)), Ok(as_is), "in range as it is: not reinterpreted");
        assert_eq!(to_raw(&i16, &MetricValue::Int(32767)), Ok(Value::Int(32767)));
    }

    #[test]
    fn an_integer_out_of_the_points_range_is_refused() {
        assert_eq!(
            raw_err(&plain(ValueType::U16), &MetricValue::Long(70000)),
            "P1: long_value 70000 given; the point (UInt16) takes int_value or long_value 0 to 65535"
        );
        assert_eq!(
            raw_err(&plain(ValueType::I16), &MetricValue::Int(100_000)),
            "P1: int_value 100000 given; the point (Int16) takes int_value or long_value -32768 to 32767"
        );
        assert!(to_raw(&plain(ValueType::U32), &MetricValue::Long(1 << 32)).is_err());
    }

    #[test]
    fn a_command_of_the_wrong_kind_is_refused() {
        assert_eq!(
            raw_err(&plain(ValueType::U16), &MetricValue::Double(1.0)),
            "P1: double_value 1 given; the point (UInt16) takes int_value or long_value 0 to 65535"
        );
        assert_eq!(
            raw_err(&plain(ValueType::Bit), &MetricValue::Int(1)),
            "P1: int_value 1 given; the point (Boolean) takes a Boolean"
        );
        assert_eq!(
            raw_err(&plain(ValueType::String), &MetricValue::Boolean(true)),
            "P1: boolean_value true given; the point (String) takes a String"
        );
        assert_eq!(
            raw_err(&plain(ValueType::F32), &MetricValue::String("1.5".into())),
            "P1: string_value \"1.5\" given; the point (Float) takes a Float or Double"
        );
        let data_set = MetricValue::DataSet(super::super::payload::DataSet::default());
        assert!(raw_err(&plain(ValueType::U16), &data_set).contains("a data set given"));
    }

    #[test]
    fn bits_strings_and_floats_are_written_as_given() {
        assert_eq!(to_raw(&plain(ValueType::Bit), &MetricValue::Boolean(true)), Ok(Value::Bool(true)));
        assert_eq!(to_raw(&plain(ValueType::String), &MetricValue::String("AB".into())), Ok(Value::Text("AB".into())));
        assert_eq!(
            raw_err(&plain(ValueType::String), &MetricValue::String("ABCDEFGHI".into())),
            "P1: string_value \"ABCDEFGHI\" given; the point (String) takes a String of at most 8 ASCII characters"
        );
        assert!(to_raw(&plain(ValueType::String), &MetricValue::String("µ".into())).is_err());
        assert_eq!(to_raw(&plain(ValueType::F32), &MetricValue::Float(1.5)), Ok(Value::Float(1.5)));
        assert_eq!(to_raw(&plain(ValueType::F32), &MetricValue::Double(1.5)), Ok(Value::Float(1.5)));
        assert_eq!(to_raw(&plain(ValueType::F64), &MetricValue::Int(3)), Ok(Value::Float(3.0)));
    }

    #[test]
    fn a_float_command_must_be_finite_and_fit() {
        assert_eq!(
            raw_err(&plain(ValueType::F64), &MetricValue::Double(f64::NAN)),
            "P1: double_value NaN given; the point (Double) takes a finite number of its range"
        );
        assert!(to_raw(&plain(ValueType::F32), &MetricValue::Float(f32::INFINITY)).is_err());
        assert!(to_raw(&plain(ValueType::F32), &MetricValue::Double(1e39)).is_err());
        assert_eq!(to_raw(&plain(ValueType::F64), &MetricValue::Double(1e39)), Ok(Value::Float(1e39)));
    }

    #[test]
    fn a_scaled_command_is_scaled_back_and_rounded() {
        let hz = point(ValueType::U16, 0.01, 0.0);
        assert_eq!(to_raw(&hz, &MetricValue::Double(50.0)), Ok(Value::Int(5000)));
        assert_eq!(to_raw(&hz, &MetricValue::Double(50.004)), Ok(Value::Int(5000)));
        assert_eq!(to_raw(&hz, &MetricValue::Double(50.006)), Ok(Value::Int(5001)));
        assert_eq!(to_raw(&hz, &MetricValue::Float(12.5)), Ok(Value::Int(1250)));
        assert_eq!(to_raw(&hz, &MetricValue::Int(60)), Ok(Value::Int(6000)));
        let celsius = point(ValueType::I16, 0.1, -40.0);
        assert_eq!(to_raw(&celsius, &MetricValue::Double(-40.5)), Ok(Value::Int(-5)));
        let gain = point(ValueType::F32, 0.5, 0.0);
        assert_eq!(to_raw(&gain, &MetricValue::Double(3.0)), Ok(Value::Float(6.0)));
    }

    #[test]
    fn a_scaled_command_out_of_the_raw_range_or_not_finite_is_refused() {
        let hz = point(ValueType::U16, 0.01, 0.0);
        assert_eq!(
            raw_err(&hz, &MetricValue::Double(1000.0)),
            "P1: double_value 1000 given; its raw value 100000 is out of u16's range 0 to 65535"
        );
        assert_eq!(
            raw_err(&hz, &MetricValue::Double(-0.5)),
            "P1: double_value -0.5 given; its raw value -50 is out of u16's range 0 to 65535"
        );
        assert_eq!(
            raw_err(&hz, &MetricValue::Double(f64::INFINITY)),
            "P1: double_value inf given; the point takes a finite number"
        );
        assert!(to_raw(&hz, &MetricValue::Double(f64::NAN)).is_err());
        assert_eq!(
            raw_err(&hz, &MetricValue::Boolean(true)),
            "P1: boolean_value true given; the point (scaled, a Double) takes a number"
        );
        let tiny = point(ValueType::F32, 1e-30, 0.0);
        assert!(raw_err(&tiny, &MetricValue::Double(1e10)).contains("out of f32's range"));
    }

    /// A raw value of the type, as the profile decodes one from registers.
    fn raw_of(ty: ValueType) -> BoxedStrategy<Value> {
        match ty {
            ValueType::Bit => any::<bool>().prop_map(Value::Bool).boxed(),
            ValueType::String => "[ -~]{0,8}".prop_map(Value::Text).boxed(),
            ValueType::F32 => {
                any::<f32>().prop_filter("finite", |x| x.is_finite()).prop_map(|x| Value::Float(f64::from(x))).boxed()
            }
            ValueType::F64 => any::<f64>().prop_filter("finite", |x| x.is_finite()).prop_map(Value::Float).boxed(),
            ty => {
                let (lo, hi) = ty.integer_range();
                (lo..=hi).prop_map(Value::Int).boxed()
            }
        }
    }

    fn type_and_raw() -> impl Strategy<Value = (ValueType, Value)> {
        proptest::sample::select(TYPES.to_vec()).prop_flat_map(|ty| (Just(ty), raw_of(ty)))
    }

    /// An integer type and a raw value of it within 2^40: a Double holds the engineering value
    /// of any of them closely enough to round back (beyond 2^53 no Double does).
    fn scaled_integer() -> impl Strategy<Value = (ValueType, i128)> {
        let types =
            vec![ValueType::U16, ValueType::I16, ValueType::U32, ValueType::I32, ValueType::U64, ValueType::I64];
        proptest::sample::select(types).prop_flat_map(|ty| {
            let (lo, hi) = ty.integer_range();
            (Just(ty), lo.max(-(1 << 40))..=hi.min(1 << 40))
        })
    }

    fn encoding() -> impl Strategy<Value = UintEncoding> {
        prop_oneof![Just(UintEncoding::Spec), Just(UintEncoding::LongValue)]
    }

    proptest! {
        #[test]
        fn a_published_value_written_back_is_the_raw_value((ty, raw) in type_and_raw(), encoding in encoding()) {
            let point = plain(ty);
            let value = metric_value(&point, &raw, encoding).expect("a raw value of the type publishes");
            prop_assert_eq!(to_raw(&point, &value), Ok(raw));
        }

        #[test]
        fn a_scaled_value_written_back_is_the_raw_value(
            (ty, n) in scaled_integer(),
            scale in proptest::sample::select(vec![0.1, 0.01, 0.5, 2.0, 10.0, 0.001]),
            offset in proptest::sample::select(vec![0.0, -40.0, 273.15]),
        ) {
            let point = point(ty, scale, offset);
            let value = metric_value(&point, &Value::Int(n), UintEncoding::Spec).expect("an engineering value");
            prop_assert_eq!(to_raw(&point, &value), Ok(Value::Int(n)));
        }

        #[test]
        fn a_scaled_float_written_back_is_close_to_the_raw_value(x in -1e6f64..1e6, scale in 0.01f64..100.0) {
            let point = point(ValueType::F64, scale, 1.0);
            let value = metric_value(&point, &Value::Float(x), UintEncoding::Spec).expect("an engineering value");
            let Ok(Value::Float(back)) = to_raw(&point, &value) else { panic!("a float") };
            prop_assert!((back - x).abs() <= 1e-9 * x.abs().max(1.0), "{} became {}", x, back);
        }
    }
}
