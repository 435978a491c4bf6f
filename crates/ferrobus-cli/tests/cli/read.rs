//! `ferrobus read`: every table, typed values, splitting, address styles, output formats.

use serde_json::Value;

use crate::server::{Seen, Server, ferrobus, pty_server, stderr, stdout};
use assert_cmd::assert::OutputAssertExt;

fn requests(server: &Server) -> Vec<(u8, u16, u16)> {
    server.take_requests().into_iter().map(|Seen { function, start, quantity }| (function, start, quantity)).collect()
}

#[test]
fn holding_registers_print_as_an_aligned_table() {
    let server = Server::start();
    let out = stdout(&server.run(&["read", "holding", "8", "--count", "3"]).success());
    assert_eq!(
        out,
        "address  addr_hex  hex     dec\n\
         \x20     8  0x0008    0x0008    8\n\
         \x20     9  0x0009    0x0009    9\n\
         \x20    10  0x000A    0x000A   10\n"
    );
    assert_eq!(requests(&server), [(0x03, 8, 3)]);
}

#[test]
fn each_table_uses_its_function_code() {
    let server = Server::start();
    let coils = stdout(&server.run(&["read", "coils", "2", "--count", "2", "--csv"]).success());
    assert_eq!(coils, "address,addr_hex,value,state\n2,0x0002,0,OFF\n3,0x0003,1,ON\n");
    let discrete = stdout(&server.run(&["read", "discrete", "0", "--count", "2", "--csv"]).success());
    assert_eq!(discrete, "address,addr_hex,value,state\n0,0x0000,1,ON\n1,0x0001,0,OFF\n");
    let input = stdout(&server.run(&["read", "input", "5", "--csv"]).success());
    assert_eq!(input, "address,addr_hex,hex,dec\n5,0x0005,0x03ED,1005\n");
    assert_eq!(requests(&server), [(0x01, 2, 2), (0x02, 0, 2), (0x04, 5, 1)]);
}

#[test]
fn a_32_bit_read_with_four_registers_per_request_splits_at_value_boundaries() {
    let server = Server::start();
    let assert =
        server.run(&["read", "holding", "0", "--type", "u32", "--count", "5", "--max-per-request", "4", "--json"]);
    let doc: Value = serde_json::from_str(&stdout(&assert.success())).unwrap();
    assert_eq!(requests(&server), [(0x03, 0, 4), (0x03, 4, 4), (0x03, 8, 2)]);
    assert_eq!(doc["requests"], 3);
    assert_eq!(doc["unit"], 1);
    assert_eq!(doc["function"], 3);
    assert_eq!(doc["start"], 0);
    assert_eq!(doc["values"], serde_json::json!([0, 1, 2, 3, 4, 5, 6, 7, 8, 9]));
    let want: Vec<u64> = (0..5).map(|i| ((2 * i) << 16) | (2 * i + 1)).collect();
    assert_eq!(doc["decoded"], serde_json::json!(want));
    assert_eq!(doc["word_order"], "ABCD");

    // An odd limit is rounded down to whole values: 5 registers per request carry 2 values.
    server.run(&["read", "holding", "0", "--type", "i32", "--count", "3", "--max-per-request", "5"]).success();
    assert_eq!(requests(&server), [(0x03, 0, 4), (0x03, 4, 2)]);
}

