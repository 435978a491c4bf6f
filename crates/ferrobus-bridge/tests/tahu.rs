//! The Sparkplug B payloads of `ferrobus_bridge::sparkplug` against a third codec nobody here
//! wrote: Eclipse Tahu's JavaScript codec, npm `sparkplug-payload` 1.0.3, the one Tahu's own
//! host and edge examples use. `tests/peers/sparkplug/tahu/decode.js` prints what Tahu decoded
//! as JSON (Longs as decimal strings); `encode.js` makes a payload the way a Tahu (or Ignition)
//! host application sends a DCMD.
//!
//! Tahu does not read everything as the specification writes it, and these tests pin down
//! exactly where (see `tahu_reads` below): UInt32 only from `long_value` (our default, the
//! specification's, puts it in `int_value`), Int8/16 only as a 32-bit sign extension (our
//! default, own-width two's complement, which pysparkplug requires, reads as a large positive
//! number), no arrays, no data set cell of an `int_value` type. `UintEncoding::LongValue`
//! (Tahu's and Ignition's convention: UInt32 in `long_value`, Int8/16 sign-extended) makes Tahu
//! read every integer right. Its encoder writes that convention; our decoder and
//! `convert::to_raw` read both.
//!
//! The peer: `node` on PATH and `npm ci` run in tests/peers/sparkplug/tahu (both done by
//! `.ci/setup-peers.sh`). Under `CI=true` a missing peer fails the test; elsewhere the test
//! passes with a `SKIPPED` line on stderr.

use std::io::Write as _;
use std::path::PathBuf;
use std::process::{Command, Stdio};

use ferrobus_bridge::sparkplug::convert::{self, UintEncoding};
use ferrobus_bridge::sparkplug::payload::{
    DataSet, DataSetRow, DataSetValue, DataSetValueKind, DataType, MetaData, Metric, MetricValue, ParameterValue,
    Payload, Template, TemplateParameter,
};
use ferrobus_profile::{Point, Profile, Table, Value, ValueType};
use serde_json::{Value as Json, json};

mod support;

const NOW: u64 = 1_700_000_000_000;

// ---------------------------------------------------------------------------------------------
// The peer

/// Eclipse Tahu's codec, run by node through decode.js and encode.js.
struct Tahu {
    dir: PathBuf,
}

/// The peer, or None (after a `SKIPPED` line) when it is missing outside CI.
///
/// # Panics
/// Under `CI=true`, when it is missing.
fn tahu(test: &str) -> Option<Tahu> {
    let dir = support::root().join("tests/peers/sparkplug/tahu");
    let package = dir.join("node_modules/sparkplug-payload/package.json");
    let mut missing = Vec::new();
    if !support::on_path("node") {
        missing.push("node (apt install nodejs npm)".to_owned());
    }
    if !package.is_file() {
        missing.push(format!("{} (npm ci there: .ci/setup-peers.sh)", package.display()));
    }
    support::present(test, &missing).then_some(Tahu { dir })
}

impl Tahu {
    /// Runs `node SCRIPT -` with `input` on stdin; its stdout, or its stderr when it failed.
    fn run(&self, script: &str, input: &[u8]) -> Result<Vec<u8>, String> {
        let mut child = Command::new("node")
            .arg(self.dir.join(script))
            .arg("-")
            .current_dir(&self.dir)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("start node {script}: {e}"));
        child.stdin.take().expect("stdin").write_all(input).expect("write stdin");
        let out = child.wait_with_output().expect("wait for node");
        if out.status.success() { Ok(out.stdout) } else { Err(String::from_utf8_lossy(&out.stderr).into_owned()) }
    }

    /// Runs `node SCRIPT -` with `input` on stdin; its stdout.
    fn node(&self, script: &str, input: &[u8]) -> Vec<u8> {
        self.run(script, input).unwrap_or_else(|stderr| panic!("Tahu's {script} failed: {stderr}"))
    }

    /// What Tahu's decodePayload made of the payload, as decode.js prints it.
    fn decode(&self, payload: &Payload) -> Json {
        let out = self.node("decode.js", &payload.encode());
        serde_json::from_slice(&out).unwrap_or_else(|e| panic!("decode.js printed no JSON ({e})"))
    }

    /// The payload Tahu's encodePayload makes of `payload` (Tahu's JSON shape), decoded by ours.
    fn encode(&self, payload: &Json) -> Payload {
        let bytes = self.node("encode.js", payload.to_string().as_bytes());
        Payload::decode(&bytes).unwrap_or_else(|e| panic!("our decoder refused Tahu's payload: {e}"))
    }
}

