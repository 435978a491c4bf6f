//! The YAML reader on files shaped like those people publish (anchors merged with `<<`, two
//! `<<` keys in one map, `!include`, `!secret`), and on files made to exhaust it.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use super::{Format, ImportError, ImportOptions, Imported, import};
use crate::model::{Access, Order, Table, ValueType};
use crate::{Point, Profile};

/// examples/maps/published/NAME.
fn published(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/maps/published").join(name)
}

fn imported(text: &str, options: &ImportOptions) -> (Profile, Imported) {
    let imported = import(text, "map.yaml", Format::HaYaml, options).unwrap_or_else(|e| panic!("import: {e}"));
    let profile = Profile::parse(&imported.toml, "imported").unwrap_or_else(|e| panic!("{e}\n{}", imported.toml));
    (profile, imported)
}

fn refused(text: &str, options: &ImportOptions) -> String {
    match import(text, "map.yaml", Format::HaYaml, options) {
        Ok(imported) => panic!("imported: {}", imported.toml),
        Err(e @ ImportError::Invalid { .. }) => panic!("an import writes no profile it refuses: {e}"),
        Err(e) => {
            let text = e.to_string();
            assert!(text.starts_with("map.yaml: "), "a refusal names the map: {text}");
            text
        }
    }
}

fn point<'a>(profile: &'a Profile, code: &str) -> &'a Point {
    profile.point(code).unwrap_or_else(|| {
        let codes: Vec<&str> = profile.points().iter().map(|p| p.code.as_str()).collect();
        panic!("no point {code}; the points are {codes:?}")
    })
}

/// (table, address, type, order, scale, unit, access) of a point.
fn shape(p: &Point) -> (Table, u16, ValueType, Order, Option<f64>, Option<&str>, Access) {
    (
        p.table,
        p.address,
        p.value_type,
        p.order,
        (!super::is(p.scale, 1.0)).then_some(p.scale),
        p.unit.as_deref(),
        p.access,
    )
}

/// The listing of `field` at `place` (exactly), if any: (value, why).
fn listed<'a>(imported: &'a Imported, place: &str, field: &str) -> Option<(&'a str, &'a str)> {
    imported.unmapped.iter().find(|u| u.place == place && u.field == field).map(|u| (u.value.as_str(), u.why.as_str()))
}

/// A fresh directory under the system's temporary one, removed on drop.
struct Dir(PathBuf);