#[test]
fn word_order_decides_which_register_is_high() {
    let server = Server::start();
    {
        let mut device = server.device();
        device.holding[0x10..0x12].copy_from_slice(&[0x0004, 0x93E0]); // 3G3RX F002 = 300000
        device.holding[0x112..0x114].copy_from_slice(&[0x0BB8, 0x0000]); // SDP example: 3000
        device.holding[0x20..0x22].copy_from_slice(&[0x3FC0, 0x0000]); // 1.5
    }
    let high = stdout(&server.run(&["read", "holding", "0x10", "--type", "u32"]).success());
    assert_eq!(
        high,
        "address  addr_hex  hex                dec     u32\n     16  0x0010    0x0004 0x93E0  4 37856  300000\n"
    );
    let low = stdout(
        &server.run(&["read", "holding", "0x112", "--type", "u32", "--word-order", "low-first", "--csv"]).success(),
    );
    assert_eq!(low, "address,addr_hex,hex,dec,u32\n274,0x0112,0x0BB8 0x0000,3000 0,3000\n");
    let swap = stdout(&server.run(&["read", "holding", "0x112", "--type", "u32", "--swap", "--csv"]).success());
    assert_eq!(swap, low);
    let float = stdout(&server.run(&["read", "holding", "0x20", "--type", "f32", "--csv"]).success());
    assert!(float.ends_with(",1.5\n"), "{float}");
    let signed = stdout(&server.run(&["read", "holding", "0x10", "--type", "i16", "--count", "2", "--csv"]).success());
    assert!(signed.ends_with("17,0x0011,0x93E0,37856,-27680\n"), "{signed}");
    let bin = stdout(&server.run(&["read", "holding", "0x10", "--type", "bin", "--csv"]).success());
    assert!(bin.ends_with(",0b0000_0000_0000_0100\n"), "{bin}");
}

#[test]
fn one_based_numbers_are_sent_as_number_minus_one_and_shown_beside_the_wire_address() {
    let server = Server::start();
    let out = stdout(&server.run(&["read", "holding", "--one-based", "0x0012", "--csv"]).success());
    // The number is shown as typed: in hex.
    assert_eq!(out, "address,addr_hex,number,hex,dec\n17,0x0011,0x0012,0x0011,17\n");
    let short = stdout(&server.run(&["read", "holding", "-1", "18", "--csv"]).success());
    assert_eq!(short, "address,addr_hex,number,hex,dec\n17,0x0011,18,0x0011,17\n", "typed in decimal");
    assert_eq!(requests(&server), [(0x03, 0x11, 1), (0x03, 0x11, 1)]);
    let zero = server.run(&["read", "holding", "--one-based", "0"]).code(2);
    assert!(stderr(&zero).contains("start at 1"), "{}", stderr(&zero));
}

#[test]
fn modicon_references_with_the_flag_imply_the_table_and_the_offset() {
    let server = Server::start();
    let out = stdout(&server.run(&["read", "holding", "--modicon", "40001", "--count", "2", "--csv"]).success());
    assert_eq!(out, "address,addr_hex,ref,hex,dec\n0,0x0000,40001,0x0000,0\n1,0x0001,40002,0x0001,1\n");
    let input = stdout(&server.run(&["read", "input", "300010", "--modicon", "--csv"]).success());
    assert_eq!(input, "address,addr_hex,ref,hex,dec\n9,0x0009,300010,0x03F1,1009\n");
    let coil = stdout(&server.run(&["read", "coils", "--modicon", "00004", "--csv"]).success());
    assert_eq!(coil, "address,addr_hex,ref,value,state\n3,0x0003,00004,1,ON\n");
    let json: Value =
        serde_json::from_str(&stdout(&server.run(&["read", "discrete", "--modicon", "10002", "--json"]).success()))
            .unwrap();
    assert_eq!((json["start"].clone(), json["start_ref"].clone()), (1.into(), "10002".into()));
    assert_eq!(requests(&server), [(0x03, 0, 2), (0x04, 9, 1), (0x01, 3, 1), (0x02, 1, 1)]);
}

#[test]
fn a_modicon_reference_to_another_table_is_a_usage_error() {
    let server = Server::start();
    let err = stderr(&server.run(&["read", "coils", "--modicon", "40001"]).code(2));
    assert!(
        err.contains("40001 is a Modicon reference to holding register 1, but the command addresses coils"),
        "{err}"
    );
    assert!(err.contains("without --modicon it is wire address 40001"), "{err}");
    assert!(server.take_requests().is_empty());
}

