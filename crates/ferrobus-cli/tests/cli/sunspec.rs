//! SunSpec: `scan --sunspec` and `--device sunspec` against `ferrobus sim --profile
//! sunspec-inverter --tcp` (common model 1 and inverter model 103 at 40000), the same layout
//! moved to 0 and 50000, and broken chains. Needs the model definitions built in (pysunspec2,
//! installed by .ci/setup-peers.sh).

use assert_cmd::assert::OutputAssertExt;
use serde_json::Value;

use crate::server::{TcpSim, ferrobus, stderr, stdout};

/// The built-in profile's text.
fn inverter() -> String {
    let path = format!("{}/../ferrobus-profile/profiles/sunspec-inverter.toml", env!("CARGO_MANIFEST_DIR"));
    std::fs::read_to_string(path).unwrap()
}

/// `text` with every `number = N` moved by `to - 40000`.
fn moved(text: &str, to: u32) -> String {
    text.lines()
        .map(|line| match line.strip_prefix("number = ").and_then(|n| n.parse::<u32>().ok()) {
            Some(n) => format!("number = {}", n - 40000 + to),
            None => line.to_string(),
        })
        .collect::<Vec<_>>()
        .join("\n")
}

fn models(doc: &Value) -> Vec<(u64, String, u64, u64, bool)> {
    doc["models"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| {
            (
                m["id"].as_u64().unwrap(),
                m["name"].as_str().unwrap_or("?").to_string(),
                m["start"].as_u64().unwrap(),
                m["length"].as_u64().unwrap(),
                m["fits"].as_bool().unwrap_or(false),
            )
        })
        .collect()
}

#[test]
fn scan_sunspec_lists_the_simulated_inverters_models_with_their_starts_and_lengths() {
    let sim = TcpSim::builtin("sunspec-inverter");
    let table = stdout(&sim.run(&["scan", "--sunspec"]).success());
    assert!(table.contains("\"SunS\" at 40000, 2 models"), "{table}");
    let rows: Vec<Vec<&str>> = table.lines().skip(2).map(|l| l.split_whitespace().collect()).collect();
    assert_eq!(rows, [["1", "common", "40002", "66", "ok"], ["103", "inverter_three_phase", "40070", "50", "ok"]]);
    let doc: Value = serde_json::from_str(&stdout(&sim.run(&["scan", "--sunspec", "--json"]).success())).unwrap();
    assert_eq!(doc["base"], 40000);
    assert_eq!(
        models(&doc),
        [(1, "common".into(), 40002, 66, true), (103, "inverter_three_phase".into(), 40070, 50, true)]
    );
}

#[test]
fn the_chain_is_found_at_0_and_at_50000_as_well() {
    for base in [0, 50000] {
        let sim = TcpSim::text(&format!("at{base}"), &moved(&inverter(), base));
        let doc: Value = serde_json::from_str(&stdout(&sim.run(&["scan", "--sunspec", "--json"]).success())).unwrap();
        assert_eq!(doc["base"], base);
        let starts: Vec<(u64, u64)> = models(&doc).iter().map(|m| (m.0, m.2)).collect();
        assert_eq!(starts, [(1, u64::from(base) + 2), (103, u64::from(base) + 70)]);
    }
}

#[test]
fn a_length_that_does_not_fit_the_definition_is_listed_with_what_differs() {
    let text = inverter().replace(
        "name = \"inverter.L\"\ngroup = \"inverter\"\ndefault = 50",
        "name = \"inverter.L\"\ngroup = \"inverter\"\ndefault = 48",
    );
    assert_ne!(text, inverter());
    let sim = TcpSim::text("short", &text);
    let doc: Value = serde_json::from_str(&stdout(&sim.run(&["scan", "--sunspec", "--json"]).success())).unwrap();
    let inverter = &doc["models"][1];
    assert_eq!(
        (inverter["id"].as_u64(), inverter["length"].as_u64(), inverter["fits"].as_bool()),
        (Some(103), Some(48), Some(false))
    );
    assert_eq!(inverter["problem"], "the definition takes 50 registers after the header, the device says L = 48");
}

#[test]
fn a_chain_without_an_end_marker_or_without_suns_is_a_clear_error() {
    let cut = inverter().split("[[registers]]\nnumber = 40122").next().unwrap().to_string();
    let sim = TcpSim::text("noend", &cut);
    let err = stderr(&sim.run(&["scan", "--sunspec"]).failure());
    assert!(err.contains("reading 2 registers at 40122 (the header after model 103 at 40070)"), "{err}");
    assert!(err.contains("exception"), "{err}");

    let sim = TcpSim::text("nomarker", &inverter().replace("default = \"SunS\"", "default = \"Sun?\""));
    let err = stderr(&sim.run(&["scan", "--sunspec"]).failure());
    assert!(err.contains("not a SunSpec device: no \"SunS\" at 40000, 0 or 50000 (40000: 0x5375 0x6E3F; 0: "), "{err}");
}

