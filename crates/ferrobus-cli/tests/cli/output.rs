//! Output that cannot be written, interruptions, and options a command would ignore.
//!
//! A full disk is /dev/full; a closed pipe is a pipe whose reading end is closed before the
//! binary starts, so that its first write fails whatever the timing. Interrupted runs talk to
//! a server that answers a few requests and then stays silent; the signal is sent once the
//! server holds the next request, so the binary is waiting for a reply that never comes.

use std::fs::File;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpListener;
use std::process::{Child, Command, Output, Stdio};
use std::sync::mpsc;
use std::thread;

use serde_json::Value;

use crate::server::{Server, closed_port, ferrobus};

fn dev_full() -> File {
    File::options().write(true).open("/dev/full").unwrap()
}

/// Runs the binary with stdout on /dev/full.
fn to_full_disk(args: &[&str]) -> Output {
    ferrobus().args(args).stdout(dev_full()).output().unwrap()
}

/// Runs the binary with stdout on a pipe whose reader has already gone.
fn to_closed_pipe(args: &[&str]) -> Output {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    ferrobus().args(args).stdout(writer).output().unwrap()
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn assert_full_disk(out: &Output, what: &str) {
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(6), "{what}: {err}");
    assert!(err.contains("error: cannot write stdout: No space left on device"), "{what}: {err}");
    assert!(!err.contains("panicked"), "{what}: {err}");
}

#[test]
fn every_command_fails_with_exit_6_when_stdout_is_a_full_disk() {
    let server = Server::start();
    let [flag, addr] = server.target();
    let on = |args: &[&str]| -> Vec<String> {
        [flag.as_str(), addr.as_str()].iter().chain(args).map(ToString::to_string).collect()
    };
    for args in [
        on(&["read", "holding", "0", "--count", "5", "--csv"]),
        on(&["read", "holding", "0", "--count", "5", "--json"]),
        on(&["read", "coils", "0", "--count", "5"]),
        on(&["write", "register", "7", "1"]),
        on(&["write", "coils", "0", "on", "off"]),
        on(&["mask", "20", "0xFFF0", "0x0005"]),
        on(&["readwrite", "--write", "10", "1", "--read", "10", "--count", "1"]),
        on(&["diag", "echo"]),
        on(&["info", "--server-id"]),
        on(&["raw", "03 00 00 00 01"]),
        on(&["bench", "--count", "3", "--json"]),
        on(&["bench", "--count", "3"]),
        vec!["crc".into(), "01 03 00 00 00 01".into()],
        vec!["crc".into(), "--check".into(), "01 10 01 12 00 02 E0 31".into()],
        vec!["line".into(), "--duration".into(), "10s".into()],
        vec!["sim".into(), "--profile".into(), "generic".into(), "--pty".into(), "--duration".into(), "10s".into()],
        vec!["demo".into()],
    ] {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        assert_full_disk(&to_full_disk(&args), &args.join(" "));
    }
}

#[test]
fn a_closed_pipe_ends_the_command_quietly_with_exit_141() {
    let server = Server::start();
    let [flag, addr] = server.target();
    for args in [
        vec![flag.as_str(), addr.as_str(), "read", "holding", "0", "--count", "500", "--csv"],
        vec![flag.as_str(), addr.as_str(), "bench", "--count", "3", "--json"],
        vec!["crc", "01 03 00 00 00 01"],
        vec!["line", "--duration", "10s"],
    ] {
        let out = to_closed_pipe(&args);
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(141), "{}: {err}", args.join(" "));
        // Nothing on stderr from the command itself: no error, no panic (line's banner aside).
        assert!(!err.contains("error") && !err.contains("panicked"), "{}: {err}", args.join(" "));
    }
}

/// A Modbus/TCP server that answers `answers` FC03 requests (register i holds i), then holds
/// the next request unanswered and reports it on the channel.
fn stalling_server(answers: usize) -> (u16, mpsc::Receiver<()>) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let (tx, rx) = mpsc::channel();
    thread::spawn(move || {
        let (mut stream, _) = listener.accept().unwrap();
        let mut served = 0;
        let mut header = [0u8; 7];
        while stream.read_exact(&mut header).is_ok() {
            let len = usize::from(u16::from_be_bytes([header[4], header[5]]));
            let mut pdu = vec![0u8; len - 1];
            stream.read_exact(&mut pdu).unwrap();
            if served == answers {
                tx.send(()).unwrap();
                // Keep the connection open and silent until the client goes.
                let _ = stream.read(&mut [0u8; 1]);
                return;
            }
            served += 1;
            let start = u16::from_be_bytes([pdu[1], pdu[2]]);
            let quantity = u16::from_be_bytes([pdu[3], pdu[4]]);
            let mut reply = vec![0x03, u8::try_from(quantity * 2).unwrap()];
            for i in 0..quantity {
                reply.extend((start.wrapping_add(i)).to_be_bytes());
            }
            let mut frame = header[..4].to_vec();
            frame.extend(u16::try_from(reply.len() + 1).unwrap().to_be_bytes());
            frame.push(header[6]);
            frame.extend(reply);
            stream.write_all(&frame).unwrap();
        }
    });
    (port, rx)
}

