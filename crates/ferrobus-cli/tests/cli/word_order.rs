//! One word-order type, one codec: the four orders (ABCD, CDAB, BADC, DCBA) through `write`,
//! `read`, `get`, `set` and `poll` against `ferrobus sim`, each putting 0x11223344 (A=11 B=22
//! C=33 D=44) in the same two registers.

use assert_cmd::assert::OutputAssertExt;
use serde_json::Value;

use crate::backup::{TcpSim, temp};
use crate::server::{ferrobus, stdout};

/// The table of `ferrobus_proto::words`: the order, the profile's point in it, its wire
/// address, and 0x11223344 in its registers.
const TABLE: [(&str, &str, u16, [u16; 2]); 4] = [
    ("ABCD", "P_ABCD", 0x10, [0x1122, 0x3344]),
    ("CDAB", "P_CDAB", 0x12, [0x3344, 0x1122]),
    ("BADC", "P_BADC", 0x14, [0x2211, 0x4433]),
    ("DCBA", "P_DCBA", 0x16, [0x4433, 0x2211]),
];

fn profile() -> String {
    let head = "[device]\nname='orders'\nvendor='v'\nproduct_code='p'\nrevision='1'\n".to_string();
    let text = TABLE.iter().fold(head, |text, (order, code, address, _)| {
        text + &format!("[[registers]]\nnumber={address}\nname='{code}'\ntype='u32'\norder='{order}'\naccess='rw'\n")
    });
    let path = temp("word-order.toml");
    std::fs::write(&path, text).unwrap();
    path.to_str().unwrap().to_string()
}

fn json(assert: &assert_cmd::assert::Assert) -> Value {
    serde_json::from_str(&stdout(assert)).unwrap()
}

#[test]
fn the_four_orders_put_the_same_registers_through_write_read_get_set_and_poll() {
    let file = profile();
    let sim = TcpSim::start(&["--profile", &file]);
    let plain = |args: &[&str]| ferrobus().args(["--tcp", &sim.addr, "--timeout", "2s"]).args(args).assert();
    for (order, code, address, registers) in TABLE {
        let at = address.to_string();
        // write --word-order, in the order's name and in lower case.
        for name in [order.to_string(), order.to_lowercase()] {
            plain(&["write", "register", &at, "0x11223344", "--type", "u32", "--word-order", &name]).success();
            let raw = json(&plain(&["read", "holding", &at, "--count", "2", "--json"]).success());
            assert_eq!(raw["values"], serde_json::json!(registers), "write --word-order {name}");
        }
        // read --word-order decodes them back.
        let read = json(&plain(&["read", "holding", &at, "--type", "u32", "--word-order", order, "--json"]).success());
        assert_eq!(
            (read["decoded"].clone(), read["word_order"].clone()),
            (serde_json::json!([0x1122_3344]), order.into())
        );
        // get decodes them by the profile's order; read with --device takes it as its default.
        let got = json(&sim.run(&file, &["get", code, "--json"]).success());
        assert_eq!(got["points"][0]["raw"], 0x1122_3344, "get {code}: {got}");
        let named = json(&sim.run(&file, &["read", "holding", code, "--json"]).success());
        assert_eq!(named["decoded"], serde_json::json!([0x1122_3344]), "read {code}");
        // set writes what write --word-order writes.
        sim.run(&file, &["set", code, "0"]).success();
        sim.run(&file, &["set", code, "0x11223344"]).success();
        let raw = json(&plain(&["read", "holding", &at, "--count", "2", "--json"]).success());
        assert_eq!(raw["values"], serde_json::json!(registers), "set {code}");
        // poll --order decodes them the same.
        let polled = stdout(
            &plain(&[
                "poll",
                "holding",
                &at,
                "--count",
                "2",
                "--format",
                "u32",
                "--order",
                order,
                "--every",
                "50ms",
                "--duration",
                "120ms",
                "--jsonl",
            ])
            .success(),
        );
        let first: Value = serde_json::from_str(polled.lines().next().expect("a poll record")).unwrap();
        assert!(first.to_string().contains(&0x1122_3344u32.to_string()), "poll --order {order}: {first}");
    }
}