/// The metric of that name in Tahu's decoded payload.
fn find<'a>(decoded: &'a Json, name: &str) -> &'a Json {
    decoded["metrics"]
        .as_array()
        .and_then(|metrics| metrics.iter().find(|m| m["name"] == name))
        .unwrap_or_else(|| panic!("no metric {name} in {decoded}"))
}

// ---------------------------------------------------------------------------------------------
// Points and births

fn rx() -> Profile {
    Profile::builtin("omron-3g3rx").expect("the built-in 3G3RX profile")
}

/// The 3G3RX's F001 (output frequency, u32 in 0.01 Hz, raw 0 to 40000).
fn f001() -> Point {
    rx().point("F001").expect("3G3RX has F001").clone()
}

/// A point of that code and type, unscaled unless `scale` says, from F001's shape.
fn point(code: &str, value_type: ValueType, scale: f64, unit: Option<&str>) -> Point {
    Point {
        table: if value_type == ValueType::Bit { Table::Coils } else { Table::Holding },
        code: code.into(),
        value_type,
        width: if value_type == ValueType::String { 4 } else { value_type.registers() },
        unit: unit.map(str::to_owned),
        scale,
        offset: 0.0,
        min: None,
        max: None,
        ..f001()
    }
}

/// A DBIRTH metric, and what Tahu reads of it with each [`UintEncoding`].
struct Born {
    metric: Metric,
    /// Tahu's name of the datatype (null: it knows none).
    tahu_type: Json,
    /// The value Tahu reads when the metric was written with `UintEncoding::Spec`.
    spec: Json,
    /// ... with `UintEncoding::LongValue`.
    long_value: Json,
    /// The right value, when Tahu reads another.
    right: Option<Json>,
}

/// A profile point's metric, born through `convert` as the edge node births it.
fn from_point(point: &Point, raw: &Value, encoding: UintEncoding) -> Metric {
    let value = convert::metric_value(point, raw, encoding).expect("a value of the point's type");
    Metric {
        timestamp: Some(NOW),
        properties: convert::properties_of(point),
        ..Metric::new(&point.code, convert::datatype_of(point), Some(value))
    }
}

fn direct(name: &str, datatype: DataType, value: Option<MetricValue>) -> Metric {
    Metric { timestamp: Some(NOW), ..Metric::new(name, datatype, value) }
}

