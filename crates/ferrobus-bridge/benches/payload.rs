//! Criterion benchmarks of the Sparkplug B payload: what the edge node pays per message.
//!
//! - `payload/encode ddata-50`, `payload/decode ddata-50`: a DDATA of 50 changed metrics by
//!   alias (a UInt16 each, with its timestamp), the common message of a busy device.
//! - `payload/encode dbirth-200`, `payload/decode dbirth-200`: a DBIRTH of 200 metrics, each
//!   with name, alias, datatype, timestamp, value and an `engUnit` property.
//! - `convert/metric_value+to_raw`: a scaled point's raw value to its Double and back.
//!
//! Run: `cargo bench -p ferrobus-bridge --bench payload` (add `-- --warm-up-time 1
//! --measurement-time 3` for a quick run).

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use ferrobus_bridge::sparkplug::convert::{self, UintEncoding};
use ferrobus_bridge::sparkplug::payload::{
    DataType, Metric, MetricValue, Payload, PropertySet, PropertyValue, PropertyValueKind,
};
use ferrobus_profile::{Access, Order, Point, Table, Value, ValueType};

const NOW: u64 = 1_700_000_000_000;

fn ddata(metrics: u32) -> Payload {
    let metrics = (0..metrics)
        .map(|i| Metric {
            alias: Some(u64::from(i) + 1),
            timestamp: Some(NOW + u64::from(i)),
            value: Some(MetricValue::Int(5000 + i)),
            ..Metric::default()
        })
        .collect();
    Payload { timestamp: Some(NOW), seq: Some(17), metrics, ..Payload::default() }
}

fn dbirth(metrics: u32) -> Payload {
    let unit = PropertySet {
        keys: vec!["engUnit".into()],
        values: vec![PropertyValue {
            r#type: Some(DataType::String.number()),
            is_null: None,
            value: Some(PropertyValueKind::String("Hz".into())),
        }],
    };
    let metrics = (0..metrics)
        .map(|i| Metric {
            alias: Some(u64::from(i) + 1),
            timestamp: Some(NOW),
            properties: Some(unit.clone()),
            ..Metric::new(&format!("F{i:03}"), DataType::Double, Some(MetricValue::Double(f64::from(i) * 0.01)))
        })
        .collect();
    Payload { timestamp: Some(NOW), seq: Some(1), metrics, ..Payload::default() }
}

fn payload(c: &mut Criterion) {
    let mut group = c.benchmark_group("payload");
    for (name, payload) in [("ddata-50", ddata(50)), ("dbirth-200", dbirth(200))] {
        let bytes = payload.encode();
        group.throughput(Throughput::Bytes(u64::try_from(bytes.len()).unwrap_or(u64::MAX)));
        group.bench_function(format!("encode {name}"), |b| b.iter(|| black_box(&payload).encode()));
        group.bench_function(format!("decode {name}"), |b| b.iter(|| Payload::decode(black_box(&bytes))));
    }
    group.finish();
}

fn scaled_point() -> Point {
    Point {
        table: Table::Holding,
        address: 0,
        number: 1,
        code: "F001".into(),
        label: String::new(),
        description: String::new(),
        value_type: ValueType::U16,
        order: Order::Abcd,
        width: 1,
        unit: Some("Hz".into()),
        scale: 0.01,
        offset: 0.0,
        min: None,
        max: None,
        access: Access::Rw,
        while_running: true,
        group: None,
        values: Vec::new(),
        bits: Vec::new(),
        depends_on: Vec::new(),
        backup: false,
        source: None,
        confirmed: true,
        default: Value::Int(0),
    }
}

fn convert(c: &mut Criterion) {
    let point = scaled_point();
    let raw = Value::Int(5000);
    c.bench_function("convert/metric_value+to_raw", |b| {
        b.iter(|| {
            let value = convert::metric_value(black_box(&point), black_box(&raw), UintEncoding::Spec);
            value.map(|v| convert::to_raw(&point, &v))
        });
    });
}

criterion_group!(benches, payload, convert);
criterion_main!(benches);
