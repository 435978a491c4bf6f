//! Peer clients and the manuals' own frames against the drive profiles of `ferrobus sim`.
//!
//! - `omron-3g3rx`: 4 registers per message (exception 03 for 5), no FC04 (exception 01),
//!   vendor exception 21h for F001 above 40000 and 22h for a read-only register, and the
//!   3G3RX example frames of shared/reference/modbus-and-drives.md §4.10, byte for byte.
//! - `sdp-servo`: the SDP manual's FC10 example (p.413), 10 registers per access (exception
//!   03 for 11), and only FC03, 04, 06, 10.
//!
//! The clients run over RTU on a socat pair, a fresh simulator each; the raw frames go
//! through the simulator's own pty.

use std::time::Duration;

use crate::support::{Need, Over, RawPort, Stack, check_script, hex, require, show, sim, sim_pty, with_crc};

/// An exception code as the client prints it: libmodbus knows only codes 01-0B.
fn vendor_exception(stack: Stack, line: &'static str) -> &'static str {
    if stack == Stack::Libmodbus { "error Invalid exception code" } else { line }
}

fn omron_script(stack: Stack) -> Vec<(&'static str, &'static str)> {
    let mut steps = vec![
        // F001 high and low, status A (2 = stop), status B (0 = stop).
        ("read_holding 0 4", "ok 0 0 2 0"),
        ("read_holding 0 5", "exception 3"),
        ("read_input 0 1", "exception 1"),
        // F001 (frame address 0, 32-bit, 0-40000): 40001 is out of the inverter's range.
        ("write_registers 0 0 40001", vendor_exception(stack, "exception 33")),
        ("write_registers 0 0 40000", "ok"),
        ("read_holding 0 2", "ok 0 40000"),
        // A003 (register 1203h, frame 1202h), the manual's FC06 example: 50 Hz; 30-400 Hz.
        ("write_register 0x1202 50", "ok"),
        ("read_holding 0x1202 1", "ok 50"),
        ("write_register 0x1202 29", vendor_exception(stack, "exception 33")),
        // Status A is read-only: 22h.
        ("write_register 2 5", vendor_exception(stack, "exception 34")),
        // Coils 1-4 (run, direction, external trip, reset) and 11h (ready, on at start).
        ("read_coils 0 4", "ok 0 0 0 0"),
        ("read_coils 16 1", "ok 1"),
        ("read_coils 0 33", "exception 3"),
        ("write_coils 6 1 1 1 0 1 0", "ok"),
        ("read_coils 6 6", "ok 1 1 1 0 1 0"),
        // Not in the 3G3RX's list: FC11, 16, 17.
        ("report_slave_id", "exception 1"),
        ("mask_write 0x1202 0 0", "exception 1"),
        ("write_read 0 1 0x1202 50", "exception 1"),
        ("unit 2", "ok"),
        ("read_holding 0 1", "timeout"),
    ];
    if stack != Stack::Libmodbus {
        // FC08: loop-back (sub-function 0) only.
        steps.extend([("unit 1", "ok"), ("diag 0 0x1234", "ok 0 4660"), ("diag 10 0", "exception 1")]);
    }
    steps
}

fn sdp_script() -> Vec<(&'static str, &'static str)> {
    vec![
        // The manual's example: 0BB8h to 0112h, 0000h to 0113h.
        ("write_registers 0x112 0x0BB8 0", "ok"),
        ("read_holding 0x112 2", "ok 3000 0"),
        ("read_holding 0 10", "ok 0 0 0 0 0 0 0 0 0 0"),
        ("read_holding 0 11", "exception 3"),
        ("write_registers 0 0 0 0 0 0 0 0 0 0 0 0", "exception 3"),
        ("write_register 0x201 500", "ok"),
        ("read_holding 0x201 1", "ok 500"),
        // Speed command 0112h/0113h is a 32-bit value of -6000..6000 r/min, low word first.
        ("write_register 0x112 6001", "exception 3"),
        ("read_input 0 1", "ok 0"),
        ("read_input 0 11", "exception 3"),
        // Only 03, 04, 06, 10.
        ("read_coils 0 1", "exception 1"),
        ("write_coil 0 1", "exception 1"),
        ("mask_write 0 0 0", "exception 1"),
        ("unit 2", "ok"),
        ("read_holding 0 1", "timeout"),
    ]
}

/// Runs each peer client's script against a fresh `ferrobus sim --profile PROFILE` on RTU.
fn each_client(profile: &str, script: impl Fn(Stack) -> Vec<(&'static str, &'static str)>) {
    let Some(_turn) = require(&[Need::Socat, Need::Libmodbus, Need::Pymodbus, Need::TokioModbus]) else { return };
    for stack in [Stack::Libmodbus, Stack::Pymodbus, Stack::TokioModbus] {
        let served = sim(Over::Rtu, stack.parity(), &["--profile", profile]);
        check_script(stack, &served.link, 1, &script(stack));
    }
}

#[test]
fn omron_3g3rx_limits_and_vendor_exceptions_reach_every_peer_client() {
    each_client("omron-3g3rx", omron_script);
}

#[test]
fn sdp_servo_manual_example_and_ten_register_limit_reach_every_peer_client() {
    each_client("sdp-servo", |_| sdp_script());
}

/// Sends each request and compares the reply byte for byte; all mismatches in one message.
fn replies_byte_for_byte(port: &RawPort, frames: &[(Vec<u8>, Vec<u8>)], t3_5: Duration) {
    let mut bad = Vec::new();
    for (request, expected) in frames {
        let got = port.transact(request, expected.len());
        if &got != expected {
            bad.push(format!("{} -> {}, expected {}", show(request), show(&got), show(expected)));
        }
        // The master's silence between a reply and the next request.
        std::thread::sleep(t3_5);
    }
    assert!(bad.is_empty(), "{} of {} replies differ:\n{}", bad.len(), frames.len(), bad.join("\n"));
}

/// A frame as printed in a manual, after checking that its CRC is right.
fn printed(frame: &str) -> Vec<u8> {
    let bytes = hex(frame);
    let body = &bytes[..bytes.len() - 2];
    assert_eq!(with_crc(body), bytes, "the CRC of {frame}");
    bytes
}

/// A frame from its bytes without the CRC.
fn framed(body: &str) -> Vec<u8> {
    with_crc(&hex(body))
}

#[test]
fn omron_3g3rx_answers_the_manual_example_frames_byte_for_byte() {
    let Some(_turn) = require(&[]) else { return };
    let units = ["--unit", "1", "--unit", "5", "--unit", "8", "--unit", "10"];
    let (_sim, pty) = sim_pty(&[&["--profile", "omron-3g3rx", "--baud", "9600"][..], &units].concat());
    let port = RawPort::open(&pty, 9600);
    let frames = [
        // The read example expects 17h in coils 7-12 of slave 8: write them first (FC0F).
        (framed("08 0F 00 06 00 06 02 17 00"), framed("08 0F 00 06 00 06")),
        // p.4-168: FC01, coils 7-12 of slave 8.
        (printed("08 01 00 06 00 06 5C 90"), printed("08 01 01 17 12 1A")),
        // p.4-170: FC05, run command on, slave 10: the query comes back unchanged.
        (printed("0A 05 00 00 FF 00 8D 41"), printed("0A 05 00 00 FF 00 8D 41")),
        // p.4-169: FC03, 0012h-0013h (trip factor and status) of slave 5: no trip yet.
        (printed("05 03 00 11 00 02 95 8A"), framed("05 03 04 00 00 00 00")),
        // p.4-171: FC06, A003 (1203h) = 50 on slave 5.
        (printed("05 06 12 02 00 32 AD 23"), printed("05 06 12 02 00 32 AD 23")),
        // FC0F, 6 coils from 7 on slave 5.
        (printed("05 0F 00 06 00 06 02 17 00 DB 3E"), printed("05 0F 00 06 00 06 34 4C")),
        // p.4-173: FC10, F002 = 300000 (0x000493E0, high word first) on slave 1, then read back.
        (printed("01 10 11 02 00 02 04 00 04 93 E0 9E 9F"), printed("01 10 11 02 00 02 E5 34")),
        (framed("01 03 11 02 00 02"), framed("01 03 04 00 04 93 E0")),
        // 5 registers: exception 03; FC04: exception 01; F001 = 40001: exception 21h.
        (framed("01 03 00 00 00 05"), framed("01 83 03")),
        (framed("01 04 00 00 00 01"), framed("01 84 01")),
        (framed("01 10 00 00 00 02 04 00 00 9C 41"), framed("01 90 21")),
        (framed("01 10 00 00 00 02 04 00 00 9C 40"), framed("01 10 00 00 00 02")),
    ];
    // t3.5 at 9600 baud is 4.01 ms.
    replies_byte_for_byte(&port, &frames, Duration::from_millis(5));
}

#[test]
fn sdp_servo_answers_the_manual_example_frame_byte_for_byte() {
    let Some(_turn) = require(&[]) else { return };
    let (_sim, pty) = sim_pty(&["--profile", "sdp-servo"]);
    let port = RawPort::open(&pty, 19200);
    let frames = [
        // p.413: 0BB8h, 0000h to 0112h of unit 1.
        (printed("01 10 01 12 00 02 04 0B B8 00 00 FC EB"), printed("01 10 01 12 00 02 E0 31")),
        (framed("01 03 01 12 00 02"), framed("01 03 04 0B B8 00 00")),
        // 11 registers: exception 03, for a read and for a write.
        (framed("01 03 00 00 00 0B"), framed("01 83 03")),
        (framed(&format!("01 10 00 00 00 0B 16{}", " 00".repeat(22))), framed("01 90 03")),
        // No FC01.
        (framed("01 01 00 00 00 01"), framed("01 81 01")),
    ];
    // t3.5 at 19200 baud is 2.0 ms.
    replies_byte_for_byte(&port, &frames, Duration::from_millis(3));
}
