//! The Sparkplug B payloads of `ferrobus_bridge::sparkplug`, read by decoders the team did not
//! write: pysparkplug 0.6.1 (through `tests/peers/sparkplug/decode.py`, which prints what it
//! decoded as JSON) and Google's `protoc --decode_raw` (the raw field numbers and wire values,
//! no schema at all); and payloads pysparkplug encodes, read by ours.
//!
//! The peers: `protoc` on PATH (protobuf-compiler) and pysparkplug in
//! `target/peers/sparkplug-venv` (both installed by `.ci/setup-peers.sh`). Under `CI=true` a
//! missing peer fails the test; elsewhere the test passes with a `SKIPPED` line on stderr.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use ferrobus_bridge::sparkplug::convert::{self, UintEncoding};
use ferrobus_bridge::sparkplug::payload::{
    DataSet, DataSetRow, DataSetValue, DataSetValueKind, DataType, MetaData, Metric, MetricValue, ParameterValue,
    Payload, PropertySet, PropertyValue, PropertyValueKind, Template, TemplateParameter,
};
use ferrobus_profile::{Access, Order, Point, Table, Value, ValueType};
use serde_json::{Value as Json, json};

const NOW: u64 = 1_700_000_000_000;

// ---------------------------------------------------------------------------------------------
// The peers

/// The repository root.
fn root() -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    root.canonicalize().unwrap_or(root)
}

fn in_ci() -> bool {
    matches!(std::env::var("CI").as_deref(), Ok("true" | "TRUE" | "True" | "1" | "yes"))
}

fn on_path(program: &str) -> bool {
    std::env::var_os("PATH").is_some_and(|paths| std::env::split_paths(&paths).any(|dir| dir.join(program).is_file()))
}

struct Peers {
    python: PathBuf,
    script: PathBuf,
}

/// The peers, or None (after a `SKIPPED` line) when one is missing outside CI.
///
/// # Panics
/// Under `CI=true`, when one is missing.
fn peers(test: &str) -> Option<Peers> {
    let python = root().join("target/peers/sparkplug-venv/bin/python");
    let script = root().join("tests/peers/sparkplug/decode.py");
    let mut missing = Vec::new();
    if !on_path("protoc") {
        missing.push("protoc (apt install protobuf-compiler)".to_owned());
    }
    if !python.is_file() {
        missing.push(format!("{} (pysparkplug 0.6.1: .ci/setup-peers.sh)", python.display()));
    }
    if !script.is_file() {
        missing.push(script.display().to_string());
    }
    if missing.is_empty() {
        return Some(Peers { python, script });
    }
    let what = missing.join(", ");
    assert!(!in_ci(), "{test}: missing {what} (CI=true: a missing peer is a failure)");
    // Past the harness's capture, so that a skip shows with the passing tests.
    let _ = writeln!(std::io::stderr(), "\nSKIPPED {test}: missing {what}\n");
    None
}

/// A payload in a file of its own, for decode.py.
struct PayloadFile(PathBuf);

impl PayloadFile {
    fn new(name: &str, bytes: &[u8]) -> PayloadFile {
        let path = std::env::temp_dir().join(format!("ferrobus-spb-{}-{name}.bin", std::process::id()));
        std::fs::write(&path, bytes).expect("write the payload");
        PayloadFile(path)
    }
}

impl Drop for PayloadFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

fn run(command: &mut Command, stdin: &[u8]) -> Output {
    let mut child = command
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("start {command:?}: {e}"));
    child.stdin.take().expect("stdin").write_all(stdin).expect("write stdin");
    child.wait_with_output().expect("wait")
}

impl Peers {
    /// What pysparkplug decoded, as decode.py prints it.
    fn pysparkplug(&self, kind: &str, payload: &[u8], birth: Option<&[u8]>) -> Json {
        let file = PayloadFile::new(&format!("{kind}-{}", payload.len()), payload);
        let born = birth.map(|b| PayloadFile::new(&format!("{kind}-birth-{}", payload.len()), b));
        let mut command = Command::new(&self.python);
        command.arg(&self.script).arg(kind).arg(&file.0);
        if let Some(born) = &born {
            command.arg("--birth").arg(&born.0);
        }
        let out = run(&mut command, b"");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "pysparkplug refused the {kind}: {stderr}");
        serde_json::from_slice(&out.stdout).unwrap_or_else(|e| panic!("decode.py printed no JSON ({e}): {stderr}"))
    }

    /// The python of the venv running `script` (pysparkplug importable); its stdout.
    fn python(&self, script: &str) -> Vec<u8> {
        let out = run(Command::new(&self.python).arg("-c").arg(script), b"");
        assert!(out.status.success(), "python: {}", String::from_utf8_lossy(&out.stderr));
        out.stdout
    }
}

