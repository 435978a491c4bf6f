//! `ferrobus bench` when most reads fail: it stops once more than half of --count have failed
//! and exits with the first failure's code, instead of exiting 0; a port that dies mid-run is
//! reopened with a growing wait, not in a busy loop.

use std::io::{Read, Write};
use std::net::TcpListener;
use std::thread;

use assert_cmd::assert::OutputAssertExt;

use crate::server::{Server, ferrobus, stderr, stdout};

/// A Modbus/TCP server that answers `answers` FC03 reads of one register (value 7), then closes
/// the connection and stops listening: a port that dies mid-run.
fn dying_server(answers: usize) -> u16 {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    thread::spawn(move || {
        let Ok((mut stream, _)) = listener.accept() else { return };
        drop(listener);
        let mut request = [0u8; 12];
        for _ in 0..answers {
            if stream.read_exact(&mut request).is_err() {
                return;
            }
            // Transaction id echoed, protocol 0, length 5, unit, 03, 2 bytes, 0x0007.
            let reply = [request[0], request[1], 0, 0, 0, 5, request[6], 0x03, 0x02, 0x00, 0x07];
            let _ = stream.write_all(&reply);
        }
    });
    port
}

#[test]
fn bench_on_a_port_that_dies_stops_once_most_reads_failed_and_exits_4() {
    let port = dying_server(3).to_string();
    let target = format!("127.0.0.1:{port}");
    let assert = ferrobus()
        .args(["--tcp", &target, "--timeout", "200ms", "bench", "--count", "10", "--quantity", "1", "--json"])
        .assert()
        .code(4);
    let out = stdout(&assert);
    let json: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    // Three answered, then six failed (more than half of 10) and it stopped.
    assert_eq!(json["transactions"], 9, "{out}");
    assert_eq!(json["errors"], 6, "{out}");
    // The five reopens waited 10 + 20 + 40 + 80 + 160 ms at least: no busy loop.
    let seconds = json["seconds"].as_f64().unwrap();
    assert!(seconds >= 0.31, "six failed reads in {seconds} s");
}

#[test]
fn bench_stops_with_exit_4_and_its_summary_once_the_server_is_gone_for_the_give_up_bound() {
    let port = dying_server(3).to_string();
    let target = format!("127.0.0.1:{port}");
    // A million reads: without the bound it would retry for days.
    let args = ["--tcp", &target, "--timeout", "200ms", "bench", "--count", "1000000", "--quantity", "1"];
    let assert = ferrobus().args(args).args(["--give-up", "1s"]).assert().code(4);
    let err = stderr(&assert);
    assert!(err.contains("bench: stopped after "), "{err}");
    assert!(err.contains("of 1000000 reads: none has got through for "), "{err}");
    assert!(err.contains("the server or the device is gone"), "{err}");
    let out = stdout(&assert);
    assert!(out.starts_with("bench: "), "the summary of what was measured: {out}");
    let reads: u32 = out.split_whitespace().nth(1).and_then(|n| n.parse().ok()).unwrap();
    assert!((6..1000).contains(&reads), "3 answered and at least 3 failed: {out}");
}

#[test]
fn bench_with_most_reads_timing_out_says_it_stopped_and_exits_3() {
    let server = Server::start();
    let assert = server.run(&["--unit", "9", "bench", "--count", "4"]).code(3);
    let err = stderr(&assert);
    assert!(err.contains("bench: stopped after 3 of 4 reads: 3 failed, more than half of them"), "{err}");
    assert!(err.contains("no reply from unit 9"), "the first failure is reported: {err}");
    let out = stdout(&assert);
    assert!(out.contains("bench: 3 FC03 reads"), "the summary counts the reads made: {out}");
}
