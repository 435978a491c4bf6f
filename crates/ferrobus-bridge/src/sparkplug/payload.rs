//! The Sparkplug B payload: the protobuf (proto2) messages of the Sparkplug 3.0 specification,
//! written as prost derives from the specification's description of the wire format (field
//! numbers and types are facts of the format), so no protoc and no schema file enter the build.
//!
//! proto2 optional scalars are `Option<T>`; a repeated scalar is encoded unpacked, as proto2
//! does without `[packed = true]`, and decoded packed or not. The format's `extensions` ranges
//! have no prost counterpart: fields in them are unknown fields, which decoding skips. A value
//! extension (`extension_value` of a metric, property, data set value or template parameter)
//! is a message the specification leaves empty; it is kept here as its encoded bytes.

use prost::Message;

/// A Sparkplug B message's payload: NBIRTH, NDATA, DBIRTH, DDATA, NCMD, DCMD, NDEATH, DDEATH.
#[derive(Clone, PartialEq, Message)]
pub struct Payload {
    /// When the message was made, milliseconds since the Unix epoch (UTC).
    #[prost(uint64, optional, tag = "1")]
    pub timestamp: Option<u64>,
    /// The metrics.
    #[prost(message, repeated, tag = "2")]
    pub metrics: Vec<Metric>,
    /// The message's sequence number, 0 to 255 (absent in an NDEATH).
    #[prost(uint64, optional, tag = "3")]
    pub seq: Option<u64>,
    /// A UUID the publisher may set to say how to read `body`.
    #[prost(string, optional, tag = "4")]
    pub uuid: Option<String>,
    /// Opaque bytes the publisher may attach.
    #[prost(bytes = "vec", optional, tag = "5")]
    pub body: Option<Vec<u8>>,
}

/// One metric: a name (or an alias after the birth), a datatype (in births), a value.
#[derive(Clone, PartialEq, Message)]
pub struct Metric {
    /// The metric's name; may be left out once an alias stands for it.
    #[prost(string, optional, tag = "1")]
    pub name: Option<String>,
    /// The alias, unique within the edge node, that DATA and CMD messages may use instead of the name.
    #[prost(uint64, optional, tag = "2")]
    pub alias: Option<u64>,
    /// When the value was sampled, milliseconds since the Unix epoch (UTC).
    #[prost(uint64, optional, tag = "3")]
    pub timestamp: Option<u64>,
    /// The value's [`DataType`], as its number; required in births, left out in DATA and CMD.
    #[prost(uint32, optional, tag = "4")]
    pub datatype: Option<u32>,
    /// A value from the past (store and forward), not the current one.
    #[prost(bool, optional, tag = "5")]
    pub is_historical: Option<bool>,
    /// A value that a host should not store.
    #[prost(bool, optional, tag = "6")]
    pub is_transient: Option<bool>,
    /// The value is null (and `value` absent).
    #[prost(bool, optional, tag = "7")]
    pub is_null: Option<bool>,
    /// About a bytes, file or multi-part value.
    #[prost(message, optional, tag = "8")]
    pub metadata: Option<MetaData>,
    /// Properties of the metric (its engineering unit, ...).
    #[prost(message, optional, tag = "9")]
    pub properties: Option<PropertySet>,
    /// The value, in the field its datatype takes.
    #[prost(oneof = "MetricValue", tags = "10, 11, 12, 13, 14, 15, 16, 17, 18, 19")]
    pub value: Option<MetricValue>,
}

/// A metric's value: the field of the payload it is carried in.
#[derive(Clone, PartialEq, prost::Oneof)]
pub enum MetricValue {
    /// `int_value` (uint32): Int8/16/32 (two's complement), UInt8/16/32 by the specification.
    #[prost(uint32, tag = "10")]
    Int(u32),
    /// `long_value` (uint64): Int64 (two's complement), UInt64, DateTime.
    #[prost(uint64, tag = "11")]
    Long(u64),
    /// `float_value`: Float.
    #[prost(float, tag = "12")]
    Float(f32),
    /// `double_value`: Double.
    #[prost(double, tag = "13")]
    Double(f64),
    /// `boolean_value`: Boolean.
    #[prost(bool, tag = "14")]
    Boolean(bool),
    /// `string_value`: String, Text, UUID.
    #[prost(string, tag = "15")]
    String(String),
    /// `bytes_value`: Bytes, File, arrays.
    #[prost(bytes = "vec", tag = "16")]
    Bytes(Vec<u8>),
    /// `dataset_value`: DataSet.
    #[prost(message, tag = "17")]
    DataSet(DataSet),
    /// `template_value`: Template.
    #[prost(message, tag = "18")]
    Template(Template),
    /// `extension_value`: the encoded fields of a value extension.
    #[prost(bytes = "vec", tag = "19")]
    Extension(Vec<u8>),
}

