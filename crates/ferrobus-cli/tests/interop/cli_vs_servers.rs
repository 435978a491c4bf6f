//! The `ferrobus` binary as a client of each peer server (libmodbus, pymodbus, tokio-modbus),
//! over RTU on a socat pty pair and over Modbus/TCP.
//!
//! Every test checks the reads of all four tables at both ends of the shared data map
//! (tests/peers/README.md), write-then-read-back for FC05, 0F, 06, 10, 16 and 17, exception 02
//! past the map (exit code 1), and a timeout (exit code 3) for a unit the server does not
//! serve; then whatever else that server supports: FC07, 08, 0B, 0C, 11, 14, 15, 18, 2B/0E.

use serde_json::Value;

use crate::support::{Ferrobus, Need, Over, Stack, bits, ferrobus, peer_server, require, words};

/// The unit every peer server here serves.
const UNIT: u8 = 17;

/// Starts `stack`'s server and runs `check` with a client for it, if the peers are there.
fn with_server(stack: Stack, over: Over, check: impl FnOnce(&Ferrobus)) {
    let needs = if over == Over::Rtu { vec![stack.need(), Need::Socat] } else { vec![stack.need()] };
    let Some(_turn) = require(&needs) else { return };
    let server = peer_server(stack, over, UNIT);
    check(&ferrobus(&server.link).unit(UNIT));
}

/// Reads of the four tables, and every write function code followed by a read-back.
fn reads_and_writes_follow_the_data_map(fb: &Ferrobus) {
    // holding i = i * 7 + 3, input i = 0x1000 + i, coil i = i % 3 == 0, discrete i = i % 5 == 0.
    assert_eq!(fb.values(&["read", "holding", "0", "--count", "3"]), words(&[3, 10, 17]));
    assert_eq!(fb.values(&["read", "holding", "997", "--count", "3"]), words(&[6982, 6989, 6996]));
    assert_eq!(fb.values(&["read", "input", "0", "--count", "2"]), words(&[0x1000, 0x1001]));
    assert_eq!(fb.values(&["read", "input", "999"]), words(&[0x1000 + 999]));
    assert_eq!(fb.values(&["read", "coils", "0", "--count", "7"]), bits("1001001"));
    assert_eq!(fb.values(&["read", "coils", "1998", "--count", "2"]), bits("10"));
    assert_eq!(fb.values(&["read", "discrete", "0", "--count", "6"]), bits("100001"));
    assert_eq!(fb.values(&["read", "discrete", "1995", "--count", "5"]), bits("10000"));

    fb.run(&["write", "coil", "1", "on"]).ok(); // FC05
    fb.run(&["write", "coils", "10", "1", "1", "0", "1"]).ok(); // FC0F
    assert_eq!(fb.values(&["read", "coils", "0", "--count", "3"]), bits("110"));
    assert_eq!(fb.values(&["read", "coils", "9", "--count", "6"]), bits("111010"));

    fb.run(&["write", "register", "5", "0x1234"]).ok(); // FC06
    fb.run(&["write", "registers", "6", "1", "2", "3"]).ok(); // FC10
    assert_eq!(fb.values(&["read", "holding", "4", "--count", "6"]), words(&[31, 0x1234, 1, 2, 3, 66]));

    // FC16 on register 4 (31 = 0x1F): (0x1F AND 0xF2) OR (0x25 AND NOT 0xF2) = 0x17.
    fb.run(&["mask", "4", "0xF2", "0x25"]).ok();
    assert_eq!(fb.values(&["read", "holding", "4"]), words(&[0x17]));

    // FC17 writes first: the read of 20..22 sees the 7 and 8 just written to 21 and 22.
    let read = fb.values(&["readwrite", "--read", "20", "--count", "3", "--write", "21", "7", "8"]);
    assert_eq!(read, words(&[143, 7, 8]));
}

/// Exception 02 for each table just past the map, and for a write there.
fn exception_02_past_the_map(fb: &Ferrobus) {
    fb.run(&["read", "holding", "1000"]).exception(0x02);
    fb.run(&["read", "input", "999", "--count", "2"]).exception(0x02);
    fb.run(&["read", "coils", "2000"]).exception(0x02);
    fb.run(&["read", "discrete", "1999", "--count", "2"]).exception(0x02);
    fb.run(&["write", "register", "1000", "1"]).exception(0x02);
}

/// A unit nobody serves: exit code 3 after the timeout.
fn another_unit_times_out(fb: &Ferrobus) {
    fb.unit(UNIT + 1).timeout_ms(300).run(&["read", "holding", "0"]).timeout();
}

