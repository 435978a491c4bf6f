//! `ferrobus sim --tcp` as a hardened Modbus/TCP server, driven by raw frames over
//! `std::net::TcpStream`: pipelined requests, corrupt MBAP headers, unit ids over TCP, the
//! connection cap and the per-source limit (127.0.0.2 another host), idle and unfinished-frame
//! timeouts, and running out of file descriptors.

use std::io::{ErrorKind, Read, Write};
use std::net::TcpStream;
use std::process::Command;
use std::time::{Duration, Instant};

use crate::support::cli::{Link, Parity};
use crate::support::env::{require, require_tool};
use crate::support::mbap::{ask, closed_silently, connect_to, mbap, read_frame};
use crate::support::peers::{Over, Served, free_port, sim};
use crate::support::process::{Proc, Stream};

/// A bound on how long any single step may take before the test fails (not a timing claim).
const STEP: Duration = Duration::from_secs(10);

/// A connection to the TCP simulator `served`.
fn connect(served: &Served) -> TcpStream {
    let Link::Tcp(addr) = &served.link else { panic!("a TCP simulator") };
    connect_to(addr)
}

fn generic(extra: &[&str]) -> Served {
    let mut args = vec!["--profile", "generic"];
    args.extend_from_slice(extra);
    sim(Over::Tcp, Parity::None, &args)
}

#[test]
fn twenty_pipelined_requests_get_twenty_replies_in_order_each_with_its_transaction() {
    let Some(_turn) = require(&[]) else { return };
    let served = generic(&[]);
    let mut stream = connect(&served);
    // Ten writes and ten reads back, written back to back in one go.
    let mut burst = Vec::new();
    for i in 0..10u16 {
        burst.extend(mbap(0x0100 + i, 1, &[0x06, 0x00, u8::try_from(i).unwrap(), 0xB0, u8::try_from(i).unwrap()]));
    }
    for i in 0..10u16 {
        burst.extend(mbap(0x0200 + i, 1, &[0x03, 0x00, u8::try_from(i).unwrap(), 0x00, 0x01]));
    }
    stream.write_all(&burst).unwrap();
    for i in 0..10u16 {
        let reply = read_frame(&mut stream).expect("a reply to each write");
        let value = u8::try_from(i).unwrap();
        assert_eq!(reply, mbap(0x0100 + i, 1, &[0x06, 0x00, value, 0xB0, value]), "write {i}");
    }
    for i in 0..10u16 {
        let reply = read_frame(&mut stream).expect("a reply to each read");
        assert_eq!(reply, mbap(0x0200 + i, 1, &[0x03, 0x02, 0xB0, u8::try_from(i).unwrap()]), "read {i}");
    }
}

#[test]
fn a_corrupt_mbap_header_closes_the_connection_and_executes_nothing_behind_it() {
    let Some(_turn) = require(&[]) else { return };
    let served = generic(&[]);
    // Length 65535, then a write of 0x1234 to register 5 (transaction 0x0032).
    let mut stream = connect(&served);
    let mut input = vec![0x00, 0x31, 0x00, 0x00, 0xFF, 0xFF, 0x01];
    input.extend(mbap(0x0032, 1, &[0x06, 0x00, 0x05, 0x12, 0x34]));
    stream.write_all(&input).unwrap();
    assert!(closed_silently(&mut stream), "the connection is closed, nothing answered");
    // Six zero bytes, then ten requests: none is answered.
    let mut stream = connect(&served);
    let mut input = vec![0u8; 6];
    for t in 0..10 {
        input.extend(mbap(t, 1, &[0x06, 0x00, 0x06, 0x56, 0x78]));
    }
    stream.write_all(&input).unwrap();
    assert!(closed_silently(&mut stream));
    let mut fresh = connect(&served);
    assert_eq!(ask(&mut fresh, 1, 1, &[0x03, 0x00, 0x05, 0x00, 0x02]), [0x03, 0x04, 0, 0, 0, 0], "nothing was written");
}

