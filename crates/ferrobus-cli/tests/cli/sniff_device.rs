//! `sniff --device omron-3g3rx:1` on the tap of a `ferrobus line` while `ferrobus set` and
//! `ferrobus get` are the bus's master for a simulated 3G3RX: the values the sniffer shows (as
//! its table, as CSV and as JSON lines) are what `get` read, point for point, and the write is
//! heard too.

use std::collections::HashMap;
use std::process::Stdio;

use assert_cmd::assert::OutputAssertExt;
use serde_json::Value;

use crate::server::{ferrobus, stderr};
use crate::sniff::{bus_of, lines, sniff, wait_for};

/// Points of each kind: a u32 high word first (F001, d001), scaled (F002), plain (A004), an
/// enumeration (d003). A004 has the highest address: `get` reads it last.
const POINTS: [&str; 5] = ["F001", "d001", "d003", "F002", "A004"];

/// Per point code: its value as shown, engineering value, raw value and unit.
type Read = HashMap<String, (String, f64, i64, String)>;

/// A point of a JSON document by the names of its fields: code, value as shown, number, unit.
fn point(p: &Value, [code, shown, number, unit]: [&str; 4]) -> (String, (String, f64, i64, String)) {
    let text = |key: &str| p[key].as_str().unwrap_or_default().to_string();
    (text(code), (text(shown), p[number].as_f64().unwrap(), p["raw"].as_i64().unwrap(), text(unit)))
}

/// What `get --json` reads of [`POINTS`].
fn get(master: &str) -> Read {
    let out = ferrobus().args(["--port", master, "--device", "omron-3g3rx", "get", "--json"]).args(POINTS).assert();
    assert!(out.get_output().status.success(), "get: {}", stderr(&out));
    let doc: Value = serde_json::from_slice(&out.get_output().stdout).unwrap();
    doc["points"].as_array().unwrap().iter().map(|p| point(p, ["code", "value", "engineering", "unit"])).collect()
}

/// Runs `sniff --device omron-3g3rx:1 FLAGS` on a fresh bus while `set F001 45.5Hz` and `get`
/// of [`POINTS`] are the master; returns what it printed on stdout (once `get`'s last reply,
/// A004's, was printed) and what `get` read.
fn sniffed(flags: &[&str]) -> (Vec<String>, Read) {
    let bus = bus_of("omron-3g3rx");
    let mut args = vec!["--device", "omron-3g3rx:1"];
    args.extend_from_slice(flags);
    let (mut sniffer, _said) = sniff(&bus.tap, &args, Stdio::piped());
    let out = lines(sniffer.0.stdout.take().unwrap());
    let set = ferrobus().args(["--port", &bus.master, "--device", "omron-3g3rx", "set", "F001", "45.5Hz"]).assert();
    assert!(set.get_output().status.success(), "set: {}", stderr(&set));
    let read = get(&bus.master);
    let printed = wait_for(&out, usize::MAX, "A004", "sniff --device");
    assert!(sniffer.stop().success());
    (printed, read)
}

#[test]
fn the_sniffers_table_shows_what_get_read_and_the_value_set() {
    let (printed, read) = sniffed(&[]);
    let fields = |line: &str| -> Vec<String> {
        line.split("  ").map(str::trim).filter(|f| !f.is_empty()).map(String::from).collect()
    };
    assert_eq!(fields(&printed[0]), ["time", "unit", "group", "point", "value"], "{printed:#?}");
    let rows: Vec<Vec<String>> = printed.iter().skip(1).map(|l| fields(l)).collect();
    let mut last = HashMap::new();
    for row in &rows {
        let [time, unit, _group, point, value] = row.as_slice() else { panic!("{row:?} in {printed:#?}") };
        assert_eq!(unit, "1");
        assert_eq!(time.len(), "15:28:34.928177".len(), "{time}");
        last.insert(point.clone(), value.clone());
    }
    for (code, (shown, ..)) in &read {
        assert_eq!(last.get(code), Some(shown), "{code}: {printed:#?}");
    }
    assert_eq!(read["F001"].0, "45.50 Hz");
    // The write, its read-back by set, and get's read.
    let f001 = rows.iter().filter(|r| r[3] == "F001").count();
    assert!(f001 >= 3, "{printed:#?}");
}

#[test]
fn the_sniffers_csv_has_polls_columns_and_what_get_read() {
    let (printed, read) = sniffed(&["--csv"]);
    assert_eq!(printed[0], "time,seq,unit,group,point,raw,value,meaning,uom,status,response_ms,diagnosis");
    let mut last = HashMap::new();
    for line in printed.iter().skip(1) {
        let row: Vec<&str> = line.split(',').collect();
        let [time, _seq, unit, _group, point, raw, value, _meaning, uom, status, response_ms, _] = row.as_slice()
        else {
            panic!("{line}")
        };
        assert!(time.starts_with("20") && time.ends_with('Z'), "{time}");
        assert_eq!((*unit, *status), ("1", "ok"));
        assert!(response_ms.parse::<f64>().unwrap() > 0.0);
        last.insert(point.to_string(), (raw.parse::<i64>().unwrap(), value.parse::<f64>().unwrap(), uom.to_string()));
    }
    for (code, (_, engineering, raw, unit)) in &read {
        assert_eq!(last.get(code), Some(&(*raw, *engineering, unit.clone())), "{code}: {printed:#?}");
    }
}

#[test]
fn the_sniffers_json_lines_are_polls_records_with_what_get_read() {
    let (printed, read) = sniffed(&["--json"]);
    let mut last = HashMap::new();
    for line in &printed {
        let doc: Value = serde_json::from_str(line).unwrap_or_else(|e| panic!("{e}: {line}"));
        assert_eq!((doc["unit"].as_u64(), doc["status"].as_str()), (Some(1), Some("ok")), "{line}");
        assert!(doc["time"].as_str().unwrap().ends_with('Z'));
        last.extend(doc["points"].as_array().unwrap().iter().map(|p| point(p, ["point", "shown", "value", "uom"])));
    }
    for (code, got) in &read {
        assert_eq!(last.get(code), Some(got), "{code}: {printed:#?}");
    }
}

#[test]
fn device_takes_a_unit_from_1_to_247_and_csv_needs_it() {
    for (args, said) in [
        (vec!["--port", "/dev/null", "sniff", "--device", "omron-3g3rx:0"], "1 to 247"),
        (vec!["--port", "/dev/null", "sniff", "--csv"], "--csv writes the values of --device"),
        (vec!["--port", "/dev/null", "sniff", "--device", "omron-3g3rx", "--pcap", "-"], "give --pcap a FILE"),
        (vec!["--port", "/dev/null", "sniff", "--device", "no-such-drive"], "no profile named"),
    ] {
        let out = ferrobus().args(&args).assert();
        assert_eq!(out.get_output().status.code(), Some(2), "{args:?}: {}", stderr(&out));
        assert!(stderr(&out).contains(said), "{args:?}: {}", stderr(&out));
    }
}
