//! `--device PROFILE` with `get`, `set` and `profile`: named parameters against `ferrobus sim`
//! serving the same profile, and against the in-process server where the requests sent must
//! be seen (or proven absent).

use assert_cmd::assert::OutputAssertExt;

use crate::server::{Seen, Server, Sim, ferrobus, offline, stderr, stdout};

/// A test profile's path: a labelled copy of the 3G3RX (`rx-test.toml`) or every type
/// (`types.toml`).
fn profile(name: &str) -> String {
    format!("{}/tests/profiles/{name}", env!("CARGO_MANIFEST_DIR"))
}

/// The row of `code` in a table.
fn row<'a>(out: &'a str, code: &str) -> &'a str {
    out.lines()
        .find(|l| l.split_whitespace().next() == Some(code))
        .unwrap_or_else(|| panic!("no row {code} in:\n{out}"))
}

/// The cells of a row: columns are two or more spaces apart.
fn cells(line: &str) -> Vec<&str> {
    line.split("  ").map(str::trim).filter(|c| !c.is_empty()).collect()
}

#[test]
fn get_shows_the_3g3rx_values_scaled_with_units_labels_and_enumerations() {
    let rx = profile("rx-test.toml");
    let sim = Sim::pty(&["--profile", &rx]);
    sim.run(1, &["--device", &rx, "set", "F001", "45Hz"]).success();
    let out = stdout(&sim.run(1, &["--device", &rx, "get", "F001", "F002", "status-a", "A001", "--raw"]).success());
    assert_eq!(cells(row(&out, "F001")), ["F001", "output frequency setting", "45.00 Hz", "4500 (0x00001194)"]);
    assert_eq!(cells(row(&out, "F002")), ["F002", "acceleration time 1", "10.00 s", "1000 (0x000003e8)"]);
    assert_eq!(cells(row(&out, "status-a")), ["status-a", "status", "stop", "2 (0x0002)"]);
    assert_eq!(cells(row(&out, "A001")), ["A001", "frequency reference source", "modbus", "3 (0x0003)"]);
    // Labels, globs and groups name the same points, case-insensitively.
    let by_label = stdout(&sim.run(1, &["--device", &rx, "get", "Output Frequency Setting"]).success());
    assert_eq!(cells(row(&by_label, "F001"))[2], "45.00 Hz");
    let monitor = stdout(&sim.run(1, &["--device", &rx, "get", "--group", "monitor", "--csv"]).success());
    let codes: Vec<&str> = monitor.lines().skip(1).map(|l| l.split(',').next().unwrap()).collect();
    assert_eq!(codes, ["status-a", "d001", "d002", "d003"]);
    let globbed = stdout(&sim.run(1, &["--device", &rx, "get", "d00*"]).success());
    assert_eq!(globbed.lines().count(), 4, "d001, d002, d003 under a header: {globbed}");
}

#[test]
fn get_and_set_work_on_the_builtin_profiles_of_both_drives() {
    let sim = Sim::pty(&["--profile", "omron-3g3rx"]);
    sim.run(1, &["--device", "omron-3g3rx", "set", "F002", "12.5s"]).success();
    let out = stdout(&sim.run(1, &["--device", "omron-3g3rx", "get", "F002", "--json"]).success());
    let doc: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(doc["points"][0]["value"], "12.50 s");
    assert_eq!(doc["points"][0]["raw"], 1250);
    assert_eq!(doc["points"][0]["engineering"], 12.5);
    // The raw registers, high word first, as the drive holds them.
    let words = stdout(&sim.run(1, &["read", "holding", "--one-based", "0x1103", "--count", "2", "--csv"]).success());
    assert!(words.contains(",0\n") && words.contains(",1250\n"), "{words}");
    // With --device, the manual's numbering and the drive's limits need no options.
    let typed = stdout(
        &sim.run(1, &["--device", "omron-3g3rx", "read", "holding", "0x1103", "--type", "u32", "--csv"]).success(),
    );
    assert!(typed.lines().nth(1).is_some_and(|l| l.ends_with(",1250")), "{typed}");

    let servo = Sim::pty(&["--profile", "sdp-servo"]);
    let set =
        stdout(&servo.run(1, &["--device", "sdp-servo", "set", "speed-command", "-1500r/min", "--json"]).success());
    let doc: serde_json::Value = serde_json::from_str(&set).unwrap();
    assert_eq!(doc["read_back"]["value"], "-1500 r/min");
    // CDAB: the low word first, as the manual's example (0BB8h then 0000h for 3000).
    let words = stdout(&servo.run(1, &["read", "holding", "0x0112", "--count", "2", "--csv"]).success());
    let values: Vec<&str> = words.lines().skip(1).map(|l| l.rsplit(',').next().unwrap()).collect();
    assert_eq!(values, ["64036", "65535"], "-1500 = 0xFFFF_FA24: FA24h, then FFFFh");
    let speed = stdout(&servo.run(1, &["--device", "sdp-servo", "get", "motor-speed", "torque"]).success());
    assert!(row(&speed, "motor-speed").contains("r/min"), "{speed}");
}

