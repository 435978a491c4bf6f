//! Fault rules aimed at requests (`--fault UNIT:fc=..,addr=..,ACTION`), each met by a peer
//! client: the pymodbus and libmodbus script clients over Modbus/TCP and RTU (a socat pair),
//! and a pymodbus client scripted in Python for what a script line cannot show — when a
//! delayed or trickled reply arrives, and what share of requests a rule takes.
//!
//! One simulator carries one rule per block of ten holding registers; a read outside every
//! block after each fault shows that the client recovers and that the rule's address range
//! holds.

use std::process::Command;
use std::time::Duration;

use crate::support::peers::Served;
use crate::support::process::output_within;
use crate::support::{Link, Need, Over, Parity, Stack, check_script, require, sim};

/// The rules: one per block of registers, all for 0x03; and half the 0x04 reads refused.
const RULES: &[&str] = &[
    "1:fc=3,addr=100-109,exception=0x06",
    "1:fc=3,addr=110-119,no-reply",
    "1:fc=0x03,addr=120-129,delay=100ms",
    "1:fc=3,addr=130-139,short",
    "1:fc=3,addr=140-149,malformed",
    "1:fc=3,addr=150-159,unit=7",
    "1:fc=3,addr=160-169,tid=+1",
    "1:fc=3,addr=170-179,trickle=5ms",
    "1:fc=4,share=50%,exception=0x21",
];

fn sim_with_rules(over: Over, parity: Parity) -> Served {
    let mut args = vec!["--profile", "generic"];
    for rule in RULES {
        args.extend(["--fault", rule]);
    }
    sim(over, parity, &args)
}

/// What `stack`'s script client prints for each rule over `over`.
fn steps(stack: Stack, over: Over) -> Vec<(&'static str, &'static str)> {
    let tcp = over == Over::Tcp;
    vec![
        ("read_holding 100 2", "exception 6"),
        // A read that touches the block's last address is aimed at too; one past it is not.
        ("read_holding 98 2", "ok 0 0"),
        ("read_holding 109 2", "exception 6"),
        ("read_holding 110 2", "timeout"),
        ("read_holding 0 2", "ok 0 0"),
        // 100 ms late, well within the 300 ms timeout (a loaded machine adds to it).
        ("read_holding 120 2", "ok 0 0"),
        // Half a frame: the client waits for the rest.
        ("read_holding 130 2", "timeout"),
        ("read_holding 0 1", "ok 0"),
        // A valid checksum over a PDU one byte short of its byte count: the client waits
        // for the byte the count promises.
        ("read_holding 140 2", "timeout"),
        ("read_holding 0 1", "ok 0"),
        // From unit 7: pymodbus waits for unit 1; libmodbus checks the unit on RTU only.
        (
            "read_holding 150 2",
            match (stack, tcp) {
                (Stack::Libmodbus, true) => "ok 0 0",
                (Stack::Libmodbus, false) => "error Response not from requested slave",
                _ => "timeout",
            },
        ),
        ("read_holding 0 1", "ok 0"),
        // Another transaction id: Modbus/TCP only, a serial reply has none.
        (
            "read_holding 160 2",
            match (stack, tcp) {
                (_, false) => "ok 0 0",
                (Stack::Libmodbus, true) => "error Invalid data",
                _ => "timeout",
            },
        ),
        ("read_holding 0 1", "ok 0"),
        // Byte by byte, 5 ms apart (50 ms for an MBAP reply, well within the timeout): both
        // clients gather the bytes.
        ("read_holding 170 2", "ok 0 0"),
        ("read_holding 0 1", "ok 0"),
        // Another function code at a blocked address: no rule for it.
        ("read_coils 100 1", "ok 0"),
    ]
}

fn client_meets_each_rule(stack: Stack, over: Over) {
    let needs = if over == Over::Rtu { vec![stack.need(), Need::Socat] } else { vec![stack.need()] };
    let Some(_turn) = require(&needs) else { return };
    let served = sim_with_rules(over, stack.parity());
    check_script(stack, &served.link, 1, &steps(stack, over));
}

