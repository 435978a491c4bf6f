//! `gateway --lines-file` reloaded on SIGHUP: two `ferrobus line` buses with a simulated
//! device each, a client connected throughout; a broken file changes nothing and is logged
//! with its place; a good one adds a third line, changes one and leaves one running, and the
//! client's one connection is answered before, between and after, the unchanged line's
//! counters running on across the reload and the changed line's starting afresh; then the
//! added line is removed again and its unit goes unrouted. Throughout, `/status.json` names the
//! lines as applied last and counts the reloads; the refused one's error is among its recent
//! warnings, escaped.

use std::net::TcpStream;
use std::time::Duration;

use crate::gateway_lines::{LINE_A, LINE_B, Proc, ask, bus, dir, sim, status_after};

/// A `[[line]]` on `port` at 9600 8N2 (line A's settings), serving `units`.
fn line_a(port: &str, units: &str) -> String {
    format!("[[line]]\nport = \"{port}\"\nbaud = 9600\nparity = \"none\"\nstop-bits = 2\nunits = [{units}]\n\n")
}

/// A `[[line]]` on `port` at 38400 8N1 (line B's), with `extra` keys, serving `units`.
fn line_b(port: &str, extra: &str, units: &str) -> String {
    format!("[[line]]\nport = \"{port}\"\nbaud = 38400\nparity = \"none\"\n{extra}units = [{units}]\n\n")
}

/// Reads and checks holding register 0 of `unit` on `stream`: the device answers.
fn answers(stream: &mut TcpStream, id: u16, unit: u8) {
    assert_eq!(ask(stream, id, unit, &[0x03, 0, 0, 0, 1]).first(), Some(&0x03), "unit {unit}");
}