/// About a metric's bytes, file or multi-part value.
#[derive(Clone, PartialEq, Message)]
pub struct MetaData {
    /// The value is one part of several.
    #[prost(bool, optional, tag = "1")]
    pub is_multi_part: Option<bool>,
    /// Its content type (a MIME type).
    #[prost(string, optional, tag = "2")]
    pub content_type: Option<String>,
    /// Its size in bytes.
    #[prost(uint64, optional, tag = "3")]
    pub size: Option<u64>,
    /// The part's sequence number in a multi-part value.
    #[prost(uint64, optional, tag = "4")]
    pub seq: Option<u64>,
    /// The file's name.
    #[prost(string, optional, tag = "5")]
    pub file_name: Option<String>,
    /// The file's type.
    #[prost(string, optional, tag = "6")]
    pub file_type: Option<String>,
    /// The MD5 sum of the value.
    #[prost(string, optional, tag = "7")]
    pub md5: Option<String>,
    /// Anything else about it.
    #[prost(string, optional, tag = "8")]
    pub description: Option<String>,
}

/// A property's value (typed like a metric's).
#[derive(Clone, PartialEq, Message)]
pub struct PropertyValue {
    /// The value's [`DataType`], as its number.
    #[prost(uint32, optional, tag = "1")]
    pub r#type: Option<u32>,
    /// The value is null.
    #[prost(bool, optional, tag = "2")]
    pub is_null: Option<bool>,
    /// The value.
    #[prost(oneof = "PropertyValueKind", tags = "3, 4, 5, 6, 7, 8, 9, 10, 11")]
    pub value: Option<PropertyValueKind>,
}

/// A property's value: the field it is carried in.
#[derive(Clone, PartialEq, prost::Oneof)]
pub enum PropertyValueKind {
    /// `int_value` (uint32).
    #[prost(uint32, tag = "3")]
    Int(u32),
    /// `long_value` (uint64).
    #[prost(uint64, tag = "4")]
    Long(u64),
    /// `float_value`.
    #[prost(float, tag = "5")]
    Float(f32),
    /// `double_value`.
    #[prost(double, tag = "6")]
    Double(f64),
    /// `boolean_value`.
    #[prost(bool, tag = "7")]
    Boolean(bool),
    /// `string_value`.
    #[prost(string, tag = "8")]
    String(String),
    /// `propertyset_value`: a nested property set.
    #[prost(message, tag = "9")]
    PropertySet(PropertySet),
    /// `propertysets_value`: a list of property sets.
    #[prost(message, tag = "10")]
    PropertySetList(PropertySetList),
    /// `extension_value`: the encoded fields of a value extension.
    #[prost(bytes = "vec", tag = "11")]
    Extension(Vec<u8>),
}

/// Properties: `keys[i]` names `values[i]`.
#[derive(Clone, PartialEq, Message)]
pub struct PropertySet {
    /// The properties' names.
    #[prost(string, repeated, tag = "1")]
    pub keys: Vec<String>,
    /// Their values, in the keys' order.
    #[prost(message, repeated, tag = "2")]
    pub values: Vec<PropertyValue>,
}

/// A list of property sets.
#[derive(Clone, PartialEq, Message)]
pub struct PropertySetList {
    /// The property sets.
    #[prost(message, repeated, tag = "1")]
    pub propertyset: Vec<PropertySet>,
}

/// A table: typed columns and rows of values.
#[derive(Clone, PartialEq, Message)]
pub struct DataSet {
    /// How many columns.
    #[prost(uint64, optional, tag = "1")]
    pub num_of_columns: Option<u64>,
    /// The columns' names.
    #[prost(string, repeated, tag = "2")]
    pub columns: Vec<String>,
    /// The columns' [`DataType`]s, as numbers.
    #[prost(uint32, repeated, packed = "false", tag = "3")]
    pub types: Vec<u32>,
    /// The rows.
    #[prost(message, repeated, tag = "4")]
    pub rows: Vec<DataSetRow>,
}

