//! A profile written for a device ferrobus did not make: the peer servers' data map
//! (tests/peers/README.md) described as a small drive — a scaled speed, a 32-bit position, an
//! enumeration, an enable coil and a read-only input register — used with get, set, backup,
//! diff and restore against the libmodbus and pymodbus servers over Modbus/TCP.

use crate::support::{Over, Stack, ferrobus, peer_server, require, words};

/// The unit the peer servers serve here.
const UNIT: u8 = 17;

/// The data map as a profile: holding i = i * 7 + 3, input i = 0x1000 + i, coil i = i % 3 == 0.
/// Four registers per read, so that the plan has to split; the whole holding table answers
/// (a span), so a request may cross the unmapped registers between points.
const PROFILE: &str = r#"
[device]
name = "peer data map"
vendor = "tests/peers"
product_code = "MAP"
revision = "1"

[addressing]
base = 0

[limits]
read_registers = 4

[[span]]
table = "holding"
first = 0
last = 999

[[registers]]
number = 0
name = "speed"
label = "speed reference"
scale = 0.1
unit = "r/min"
access = "rw"

[[registers]]
number = 1
name = "position"
label = "target position"
type = "u32"
order = "ABCD"
access = "rw"

[[registers]]
number = 10
name = "mode"
label = "control mode"
access = "rw"
values = { "73" = "auto", "1" = "manual" }

[[registers]]
number = 20
name = "limit"
label = "current limit"
scale = 0.01
unit = "A"
min = 0
max = 500
access = "rw"

[[inputs]]
number = 0
name = "firmware"
label = "firmware version"

[[coils]]
number = 0
name = "enable"
label = "drive enable"
access = "rw"
"#;

fn backup_diff_restore(stack: Stack) {
    let Some(_turn) = require(&[stack.need()]) else { return };
    let server = peer_server(stack, Over::Tcp, UNIT);
    let dir = std::env::temp_dir().join(format!("ferrobus-custom-{}-{stack:?}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let profile = dir.join("map.toml");
    std::fs::write(&profile, PROFILE).unwrap();
    let device = profile.to_str().unwrap();
    let backup = dir.join("backup.toml");
    let file = backup.to_str().unwrap();
    let fb = ferrobus(&server.link).unit(UNIT);

    // The values of the data map, scaled and named; the hash names the exact profile file.
    fb.run(&["--device", device, "backup", "-o", file]).ok();
    let text = std::fs::read_to_string(&backup).unwrap();
    for want in [
        "# speed reference\nspeed = { raw = 3, value = \"0.3 r/min\" }\n",
        "# target position\nposition = { raw = 655377, value = \"655377\" }\n",
        "mode = { raw = 73, value = \"auto\" }\n",
        "limit = { raw = 143, value = \"1.43 A\" }\n",
        "enable = { raw = true, value = \"1\" }\n",
        "profile_hash = \"sha256:",
    ] {
        assert!(text.contains(want), "{stack:?}: {want:?} not in\n{text}");
    }
    assert!(!text.contains("firmware"), "a read-only input is not backed up:\n{text}");

    // get: named, scaled, with units, the enumeration decoded, the input register too.
    let got = fb.run(&["--device", device, "get", "speed", "position", "mode", "firmware", "--json"]).json();
    let values: Vec<(String, String)> = got["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| (p["code"].as_str().unwrap().to_string(), p["value"].as_str().unwrap().to_string()))
        .collect();
    let want = [("speed", "0.3 r/min"), ("position", "655377"), ("mode", "auto"), ("firmware", "4096")];
    assert_eq!(values, want.map(|(c, v)| (c.to_string(), v.to_string())), "{stack:?}: {got}");

    // set: in the parameter's unit, range-checked before sending, read back.
    fb.run(&["--device", device, "set", "speed", "25r/min"]).ok();
    // 6 A is above limit's 5.00 A: refused before sending (the diff below does not list limit).
    fb.run(&["--device", device, "set", "limit", "6A"]).code(2);
    // Then two more changes behind the profile's back.
    fb.run(&["write", "registers", "1", "0", "42"]).ok();
    fb.run(&["write", "coil", "0", "off"]).ok();
    let diff = fb.run(&["--device", device, "diff", file]).code(1).stdout;
    let codes: Vec<&str> = diff.lines().skip(1).filter_map(|l| l.split_whitespace().next()).collect();
    assert_eq!(codes, ["enable", "speed", "position"], "{stack:?}:\n{diff}");
    assert!(diff.contains("0.3 r/min") && diff.contains("25.0 r/min"), "{stack:?}:\n{diff}");

    // Dry run, then apply: only what differs, read back.
    let dry = fb.run(&["--device", device, "restore", file]).ok();
    assert_eq!(dry.matches("would write").count(), 3, "{stack:?}:\n{dry}");
    assert_eq!(fb.values(&["read", "holding", "0"]), words(&[250]), "the dry run wrote nothing");
    let applied = fb.run(&["--device", device, "restore", file, "--apply"]).ok();
    assert_eq!(applied.matches("written, verified").count(), 3, "{stack:?}:\n{applied}");
    let same = fb.run(&["--device", device, "diff", file]).ok();
    assert!(same.contains("agree on all 5 parameters"), "{stack:?}:\n{same}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_custom_profile_gets_sets_backs_up_diffs_and_restores_the_libmodbus_server() {
    backup_diff_restore(Stack::Libmodbus);
}

#[test]
fn a_custom_profile_gets_sets_backs_up_diffs_and_restores_the_pymodbus_server() {
    backup_diff_restore(Stack::Pymodbus);
}
