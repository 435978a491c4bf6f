//! `ferrobus gateway` between real peers: the libmodbus, pymodbus and tokio-modbus TCP
//! clients through the gateway to `ferrobus sim` on a socat pty pair, the `ferrobus` client
//! through it to the libmodbus and pymodbus RTU servers, and the hostile-input tests of the
//! TCP server (tests/interop/tcp_server.rs) run against the gateway's front end.

use std::io::Write;
use std::net::TcpStream;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use crate::support::cli::{BAUD, Link};
use crate::support::env::require_tool;
use crate::support::mbap::{ask, closed_silently, connect_to, mbap, read_frame};
use crate::support::peers::{Stack, free_port, peer_server_on, sim_on};
use crate::support::process::{Proc, Stream};
use crate::support::{Need, Parity, SocatPair, TempDir, check_script, ferrobus, require, words};

/// A bound on how long any single step may take before the test fails (not a timing claim).
const STEP: Duration = Duration::from_secs(20);

/// A device behind a gateway: the device on one end of a socat pair, the gateway on the
/// other, listening on 127.0.0.1. Dropped in order: gateway, device, line, directory.
struct Behind {
    gateway: Proc,
    _device: Proc,
    _pair: SocatPair,
    _dir: TempDir,
    addr: String,
}

impl Behind {
    fn link(&self) -> Link {
        Link::Tcp(self.addr.clone())
    }
}

/// `ferrobus gateway GATEWAY_ARGS` to the device that `device` starts on a tty, at 8N1 (the
/// pymodbus peers cannot set parity on a pty opened twice). The gateway waits 100 ms for a
/// reply (the peer clients' own timeout is 300 ms).
fn behind(device: impl FnOnce(&Path) -> Proc, gateway_args: &[&str]) -> Behind {
    behind_with(device, gateway_args, &[])
}

fn behind_with(device: impl FnOnce(&Path) -> Proc, gateway_args: &[&str], wrapper: &[&str]) -> Behind {
    behind_waiting(device, "100ms", gateway_args, wrapper)
}

/// As [`behind_with`], the gateway waiting `timeout` for a reply.
fn behind_waiting(
    device: impl FnOnce(&Path) -> Proc,
    timeout: &str,
    gateway_args: &[&str],
    wrapper: &[&str],
) -> Behind {
    let dir = TempDir::new();
    let pair = SocatPair::start(dir.path());
    let device = device(&pair.b);
    let addr = format!("127.0.0.1:{}", free_port());
    let (program, pre) = match wrapper.split_first() {
        Some((program, rest)) => (program.to_string(), [rest, &["--", env!("CARGO_BIN_EXE_ferrobus")]].concat()),
        None => (env!("CARGO_BIN_EXE_ferrobus").to_string(), Vec::new()),
    };
    let mut command = Command::new(program);
    command.args(pre);
    command.args(["--port", &pair.a.display().to_string(), "--baud", &BAUD.to_string(), "--parity", "none"]);
    command.args(["--timeout", timeout, "gateway", "--listen", &addr]).args(gateway_args);
    let gateway = Proc::spawn("ferrobus gateway", &mut command);
    gateway.wait_for(Stream::Err, |l| l.starts_with("gateway: listening on"), STEP);
    Behind { gateway, _device: device, _pair: pair, _dir: dir, addr }
}

fn generic_sim(path: &Path) -> Proc {
    sim_on(path, Parity::None, &["--profile", "generic"])
}

