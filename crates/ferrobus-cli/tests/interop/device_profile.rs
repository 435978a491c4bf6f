//! A custom profile describing the peer servers' data map (tests/profiles/peer-map.toml),
//! used with `get` and `set` against the libmodbus and pymodbus servers: values scaled with
//! their units, a 32-bit pair in its order, bit fields, a refused point beside good ones, a
//! setpoint written in its unit and read back by name and by address.

use crate::support::{Ferrobus, Need, Over, Stack, ferrobus, peer_server, require, words};

/// The unit the peer servers serve here.
const UNIT: u8 = 9;

fn profile() -> String {
    format!("{}/tests/profiles/peer-map.toml", env!("CARGO_MANIFEST_DIR"))
}

fn with_server(stack: Stack, over: Over, check: impl FnOnce(&Ferrobus)) {
    let needs = if over == Over::Rtu { vec![stack.need(), Need::Socat] } else { vec![stack.need()] };
    let Some(_turn) = require(&needs) else { return };
    let server = peer_server(stack, over, UNIT);
    check(&ferrobus(&server.link).unit(UNIT));
}

/// The `"value"` of `code` in a `get --json` document.
fn value(doc: &serde_json::Value, code: &str) -> String {
    let points = doc["points"].as_array().expect("points");
    let point = points.iter().find(|p| p["code"] == code).unwrap_or_else(|| panic!("no {code} in {doc}"));
    point["value"].as_str().map_or_else(|| format!("error: {}", point["error"]), str::to_string)
}

fn get_and_set_speak_the_profile(fb: &Ferrobus) {
    let device = profile();
    let doc = fb
        .run(&[
            "--device",
            &device,
            "get",
            "h0",
            "pair",
            "voltage",
            "setpoint",
            "status",
            "run",
            "jog",
            "limit-switch",
            "--json",
        ])
        .json();
    assert_eq!(value(&doc, "h0"), "3");
    assert_eq!(value(&doc, "pair"), "1114122", "CDAB: register 2 (17) is the high word: 17 × 65536 + 10");
    assert_eq!(value(&doc, "voltage"), "2.4 V");
    assert_eq!(value(&doc, "setpoint"), "3.8 bar");
    assert_eq!(value(&doc, "status"), "ready", "0x1000: bit 12");
    assert_eq!(
        (value(&doc, "run"), value(&doc, "jog"), value(&doc, "limit-switch")),
        ("1".into(), "0".into(), "1".into())
    );
    // Registers 0..5 in one request of the profile's 10 (across the unmapped 4: the span says
    // the peer answers it), the input, the two coils, the input bit.
    assert_eq!(doc["requests"], 4);

    let set = fb.run(&["--device", &device, "set", "pressure setpoint", "12.3bar", "--json"]).json();
    assert_eq!(set["read_back"]["value"], "12.3 bar");
    assert_eq!(fb.values(&["read", "holding", "5"]), words(&[123]));
    fb.run(&["--device", &device, "set", "setpoint", "25bar"]).code(2);
    assert_eq!(fb.values(&["read", "holding", "5"]), words(&[123]), "refused before sending");
    fb.run(&["--device", &device, "set", "jog", "on"]).ok();
    assert_eq!(value(&fb.run(&["--device", &device, "get", "jog", "--json"]).json(), "jog"), "1");

    // The register past the peer's map is refused; the one beside it still prints.
    let run = fb.run(&["--device", &device, "get", "last", "beyond"]).code(1);
    assert!(run.stdout.lines().any(|l| l.starts_with("last") && l.contains("6996")), "{}", run.stdout);
    assert!(
        run.stdout.lines().any(|l| l.starts_with("beyond") && l.contains("error: exception 0x02")),
        "{}",
        run.stdout
    );
    assert!(run.stderr.contains("1 of 2 parameters could not be read: beyond"), "{}", run.stderr);
}

#[test]
fn libmodbus_server_over_tcp_speaks_a_custom_profile() {
    with_server(Stack::Libmodbus, Over::Tcp, get_and_set_speak_the_profile);
}

#[test]
fn pymodbus_server_over_tcp_speaks_a_custom_profile() {
    with_server(Stack::Pymodbus, Over::Tcp, get_and_set_speak_the_profile);
}

#[test]
fn libmodbus_server_over_rtu_speaks_a_custom_profile() {
    with_server(Stack::Libmodbus, Over::Rtu, get_and_set_speak_the_profile);
}