/// Starts the binary with SIGINT at its default disposition (a non-interactive shell's
/// background children ignore it), stdout and stderr piped.
fn spawn(args: &[&str]) -> Child {
    Command::new("env")
        .arg("--default-signal=INT")
        .arg(env!("CARGO_BIN_EXE_ferrobus"))
        .env("XDG_CONFIG_HOME", crate::server::no_settings())
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn signal(child: &Child, name: &str) {
    let status = Command::new("kill").args([format!("-{name}"), child.id().to_string()]).status().unwrap();
    assert!(status.success(), "kill -{name}");
}

#[test]
fn ctrl_c_during_a_long_read_prints_the_rows_read_and_exits_130() {
    let (port, held) = stalling_server(3);
    let addr = format!("127.0.0.1:{port}");
    let child = spawn(&["--tcp", &addr, "--timeout", "60s", "read", "holding", "0", "--count", "60000", "--csv"]);
    held.recv().unwrap();
    signal(&child, "INT");
    let out = child.wait_with_output().unwrap();
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert_eq!(out.status.code(), Some(130), "{stderr}");
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 1 + 3 * 125, "{stderr}");
    assert_eq!(lines[0], "address,addr_hex,hex,dec");
    assert_eq!(lines[375], "374,0x0176,0x0176,374");
    assert!(stderr.contains("read: interrupted after 375 of 60000 holding registers"), "{stderr}");
    assert!(stderr.contains("error: interrupted"), "{stderr}");
}

#[test]
fn ctrl_c_while_the_first_reply_is_awaited_prints_only_the_header_and_exits_130() {
    let (port, held) = stalling_server(0);
    let addr = format!("127.0.0.1:{port}");
    let child = spawn(&["--tcp", &addr, "--timeout", "60s", "read", "coils", "0", "--count", "8", "--csv"]);
    held.recv().unwrap();
    signal(&child, "INT");
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(130), "{}", text(&out.stderr));
    assert_eq!(text(&out.stdout), "address,addr_hex,value,state\n");
    assert!(text(&out.stderr).contains("read: interrupted after 0 of 8 coils"), "{}", text(&out.stderr));
}

#[test]
fn sigterm_during_a_json_read_prints_the_values_read_and_exits_130() {
    let (port, held) = stalling_server(2);
    let addr = format!("127.0.0.1:{port}");
    let child = spawn(&["--tcp", &addr, "--timeout", "60s", "read", "holding", "0", "--count", "1000", "--json"]);
    held.recv().unwrap();
    signal(&child, "TERM");
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(130), "{}", text(&out.stderr));
    let doc: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!((doc["count"].clone(), doc["requests"].clone()), (250.into(), 2.into()));
    assert_eq!(doc["values"][249], 249);
}

#[test]
fn an_interrupted_bench_prints_the_summary_of_the_reads_done_and_exits_130() {
    for (signal_name, json) in [("INT", true), ("TERM", false)] {
        let (port, held) = stalling_server(5);
        let addr = format!("127.0.0.1:{port}");
        let mut args = vec!["--tcp", &addr, "--timeout", "60s", "bench", "--count", "1000"];
        if json {
            args.push("--json");
        }
        let child = spawn(&args);
        held.recv().unwrap();
        signal(&child, signal_name);
        let out = child.wait_with_output().unwrap();
        let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
        assert_eq!(out.status.code(), Some(130), "{signal_name}: {stderr}");
        assert!(stderr.contains("bench: interrupted after 5 of 1000 reads"), "{signal_name}: {stderr}");
        if json {
            let doc: Value = serde_json::from_str(&stdout).unwrap();
            assert_eq!((doc["transactions"].clone(), doc["errors"].clone()), (5.into(), 0.into()), "{stdout}");
        } else {
            assert!(stdout.starts_with("bench: 5 FC03 reads of 10 registers"), "{stdout}");
            assert!(stdout.contains(", 0 errors,"), "{stdout}");
        }
    }
}