/// What each peer client is answered through the gateway by the generic sim (unit 1; unit 2
/// is routed but silent, unit 3 is in no route).
fn script(stack: Stack) -> Vec<(&'static str, &'static str)> {
    let mut steps = vec![
        ("read_holding 0 3", "ok 0 0 0"),
        ("read_input 65534 2", "ok 0 0"),
        ("read_discrete 0 4", "ok 0 0 0 0"),
        ("write_coil 3 1", "ok"),
        ("write_coils 4 1 0 1", "ok"),
        ("read_coils 0 8", "ok 0 0 0 1 1 0 1 0"),
        ("write_register 5 1234", "ok"),
        ("write_registers 6 5 6 7", "ok"),
        ("mask_write 5 0xF2 0x25", "ok"),
        ("write_read 10 3 11 9 8", "ok 0 9 8"),
        ("read_holding 5 4", "ok 215 5 6 7"),
        ("read_exception_status", "ok 0"),
        // The device's own exception comes through as it was.
        ("read_holding 65535 2", "exception 2"),
        // Routed, but nobody answers: 0x0B; in no route: 0x0A.
        ("unit 2", "ok"),
        ("read_holding 0 1", "exception 11"),
        ("unit 3", "ok"),
        ("read_holding 0 1", "exception 10"),
        ("unit 1", "ok"),
        ("read_coils 0 1", "ok 0"),
    ];
    if stack != Stack::Libmodbus {
        steps.extend([
            ("diag 0 0x1234", "ok 0 4660"),
            ("read_device_id 1 0", "ok 00=666572726f627573 01=46422d47454e45524943 02=302e31"),
            ("read_fifo 0x04DE", "ok"),
        ]);
    }
    if stack == Stack::Pymodbus {
        steps.extend([("write_file 1 0 7 8", "ok"), ("read_file 1 0 2", "ok 7 8")]);
    }
    steps
}

fn client_through_gateway(stack: Stack) {
    let Some(_turn) = require(&[stack.need(), Need::Socat]) else { return };
    let gw = behind(generic_sim, &["--route", "1-2=0"]);
    check_script(stack, &gw.link(), 1, &script(stack));
}

#[test]
fn libmodbus_tcp_client_through_the_gateway_gets_every_answer_of_the_sim_and_the_gateway_exceptions() {
    client_through_gateway(Stack::Libmodbus);
}

#[test]
fn pymodbus_tcp_client_through_the_gateway_gets_every_answer_of_the_sim_and_the_gateway_exceptions() {
    client_through_gateway(Stack::Pymodbus);
}

#[test]
fn tokio_modbus_tcp_client_through_the_gateway_gets_every_answer_of_the_sim_and_the_gateway_exceptions() {
    client_through_gateway(Stack::TokioModbus);
}

/// The data map of tests/peers/README.md read and written through the gateway.
fn rtu_server_behind_gateway(stack: Stack) {
    let Some(_turn) = require(&[stack.need(), Need::Socat]) else { return };
    let gw = behind(|path| peer_server_on(stack, path, 1), &[]);
    let client = ferrobus(&gw.link());
    // Holding i = i*7+3; input 0x1000+i; coils i%3==0; discrete i%5==0.
    assert_eq!(client.values(&["read", "holding", "10", "--count", "3"]), words(&[73, 80, 87]));
    assert_eq!(client.values(&["read", "input", "2", "--count", "2"]), words(&[0x1002, 0x1003]));
    client.run(&["write", "register", "10", "4242"]).ok();
    assert_eq!(client.values(&["read", "holding", "10", "--count", "1"]), words(&[4242]));
    client.run(&["write", "registers", "20", "1", "2"]).ok();
    assert_eq!(client.values(&["read", "holding", "20", "--count", "2"]), words(&[1, 2]));
    client.run(&["write", "coil", "1", "1"]).ok();
    client.run(&["read", "coils", "0", "--count", "4"]).ok();
    client.run(&["read", "holding", "1000", "--count", "1"]).exception(2);
}

#[test]
fn the_ferrobus_client_through_the_gateway_reads_and_writes_a_libmodbus_rtu_server() {
    rtu_server_behind_gateway(Stack::Libmodbus);
}

#[test]
fn the_ferrobus_client_through_the_gateway_reads_and_writes_a_pymodbus_rtu_server() {
    rtu_server_behind_gateway(Stack::Pymodbus);
}

// The TCP server's hostile-input tests, against the gateway.

const READ_0: [u8; 5] = [0x03, 0x00, 0x00, 0x00, 0x01];