/// One row of a [`DataSet`].
#[derive(Clone, PartialEq, Message)]
pub struct DataSetRow {
    /// Its values, one per column.
    #[prost(message, repeated, tag = "1")]
    pub elements: Vec<DataSetValue>,
}

/// One value of a [`DataSet`] row.
#[derive(Clone, PartialEq, Message)]
pub struct DataSetValue {
    /// The value.
    #[prost(oneof = "DataSetValueKind", tags = "1, 2, 3, 4, 5, 6, 7")]
    pub value: Option<DataSetValueKind>,
}

/// A data set value: the field it is carried in.
#[derive(Clone, PartialEq, prost::Oneof)]
pub enum DataSetValueKind {
    /// `int_value` (uint32).
    #[prost(uint32, tag = "1")]
    Int(u32),
    /// `long_value` (uint64).
    #[prost(uint64, tag = "2")]
    Long(u64),
    /// `float_value`.
    #[prost(float, tag = "3")]
    Float(f32),
    /// `double_value`.
    #[prost(double, tag = "4")]
    Double(f64),
    /// `boolean_value`.
    #[prost(bool, tag = "5")]
    Boolean(bool),
    /// `string_value`.
    #[prost(string, tag = "6")]
    String(String),
    /// `extension_value`: the encoded fields of a value extension.
    #[prost(bytes = "vec", tag = "7")]
    Extension(Vec<u8>),
}

/// A template: a definition (in an NBIRTH) or an instance of one.
#[derive(Clone, PartialEq, Message)]
pub struct Template {
    /// The template's version.
    #[prost(string, optional, tag = "1")]
    pub version: Option<String>,
    /// Its members.
    #[prost(message, repeated, tag = "2")]
    pub metrics: Vec<Metric>,
    /// Its parameters.
    #[prost(message, repeated, tag = "3")]
    pub parameters: Vec<TemplateParameter>,
    /// For an instance: the definition's name.
    #[prost(string, optional, tag = "4")]
    pub template_ref: Option<String>,
    /// Whether this is a definition.
    #[prost(bool, optional, tag = "5")]
    pub is_definition: Option<bool>,
}

/// A template's parameter.
#[derive(Clone, PartialEq, Message)]
pub struct TemplateParameter {
    /// Its name.
    #[prost(string, optional, tag = "1")]
    pub name: Option<String>,
    /// Its [`DataType`], as its number.
    #[prost(uint32, optional, tag = "2")]
    pub r#type: Option<u32>,
    /// The value.
    #[prost(oneof = "ParameterValue", tags = "3, 4, 5, 6, 7, 8, 9")]
    pub value: Option<ParameterValue>,
}

/// A template parameter's value: the field it is carried in.
#[derive(Clone, PartialEq, prost::Oneof)]
pub enum ParameterValue {
    /// `int_value` (uint32).
    #[prost(uint32, tag = "3")]
    Int(u32),
    /// `long_value` (uint64).
    #[prost(uint64, tag = "4")]
    Long(u64),
    /// `float_value`.
    #[prost(float, tag = "5")]
    Float(f32),
    /// `double_value`.
    #[prost(double, tag = "6")]
    Double(f64),
    /// `boolean_value`.
    #[prost(bool, tag = "7")]
    Boolean(bool),
    /// `string_value`.
    #[prost(string, tag = "8")]
    String(String),
    /// `extension_value`: the encoded fields of a value extension.
    #[prost(bytes = "vec", tag = "9")]
    Extension(Vec<u8>),
}