impl Dir {
    fn new(name: &str) -> Dir {
        let path = std::env::temp_dir().join(format!("ferrobus-yaml-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&path);
        std::fs::create_dir_all(&path).unwrap();
        Dir(path)
    }

    fn write(&self, name: &str, text: &str) -> &Dir {
        let path = self.0.join(name);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, text).unwrap();
        self
    }

    fn options(&self) -> ImportOptions {
        ImportOptions { dir: Some(self.0.clone()), ..ImportOptions::default() }
    }
}

impl Drop for Dir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Runs `f`, failing if it takes more than `limit`; the time it took.
fn quick<T>(limit: Duration, f: impl FnOnce() -> T) -> (T, Duration) {
    let start = Instant::now();
    let out = f();
    let took = start.elapsed();
    assert!(took < limit, "took {took:?}");
    (out, took)
}

#[test]
fn an_sma_file_of_anchors_and_two_merge_keys_imports_every_sensor_with_its_type_scale_and_unit() {
    let text = std::fs::read_to_string(published("sma-sunny-tripower.yaml")).unwrap();
    let (profile, imported) = imported(&text, &ImportOptions::default());
    assert_eq!(imported.points, 9, "{:?}", imported.unmapped);
    let h = Table::Holding;
    for (code, expected) in [
        ("SMA_Grid_Power", (h, 30775, ValueType::I32, Order::Abcd, None, Some("W"), Access::Ro)),
        ("SMA_Total_Yield", (h, 30513, ValueType::U64, Order::Abcd, Some(0.001), Some("kWh"), Access::Ro)),
        // Two `<<` keys: the settings of both anchors.
        ("SMA_Grid_Frequency", (h, 30803, ValueType::U32, Order::Abcd, Some(0.01), Some("Hz"), Access::Ro)),
        ("SMA_Grid_Voltage_L1", (h, 30783, ValueType::U32, Order::Abcd, Some(0.01), Some("V"), Access::Ro)),
        // `<<: [*centi, *sma_u32]`.
        ("SMA_Grid_Voltage_L2", (h, 30785, ValueType::U32, Order::Abcd, Some(0.01), Some("V"), Access::Ro)),
        // The sensor's own scale beside the anchor's type.
        ("SMA_Grid_Current_L1", (h, 30977, ValueType::I32, Order::Abcd, Some(0.001), Some("A"), Access::Ro)),
        ("SMA_DC_Power_A", (h, 30773, ValueType::I32, Order::Abcd, None, Some("W"), Access::Ro)),
        ("SMA_Internal_Temperature", (h, 30953, ValueType::I32, Order::Abcd, Some(0.1), Some("°C"), Access::Ro)),
        ("SMA_Device_Status", (h, 30201, ValueType::U32, Order::Abcd, None, None, Access::Ro)),
    ] {
        assert_eq!(shape(point(&profile, code)), expected, "{code}");
    }
    // The merged display settings are listed like written ones; the unit is the anchors' 3.
    assert_eq!(listed(&imported, "modbus[0].sensors[3]", "precision"), Some(("2", listed_why())));
    let other = ImportOptions { unit: Some(1), ..ImportOptions::default() };
    let Err(ImportError::Nothing { list, .. }) = import(&text, "sma.yaml", Format::HaYaml, &other) else {
        panic!("every entity is of unit 3")
    };
    assert!(list.iter().any(|u| u.field == "slave" && u.value == "3" && u.why.contains("of unit 3, not of unit 1")));
}

fn listed_why() -> &'static str {
    "how Home Assistant shows or polls it: a profile has no such setting"
}

#[test]
fn merge_keys_give_way_to_the_maps_own_keys_the_first_of_a_list_and_the_later_of_two() {
    let text = "sensors:\n\
                - name: a\n  address: 1\n  <<: [{scale: 0.5, unit_of_measurement: A}, {scale: 2, unit_of_measurement: B, data_type: uint16}]\n\
                - name: b\n  address: 2\n  <<: {scale: 0.5, data_type: int32}\n  <<: {scale: 2}\n\
                - name: c\n  <<: {scale: 0.5, address: 9}\n  scale: 4\n  address: 4\n\
                - name: d\n  address: 6\n  <<: 7\n\
                - name: e\n  address: 7\n  !!merge <<: {scale: 3}\n  '<<': {scale: 5}\n";
    let (profile, imported) = imported(text, &ImportOptions::default());
    let scale = |code: &str| {
        let p = point(&profile, code);
        (p.address, p.value_type, p.scale, p.unit.clone())
    };
    assert_eq!(scale("a"), (1, ValueType::U16, 0.5, Some("A".into())));
    assert_eq!(scale("b"), (2, ValueType::I32, 2.0, None));
    assert_eq!(scale("c"), (4, ValueType::I16, 4.0, None));
    // `!!merge <<` merges; a quoted `'<<'` is a key like any other (listed).
    assert_eq!(scale("e"), (7, ValueType::I16, 3.0, None));
    assert!(listed(&imported, "sensors[4]", "<<").is_some_and(|(_, why)| why.contains("no profile equivalent")));
    let (value, why) = listed(&imported, "sensors[3]", "<<").unwrap();
    assert_eq!(value, "7");
    assert!(why.contains("merges a map or a list of maps"), "{why}");
}