/// Exception 03 for 126 registers, sent raw (the CLI splits a long read itself).
fn exception_03_for_126_registers(fb: &Ferrobus) {
    fb.run(&["raw", "03 0000 007E"]).exception(0x03);
}

/// The objects of FC2B/0E and the conformity level.
fn identification(fb: &Ferrobus) -> (u64, Vec<String>) {
    let doc = fb.run(&["info", "--json"]).json();
    let objects = doc["objects"].as_array().cloned().unwrap_or_default();
    let values = objects.iter().map(|o| o["value"].as_str().unwrap_or_default().to_string()).collect();
    (doc["conformity"].as_u64().unwrap_or_default(), values)
}

/// The bytes of the FC11 reply after the byte count, as `"B4 FF 4C ..."`.
fn server_id(fb: &Ferrobus) -> String {
    let doc = fb.run(&["info", "--server-id", "--json"]).json();
    doc["data"].as_str().unwrap_or_default().to_string()
}

/// The reply line of `ferrobus raw`.
fn raw_reply(fb: &Ferrobus, pdu: &str) -> String {
    let out = fb.run(&["raw", pdu]).ok();
    let line = out.lines().find_map(|l| l.strip_prefix("reply"));
    line.unwrap_or_else(|| panic!("no reply line in:\n{out}")).trim().to_string()
}

/// What libmodbus's FC11 reply carries after the byte count: its slave id 0xB4 (180), run
/// indicator 0xFF, then `LMB` and the version of the libmodbus the fixture was built with —
/// the installed one, as pkg-config reports it (`.ci/setup-peers.sh` builds against it), e.g.
/// `B4 FF 4C 4D 42 33 2E 31 2E 36` for 3.1.6.
fn libmodbus_server_id() -> String {
    let out = std::process::Command::new("pkg-config")
        .args(["--modversion", "libmodbus"])
        .output()
        .unwrap_or_else(|e| panic!("pkg-config --modversion libmodbus: {e} (the libmodbus fixtures need pkg-config)"));
    let version = String::from_utf8_lossy(&out.stdout).trim().to_string();
    assert!(
        out.status.success() && !version.is_empty(),
        "pkg-config --modversion libmodbus gave no version ({}): {}",
        out.status,
        String::from_utf8_lossy(&out.stderr).trim()
    );
    let text = format!("LMB{version}");
    [0xB4, 0xFF].into_iter().chain(text.bytes()).map(|b| format!("{b:02X}")).collect::<Vec<_>>().join(" ")
}

fn libmodbus(fb: &Ferrobus, over: Over) {
    reads_and_writes_follow_the_data_map(fb);
    exception_02_past_the_map(fb);
    exception_03_for_126_registers(fb); // after libmodbus's 500 ms sleep
    assert_eq!(server_id(fb), libmodbus_server_id());
    if over == Over::Tcp {
        // Unknown to libmodbus: exception 01 over TCP (over RTU it cannot frame it: silence).
        fb.run(&["diag", "echo"]).exception(0x01);
    }
    // Last: libmodbus's RTU server drops a request sent within 500 ms after another unit's.
    another_unit_times_out(fb);
}

#[test]
fn libmodbus_rtu_server_serves_every_cli_command_it_supports() {
    with_server(Stack::Libmodbus, Over::Rtu, |fb| libmodbus(fb, Over::Rtu));
}

#[test]
fn libmodbus_tcp_server_serves_every_cli_command_it_supports() {
    with_server(Stack::Libmodbus, Over::Tcp, |fb| libmodbus(fb, Over::Tcp));
}