#[test]
fn every_type_and_order_is_served_by_the_sim_and_read_and_written_by_name() {
    let types = profile("types.toml");
    let sim = Sim::pty(&["--profile", &types]);
    let out = stdout(&sim.run(1, &["--device", &types, "get", "*", "--json"]).success());
    let doc: serde_json::Value = serde_json::from_str(&out).unwrap();
    let value = |code: &str| {
        doc["points"].as_array().unwrap().iter().find(|p| p["code"] == code).unwrap()["value"]
            .as_str()
            .unwrap()
            .to_string()
    };
    assert_eq!(value("u16"), "65535");
    assert_eq!(value("i16"), "-2");
    assert_eq!(value("u32-abcd"), "287454020");
    assert_eq!(value("i32-default-order"), "-100000");
    assert_eq!(value("u32-badc"), "287454020");
    assert_eq!(value("u32-dcba"), "287454020");
    assert_eq!(value("u64"), "1234605616436508552");
    assert_eq!(value("i64"), "-5");
    assert_eq!(value("f32"), "1.5 bar");
    assert_eq!(value("f64"), "-2.25");
    assert_eq!(value("tag"), "PUMP-7");
    assert_eq!(value("temperature"), "25.0 °C");
    assert_eq!(value("alarms"), "overheat, low level");
    // The words on the wire, in each entry's order (the device default is CDAB).
    // --device sets read's limit (8 here): 28 registers in four requests.
    let words = stdout(&sim.run(1, &["--device", &types, "read", "holding", "0", "--count", "28", "--csv"]).success());
    let w: Vec<u16> = words.lines().skip(1).map(|l| l.rsplit(',').next().unwrap().parse().unwrap()).collect();
    assert_eq!(w[2..4], [0x1122, 0x3344], "ABCD");
    assert_eq!(w[4..6], [0x7960, 0xFFFE], "CDAB by default: -100000 = 0xFFFE7960");
    assert_eq!(w[6..8], [0x2211, 0x4433], "BADC");
    assert_eq!(w[8..10], [0x4433, 0x2211], "DCBA");
    assert_eq!(w[10..14], [0x1122, 0x3344, 0x5566, 0x7788], "u64 ABCD");
    assert_eq!(w[14..18], [0xFBFF, 0xFFFF, 0xFFFF, 0xFFFF], "i64 DCBA: -5");
    assert_eq!(w[18..20], [0x3FC0, 0x0000], "f32 1.5");
    assert_eq!(w[24..28], [0x5055, 0x4D50, 0x2D37, 0x0000], "PUMP-7, NUL padded");
    // The device's order (CDAB) is read's default word order under --device; an option wins.
    let i32 = |extra: &[&str]| {
        let mut args = vec!["--device", types.as_str(), "read", "holding", "4", "--type", "i32", "--csv"];
        args.extend_from_slice(extra);
        stdout(&sim.run(1, &args).success()).lines().nth(1).unwrap().rsplit(',').next().unwrap().to_string()
    };
    assert_eq!(i32(&[]), "-100000");
    assert_eq!(i32(&["--word-order", "high-first"]), 0x7960_FFFEu32.cast_signed().to_string());
    // Written by name, in its unit, and read back.
    for (code, value, shown) in [
        ("f64", "6.5", "6.5"),
        ("tag", "AB", "AB"),
        ("temperature", "20°C", "20.0 °C"),
        ("u64", "0xFFFFFFFFFFFFFFFF", "18446744073709551615"),
        ("i16", "-300", "-300"),
    ] {
        let out = stdout(&sim.run(1, &["--device", &types, "set", code, value, "--json"]).success());
        let doc: serde_json::Value = serde_json::from_str(&out).unwrap();
        assert_eq!(doc["read_back"]["value"], shown, "{code} = {value}: {out}");
    }
}

