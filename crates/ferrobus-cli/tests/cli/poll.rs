//! `ferrobus poll` against `ferrobus sim` with faults: one record per poll with the right
//! kind, counters in the summary that match the records, the port lost and found again,
//! SIGTERM flushing and summarising, a full disk failing loudly, log rotation, --on-change.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use assert_cmd::assert::OutputAssertExt;
use serde_json::Value;

use crate::server::{Sim, ferrobus, stderr, stdout};

/// Units 1 (healthy), 2 (silent), 3 (exception 0x06), 4 (every reply with a bad CRC) and 5
/// (every reply dropped) on one pty.
fn faulty_sim() -> Sim {
    Sim::pty(&[
        "--profile",
        "generic",
        "--unit",
        "1",
        "--unit",
        "2",
        "--unit",
        "3",
        "--unit",
        "4",
        "--unit",
        "5",
        "--fault",
        "2:silent",
        "--fault",
        "3:exception=0x06",
        "--fault",
        "4:corrupt=100%",
        "--fault",
        "5:drop=100%",
    ])
}

fn jsonl(text: &str) -> Vec<Value> {
    text.lines().map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{l:?}: {e}"))).collect()
}

/// `N polls` of the summary line of group `name`, and its count of `kind`.
fn summary_count(summary: &str, name: &str, what: &str) -> u64 {
    let line = summary
        .lines()
        .find(|l| l.trim_start().starts_with(&format!("{name}:")))
        .unwrap_or_else(|| panic!("no summary line for {name} in {summary}"));
    line.split(", ")
        .find_map(|part| {
            let part = part.trim().trim_start_matches(&format!("{name}: "));
            let (n, word) = part.split_once(' ')?;
            (word == what).then(|| n.parse().ok()).flatten()
        })
        .unwrap_or(0)
}

#[test]
fn every_fault_is_a_record_of_its_kind_and_the_summary_counts_match_the_records() {
    let sim = faulty_sim();
    let out = ferrobus()
        .args(["--port", &sim.path, "--parity", "none", "--timeout", "80ms", "poll", "--every", "250ms"])
        .args(["--unit", "1", "holding", "0", "--count", "2"])
        .args(["--unit", "2", "holding", "0", "--unit", "3", "holding", "0"])
        .args(["--unit", "4", "holding", "0", "--unit", "5", "holding", "0"])
        .args(["--duration", "1500ms", "--jsonl"])
        .assert()
        .success();
    let records = jsonl(&stdout(&out));
    let summary = stderr(&out);
    let expected = [(1, "ok"), (2, "timeout"), (3, "exception"), (4, "crc"), (5, "timeout")];
    for (unit, status) in expected {
        let mine: Vec<&Value> = records.iter().filter(|r| r["unit"] == unit).collect();
        assert!(mine.len() >= 2, "unit {unit} polled at least twice in 1.5 s: {mine:?}");
        for (k, r) in mine.iter().enumerate() {
            assert_eq!(r["status"], status, "unit {unit}: {r}");
            assert_eq!(r["seq"], k, "one record per poll, in order: {r}");
            assert!(r["time"].as_str().unwrap().ends_with('Z') && r["time"].as_str().unwrap().len() == 24, "{r}");
        }
        let name = format!("u{unit} holding 0x0000");
        assert_eq!(summary_count(&summary, &name, "polls"), mine.len() as u64, "{summary}");
        let counted = if status == "ok" { "ok" } else { status };
        assert_eq!(summary_count(&summary, &name, counted), mine.len() as u64, "{summary}");
    }
    let exception = records.iter().find(|r| r["unit"] == 3).unwrap();
    assert_eq!(exception["exception"], 6);
    assert!(exception["diagnosis"].as_str().unwrap().contains("exception 0x06"), "{exception}");
    let crc = records.iter().find(|r| r["unit"] == 4).unwrap();
    assert!(crc["diagnosis"].as_str().unwrap().contains("checksum was wrong"), "{crc}");
    let ok = records.iter().find(|r| r["unit"] == 1).unwrap();
    assert_eq!(ok["points"].as_array().unwrap().len(), 2);
    assert!(summary.contains("unit 1: response time p50"), "{summary}");
}