#[test]
fn through_the_gateway_twenty_pipelined_requests_get_twenty_replies_in_order_each_with_its_transaction() {
    let Some(_turn) = require(&[Need::Socat]) else { return };
    let gw = behind(generic_sim, &["--pipeline", "4"]);
    let mut stream = connect_to(&gw.addr);
    let mut burst = Vec::new();
    for i in 0..10u16 {
        let v = u8::try_from(i).unwrap();
        burst.extend(mbap(0x0100 + i, 1, &[0x06, 0x00, v, 0xB0, v]));
    }
    for i in 0..10u16 {
        burst.extend(mbap(0x0200 + i, 1, &[0x03, 0x00, u8::try_from(i).unwrap(), 0x00, 0x01]));
    }
    stream.write_all(&burst).unwrap();
    for i in 0..10u16 {
        let v = u8::try_from(i).unwrap();
        assert_eq!(read_frame(&mut stream), Some(mbap(0x0100 + i, 1, &[0x06, 0x00, v, 0xB0, v])), "write {i}");
    }
    for i in 0..10u16 {
        let v = u8::try_from(i).unwrap();
        assert_eq!(read_frame(&mut stream), Some(mbap(0x0200 + i, 1, &[0x03, 0x02, 0xB0, v])), "read {i}");
    }
}

#[test]
fn through_the_gateway_a_corrupt_mbap_header_closes_the_connection_and_nothing_behind_it_reaches_the_line() {
    let Some(_turn) = require(&[Need::Socat]) else { return };
    let gw = behind(generic_sim, &[]);
    let mut stream = connect_to(&gw.addr);
    let mut input = vec![0x00, 0x31, 0x00, 0x00, 0xFF, 0xFF, 0x01];
    input.extend(mbap(0x0032, 1, &[0x06, 0x00, 0x05, 0x12, 0x34]));
    stream.write_all(&input).unwrap();
    assert!(closed_silently(&mut stream), "the connection is closed, nothing answered");
    let mut stream = connect_to(&gw.addr);
    let mut input = vec![0u8; 6];
    for t in 0..10 {
        input.extend(mbap(t, 1, &[0x06, 0x00, 0x06, 0x56, 0x78]));
    }
    stream.write_all(&input).unwrap();
    assert!(closed_silently(&mut stream));
    let mut fresh = connect_to(&gw.addr);
    assert_eq!(ask(&mut fresh, 1, 1, &[0x03, 0x00, 0x05, 0x00, 0x02]), [0x03, 0x04, 0, 0, 0, 0], "nothing was written");
}

#[test]
fn past_max_connections_the_gateway_serves_a_new_connection_and_closes_the_one_idle_longest() {
    let Some(_turn) = require(&[Need::Socat]) else { return };
    let gw = behind(generic_sim, &["--max-connections", "2"]);
    let mut first = connect_to(&gw.addr);
    let mut second = connect_to(&gw.addr);
    ask(&mut first, 1, 1, &READ_0);
    ask(&mut second, 1, 1, &READ_0);
    let mut third = connect_to(&gw.addr);
    assert_eq!(ask(&mut third, 1, 1, &READ_0), [0x03, 0x02, 0x00, 0x00], "the newcomer is served");
    assert!(closed_silently(&mut first), "the connection idle longest is closed to make room");
    assert_eq!(ask(&mut second, 2, 1, &READ_0), [0x03, 0x02, 0x00, 0x00]);
}

#[test]
fn the_gateway_closes_an_idle_connection_and_an_unfinished_frame_never_early() {
    let Some(_turn) = require(&[Need::Socat]) else { return };
    let gw = behind(generic_sim, &["--idle-timeout", "400ms", "--frame-timeout", "200ms"]);
    let mut idle = connect_to(&gw.addr);
    let start = Instant::now();
    assert!(closed_silently(&mut idle));
    let idle_after = start.elapsed();
    assert!(idle_after >= Duration::from_millis(400), "closed after {idle_after:?}, before the 400 ms idle timeout");
    let mut truncated = connect_to(&gw.addr);
    truncated.write_all(&[0x00, 0x01, 0x00]).unwrap();
    let start = Instant::now();
    assert!(closed_silently(&mut truncated));
    let frame_after = start.elapsed();
    assert!(frame_after >= Duration::from_millis(200), "closed after {frame_after:?}, before the 200 ms frame timeout");
}

