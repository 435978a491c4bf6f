//! `ferrobus gateway`: its usage errors, named before any port is opened, and a run against a
//! silent line that ends by `--duration` with the counters of the line and the unit.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::process::Stdio;
use std::time::Duration;

use ferrobus::Pty;

use crate::server::{ferrobus, offline, stderr};

fn usage_error(args: &[&str], expected: &str) {
    let err = stderr(&offline(args).code(2));
    assert!(err.contains(expected), "{args:?}: {err}");
}

#[test]
fn gateway_usage_errors_name_the_option_and_what_is_wrong() {
    let port = ["--port", "/dev/null-no-such-port", "gateway"];
    let with = |extra: &[&'static str]| [&port[..], extra].concat();
    usage_error(
        &["--tcp", "127.0.0.1:1502", "gateway", "--line", "/dev/null-other"],
        "--line adds serial lines beside --port",
    );
    usage_error(&["--tcp", "127.0.0.1:1502", "--tls", "gateway"], "not Modbus/TCP Security");
    usage_error(&with(&["--route", "5=1"]), "--route '5=1': line 1 does not exist: there are 1");
    usage_error(&with(&["--route", "0=0"]), "unit 0 is the broadcast");
    usage_error(&with(&["--route", "5"]), "--route '5': no '='");
    usage_error(&with(&["--line", "/dev/null-other"]), "with 2 lines, say which units go where");
    usage_error(&with(&["--allow-units", "1,x"]), "--allow-units '1,x'");
}

#[test]
fn a_bad_or_busy_metrics_address_is_refused_before_any_line_is_opened() {
    let gateway = ["--port", "/dev/null-no-such-port", "gateway", "--listen", "127.0.0.1:0"];
    let with = |extra: &[&str]| -> Vec<String> { gateway.iter().chain(extra).map(ToString::to_string).collect() };
    let refused =
        |args: Vec<String>, expected: &str| usage_error(&args.iter().map(String::as_str).collect::<Vec<_>>(), expected);
    refused(with(&["--metrics", "nonsense"]), "--metrics 'nonsense': give ADDR:PORT");
    refused(with(&["--metrics", "1.2.3.4:70000"]), "--metrics '1.2.3.4:70000'");
    usage_error(
        &[
            "--port",
            "/dev/null-no-such-port",
            "gateway",
            "--reverse",
            "--route",
            "5=127.0.0.1:1502",
            "--metrics",
            "9100",
        ],
        "--metrics is the forward gateway's: not with --reverse",
    );
    let busy = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let taken = busy.local_addr().unwrap().to_string();
    let args = with(&["--metrics", &taken]);
    let err = stderr(&offline(&args.iter().map(String::as_str).collect::<Vec<_>>()).failure());
    assert!(err.contains(&format!("--metrics: listening on {taken}")), "{err}");
    assert!(!err.contains("/dev/null-no-such-port"), "the line was opened first: {err}");
}

#[test]
fn a_port_that_cannot_be_opened_is_named() {
    let err = stderr(&offline(&["--port", "/dev/null-no-such-port", "gateway", "--listen", "127.0.0.1:0"]).failure());
    assert!(err.contains("/dev/null-no-such-port"), "{err}");
}

#[test]
fn against_a_silent_line_a_read_gets_0b_and_the_exit_prints_the_line_and_unit_counters() {
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let _inside = runtime.enter();
    let pty = Pty::open().unwrap();
    let path = pty.path.display().to_string();
    let mut child = ferrobus()
        .args(["--port", &path, "--timeout", "50ms", "gateway", "--listen", "127.0.0.1:0", "--duration", "2s"])
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    let mut err = child.stderr.take().unwrap();
    // A line says where it listens.
    let mut text = String::new();
    let mut byte = [0u8; 1];
    while !(text.ends_with('\n') && text.contains("gateway: listening on")) {
        if text.ends_with('\n') {
            text.clear();
        }
        assert_eq!(err.read(&mut byte).unwrap(), 1, "the gateway ended before saying where it listens: {text}");
        text.push(char::from(byte[0]));
    }
    let addr = text.split_whitespace().nth(3).unwrap_or_else(|| panic!("no address in {text:?}")).to_string();
    assert!(text.starts_with("gateway: listening on 127.0.0.1:"), "{text}");
    let mut stream = TcpStream::connect(&addr).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    stream.write_all(&[0x00, 0x07, 0x00, 0x00, 0x00, 0x06, 0x05, 0x03, 0x00, 0x00, 0x00, 0x01]).unwrap();
    let mut reply = [0u8; 9];
    stream.read_exact(&mut reply).unwrap();
    assert_eq!(reply, [0x00, 0x07, 0x00, 0x00, 0x00, 0x03, 0x05, 0x83, 0x0B]);
    let status = child.wait().unwrap();
    let mut rest = String::new();
    err.read_to_string(&mut rest).unwrap();
    assert!(status.success(), "{rest}");
    assert!(rest.contains(&format!("line {path}")), "{rest}");
    assert!(rest.contains("  unit 5: requests 1 replies 0 timeouts 1"), "{rest}");
    assert!(rest.contains("tcp: 1 connections served"), "{rest}");
    drop(pty);
}

#[test]
fn a_gateway_stopped_with_a_request_on_its_line_keeps_the_port_for_the_reply_in_flight() {
    use tokio::io::AsyncReadExt;
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let _inside = runtime.enter();
    let mut pty = Pty::open().unwrap();
    let path = pty.path.display().to_string();
    let mut child = ferrobus()
        .args(["--port", &path, "--timeout", "5s", "gateway", "--listen", "127.0.0.1:0"])
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    let mut err = std::io::BufReader::new(child.stderr.take().unwrap());
    let mut line = String::new();
    while !line.contains("gateway: listening on") {
        line.clear();
        assert!(std::io::BufRead::read_line(&mut err, &mut line).unwrap() > 0, "the gateway ended before listening");
    }
    let addr = line.split_whitespace().nth(3).unwrap().to_string();
    let mut stream = TcpStream::connect(&addr).unwrap();
    stream.write_all(&[0x00, 0x07, 0x00, 0x00, 0x00, 0x06, 0x05, 0x03, 0x00, 0x00, 0x00, 0x01]).unwrap();
    // The request is on the line (the device's end of the pty has it), its reply owed.
    let mut request = [0u8; 8];
    runtime.block_on(pty.read_exact(&mut request)).unwrap();
    assert_eq!(request[..2], [0x05, 0x03]);
    let kill = |child: &std::process::Child| {
        let status = std::process::Command::new("kill").args(["-INT", &child.id().to_string()]).status();
        assert!(status.is_ok_and(|s| s.success()));
    };
    kill(&child);
    let mut rest = String::new();
    while !rest.contains("waiting up to") {
        line.clear();
        let read = std::io::BufRead::read_line(&mut err, &mut line).unwrap();
        assert!(read > 0, "no note of the reply in flight:\n{rest}");
        rest.push_str(&line);
    }
    assert!(rest.contains("ms for the reply in flight"), "{rest}");
    // A second Ctrl-C: out at once.
    kill(&child);
    child.wait().unwrap();
    drop(pty);
}
