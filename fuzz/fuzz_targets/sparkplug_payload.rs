//! What the bridge reads from a broker, on arbitrary bytes: the Sparkplug B payload, the topic,
//! a host's STATE.
//!
//! - `Payload::decode` never panics; what decodes encodes to bytes that decode again and encode
//!   to the same bytes (`encoded_len` agrees). Bytes are compared, not values, so that a NaN
//!   float (never equal to itself) still has to come back bit for bit.
//! - Every metric value in it, nested template members too, goes through `convert::to_raw`
//!   against real points (the 3G3RX's F001, its `run` coil and its i16 `d009`, and a string, an
//!   f32 and a scaled i32 of a small profile): an error names the point; a raw value accepted
//!   fits the point's registers (`Point::encode`), passes or fails `check_write` without
//!   panicking, and publishes as a metric value (`metric_value`, both UInt encodings) that
//!   `to_raw` maps back to the same registers.
//! - The bytes as text, alone and after `spBv1.0/` with a message type put in as the second
//!   level: `Topic::parse` gives a topic whose Display is that text, a device id exactly for a
//!   device's message type; `parse_state_topic` gives a host id whose `state_topic` is that
//!   text. The bytes, and the text as the values of `{"online":..,"timestamp":..}`:
//!   `parse_state` gives a state whose JSON parses to itself.
#![no_main]

use std::sync::LazyLock;

use ferrobus_bridge::sparkplug::convert::{self, UintEncoding};
use ferrobus_bridge::sparkplug::payload::{DataType, Metric, MetricValue, Payload};
use ferrobus_bridge::sparkplug::topic::{self, MessageType, NAMESPACE, Topic};
use ferrobus_profile::{Point, Profile, Value, ValueType};
use libfuzzer_sys::fuzz_target;

/// A string, an f32 and a scaled signed point, which the built-in profiles do not have.
const TYPES_PROFILE: &str = r#"
[device]
name = "fuzz types"
vendor = "ferrobus"
product_code = "FB-FUZZ"
revision = "1"

[addressing]
base = 0

[[registers]]
number = 0
type = "string"
length = 4
name = "tag"
access = "rw"

[[registers]]
number = 4
type = "f32"
name = "ratio"
access = "rw"
min = -10
max = 10

[[registers]]
number = 6
type = "i32"
name = "temperature"
scale = 0.1
offset = -40
unit = "°C"
access = "rw"
"#;

/// The points every metric value is tried against.
static POINTS: LazyLock<Vec<Point>> = LazyLock::new(|| {
    let inverter = Profile::builtin("omron-3g3rx").expect("the built-in 3G3RX profile parses");
    let types = Profile::parse(TYPES_PROFILE, "fuzz-types.toml").expect("the fuzz profile parses");
    let pick = |profile: &Profile, code: &str| {
        profile.point(code).cloned().unwrap_or_else(|| panic!("{} has no point {code}", profile.origin))
    };
    vec![
        pick(&inverter, "F001"),
        pick(&inverter, "run"),
        pick(&inverter, "d009"),
        pick(&types, "tag"),
        pick(&types, "ratio"),
        pick(&types, "temperature"),
    ]
});

fuzz_target!(|data: &[u8]| {
    if let Ok(payload) = Payload::decode(data) {
        round_trip(&payload);
        for metric in &payload.metrics {
            check_metric(metric);
        }
    }
    check_state(data);
    if let Ok(text) = std::str::from_utf8(data) {
        check_topic(text);
        // The fuzzer does not guess "spBv1.0" or "DCMD" by itself: the text also goes in as
        // the levels after them, and as a STATE's values.
        let kind = MessageType::ALL[usize::from(data.first().copied().unwrap_or(0)) % MessageType::ALL.len()];
        let (group, rest) = text.split_once('/').unwrap_or((text, ""));
        check_topic(&format!("{NAMESPACE}/{group}/{kind}/{rest}"));
        check_topic(&topic::state_topic(text));
        check_state(format!("{{\"online\":{text}}}").as_bytes());
        check_state(format!("{{\"online\":true,\"timestamp\":{text}}}").as_bytes());
    }
});