#[test]
fn out_of_file_descriptors_the_gateway_keeps_serving_old_connections_and_new_ones_once_some_close() {
    let Some(_turn) = require(&[Need::Socat]) else { return };
    let prlimit = Command::new("prlimit").arg("--version").output().is_ok();
    if !require_tool(prlimit, "prlimit (not on PATH)", "apt install util-linux") {
        return;
    }
    let gw = behind_with(generic_sim, &[], &["prlimit", "--nofile=48:48"]);
    let mut first = connect_to(&gw.addr);
    ask(&mut first, 1, 1, &READ_0);
    let mut others: Vec<TcpStream> = (0..60).map(|_| connect_to(&gw.addr)).collect();
    gw.gateway.wait_for(Stream::Err, |l| l.contains("Too many open files"), STEP);
    assert_eq!(ask(&mut first, 2, 1, &READ_0), [0x03, 0x02, 0x00, 0x00], "an old connection is served");
    others.drain(..40);
    let mut late = connect_to(&gw.addr);
    assert_eq!(ask(&mut late, 3, 1, &READ_0), [0x03, 0x02, 0x00, 0x00], "a new client is served");
    for (i, stream) in others.iter_mut().enumerate() {
        let t = u16::try_from(i).unwrap();
        assert_eq!(ask(stream, t, 1, &READ_0), [0x03, 0x02, 0x00, 0x00], "queued connection {i}");
    }
}

#[test]
fn the_gateway_counts_crc_errors_apart_from_timeouts_and_prints_them_on_sigusr1() {
    let Some(_turn) = require(&[Need::Socat]) else { return };
    // Unit 1 corrupts every reply; unit 2 is silent.
    let device =
        |path: &Path| sim_on(path, Parity::None, &["--profile", "generic", "--unit", "1", "--fault", "1:corrupt=100%"]);
    let gw = behind(device, &["--route", "1-2=0", "--backoff-after", "0"]);
    let mut stream = connect_to(&gw.addr);
    assert_eq!(ask(&mut stream, 1, 1, &READ_0), [0x83, 0x0B], "a bad CRC is 0x0B");
    assert_eq!(ask(&mut stream, 2, 2, &READ_0), [0x83, 0x0B], "silence is 0x0B");
    let pid = gw.gateway.id();
    let killed = Command::new("kill").args(["-USR1", &pid.to_string()]).status().unwrap();
    assert!(killed.success());
    let unit1 = gw.gateway.wait_for(Stream::Err, |l| l.contains("unit 1:"), STEP);
    let unit2 = gw.gateway.wait_for(Stream::Err, |l| l.contains("unit 2:"), STEP);
    assert!(unit1.contains("timeouts 0 crc-errors 1"), "{unit1}");
    assert!(unit2.contains("timeouts 1 crc-errors 0"), "{unit2}");
}

// The hostile-input and load battery, against the gateway in front of a simulated line: a
// well-behaved client is served throughout, and no invalid PDU reaches the line.

/// The well-behaved client's read: register 0 of the generic sim, answered with data.
#[track_caller]
fn still_served(good: &mut TcpStream, t: u16, after: &str) {
    assert_eq!(ask(good, t, 1, &READ_0), [0x03, 0x02, 0x00, 0x00], "the good client, after {after}");
}

/// The counters the gateway prints on SIGUSR1: the line's total, and the front end's line.
fn counters(gw: &Behind) -> (String, String) {
    let pid = gw.gateway.id();
    assert!(Command::new("kill").args(["-USR1", &pid.to_string()]).status().unwrap().success());
    let line = gw.gateway.wait_for(Stream::Err, |l| l.starts_with("line "), STEP);
    let front = gw.gateway.wait_for(Stream::Err, |l| l.starts_with("front: refused"), STEP);
    (line, front)
}