#[test]
fn a_configuration_with_include_and_secret_imports_from_its_directory() {
    let dir = published("ha-config");
    let text = std::fs::read_to_string(dir.join("configuration.yaml")).unwrap();
    let options = ImportOptions { dir: Some(dir.clone()), ..ImportOptions::default() };
    let (profile, imported) = imported(&text, &options);
    assert_eq!(imported.points, 6, "{:?}", imported.unmapped);
    let (i, h) = (Table::Input, Table::Holding);
    for (code, expected) in [
        // From modbus/sensors.yaml, whose secret comes from the secrets.yaml above it.
        ("Outdoor_temperature", (i, 100, ValueType::I16, Order::Abcd, Some(0.1), Some("°C"), Access::Ro)),
        ("Flow_temperature", (i, 101, ValueType::I16, Order::Abcd, Some(0.1), Some("°C"), Access::Ro)),
        ("Compressor_energy", (i, 110, ValueType::U32, Order::Cdab, Some(0.01), Some("kWh"), Access::Ro)),
        ("Living_room_current", (h, 120, ValueType::I16, Order::Abcd, Some(0.1), Some("°C"), Access::Ro)),
        ("Living_room_target", (h, 121, ValueType::I16, Order::Abcd, Some(0.1), Some("°C"), Access::Rw)),
        ("Heating_enable", (h, 200, ValueType::U16, Order::Abcd, None, None, Access::Rw)),
    ] {
        assert_eq!(shape(point(&profile, code)), expected, "{code}");
    }
    // Every entity is of the secret's unit 7: none is of unit 0.
    let of_seven = ImportOptions { unit: Some(7), ..options.clone() };
    assert_eq!(import(&text, "c.yaml", Format::HaYaml, &of_seven).unwrap().points, 6);
    let of_zero = ImportOptions { unit: Some(0), ..options.clone() };
    let Err(ImportError::Nothing { list, .. }) = import(&text, "c.yaml", Format::HaYaml, &of_zero) else {
        panic!("no entity is of unit 0")
    };
    assert_eq!(list.iter().filter(|u| u.why.contains("of unit 7, not of unit 0")).count(), 5, "{list:?}");
    // A secret's value is listed as its tag, never shown.
    assert_eq!(listed(&imported, "modbus[0]", "host").map(|(v, _)| v), Some("!secret modbus_host"));
    assert!(!imported.unmapped.iter().any(|u| u.value.contains("192.168.1.40")), "{:?}", imported.unmapped);
    assert!(!imported.toml.contains("192.168.1.40"));
}

#[test]
fn without_a_directory_an_include_and_a_secret_are_listed_by_name_never_read_as_0() {
    let text = std::fs::read_to_string(published("ha-config/configuration.yaml")).unwrap();
    let (profile, imported) = imported(&text, &ImportOptions::default());
    let (value, why) = listed(&imported, "modbus[0]", "sensors").unwrap();
    assert_eq!(value, "!include modbus/sensors.yaml");
    assert!(why.contains("without its directory"), "{why}");
    let (value, why) = listed(&imported, "modbus[0].switches[0]", "slave").unwrap();
    assert_eq!(value, "!secret modbus_slave");
    assert!(why.contains("no secrets.yaml") && why.contains("unknown"), "{why}");
    // The entities whose unit is unknown are imported, listed as such; no sensor is made up.
    assert_eq!(imported.points, 3, "{:?}", imported.unmapped);
    assert!(profile.point("Heating_enable").is_some());
    // A unit that is no number is listed too (it was 0 before).
    let (_, imported) = imported_of("sensors:\n  - {name: a, address: 1, slave: three}\n");
    let (value, why) = listed(&imported, "sensors[0]", "slave").unwrap();
    assert_eq!(value, "three");
    assert!(why.contains("not a unit (0-255)"), "{why}");
}

fn imported_of(text: &str) -> (Profile, Imported) {
    imported(text, &ImportOptions::default())
}