#[test]
fn a_single_device_answers_unit_0xff_and_unit_0_over_tcp() {
    let Some(_turn) = require(&[]) else { return };
    let served = generic(&["--unit", "7"]);
    let mut stream = connect(&served);
    for unit in [7, 0xFF, 0] {
        assert_eq!(
            ask(&mut stream, u16::from(unit), unit, &[0x06, 0x00, 0x09, 0x00, unit]),
            [0x06, 0x00, 0x09, 0x00, unit]
        );
        assert_eq!(
            ask(&mut stream, 0x100, 7, &[0x03, 0x00, 0x09, 0x00, 0x01]),
            [0x03, 0x02, 0x00, unit],
            "the same device"
        );
    }
    // Another unit id is not this device's.
    stream.write_all(&mbap(9, 8, &[0x03, 0x00, 0x00, 0x00, 0x01])).unwrap();
    stream.set_read_timeout(Some(Duration::from_millis(300))).unwrap();
    let mut byte = [0u8; 1];
    let silent = stream.read(&mut byte).map_err(|e| e.kind());
    assert!(matches!(silent, Err(ErrorKind::WouldBlock | ErrorKind::TimedOut)), "unit 8 gets no answer: {silent:?}");
}

#[test]
fn with_several_units_an_unserved_one_gets_exception_0b_and_any_unit_answers_every_unit() {
    let Some(_turn) = require(&[]) else { return };
    let several = generic(&["--unit", "1", "--unit", "2"]);
    let mut stream = connect(&several);
    assert_eq!(ask(&mut stream, 1, 2, &[0x03, 0x00, 0x00, 0x00, 0x01]), [0x03, 0x02, 0x00, 0x00]);
    assert_eq!(
        ask(&mut stream, 2, 0xFF, &[0x03, 0x00, 0x00, 0x00, 0x01]),
        [0x83, 0x0B],
        "gateway: target failed to respond"
    );
    drop(several);
    let any = generic(&["--unit", "1", "--any-unit"]);
    let mut stream = connect(&any);
    for unit in [1, 0, 99, 0xFF] {
        assert_eq!(ask(&mut stream, 3, unit, &[0x03, 0x00, 0x00, 0x00, 0x01]), [0x03, 0x02, 0x00, 0x00], "unit {unit}");
    }
}

#[test]
fn past_max_connections_a_new_connection_is_served_and_the_one_idle_longest_is_closed() {
    let Some(_turn) = require(&[]) else { return };
    let served = generic(&["--max-connections", "2"]);
    let mut first = connect(&served);
    let mut second = connect(&served);
    // Served, so certainly accepted before the third arrives; the first idle longest.
    ask(&mut first, 1, 1, &[0x03, 0x00, 0x00, 0x00, 0x01]);
    ask(&mut second, 1, 1, &[0x03, 0x00, 0x00, 0x00, 0x01]);
    let mut third = connect(&served);
    assert_eq!(
        ask(&mut third, 1, 1, &[0x03, 0x00, 0x00, 0x00, 0x01]),
        [0x03, 0x02, 0x00, 0x00],
        "the newcomer is served"
    );
    assert!(closed_silently(&mut first), "the connection idle longest is closed to make room");
    assert_eq!(ask(&mut second, 2, 1, &[0x03, 0x00, 0x00, 0x00, 0x01]), [0x03, 0x02, 0x00, 0x00]);
}

/// A connection to `served` from `source`, an address of the loopback (127.0.0.2 is another
/// host as far as the per-source limit goes).
fn connect_from(source: [u8; 4], served: &Served) -> TcpStream {
    let Link::Tcp(addr) = &served.link else { panic!("a TCP simulator") };
    // `std` cannot bind before it connects; tokio can, on a runtime of this call's own.
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let stream = runtime.block_on(async {
        let socket = tokio::net::TcpSocket::new_v4().unwrap();
        socket.bind(std::net::SocketAddr::from((source, 0))).unwrap();
        socket.connect(addr.parse().unwrap()).await.unwrap().into_std().unwrap()
    });
    stream.set_nonblocking(false).unwrap();
    stream.set_read_timeout(Some(STEP)).unwrap();
    stream
}

