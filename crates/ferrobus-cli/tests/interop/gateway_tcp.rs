//! `ferrobus gateway --tcp`: the gateway as a Modbus/TCP multiplexer, one line to a device
//! that takes one client connection (the libmodbus server serves one connection at a time),
//! shared by many clients in front. Twenty clients each write their own block and read it
//! back through it, against libmodbus and pymodbus, with no reply given to the wrong client,
//! and against libmodbus with eight in flight on its connection (`--in-flight 8`); pymodbus,
//! which drops the requests after the first that reach it together, answers 0x0B to those and
//! nothing crosses;
//! read-only mode and the cache; a device that is down when the gateway starts and one that
//! restarts mid-run; two TCP lines from a lines file, each unit on its own device.

use std::io::Write;
use std::net::TcpStream;
use std::process::Command;
use std::time::{Duration, Instant};

use crate::support::mbap::{ask, connect_to, mbap, read_frame};
use crate::support::peers::{free_port, peer_tcp_server_on};
use crate::support::process::{Proc, Stream};
use crate::support::{Need, Over, Stack, TempDir, peer_server, require};

/// A bound on how long any single step may take before the test fails (not a timing claim).
const STEP: Duration = Duration::from_secs(20);

/// `ferrobus gateway` listening on 127.0.0.1, once it says so.
struct Gw {
    proc: Proc,
    addr: String,
}

/// `ferrobus LINE --timeout 1s gateway --listen ADDR ARGS`: `line` names the device
/// (`--tcp HOST:PORT`) or is empty beside `--lines-file`.
fn gateway(line: &[&str], args: &[&str]) -> Gw {
    let addr = format!("127.0.0.1:{}", free_port());
    let mut command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
    command.args(line).args(["--timeout", "1s", "gateway", "--listen", &addr]).args(args);
    let proc = Proc::spawn("ferrobus gateway", &mut command);
    proc.wait_for(Stream::Err, |l| l.starts_with("gateway: listening on"), STEP);
    Gw { proc, addr }
}

/// `gateway` in front of the Modbus/TCP device at `device`.
fn in_front_of(device: &str, args: &[&str]) -> Gw {
    gateway(&["--tcp", device], args)
}

/// The counters the gateway prints on SIGUSR1: the first `lines` lines' totals.
fn counters(gw: &Gw, lines: usize) -> Vec<String> {
    let pid = gw.proc.id().to_string();
    assert!(Command::new("kill").args(["-USR1", &pid]).status().unwrap().success());
    (0..lines).map(|_| gw.proc.wait_for(Stream::Err, |l| l.starts_with("line "), STEP)).collect()
}

/// The address of a TCP server's link.
fn tcp_addr(link: &crate::support::Link) -> String {
    match link {
        crate::support::Link::Tcp(addr) => addr.clone(),
        other @ crate::support::Link::Serial { .. } => panic!("not a TCP link: {other:?}"),
    }
}

const READ_5: [u8; 5] = [0x03, 0x00, 0x05, 0x00, 0x01];

/// Register 5 of the peers' data map before anyone writes it: 5 * 7 + 3.
const INITIAL_5: [u8; 4] = [0x03, 0x02, 0x00, 38];

/// What the clients of [`write_and_read_back`] saw.
#[derive(Default)]
struct Seen {
    /// What went wrong: a reply under another transaction id or unit, a write not echoed, a
    /// read-back that is not the values written, a connection lost.
    problems: Vec<String>,
    /// Requests answered 0x0B (the device did not respond), when those are tolerated.
    unanswered: usize,
}

