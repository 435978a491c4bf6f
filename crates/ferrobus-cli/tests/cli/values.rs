//! One formatting of a value in every output: a point with scale 0.01 shows two decimals
//! and no float noise (3498 × 0.01 computes to 34.980000000000004) in `get` (table, CSV,
//! JSON), `poll` (CSV, JSON lines), `backup` and `diff`; an enumeration carries its meaning
//! beside its number where scripts read it.

use serde_json::Value;

use crate::backup::{TcpSim, temp};
use crate::server::stdout;

const NOISE: &str = "34.980000000000004";

#[test]
fn a_scaled_value_has_its_resolution_and_an_enumeration_its_meaning_in_every_output() {
    let sim = TcpSim::start(&["--profile", "omron-3g3rx"]);
    let path = temp("values.toml");
    let file = path.to_str().unwrap();
    sim.run("omron-3g3rx", &["backup", "-o", file]).success();
    sim.run("omron-3g3rx", &["set", "F002", "34.98"]).success();

    let json = stdout(&sim.run("omron-3g3rx", &["get", "F002", "status-a", "--json"]).success());
    assert!(!json.contains(NOISE), "{json}");
    let doc: Value = serde_json::from_str(&json).unwrap();
    let (f002, status) = (&doc["points"][0], &doc["points"][1]);
    assert_eq!((f002["value"].clone(), f002["engineering"].clone()), ("34.98 s".into(), 34.98.into()), "{json}");
    assert_eq!(f002["meaning"], Value::Null);
    assert_eq!((status["raw"].clone(), status["meaning"].clone()), (2.into(), "stop".into()), "{json}");
    let csv = stdout(&sim.run("omron-3g3rx", &["get", "F002", "--csv"]).success());
    assert_eq!(csv, "code,label,value\nF002,acceleration time 1,34.98 s\n");

    let poll = |format: &str| {
        let args = ["poll", "F002", "status-a", "--every", "100ms", "--duration", "150ms", format];
        stdout(&sim.run("omron-3g3rx", &args).success())
    };
    let csv = poll("--csv");
    assert!(!csv.contains(NOISE), "{csv}");
    let row = |point: &str| -> Vec<String> {
        let line = csv.lines().find(|l| l.split(',').nth(4) == Some(point)).unwrap_or_default();
        line.split(',').skip(5).take(4).map(str::to_string).collect()
    };
    // raw, value, meaning, uom
    assert_eq!(row("F002"), ["3498", "34.98", "", "s"], "{csv}");
    assert_eq!(row("status-a"), ["2", "2", "stop", ""], "{csv}");
    let lines = poll("--jsonl");
    assert!(!lines.contains(NOISE), "{lines}");
    // One record per group, one group per point here.
    let points: Vec<Value> = lines
        .lines()
        .flat_map(|l| serde_json::from_str::<Value>(l).unwrap()["points"].as_array().unwrap().clone())
        .collect();
    let point = |name: &str| points.iter().find(|p| p["point"] == name).unwrap().clone();
    assert_eq!((point("F002")["value"].clone(), point("F002")["meaning"].clone()), (34.98.into(), Value::Null));
    assert_eq!((point("status-a")["value"].clone(), point("status-a")["meaning"].clone()), (2.into(), "stop".into()));

    let backup = stdout(&sim.run("omron-3g3rx", &["backup"]).success());
    assert!(backup.contains("\nF002 = { raw = 3498, value = \"34.98 s\" }\n"), "{backup}");
    let diff = stdout(&sim.run("omron-3g3rx", &["diff", file, "--json"]).code(1));
    let doc: Value = serde_json::from_str(&diff).unwrap();
    assert_eq!(doc["differences"][0]["b"]["value"], "34.98 s", "{diff}");
    std::fs::remove_file(&path).unwrap();
}