#[test]
fn csv_has_a_row_per_point_and_one_per_failed_poll() {
    let sim = faulty_sim();
    let out = ferrobus()
        .args(["--port", &sim.path, "--parity", "none", "--timeout", "80ms", "poll", "--every", "300ms"])
        .args(["--unit", "1", "holding", "0", "--count", "3", "--format", "hex", "--unit", "3", "input", "0x10"])
        .args(["--duration", "700ms"])
        .assert()
        .success();
    let text = stdout(&out);
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("time,seq,unit,group,point,raw,value,meaning,uom,status,response_ms,diagnosis"));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.splitn(12, ',').collect()).collect();
    let ok: Vec<&Vec<&str>> = rows.iter().filter(|r| r[2] == "1").collect();
    assert_eq!(ok.len() % 3, 0, "three points a poll: {rows:?}");
    assert_eq!(ok[0][4], "0x0000");
    assert_eq!(ok[2][4], "0x0002");
    assert!(ok.iter().all(|r| r[9] == "ok"));
    let failed: Vec<&Vec<&str>> = rows.iter().filter(|r| r[2] == "3").collect();
    assert!(!failed.is_empty());
    assert!(failed.iter().all(|r| r[4] == "u3 input 0x0010" && r[9] == "exception"), "{failed:?}");
}

/// `ferrobus poll ARGS` with its stdout read line by line.
fn spawn_poll(args: &[&str]) -> (Child, std::sync::mpsc::Receiver<String>) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_ferrobus"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("ferrobus poll starts");
    let out = child.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                return;
            }
        }
    });
    (child, rx)
}