#[test]
fn get_with_device_sunspec_reads_named_points_with_the_scale_factors_applied() {
    let sim = TcpSim::builtin("sunspec-inverter");
    let out = stdout(
        &sim.run(&[
            "get",
            "--device",
            "sunspec",
            "inverter_three_phase.Hz",
            "inverter_three_phase.PhVphA",
            "inverter_three_phase.A",
            "inverter_three_phase.St",
            "inverter_three_phase.WH",
            "common.Mn",
            "--json",
        ])
        .success(),
    );
    let doc: Value = serde_json::from_str(&out).unwrap();
    let shown: Vec<(String, String)> = doc["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| (p["code"].as_str().unwrap().to_string(), p["value"].as_str().unwrap_or_default().to_string()))
        .collect();
    let want = [
        ("inverter_three_phase.Hz", "50.00 Hz"),
        ("inverter_three_phase.PhVphA", "230.0 V"),
        ("inverter_three_phase.A", "15.2 A"),
        ("inverter_three_phase.St", "MPPT"),
        ("inverter_three_phase.WH", "12345678 Wh"),
        ("common.Mn", "ferrobus"),
    ];
    assert_eq!(shown, want.map(|(c, s)| (c.to_string(), s.to_string())), "{out}");
}

#[test]
fn a_scale_factor_is_read_from_the_device_at_discovery() {
    let text = inverter().replace(
        "name = \"inverter.Hz_SF\"\ntype = \"i16\"\ngroup = \"inverter\"\ndefault = -2",
        "name = \"inverter.Hz_SF\"\ntype = \"i16\"\ngroup = \"inverter\"\ndefault = -1",
    );
    assert_ne!(text, inverter());
    let sim = TcpSim::text("sf", &text);
    let out = stdout(&sim.run(&["get", "--device", "sunspec", "inverter_three_phase.Hz", "--csv"]).success());
    assert!(out.lines().nth(1).is_some_and(|l| l.contains("500.0")), "Hz 5000 with Hz_SF -1: {out}");
}

#[test]
fn poll_and_backup_with_device_sunspec_read_the_discovered_points() {
    let sim = TcpSim::builtin("sunspec-inverter");
    let out = stdout(
        &sim.run(&[
            "poll",
            "--device",
            "sunspec",
            "inverter_three_phase.W",
            "--every",
            "50ms",
            "--duration",
            "120ms",
            "--csv",
        ])
        .success(),
    );
    let row = out.lines().nth(1).unwrap();
    assert!(row.contains(",inverter_three_phase.W,10000,10000,,W,ok,"), "{out}");

    let file = std::env::temp_dir().join(format!("ferrobus-sunspec-{}-backup.toml", std::process::id()));
    sim.run(&["backup", "--device", "sunspec", "-o", file.to_str().unwrap()]).success();
    let backup = std::fs::read_to_string(&file).unwrap();
    let _ = std::fs::remove_file(&file);
    assert!(backup.contains("profile = \"sunspec\""), "{backup}");
    assert!(backup.contains("\"common.DA\" = { raw = 1"), "the read/write point is saved: {backup}");
}

#[test]
fn device_sunspec_is_refused_where_nothing_discovers_it_and_bad_model_files_before_the_port_opens() {
    let sim = TcpSim::builtin("sunspec-inverter");
    let err = stderr(&sim.run(&["set", "--device", "sunspec", "common.DA", "2"]).failure());
    assert!(err.contains("--device sunspec works with get, poll and backup"), "{err}");
    // On a serial port the model definitions are read before the port is opened.
    let out = ferrobus()
        .args(["--port", "/dev/null", "scan", "--sunspec", "--sunspec-models", "/nonexistent/models"])
        .assert()
        .failure();
    assert!(stderr(&out).contains("/nonexistent/models"), "{}", stderr(&out));
    assert!(!stderr(&out).contains("opening /dev/null"), "{}", stderr(&out));
}

#[test]
fn save_profile_writes_the_models_as_a_profile_that_get_and_the_bridge_take() {
    let sim = TcpSim::builtin("sunspec-inverter");
    let dir = std::env::temp_dir().join(format!("ferrobus-sunspec-save-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("inverter.toml");
    let path = file.to_str().unwrap();
    let saved = sim.run(&["scan", "--sunspec", "--save-profile", path]).success();
    assert!(stderr(&saved).contains(&format!("scan: profile saved to {path}: ")), "{}", stderr(&saved));
    let text = std::fs::read_to_string(&file).unwrap();
    assert!(text.starts_with("# Written by `ferrobus scan --sunspec --save-profile` from sunspec at"), "{text}");
    let watts = stdout(&sim.run(&["--device", path, "get", "inverter_three_phase.W", "--json"]).success());
    let doc: Value = serde_json::from_str(&watts).unwrap();
    assert_eq!(doc["points"][0]["engineering"].as_f64(), Some(10000.0), "{doc}");
    // A second save does not replace the file.
    let again = sim.run(&["scan", "--sunspec", "--save-profile", path]).failure();
    assert!(stderr(&again).contains("exists"), "{}", stderr(&again));
    // The bridge's plant file takes it as a device's profile, its points by name.
    let plant = dir.join("plant.toml");
    std::fs::write(
        &plant,
        format!(
            "[broker]\naddress = \"127.0.0.1:1883\"\n[sparkplug]\ngroup_id = \"g\"\nedge_node_id = \"e\"\n\
             [[line]]\nname = \"pv\"\ntcp = \"{}\"\n[[line.device]]\nid = \"inverter\"\nunit = 1\n\
             profile = \"inverter.toml\"\nevery = \"1s\"\npoints = [\"inverter_three_phase.W\", \"common.SN\"]\n\
             groups = [\"inverter_three_phase\"]\n",
            sim.addr
        ),
    )
    .unwrap();
    let check = ferrobus().args(["bridge", "--check", "--config", plant.to_str().unwrap()]).assert().success();
    assert!(stdout(&check).contains("1 line, 1 device, 2 groups, 46 metrics"), "{}", stdout(&check));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn values_the_inverter_does_not_implement_show_as_not_implemented_not_as_readings() {
    // The simulated inverter holds TmpSnk = 0x8000 (int16) and StVnd = 0xFFFF (enum16); here
    // Evt1 = 0xFFFFFFFF (bitfield32) too; TmpCab = 451 (45.1 C) is a reading.
    let text = inverter().replace(
        "name = \"inverter.Evt1\"\ntype = \"u32\"\ngroup = \"inverter\"\ndefault = 0",
        "name = \"inverter.Evt1\"\ntype = \"u32\"\ngroup = \"inverter\"\ndefault = 4294967295",
    );
    assert_ne!(text, inverter());
    let sim = TcpSim::text("sentinels", &text);
    let codes = [
        "inverter_three_phase.TmpSnk",
        "inverter_three_phase.StVnd",
        "inverter_three_phase.Evt1",
        "inverter_three_phase.TmpCab",
    ];
    let get = |format: &[&str]| {
        let mut args = vec!["get", "--device", "sunspec"];
        args.extend(codes);
        args.extend(format);
        stdout(&sim.run(&args).success())
    };
    let table = get(&[]);
    let values: Vec<&str> = table.lines().skip(1).map(|l| l.rsplit("  ").next().unwrap_or_default()).collect();
    assert_eq!(values, ["n/a", "n/a", "n/a", "45.1 C"], "{table}");
    let csv = get(&["--csv"]);
    let last: Vec<&str> = csv.lines().skip(1).map(|l| l.rsplit(',').next().unwrap_or_default()).collect();
    assert_eq!(last, ["", "", "", "45.1 C"], "{csv}");
    let doc: Value = serde_json::from_str(&get(&["--json"])).unwrap();
    let points = doc["points"].as_array().unwrap();
    for p in &points[..3] {
        assert_eq!(
            (&p["value"], &p["engineering"], &p["implemented"]),
            (&Value::Null, &Value::Null, &Value::Bool(false)),
            "{p}"
        );
    }
    assert_eq!(points[0]["raw"], -32768, "the raw value is kept");
    assert_eq!((points[3]["engineering"].as_f64(), &points[3]["implemented"]), (Some(45.1), &Value::Bool(true)));
    let poll = stdout(
        &sim.run(&["poll", "--device", "sunspec", codes[0], "--every", "50ms", "--duration", "120ms", "--csv"])
            .success(),
    );
    assert!(poll.lines().nth(1).is_some_and(|l| l.contains(",inverter_three_phase.TmpSnk,-32768,,,C,ok,")), "{poll}");
}

#[test]
fn a_value_whose_scale_factor_is_not_implemented_is_not_implemented_either() {
    let text = inverter().replace(
        "name = \"inverter.Tmp_SF\"\ntype = \"i16\"\ngroup = \"inverter\"\ndefault = -1",
        "name = \"inverter.Tmp_SF\"\ntype = \"i16\"\ngroup = \"inverter\"\ndefault = -32768",
    );
    assert_ne!(text, inverter());
    let sim = TcpSim::text("nosf", &text);
    let out = stdout(&sim.run(&["get", "--device", "sunspec", "inverter_three_phase.TmpCab", "--json"]).success());
    let doc: Value = serde_json::from_str(&out).unwrap();
    let point = &doc["points"][0];
    assert_eq!(
        (&point["value"], &point["raw"], &point["implemented"]),
        (&Value::Null, &Value::from(451), &Value::Bool(false)),
        "{out}"
    );
}