/// A metric's datatype: the numbers of the Sparkplug B specification.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum DataType {
    /// Not known.
    Unknown = 0,
    /// Signed 8 bits, in `int_value`.
    Int8 = 1,
    /// Signed 16 bits, in `int_value`.
    Int16 = 2,
    /// Signed 32 bits, in `int_value`.
    Int32 = 3,
    /// Signed 64 bits, in `long_value`.
    Int64 = 4,
    /// Unsigned 8 bits, in `int_value`.
    UInt8 = 5,
    /// Unsigned 16 bits, in `int_value`.
    UInt16 = 6,
    /// Unsigned 32 bits, in `int_value` (Tahu and Ignition: `long_value`).
    UInt32 = 7,
    /// Unsigned 64 bits, in `long_value`.
    UInt64 = 8,
    /// IEEE 754 single precision, in `float_value`.
    Float = 9,
    /// IEEE 754 double precision, in `double_value`.
    Double = 10,
    /// In `boolean_value`.
    Boolean = 11,
    /// In `string_value`.
    String = 12,
    /// Milliseconds since the Unix epoch, in `long_value`.
    DateTime = 13,
    /// In `string_value`.
    Text = 14,
    /// In `string_value`.
    Uuid = 15,
    /// In `dataset_value`.
    DataSet = 16,
    /// In `bytes_value`.
    Bytes = 17,
    /// In `bytes_value`.
    File = 18,
    /// In `template_value`.
    Template = 19,
    /// A property value's type: a property set.
    PropertySet = 20,
    /// A property value's type: a list of property sets.
    PropertySetList = 21,
    /// Array of Int8, in `bytes_value`.
    Int8Array = 22,
    /// Array of Int16, in `bytes_value`.
    Int16Array = 23,
    /// Array of Int32, in `bytes_value`.
    Int32Array = 24,
    /// Array of Int64, in `bytes_value`.
    Int64Array = 25,
    /// Array of UInt8, in `bytes_value`.
    UInt8Array = 26,
    /// Array of UInt16, in `bytes_value`.
    UInt16Array = 27,
    /// Array of UInt32, in `bytes_value`.
    UInt32Array = 28,
    /// Array of UInt64, in `bytes_value`.
    UInt64Array = 29,
    /// Array of Float, in `bytes_value`.
    FloatArray = 30,
    /// Array of Double, in `bytes_value`.
    DoubleArray = 31,
    /// Array of Boolean, in `bytes_value`.
    BooleanArray = 32,
    /// Array of String, in `bytes_value`.
    StringArray = 33,
    /// Array of DateTime, in `bytes_value`.
    DateTimeArray = 34,
}

impl DataType {
    /// Every datatype, by number.
    pub const ALL: [DataType; 35] = [
        DataType::Unknown,
        DataType::Int8,
        DataType::Int16,
        DataType::Int32,
        DataType::Int64,
        DataType::UInt8,
        DataType::UInt16,
        DataType::UInt32,
        DataType::UInt64,
        DataType::Float,
        DataType::Double,
        DataType::Boolean,
        DataType::String,
        DataType::DateTime,
        DataType::Text,
        DataType::Uuid,
        DataType::DataSet,
        DataType::Bytes,
        DataType::File,
        DataType::Template,
        DataType::PropertySet,
        DataType::PropertySetList,
        DataType::Int8Array,
        DataType::Int16Array,
        DataType::Int32Array,
        DataType::Int64Array,
        DataType::UInt8Array,
        DataType::UInt16Array,
        DataType::UInt32Array,
        DataType::UInt64Array,
        DataType::FloatArray,
        DataType::DoubleArray,
        DataType::BooleanArray,
        DataType::StringArray,
        DataType::DateTimeArray,
    ];

    /// The datatype of that number, if the specification has one.
    pub fn from_u32(number: u32) -> Option<DataType> {
        usize::try_from(number).ok().and_then(|i| DataType::ALL.get(i)).copied()
    }

    /// Its number on the wire.
    pub const fn number(self) -> u32 {
        self as u32
    }

    /// Its name in the specification.
    pub const fn name(self) -> &'static str {
        match self {
            DataType::Unknown => "Unknown",
            DataType::Int8 => "Int8",
            DataType::Int16 => "Int16",
            DataType::Int32 => "Int32",
            DataType::Int64 => "Int64",
            DataType::UInt8 => "UInt8",
            DataType::UInt16 => "UInt16",
            DataType::UInt32 => "UInt32",
            DataType::UInt64 => "UInt64",
            DataType::Float => "Float",
            DataType::Double => "Double",
            DataType::Boolean => "Boolean",
            DataType::String => "String",
            DataType::DateTime => "DateTime",
            DataType::Text => "Text",
            DataType::Uuid => "UUID",
            DataType::DataSet => "DataSet",
            DataType::Bytes => "Bytes",
            DataType::File => "File",
            DataType::Template => "Template",
            DataType::PropertySet => "PropertySet",
            DataType::PropertySetList => "PropertySetList",
            DataType::Int8Array => "Int8Array",
            DataType::Int16Array => "Int16Array",
            DataType::Int32Array => "Int32Array",
            DataType::Int64Array => "Int64Array",
            DataType::UInt8Array => "UInt8Array",
            DataType::UInt16Array => "UInt16Array",
            DataType::UInt32Array => "UInt32Array",
            DataType::UInt64Array => "UInt64Array",
            DataType::FloatArray => "FloatArray",
            DataType::DoubleArray => "DoubleArray",
            DataType::BooleanArray => "BooleanArray",
            DataType::StringArray => "StringArray",
            DataType::DateTimeArray => "DateTimeArray",
        }
    }
}

