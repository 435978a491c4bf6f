//! A reply left in the port by an interrupted command, met by the next one: `ferrobus get
//! F003` against the simulated 3G3RX on a socat pair, with F002's reply (33.00 s) already
//! waiting in the port. It once printed F002's value five times out of five.

use std::process::Command;

use crate::support::cli::BAUD;
use crate::support::peers::sim_on;
use crate::support::{Need, Parity, SocatPair, TempDir, require, with_crc};

#[test]
fn a_reply_waiting_in_the_port_before_get_is_dropped_and_get_prints_f003s_true_value() {
    let Some(_turn) = require(&[Need::Socat]) else { return };
    let dir = TempDir::new();
    let pair = SocatPair::start(dir.path());
    // The reply to a read of F002 (two registers, 3300 = 33.00 s), sent by the drive after
    // its response wait, once the command that asked had been interrupted: it waits in the
    // port for whoever opens it next.
    {
        let device_end = serial2::SerialPort::open(&pair.b, BAUD).unwrap();
        device_end.write_all(&with_crc(&[0x01, 0x03, 0x04, 0x00, 0x00, 0x0C, 0xE4])).unwrap();
    }
    let _drive = sim_on(&pair.b, Parity::None, &["--profile", "omron-3g3rx"]);
    let out = Command::new(env!("CARGO_BIN_EXE_ferrobus"))
        .args(["--port", &pair.a.display().to_string(), "--baud", &BAUD.to_string(), "--parity", "none"])
        .args(["--device", "omron-3g3rx", "-vv", "get", "F003"])
        .output()
        .unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{stderr}");
    assert!(!stdout.contains("33.00"), "F002's stale value was printed for F003: {stdout}");
    assert!(stdout.contains("10.00"), "F003's default, 10.00 s, was not printed: {stdout}");
    let dropped = stderr.lines().find(|l| l.contains("dropped bytes waiting in the port before the request"));
    assert!(dropped.is_some_and(|l| l.contains("bytes=9")), "the 9 stale bytes were not dropped and counted: {stderr}");
}
