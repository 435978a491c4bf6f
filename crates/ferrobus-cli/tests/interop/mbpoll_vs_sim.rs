//! mbpoll (libmodbus underneath, its own command line and output) against `ferrobus sim
//! --profile generic`, over RTU on a socat pair (`-m rtu`, the pty path) and over TCP.
//!
//! mbpoll prints each value as `[ref]: value` and numbers references from 1 unless `-0`.

use crate::clients_vs_sim::item_registers_profile;
use crate::support::peers::Polled;
use crate::support::{Link, Need, Over, Parity, TempDir, mbpoll, require, sim};

fn values(polled: &Polled) -> Vec<(u32, &str)> {
    polled.values.iter().map(|(r, v)| (*r, v.as_str())).collect()
}

#[track_caller]
fn succeeded(polled: Polled) -> Polled {
    assert_eq!(polled.code, 0, "mbpoll failed:\n{}\n{}", polled.stdout, polled.stderr);
    polled
}

/// Reads of the four tables, coil writes read back, 1-based references, an exception and
/// another unit's silence.
fn reads_writes_and_errors(link: &Link) {
    let read = |args: &[&str]| succeeded(mbpoll(link, 1, true, args, &[]));
    // FC03, FC04, FC02 of a fresh device: zeros, at both ends of the address space.
    assert_eq!(values(&read(&["-t", "4", "-r", "0", "-c", "3"])), [(0, "0"), (1, "0"), (2, "0")]);
    assert_eq!(values(&read(&["-t", "3", "-r", "65534", "-c", "2"])), [(65534, "0"), (65535, "0")]);
    assert_eq!(values(&read(&["-t", "1", "-r", "0", "-c", "2"])), [(0, "0"), (1, "0")]);

    // FC0F (several values), FC05 (one), then FC01.
    let written = succeeded(mbpoll(link, 1, true, &["-t", "0", "-r", "2"], &["1", "0", "1"]));
    assert!(written.stdout.contains("Written 3 references."), "{}", written.stdout);
    let written = succeeded(mbpoll(link, 1, true, &["-t", "0", "-r", "9"], &["1"]));
    assert!(written.stdout.contains("Written 1 references."), "{}", written.stdout);
    let coils = read(&["-t", "0", "-r", "0", "-c", "10"]);
    let want = ["0", "0", "1", "0", "1", "0", "0", "0", "0", "1"];
    assert_eq!(values(&coils), (0..).zip(want).collect::<Vec<_>>());

    // Without -0, reference 3 is coil address 2.
    assert_eq!(values(&succeeded(mbpoll(link, 1, false, &["-t", "0", "-r", "3"], &[]))), [(3, "1")]);

    // Exception 02 past the address space.
    let past = mbpoll(link, 1, true, &["-t", "4", "-r", "65535", "-c", "2"], &[]);
    assert_ne!(past.code, 0);
    assert!(past.stderr.contains("Illegal data address"), "{}", past.stderr);

    // Unit 2 gets no answer.
    let silent = mbpoll(link, 2, true, &["-t", "4", "-r", "0"], &[]);
    assert_ne!(silent.code, 0);
    assert!(silent.stderr.contains("timed out"), "{}", silent.stderr);
    assert!(values(&silent).is_empty());
}

#[test]
fn mbpoll_over_rtu_reads_and_writes_the_generic_sim() {
    let Some(_turn) = require(&[Need::Mbpoll, Need::Socat]) else { return };
    let served = sim(Over::Rtu, Parity::Even, &["--profile", "generic"]);
    reads_writes_and_errors(&served.link);
    // FC11 (-u, RTU only): mbpoll takes the first byte for the id and the second, 'B', for
    // the run status.
    let id = succeeded(mbpoll(&served.link, 1, false, &["-u"], &[]));
    assert!(id.stdout.contains("Length: 6"), "{}", id.stdout);
    assert!(id.stdout.contains("Id    : 0x46"), "{}", id.stdout);
    assert!(id.stdout.contains("Status: On"), "{}", id.stdout);
}

#[test]
fn mbpoll_over_tcp_reads_and_writes_the_generic_sim() {
    let Some(_turn) = require(&[Need::Mbpoll]) else { return };
    let served = sim(Over::Tcp, Parity::Even, &["--profile", "generic"]);
    reads_writes_and_errors(&served.link);
}

/// FC06 (one value) and FC10 (several), read back with FC03.
fn register_writes(link: &Link) {
    let one = succeeded(mbpoll(link, 1, true, &["-t", "4", "-r", "5"], &["1234"]));
    assert!(one.stdout.contains("Written 1 references."), "{}", one.stdout);
    let three = succeeded(mbpoll(link, 1, true, &["-t", "4", "-r", "6"], &["5", "6", "7"]));
    assert!(three.stdout.contains("Written 3 references."), "{}", three.stdout);
    let back = succeeded(mbpoll(link, 1, true, &["-t", "4", "-r", "5", "-c", "4"], &[]));
    assert_eq!(values(&back), [(5, "1234"), (6, "5"), (7, "6"), (8, "7")]);
}

#[test]
fn mbpoll_writes_holding_registers_of_the_generic_sim() {
    let Some(_turn) = require(&[Need::Mbpoll, Need::Socat]) else { return };
    let served = sim(Over::Rtu, Parity::Even, &["--profile", "generic"]);
    register_writes(&served.link);
}

#[test]
fn mbpoll_writes_holding_registers_of_a_sim_whose_registers_are_profile_items() {
    let Some(_turn) = require(&[Need::Mbpoll, Need::Socat]) else { return };
    let dir = TempDir::new();
    let profile = item_registers_profile(&dir);
    let served = sim(Over::Rtu, Parity::Even, &["--profile", &profile]);
    register_writes(&served.link);
}