/// A host's STATE payload: what parses gives JSON that parses to the same state.
fn check_state(payload: &[u8]) {
    if let Some(state) = topic::parse_state(payload) {
        assert_eq!(topic::parse_state(&state.to_json()), Some(state), "a STATE's JSON does not parse to itself");
    }
}

/// Encode, decode, encode: the same bytes twice.
fn round_trip(payload: &Payload) {
    let bytes = payload.encode();
    assert_eq!(prost::Message::encoded_len(payload), bytes.len(), "encoded_len disagrees with encode");
    let again = Payload::decode(&bytes).unwrap_or_else(|e| panic!("an encoded payload does not decode: {e}"));
    assert_eq!(again.encode(), bytes, "decode(encode(p)) encodes to other bytes");
}

/// A metric's value against every point, and the members of a template value.
fn check_metric(metric: &Metric) {
    if let Some(datatype) = metric.datatype.and_then(DataType::from_u32) {
        assert_eq!(DataType::from_u32(datatype.number()), Some(datatype));
        assert!(!datatype.name().is_empty());
    }
    let Some(value) = &metric.value else { return };
    assert!(!convert::describe(value).is_empty());
    for point in POINTS.iter() {
        check_to_raw(point, value);
    }
    if let MetricValue::Template(template) = value {
        for member in &template.metrics {
            check_metric(member);
        }
    }
}

/// `to_raw` of one value for one point, and back through `metric_value`.
fn check_to_raw(point: &Point, value: &MetricValue) {
    let raw = match convert::to_raw(point, value) {
        Ok(raw) => raw,
        Err(e) => {
            assert!(e.to_string().contains(&point.code), "the refusal does not name {}: {e}", point.code);
            return;
        }
    };
    let registers = registers_of(point, &raw);
    // Access and the profile's range are check_write's to judge; it must only not panic.
    let _ = point.check_write(&raw, &convert::describe(value));
    for encoding in [UintEncoding::Spec, UintEncoding::LongValue] {
        let published = convert::metric_value(point, &raw, encoding)
            .unwrap_or_else(|| panic!("{}: raw {raw:?} from {value:?} does not publish", point.code));
        let back = convert::to_raw(point, &published)
            .unwrap_or_else(|e| panic!("{}: {published:?}, published for raw {raw:?}, is refused: {e}", point.code));
        assert_eq!(
            registers_of(point, &back),
            registers,
            "{}: {value:?} → {raw:?} → {published:?} → {back:?}",
            point.code
        );
    }
}

/// What the raw value writes: the registers, or for a bit its state.
fn registers_of(point: &Point, raw: &Value) -> Result<Vec<u16>, bool> {
    if point.value_type == ValueType::Bit {
        let Value::Bool(on) = raw else { panic!("{}: a bit's raw value is {raw:?}", point.code) };
        return Err(*on);
    }
    Ok(point.encode(raw).unwrap_or_else(|e| panic!("{}: raw {raw:?} from to_raw does not fit: {e}", point.code)))
}

/// The text as an edge node's or device's topic, and as a STATE topic.
fn check_topic(text: &str) {
    if let Some(parsed) = Topic::parse(text) {
        assert_eq!(parsed.to_string(), text, "a topic's Display is not the text it was parsed from");
        assert_eq!(parsed.kind.is_device(), parsed.device.is_some(), "{parsed:?}");
        assert_eq!(parsed.kind.as_str().parse::<MessageType>().ok(), Some(parsed.kind));
        for id in [Some(&parsed.group), Some(&parsed.node), parsed.device.as_ref()].into_iter().flatten() {
            assert!(!id.is_empty() && !id.contains('/'), "{parsed:?}");
            let _ = topic::check_id("fuzz", id);
        }
    }
    if let Some(host) = topic::parse_state_topic(text) {
        assert_eq!(topic::state_topic(host), text, "a STATE topic does not come back from its host id");
    }
}