#[test]
fn through_garbage_a_huge_length_truncated_headers_and_slowloris_the_gateway_keeps_serving_a_good_client() {
    let Some(_turn) = require(&[Need::Socat]) else { return };
    let gw = behind(generic_sim, &["--frame-timeout", "2s"]);
    let mut good = connect_to(&gw.addr);
    still_served(&mut good, 1, "connecting");
    // Garbage: not MBAP (protocol id 0xA5A5): closed, nothing answered.
    let mut garbage = connect_to(&gw.addr);
    garbage.write_all(&[0xA5; 300]).unwrap();
    assert!(closed_silently(&mut garbage), "garbage closes its connection");
    still_served(&mut good, 2, "garbage");
    // A length field of 65535: closed, and the write behind it never executed.
    let mut huge = connect_to(&gw.addr);
    let mut input = vec![0x00, 0x01, 0x00, 0x00, 0xFF, 0xFF, 0x01];
    input.extend(mbap(2, 1, &[0x06, 0x00, 0x00, 0x12, 0x34]));
    huge.write_all(&input).unwrap();
    assert!(closed_silently(&mut huge), "a huge length closes its connection");
    still_served(&mut good, 3, "a huge length field");
    // Truncated headers and frames, and slowloris connections that send a byte now and
    // then: the good client is served while they hang, and each is closed at the frame timeout.
    let mut hanging: Vec<TcpStream> = Vec::new();
    for cut in [1, 3, 6, 8, 11] {
        let mut stream = connect_to(&gw.addr);
        stream.write_all(&mbap(9, 1, &READ_0)[..cut]).unwrap();
        hanging.push(stream);
    }
    let slow_frame = mbap(10, 1, &[0x06, 0x00, 0x00, 0x00, 0x07]);
    let mut slow: Vec<TcpStream> = (0..20).map(|_| connect_to(&gw.addr)).collect();
    for (i, byte) in slow_frame.iter().take(6).enumerate() {
        for stream in &mut slow {
            // A connection the gateway closed meanwhile refuses the byte: that is the point.
            let _ = stream.write_all(&[*byte]);
        }
        still_served(&mut good, 10 + u16::try_from(i).unwrap(), "slowloris bytes");
        std::thread::sleep(Duration::from_millis(100));
    }
    for (i, stream) in hanging.iter_mut().chain(slow.iter_mut()).enumerate() {
        assert!(closed_silently(stream), "half a frame on connection {i} is closed, never answered");
    }
    still_served(&mut good, 20, "the truncated and slow connections");
    let mut fresh = connect_to(&gw.addr);
    assert_eq!(ask(&mut fresh, 1, 1, &READ_0), [0x03, 0x02, 0x00, 0x00], "nothing of theirs was written");
}

/// Whether the gateway forwards `pdu`: the core parses it and its code is public or
/// user-defined (the test's oracle, from the spec's code ranges).
fn forwardable(pdu: &[u8]) -> bool {
    use ferrobus_proto::FunctionCode;
    use ferrobus_proto::pdu::Request;
    let code = FunctionCode::from_u8(pdu[0]);
    (code.is_public() || code.is_user_defined()) && Request::parse(pdu).is_ok()
}