fn wait_exit(child: &mut Child) -> std::process::ExitStatus {
    for _ in 0..1000 {
        if let Some(status) = child.try_wait().unwrap() {
            return status;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let _ = child.kill();
    panic!("poll did not end");
}

#[test]
fn sigterm_flushes_every_record_then_prints_the_summary_and_exits_0() {
    let sim = faulty_sim();
    let (mut child, lines) = spawn_poll(&[
        "--port", &sim.path, "--parity", "none", "--unit", "1", "poll", "holding", "0", "--every", "20ms", "--jsonl",
    ]);
    let mut seen = Vec::new();
    while seen.len() < 5 {
        seen.push(lines.recv_timeout(Duration::from_secs(10)).expect("records come"));
    }
    let pid = child.id().to_string();
    assert!(Command::new("kill").args(["-TERM", &pid]).status().unwrap().success());
    let status = wait_exit(&mut child);
    assert_eq!(status.code(), Some(0), "SIGTERM is poll's normal end");
    seen.extend(lines.iter());
    let records = jsonl(&seen.join("\n"));
    let mut summary = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut summary).unwrap();
    let polls = summary_count(&summary, "u1 holding 0x0000", "polls");
    assert_eq!(polls, records.len() as u64, "every poll counted was written: {summary}");
    // On a loaded machine an overrun warning may come first: the summary is the line after it.
    let total = summary.lines().find(|l| l.starts_with("poll: ") && l.contains(" polls, ")).unwrap_or_default();
    assert!(total.starts_with(&format!("poll: {polls} polls, {polls} ok")), "{summary}");
}

#[test]
fn a_full_disk_on_stdout_or_the_log_is_an_error_with_exit_6() {
    let sim = faulty_sim();
    let full = std::fs::OpenOptions::new().write(true).open("/dev/full").unwrap();
    let out = ferrobus()
        .args(["--port", &sim.path, "--parity", "none", "poll", "holding", "0", "--csv", "--duration", "5s"])
        .stdout(full)
        .assert()
        .code(6);
    let err = stderr(&out);
    assert!(err.contains("stdout") && err.contains("No space left on device"), "{err}");
    let out = ferrobus()
        .args(["--port", &sim.path, "--parity", "none", "poll", "holding", "0", "--log", "/dev/full"])
        .args(["--duration", "5s"])
        .assert()
        .code(6);
    let err = stderr(&out);
    assert!(err.contains("/dev/full") && err.contains("No space left on device"), "{err}");
}

#[test]
fn the_log_rotates_by_records_keeping_the_newest_files() {
    let sim = faulty_sim();
    let dir = std::env::temp_dir().join(format!("ferrobus-poll-log-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let log = dir.join("run.csv");
    let log_arg = log.display().to_string();
    ferrobus()
        .args(["--port", &sim.path, "--parity", "none", "poll", "holding", "0", "--every", "20ms"])
        .args(["--log", &log_arg, "--rotate-records", "3", "--keep", "2", "--duration", "600ms", "--csv"])
        .assert()
        .success();
    for name in ["run.csv", "run.csv.1", "run.csv.2"] {
        let text = std::fs::read_to_string(dir.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        let mut lines = text.lines();
        assert!(lines.next().unwrap().starts_with("time,seq,unit"), "{name} starts with the header");
        let n = lines.count();
        assert!((1..=3).contains(&n), "{name}: {n} records");
    }
    let full = std::fs::read_to_string(dir.join("run.csv.1")).unwrap();
    assert_eq!(full.lines().count(), 4, "a rotated file is full: {full}");
    assert!(!dir.join("run.csv.3").exists(), "only two rotated files are kept");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn on_change_writes_steady_registers_and_a_repeated_timeout_once() {
    let sim = faulty_sim();
    let out = ferrobus()
        .args(["--port", &sim.path, "--parity", "none", "--timeout", "50ms", "poll", "--every", "50ms"])
        .args(["--unit", "1", "holding", "0", "--count", "2", "--unit", "2", "holding", "0"])
        .args(["--on-change", "--duration", "600ms", "--jsonl"])
        .assert()
        .success();
    let records = jsonl(&stdout(&out));
    let unit1: Vec<&Value> = records.iter().filter(|r| r["unit"] == 1).collect();
    let unit2: Vec<&Value> = records.iter().filter(|r| r["unit"] == 2).collect();
    assert_eq!(unit1.len(), 1, "the steady registers are written once: {unit1:?}");
    assert_eq!(unit2.len(), 1, "the same timeout is written once: {unit2:?}");
    let summary = stderr(&out);
    assert!(summary_count(&summary, "u1 holding 0x0000", "polls") > 3, "{summary}");
}

#[test]
fn a_line_too_slow_for_the_period_is_said_once_with_the_arithmetic() {
    let sim = faulty_sim();
    let out = ferrobus()
        .args(["--port", &sim.path, "--parity", "none", "--baud", "9600", "poll", "holding", "0", "--count", "100"])
        .args(["--every", "50ms", "--duration", "300ms"])
        .assert()
        .success();
    let err = stderr(&out);
    assert_eq!(err.matches("the line cannot").count(), 1, "{err}");
    assert!(err.contains("(8 + 205) characters × 1.042 ms + 2 × t3.5 3.646 ms"), "{err}");
    assert!(err.contains("every 50.000 ms"), "{err}");
}

/// A `ferrobus sim` of the generic profile serving Modbus/TCP on `addr`, once it listens.
fn tcp_sim(addr: &str) -> Child {
    let mut child = Command::new(env!("CARGO_BIN_EXE_ferrobus"))
        .args(["--tcp", addr, "sim", "--profile", "generic", "--duration", "30s"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    while let Some(Ok(line)) = lines.next() {
        if line.starts_with("sim: listening on ") {
            break;
        }
    }
    child
}

/// `--in-flight 4` reads four groups at once on a Modbus/TCP connection: every poll of each
/// group answered, each group at its own rate; on a line without transaction ids it is a
/// usage error that says why.
#[test]
fn in_flight_reads_groups_together_over_modbus_tcp_and_is_refused_elsewhere() {
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let addr = format!("127.0.0.1:{port}");
    let mut sim = tcp_sim(&addr);
    let starts = ["0", "10", "20", "30", "40", "50"];
    let groups = starts.iter().flat_map(|start| ["holding", start, "--every", "50ms"]);
    let out = ferrobus()
        .args(["--tcp", &addr, "poll"])
        .args(groups)
        .args(["--in-flight", "4", "--duration", "1s", "--jsonl"])
        .assert()
        .success();
    sim.kill().unwrap();
    sim.wait().unwrap();
    let records = jsonl(&String::from_utf8_lossy(&out.get_output().stdout));
    assert!(records.iter().all(|r| r["status"] == "ok"), "{records:?}");
    for start in starts {
        let name = format!("u1 holding {:#06x}", start.parse::<u16>().unwrap());
        let mine = records.iter().filter(|r| r["group"] == name.as_str()).count();
        assert!(mine >= 10, "{name}: {mine} polls in 1 s at 50 ms");
    }
    let out =
        ferrobus().args(["--rtu-tcp", "127.0.0.1:1", "poll", "holding", "0", "--in-flight", "2"]).assert().code(2);
    assert!(stderr(&out).contains("--in-flight 2: only a Modbus/TCP connection"), "{}", stderr(&out));
}

#[test]
fn a_lost_tcp_server_is_a_port_record_and_polling_resumes_when_it_is_back() {
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let addr = format!("127.0.0.1:{port}");
    let start_sim = || tcp_sim(&addr);
    let mut sim = start_sim();
    let (mut poll, lines) =
        spawn_poll(&["--tcp", &addr, "--timeout", "200ms", "poll", "holding", "0", "--every", "50ms", "--jsonl"]);
    let mut seen: Vec<Value> = Vec::new();
    let next = || serde_json::from_str::<Value>(&lines.recv_timeout(Duration::from_secs(10)).unwrap()).unwrap();
    while seen.len() < 3 {
        seen.push(next());
    }
    sim.kill().unwrap();
    sim.wait().unwrap();
    while !seen.iter().any(|r| r["status"] == "port") {
        seen.push(next());
    }
    let mut sim = start_sim();
    loop {
        let r = next();
        let ok = r["status"] == "ok";
        seen.push(r);
        if ok {
            break;
        }
    }
    let _ = poll.kill();
    let _ = poll.wait();
    sim.kill().unwrap();
    sim.wait().unwrap();
    let port_record = seen.iter().find(|r| r["status"] == "port").unwrap();
    assert!(port_record["diagnosis"].as_str().unwrap().contains(&addr), "{port_record}");
    let statuses: Vec<&str> = seen.iter().map(|r| r["status"].as_str().unwrap()).collect();
    assert!(statuses.iter().all(|s| ["ok", "port", "timeout"].contains(s)), "{statuses:?}");
    assert_eq!(statuses.first(), Some(&"ok"));
    assert_eq!(statuses.last(), Some(&"ok"), "polling resumed: {statuses:?}");
}

#[test]
fn bad_group_arguments_are_usage_errors_that_say_what_is_wrong() {
    let cases: [(&[&str], &str); 6] = [
        (&["--unit", "7", "poll", "holding", "0", "--unit", "3", "input", "0"], "given both before and after `poll`"),
        (&["poll", "holding", "0", "--on-change", "--deadband=-1"], "give a number, 0 or more"),
        (&["poll", "holding"], "holding needs an ADDRESS after it"),
        (&["poll", "speed"], "\"speed\" is neither a table"),
        (&["poll", "holding", "0x10000"], "address 0x10000 is out of range (0-65535)"),
        (&["poll", "holding", "0", "--count", "0"], "a count of 0 reads nothing"),
    ];
    for (args, message) in cases {
        let out = ferrobus().args(["--tcp", "127.0.0.1:1"]).args(args).assert().code(2);
        assert!(stderr(&out).contains(message), "{args:?}: {}", stderr(&out));
    }
}

#[test]
fn named_points_of_a_device_are_scaled_with_their_unit() {
    let sim = Sim::pty(&["--profile", "omron-3g3rx"]);
    let out = ferrobus()
        .args(["--port", &sim.path, "--parity", "none", "--device", "omron-3g3rx", "poll", "d001", "d002"])
        .args(["--every", "100ms", "--duration", "350ms", "--jsonl"])
        .assert()
        .success();
    let records = jsonl(&stdout(&out));
    assert!(records.len() >= 3, "{records:?}");
    for (k, r) in records.iter().enumerate() {
        assert_eq!(r["status"], "ok", "{r}");
        assert_eq!(r["due_ms"], 100.0 * f64::from(u32::try_from(k).unwrap()), "due on the grid from the start: {r}");
        let points = r["points"].as_array().unwrap();
        assert_eq!(points[0]["point"], "d001");
        assert_eq!(points[0]["uom"], "Hz");
        assert!(points[0]["shown"].as_str().unwrap().ends_with(" Hz"), "{r}");
        assert_eq!(points[1]["point"], "d002");
    }
}

/// The records of `poll ARGS --jsonl` for about a second on a simulated 3G3RX.
fn rx_records(sim: &Sim, args: &[&str]) -> Vec<Value> {
    let out = ferrobus()
        .args(["--port", &sim.path, "--parity", "none", "--device", "omron-3g3rx", "poll"])
        .args(args)
        .args(["--jsonl", "--every", "300ms", "--duration", "1s"])
        .assert()
        .success();
    jsonl(&stdout(&out))
}

#[test]
fn with_device_a_raw_group_is_numbered_as_read_numbers_it_and_split_by_the_profiles_limit() {
    let sim = Sim::pty(&["--profile", "omron-3g3rx"]);
    // The 3G3RX numbers from 1 (d001 is 0x1001, wire 0x1000) and reads 4 registers a request:
    // 8 registers are two groups of 4 at wire 0x1000 and 0x1004, in both forms.
    for args in [&["holding:0x1001:8"][..], &["holding", "0x1001", "--count", "8"]] {
        let records = rx_records(&sim, args);
        assert!(!records.is_empty(), "{args:?}: no record");
        for record in &records {
            assert_eq!(record["status"], "ok", "{args:?}: {record}");
            assert_eq!(record["points"].as_array().map(Vec::len), Some(4), "{args:?}: {record}");
        }
        let groups: std::collections::BTreeSet<&str> = records.iter().filter_map(|r| r["group"].as_str()).collect();
        assert_eq!(groups.into_iter().collect::<Vec<_>>(), ["u1 holding 0x1000", "u1 holding 0x1004"], "{args:?}");
    }
    // The same registers and requests as `read` makes.
    let read = stdout(
        &ferrobus()
            .args(["--port", &sim.path, "--parity", "none", "--device", "omron-3g3rx", "read", "holding", "0x1001"])
            .args(["--count", "8", "--json"])
            .assert()
            .success(),
    );
    let read: Value = serde_json::from_str(read.trim()).unwrap();
    assert_eq!((read["start"].as_u64(), read["requests"].as_u64()), (Some(0x1000), Some(2)), "{read}");
}

#[test]
fn with_device_the_hint_for_exception_02_speaks_of_the_profiles_numbering_not_of_one_based() {
    let sim = Sim::pty(&["--profile", "omron-3g3rx"]);
    let base = ["--port", &sim.path, "--parity", "none"];
    let err =
        stderr(&ferrobus().args(base).args(["--device", "omron-3g3rx", "read", "holding", "0x5001"]).assert().code(1));
    assert!(err.contains("exception 0x02"), "{err}");
    assert!(err.contains("numbered from 1 as the Omron 3G3RX"), "{err}");
    assert!(!err.contains("add --one-based"), "{err}");
    let err = stderr(&ferrobus().args(base).args(["read", "holding", "0x5000", "--one-based"]).assert().code(1));
    assert!(err.contains("with --one-based the frame address is the number - 1"), "{err}");
    let err = stderr(&ferrobus().args(base).args(["read", "holding", "0x5000"]).assert().code(1));
    assert!(err.contains("add --one-based"), "{err}");
}