#[test]
fn get_reads_in_the_planners_fewest_requests_within_the_devices_limit() {
    let server = Server::start();
    let out = stdout(&server.run(&["--device", &profile("types.toml"), "get", "*", "--json"]).success());
    let doc: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(doc["requests"], 5);
    let seen = server.take_requests();
    let expected =
        [(0, 8), (8, 6), (14, 6), (20, 8), (28, 2)].map(|(start, quantity)| Seen { function: 3, start, quantity });
    assert_eq!(seen, expected, "8 registers a request at most, no value split");
}

#[test]
fn a_value_out_of_range_is_refused_before_anything_is_sent() {
    let server = Server::start();
    let err = stderr(&server.run(&["--device", "omron-3g3rx", "set", "F001", "500Hz"]).code(2));
    assert_eq!(err.trim(), "error: not sent: F001: 500Hz is out of range: 0.00 Hz to 400.00 Hz");
    // The user's notation is kept: a value typed in hex is shown in hex.
    let err = stderr(&server.run(&["--device", "omron-3g3rx", "set", "A001", "0x20"]).code(2));
    assert_eq!(err.trim(), "error: not sent: A001: 0x20 is out of range: 0 to 10");
    let err = stderr(&server.run(&["--device", "omron-3g3rx", "set", "F002", "12.505s"]).code(2));
    assert_eq!(err.trim(), "error: not sent: F002: 12.505s is not a multiple of its step 0.01 s");
    let err = stderr(&server.run(&["--device", "omron-3g3rx", "set", "F002", "12Hz"]).code(2));
    assert_eq!(err.trim(), "error: not sent: F002: \"12Hz\" is not in s, the unit of F002");
    let err = stderr(&server.run(&["--device", "omron-3g3rx", "set", "d001", "1"]).code(2));
    assert_eq!(err.trim(), "error: not sent: d001 is read-only");
    assert_eq!(server.take_requests(), [], "no frame went out");
}

#[test]
fn a_run_locked_parameter_is_refused_while_the_drive_runs_after_reading_only_the_run_state() {
    let server = Server::start();
    // The test profile's [state] running is the coil "running", number 0x000F: wire 14.
    server.device().coils[14] = true;
    let err = stderr(&server.run(&["--device", &profile("rx-test.toml"), "set", "A001", "modbus"]).code(2));
    assert_eq!(err.trim(), "error: not sent: A001 cannot change while the drive runs (running = 1); stop it first");
    assert_eq!(server.take_requests(), [Seen { function: 1, start: 14, quantity: 1 }], "one read, no write");

    // And against the simulated drive: started by the run coil.
    let rx = profile("rx-test.toml");
    let sim = Sim::pty(&["--profile", &rx]);
    sim.run(1, &["--device", &rx, "set", "F001", "10Hz"]).success();
    sim.run(1, &["--device", &rx, "set", "run", "1"]).success();
    let err = stderr(&sim.run(1, &["--device", &rx, "set", "A003", "50Hz"]).code(2));
    assert!(err.contains("not sent: A003 cannot change while the drive runs (running = 1)"), "{err}");
    let a003 = stdout(&sim.run(1, &["--device", &rx, "get", "A003"]).success());
    assert_eq!(cells(row(&a003, "A003"))[2], "60 Hz", "unchanged");
    // A parameter that may change while running is written.
    sim.run(1, &["--device", &rx, "set", "F001", "20Hz"]).success();
}

