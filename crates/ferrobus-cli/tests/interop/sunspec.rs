//! SunSpec against the SunSpec Alliance's own client: pysunspec2 (tests/peers/sunspec_client.py)
//! scans `ferrobus sim --profile sunspec-inverter` over Modbus/TCP and reads every point, and
//! ferrobus's `scan --sunspec` and `get --device sunspec` must find the same chain and read
//! the same values, scale factors applied. The sim's layout is ours; the models it follows and
//! the client that checks it are SunSpec's.

use std::process::Command;
use std::time::Duration;

use serde_json::Value;

use crate::support::env::{pymodbus_script, python};
use crate::support::process::output_within;
use crate::support::{Link, Need, Over, Parity, ferrobus, require, sim};

#[test]
fn pysunspec2_and_ferrobus_read_the_simulated_inverter_alike() {
    let Some(_turn) = require(&[Need::Pysunspec2]) else {
        return;
    };
    let served = sim(Over::Tcp, Parity::None, &["--profile", "sunspec-inverter"]);
    let Link::Tcp(addr) = &served.link else {
        unreachable!("a TCP sim");
    };
    let (host, port) = addr.rsplit_once(':').unwrap();
    let mut client = Command::new(python());
    client.arg(pymodbus_script("sunspec_client.py")).args([host, port, "1"]);
    let output = output_within(&mut client, "", Duration::from_secs(30));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "sunspec_client.py: {stderr}");
    let theirs: Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(theirs["base"], 40000, "{theirs}");

    let ours = ferrobus(&served.link).run(&["scan", "--sunspec", "--json"]).json();
    let chain = |doc: &Value| -> Vec<(u64, u64)> {
        doc["models"]
            .as_array()
            .unwrap()
            .iter()
            .map(|m| (m["id"].as_u64().unwrap(), m["length"].as_u64().unwrap()))
            .collect()
    };
    assert_eq!(chain(&ours), chain(&theirs), "the same models, in order, of the same lengths");
    assert_eq!(chain(&ours), [(1, 66), (103, 50)]);
    let names: Vec<(u64, String)> = ours["models"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| (m["id"].as_u64().unwrap(), m["name"].as_str().unwrap().to_string()))
        .collect();

    let got = ferrobus(&served.link).run(&["--device", "sunspec", "get", "*", "--json"]).json();
    let points = got["points"].as_array().unwrap();
    let mut compared = 0;
    for (key, point) in theirs["points"].as_object().unwrap() {
        let cvalue = &point["cvalue"];
        if cvalue.is_null() {
            continue; // not implemented, as pysunspec2 reads it
        }
        let (id, name) = key.split_once('.').unwrap();
        if name == "Pad" {
            continue; // ferrobus leaves pad points out
        }
        let model = &names.iter().find(|(i, _)| i.to_string() == id).unwrap().1;
        let code = format!("{model}.{name}");
        let ours = points.iter().find(|p| p["code"] == code).unwrap_or_else(|| panic!("ferrobus has no {code}"));
        match cvalue {
            Value::String(text) => assert_eq!(ours["value"].as_str(), Some(text.as_str()), "{code}"),
            number => {
                let (a, b) = (ours["engineering"].as_f64().unwrap(), number.as_f64().unwrap());
                assert!((a - b).abs() <= 1e-9 * b.abs().max(1.0), "{code}: ferrobus {a}, pysunspec2 {b}");
            }
        }
        compared += 1;
    }
    assert!(compared >= 40, "only {compared} points compared");
}
