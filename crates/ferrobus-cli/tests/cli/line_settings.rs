//! `ferrobus line` holds each pty endpoint to its own settings: a client at the line's baud rate
//! reads a simulated drive on another drop, one at the wrong baud rate gets no usable reply.

use std::io::{BufRead, BufReader};
use std::process::{Child, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use assert_cmd::assert::OutputAssertExt;

use crate::server::{ferrobus, stderr};

/// Kills the child it holds when dropped.
struct Running(Child);

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `ferrobus` with `args`, and returns it with the lines of its stdout or stderr
/// (whichever is asked) up to the `lines`-th and at least to one containing `until`, waiting
/// at most 10 s for each.
fn start(args: &[&str], stdout: bool, lines: usize, until: &str) -> (Running, Vec<String>) {
    let mut command = ferrobus();
    command.args(args).stdin(Stdio::null());
    if stdout {
        command.stdout(Stdio::piped()).stderr(Stdio::null());
    } else {
        command.stdout(Stdio::null()).stderr(Stdio::piped());
    }
    let mut child = command.spawn().unwrap();
    let (tx, rx) = mpsc::channel();
    let reader: Box<dyn std::io::Read + Send> =
        if stdout { Box::new(child.stdout.take().unwrap()) } else { Box::new(child.stderr.take().unwrap()) };
    std::thread::spawn(move || {
        for line in BufReader::new(reader).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                return;
            }
        }
    });
    let mut got: Vec<String> = Vec::new();
    while got.len() < lines || !got.iter().any(|l| l.contains(until)) {
        let line = rx.recv_timeout(Duration::from_secs(10));
        got.push(line.unwrap_or_else(|_| panic!("ferrobus {args:?} said only {got:#?}")));
    }
    (Running(child), got)
}

#[test]
fn on_the_line_a_client_at_the_wrong_baud_rate_gets_no_reply_and_at_the_right_one_reads() {
    let (_line, drops) = start(&["--baud", "9600", "line", "--unpaced"], true, 2, "");
    let sim = ["--baud", "9600", "sim", "--profile", "generic", "--port", &drops[1]];
    let (_sim, _) = start(&sim, false, 1, "serving on");
    let read = |baud: &str| {
        ferrobus().args(["--baud", baud, "--port", &drops[0], "--timeout", "300ms", "read", "holding", "0"]).assert()
    };
    let wrong = read("19200");
    let code = wrong.get_output().status.code();
    assert!(matches!(code, Some(3 | 5)), "at 19200 on a 9600 line: {code:?}, {}", stderr(&wrong));
    read("9600").success();
}