/// An unsigned 8/16/32-bit value in the field `encoding` puts it in.
/// Every datatype Tahu 1.0.3 knows (and one it does not), each with what Tahu reads of it.
///
/// Where Tahu diverges (`right` is set), the reason is in its `getValue`: UInt8/16 from
/// `int_value` only, UInt32 from `long_value` only, Int8/16/32 as `int_value` taken as a
/// signed 32-bit number (so our own-width two's complement of an Int8/16 stays positive), a
/// data set's Int64 cell as unsigned, arrays not at all.
#[allow(clippy::too_many_lines)]
fn tahu_reads(encoding: UintEncoding) -> Vec<Born> {
    let big_u64 = (1u64 << 53) + 1;
    let points = [
        // (point, raw, Tahu's type, Spec read, LongValue read, right)
        (point("u16", ValueType::U16, 1.0, None), Value::Int(5000), "UInt16", json!(5000), json!(5000), Json::Null),
        (point("i16", ValueType::I16, 1.0, None), Value::Int(-5), "Int16", json!(65531), json!(-5), json!(-5)),
        (point("u32", ValueType::U32, 1.0, None), Value::Int(19200), "UInt32", Json::Null, json!(19200), json!(19200)),
        (
            point("u32-big", ValueType::U32, 1.0, None),
            Value::Int(4_000_000_000),
            "UInt32",
            Json::Null,
            json!(4_000_000_000u32),
            json!(4_000_000_000u32),
        ),
        (
            point("i32", ValueType::I32, 1.0, None),
            Value::Int(-70000),
            "Int32",
            json!(-70000),
            json!(-70000),
            Json::Null,
        ),
        (
            point("u64-big", ValueType::U64, 1.0, None),
            Value::Int(i128::from(big_u64)),
            "UInt64",
            json!(big_u64.to_string()),
            json!(big_u64.to_string()),
            Json::Null,
        ),
        (
            point("i64", ValueType::I64, 1.0, None),
            Value::Int(-(1 << 40)),
            "Int64",
            json!("-1099511627776"),
            json!("-1099511627776"),
            Json::Null,
        ),
        (point("f32", ValueType::F32, 1.0, None), Value::Float(1.5), "Float", json!(1.5), json!(1.5), Json::Null),
        (
            point("f64", ValueType::F64, 1.0, None),
            Value::Float(-2.25),
            "Double",
            json!(-2.25),
            json!(-2.25),
            Json::Null,
        ),
        (point("bit", ValueType::Bit, 1.0, None), Value::Bool(true), "Boolean", json!(true), json!(true), Json::Null),
        (
            point("string", ValueType::String, 1.0, None),
            Value::Text("3G3RX".into()),
            "String",
            json!("3G3RX"),
            json!("3G3RX"),
            Json::Null,
        ),
        // 50.0 Hz: JavaScript prints a whole Double as an integer.
        (point("hz", ValueType::U16, 0.01, Some("Hz")), Value::Int(5000), "Double", json!(50), json!(50), Json::Null),
    ];
    let mut born: Vec<Born> = points
        .into_iter()
        .map(|(point, raw, tahu_type, spec, long_value, right)| Born {
            metric: from_point(&point, &raw, encoding),
            tahu_type: json!(tahu_type),
            spec,
            long_value,
            right: (!right.is_null()).then_some(right),
        })
        .collect();
    let same = |metric: Metric, tahu_type: &str, read: Json| Born {
        metric,
        tahu_type: json!(tahu_type),
        spec: read.clone(),
        long_value: read,
        right: None,
    };
    // Int8 −100 as our encoder lays it out (no profile type is 8 bits wide): two's complement
    // of 8 bits, or sign-extended to 32 bits in Tahu's convention.
    let int8_value = match encoding {
        UintEncoding::Spec => 156,
        UintEncoding::LongValue => (-100i32).cast_unsigned(),
    };
    let int8 = direct("i8", DataType::Int8, Some(MetricValue::Int(int8_value)));
    born.push(Born { long_value: json!(-100), right: Some(json!(-100)), ..same(int8, "Int8", json!(156)) });
    born.push(same(direct("u8", DataType::UInt8, Some(MetricValue::Int(200))), "UInt8", json!(200)));
    let datetime = direct("datetime", DataType::DateTime, Some(MetricValue::Long(NOW + 123)));
    born.push(same(datetime, "DateTime", json!((NOW + 123).to_string())));
    born.push(same(
        direct("text", DataType::Text, Some(MetricValue::String("free text".into()))),
        "Text",
        json!("free text"),
    ));
    let uuid = "0b8e1c3a-5d2f-4e6a-9b7c-1d2e3f405162";
    born.push(same(direct("uuid", DataType::Uuid, Some(MetricValue::String(uuid.into()))), "UUID", json!(uuid)));
    born.push(same(
        direct("bytes", DataType::Bytes, Some(MetricValue::Bytes(vec![1, 2, 0xff]))),
        "Bytes",
        json!("0102ff"),
    ));
    let file = Metric {
        metadata: Some(MetaData { file_name: Some("hi.txt".into()), ..MetaData::default() }),
        ..direct("file", DataType::File, Some(MetricValue::Bytes(b"hi\n".to_vec())))
    };
    born.push(same(file, "File", json!("68690a")));
    let data_set = direct("dataset", DataType::DataSet, Some(MetricValue::DataSet(data_set())));
    let tahu_data_set = |int64: &str| {
        json!({"types": ["Int64", "Double", "String"], "rows": [[int64, 2.5, "a"]], "numOfColumns": "3",
               "columns": ["n", "x", "s"]})
    };
    born.push(Born {
        right: Some(tahu_data_set("-7")),
        ..same(data_set, "DataSet", tahu_data_set(&(u64::MAX - 6).to_string()))
    });
    let template = direct("template", DataType::Template, Some(MetricValue::Template(template())));
    let tahu_template = json!({"version": "1", "templateRef": "Drive", "isDefinition": false,
        "metrics": [{"value": "42", "type": "Int64", "name": "speed"}],
        "parameters": [{"value": "Hz", "type": "String", "name": "unit"}]});
    born.push(same(template, "Template", tahu_template));
    // Arrays (22 and up) are newer than Tahu 1.0.3's codec: no type, no value.
    let array = direct("i16-array", DataType::Int16Array, Some(MetricValue::Bytes(vec![0xfe, 0xff, 0x2c, 0x01])));
    born.push(Born { tahu_type: Json::Null, right: Some(json!([-2, 300])), ..same(array, "", Json::Null) });
    born.push(same(direct("null", DataType::UInt16, None), "UInt16", Json::Null));
    for (alias, b) in (1u64..).zip(born.iter_mut()) {
        b.metric.alias = Some(alias);
    }
    born
}