/// `clients` clients at once through `addr`, each writing its own 10 registers (client i at
/// 10 * i) `rounds` times with new values and reading them back. With `tolerate_0b`, a 0x0B
/// under the request's own transaction id is counted, not a problem, and ends the round (a
/// write the device never answered may or may not have been done).
fn write_and_read_back(addr: &str, clients: u16, rounds: u16, tolerate_0b: bool) -> Seen {
    let threads: Vec<_> = (0..clients)
        .map(|i| {
            let addr = addr.to_string();
            std::thread::spawn(move || {
                let mut seen = Seen::default();
                let mut stream = connect_to(&addr);
                let start = (10 * i).to_be_bytes();
                for round in 0..rounds {
                    let values: Vec<u16> = (0..10).map(|k| i * 1000 + round * 10 + k).collect();
                    let words: Vec<u8> = values.iter().flat_map(|v| v.to_be_bytes()).collect();
                    let write = [&[0x10, start[0], start[1], 0x00, 0x0A, 20][..], &words].concat();
                    let read_back = [&[0x03, 20][..], &words].concat();
                    let t = round * 2;
                    let steps = [
                        (t, write, vec![0x10, start[0], start[1], 0x00, 0x0A]),
                        (t + 1, vec![0x03, start[0], start[1], 0x00, 0x0A], read_back),
                    ];
                    for (t, request, expected) in steps {
                        stream.write_all(&mbap(t, 1, &request)).unwrap();
                        match read_frame(&mut stream) {
                            Some(reply) if reply == mbap(t, 1, &expected) => {}
                            Some(reply) if tolerate_0b && reply == mbap(t, 1, &[request[0] | 0x80, 0x0B]) => {
                                seen.unanswered += 1;
                                break;
                            }
                            Some(reply) => seen.problems.push(format!("client {i}, transaction {t}: got {reply:02X?}")),
                            None => {
                                seen.problems.push(format!("client {i}: connection lost at transaction {t}"));
                                return seen;
                            }
                        }
                    }
                }
                seen
            })
        })
        .collect();
    threads.into_iter().fold(Seen::default(), |mut all, t| {
        let seen = t.join().unwrap_or_else(|_| Seen { problems: vec!["a client panicked".into()], unanswered: 0 });
        all.problems.extend(seen.problems);
        all.unanswered += seen.unanswered;
        all
    })
}

/// Twenty clients through `gateway --tcp` with `args` to `stack`'s server.
fn twenty_clients_through_the_gateway(stack: Stack, args: &[&str]) {
    let Some(_turn) = require(&[stack.need()]) else { return };
    let device = peer_server(stack, Over::Tcp, 1);
    let gw = in_front_of(&tcp_addr(&device.link), &[&["--queue", "64"][..], args].concat());
    let Seen { problems, .. } = write_and_read_back(&gw.addr, 20, 10, false);
    assert!(problems.is_empty(), "{} mismatches: {problems:#?}", problems.len());
    let [line] = counters(&gw, 1).try_into().unwrap();
    assert!(line.contains("requests 400 replies 400 timeouts 0"), "{line}");
    assert!(line.contains("connects 1 connect-failures 0 disconnects 0"), "{line}");
}

#[test]
fn twenty_clients_through_a_tcp_gateway_to_a_one_connection_libmodbus_server_each_read_back_their_own_writes() {
    twenty_clients_through_the_gateway(Stack::Libmodbus, &[]);
}

#[test]
fn twenty_clients_through_a_tcp_gateway_to_a_pymodbus_server_each_read_back_their_own_writes() {
    twenty_clients_through_the_gateway(Stack::Pymodbus, &[]);
}

/// The libmodbus server reads its connection in order, one request at a time: eight sent
/// before the first is answered are answered in turn.
#[test]
fn twenty_clients_through_a_pipelined_tcp_gateway_to_a_libmodbus_server_each_read_back_their_own_writes() {
    twenty_clients_through_the_gateway(Stack::Libmodbus, &["--in-flight", "8"]);
}

/// pymodbus's server (3.16.1) answers only the first of the requests that reach it in one
/// read and drops the rest: a device that wants `--in-flight 1`. Pipelined, its dropped
/// requests time out and get 0x0B, and no client is ever handed another's reply.
#[test]
fn in_front_of_pymodbus_which_drops_pipelined_requests_they_get_0b_and_no_reply_crosses_to_another_client() {
    let Some(_turn) = require(&[Stack::Pymodbus.need()]) else { return };
    let device = peer_server(Stack::Pymodbus, Over::Tcp, 1);
    let gw = in_front_of(&tcp_addr(&device.link), &["--in-flight", "8", "--backoff-after", "0"]);
    let Seen { problems, unanswered } = write_and_read_back(&gw.addr, 10, 3, true);
    assert!(problems.is_empty(), "{} mismatches ({unanswered} answered 0x0B): {problems:#?}", problems.len());
    let [line] = counters(&gw, 1).try_into().unwrap();
    assert!(line.contains("connects 1 connect-failures 0 disconnects 0"), "{line}");
}