#[test]
fn a_secret_is_looked_up_from_the_including_files_directory_up_to_the_maps() {
    let dir = Dir::new("secrets");
    dir.write("secrets.yaml", "unit: 4\naddress: 40\npassword: hunter2\npassword: hunter3\n<<: hunter4\n")
        .write("sub/secrets.yaml", "address: 41\n")
        .write(
            "sub/sensors.yaml",
            "- {name: near, address: !secret address, slave: !secret unit}\n- {name: gone, address: !secret nowhere}\n",
        );
    let text = "modbus:\n  - name: hub\n    sensors: !include sub/sensors.yaml\n    switches:\n      - {name: far, address: !secret address, slave: !secret unit}\n";
    let (profile, imported) = imported(text, &ImportOptions { unit: Some(4), ..dir.options() });
    // The nearer secrets.yaml wins; a secret it lacks comes from the one above.
    assert_eq!(point(&profile, "near").address, 41);
    assert_eq!(point(&profile, "far").address, 40);
    let (value, why) = listed(&imported, "modbus[0].sensors[1]", "address").unwrap();
    assert_eq!(value, "!secret nowhere");
    assert!(why.contains("no secret of this name in sub/secrets.yaml, secrets.yaml"), "{why}");
    assert_eq!(imported.points, 2, "{:?}", imported.unmapped);
    // A secrets.yaml's own mistakes are not listed: its values are secrets.
    assert!(!imported.unmapped.iter().any(|u| u.value.contains("hunter")), "{:?}", imported.unmapped);
}

#[test]
fn include_dirs_read_every_yaml_file_in_path_order() {
    let dir = Dir::new("dirs");
    dir.write("sensors/b.yaml", "- {name: b, address: 2}\n")
        .write("sensors/a.yaml", "- {name: a, address: 1}\n- {name: a2, address: 3}\n")
        .write("sensors/.hidden.yaml", "- {name: hidden, address: 4}\n")
        .write("sensors/secrets.yaml", "- {name: secret, address: 5}\n")
        .write("sensors/notes.txt", "- {name: text, address: 6}\n")
        .write("switches/one.yaml", "{name: one, address: 10, write_type: coil}\n");
    let text = "sensors: !include_dir_merge_list sensors\nswitches: !include_dir_list switches\n";
    let (profile, imported) = imported(text, &dir.options());
    let codes: Vec<&str> = profile.points().iter().map(|p| p.code.as_str()).collect();
    assert_eq!(codes, ["one", "a", "a2", "b"], "{:?}", imported.unmapped);
    assert_eq!(point(&profile, "b").address, 2);
}

#[test]
fn an_include_is_read_relative_to_its_file_and_never_outside_the_maps_directory() {
    let dir = Dir::new("outside");
    dir.write("map/hub.yaml", "sensors: !include ../outside.yaml\n").write("outside.yaml", "- {name: x, address: 1}\n");
    let map = Dir(dir.0.join("map"));
    let text = "modbus:\n  - !include hub.yaml\n  - {name: h2, sensors: [{name: in, address: 2}]}\n";
    let (_, imported) = imported(text, &map.options());
    let (value, why) = listed(&imported, "modbus[0]", "sensors").unwrap();
    assert_eq!(value, "!include ../outside.yaml");
    assert!(why.contains("outside the map's directory") && why.contains("(in hub.yaml)"), "{why}");
}

#[test]
fn a_key_written_twice_keeps_the_last_and_lists_the_first() {
    let (profile, imported) = imported_of("sensors:\n  - name: a\n    address: 1\n    address: 5\n");
    assert_eq!(point(&profile, "a").address, 5);
    let (value, why) = listed(&imported, "sensors[0]", "address").unwrap();
    assert_eq!(value, "1");
    assert!(why.contains("written again at line 4: the last is kept"), "{why}");
}

#[test]
fn deep_nesting_is_refused_at_once_and_in_linear_time() {
    let flow = "[".repeat(200_000);
    let (message, took) = quick(Duration::from_secs(1), || refused(&flow, &ImportOptions::default()));
    assert!(message.contains("nested deeper than 64 at line 1"), "{message}");
    println!("200 KB of [: refused in {took:?}");
    let block: String = (0..100).map(|depth| "  ".repeat(depth) + "-\n").collect();
    let message = refused(&block, &ImportOptions::default());
    assert!(message.contains("nested deeper than 64"), "{message}");
    let evcc = import(&"{a: ".repeat(100_000), "map.yaml", Format::EvccYaml, &ImportOptions::default());
    assert!(evcc.unwrap_err().to_string().contains("nested deeper than 64"));
    // Nesting counts over includes.
    let dir = Dir::new("deep");
    dir.write("deep.yaml", &format!("{}{}", "[".repeat(40), "]".repeat(40)));
    let text = format!("{}!include deep.yaml{}", "[".repeat(40), "]".repeat(40));
    assert!(refused(&text, &dir.options()).contains("deep.yaml: nested deeper than 64"));
}