#[test]
fn sighup_with_a_broken_file_changes_nothing_and_a_good_one_adds_and_changes_lines_while_the_client_stays() {
    let dir = dir("reload");
    let (_bus_a, a) = bus(&LINE_A, &dir.join("a.json"));
    let (_bus_b, b) = bus(&LINE_B, &dir.join("b.json"));
    let (_bus_c, c) = bus(&LINE_B, &dir.join("c.json"));
    let _sim_a = sim(&a[1], &LINE_A, &["--unit", "1"]);
    let _sim_b = sim(&b[1], &LINE_B, &["--unit", "2"]);
    let _sim_c = sim(&c[1], &LINE_B, &["--unit", "3"]);
    let file = dir.join("lines.toml");
    let running = line_a(&a[0], "1") + &line_b(&b[0], "", "2");
    std::fs::write(&file, &running).unwrap();
    let path = file.to_str().unwrap();
    let args = [
        "-v",
        "gateway",
        "--lines-file",
        path,
        "--listen",
        "127.0.0.1:0",
        "--metrics",
        "127.0.0.1:0",
        "--duration",
        "120s",
    ];
    let mut gateway = Proc::ferrobus(&args, false);
    let listening = gateway.until("gateway: listening on");
    let addr = listening.split_whitespace().nth(3).unwrap().to_string();
    let page = gateway.until("gateway: status on http://");
    let page = page.split("http://").nth(1).unwrap().split('/').next().unwrap().to_string();
    let summary = |status: &serde_json::Value| status["summary"].as_str().unwrap().to_string();
    let (status, row) = status_after(&page, 0);
    let at_start = format!("listening on {addr} (Modbus/TCP), lines: 0={} at 9600 8N2, 1={} at 38400 8N1", a[0], b[0]);
    assert_eq!(summary(&status), at_start);
    assert_eq!(row, ["0", "0", "never", "-", "never"]);
    let mut stream = TcpStream::connect(&addr).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    answers(&mut stream, 1, 1);
    answers(&mut stream, 2, 2);
    assert_eq!(ask(&mut stream, 3, 3, &[0x03, 0, 0, 0, 1]), [0x83, 0x0A], "unit 3 is in no route yet");

    // A mistake in the file: refused with its place, the running lines untouched.
    std::fs::write(&file, running.replace("baud = 38400", "baud = \"fast\u{1b}[31m\"")).unwrap();
    gateway.signal("HUP");
    let refused = gateway.until("reload refused");
    assert!(refused.contains("ERROR"), "{refused}");
    assert!(refused.contains(&format!("{path}:10:13: invalid basic string")), "{refused}");
    assert!(refused.contains(r#"(in `baud = "fast\u{1b}[31m"`)"#), "the file's bytes are escaped: {refused}");
    answers(&mut stream, 4, 1);
    answers(&mut stream, 5, 2);
    let (status, row) = status_after(&page, 1);
    assert_eq!(summary(&status), at_start, "a refused reload leaves the summary");
    assert_eq!(row[..4], ["1", "1", "never", "-"]);
    assert!(row[4].ends_with(" (why: the recent warnings)"), "{row:?}");
    let recent: Vec<&str> = status["recent"].as_array().unwrap().iter().map(|r| r["text"].as_str().unwrap()).collect();
    let why = recent.iter().find(|r| r.contains("reload refused")).unwrap_or_else(|| panic!("{recent:?}"));
    assert!(why.contains(&format!("{path}:10:13: invalid basic string")), "{why}");
    assert!(why.contains(r#"`baud = "fast\u{1b}[31m"`"#) && !why.contains('\u{1b}'), "escaped on the page: {why}");

    // Line A as it was, line B with another timeout, line C added for unit 3.
    let new = line_a(&a[0], "1") + &line_b(&b[0], "timeout = \"700ms\"\n", "2") + &line_b(&c[0], "", "3");
    std::fs::write(&file, new).unwrap();
    gateway.signal("HUP");
    let done = gateway.until("reload:");
    assert!(done.contains("reload: 1 line added, 1 changed, 0 removed, 1 unchanged; routes changed"), "{done}");
    answers(&mut stream, 6, 3);
    answers(&mut stream, 7, 1);
    answers(&mut stream, 8, 2);
    let (status, row) = status_after(&page, 2);
    let three = format!(
        "listening on {addr} (Modbus/TCP), lines: 0={} at 9600 8N2, 1={} at 38400 8N1, 2={} at 38400 8N1",
        a[0], b[0], c[0]
    );
    assert_eq!(summary(&status), three, "the summary names the lines as applied");
    assert_eq!(row[..2], ["2", "1"]);
    assert!(row[2].starts_with("20") && row[2].ends_with('Z'), "when it was applied: {row:?}");
    assert_eq!(row[3], "1 line added, 1 changed, 0 removed, 1 unchanged; routes changed");

    // Line C removed again: unit 3 is in no route, the others answer on.
    std::fs::write(&file, line_a(&a[0], "1") + &line_b(&b[0], "timeout = \"700ms\"\n", "2")).unwrap();
    gateway.signal("HUP");
    let removed = gateway.until("reload:");
    assert!(removed.contains("reload: 0 lines added, 0 changed, 1 removed, 2 unchanged; routes changed"), "{removed}");
    assert_eq!(ask(&mut stream, 9, 3, &[0x03, 0, 0, 0, 1]), [0x83, 0x0A], "unit 3 is in no route again");
    answers(&mut stream, 10, 1);
    answers(&mut stream, 11, 2);
    let (status, row) = status_after(&page, 3);
    assert_eq!(summary(&status), at_start, "line C is gone from the summary");
    assert_eq!(row[..2], ["3", "1"]);
    assert_eq!(row[3], "0 lines added, 0 changed, 1 removed, 2 unchanged; routes changed");

    drop(stream);
    let report = gateway.stop().join("\n");
    // Line A ran on: its counters hold every request since the start; line B restarted once.
    assert!(report.contains("  unit 1: requests 4 replies 4 timeouts 0"), "{report}");
    assert!(report.contains("  unit 2: requests 2 replies 2 timeouts 0"), "{report}");
    assert!(!report.contains(&format!("line {}", c[0])), "line C is gone: {report}");
    assert!(report.contains("tcp: 1 connections served"), "one connection throughout: {report}");
    assert!(report.contains("reload: 2 done, 1 refused"), "{report}");
}