#[test]
fn a_read_only_tcp_gateway_refuses_a_write_with_01_and_the_device_keeps_its_value() {
    let Some(_turn) = require(&[Need::Libmodbus]) else { return };
    let device = peer_server(Stack::Libmodbus, Over::Tcp, 1);
    let gw = in_front_of(&tcp_addr(&device.link), &["--read-only"]);
    let mut client = connect_to(&gw.addr);
    assert_eq!(ask(&mut client, 1, 1, &[0x06, 0x00, 0x05, 0x12, 0x34]), [0x86, 0x01]);
    assert_eq!(ask(&mut client, 2, 1, &[0x10, 0x00, 0x05, 0x00, 0x01, 0x02, 0x12, 0x34]), [0x90, 0x01]);
    assert_eq!(ask(&mut client, 3, 1, &READ_5), INITIAL_5, "the write never reached the device");
}

#[test]
fn through_a_tcp_gateway_the_cache_answers_a_repeated_read_without_asking_the_device() {
    let Some(_turn) = require(&[Need::Pymodbus]) else { return };
    // pymodbus takes several connections: the test changes the register behind the gateway.
    let device = peer_server(Stack::Pymodbus, Over::Tcp, 1);
    let gw = in_front_of(&tcp_addr(&device.link), &["--cache-max-age", "60s"]);
    let mut client = connect_to(&gw.addr);
    assert_eq!(ask(&mut client, 1, 1, &READ_5), INITIAL_5);
    let mut direct = connect_to(&tcp_addr(&device.link));
    assert_eq!(ask(&mut direct, 1, 1, &[0x06, 0x00, 0x05, 0x00, 0x63]), [0x06, 0x00, 0x05, 0x00, 0x63]);
    assert_eq!(ask(&mut direct, 2, 1, &READ_5), [0x03, 0x02, 0x00, 0x63]);
    assert_eq!(ask(&mut client, 2, 1, &READ_5), INITIAL_5, "answered from the cache, not the device");
    // A write through the gateway drops the cached read: the next one asks the device.
    assert_eq!(ask(&mut client, 3, 1, &[0x06, 0x00, 0x05, 0x00, 0x64]), [0x06, 0x00, 0x05, 0x00, 0x64]);
    assert_eq!(ask(&mut client, 4, 1, &READ_5), [0x03, 0x02, 0x00, 0x64]);
    let [line] = counters(&gw, 1).try_into().unwrap();
    assert!(line.contains("requests 3 replies 3") && line.contains("cached 1"), "{line}");
}

/// Asks `pdu` of unit 1 through `client` until the answer is not 0x0A (the line down), within
/// [`STEP`]; returns the answer and how many 0x0A came first.
fn until_served(client: &mut TcpStream, pdu: &[u8], t: &mut u16) -> (Vec<u8>, u32) {
    let deadline = Instant::now() + STEP;
    let mut down = 0;
    loop {
        *t += 1;
        let reply = ask(client, *t, 1, pdu);
        if reply != [pdu[0] | 0x80, 0x0A] {
            return (reply, down);
        }
        down += 1;
        assert!(Instant::now() < deadline, "still 0x0A after {down} requests");
    }
}