#[test]
fn the_devices_refusal_is_explained_in_the_profiles_words() {
    let rx = profile("rx-test.toml");
    let sim = Sim::pty(&["--profile", &rx, "--fault", "1:fc=0x06,addr=0x1200,exception=0x21"]);
    let err = stderr(&sim.run(1, &["--device", &rx, "set", "A001", "control terminal"]).code(1));
    assert_eq!(
        err.trim(),
        "error: the device refused A001 = control terminal: exception 0x21 (data outside the inverter's range)"
    );
}

#[test]
fn a_point_the_device_refuses_is_reported_and_the_others_still_print() {
    let rx = profile("rx-test.toml");
    let sim = Sim::pty(&["--profile", &rx, "--fault", "1:fc=0x03,addr=0x1003,exception=0x22"]);
    let assert = sim.run(1, &["--device", &rx, "get", "d001", "d002", "d003"]).code(1);
    let out = stdout(&assert);
    assert_eq!(cells(row(&out, "d001"))[2], "0.00 Hz");
    assert_eq!(cells(row(&out, "d002"))[2], "0.00 A");
    assert_eq!(
        cells(row(&out, "d003"))[2],
        "error: exception 0x22 (the inverter restricts execution: read-only, run-locked or tripped)"
    );
    assert_eq!(stderr(&assert).trim(), "error: 1 of 3 parameters could not be read: d003");
}

#[test]
fn get_and_set_need_a_device_and_known_names() {
    let err = stderr(&offline(&["--tcp", "127.0.0.1:1", "get", "d001"]).code(2));
    assert!(
        err.contains("get needs --device PROFILE: a built-in one (omron-3g3rx, sdp-servo, generic, sunspec-inverter)"),
        "{err}"
    );
    let err = stderr(&offline(&["--tcp", "127.0.0.1:1", "--device", "omron-3g3rx", "get", "x999"]).code(2));
    assert!(err.contains("omron-3g3rx has no parameter \"x999\""), "{err}");
    let err = stderr(&offline(&["--tcp", "127.0.0.1:1", "--device", "omron-3g3rx", "set", "d00*", "1"]).code(2));
    assert!(
        err.contains(
            "\"d00*\" names 9 parameters (d001, d002, d003, d004, d005, d006, d007, d008, d009): set one at a time"
        ),
        "{err}"
    );
    let err = stderr(&offline(&["--tcp", "127.0.0.1:1", "--device", "./nope.toml", "get", "x"]).code(2));
    assert_eq!(err.trim(), "error: profile ./nope.toml: no such file");
}