/// A data set of the column types Tahu 1.0.3 reads (its `getDataSetValue` throws on
/// Int8/16/32, UInt8/16/64 and any `int_value` cell).
fn data_set() -> DataSet {
    let cell = |kind| DataSetValue { value: Some(kind) };
    DataSet {
        num_of_columns: Some(3),
        columns: vec!["n".into(), "x".into(), "s".into()],
        types: vec![DataType::Int64.number(), DataType::Double.number(), DataType::String.number()],
        rows: vec![DataSetRow {
            elements: vec![
                cell(DataSetValueKind::Long((-7i64).cast_unsigned())),
                cell(DataSetValueKind::Double(2.5)),
                cell(DataSetValueKind::String("a".into())),
            ],
        }],
    }
}

fn template() -> Template {
    Template {
        version: Some("1".into()),
        metrics: vec![Metric::new("speed", DataType::Int64, Some(MetricValue::Long(42)))],
        parameters: vec![TemplateParameter {
            name: Some("unit".into()),
            r#type: Some(DataType::String.number()),
            value: Some(ParameterValue::String("Hz".into())),
        }],
        template_ref: Some("Drive".into()),
        is_definition: Some(false),
    }
}

fn dbirth(born: &[Born]) -> Payload {
    Payload {
        timestamp: Some(NOW),
        seq: Some(1),
        metrics: born.iter().map(|b| b.metric.clone()).collect(),
        ..Payload::default()
    }
}