#[test]
fn pymodbus_client_over_tcp_meets_each_fault_rule() {
    client_meets_each_rule(Stack::Pymodbus, Over::Tcp);
}

#[test]
fn pymodbus_client_over_rtu_meets_each_fault_rule() {
    client_meets_each_rule(Stack::Pymodbus, Over::Rtu);
}

#[test]
fn libmodbus_client_over_tcp_meets_each_fault_rule() {
    client_meets_each_rule(Stack::Libmodbus, Over::Tcp);
}

#[test]
fn libmodbus_client_over_rtu_meets_each_fault_rule() {
    client_meets_each_rule(Stack::Libmodbus, Over::Rtu);
}

/// A pymodbus client that times a delayed, a trickled and a plain read, counts how many of
/// 40 input register reads get exception 0x21, and prints one line each.
const TIMED: &str = r#"
import asyncio, sys, time
from pymodbus.client import AsyncModbusTcpClient

async def main(host, port):
    client = AsyncModbusTcpClient(host, port=int(port), timeout=2, retries=0)
    await client.connect()
    for name, address in (("delay", 120), ("trickle", 170), ("plain", 0)):
        start = time.monotonic()
        reply = await client.read_holding_registers(address, count=2, device_id=1)
        ms = (time.monotonic() - start) * 1000
        print(f"{name} {ms:.1f} {'error' if reply.isError() else 'ok'}")
    codes = []
    for _ in range(40):
        reply = await client.read_input_registers(0, count=1, device_id=1)
        codes.append(getattr(reply, "exception_code", 0) if reply.isError() else 0)
    print(f"share {codes.count(0x21)} {codes.count(0)}")
    client.close()

asyncio.run(main(*sys.argv[1].rsplit(":", 1)))
"#;

#[test]
fn a_pymodbus_client_gets_delayed_and_trickled_replies_never_early_and_a_share_refused() {
    let Some(_turn) = require(&[Need::Pymodbus]) else { return };
    let served = sim_with_rules(Over::Tcp, Parity::None);
    let Link::Tcp(addr) = &served.link else { panic!("a TCP sim") };
    let output = output_within(
        Command::new(crate::support::env::python()).args(["-c", TIMED, addr]),
        "",
        Duration::from_secs(60),
    );
    let stdout = String::from_utf8_lossy(&output.stdout);
    let lines: Vec<Vec<&str>> = stdout.lines().map(|l| l.split(' ').collect()).collect();
    let context = format!("stdout:\n{stdout}stderr:\n{}", String::from_utf8_lossy(&output.stderr));
    let ms = |name: &str| -> f64 {
        let line = lines.iter().find(|l| l.first() == Some(&name)).unwrap_or_else(|| panic!("no {name}: {context}"));
        assert_eq!(line.get(2), Some(&"ok"), "{name}: {context}");
        line.get(1).and_then(|v| v.parse().ok()).unwrap_or_else(|| panic!("{name}: {context}"))
    };
    // Never early; how late is the machine's business. The MBAP reply to a read of two
    // registers is 11 bytes: 10 gaps of 5 ms.
    let (delay, trickle, plain) = (ms("delay"), ms("trickle"), ms("plain"));
    assert!(delay >= 100.0, "the delayed reply came after {delay} ms, before its 100 ms: {context}");
    assert!(trickle >= 50.0, "the trickled reply came whole after {trickle} ms, before 10 × 5 ms: {context}");
    eprintln!("delay {delay} ms, trickle {trickle} ms, a plain read {plain} ms");
    let share = lines.iter().find(|l| l.first() == Some(&"share")).unwrap_or_else(|| panic!("no share: {context}"));
    let (refused, served): (u32, u32) = (
        share.get(1).and_then(|v| v.parse().ok()).unwrap_or_default(),
        share.get(2).and_then(|v| v.parse().ok()).unwrap_or_default(),
    );
    // The draws are seeded (--seed 1), so the count repeats; any fair share of 40 lies here.
    assert_eq!(refused + served, 40, "every read is refused with 0x21 or served: {context}");
    assert!((8..=32).contains(&refused), "{refused} of 40 reads refused by a 50% rule: {context}");
}