#[test]
fn a_plain_40001_is_wire_address_40001_with_a_warning_naming_the_modicon_reading() {
    let server = Server::start();
    // The test device has 1000 registers: wire 40001 is past them, and the request shows it.
    let assert = server.run(&["read", "holding", "40001"]).code(1);
    let err = stderr(&assert);
    assert!(
        err.contains(
            "warning: 40001 is taken as wire address 40001 (0x9C41); for the Modicon reference to holding \
             register 1 (wire 0) add --modicon"
        ),
        "{err}"
    );
    assert_eq!(requests(&server), [(0x03, 40001, 1)]);
    // 40000 (SunSpec's base) is no Modicon reference: no warning.
    let quiet = stderr(&server.run(&["read", "holding", "40000"]).code(1));
    assert!(!quiet.contains("warning"), "{quiet}");
    assert_eq!(requests(&server), [(0x03, 40000, 1)]);
}

#[test]
fn a_lone_minus_one_is_explained_as_the_one_based_flag_when_the_address_or_value_is_missing() {
    let server = Server::start();
    let err = stderr(&server.run(&["read", "holding", "-1"]).code(2));
    assert!(err.contains("<ADDRESS> missing: '-1' is the flag -1 (--one-based), not a number"), "{err}");
    assert!(err.contains("addresses are 0 to 65535"), "{err}");
    let err = stderr(&server.run(&["write", "register", "-1", "5"]).code(2));
    assert!(err.contains("<VALUE> missing: '-1' is the flag -1 (--one-based)"), "{err}");
    // Behind `--` it is an address, and refused as one.
    let err = stderr(&server.run(&["read", "holding", "--", "-1"]).code(2));
    assert!(err.contains("'-1' is not an address: addresses are 0 to 65535"), "{err}");
    assert!(server.take_requests().is_empty());
}

#[test]
fn long_reads_are_split_at_the_spec_limits() {
    let server = Server::start();
    let json: Value =
        serde_json::from_str(&stdout(&server.run(&["read", "input", "0", "--count", "300", "--json"]).success()))
            .unwrap();
    assert_eq!(json["values"].as_array().unwrap().len(), 300);
    assert_eq!(json["values"][299], 1299);
    server.run(&["read", "coils", "0", "--count", "1000", "--max-per-request", "400", "--csv"]).success();
    assert_eq!(
        requests(&server),
        [(0x04, 0, 125), (0x04, 125, 125), (0x04, 250, 50), (0x01, 0, 400), (0x01, 400, 400), (0x01, 800, 200)]
    );
}

#[test]
fn json_bits_are_booleans() {
    let server = Server::start();
    let json: Value =
        serde_json::from_str(&stdout(&server.run(&["read", "coils", "0", "--count", "4", "--json"]).success()))
            .unwrap();
    assert_eq!(json["values"], serde_json::json!([true, false, false, true]));
    assert_eq!(json["table"], "coils");
    assert_eq!(json["count"], 4);
}

#[test]
fn rtu_over_tcp_reads_the_same() {
    let server = Server::rtu_over_tcp();
    let out = stdout(&server.run(&["read", "holding", "3", "--csv"]).success());
    assert_eq!(out, "address,addr_hex,hex,dec\n3,0x0003,0x0003,3\n");
}

#[test]
fn a_serial_port_speaks_rtu_and_ascii() {
    let rtu_timing = ["--t35", "5ms", "--t15", "2ms", "--turnaround", "50ms", "--rs485", "auto"];
    for (ascii, framing) in [(false, &rtu_timing[..]), (true, &["--ascii"][..])] {
        let path = pty_server(ascii);
        let assert = ferrobus()
            .args(["--port", &path, "--parity", "none", "--timeout", "500ms"])
            .args(framing)
            .args(["read", "holding", "5", "--count", "2", "--csv"])
            .assert();
        assert_eq!(stdout(&assert.success()), "address,addr_hex,hex,dec\n5,0x0005,0x0005,5\n6,0x0006,0x0006,6\n");
    }
}