/// Checks Tahu's reading of every metric of the DBIRTH; returns a line per metric for the table.
fn check_dbirth(tahu: &Tahu, encoding: UintEncoding) -> Vec<String> {
    let born = tahu_reads(encoding);
    let decoded = tahu.decode(&dbirth(&born));
    assert_eq!((&decoded["timestamp"], &decoded["seq"]), (&json!(NOW.to_string()), &json!("1")));
    let metrics = decoded["metrics"].as_array().expect("metrics");
    assert_eq!(metrics.len(), born.len(), "every metric decoded");
    let mut table = Vec::new();
    for (b, metric) in born.iter().zip(metrics) {
        let name = b.metric.name.as_deref().unwrap_or_default();
        let datatype = b.metric.data_type().map_or("?", DataType::name);
        let want = if encoding == UintEncoding::Spec { &b.spec } else { &b.long_value };
        assert_eq!(metric["name"], name);
        assert_eq!(metric["alias"], json!(b.metric.alias.map(|a| a.to_string())), "{name}");
        assert_eq!(metric["timestamp"], json!(NOW.to_string()), "{name}");
        assert_eq!(metric["type"], b.tahu_type, "{name} ({datatype})");
        assert_eq!(&metric["value"], want, "{name} ({datatype}, {encoding:?})");
        let right = b.right.as_ref().unwrap_or(&b.spec);
        let verdict = if want == right { "right".to_owned() } else { format!("WRONG (right: {right})") };
        table.push(format!("{encoding:?} {datatype:<10} {name}: Tahu reads {want} {verdict}"));
    }
    assert_eq!(find(&decoded, "hz")["properties"], json!({"engUnit": {"type": "String", "value": "Hz"}}));
    assert_eq!(find(&decoded, "u16").get("properties"), None, "no unit, no properties");
    // Tahu fills the metadata's unset fields with protobuf's defaults ("", 0, false).
    let metadata = &find(&decoded, "file")["metadata"];
    assert_eq!((&metadata["fileName"], &metadata["size"]), (&json!("hi.txt"), &json!("0")));
    table
}

// ---------------------------------------------------------------------------------------------
// Our births, Tahu's decoder

#[test]
fn tahu_reads_a_spec_dbirth_right_but_for_uint32_and_own_width_int8_16() {
    let Some(tahu) = tahu("tahu_reads_a_spec_dbirth_right_but_for_uint32_and_own_width_int8_16") else { return };
    let table = check_dbirth(&tahu, UintEncoding::Spec);
    eprintln!("{}", table.join("\n"));
    let wrong: Vec<&str> = table.iter().filter(|l| l.contains("WRONG")).map(String::as_str).collect();
    assert_eq!(wrong.len(), 6, "UInt32 ×2, Int8, Int16, DataSet's Int64, Int16Array: {wrong:#?}");
}

#[test]
fn tahu_reads_every_integer_right_in_its_own_convention() {
    let Some(tahu) = tahu("tahu_reads_every_integer_right_in_its_own_convention") else { return };
    let table = check_dbirth(&tahu, UintEncoding::LongValue);
    eprintln!("{}", table.join("\n"));
    let wrong: Vec<&str> = table.iter().filter(|l| l.contains("WRONG")).map(String::as_str).collect();
    assert_eq!(wrong.len(), 2, "DataSet's Int64, Int16Array: {wrong:#?}");
}

#[test]
fn tahu_throws_on_a_data_set_with_an_int_value_column() {
    let Some(tahu) = tahu("tahu_throws_on_a_data_set_with_an_int_value_column") else { return };
    // An Int32 column, in int_value as every decoder reads it: Tahu 1.0.3 reads no data set
    // cell of Int8/16/32, UInt8/16 or UInt64 (not even one its own encoder wrote).
    let data_set = DataSet {
        num_of_columns: Some(1),
        columns: vec!["n".into()],
        types: vec![DataType::Int32.number()],
        rows: vec![DataSetRow { elements: vec![DataSetValue { value: Some(DataSetValueKind::Int(5)) }] }],
    };
    let metric = direct("dataset", DataType::DataSet, Some(MetricValue::DataSet(data_set)));
    let payload = Payload { timestamp: Some(NOW), seq: Some(1), metrics: vec![metric], ..Payload::default() };
    let refused = tahu.run("decode.js", &payload.encode()).expect_err("Tahu throws");
    assert!(refused.contains("Invalid DataSetValue"), "{refused}");
}

// ---------------------------------------------------------------------------------------------
// Tahu's commands, our decoder

/// A DCMD as a Tahu host sends one: one metric, by name, with its datatype.
fn tahu_dcmd(name: &str, tahu_type: &str, value: &Json) -> Json {
    json!({"timestamp": NOW.to_string(),
           "metrics": [{"name": name, "type": tahu_type, "value": value, "timestamp": NOW.to_string()}]})
}

