//! Each peer client (libmodbus, pymodbus, tokio-modbus, through the `script` contract of
//! tests/peers/README.md) against `ferrobus sim --profile generic`: the sim on one end of a
//! socat pair (`--port`) or on TCP, the client on the other.
//!
//! The generic device starts all zero, so reads check zeros and coil writes are read back;
//! every function code each client can send is covered, with exception 02 past the address
//! space, exception 03 over a quantity limit (where the client sends it), and silence for
//! another unit (the client times out, then the sim answers unit 1 again).
//!
//! Holding register writes (FC06, FC10, 16, 17) are checked against both kinds of map: the
//! generic device's `[tables]` block (one item owning every address, which once sent the sim
//! into an endless loop) and a profile whose registers are items.

use crate::support::{Need, Over, Parity, Stack, TempDir, check_script, require, sim};

/// The script for `stack` against a fresh generic sim (unit 1), over `over`.
fn generic_script(stack: Stack, over: Over) -> Vec<(&'static str, &'static str)> {
    let mut steps = vec![
        ("read_holding 0 3", "ok 0 0 0"),
        ("read_holding 65533 3", "ok 0 0 0"),
        ("read_input 65534 2", "ok 0 0"),
        ("read_discrete 0 4", "ok 0 0 0 0"),
        ("write_coil 3 1", "ok"),
        ("write_coils 4 1 0 1", "ok"),
        ("read_coils 0 8", "ok 0 0 0 1 1 0 1 0"),
        ("write_coils 65534 1 1", "ok"),
        ("read_coils 65533 3", "ok 0 1 1"),
        ("read_exception_status", "ok 0"),
        ("read_holding 65535 2", "exception 2"),
        ("read_coils 65535 2", "exception 2"),
        ("write_coil 0 1", "ok"),
        // The sim is silent for unit 2; the client recovers for unit 1.
        ("unit 2", "ok"),
        ("read_holding 0 1", "timeout"),
        ("unit 1", "ok"),
        ("read_coils 0 1", "ok 1"),
    ];
    // FC11: server id "FB", run indicator ff, then the revision "0.1". tokio-modbus wants a
    // one-byte server id and takes 'B' for the run indicator.
    steps.push(match stack {
        Stack::TokioModbus => ("report_slave_id", "error invalid run indication status: 0x42"),
        _ => ("report_slave_id", "ok 46 42 ff 30 2e 31"),
    });
    // Over the 125-register limit: only tokio-modbus sends it.
    steps.push(match stack {
        Stack::Libmodbus => ("read_holding 0 126", "error Too many data"),
        Stack::Pymodbus => ("read_holding 0 126", "error 1 <= count 126 <= 125 !"),
        Stack::TokioModbus => ("read_holding 0 126", "exception 3"),
    });
    if stack == Stack::TokioModbus {
        steps.push(("read_coils 0 2001", "exception 3"));
    }
    if stack != Stack::Libmodbus {
        steps.extend([
            ("diag 0 0x1234", "ok 0 4660"),
            // 00 "ferrobus", 01 "FB-GENERIC", 02 "0.1".
            ("read_device_id 1 0", "ok 00=666572726f627573 01=46422d47454e45524943 02=302e31"),
        ]);
        // An empty FIFO. pymodbus's RTU client sizes the FC18 reply 2 bytes short.
        let fifo = if stack == Stack::Pymodbus && over == Over::Rtu { "timeout" } else { "ok" };
        steps.push(("read_fifo 0x04DE", fifo));
    }
    if stack == Stack::Pymodbus {
        steps.extend([
            ("read_file 1 0 2", "ok 0 0"),
            ("write_file 1 0 7 8", "ok"),
            ("read_file 1 0 2", "ok 7 8"),
            ("read_file 17 0 2", "exception 2"),
        ]);
    }
    steps
}