#[test]
fn all_256_function_codes_through_the_gateway_refused_ones_get_01_or_03_at_once_and_never_reach_the_line() {
    let Some(_turn) = require(&[Need::Socat]) else { return };
    let gw = behind(generic_sim, &[]);
    let mut hostile = connect_to(&gw.addr);
    let mut good = connect_to(&gw.addr);
    let mut forwarded = 0u64;
    for code in 0..=u8::MAX {
        // Address 16: a write that gets through leaves the good client's register 0 alone.
        let pdu = [code, 0x00, 0x10, 0x00, 0x01];
        let t = u16::from(code);
        let reply = ask(&mut hostile, t, 1, &pdu);
        if forwardable(&pdu) {
            forwarded += 1;
            assert_eq!(reply[0] & 0x7F, code, "function {code:#04x}: the device's answer to it");
        } else {
            let illegal = !ferrobus_proto::FunctionCode::from_u8(code).is_public();
            let expected = if illegal { 0x01 } else { 0x03 };
            assert_eq!(reply, [code | 0x80, expected], "function {code:#04x}: refused by the gateway");
        }
        still_served(&mut good, t, &format!("function {code:#04x}"));
    }
    let (line, front) = counters(&gw);
    // Every good read, and only the forwardable requests, reached the line.
    assert!(line.contains(&format!("requests {} ", 256 + forwarded)), "{line}");
    assert!(line.contains(" skipped 0 "), "no unit was put in backoff: {line}");
    assert!(front.starts_with(&format!("front: refused {} invalid requests", 256 - forwarded)), "{front}");
    assert!(front.contains("not-a-request 129"), "0x00 and the 128 codes with bit 7: {front}");
}