#[test]
fn profile_check_names_the_file_and_line_of_a_mistake() {
    let dir = std::env::temp_dir().join(format!("ferrobus-cli-profile-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.toml");
    std::fs::write(
        &bad,
        "[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\n\n[[registers]]\nnumber=1\nname='r'\ntype='u32'\nbits={ '40' = 'x' }\n",
    )
    .unwrap();
    let shown = bad.display().to_string();
    let err = stderr(&offline(&["profile", "check", &shown]).code(2));
    assert_eq!(
        err.trim(),
        format!(
            "{shown}:11:1: [[registers]] 1 (r): bits key \"40\" is not a bit from 0 to 31 (in `bits={{ '40' = 'x' }}`)\n\
             error: {shown}: 1 mistake"
        )
    );
    let unknown = dir.join("unknown.toml");
    std::fs::write(&unknown, "[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\ncolour='red'\n").unwrap();
    let err = stderr(&offline(&["profile", "check", &unknown.display().to_string()]).code(2));
    assert!(err.starts_with(&format!("{}:6:1: [device]: unknown field `colour`", unknown.display())), "{err}");
    let out = stdout(&offline(&["profile", "check", &profile("types.toml")]).success());
    assert!(out.ends_with("types.toml: ok: ferrobus type test device — 0 coils, 0 discrete inputs, 13 holding and 0 input register values\n"), "{out}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn profile_check_lists_every_mistake_of_a_profile_in_one_run_and_exits_2() {
    let dir = std::env::temp_dir().join(format!("ferrobus-cli-mistakes-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("three.toml");
    std::fs::write(
        &bad,
        "[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\n\n[[registers]]\nnumber=1\nname='a'\n\
         scale=0\n\n[[registers]]\nnumber=2\nname='b'\ntype='u16'\nvalues={ 'x' = 'on' }\n\n[[registers]]\n\
         number=1\nname='c'\n",
    )
    .unwrap();
    let shown = bad.display().to_string();
    let err = stderr(&offline(&["profile", "check", &shown]).code(2));
    let places: Vec<&str> = err.lines().filter_map(|l| l.split(": ").next()).collect();
    let at = |place: &str| format!("{shown}:{place}");
    assert_eq!(places, [at("10:1"), at("16:1"), at("18:1"), "error".to_string()], "{err}");
    assert!(err.ends_with(&format!("error: {shown}: 3 mistakes\n")), "{err}");
    let json = stdout(&offline(&["profile", "check", &shown, "--json"]).code(2));
    let doc: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(doc["ok"], false);
    assert_eq!(doc["mistakes"].as_array().map(Vec::len), Some(3), "{json}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn profile_check_of_a_10_mb_line_or_a_binary_file_prints_a_few_hundred_bytes_with_line_and_column() {
    let dir = std::env::temp_dir().join(format!("ferrobus-cli-huge-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let huge = dir.join("huge.toml");
    let line = format!("[device]\nname = '{}\n", "x".repeat(10 << 20));
    std::fs::write(&huge, line).unwrap();
    let err = stderr(&offline(&["profile", "check", &huge.display().to_string()]).code(2));
    assert!(err.len() < 2_000, "{} bytes of stderr", err.len());
    assert!(err.starts_with(&format!("{}:2:", huge.display())) && err.contains('…'), "{err}");
    let binary = dir.join("binary.toml");
    std::fs::write(&binary, b"\x7fELF\x02\x01\x01\0\0\0\0\0\0\0\0\0\n\x03\0\xff").unwrap();
    let err = stderr(&offline(&["profile", "check", &binary.display().to_string()]).code(2));
    assert!(err.starts_with(&format!("{}:2:3: byte 0xFF is not UTF-8 text", binary.display())), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn profile_list_and_show_print_the_profiles_and_their_parameter_tables() {
    let list = stdout(&offline(&["profile", "list"]).success());
    for name in ["omron-3g3rx", "sdp-servo", "generic"] {
        assert!(list.lines().any(|l| l.starts_with(name)), "{list}");
    }
    let show = stdout(&offline(&["profile", "show", &profile("rx-test.toml"), "--group", "basic"]).success());
    let f001 = cells(row(&show, "F001"));
    assert_eq!(
        f001,
        [
            "F001",
            "output frequency setting",
            "holding",
            "0x0001",
            "u32 ABCD",
            "rw",
            "Hz",
            "0.00 Hz .. 400.00 Hz",
            "basic"
        ]
    );
    let a001 = stdout(&offline(&["profile", "show", &profile("rx-test.toml"), "--group", "A"]).success());
    assert!(row(&a001, "A001").contains("rw stopped"), "run-locked: {a001}");
    let json = stdout(&offline(&["profile", "show", "sdp-servo", "--json"]).success());
    let doc: serde_json::Value = serde_json::from_str(&json).unwrap();
    let speed = doc["points"].as_array().unwrap().iter().find(|p| p["code"] == "speed-command").unwrap().clone();
    assert_eq!((speed["type"].as_str(), speed["order"].as_str()), (Some("i32"), Some("CDAB")));
    // What a profile says of a point's factory value and of how the device marks it absent.
    let dir = std::env::temp_dir().join(format!("ferrobus-cli-show-ni-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("meter.toml");
    std::fs::write(
        &file,
        "[device]\nname = \"meter\"\nvendor = \"v\"\nproduct_code = \"p\"\nrevision = \"1\"\nidentification = false\n\n\
         [[inputs]]\nnumber = 0\nname = \"temp\"\ntype = \"i16\"\nnot_implemented = -32768\ndefault = 215\n\n\
         [[inputs]]\nnumber = 1\nname = \"hz\"\ntype = \"f32\"\nnot_implemented = nan\n\n\
         [[inputs]]\nnumber = 3\nname = \"absent\"\nimplemented = false\n",
    )
    .unwrap();
    let json = stdout(&offline(&["profile", "show", file.to_str().unwrap(), "--json"]).success());
    std::fs::remove_dir_all(&dir).unwrap();
    let doc: serde_json::Value = serde_json::from_str(&json).unwrap();
    let point = |code: &str| doc["points"].as_array().unwrap().iter().find(|p| p["code"] == code).unwrap().clone();
    let temp = point("temp");
    assert_eq!((temp["not_implemented"].as_i64(), temp["default"].as_i64()), (Some(-32768), Some(215)), "{temp}");
    assert_eq!(point("hz")["not_implemented"].as_str(), Some("nan"));
    let absent = point("absent");
    assert_eq!((absent["implemented"].as_bool(), absent["not_implemented"].is_null()), (Some(false), true));
    assert!(absent["default"].is_null() && temp["implemented"] == true, "{absent}");
}

#[test]
fn profile_commands_need_no_bus() {
    let out = ferrobus().args(["profile", "list", "--csv"]).assert().success();
    assert!(stdout(&out).starts_with("name,device,vendor,points\n"));
}

#[test]
fn read_and_write_take_a_parameter_name_where_an_address_goes_and_type_it_whole() {
    let sim = Sim::pty(&["--profile", "omron-3g3rx"]);
    let rx = ["--device", "omron-3g3rx"];
    let run = |args: &[&str]| sim.run(1, &[&rx[..], args].concat());
    let read = stdout(&run(&["read", "holding", "F002", "--csv"]).success());
    assert_eq!(
        read, "address,addr_hex,hex,dec,u32\n4354,0x1102,0x0000 0x03E8,0 1000,1000\n",
        "both registers, as a u32"
    );
    let wrote = stdout(&run(&["write", "register", "F002", "1500"]).success());
    assert_eq!(wrote, "unit 1: FC10 wrote 2 registers at 4354 (0x1102): 0x0000 0x05DC (u32 1500)\n");
    let doc: serde_json::Value = serde_json::from_str(&stdout(&run(&["get", "F002", "--json"]).success())).unwrap();
    assert_eq!(doc["points"][0]["value"], "15.00 s");
    run(&["write", "coil", "run", "on"]).success();
    assert!(stdout(&run(&["read", "coils", "run", "--csv"]).success()).ends_with(",1,ON\n"));
    let err = stderr(&run(&["read", "input", "F002"]).code(2));
    assert_eq!(err.trim(), "error: F002 is in the holding table, not input");
    let err = stderr(&run(&["read", "holding", "d00*"]).code(2));
    assert_eq!(
        err.trim(),
        "error: \"d00*\" names 9 parameters (d001, d002, d003, d004, d005, d006, d007, d008, d009): give one, or use get"
    );
}

const DEVICE: &str = "[device]\nname='x'\nvendor='v'\nproduct_code='p'\nrevision='1'\n";

/// `profile check` of a file holding `text`: its exit, stderr and stdout.
fn check(name: &str, text: &str) -> (Option<i32>, String) {
    let dir = std::env::temp_dir().join(format!("ferrobus-cli-check-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join(format!("{name}.toml"));
    std::fs::write(&file, text).unwrap();
    let out = offline(&["profile", "check", &file.display().to_string()]);
    let code = out.get_output().status.code();
    let err = stderr(&out);
    std::fs::remove_dir_all(&dir).unwrap();
    (code, err)
}

#[test]
fn profile_check_reports_seven_type_errors_in_seven_entries_in_one_run() {
    let text = format!(
        "{DEVICE}[[registers]]\nnumber = 'one'\nname = 'a'\n[[registers]]\nnumber = 2\nname = 'b'\ntype = 'u24'\n\
         [[registers]]\nnumber = 3\nname = 'c'\nscale = 'ten'\n[[inputs]]\nnumber = 1\nname = 'd'\ncolour = 1\n\
         [[coils]]\nnumber = 1\nname = 'e'\ndefault = 'on'\n[[coils]]\nnumber = -2\nname = 'f'\n\
         [[discrete_inputs]]\nnumber = 1\nname = 'g'\naccess = 'all'\n"
    );
    let (code, err) = check("seven", &text);
    assert_eq!(code, Some(2), "{err}");
    let mistakes: Vec<&str> = err.lines().filter(|l| !l.starts_with("error:")).collect();
    assert_eq!(mistakes.len(), 7, "{err}");
    for (mistake, entry) in mistakes.iter().zip([
        "[[registers]] entry 1 (a): invalid type",
        "[[registers]] 2 (b): unknown variant `u24`",
        "[[registers]] 3 (c): invalid type",
        "[[inputs]] 1 (d): unknown field `colour`",
        "[[coils]] 1 (e): invalid type",
        "[[coils]] entry 2 (f): invalid value",
        "[[discrete_inputs]] 1 (g): unknown variant `all`",
    ]) {
        assert!(mistake.contains(entry), "{mistake:?} names {entry:?}");
    }
    assert!(err.ends_with(": 7 mistakes\n"), "{err}");
}

#[test]
fn profile_check_refuses_two_points_of_one_code_naming_both_entries() {
    let (code, err) = check(
        "twice",
        &format!("{DEVICE}[[registers]]\nnumber=1\nname='F001'\n[[registers]]\nnumber=5\nname='F001'\n"),
    );
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains(":9:1: [[registers]] 5 (F001): the name is also that of [[registers]] 1 (F001) on line 6"),
        "{err}"
    );
    let (code, err) = check(
        "run",
        &format!("{DEVICE}[[coils]]\nnumber=1\nname='DI'\ncount=4\n[[registers]]\nnumber=1\nname='di3'\n"),
    );
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("[[registers]] 1 (di3): its point di3 has the code of a point of [[coils]] 1 (DI) on line 6"),
        "{err}"
    );
}

#[test]
fn profile_check_refuses_control_characters_and_endless_names_and_says_what_it_saw() {
    let (code, err) = check("escape", &format!("{DEVICE}[[registers]]\nnumber=1\nname='r'\nunit=\"\\u001b[2J\"\n"));
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("[[registers]] 1 (r): unit holds the control character \\u{1b} at character 1"), "{err}");
    assert!(!err.contains('\u{1b}'), "nothing reaches the terminal raw: {err:?}");
    let (code, err) = check("nul", &format!("{DEVICE}[[coils]]\nnumber=1\nname=\"c\\u0000\"\n"));
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("name holds the control character \\u{0}"), "{err}");
    let (code, err) = check("long", &format!("{DEVICE}[[registers]]\nnumber=1\nname='{}'\n", "n".repeat(10 << 20)));
    assert_eq!(code, Some(2), "{err}");
    assert!(err.len() < 2_000, "{} bytes", err.len());
    assert!(err.contains(&format!("name is {} characters long, more than the 128 a name may have", 10 << 20)), "{err}");
}

#[test]
fn a_string_read_from_a_device_reaches_the_terminal_with_its_control_characters_spelled_out() {
    let server = Server::start();
    // The types profile's "tag" (number 24, 4 registers): ESC [ 2 J, then NUL padding.
    server.device().holding[24..28].copy_from_slice(&[0x1B5B, 0x324A, 0, 0]);
    let out = stdout(&server.run(&["--device", &profile("types.toml"), "get", "tag"]).success());
    assert!(!out.contains('\u{1b}'), "{out:?}");
    assert!(row(&out, "tag").ends_with("\\u{1b}[2J"), "{out}");
    let csv = stdout(&server.run(&["--device", &profile("types.toml"), "get", "tag", "--csv"]).success());
    assert!(csv.lines().nth(1).is_some_and(|l| l.ends_with(",\\u{1b}[2J")), "{csv}");
}