#[test]
fn past_max_per_source_a_hosts_new_connection_is_closed_and_another_host_is_served() {
    let Some(_turn) = require(&[]) else { return };
    let served = generic(&["--max-per-source", "2"]);
    let (this_host, other_host) = ([127, 0, 0, 1], [127, 0, 0, 2]);
    let mut first = connect_from(other_host, &served);
    let mut second = connect_from(other_host, &served);
    ask(&mut first, 1, 1, &[0x03, 0x00, 0x00, 0x00, 0x01]);
    ask(&mut second, 1, 1, &[0x03, 0x00, 0x00, 0x00, 0x01]);
    let mut third = connect_from(other_host, &served);
    assert!(closed_silently(&mut third), "the other host's third connection is closed");
    let mut ours = connect_from(this_host, &served);
    ask(&mut ours, 1, 1, &[0x03, 0x00, 0x00, 0x00, 0x01]);
    // The other host's first two are still served.
    ask(&mut first, 2, 1, &[0x03, 0x00, 0x00, 0x00, 0x01]);
}

#[test]
fn an_idle_connection_and_an_unfinished_frame_are_closed_never_early() {
    let Some(_turn) = require(&[]) else { return };
    let served = generic(&["--idle-timeout", "400ms", "--frame-timeout", "200ms"]);
    let mut idle = connect(&served);
    let start = Instant::now();
    assert!(closed_silently(&mut idle));
    let idle_after = start.elapsed();
    assert!(idle_after >= Duration::from_millis(400), "closed after {idle_after:?}, before the 400 ms idle timeout");
    let mut truncated = connect(&served);
    truncated.write_all(&[0x00, 0x01, 0x00]).unwrap();
    let start = Instant::now();
    assert!(closed_silently(&mut truncated));
    let frame_after = start.elapsed();
    assert!(frame_after >= Duration::from_millis(200), "closed after {frame_after:?}, before the 200 ms frame timeout");
    eprintln!("idle connection closed after {idle_after:?} (400 ms), unfinished frame after {frame_after:?} (200 ms)");
}

#[test]
fn out_of_file_descriptors_the_server_keeps_serving_old_connections_and_new_ones_once_some_close() {
    let Some(_turn) = require(&[]) else { return };
    let prlimit = Command::new("prlimit").arg("--version").output().is_ok();
    if !require_tool(prlimit, "prlimit (not on PATH)", "apt install util-linux") {
        return;
    }
    let addr = format!("127.0.0.1:{}", free_port());
    let mut command = Command::new("prlimit");
    command.args(["--nofile=48:48", "--", env!("CARGO_BIN_EXE_ferrobus"), "sim", "--profile", "generic"]);
    command.args(["--tcp", &addr]);
    let proc = Proc::spawn("ferrobus sim (48 descriptors)", &mut command);
    proc.wait_for(Stream::Err, |l| l.starts_with("sim: listening on"), STEP);
    let mut first = connect_to(&addr);
    ask(&mut first, 1, 1, &[0x03, 0x00, 0x00, 0x00, 0x01]);
    // More connections than the server has descriptors: the kernel queues the rest.
    let mut others: Vec<TcpStream> = (0..60).map(|_| connect_to(&addr)).collect();
    proc.wait_for(Stream::Err, |l| l.contains("Too many open files"), STEP);
    assert_eq!(
        ask(&mut first, 2, 1, &[0x03, 0x00, 0x00, 0x00, 0x01]),
        [0x03, 0x02, 0x00, 0x00],
        "an old connection is served"
    );
    // Close forty: the queued ones and a new client get descriptors.
    others.drain(..40);
    let mut late = connect_to(&addr);
    assert_eq!(
        ask(&mut late, 3, 1, &[0x03, 0x00, 0x00, 0x00, 0x01]),
        [0x03, 0x02, 0x00, 0x00],
        "a new client is served"
    );
    for (i, stream) in others.iter_mut().enumerate() {
        let t = u16::try_from(i).unwrap();
        assert_eq!(
            ask(stream, t, 1, &[0x03, 0x00, 0x00, 0x00, 0x01]),
            [0x03, 0x02, 0x00, 0x00],
            "queued connection {i}"
        );
    }
    assert_eq!(ask(&mut first, 4, 1, &[0x03, 0x00, 0x00, 0x00, 0x01]), [0x03, 0x02, 0x00, 0x00]);
}