#[test]
fn a_raw_client_that_writes_200_requests_at_once_is_held_back_and_every_request_answered_in_order() {
    let Some(_turn) = require(&[Need::Socat]) else { return };
    let gw = behind(generic_sim, &["--pipeline", "16", "--queue", "64"]);
    let mut flood = connect_to(&gw.addr);
    let mut good = connect_to(&gw.addr);
    let burst: Vec<u8> = (0..200u16).flat_map(|t| mbap(t, 1, &READ_0)).collect();
    flood.write_all(&burst).unwrap();
    still_served(&mut good, 1, "a burst of 200 from another connection");
    for t in 0..200u16 {
        let reply = read_frame(&mut flood).expect("a reply to every request");
        assert_eq!(reply, mbap(t, 1, &[0x03, 0x02, 0x00, 0x00]), "reply {t}: in order, served, never 0x06");
    }
    let (line, _) = counters(&gw);
    let max: usize = line
        .split("(max ")
        .nth(1)
        .and_then(|rest| rest.split(')').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no queue maximum in {line}"));
    // Sixteen of the flood's (all queued while the worker is between two requests), and the
    // good client's one.
    assert!(max <= 17, "one connection of pipeline 16 (and the good one) queued {max} at once: {line}");
    eprintln!("200 requests written at once with --pipeline 16: the line's queue held at most {max}");
    assert!(line.contains(" busy 0 "), "{line}");
}

// Refusals by the gateway's rules: the client's hint names what lets the request through.

#[test]
fn a_write_refused_by_a_read_only_gateway_gets_a_hint_naming_the_gateway_setting_and_following_it_works() {
    let Some(_turn) = require(&[Need::Socat]) else { return };
    let gw = behind(generic_sim, &["--read-only"]);
    let refused = ferrobus(&gw.link()).run(&["write", "register", "5", "7"]).exception(1);
    assert!(refused.stderr.contains("run it without --read-only"), "{}", refused.stderr);
    // FC10 is no way round a read-only gateway, which is why the hint names the gateway.
    ferrobus(&gw.link()).run(&["write", "register", "5", "7", "--multiple"]).exception(1);
    drop(gw);
    let gw = behind(generic_sim, &[]);
    ferrobus(&gw.link()).run(&["write", "register", "5", "7"]).ok();
    assert_eq!(ferrobus(&gw.link()).values(&["read", "holding", "5"]), words(&[7]));
    drop(gw);
    // FC06 kept out by the function allowlist: both ways the hint names go through.
    let gw = behind(generic_sim, &["--allow-functions", "3,16"]);
    let refused = ferrobus(&gw.link()).run(&["write", "register", "5", "8"]).exception(1);
    assert!(refused.stderr.contains("try --multiple"), "{}", refused.stderr);
    assert!(refused.stderr.contains("with 6 in --allow-functions"), "{}", refused.stderr);
    ferrobus(&gw.link()).run(&["write", "register", "5", "8", "--multiple"]).ok();
    assert_eq!(ferrobus(&gw.link()).values(&["read", "holding", "5"]), words(&[8]));
}

#[test]
fn a_reply_later_than_the_timeout_and_the_guard_is_dropped_as_late_and_never_given_to_the_next_client() {
    let Some(_turn) = require(&[Need::Socat]) else { return };
    // With the defaults (timeout 1 s, guard 100 ms), registers 0x10-0x12 answer 1150, 1300
    // and 2000 ms late: each late reply once came as the next client's register value.
    let device = |path: &Path| {
        let rules = ["1:fc=3,addr=0x10,delay=1150ms", "1:fc=3,addr=0x11,delay=1300ms", "1:fc=3,addr=0x12,delay=2000ms"];
        let mut args = vec!["--profile", "generic"];
        for rule in &rules {
            args.extend(["--fault", *rule]);
        }
        sim_on(path, Parity::None, &args)
    };
    let gw = behind_waiting(device, "1s", &["--backoff-after", "0"], &[]);
    let mut slow = connect_to(&gw.addr);
    let mut other = connect_to(&gw.addr);
    for (t, register) in [(1u16, 0x10u8), (2, 0x11), (3, 0x12)] {
        assert_eq!(
            ask(&mut slow, t, 1, &[0x06, 0x00, register, 0x11, register]),
            [0x06, 0x00, register, 0x11, register]
        );
    }
    assert_eq!(ask(&mut other, 9, 1, &[0x06, 0x00, 0x20, 0x22, 0x22]), [0x06, 0x00, 0x20, 0x22, 0x22]);
    for (t, register) in [(11u16, 0x10u8), (12, 0x11), (13, 0x12)] {
        slow.write_all(&mbap(t, 1, &[0x03, 0x00, register, 0x00, 0x01])).unwrap();
        // Queued behind the slow read (the pause only orders the two; nothing is timed).
        std::thread::sleep(Duration::from_millis(50));
        let theirs = ask(&mut other, t + 100, 1, &[0x03, 0x00, 0x20, 0x00, 0x01]);
        assert_eq!(theirs, [0x03, 0x02, 0x22, 0x22], "register 0x20 read after register {register:#04X}'s late reply");
        assert_eq!(read_frame(&mut slow), Some(mbap(t, 1, &[0x83, 0x0B])), "register {register:#04X} timed out");
    }
    // A last read settles the last late reply before the counters are printed.
    assert_eq!(ask(&mut other, 200, 1, &[0x03, 0x00, 0x20, 0x00, 0x01]), [0x03, 0x02, 0x22, 0x22]);
    let killed = Command::new("kill").args(["-USR1", &gw.gateway.id().to_string()]).status().unwrap();
    assert!(killed.success());
    let line = gw.gateway.wait_for(Stream::Err, |l| l.starts_with("line "), STEP);
    assert!(line.contains("late-window 2s late-replies 3 early-replies 0"), "{line}");
}

#[test]
fn a_reply_later_than_the_late_window_is_dropped_as_suspect_and_never_given_to_the_next_client() {
    let Some(_turn) = require(&[Need::Socat]) else { return };
    // Register 0x10 answers 3.1 s late: after the timeout (1 s) and the late window (2 s), so
    // it arrives while the next client's read of register 0x20 waits. Its content cannot tell;
    // its timing can: the unit answers the other reads within milliseconds.
    let device =
        |path: &Path| sim_on(path, Parity::None, &["--profile", "generic", "--fault", "1:fc=3,addr=0x10,delay=3100ms"]);
    let gw = behind_waiting(device, "1s", &["--backoff-after", "0"], &[]);
    let mut slow = connect_to(&gw.addr);
    let mut other = connect_to(&gw.addr);
    assert_eq!(ask(&mut slow, 1, 1, &[0x06, 0x00, 0x10, 0x11, 0x10]), [0x06, 0x00, 0x10, 0x11, 0x10]);
    assert_eq!(ask(&mut other, 2, 1, &[0x06, 0x00, 0x20, 0x22, 0x22]), [0x06, 0x00, 0x20, 0x22, 0x22]);
    // The unit's habit: 30 replies.
    for t in 0..30u16 {
        assert_eq!(ask(&mut other, 10 + t, 1, &[0x03, 0x00, 0x20, 0x00, 0x01]), [0x03, 0x02, 0x22, 0x22]);
    }
    for round in 0..3u16 {
        slow.write_all(&mbap(100 + round, 1, &[0x03, 0x00, 0x10, 0x00, 0x01])).unwrap();
        // Queued behind the slow read (the pause only orders the two; nothing is timed).
        std::thread::sleep(Duration::from_millis(50));
        let theirs = ask(&mut other, 200 + round, 1, &[0x03, 0x00, 0x20, 0x00, 0x01]);
        assert_eq!(theirs, [0x03, 0x02, 0x22, 0x22], "round {round}: register 0x20 read after 0x10's late reply");
        assert_eq!(read_frame(&mut slow), Some(mbap(100 + round, 1, &[0x83, 0x0B])), "round {round}: 0x10 timed out");
    }
    let killed = Command::new("kill").args(["-USR1", &gw.gateway.id().to_string()]).status().unwrap();
    assert!(killed.success());
    let line = gw.gateway.wait_for(Stream::Err, |l| l.starts_with("line "), STEP);
    assert!(line.contains("late-window 2s"), "{line}");
    assert!(!line.contains("suspect-replies 0 "), "no reply was dropped as suspect: {line}");
}

// Reverse: a serial master through the gateway to Modbus/TCP servers.

/// `ferrobus gateway --reverse` on one end of a socat pair; the master's end of the line.
fn reverse(args: &[&str]) -> (Proc, SocatPair, TempDir, Link) {
    let dir = TempDir::new();
    let pair = SocatPair::start(dir.path());
    let mut command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
    command.args(["--port", &pair.b.display().to_string(), "--baud", &BAUD.to_string(), "--parity", "none"]);
    command.args(["--timeout", "200ms", "gateway", "--reverse"]).args(args);
    let proc = Proc::spawn("ferrobus gateway --reverse", &mut command);
    proc.wait_for(Stream::Err, |l| l.starts_with("gateway: reverse on"), STEP);
    let link = Link::Serial { path: pair.a.clone(), parity: Parity::None };
    (proc, pair, dir, link)
}

#[test]
fn reverse_a_serial_master_reads_and_writes_a_libmodbus_tcp_server_and_an_unlisted_unit_is_silent() {
    let Some(_turn) = require(&[Need::Libmodbus, Need::Socat]) else { return };
    let server = crate::support::peer_server(Stack::Libmodbus, crate::support::Over::Tcp, 1);
    let Link::Tcp(addr) = &server.link else { unreachable!("a TCP server") };
    // Serial unit 5 is the server's unit 1.
    let (_gw, _pair, _dir, link) = reverse(&["--route", &format!("5={addr}/1")]);
    let client = ferrobus(&link).unit(5);
    assert_eq!(client.values(&["read", "holding", "10", "--count", "3"]), words(&[73, 80, 87]));
    client.run(&["write", "register", "10", "4242"]).ok();
    assert_eq!(client.values(&["read", "holding", "10", "--count", "1"]), words(&[4242]));
    client.run(&["read", "holding", "1000", "--count", "1"]).exception(2);
    ferrobus(&link).unit(6).timeout_ms(300).run(&["read", "holding", "0"]).timeout();
}

#[test]
fn reverse_with_on_failure_exception_a_server_that_cannot_be_reached_gets_0a_on_the_line() {
    let Some(_turn) = require(&[Need::Socat]) else { return };
    let nobody = format!("127.0.0.1:{}", free_port());
    let (_gw, _pair, _dir, link) = reverse(&["--route", &format!("5={nobody}"), "--on-failure", "exception"]);
    ferrobus(&link).unit(5).timeout_ms(3000).run(&["read", "holding", "0"]).exception(10);
    let (_gw, _pair, _dir, link) = reverse(&["--route", &format!("5={nobody}")]);
    ferrobus(&link).unit(5).timeout_ms(1500).run(&["read", "holding", "0"]).timeout();
}