/// The one metric of a DCMD.
fn only_metric(payload: &Payload) -> &Metric {
    assert_eq!(payload.metrics.len(), 1, "one metric in {payload:?}");
    payload.metrics.first().expect("one metric")
}

/// The raw value the DCMD's metric asks to write to `point`, checked as the edge node checks it.
fn command(point: &Point, metric: &Metric, typed: &str) -> Result<Value, String> {
    let value = metric.value.as_ref().ok_or("no value")?;
    let raw = convert::to_raw(point, value).map_err(|e| e.to_string())?;
    point.check_write(&raw, typed).map_err(|e| e.to_string())?;
    Ok(raw)
}

#[test]
fn a_tahu_uint32_dcmd_in_long_value_writes_f001() {
    let Some(tahu) = tahu("a_tahu_uint32_dcmd_in_long_value_writes_f001") else { return };
    let f001 = f001();
    assert_eq!(convert::datatype_of(&f001), DataType::Double, "F001 is born as its engineering value, in Hz");

    // 50 Hz as Ignition sends a UInt32: in long_value; an integer for a scaled point is Hz.
    let dcmd = tahu.encode(&tahu_dcmd("F001", "UInt32", &json!(50)));
    assert_eq!(dcmd.timestamp, Some(NOW));
    let metric = only_metric(&dcmd);
    assert_eq!((metric.name.as_deref(), metric.data_type()), (Some("F001"), Some(DataType::UInt32)));
    assert_eq!(metric.value, Some(MetricValue::Long(50)), "Tahu writes UInt32 in long_value");
    assert_eq!(command(&f001, metric, "50"), Ok(Value::Int(5000)));

    // The datatype F001 is born with.
    let dcmd = tahu.encode(&tahu_dcmd("F001", "Double", &json!(50.25)));
    assert_eq!(only_metric(&dcmd).value, Some(MetricValue::Double(50.25)));
    assert_eq!(command(&f001, only_metric(&dcmd), "50.25"), Ok(Value::Int(5025)));

    // Above 400.00 Hz: converted, then refused by the profile's range.
    let dcmd = tahu.encode(&tahu_dcmd("F001", "UInt32", &json!(401)));
    let refused = command(&f001, only_metric(&dcmd), "401").expect_err("F001 stops at 400.00 Hz");
    assert!(refused.contains("401"), "{refused}");

    // F001 as raw counts, unscaled: a UInt32 point, whose every value Tahu carries in long_value.
    let counts = Point { scale: 1.0, max: None, ..f001.clone() };
    assert_eq!(convert::datatype_of(&counts), DataType::UInt32);
    let dcmd = tahu.encode(&tahu_dcmd("F001", "UInt32", &json!(4_000_000_000u32)));
    assert_eq!(only_metric(&dcmd).value, Some(MetricValue::Long(4_000_000_000)));
    assert_eq!(command(&counts, only_metric(&dcmd), "4000000000"), Ok(Value::Int(4_000_000_000)));
}

#[test]
fn the_same_dcmd_in_int_value_writes_f001_too_which_tahu_reads_as_null() {
    let Some(tahu) = tahu("the_same_dcmd_in_int_value_writes_f001_too_which_tahu_reads_as_null") else { return };
    let f001 = f001();
    // As the specification puts UInt32 (Tahu's encoder cannot): int_value.
    let spec = Payload {
        timestamp: Some(NOW),
        metrics: vec![Metric {
            timestamp: Some(NOW),
            ..Metric::new("F001", DataType::UInt32, Some(MetricValue::Int(50)))
        }],
        ..Payload::default()
    };
    let ours = Payload::decode(&spec.encode()).expect("our own DCMD");
    assert_eq!(command(&f001, only_metric(&ours), "50"), Ok(Value::Int(5000)));
    let counts = Point { scale: 1.0, ..f001 };
    assert_eq!(command(&counts, only_metric(&ours), "50"), Ok(Value::Int(50)));

    let decoded = tahu.decode(&spec);
    let metric = find(&decoded, "F001");
    assert_eq!((&metric["type"], &metric["value"]), (&json!("UInt32"), &Json::Null), "Tahu: UInt32 in long_value only");
}