// ---------------------------------------------------------------------------------------------
// protoc --decode_raw

/// One field of `protoc --decode_raw`'s output: a scalar as printed, or a nested message.
#[derive(Debug)]
enum Raw {
    Scalar(String),
    Message(Vec<(u32, Raw)>),
}

fn decode_raw(payload: &[u8]) -> Vec<(u32, Raw)> {
    let out = run(Command::new("protoc").arg("--decode_raw"), payload);
    assert!(out.status.success(), "protoc --decode_raw: {}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).expect("protoc prints text");
    let mut stack: Vec<(u32, Vec<(u32, Raw)>)> = vec![(0, Vec::new())];
    for line in text.lines().map(str::trim).filter(|l| !l.is_empty()) {
        if line == "}" {
            let (number, fields) = stack.pop().expect("balanced braces");
            stack.last_mut().expect("an enclosing message").1.push((number, Raw::Message(fields)));
        } else if let Some(number) = line.strip_suffix(" {") {
            stack.push((number.parse().expect("a field number"), Vec::new()));
        } else {
            let (number, value) = line.split_once(": ").expect("N: value");
            let scalar = Raw::Scalar(value.to_owned());
            stack.last_mut().expect("a message").1.push((number.parse().expect("a field number"), scalar));
        }
    }
    assert_eq!(stack.len(), 1, "balanced braces in {text}");
    stack.pop().map(|(_, fields)| fields).unwrap_or_default()
}

/// The scalars of field `number`, as protoc prints them.
fn scalars(message: &[(u32, Raw)], number: u32) -> Vec<&str> {
    message
        .iter()
        .filter(|(n, _)| *n == number)
        .filter_map(|(_, raw)| match raw {
            Raw::Scalar(s) => Some(s.as_str()),
            Raw::Message(_) => None,
        })
        .collect()
}

fn scalar(message: &[(u32, Raw)], number: u32) -> Option<&str> {
    scalars(message, number).first().copied()
}

/// The nested messages of field `number`.
fn messages(message: &[(u32, Raw)], number: u32) -> Vec<&[(u32, Raw)]> {
    message
        .iter()
        .filter(|(n, _)| *n == number)
        .filter_map(|(_, raw)| match raw {
            Raw::Message(m) => Some(m.as_slice()),
            Raw::Scalar(_) => None,
        })
        .collect()
}

fn numbers(message: &[(u32, Raw)]) -> Vec<u32> {
    message.iter().map(|(n, _)| *n).collect()
}

// ---------------------------------------------------------------------------------------------
// The payloads

fn point(code: &str, value_type: ValueType, scale: f64, unit: Option<&str>) -> Point {
    Point {
        table: if value_type == ValueType::Bit { Table::Coils } else { Table::Holding },
        address: 0,
        number: 1,
        code: code.into(),
        label: String::new(),
        description: String::new(),
        value_type,
        order: Order::Abcd,
        width: if value_type == ValueType::String { 4 } else { value_type.registers() },
        unit: unit.map(str::to_owned),
        scale,
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

/// A DBIRTH metric and what pysparkplug must read: its datatype's name and its value.
struct Case {
    metric: Metric,
    datatype: &'static str,
    value: Json,
}

fn born(name: &str, datatype: DataType, value: MetricValue) -> Metric {
    Metric { timestamp: Some(NOW), ..Metric::new(name, datatype, Some(value)) }
}

fn le<T, const N: usize>(values: &[T], bytes: impl Fn(&T) -> [u8; N]) -> MetricValue {
    MetricValue::Bytes(values.iter().flat_map(bytes).collect())
}

/// The profile's points, one of each value type, with a raw value each.
fn points() -> Vec<(Point, Value, &'static str, Json)> {
    vec![
        (point("F001", ValueType::U16, 1.0, None), Value::Int(5000), "UINT16", json!(5000)),
        (point("F002", ValueType::I16, 1.0, None), Value::Int(-5), "INT16", json!(-5)),
        (point("F003", ValueType::U32, 1.0, None), Value::Int(19200), "UINT32", json!(19200)),
        (point("F004", ValueType::I32, 1.0, None), Value::Int(-70000), "INT32", json!(-70000)),
        (point("F005", ValueType::U64, 1.0, None), Value::Int(1 << 40), "UINT64", json!(1u64 << 40)),
        (point("F006", ValueType::I64, 1.0, None), Value::Int(-(1 << 40)), "INT64", json!(-(1i64 << 40))),
        (point("F007", ValueType::F32, 1.0, None), Value::Float(1.5), "FLOAT", json!(1.5)),
        (point("F008", ValueType::F64, 1.0, None), Value::Float(-2.25), "DOUBLE", json!(-2.25)),
        (point("F009", ValueType::String, 1.0, None), Value::Text("3G3RX".into()), "STRING", json!("3G3RX")),
        (point("C001", ValueType::Bit, 1.0, None), Value::Bool(true), "BOOLEAN", json!(true)),
        // "rpm", not "Hz": protoc --decode_raw shows a string that parses as a message as one,
        // and "Hz" does (0x48 is field 9 as a varint, 'z' its value).
        (point("F010", ValueType::U16, 0.01, Some("rpm")), Value::Int(5000), "DOUBLE", json!(50.0)),
    ]
}

/// A DBIRTH with a metric of every datatype pysparkplug knows: the profile's points (through
/// `convert`) and the other types of the specification, written directly.
fn dbirth_cases(encoding: UintEncoding) -> Vec<Case> {
    let mut cases: Vec<Case> = points()
        .into_iter()
        .map(|(point, raw, datatype, value)| {
            let metric_value = convert::metric_value(&point, &raw, encoding).expect("a value of the point's type");
            let metric = Metric {
                properties: convert::properties_of(&point),
                ..born(&point.code, convert::datatype_of(&point), metric_value)
            };
            Case { metric, datatype, value }
        })
        .collect();
    let direct = [
        (DataType::Int8, MetricValue::Int(156), "INT8", json!(-100)),
        (DataType::UInt8, MetricValue::Int(200), "UINT8", json!(200)),
        (DataType::DateTime, MetricValue::Long(NOW + 123), "DATETIME", json!(NOW + 123)),
        (DataType::Text, MetricValue::String("free text".into()), "TEXT", json!("free text")),
        (
            DataType::Uuid,
            MetricValue::String("0b8e1c3a-5d2f-4e6a-9b7c-1d2e3f405162".into()),
            "UUID",
            json!("0b8e1c3a-5d2f-4e6a-9b7c-1d2e3f405162"),
        ),
        (DataType::Bytes, MetricValue::Bytes(vec![1, 2, 0xff]), "BYTES", json!("0102ff")),
        (DataType::File, MetricValue::Bytes(b"hi\n".to_vec()), "FILE", json!("68690a")),
        (DataType::Int8Array, le(&[-1i8, 2], |v| v.to_le_bytes()), "INT8_ARRAY", json!([-1, 2])),
        (DataType::Int16Array, le(&[-2i16, 300], |v| v.to_le_bytes()), "INT16_ARRAY", json!([-2, 300])),
        (DataType::Int32Array, le(&[-3i32, 70000], |v| v.to_le_bytes()), "INT32_ARRAY", json!([-3, 70000])),
        (DataType::Int64Array, le(&[-4i64, 1 << 40], |v| v.to_le_bytes()), "INT64_ARRAY", json!([-4, 1i64 << 40])),
        (DataType::UInt8Array, le(&[255u8, 1], |v| v.to_le_bytes()), "UINT8_ARRAY", json!([255, 1])),
        (DataType::UInt16Array, le(&[65535u16, 2], |v| v.to_le_bytes()), "UINT16_ARRAY", json!([65535, 2])),
        (DataType::UInt32Array, le(&[u32::MAX, 3], |v| v.to_le_bytes()), "UINT32_ARRAY", json!([u32::MAX, 3])),
        (DataType::UInt64Array, le(&[u64::MAX, 4], |v| v.to_le_bytes()), "UINT64_ARRAY", json!([u64::MAX, 4])),
        (DataType::FloatArray, le(&[1.5f32, -0.25], |v| v.to_le_bytes()), "FLOAT_ARRAY", json!([1.5, -0.25])),
        (DataType::DoubleArray, le(&[2.5f64, -8.0], |v| v.to_le_bytes()), "DOUBLE_ARRAY", json!([2.5, -8.0])),
        // A count (u32, little-endian), then the bits, the first the highest of its byte.
        (
            DataType::BooleanArray,
            MetricValue::Bytes(vec![3, 0, 0, 0, 0b1010_0000]),
            "BOOLEAN_ARRAY",
            json!([true, false, true]),
        ),
        (DataType::StringArray, MetricValue::Bytes(b"a\0bc\0".to_vec()), "STRING_ARRAY", json!(["a", "bc"])),
        (DataType::DateTimeArray, le(&[NOW, NOW + 1], |v| v.to_le_bytes()), "DATETIME_ARRAY", json!([NOW, NOW + 1])),
    ];
    for (i, (datatype, value, name, json)) in direct.into_iter().enumerate() {
        let mut metric = born(&format!("X{i:02}"), datatype, value);
        if datatype == DataType::File {
            metric.metadata = Some(MetaData { file_name: Some("hi.txt".into()), ..MetaData::default() });
        }
        cases.push(Case { metric, datatype: name, value: json });
    }
    let null = Metric { timestamp: Some(NOW), ..Metric::new("F099", DataType::UInt16, None) };
    cases.push(Case { metric: null, datatype: "UINT16", value: Json::Null });
    for (alias, case) in (1u64..).zip(cases.iter_mut()) {
        case.metric.alias = Some(alias);
    }
    cases
}

fn dbirth(cases: &[Case]) -> Payload {
    Payload {
        timestamp: Some(NOW),
        seq: Some(1),
        metrics: cases.iter().map(|c| c.metric.clone()).collect(),
        ..Payload::default()
    }
}

fn nbirth(bd_seq: u64) -> Payload {
    let metrics = vec![
        Metric { alias: Some(0), ..born("bdSeq", DataType::UInt64, MetricValue::Long(bd_seq)) },
        born("Node Control/Rebirth", DataType::Boolean, MetricValue::Boolean(false)),
    ];
    Payload { timestamp: Some(NOW), seq: Some(0), metrics, ..Payload::default() }
}

fn find<'a>(decoded: &'a Json, name: &str) -> &'a Json {
    decoded["metrics"]
        .as_array()
        .and_then(|metrics| metrics.iter().find(|m| m["name"] == name))
        .unwrap_or_else(|| panic!("no metric {name} in {decoded}"))
}

// ---------------------------------------------------------------------------------------------
// Our payloads, their decoders

#[test]
fn an_nbirth_reads_in_pysparkplug_and_protoc() {
    let Some(peers) = peers("an_nbirth_reads_in_pysparkplug_and_protoc") else { return };
    let bytes = nbirth(3).encode();
    let decoded = peers.pysparkplug("NBIRTH", &bytes, None);
    assert_eq!(decoded["type"], "NBIRTH");
    assert_eq!(decoded["seq"], 0);
    assert_eq!(decoded["timestamp"], NOW);
    let bd_seq = find(&decoded, "bdSeq");
    assert_eq!((bd_seq["datatype"].as_str(), &bd_seq["value"]), (Some("UINT64"), &json!(3)));
    let rebirth = find(&decoded, "Node Control/Rebirth");
    assert_eq!((rebirth["datatype"].as_str(), &rebirth["value"]), (Some("BOOLEAN"), &json!(false)));

    let raw = decode_raw(&bytes);
    assert_eq!(numbers(&raw), [1, 2, 2, 3], "timestamp, two metrics, seq");
    assert_eq!(scalar(&raw, 1), Some("1700000000000"));
    assert_eq!(scalar(&raw, 3), Some("0"), "seq 0 is on the wire");
    let metrics = messages(&raw, 2);
    let first = metrics.first().expect("bdSeq");
    assert_eq!(scalar(first, 1), Some("\"bdSeq\""));
    assert_eq!(scalar(first, 2), Some("0"), "alias");
    assert_eq!(scalar(first, 4), Some("8"), "datatype UInt64");
    assert_eq!(scalar(first, 11), Some("3"), "long_value");
    let second = metrics.get(1).expect("Rebirth");
    assert_eq!(scalar(second, 4), Some("11"), "datatype Boolean");
    assert_eq!(scalar(second, 14), Some("0"), "boolean_value false is on the wire");
}

#[test]
fn a_dbirth_of_every_datatype_reads_in_pysparkplug() {
    let Some(peers) = peers("a_dbirth_of_every_datatype_reads_in_pysparkplug") else { return };
    for encoding in [UintEncoding::Spec, UintEncoding::LongValue] {
        let cases = dbirth_cases(encoding);
        let decoded = peers.pysparkplug("DBIRTH", &dbirth(&cases).encode(), None);
        assert_eq!(decoded["seq"], 1);
        let metrics = decoded["metrics"].as_array().expect("metrics");
        assert_eq!(metrics.len(), cases.len());
        for (case, metric) in cases.iter().zip(metrics) {
            let name = case.metric.name.as_deref().unwrap_or_default();
            assert_eq!(metric["name"], name);
            assert_eq!(metric["alias"], json!(case.metric.alias), "{name}");
            assert_eq!(metric["datatype"], case.datatype, "{name} ({encoding:?})");
            assert_eq!(metric["value"], case.value, "{name} ({encoding:?})");
            assert_eq!(metric["timestamp"], NOW, "{name}");
            assert_eq!(metric["is_null"], case.value.is_null(), "{name}");
            assert_eq!(metric["is_historical"], false, "{name}");
        }
        let scaled = find(&decoded, "F010");
        assert_eq!(
            scaled["properties"],
            json!({"engUnit": {"type": 12, "field": "string_value", "is_null": false, "value": "rpm"}})
        );
        assert_eq!(find(&decoded, "F001")["properties"], Json::Null, "no unit, no properties");
    }
}

#[test]
fn a_dbirth_puts_each_value_in_its_field() {
    let Some(_peers) = peers("a_dbirth_puts_each_value_in_its_field") else { return };
    // (metric, datatype number, the field its value is in, the value as protoc prints it)
    let expect = [
        ("F001", 6, 10, "5000"),
        ("F002", 2, 10, "65531"),
        ("F003", 7, 10, "19200"),
        ("F004", 3, 10, "4294897296"),
        ("F005", 8, 11, "1099511627776"),
        ("F006", 4, 11, "18446742974197923840"),
        ("F007", 9, 12, "0x3fc00000"),
        ("F008", 10, 13, "0xc002000000000000"),
        ("F009", 12, 15, "\"3G3RX\""),
        ("C001", 11, 14, "1"),
        ("F010", 10, 13, "0x4049000000000000"),
    ];
    for encoding in [UintEncoding::Spec, UintEncoding::LongValue] {
        let cases = dbirth_cases(encoding);
        let raw = decode_raw(&dbirth(&cases).encode());
        assert_eq!(scalar(&raw, 3), Some("1"), "seq");
        let metrics = messages(&raw, 2);
        assert_eq!(metrics.len(), cases.len());
        for (name, datatype, field, value) in expect {
            let metric = metrics
                .iter()
                .find(|m| scalar(m, 1) == Some(&format!("\"{name}\"")))
                .unwrap_or_else(|| panic!("{name} on the wire"));
            assert_eq!(scalar(metric, 4), Some(datatype.to_string().as_str()), "{name}'s datatype");
            let unsigned_small = matches!(datatype, 6 | 7);
            let field = if unsigned_small && encoding == UintEncoding::LongValue { 11 } else { field };
            assert_eq!(scalar(metric, field), Some(value), "{name} ({encoding:?}) in field {field}: {metric:?}");
            assert_eq!(scalar(metric, 3), Some("1700000000000"), "{name}'s timestamp");
        }
        let scaled = metrics.iter().find(|m| scalar(m, 1) == Some("\"F010\"")).expect("F010");
        let properties = messages(scaled, 9);
        let properties = properties.first().expect("properties are field 9");
        assert_eq!(scalars(properties, 1), ["\"engUnit\""], "keys are field 1");
        let value = messages(properties, 2);
        let value = value.first().expect("values are field 2");
        assert_eq!((scalar(value, 1), scalar(value, 8)), (Some("12"), Some("\"rpm\"")), "type String, string_value");
        let null = metrics.iter().find(|m| scalar(m, 1) == Some("\"F099\"")).expect("F099");
        assert_eq!(scalar(null, 7), Some("1"), "is_null is field 7");
        assert!(numbers(null).iter().all(|n| *n < 10), "a null metric has no value field: {null:?}");
        let file = metrics.iter().find(|m| scalar(m, 4) == Some("18")).expect("the File metric");
        let metadata = messages(file, 8);
        assert_eq!(metadata.first().and_then(|m| scalar(m, 5)), Some("\"hi.txt\""), "metadata field 8, file_name 5");
    }
}

#[test]
fn a_ddata_of_aliases_only_reads_with_its_birth() {
    let Some(peers) = peers("a_ddata_of_aliases_only_reads_with_its_birth") else { return };
    let cases = dbirth_cases(UintEncoding::Spec);
    let birth = dbirth(&cases).encode();
    let (hz, raw_hz) = points().into_iter().find(|(p, ..)| p.code == "F010").map(|(p, r, ..)| (p, r)).expect("F010");
    let (i16, _) = points().into_iter().find(|(p, ..)| p.code == "F002").map(|(p, r, ..)| (p, r)).expect("F002");
    let alias = |code: &str| cases.iter().find(|c| c.metric.name.as_deref() == Some(code)).and_then(|c| c.metric.alias);
    let changed = |code: &str, point: &Point, raw: Value, at: u64| Metric {
        alias: alias(code),
        timestamp: Some(at),
        is_historical: Some(true),
        value: convert::metric_value(point, &raw, UintEncoding::Spec),
        ..Metric::default()
    };
    assert_eq!(raw_hz, Value::Int(5000));
    let ddata = Payload {
        timestamp: Some(NOW + 5000),
        seq: Some(2),
        metrics: vec![
            changed("F010", &hz, Value::Int(4990), NOW + 1000),
            changed("F002", &i16, Value::Int(-32768), NOW + 2000),
        ],
        ..Payload::default()
    }
    .encode();

    let decoded = peers.pysparkplug("DDATA", &ddata, Some(&birth));
    assert_eq!(decoded["seq"], 2);
    let hz = find(&decoded, "F010");
    assert_eq!((&hz["value"], &hz["datatype"], &hz["alias"]), (&json!(49.9), &json!("DOUBLE"), &json!(alias("F010"))));
    assert_eq!((&hz["is_historical"], &hz["timestamp"]), (&json!(true), &json!(NOW + 1000)));
    let i16 = find(&decoded, "F002");
    assert_eq!(
        (&i16["value"], &i16["datatype"], &i16["is_historical"]),
        (&json!(-32768), &json!("INT16"), &json!(true))
    );

    let raw = decode_raw(&ddata);
    for metric in messages(&raw, 2) {
        let fields = numbers(metric);
        assert!(!fields.contains(&1) && !fields.contains(&4), "no name, no datatype in DDATA: {metric:?}");
        assert_eq!(scalar(metric, 5), Some("1"), "is_historical is field 5");
    }
    assert_eq!(scalars(messages(&raw, 2).get(1).copied().unwrap_or_default(), 10), ["32768"], "Int16 -32768");
}

#[test]
fn an_ndeath_carries_only_bdseq() {
    let Some(peers) = peers("an_ndeath_carries_only_bdseq") else { return };
    let ndeath = Payload {
        timestamp: Some(NOW),
        metrics: vec![born("bdSeq", DataType::UInt64, MetricValue::Long(255))],
        ..Payload::default()
    }
    .encode();
    let decoded = peers.pysparkplug("NDEATH", &ndeath, None);
    let bd_seq = find(&decoded, "bdSeq");
    assert_eq!((&bd_seq["value"], &bd_seq["datatype"]), (&json!(255), &json!("UINT64")));
    assert_eq!(decoded["seq"], Json::Null);
    let raw = decode_raw(&ndeath);
    assert_eq!(numbers(&raw), [1, 2], "a timestamp and the bdSeq metric, no seq (field 3)");
    let metric = messages(&raw, 2);
    let metric = metric.first().expect("bdSeq");
    assert_eq!((scalar(metric, 4), scalar(metric, 11)), (Some("8"), Some("255")));
}

#[test]
fn data_sets_and_templates_read_in_protoc() {
    // pysparkplug 0.6.1 decodes neither (its DataType says "Unsupported"); protoc shows the fields.
    let Some(_peers) = peers("data_sets_and_templates_read_in_protoc") else { return };
    let set = DataSet {
        num_of_columns: Some(2),
        columns: vec!["speed".into(), "ok".into()],
        types: vec![DataType::UInt16.number(), DataType::Boolean.number()],
        rows: vec![DataSetRow {
            elements: vec![
                DataSetValue { value: Some(DataSetValueKind::Int(1500)) },
                DataSetValue { value: Some(DataSetValueKind::Boolean(true)) },
            ],
        }],
    };
    let template = Template {
        version: Some("v1".into()),
        metrics: vec![born("speed", DataType::Float, MetricValue::Float(0.5))],
        parameters: vec![TemplateParameter {
            name: Some("max".into()),
            r#type: Some(DataType::Int32.number()),
            value: Some(ParameterValue::Int(10)),
        }],
        template_ref: Some("Drive".into()),
        is_definition: Some(false),
    };
    let nested = PropertySet {
        keys: vec!["Quality".into()],
        values: vec![PropertyValue {
            r#type: Some(DataType::Int32.number()),
            is_null: None,
            value: Some(PropertyValueKind::Int(192)),
        }],
    };
    let properties = PropertySet {
        keys: vec!["nested".into()],
        values: vec![PropertyValue {
            r#type: Some(DataType::PropertySet.number()),
            is_null: None,
            value: Some(PropertyValueKind::PropertySet(nested)),
        }],
    };
    let payload = Payload {
        timestamp: Some(NOW),
        seq: Some(7),
        metrics: vec![
            Metric { properties: Some(properties), ..born("table", DataType::DataSet, MetricValue::DataSet(set)) },
            born("drive", DataType::Template, MetricValue::Template(template)),
        ],
        ..Payload::default()
    };
    let bytes = payload.encode();
    assert_eq!(Payload::decode(&bytes), Ok(payload));
    let raw = decode_raw(&bytes);
    let metrics = messages(&raw, 2);
    let table = metrics.first().expect("the data set");
    let set = messages(table, 17);
    let set = set.first().expect("dataset_value is field 17");
    assert_eq!(scalar(set, 1), Some("2"), "num_of_columns");
    assert_eq!(scalars(set, 2), ["\"speed\"", "\"ok\""], "columns");
    assert_eq!(scalars(set, 3), ["6", "11"], "types, one field each (unpacked)");
    let row = messages(set, 4);
    let elements = row.first().map(|r| messages(r, 1)).unwrap_or_default();
    assert_eq!(elements.iter().map(|e| scalar(e, 1).or(scalar(e, 5))).collect::<Vec<_>>(), [Some("1500"), Some("1")]);
    let nested = messages(table, 9).first().map(|p| messages(p, 2)).unwrap_or_default();
    let quality = nested.first().map(|v| messages(v, 9)).unwrap_or_default();
    assert_eq!(quality.first().and_then(|q| messages(q, 2).first().and_then(|v| scalar(v, 3))), Some("192"));
    let drive = metrics.get(1).expect("the template");
    let template = messages(drive, 18);
    let template = template.first().expect("template_value is field 18");
    assert_eq!(
        (scalar(template, 1), scalar(template, 4), scalar(template, 5)),
        (Some("\"v1\""), Some("\"Drive\""), Some("0"))
    );
    let parameter = messages(template, 3);
    let parameter = parameter.first().expect("parameters are field 3");
    assert_eq!(
        (scalar(parameter, 1), scalar(parameter, 2), scalar(parameter, 3)),
        (Some("\"max\""), Some("3"), Some("10"))
    );
    assert_eq!(messages(template, 2).first().and_then(|m| scalar(m, 12)), Some("0x3f000000"), "member float 0.5");
}

// ---------------------------------------------------------------------------------------------
// pysparkplug's payloads, our decoder

const PYSPARKPLUG_ENCODES: &str = r#"
import sys
import pysparkplug as p
D = p.DataType
T = 1700000000000
values = [("F001", D.UINT16, 5000), ("F002", D.INT16, -5), ("F003", D.UINT32, 19200),
          ("F004", D.INT32, -70000), ("F005", D.UINT64, 1 << 40), ("F006", D.INT64, -(1 << 40)),
          ("F007", D.FLOAT, 1.5), ("F008", D.DOUBLE, -2.25), ("F009", D.STRING, "3G3RX"),
          ("C001", D.BOOLEAN, True), ("X01", D.INT8, -100), ("X02", D.BYTES, b"\x01\x02")]
birth = p.DBirth(timestamp=T, seq=1, metrics=tuple(
    p.Metric(timestamp=T, name=n, datatype=d, value=v, alias=i + 1) for i, (n, d, v) in enumerate(values)))
data = p.DData(timestamp=T + 1, seq=2, metrics=(
    p.Metric(timestamp=T + 1, name=None, alias=2, datatype=D.INT16, value=-7, is_historical=True),))
death = p.NDeath(timestamp=T, bd_seq_metric=p.Metric(timestamp=T, name="bdSeq", datatype=D.UINT64, value=4))
for message in (birth, data, death):
    raw = message.encode()
    sys.stdout.write(raw.hex() + "\n")
"#;

fn hex(text: &str) -> Vec<u8> {
    (0..text.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(text.get(i..i + 2).expect("two digits"), 16).expect("hex"))
        .collect()
}

#[test]
fn payloads_pysparkplug_encodes_decode_with_ours() {
    let Some(peers) = peers("payloads_pysparkplug_encodes_decode_with_ours") else { return };
    let out = String::from_utf8(peers.python(PYSPARKPLUG_ENCODES)).expect("hex lines");
    let payloads: Vec<Payload> =
        out.lines().map(|line| Payload::decode(&hex(line)).expect("pysparkplug's payload decodes")).collect();
    let [birth, data, death] = payloads.as_slice() else { panic!("three payloads, got {out}") };

    assert_eq!((birth.timestamp, birth.seq), (Some(NOW), Some(1)));
    for (point, raw, ..) in points().into_iter().filter(|(p, ..)| p.code != "F010") {
        let metric = birth.metrics.iter().find(|m| m.name.as_deref() == Some(&point.code)).expect("the point's metric");
        assert_eq!(metric.data_type(), Some(convert::datatype_of(&point)), "{}", point.code);
        let value = metric.value.as_ref().expect("a value");
        assert_eq!(convert::to_raw(&point, value), Ok(raw), "{}: {value:?}", point.code);
    }
    let int8 = birth.metrics.iter().find(|m| m.name.as_deref() == Some("X01")).expect("X01");
    assert_eq!((int8.data_type(), &int8.value), (Some(DataType::Int8), &Some(MetricValue::Int(156))));
    let bytes = birth.metrics.iter().find(|m| m.name.as_deref() == Some("X02")).expect("X02");
    assert_eq!(bytes.value, Some(MetricValue::Bytes(vec![1, 2])));

    let [changed] = data.metrics.as_slice() else { panic!("one metric in {data:?}") };
    assert_eq!((changed.name.as_deref(), changed.alias, changed.datatype), (None, Some(2), None));
    assert_eq!(changed.is_historical, Some(true));
    let i16 = point("F002", ValueType::I16, 1.0, None);
    assert_eq!(convert::to_raw(&i16, changed.value.as_ref().expect("a value")), Ok(Value::Int(-7)));

    assert_eq!(death.seq, None, "NDEATH has no seq");
    let bd_seq = death.metrics.first().expect("bdSeq");
    assert_eq!((bd_seq.name.as_deref(), &bd_seq.value), (Some("bdSeq"), &Some(MetricValue::Long(4))));
}

#[test]
fn decode_py_reads_stdin_and_says_what_pysparkplug_refused() {
    let Some(peers) = peers("decode_py_reads_stdin_and_says_what_pysparkplug_refused") else { return };
    let bytes = nbirth(9).encode();
    let out = run(Command::new(&peers.python).arg(&peers.script).arg("NBIRTH").arg("-"), &bytes);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let decoded: Json = serde_json::from_slice(&out.stdout).expect("JSON");
    assert_eq!(find(&decoded, "bdSeq")["value"], 9);
    // An Int16 sign-extended to 32 bits: Tahu would read it, pysparkplug refuses it (why we
    // write two's complement of the type's own width).
    let extended = Payload {
        timestamp: Some(NOW),
        seq: Some(1),
        metrics: vec![born("F002", DataType::Int16, MetricValue::Int(u32::MAX - 4))],
        ..Payload::default()
    };
    let out = run(Command::new(&peers.python).arg(&peers.script).arg("DBIRTH"), &extended.encode());
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.starts_with("error: OverflowError"), "{stderr}");
}