#[test]
fn a_tcp_device_down_when_the_gateway_starts_gets_0a_until_it_comes_up_and_is_then_served() {
    let Some(_turn) = require(&[Need::Libmodbus]) else { return };
    let port = free_port();
    let gw = in_front_of(&format!("127.0.0.1:{port}"), &[]);
    let mut client = connect_to(&gw.addr);
    assert_eq!(ask(&mut client, 1, 1, &READ_5), [0x83, 0x0A], "nobody listens: the path is unavailable");
    let _device = peer_tcp_server_on(Stack::Libmodbus, port, 1, &[]);
    let mut t = 1;
    let (reply, _) = until_served(&mut client, &READ_5, &mut t);
    assert_eq!(reply, INITIAL_5);
    let [line] = counters(&gw, 1).try_into().unwrap();
    assert!(line.contains("connects 1 connect-failures ") && line.contains("disconnects 0"), "{line}");
    assert!(!line.contains("connect-failures 0"), "the first request's connect failed: {line}");
}

#[test]
fn a_tcp_device_that_restarts_mid_run_is_reconnected_and_served_again() {
    let Some(_turn) = require(&[Need::Libmodbus]) else { return };
    let port = free_port();
    let mut device = peer_tcp_server_on(Stack::Libmodbus, port, 1, &[]);
    let gw = in_front_of(&format!("127.0.0.1:{port}"), &[]);
    let mut client = connect_to(&gw.addr);
    assert_eq!(ask(&mut client, 1, 1, &[0x06, 0x00, 0x05, 0x10, 0x92]), [0x06, 0x00, 0x05, 0x10, 0x92]);
    assert_eq!(ask(&mut client, 2, 1, &READ_5), [0x03, 0x02, 0x10, 0x92]);
    device.terminate();
    let _device = peer_tcp_server_on(Stack::Libmodbus, port, 1, &[]);
    let mut t = 2;
    let (reply, _) = until_served(&mut client, &READ_5, &mut t);
    assert_eq!(reply, INITIAL_5, "the restarted device, which starts from the data map again");
    let [line] = counters(&gw, 1).try_into().unwrap();
    assert!(line.contains("connects 2 ") && line.contains("disconnects 1"), "{line}");
}

#[test]
fn a_lines_file_with_two_tcp_lines_routes_each_unit_to_its_own_device() {
    let Some(_turn) = require(&[Need::Libmodbus, Need::Pymodbus]) else { return };
    let libmodbus = peer_server(Stack::Libmodbus, Over::Tcp, 1);
    let pymodbus = peer_server(Stack::Pymodbus, Over::Tcp, 1);
    let dir = TempDir::new();
    let file = dir.path().join("lines.toml");
    let text = format!(
        "[[line]]\ntcp = \"{}\"\nunits = [1]\n\n[[line]]\ntcp = \"{}\"\nretries = 1\nrenumber = {{ 2 = 1 }}\n",
        tcp_addr(&libmodbus.link),
        tcp_addr(&pymodbus.link)
    );
    std::fs::write(&file, text).unwrap();
    let gw = gateway(&[], &["--lines-file", &file.display().to_string()]);
    let mut client = connect_to(&gw.addr);
    assert_eq!(ask(&mut client, 1, 1, &[0x06, 0x00, 0x05, 0x00, 0x6F]), [0x06, 0x00, 0x05, 0x00, 0x6F]);
    assert_eq!(ask(&mut client, 2, 2, &[0x06, 0x00, 0x05, 0x00, 0xDE]), [0x06, 0x00, 0x05, 0x00, 0xDE]);
    assert_eq!(ask(&mut client, 3, 1, &READ_5), [0x03, 0x02, 0x00, 0x6F], "unit 1: libmodbus");
    assert_eq!(ask(&mut client, 4, 2, &READ_5), [0x03, 0x02, 0x00, 0xDE], "unit 2: pymodbus's unit 1");
    assert_eq!(ask(&mut client, 5, 3, &READ_5), [0x83, 0x0A], "unit 3 is in no route");
    let lines = counters(&gw, 2);
    assert!(lines[0].starts_with(&format!("line {}:", tcp_addr(&libmodbus.link))), "{lines:#?}");
    assert!(lines[1].starts_with(&format!("line {}:", tcp_addr(&pymodbus.link))), "{lines:#?}");
    assert!(lines.iter().all(|l| l.contains("requests 2 replies 2")), "{lines:#?}");
}