#[test]
fn tahu_sign_extends_int8_and_int16_commands_which_we_read() {
    let Some(tahu) = tahu("tahu_sign_extends_int8_and_int16_commands_which_we_read") else { return };
    let offset = point("b001", ValueType::I16, 1.0, None);
    let dcmd = tahu.encode(&tahu_dcmd("b001", "Int16", &json!(-5)));
    assert_eq!(only_metric(&dcmd).value, Some(MetricValue::Int(u32::MAX - 4)), "-5 sign-extended to 32 bits");
    assert_eq!(command(&offset, only_metric(&dcmd), "-5"), Ok(Value::Int(-5)));

    let dcmd = tahu.encode(&tahu_dcmd("b002", "Int64", &json!("-9000000000")));
    assert_eq!(only_metric(&dcmd).value, Some(MetricValue::Long((-9_000_000_000i64).cast_unsigned())));
    let wide = point("b002", ValueType::I64, 1.0, None);
    assert_eq!(command(&wide, only_metric(&dcmd), "-9000000000"), Ok(Value::Int(-9_000_000_000)));

    let dcmd = tahu.encode(&tahu_dcmd("C001", "Boolean", &json!(true)));
    let run = point("C001", ValueType::Bit, 1.0, None);
    assert_eq!(command(&run, only_metric(&dcmd), "true"), Ok(Value::Bool(true)));
}

// ---------------------------------------------------------------------------------------------
// Historical DDATA and NDEATH

#[test]
fn tahu_reads_a_historical_ddata_of_aliases_without_values() {
    let Some(tahu) = tahu("tahu_reads_a_historical_ddata_of_aliases_without_values") else { return };
    let sampled = NOW - 60_000;
    let historical = |alias, value| Metric {
        alias: Some(alias),
        timestamp: Some(sampled),
        is_historical: Some(true),
        value: Some(value),
        ..Metric::default()
    };
    let ddata = Payload {
        timestamp: Some(NOW),
        seq: Some(7),
        metrics: vec![historical(1, MetricValue::Int(5000)), historical(11, MetricValue::Double(50.0))],
        ..Payload::default()
    };
    let decoded = tahu.decode(&ddata);
    assert_eq!((&decoded["timestamp"], &decoded["seq"]), (&json!(NOW.to_string()), &json!("7")));
    let metrics = decoded["metrics"].as_array().expect("metrics");
    assert_eq!(metrics.len(), 2);
    for (metric, alias) in metrics.iter().zip(["1", "11"]) {
        assert_eq!(metric["alias"], alias);
        assert_eq!(metric["isHistorical"], true, "alias {alias}");
        assert_eq!(metric["timestamp"], json!(sampled.to_string()), "the sample's own time, alias {alias}");
        assert_eq!(metric.get("name"), None, "alias only");
        // Without the DBIRTH's datatype a stateless decoder cannot read the value.
        assert_eq!((&metric["type"], &metric["value"]), (&Json::Null, &Json::Null), "alias {alias}");
    }
}

#[test]
fn tahu_reads_an_ndeath_of_bdseq_only_without_seq() {
    let Some(tahu) = tahu("tahu_reads_an_ndeath_of_bdseq_only_without_seq") else { return };
    let ndeath = Payload {
        timestamp: Some(NOW),
        metrics: vec![Metric::new("bdSeq", DataType::UInt64, Some(MetricValue::Long(3)))],
        ..Payload::default()
    };
    let decoded = tahu.decode(&ndeath);
    assert_eq!(decoded.get("seq"), None, "an NDEATH has no seq");
    assert_eq!(decoded["timestamp"], json!(NOW.to_string()));
    let metrics = decoded["metrics"].as_array().expect("metrics");
    assert_eq!(metrics, &[json!({"name": "bdSeq", "type": "UInt64", "value": "3"})]);
}