fn pymodbus(fb: &Ferrobus, over: Over) {
    reads_and_writes_follow_the_data_map(fb);
    exception_02_past_the_map(fb);
    another_unit_times_out(fb);
    assert_eq!(raw_reply(fb, "07"), "07 00");
    assert!(fb.run(&["diag", "echo", "--data", "1234"]).ok().contains("echo OK (FC08/00): 12 34"));
    let counters = fb.run(&["diag", "counters", "--json"]).json();
    assert_eq!(counters["counters"].as_object().map(serde_json::Map::len), Some(8), "{counters}");
    assert_eq!(fb.run(&["diag", "event-counter", "--json"]).json()["status"], 0);
    assert_eq!(fb.run(&["diag", "event-log", "--json"]).json()["events"], Value::Array(vec![]));
    assert_eq!(identification(fb), (0x83, vec!["pymodbus".into(), "PM".into(), "3.16".into()]));
    // pymodbus puts the run indicator last: "pymodbus-PM-3.16" ff.
    assert_eq!(server_id(fb), "70 79 6D 6F 64 62 75 73 2D 50 4D 2D 33 2E 31 36 FF");
    // Dummies: FC18 always 0 1 2 3, FC14 "SERVER DUMMY RECORD." (10 words), FC15 echoes.
    assert_eq!(raw_reply(fb, "18 04DE"), "18 00 0A 00 04 00 00 00 01 00 02 00 03");
    let record = raw_reply(fb, "14 07 06 0004 0001 0002");
    assert!(record.starts_with("14 16 15 06 53 45 52 56 45 52 20 44 55 4D 4D 59"), "{record}");
    let write = "15 0D 06 0004 0007 0003 06AF 04BE 100D";
    assert_eq!(raw_reply(fb, write), "15 0D 06 00 04 00 07 00 03 06 AF 04 BE 10 0D");
    // pymodbus cannot decode 126 registers and answers `80 01`, which answers nothing that
    // was asked (function 0x80 is not 0x83): ignored, so the request times out. Over TCP the
    // error says what the unit sent instead; on RTU function 0 is not a function, and the
    // receiver drops the frame as noise.
    let run = fb.timeout_ms(300).run(&["raw", "03 0000 007E"]).timeout();
    if over == Over::Tcp {
        assert!(run.stderr.contains("function code 0x80 instead"), "{}", run.stderr);
        assert!(run.stderr.contains("may not support"), "{}", run.stderr);
    }
}

#[test]
fn pymodbus_rtu_server_serves_every_cli_command_it_supports() {
    with_server(Stack::Pymodbus, Over::Rtu, |fb| pymodbus(fb, Over::Rtu));
}

#[test]
fn pymodbus_tcp_server_serves_every_cli_command_it_supports() {
    with_server(Stack::Pymodbus, Over::Tcp, |fb| pymodbus(fb, Over::Tcp));
}

fn tokio_modbus(fb: &Ferrobus, over: Over) {
    reads_and_writes_follow_the_data_map(fb);
    exception_02_past_the_map(fb);
    exception_03_for_126_registers(fb);
    another_unit_times_out(fb);
    assert_eq!(raw_reply(fb, "07"), "07 00");
    assert_eq!(identification(fb), (0x81, vec!["tokio-modbus".into(), "TM".into(), "0.17".into()]));
    fb.run(&["diag", "event-counter"]).exception(0x01);
    fb.run(&["raw", "18 0000"]).exception(0x01);
    match over {
        Over::Rtu => {
            // <unit> ff "tokio-modbus". (FC08 cannot be framed by its RTU server: not sent.)
            assert_eq!(server_id(fb), "11 FF 74 6F 6B 69 6F 2D 6D 6F 64 62 75 73");
        }
        Over::Tcp => {
            assert!(fb.run(&["diag", "echo", "--data", "BEEF"]).ok().contains("echo OK (FC08/00): BE EF"));
            fb.run(&["diag", "sub", "1"]).exception(0x01);
            // Its TCP server sends FC11 with an MBAP length one byte short: a bad reply.
            let run = fb.run(&["info", "--server-id"]).code(5);
            assert!(run.stderr.contains("PDU truncated"), "{}", run.stderr);
        }
    }
}

#[test]
fn tokio_modbus_rtu_server_serves_every_cli_command_it_supports() {
    with_server(Stack::TokioModbus, Over::Rtu, |fb| tokio_modbus(fb, Over::Rtu));
}

#[test]
fn tokio_modbus_tcp_server_serves_every_cli_command_it_supports() {
    with_server(Stack::TokioModbus, Over::Tcp, |fb| tokio_modbus(fb, Over::Tcp));
}

#[test]
fn diag_echo_with_json_prints_one_json_document() {
    with_server(Stack::Pymodbus, Over::Tcp, |fb| {
        let doc = fb.run(&["diag", "echo", "--data", "1234", "--json"]).json();
        assert_eq!((doc["function"].as_u64(), doc["sub"].as_u64()), (Some(8), Some(0)), "{doc}");
        assert_eq!(doc["reply"], "12 34", "{doc}");
        let csv = fb.run(&["diag", "echo", "--data", "1234", "--csv"]).ok();
        assert!(csv.starts_with("unit,function,sub,name,reply,word,result\n"), "{csv:?}");
        assert!(csv.contains(",12 34,4660,"), "{csv:?}");
    });
}