#[test]
fn a_billion_laughs_is_refused_quickly() {
    let mut text = String::from("a0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol, lol]\n");
    for i in 1..10 {
        let previous = format!("*a{}", i - 1);
        let _ = writeln!(text, "a{i}: &a{i} [{}]", vec![previous; 10].join(", "));
    }
    text.push_str("sensors: *a9\n");
    let (message, took) = quick(Duration::from_secs(2), || refused(&text, &ImportOptions::default()));
    assert!(message.contains("aliases expand to more than 200000 nodes"), "{message}");
    println!("a billion laughs: refused in {took:?}");
    // Anchors nested in anchors, each a copy of the rest, count as well.
    let nested = format!("{}{}{}", "&a [".repeat(60), vec!["x"; 5000].join(", "), "]".repeat(60));
    let (message, _) = quick(Duration::from_secs(2), || refused(&nested, &ImportOptions::default()));
    assert!(message.contains("aliases expand to more than 200000 nodes"), "{message}");
    // An alias inside what it names is refused, not followed.
    assert!(refused("sensors: &a [*a]\n", &ImportOptions::default()).contains("to a node that holds it"));
}

#[test]
fn an_include_cycle_and_includes_nested_too_deep_are_refused() {
    let dir = Dir::new("cycle");
    dir.write("a.yaml", "sensors: !include b.yaml\n").write("b.yaml", "!include a.yaml\n");
    let message = refused("modbus:\n  - !include a.yaml\n", &dir.options());
    assert!(message.contains("an include cycle: a.yaml includes b.yaml includes a.yaml: refused"), "{message}");
    let dir = Dir::new("chain");
    for i in 0..20 {
        dir.write(&format!("f{i}.yaml"), &format!("!include f{}.yaml\n", i + 1));
    }
    let message = refused("sensors: !include f0.yaml\n", &dir.options());
    assert!(message.contains("includes nested deeper than 16"), "{message}");
}

#[test]
fn a_map_or_an_included_file_past_16_mib_is_refused_naming_it() {
    let big = format!("# {}\n", "x".repeat(16 << 20));
    let (message, _) = quick(Duration::from_secs(5), || refused(&big, &ImportOptions::default()));
    assert!(message.contains("larger than the 16 MiB a map file may be"), "{message}");
    let dir = Dir::new("big");
    dir.write("big.yaml", &big);
    let message = refused("sensors: !include big.yaml\n", &dir.options());
    assert!(message.contains("big.yaml: larger than the 16 MiB"), "{message}");
    dir.write("bad.yaml", "a: [\n");
    let message = refused("sensors: !include bad.yaml\n", &dir.options());
    assert!(message.starts_with("map.yaml: bad.yaml: not YAML: ") && message.contains("line 2"), "{message}");
}

#[test]
fn long_keys_deep_down_and_many_small_nodes_are_read_in_bounded_time() {
    // 60 maps nested under 80-character keys, then 300 000 empty lists: a place is made only
    // for what is listed, not copied into every node.
    let mut text = String::new();
    for depth in 0..60 {
        let _ = writeln!(text, "{}{}:", " ".repeat(depth), "k".repeat(80));
    }
    let _ = writeln!(text, "{}list: [{}]", " ".repeat(60), vec!["[]"; 300_000].join(","));
    let (message, took) = quick(Duration::from_secs(10), || refused(&text, &ImportOptions::default()));
    assert!(message.contains("no Home Assistant modbus configuration"), "{message}");
    println!("{} KB of long keys and small lists: read in {took:?}", text.len() / 1024);
}
