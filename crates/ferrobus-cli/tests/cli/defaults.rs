//! `diff --defaults`: what was changed from the factory default, on the simulated 3G3RX after
//! `set` of two parameters, and on a backup of it offline; the parameters whose default the
//! profile does not give are counted, not compared.

use assert_cmd::assert::OutputAssertExt;
use serde_json::Value;

use crate::backup::{TcpSim, temp};
use crate::server::{ferrobus, stderr, stdout};

#[test]
fn diff_defaults_lists_exactly_the_parameters_set_away_from_their_default_on_the_device_and_in_a_backup() {
    let sim = TcpSim::start(&["--profile", "omron-3g3rx"]);
    // The simulator starts every parameter at its default.
    let fresh = sim.run("omron-3g3rx", &["diff", "--defaults"]).success();
    assert!(stdout(&fresh).starts_with("unit 1: all "), "{}", stdout(&fresh));
    let json: Value =
        serde_json::from_str(&stdout(&sim.run("omron-3g3rx", &["diff", "--defaults", "--json"]).success())).unwrap();
    let (compared, unknown) = (json["compared"].as_u64().unwrap(), json["no_default"].as_array().unwrap().len());
    assert!(compared >= 2 && unknown > 0, "{json}");
    assert!(json["no_default"].as_array().unwrap().contains(&"A011".into()), "A011 has no default: {json}");
    assert!(
        stderr(&fresh).contains(&format!(
            "diff --defaults: 0 of {compared} parameters of unit 1 differ from the profile's default; {unknown} more \
             have no default in the profile and were not compared"
        )),
        "{}",
        stderr(&fresh)
    );

    sim.run("omron-3g3rx", &["set", "F002", "12.5s"]).success();
    sim.run("omron-3g3rx", &["set", "A003", "50"]).success();
    let expected =
        "code,label,value,default,unit\nF002,acceleration time 1,12.50,10.00,s\nA003,base frequency,50,60,Hz\n";
    let changed = sim.run("omron-3g3rx", &["diff", "--defaults", "--csv"]).code(1);
    assert_eq!(stdout(&changed), expected);
    let json: Value =
        serde_json::from_str(&stdout(&sim.run("omron-3g3rx", &["diff", "--defaults", "--json"]).code(1))).unwrap();
    assert_eq!(json["equal"], false);
    assert_eq!(json["changed"][0]["value"], serde_json::json!({ "raw": 1250, "value": "12.50 s" }), "{json}");
    assert_eq!(json["changed"][0]["default"], serde_json::json!({ "raw": 1000, "value": "10.00 s" }), "{json}");

    // The same from a backup, offline: the file names its profile.
    let path = temp("defaults.toml");
    let file = path.to_str().unwrap();
    sim.run("omron-3g3rx", &["backup", "-o", file]).success();
    drop(sim);
    let offline = ferrobus().args(["diff", "--defaults", file, "--csv"]).assert().code(1);
    assert_eq!(stdout(&offline), expected);
    // A parameter with a default but no value in the file cannot be compared: exit 7, named.
    let text = std::fs::read_to_string(&path).unwrap();
    let holed = text.replace("F003 = { raw = 1000, value = \"10.00 s\" }", "F003 = { error = \"no reply\" }");
    assert_ne!(holed, text);
    std::fs::write(&path, holed).unwrap();
    let err = stderr(&ferrobus().args(["diff", "--defaults", file]).assert().code(7));
    assert!(
        err.contains("1 parameter with a default could not be compared (F003): the backup holds no value: no reply"),
        "{err}"
    );
    let refused = stderr(&ferrobus().args(["diff", "--defaults", file, file]).assert().code(2));
    assert!(refused.contains("'--defaults' cannot be used with '[OTHER]'"), "{refused}");
    std::fs::remove_file(&path).unwrap();
}