fn temp_path(name: &str) -> std::path::PathBuf {
    std::env::temp_dir().join(format!("ferrobus-cli-test-{}-{name}", std::process::id()))
}

#[test]
fn line_writes_its_statistics_file_on_sigterm_and_exits_0() {
    let path = temp_path("line-stats.json");
    let _ = std::fs::remove_file(&path);
    let mut child = spawn(&["line", "--drops", "3", "--stats-json", path.to_str().unwrap()]);
    // The file exists from the start.
    let mut paths = BufReader::new(child.stdout.take().unwrap()).lines();
    for _ in 0..3 {
        assert!(paths.next().unwrap().unwrap().starts_with("/dev/pts/"));
    }
    assert!(path.exists(), "the statistics file is created before the line runs");
    signal(&child, "TERM");
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(text(&out.stderr).contains("line: 0 characters, 0 frames"), "{}", text(&out.stderr));
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    assert_eq!(doc["endpoints"].as_array().unwrap().len(), 3, "{doc}");
    std::fs::remove_file(&path).unwrap();
}

#[test]
fn sim_with_a_duration_still_prints_its_counters_on_sigterm() {
    let mut child = spawn(&["--tcp", "127.0.0.1:0", "sim", "--profile", "generic", "--duration", "10min"]);
    // Its stderr says when it listens; the signal comes after.
    let mut log = BufReader::new(child.stderr.take().unwrap()).lines();
    assert!(log.any(|line| line.unwrap().starts_with("sim: listening on")), "the sim listens");
    signal(&child, "TERM");
    let status = child.wait().unwrap();
    let rest: Vec<String> = log.map(Result::unwrap).collect();
    assert_eq!(status.code(), Some(0), "{rest:?}");
    assert!(rest.iter().any(|line| line.starts_with("sim: 0 requests")), "the counters: {rest:?}");
}

#[test]
fn line_refuses_a_statistics_file_it_cannot_create_before_it_starts() {
    let path = temp_path("no-such-dir").join("stats.json");
    let out =
        ferrobus().args(["line", "--duration", "3600s", "--stats-json", path.to_str().unwrap()]).output().unwrap();
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(6), "{err}");
    assert!(err.contains(&format!("cannot write {}: No such file or directory", path.display())), "{err}");
    assert!(out.stdout.is_empty(), "no pty is made: {}", text(&out.stdout));
}

#[test]
fn line_refuses_a_dead_endpoint_beyond_its_drops() {
    let out = ferrobus().args(["line", "--drops", "3", "--dead", "5", "--duration", "3600s"]).output().unwrap();
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("--dead 5: there are 3 drops, numbered 0 to 2"), "{err}");
    assert!(out.stdout.is_empty());
}

#[test]
fn connection_options_that_crc_demo_line_and_profile_would_ignore_are_refused() {
    for (args, want) in [
        (&["--port", "/dev/ttyUSB0", "crc", "01"][..], "--port is not used by `crc`: crc works offline"),
        (&["crc", "--tcp", "10.0.0.1", "--baud", "9600", "01"], "--tcp, --baud are not used by `crc`"),
        (&["--tcp", "10.0.0.1", "demo"], "--tcp is not used by `demo`: demo runs its own virtual line"),
        (&["line", "--port", "/dev/ttyUSB0"], "--port is not used by `line`: line makes its own ptys"),
        (&["line", "--tcp", "10.0.0.1:502", "--unit", "3"], "--tcp, --unit are not used by `line`"),
        (&["--device", "omron-3g3rx", "crc", "01"], "--device is not used by `crc`"),
        (&["--device", "omron-3g3rx", "profile", "show", "sdp-servo"], "--device is not used by `profile`"),
    ] {
        let out = ferrobus().args(args).output().unwrap();
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{}: {err}", args.join(" "));
        assert!(err.contains(want), "{}: {err}", args.join(" "));
        assert!(out.stdout.is_empty(), "{}", args.join(" "));
    }
    // The line settings are line's own.
    let out = ferrobus().args(["line", "--baud", "9600", "--parity", "none", "--duration", "1ms"]).output().unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(text(&out.stderr).contains("at 9600 8N1"), "{}", text(&out.stderr));
}

#[test]
fn a_zero_timeout_is_refused() {
    let port = closed_port().to_string();
    let out = ferrobus()
        .args(["--tcp", &format!("127.0.0.1:{port}"), "--timeout", "0", "read", "holding", "0"])
        .output()
        .unwrap();
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("a timeout of 0 gives up before any reply can come"), "{err}");
}