impl std::fmt::Display for DataType {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl Payload {
    /// The payload's protobuf encoding.
    pub fn encode(&self) -> Vec<u8> {
        self.encode_to_vec()
    }

    /// The payload of a message's bytes; fields unknown to the format (its extensions) are
    /// skipped.
    ///
    /// # Errors
    /// The bytes are not a well-formed payload.
    pub fn decode(bytes: &[u8]) -> Result<Payload, prost::DecodeError> {
        <Payload as Message>::decode(bytes)
    }
}

impl Metric {
    /// A metric of that name, datatype and value (a birth's metric); the rest unset.
    pub fn new(name: &str, datatype: DataType, value: Option<MetricValue>) -> Metric {
        Metric {
            name: Some(name.to_owned()),
            datatype: Some(datatype.number()),
            is_null: value.is_none().then_some(true),
            value,
            ..Metric::default()
        }
    }

    /// The metric's [`DataType`], if it has a known one.
    pub fn data_type(&self) -> Option<DataType> {
        self.datatype.and_then(DataType::from_u32)
    }
}

#[cfg(test)]
mod tests {
    use proptest::collection::vec;
    use proptest::option;
    use proptest::prelude::*;

    use super::*;

    fn float() -> impl Strategy<Value = f32> {
        any::<f32>().prop_filter("NaN is not equal to itself", |x| !x.is_nan())
    }

    fn double() -> impl Strategy<Value = f64> {
        any::<f64>().prop_filter("NaN is not equal to itself", |x| !x.is_nan())
    }

    fn text() -> impl Strategy<Value = String> {
        "[a-zA-Z0-9 /°µ_-]{0,12}"
    }

