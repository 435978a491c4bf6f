//! A serial port that disappears and comes back, seen through the library: a
//! `ferrobus::Client` on one end of a socat pair, a server (`ferrobus sim` or the libmodbus
//! peer) on the other.
//!
//! socat is stopped: both ptys vanish and the links are removed. The next requests must fail
//! with `Error::Io` (not hang, not panic). socat is started again with the same link names
//! and the server restarted; the client's next request must succeed, on the reopened port.
//! The simulator, for its part, must not need restarting: it reopens its port itself and
//! keeps its devices' state.

use std::future::Future;
use std::path::Path;
use std::time::{Duration, Instant};

use ferrobus::{Client, ClientConfig, Error, SerialConfig, Transport};
use ferrobus_proto::frame::{LineConfig, Parity as LineParity};

use tokio::runtime::Runtime;

use crate::support::cli::BAUD;
use crate::support::peers::{peer_server_on, sim_on};
use crate::support::process::{Proc, Stream};
use crate::support::{Need, Parity, SocatPair, Stack, TempDir, require};

/// Runs `request` on `runtime`; a request that takes more than 5 s is a hang.
fn within<T>(runtime: &Runtime, what: &str, request: impl Future<Output = T>) -> T {
    runtime
        .block_on(async { tokio::time::timeout(Duration::from_secs(5), request).await })
        .unwrap_or_else(|_| panic!("{what}: no result within 5 s (hung)"))
}

/// The library's client on `path` at 8E1 and the lines' baud rate, with a 500 ms timeout.
fn client(runtime: &Runtime, path: &Path) -> Client {
    let line = LineConfig::new(BAUD).expect("a baud rate").with_parity(LineParity::Even);
    let config = ClientConfig { timeout: Duration::from_millis(500), ..ClientConfig::default() };
    let transport = Transport::rtu(SerialConfig::new(path, line));
    within(runtime, "connecting", Client::connect(transport, config)).expect("opening the port")
}

/// Stops the line and checks that requests fail with an IO error; then brings the line and
/// the server (`start`) back and checks (`works`) that the client is usable again.
fn survives_a_vanishing_port(unit: u8, start: impl Fn(&Path) -> Proc, works: impl Fn(&Runtime, &Client)) {
    let runtime = Runtime::new().expect("a runtime");
    let dir = TempDir::new();
    let mut line = SocatPair::start(dir.path());
    let server = start(&line.b);
    let client = client(&runtime, &line.a);
    works(&runtime, &client);

    // A request waiting for a reply (from a unit nobody serves, 3 s timeout) while socat is
    // stopped ends with the IO error, not with the timeout.
    let waiting = client.with_timeout(Duration::from_secs(3));
    let in_flight = runtime.spawn(async move { waiting.read_holding_registers(unit + 1, 0, 1).await });
    let stopped = Instant::now();
    line.stop();
    assert!(!line.a.exists(), "socat left its link {} behind", line.a.display());
    let result = within(&runtime, "the request in flight", in_flight).expect("the request task");
    let took = stopped.elapsed();
    // The IO error, not the 3 s timeout's: it ended when the port went. How soon is a figure.
    assert!(matches!(result, Err(Error::Io { .. })), "the request in flight after {took:?}: {result:?}");
    eprintln!("the request in flight, {took:?} after socat was stopped: {result:?}");
    for attempt in 1..=2 {
        let result = within(&runtime, "a request on a vanished port", client.read_holding_registers(unit, 0, 1));
        assert!(matches!(result, Err(Error::Io { .. })), "request {attempt} after the port vanished: {result:?}");
        eprintln!("request {attempt} after the port vanished: {result:?}");
    }

    line.restart();
    drop(server);
    let _server = start(&line.b);
    works(&runtime, &client);
}

#[test]
fn client_fails_with_io_while_the_port_is_gone_and_reopens_it_for_the_sim() {
    let Some(_turn) = require(&[Need::Socat]) else { return };
    survives_a_vanishing_port(
        1,
        |path| sim_on(path, Parity::Even, &["--profile", "generic"]),
        |runtime, client| {
            // A fresh simulator each time: coil 3 starts off.
            within(runtime, "write coil", client.write_single_coil(1, 3, true)).expect("FC05");
            let coils = within(runtime, "read coils", client.read_coils(1, 0, 4)).expect("FC01");
            assert_eq!(coils, [false, false, false, true]);
        },
    );
}

#[test]
fn client_fails_with_io_while_the_port_is_gone_and_reopens_it_for_libmodbus() {
    let Some(_turn) = require(&[Need::Socat, Need::Libmodbus]) else { return };
    survives_a_vanishing_port(
        17,
        |path| peer_server_on(Stack::Libmodbus, path, 17),
        |runtime, client| {
            let holding = within(runtime, "read holding", client.read_holding_registers(17, 0, 3)).expect("FC03");
            assert_eq!(holding, [3, 10, 17]);
            within(runtime, "write register", client.write_single_register(17, 5, 0xBEEF)).expect("FC06");
            let back = within(runtime, "read back", client.read_holding_registers(17, 5, 1)).expect("FC03");
            assert_eq!(back, [0xBEEF]);
        },
    );
}

#[test]
fn the_sim_reopens_its_vanished_port_and_keeps_its_state() {
    let Some(_turn) = require(&[Need::Socat]) else { return };
    let runtime = Runtime::new().expect("a runtime");
    let dir = TempDir::new();
    let mut line = SocatPair::start(dir.path());
    let sim = sim_on(&line.b, Parity::Even, &["--profile", "generic"]);
    let client = client(&runtime, &line.a);
    within(&runtime, "write coil", client.write_single_coil(1, 3, true)).expect("FC05");

    line.stop();
    let said = sim.wait_for(Stream::Err, |l| l.contains("reopening"), Duration::from_secs(5));
    eprintln!("{said}");
    line.restart();
    sim.wait_for(Stream::Err, |l| l.contains("again"), Duration::from_secs(5));
    let coils = within(&runtime, "read coils", client.read_coils(1, 0, 4)).expect("FC01 after the port came back");
    assert_eq!(coils, [false, false, false, true], "the coil written before the port vanished");
}
