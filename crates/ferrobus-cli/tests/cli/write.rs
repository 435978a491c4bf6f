//! `ferrobus write`, `mask`, `readwrite`: function codes, typed values, splitting, broadcast.

use std::time::{Duration, Instant};

use serde_json::Value;

use crate::server::{GUARDED, Seen, Server, stderr, stdout};

fn requests(server: &Server) -> Vec<(u8, u16, u16)> {
    server.take_requests().into_iter().map(|Seen { function, start, quantity }| (function, start, quantity)).collect()
}

#[test]
fn coils_are_written_with_fc05_and_fc0f() {
    let server = Server::start();
    let one = stdout(&server.run(&["write", "coil", "5", "on"]).success());
    assert_eq!(one, "unit 1: FC05 wrote coil at 5 (0x0005): ON\n");
    let many = stdout(&server.run(&["write", "coils", "10", "1", "off", "true"]).success());
    assert_eq!(many, "unit 1: FC0F wrote 3 coils at 10 (0x000A): ON OFF ON\n");
    assert_eq!(requests(&server), [(0x05, 5, 1), (0x0F, 10, 3)]);
    let device = server.device();
    assert_eq!((device.coils[5], &device.coils[10..13]), (true, &[true, false, true][..]));
}

#[test]
fn one_register_uses_fc06_unless_multiple_or_32_bit() {
    let server = Server::start();
    let out = stdout(&server.run(&["write", "register", "7", "1234"]).success());
    assert_eq!(out, "unit 1: FC06 wrote register at 7 (0x0007): 0x04D2 (u16 1234)\n");
    let multiple = stdout(&server.run(&["write", "register", "8", "0x0BB8", "--multiple"]).success());
    assert_eq!(multiple, "unit 1: FC10 wrote 1 register at 8 (0x0008): 0x0BB8 (u16 3000)\n");
    let wide = stdout(&server.run(&["write", "register", "0x10", "300000", "--type", "u32"]).success());
    assert_eq!(wide, "unit 1: FC10 wrote 2 registers at 16 (0x0010): 0x0004 0x93E0 (u32 300000)\n");
    server.run(&["write", "register", "0x112", "3000", "--type", "u32", "--word-order", "low-first"]).success();
    assert_eq!(requests(&server), [(0x06, 7, 1), (0x10, 8, 1), (0x10, 0x10, 2), (0x10, 0x112, 2)]);
    let device = server.device();
    assert_eq!(device.holding[7..9], [1234, 0x0BB8]);
    assert_eq!(device.holding[0x10..0x12], [0x0004, 0x93E0]);
    assert_eq!(device.holding[0x112..0x114], [0x0BB8, 0x0000]);
}

#[test]
fn negative_and_float_values_are_typed() {
    let server = Server::start();
    server.run(&["write", "registers", "100", "-1", "-2", "--type", "i16"]).success();
    server.run(&["write", "register", "102", "-2.5", "--type", "f32", "--swap"]).success();
    server.run(&["write", "register", "-1", "105", "-300", "--type", "i16"]).success();
    let device = server.device();
    assert_eq!(device.holding[100..104], [0xFFFF, 0xFFFE, 0x0000, 0xC020]);
    assert_eq!(device.holding[104], 0xFED4);
}

#[test]
fn long_typed_writes_split_between_values() {
    let server = Server::start();
    let out = stdout(
        &server
            .run(&["write", "registers", "0", "1", "2", "3", "4", "5", "--type", "u32", "--max-per-request", "5"])
            .success(),
    );
    assert_eq!(out.lines().count(), 3, "{out}");
    assert_eq!(requests(&server), [(0x10, 0, 4), (0x10, 4, 4), (0x10, 8, 2)]);
    assert_eq!(server.device().holding[..10], [0, 1, 0, 2, 0, 3, 0, 4, 0, 5]);
}

#[test]
fn one_based_writes_land_one_lower() {
    let server = Server::start();
    let out = stdout(&server.run(&["write", "register", "--one-based", "0x0012", "50"]).success());
    assert_eq!(
        out, "unit 1: FC06 wrote register at 17 (0x0011) = 0x0012: 0x0032 (u16 50)\n",
        "the number as typed, in hex"
    );
    let modicon = stdout(&server.run(&["write", "registers", "--modicon", "40020", "1", "2"]).success());
    assert_eq!(modicon, "unit 1: FC10 wrote 2 registers at 19 (0x0013) = 40020: 0x0001 0x0002 (u16 1 2)\n");
    assert_eq!(requests(&server), [(0x06, 0x11, 1), (0x10, 19, 2)]);
    assert_eq!(server.device().holding[0x11], 50);
}

#[test]
fn mask_write_applies_and_or() {
    let server = Server::start();
    let out = stdout(&server.run(&["mask", "20", "0xFFF0", "0x0005"]).success());
    assert_eq!(out, "unit 1: FC16 masked register at 20 (0x0014): AND 0xFFF0 OR 0x0005\n");
    assert_eq!(server.device().holding[20], 0x15);
}

#[test]
fn readwrite_writes_then_reads_in_one_fc17() {
    let server = Server::start();
    let out = stdout(
        &server.run(&["readwrite", "--read", "30", "--count", "3", "--write", "30", "7", "8", "--csv"]).success(),
    );
    assert_eq!(out, "address,addr_hex,hex,dec\n30,0x001E,0x0007,7\n31,0x001F,0x0008,8\n32,0x0020,0x0020,32\n");
    let json: Value = serde_json::from_str(&stdout(
        &server.run(&["readwrite", "--read", "0", "--write", "40", "9", "--json"]).success(),
    ))
    .unwrap();
    assert_eq!((json["function"].clone(), json["written"].clone()), (0x17.into(), serde_json::json!([9])));
    assert_eq!(server.take_requests().iter().filter(|s| s.function == 0x17).count(), 2);
}

#[test]
fn a_broadcast_write_returns_without_a_reply_and_is_executed() {
    let server = Server::rtu_over_tcp();
    let out = stdout(&server.run(&["--unit", "0", "write", "register", "40", "77"]).success());
    assert_eq!(out, "broadcast: FC06 sent register at 40 (0x0028): 0x004D (u16 77) (no reply expected)\n");
    let deadline = Instant::now() + Duration::from_secs(2);
    while server.device().holding[40] != 77 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(5));
    }
    assert_eq!(server.device().holding[40], 77);
    let read = server.run(&["--unit", "0", "read", "holding", "0"]).code(2);
    assert!(stderr(&read).contains("unit 0 is a broadcast"), "{}", stderr(&read));
}

#[test]
fn vendor_exceptions_are_named_with_the_inverter_hint() {
    let server = Server::start();
    let assert = server.run(&["write", "register", &GUARDED.to_string(), "2000"]).code(1);
    let err = stderr(&assert);
    assert!(err.contains("exception 0x21 (vendor-specific)"), "{err}");
    assert!(err.contains("value out of the inverter's range"), "{err}");
}