    fn property_set(depth: u32) -> BoxedStrategy<PropertySet> {
        let leaf = prop_oneof![
            any::<u32>().prop_map(PropertyValueKind::Int),
            any::<u64>().prop_map(PropertyValueKind::Long),
            float().prop_map(PropertyValueKind::Float),
            double().prop_map(PropertyValueKind::Double),
            any::<bool>().prop_map(PropertyValueKind::Boolean),
            text().prop_map(PropertyValueKind::String),
            vec(any::<u8>(), 0..6).prop_map(PropertyValueKind::Extension),
        ];
        let kind = if depth == 0 {
            leaf.boxed()
        } else {
            prop_oneof![
                4 => leaf,
                1 => property_set(depth - 1).prop_map(PropertyValueKind::PropertySet),
                1 => vec(property_set(depth - 1), 0..3)
                    .prop_map(|propertyset| PropertyValueKind::PropertySetList(PropertySetList { propertyset })),
            ]
            .boxed()
        };
        let value = (option::of(0u32..35), option::of(any::<bool>()), option::of(kind))
            .prop_map(|(r#type, is_null, value)| PropertyValue { r#type, is_null, value });
        vec((text(), value), 0..4)
            .prop_map(|pairs| {
                let (keys, values) = pairs.into_iter().unzip();
                PropertySet { keys, values }
            })
            .boxed()
    }

    fn data_set() -> impl Strategy<Value = DataSet> {
        let value = prop_oneof![
            any::<u32>().prop_map(DataSetValueKind::Int),
            any::<u64>().prop_map(DataSetValueKind::Long),
            float().prop_map(DataSetValueKind::Float),
            double().prop_map(DataSetValueKind::Double),
            any::<bool>().prop_map(DataSetValueKind::Boolean),
            text().prop_map(DataSetValueKind::String),
        ];
        let row = vec(option::of(value).prop_map(|value| DataSetValue { value }), 0..4)
            .prop_map(|elements| DataSetRow { elements });
        (option::of(any::<u64>()), vec(text(), 0..4), vec(0u32..35, 0..4), vec(row, 0..3))
            .prop_map(|(num_of_columns, columns, types, rows)| DataSet { num_of_columns, columns, types, rows })
    }

    fn template(depth: u32) -> BoxedStrategy<Template> {
        let parameter_value = prop_oneof![
            any::<u32>().prop_map(ParameterValue::Int),
            any::<u64>().prop_map(ParameterValue::Long),
            float().prop_map(ParameterValue::Float),
            double().prop_map(ParameterValue::Double),
            any::<bool>().prop_map(ParameterValue::Boolean),
            text().prop_map(ParameterValue::String),
            vec(any::<u8>(), 0..6).prop_map(ParameterValue::Extension),
        ];
        let parameter = (option::of(text()), option::of(0u32..35), option::of(parameter_value))
            .prop_map(|(name, r#type, value)| TemplateParameter { name, r#type, value });
        (
            option::of(text()),
            vec(metric(depth), 0..3),
            vec(parameter, 0..3),
            option::of(text()),
            option::of(any::<bool>()),
        )
            .prop_map(|(version, metrics, parameters, template_ref, is_definition)| Template {
                version,
                metrics,
                parameters,
                template_ref,
                is_definition,
            })
            .boxed()
    }

    fn metric_value(depth: u32) -> BoxedStrategy<MetricValue> {
        let scalar = prop_oneof![
            any::<u32>().prop_map(MetricValue::Int),
            any::<u64>().prop_map(MetricValue::Long),
            float().prop_map(MetricValue::Float),
            double().prop_map(MetricValue::Double),
            any::<bool>().prop_map(MetricValue::Boolean),
            text().prop_map(MetricValue::String),
            vec(any::<u8>(), 0..16).prop_map(MetricValue::Bytes),
            data_set().prop_map(MetricValue::DataSet),
            vec(any::<u8>(), 0..6).prop_map(MetricValue::Extension),
        ];
        if depth == 0 {
            scalar.boxed()
        } else {
            prop_oneof![6 => scalar, 1 => template(depth - 1).prop_map(MetricValue::Template)].boxed()
        }
    }

    fn metadata() -> impl Strategy<Value = MetaData> {
        (
            option::of(any::<bool>()),
            option::of(text()),
            option::of(any::<u64>()),
            option::of(any::<u64>()),
            (option::of(text()), option::of(text()), option::of(text()), option::of(text())),
        )
            .prop_map(|(is_multi_part, content_type, size, seq, (file_name, file_type, md5, description))| {
                MetaData { is_multi_part, content_type, size, seq, file_name, file_type, md5, description }
            })
    }

    fn metric(depth: u32) -> BoxedStrategy<Metric> {
        (
            (option::of(text()), option::of(any::<u64>()), option::of(any::<u64>()), option::of(any::<u32>())),
            (option::of(any::<bool>()), option::of(any::<bool>()), option::of(any::<bool>())),
            option::of(metadata()),
            option::of(property_set(1)),
            option::of(metric_value(depth)),
        )
            .prop_map(
                |(
                    (name, alias, timestamp, datatype),
                    (is_historical, is_transient, is_null),
                    metadata,
                    properties,
                    value,
                )| Metric {
                    name,
                    alias,
                    timestamp,
                    datatype,
                    is_historical,
                    is_transient,
                    is_null,
                    metadata,
                    properties,
                    value,
                },
            )
            .boxed()
    }

    fn payload() -> impl Strategy<Value = Payload> {
        (
            option::of(any::<u64>()),
            vec(metric(1), 0..6),
            option::of(any::<u64>()),
            option::of(text()),
            option::of(vec(any::<u8>(), 0..8)),
        )
            .prop_map(|(timestamp, metrics, seq, uuid, body)| Payload { timestamp, metrics, seq, uuid, body })
    }

    proptest! {
        #[test]
        fn every_payload_decodes_to_itself(payload in payload()) {
            let bytes = payload.encode();
            prop_assert_eq!(Payload::decode(&bytes), Ok(payload));
        }

        #[test]
        fn any_bytes_decode_or_fail_without_panicking(bytes in vec(any::<u8>(), 0..64)) {
            if let Ok(payload) = Payload::decode(&bytes) {
                // What decoded encodes again and decodes to the same payload.
                prop_assert_eq!(Payload::decode(&payload.encode()), Ok(payload));
            }
        }
    }

    #[test]
    fn fields_are_where_the_specification_puts_them() {
        let payload = Payload { timestamp: Some(1), seq: Some(2), ..Payload::default() };
        assert_eq!(payload.encode(), [0x08, 1, 0x18, 2], "timestamp is field 1, seq field 3 (varints)");
        let metric = Metric { alias: Some(3), value: Some(MetricValue::Int(19200)), ..Metric::default() };
        let bytes = Payload { metrics: vec![metric], ..Payload::default() }.encode();
        // metrics: field 2, length-delimited; alias field 2; int_value field 10 (tag 0x50), 19200 = 0x80 0x96 0x01.
        assert_eq!(bytes, [0x12, 6, 0x10, 3, 0x50, 0x80, 0x96, 0x01]);
    }

    #[test]
    fn a_set_scalar_is_encoded_even_when_zero() {
        let metric = Metric { is_historical: Some(false), value: Some(MetricValue::Long(0)), ..Metric::default() };
        let bytes = Payload { metrics: vec![metric], seq: Some(0), ..Payload::default() }.encode();
        assert_eq!(bytes, [0x12, 4, 0x28, 0, 0x58, 0, 0x18, 0]);
    }

    #[test]
    fn data_set_types_are_unpacked_as_proto2_writes_them() {
        let set = DataSet { types: vec![7, 12], ..DataSet::default() };
        assert_eq!(set.encode_to_vec(), [0x18, 7, 0x18, 12]);
        let packed = [0x1a, 2, 7, 12];
        assert_eq!(DataSet::decode(&packed[..]).map(|s| s.types), Ok(vec![7, 12]), "packed decodes too");
    }

    #[test]
    fn extension_fields_are_skipped() {
        let payload = Payload {
            seq: Some(4),
            metrics: vec![Metric::new("bdSeq", DataType::UInt64, Some(MetricValue::Long(7)))],
            ..Payload::default()
        };
        let mut bytes = payload.encode();
        // Field 6 (the first of Payload's extensions), a varint; field 1000, length-delimited.
        bytes.extend([0x30, 0x2a, 0xc2, 0x3e, 3, b'a', b'b', b'c']);
        assert_eq!(Payload::decode(&bytes), Ok(payload));
    }

    #[test]
    fn a_value_extension_is_kept_as_its_bytes() {
        let metric = Metric { value: Some(MetricValue::Extension(vec![0x08, 0x01])), ..Metric::default() };
        let payload = Payload { metrics: vec![metric], ..Payload::default() };
        let bytes = payload.encode();
        assert_eq!(bytes, [0x12, 5, 0x9a, 0x01, 2, 0x08, 0x01], "extension_value is field 19");
        assert_eq!(Payload::decode(&bytes), Ok(payload));
    }

    #[test]
    fn truncated_bytes_are_an_error() {
        let bytes = Payload { uuid: Some("abcdef".into()), ..Payload::default() }.encode();
        let short = bytes.get(..bytes.len() - 1).unwrap_or_default();
        assert!(Payload::decode(short).is_err());
    }

    #[test]
    fn every_datatype_has_its_number_and_name() {
        for (number, datatype) in (0u32..).zip(DataType::ALL) {
            assert_eq!(datatype.number(), number);
            assert_eq!(DataType::from_u32(number), Some(datatype));
        }
        assert_eq!(DataType::from_u32(35), None);
        assert_eq!(DataType::from_u32(u32::MAX), None);
        assert_eq!(DataType::UInt32.name(), "UInt32");
        assert_eq!(DataType::Uuid.to_string(), "UUID");
        assert_eq!(DataType::DateTimeArray.number(), 34);
    }

    #[test]
    fn a_birth_metric_has_name_datatype_and_value() {
        let metric = Metric::new("Node Control/Rebirth", DataType::Boolean, Some(MetricValue::Boolean(false)));
        assert_eq!(metric.name.as_deref(), Some("Node Control/Rebirth"));
        assert_eq!(metric.data_type(), Some(DataType::Boolean));
        assert_eq!(metric.is_null, None);
        let null = Metric::new("F001", DataType::UInt16, None);
        assert_eq!(null.is_null, Some(true));
    }
}
