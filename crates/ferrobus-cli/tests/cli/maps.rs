//! `profile import` and `profile export`: the example maps of examples/maps/ imported and
//! checked, the files written and refused, and a map imported, served by `ferrobus sim` and
//! read back with `get` through the profile written.

use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::server::{TcpSim, offline, stderr, stdout};

/// examples/maps/NAME.
fn example(name: &str) -> String {
    format!("{}/../../examples/maps/{name}", env!("CARGO_MANIFEST_DIR"))
}

/// A fresh path in the temporary directory (the file is removed on drop).
struct Temp(PathBuf);

impl Temp {
    fn new(name: &str) -> Temp {
        let path = std::env::temp_dir().join(format!("ferrobus-maps-{}-{name}", std::process::id()));
        let _ = std::fs::remove_file(&path);
        Temp(path)
    }

    fn path(&self) -> &str {
        self.0.to_str().unwrap()
    }
}

impl Drop for Temp {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// Imports `map` as `from` (with `more` options) into a new file; the file, and stderr.
fn import(map: &str, from: &str, more: &[&str], name: &str) -> (Temp, String) {
    let out = Temp::new(name);
    let mut args = vec!["profile", "import", map, "--from", from, "-o", out.path()];
    args.extend_from_slice(more);
    let assert = offline(&args).success();
    assert!(stdout(&assert).is_empty(), "the profile goes to the file: {}", stdout(&assert));
    (out, stderr(&assert))
}

#[test]
fn the_example_maps_import_into_profiles_that_check_with_what_was_not_mapped_listed() {
    for (map, from, more, points) in [
        ("meter.csv", "csv", &["--first-address", "1"][..], 13),
        ("home-assistant.yaml", "ha-yaml", &[][..], 9),
        ("evcc.yaml", "evcc-yaml", &[][..], 7),
    ] {
        let (profile, report) = import(&example(map), from, more, map);
        assert!(report.contains(&format!("{points} points imported into {}", profile.path())), "{map}: {report}");
        let check = stdout(&offline(&["profile", "check", profile.path()]).success());
        assert!(check.contains(": ok: "), "{map}: {check}");
        let text = std::fs::read_to_string(&profile.0).unwrap();
        assert!(text.starts_with(&format!("# Imported by `ferrobus profile import --from {from}`")), "{text}");
    }
    let (_, report) = import(&example("home-assistant.yaml"), "ha-yaml", &[], "ha-report");
    assert!(report.contains("not mapped: modbus[0]: host = 192.168.1.40: a connection setting"), "{report}");
    assert!(report.contains("not mapped: modbus[0].sensors[0]: precision = 1"), "{report}");
    let (_, report) = import(&example("evcc.yaml"), "evcc-yaml", &[], "evcc-report");
    assert!(report.contains("not mapped: meters[1].power: source = http: a source other than Modbus"), "{report}");
    assert!(report.contains("(and 7 more): uri = 192.168.1.50:502"), "{report}");
}

#[test]
fn json_gives_the_profile_and_the_list_in_one_document() {
    let assert = offline(&["profile", "import", &example("evcc.yaml"), "--from", "evcc-yaml", "--json"]).success();
    let doc: Value = serde_json::from_str(&stdout(&assert)).unwrap();
    assert_eq!((doc["from"].as_str(), doc["points"].as_u64()), (Some("evcc-yaml"), Some(7)));
    assert!(doc["profile"].as_str().unwrap().contains("name = \"grid.power\""));
    let first = &doc["unmapped"][0];
    assert_eq!((first["place"].as_str(), first["field"].as_str()), (Some("meters[1].power"), Some("source")));
}

#[test]
fn an_existing_output_is_kept_unless_forced_and_bad_input_is_a_usage_error() {
    let (out, _) = import(&example("meter.csv"), "csv", &["--first-address", "1"], "kept");
    let again = offline(&["profile", "import", &example("meter.csv"), "--from", "csv", "-o", out.path()]).code(2);
    assert!(stderr(&again).contains("exists and is kept: give --force to replace it"), "{}", stderr(&again));
    offline(&["profile", "import", &example("meter.csv"), "--from", "csv", "-o", out.path(), "--force"]).success();
    let missing = offline(&["profile", "import", "/nonexistent/map.csv", "--from", "csv"]).code(2);
    assert!(stderr(&missing).contains("/nonexistent/map.csv"), "{}", stderr(&missing));
    let wrong = offline(&["profile", "import", &example("meter.csv"), "--from", "ha-yaml"]).code(2);
    assert!(stderr(&wrong).contains("meter.csv: not YAML: "), "{}", stderr(&wrong));
    let empty = Temp::new("empty.yaml");
    std::fs::write(&empty.0, "homeassistant:\n  name: Home\n").unwrap();
    let none = offline(&["profile", "import", empty.path(), "--from", "ha-yaml"]).code(2);
    assert!(stderr(&none).contains("no Home Assistant modbus configuration"), "{}", stderr(&none));
    let several = Temp::new("several.yaml");
    std::fs::write(&several.0, "sensors:\n  - {name: a, slave: 1, address: 1}\n  - {name: b, slave: 2, address: 1}\n")
        .unwrap();
    let refused = offline(&["profile", "import", several.path(), "--from", "ha-yaml"]).code(2);
    assert!(stderr(&refused).contains("describes units 1, 2: pick one with --only-unit"), "{}", stderr(&refused));
    offline(&["profile", "import", several.path(), "--from", "ha-yaml", "--only-unit", "2"]).success();
    let big = Temp::new("big.yaml");
    std::fs::File::create(&big.0).unwrap().set_len((16 << 20) + 1).unwrap();
    let refused = offline(&["profile", "import", big.path(), "--from", "ha-yaml"]).code(2);
    let said = stderr(&refused);
    assert!(said.contains(&format!("{}: larger than the 16 MiB a map file may be", big.path())), "{said}");
    let bad = offline(&["profile", "import", &example("meter.csv"), "--from", "xml"]).code(2);
    assert!(stderr(&bad).contains("csv, ha-yaml, evcc-yaml"), "{}", stderr(&bad));
}

#[test]
fn a_builtin_exported_to_csv_imports_back_and_checks() {
    let csv = Temp::new("rx.csv");
    offline(&["profile", "export", "omron-3g3rx", "--to", "csv", "-o", csv.path()]).success();
    let text = std::fs::read_to_string(&csv.0).unwrap();
    assert!(text.starts_with("name,table,address,type,length,order,scale,"), "{text}");
    let (profile, report) = import(csv.path(), "csv", &[], "rx.toml");
    assert!(report.contains("0 things not mapped"), "{report}");
    let shown = |name: &str| stdout(&offline(&["profile", "show", name, "--json"]).success());
    let (a, b): (Value, Value) =
        (serde_json::from_str(&shown("omron-3g3rx")).unwrap(), serde_json::from_str(&shown(profile.path())).unwrap());
    let codes = |doc: &Value| doc["points"].as_array().unwrap().iter().map(|p| p["code"].clone()).collect::<Vec<_>>();
    assert_eq!(codes(&a), codes(&b));
}

#[test]
fn a_map_imported_is_served_by_sim_and_read_back_with_get() {
    let map = Temp::new("served.csv");
    std::fs::write(
        &map.0,
        "name;table;address;type;order;scale;unit;access;default\n\
         voltage;input;0;u16;;0.1;V;ro;2301\n\
         power;input;1;f32;CDAB;;W;ro;-1250.5\n\
         energy;input;3;u32;CDAB;0.01;kWh;ro;123456\n\
         setpoint;holding;10;i16;;0.5;°C;rw;42\n\
         relay;coils;5;;;;;rw;1\n",
    )
    .unwrap();
    let (profile, _) = import(map.path(), "csv", &[], "served.toml");
    let sim = TcpSim::start(profile.path(), None);
    let get = |codes: &[&str]| {
        let mut args = vec!["--device", profile.path(), "get"];
        args.extend_from_slice(codes);
        args.push("--json");
        let doc: Value = serde_json::from_str(&stdout(&sim.run(&args).success())).unwrap();
        doc["points"].as_array().unwrap().clone()
    };
    let values = get(&["voltage", "power", "energy", "setpoint", "relay"]);
    let value = |code: &str| {
        let found = values.iter().find(|v| v["code"] == code).unwrap_or_else(|| panic!("{code}: {values:?}"));
        (found["engineering"].as_f64(), found["unit"].clone())
    };
    assert_eq!(value("voltage"), (Some(230.1), Value::from("V")));
    assert_eq!(value("power"), (Some(-1250.5), Value::from("W")));
    assert_eq!(value("energy"), (Some(1234.56), Value::from("kWh")));
    assert_eq!(value("setpoint"), (Some(21.0), Value::from("°C")));
    assert_eq!(value("relay").0, Some(1.0));
    sim.run(&["--device", profile.path(), "set", "setpoint", "30.5"]).success();
    let after = get(&["setpoint"]);
    assert_eq!(after[0]["engineering"].as_f64(), Some(30.5), "{after:?}");
    let refused = sim.run(&["--device", profile.path(), "set", "voltage", "1"]);
    assert!(!refused.get_output().status.success(), "an input register is read-only");
    assert!(Path::new(profile.path()).exists());
}

/// A reference device for the published-shape maps: the registers where the meters' manuals
/// put them, by their frame addresses, with readings as defaults.
const METERS: &str = r#"
[device]
name = "reference meters"
vendor = "test"
product_code = "reference"
revision = "1"
identification = false

[addressing]
base = 0

[[inputs]]
number = 0
name = "l1_volts"
type = "f32"
default = 231.5

[[inputs]]
number = 342
name = "total_kwh"
type = "f32"
default = 1234.5

[[registers]]
number = 12
name = "demand_period"
type = "f32"
access = "rw"
default = 15.0

[[registers]]
number = 0x5000
name = "active_import"
type = "u64"
default = 123456

[[registers]]
number = 0x5B00
name = "l1_n"
type = "u32"
default = 2302

[[registers]]
number = 0x5B14
name = "active_power"
type = "i32"
default = -150025
"#;

/// The engineering values and units of `codes`, read with `get` through `profile` from `sim`.
fn readings(sim: &TcpSim, profile: &str, codes: &[&str]) -> Vec<(Option<f64>, Value)> {
    let mut args = vec!["--device", profile, "get"];
    args.extend_from_slice(codes);
    args.push("--json");
    let doc: Value = serde_json::from_str(&stdout(&sim.run(&args).success())).unwrap();
    let points = doc["points"].as_array().unwrap();
    codes
        .iter()
        .map(|code| {
            let found = points.iter().find(|v| v["code"] == *code).unwrap_or_else(|| panic!("{code}: {points:?}"));
            (found["engineering"].as_f64(), found["unit"].clone())
        })
        .collect()
}

#[test]
fn vendor_lists_in_the_shapes_people_publish_read_the_devices_values() {
    let reference = Temp::new("reference.toml");
    std::fs::write(&reference.0, METERS).unwrap();
    let sim = TcpSim::start(reference.path(), None);
    // Eastron's Modicon numbers: recognised, with a note; every read lands where the manual says.
    let (sdm, report) = import(&example("published/sdm630.csv"), "csv", &[], "sdm630.toml");
    assert!(report.contains("note: Every address is a Modicon register number"), "{report}");
    assert!(report.contains("8 points imported") && report.contains("0 things not mapped"), "{report}");
    let values = readings(&sim, sdm.path(), &["Phase_1_line_to_neutral_volts", "Total_kWh", "Demand_period"]);
    assert_eq!(
        values,
        [(Some(231.5), Value::from("V")), (Some(1234.5), Value::from("kWh")), (Some(15.0), Value::from("minutes"))]
    );
    // ABB's hex start registers, sizes and resolutions.
    let (abb, report) = import(&example("published/abb-b23.csv"), "csv", &[], "abb.toml");
    assert!(report.contains("6 points imported") && report.contains("0 things not mapped"), "{report}");
    let values = readings(&sim, abb.path(), &["Active_import", "Voltage_L1-N", "Active_power"]);
    assert_eq!(
        values,
        [(Some(1234.56), Value::from("kWh")), (Some(230.2), Value::from("V")), (Some(-1500.25), Value::from("W"))]
    );
}

#[test]
fn an_evcc_file_of_two_devices_imports_one_profile_per_device() {
    let map = example("published/evcc-meter-and-wallbox.yaml");
    let refused = offline(&["profile", "import", &map, "--from", "evcc-yaml"]).code(2);
    let err = stderr(&refused);
    assert!(err.contains("describes 2 devices (grid at 192.168.1.50:502, wallbox at 192.168.1.60:502)"), "{err}");
    assert!(stdout(&refused).is_empty());
    let (grid, report) = import(&map, "evcc-yaml", &["--only-device", "grid"], "grid.toml");
    assert!(report.contains("2 points imported"), "{report}");
    assert!(report.contains("template = sma-inverter: an evcc template"), "{report}");
    let text = std::fs::read_to_string(&grid.0).unwrap();
    assert!(text.contains("name = \"grid\"") && text.contains("name = \"grid.energy\""), "{text}");
    assert!(!text.contains("wallbox"), "{text}");
    let (wallbox, report) = import(&map, "evcc-yaml", &["--only-device", "wallbox"], "wallbox.toml");
    assert!(report.contains("3 points imported"), "{report}");
    let check = stdout(&offline(&["profile", "check", wallbox.path()]).success());
    assert!(check.contains(": ok: "), "{check}");
}

#[test]
fn a_long_list_of_what_was_not_mapped_is_summed_up_past_a_hundred_lines() {
    let map = Temp::new("many.csv");
    let mut text = String::from("address,name,colour\n0,first,red\n");
    for n in 0..5000 {
        let _ = std::fmt::Write::write_fmt(&mut text, format_args!("x{n},bad,\n"));
    }
    std::fs::write(&map.0, &text).unwrap();
    let (_, report) = import(map.path(), "csv", &[], "many.toml");
    let lines: Vec<&str> = report.lines().filter(|l| l.starts_with("not mapped:")).collect();
    assert_eq!(lines.len(), 101, "{report}");
    assert!(lines[100].contains("... and 4901 more (4900 address, 1 colour; --json lists them all)"), "{}", lines[100]);
    assert!(report.contains("1 point imported into") && report.contains("5001 things not mapped"), "{report}");
    let all = offline(&["profile", "import", map.path(), "--from", "csv", "--json"]).success();
    let doc: Value = serde_json::from_str(&stdout(&all)).unwrap();
    assert_eq!(doc["unmapped"].as_array().unwrap().len(), 5001);
}

/// examples/maps/published/NAME: maps in the shapes people publish them in.
fn published(name: &str) -> String {
    example(&format!("published/{name}"))
}

#[test]
fn published_home_assistant_files_import_through_anchors_include_and_secret_and_serve_scaled_values() {
    // Anchors merged with `<<`, two `<<` keys in a map: every sensor with its type and scale.
    let (sma, report) = import(&published("sma-sunny-tripower.yaml"), "ha-yaml", &[], "sma.toml");
    assert!(report.contains("9 points imported into"), "{report}");
    let sim = TcpSim::start(sma.path(), None);
    let shown = stdout(&sim.run(&["--device", sma.path(), "get", "SMA_Grid_Frequency"]).success());
    assert!(shown.contains("SMA Grid Frequency  0.00 Hz"), "u32 at a scale of 0.01: {shown}");
    drop(sim);
    // `sensors: !include` and `slave: !secret`, read from the map's directory.
    let (config, report) = import(&published("ha-config/configuration.yaml"), "ha-yaml", &[], "config.toml");
    assert!(report.contains("6 points imported into"), "{report}");
    assert!(report.contains("not mapped: modbus[0]: host = !secret modbus_host: a connection setting"), "{report}");
    assert!(!report.contains("192.168.1.40"), "a secret is never shown: {report}");
    let (_, seven) = import(&published("ha-config/configuration.yaml"), "ha-yaml", &["--only-unit", "7"], "seven.toml");
    assert!(seven.contains("6 points imported into"), "every entity is of the secret's unit 7: {seven}");
    let zero = offline(&[
        "profile",
        "import",
        &published("ha-config/configuration.yaml"),
        "--from",
        "ha-yaml",
        "--only-unit",
        "0",
    ])
    .code(2);
    assert!(stderr(&zero).contains("an entity of unit 7, not of unit 0"), "{}", stderr(&zero));
    let sim = TcpSim::start(config.path(), None);
    sim.run(&["--device", config.path(), "set", "Living_room_target", "21.5"]).success();
    let shown = stdout(&sim.run(&["--device", config.path(), "get", "Living_room_target"]).success());
    assert!(shown.contains("21.5 °C"), "{shown}");
    let json = stdout(
        &sim.run(&["--device", config.path(), "get", "Outdoor_temperature", "Living_room_target", "--json"]).success(),
    );
    let doc: Value = serde_json::from_str(&json).unwrap();
    let points = doc["points"].as_array().unwrap();
    let target = points.iter().find(|p| p["code"] == "Living_room_target").unwrap();
    assert_eq!((target["raw"].as_i64(), target["unit"].as_str()), (Some(215), Some("°C")), "{target}");
    let outdoor = points.iter().find(|p| p["code"] == "Outdoor_temperature").unwrap();
    assert_eq!(outdoor["unit"].as_str(), Some("°C"), "from the included file: {outdoor}");
}