/// Holding register writes with every function code, then a read-back.
const REGISTER_WRITES: &[(&str, &str)] = &[
    ("write_register 5 1234", "ok"),
    ("write_registers 6 5 6 7", "ok"),
    // (0x04D2 AND 0xF2) OR (0x25 AND NOT 0xF2) = 0xD7.
    ("mask_write 5 0xF2 0x25", "ok"),
    ("write_read 10 3 11 9 8", "ok 0 9 8"),
    ("read_holding 5 4", "ok 215 5 6 7"),
];

fn client_against_generic_sim(stack: Stack, over: Over) {
    let needs = if over == Over::Rtu { vec![stack.need(), Need::Socat] } else { vec![stack.need()] };
    let Some(_turn) = require(&needs) else { return };
    let parity = stack.parity();
    let served = sim(over, parity, &["--profile", "generic"]);
    check_script(stack, &served.link, 1, &generic_script(stack, over));
}

#[test]
fn libmodbus_client_over_rtu_gets_every_answer_from_the_generic_sim() {
    client_against_generic_sim(Stack::Libmodbus, Over::Rtu);
}

#[test]
fn libmodbus_client_over_tcp_gets_every_answer_from_the_generic_sim() {
    client_against_generic_sim(Stack::Libmodbus, Over::Tcp);
}

#[test]
fn pymodbus_client_over_rtu_gets_every_answer_from_the_generic_sim() {
    client_against_generic_sim(Stack::Pymodbus, Over::Rtu);
}

#[test]
fn pymodbus_client_over_tcp_gets_every_answer_from_the_generic_sim() {
    client_against_generic_sim(Stack::Pymodbus, Over::Tcp);
}

#[test]
fn tokio_modbus_client_over_rtu_gets_every_answer_from_the_generic_sim() {
    client_against_generic_sim(Stack::TokioModbus, Over::Rtu);
}

#[test]
fn tokio_modbus_client_over_tcp_gets_every_answer_from_the_generic_sim() {
    client_against_generic_sim(Stack::TokioModbus, Over::Tcp);
}

// Regression: the generic sim used to spin forever (100% CPU, memory growing, deaf to SIGTERM)
// on any holding register write but one register at address 0.

fn register_writes_against_generic_sim(stack: Stack) {
    let Some(_turn) = require(&[stack.need()]) else { return };
    let served = sim(Over::Tcp, stack.parity(), &["--profile", "generic"]);
    check_script(stack, &served.link, 1, REGISTER_WRITES);
}

#[test]
fn libmodbus_client_writes_holding_registers_of_the_generic_sim() {
    register_writes_against_generic_sim(Stack::Libmodbus);
}

#[test]
fn pymodbus_client_writes_holding_registers_of_the_generic_sim() {
    register_writes_against_generic_sim(Stack::Pymodbus);
}

#[test]
fn tokio_modbus_client_writes_holding_registers_of_the_generic_sim() {
    register_writes_against_generic_sim(Stack::TokioModbus);
}

/// A device of 100 read/write holding registers, each its own profile item.
pub(crate) const ITEM_REGISTERS_PROFILE: &str = r#"
[device]
name = "holding registers as items"
vendor = "ferrobus"
product_code = "FB-ITEMS"
revision = "0.1"

[[registers]]
number = 0
count = 100
name = "r"
access = "rw"
"#;

/// Writes `ITEM_REGISTERS_PROFILE` into `dir` and returns its path.
pub(crate) fn item_registers_profile(dir: &TempDir) -> String {
    let path = dir.path().join("items.toml");
    std::fs::write(&path, ITEM_REGISTERS_PROFILE).expect("writing the profile");
    path.display().to_string()
}

#[test]
fn every_peer_client_writes_holding_registers_of_a_sim_whose_registers_are_profile_items() {
    let Some(_turn) = require(&[Need::Libmodbus, Need::Pymodbus, Need::TokioModbus]) else { return };
    let dir = TempDir::new();
    let profile = item_registers_profile(&dir);
    for stack in [Stack::Libmodbus, Stack::Pymodbus, Stack::TokioModbus] {
        // A fresh device for each client: the read-back expects exactly one round of writes.
        let served = sim(Over::Tcp, Parity::Even, &["--profile", &profile]);
        check_script(stack, &served.link, 1, REGISTER_WRITES);
    }
}
