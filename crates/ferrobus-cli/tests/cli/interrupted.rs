//! A command interrupted while its request is on an RTU line: the reply still comes, and the
//! next program on the port must not take it for its own. The interrupted process keeps the
//! port until the reply has come (or its window has passed), says so, and exits at once on a
//! second Ctrl-C. A command that ended on a timeout waits the same way, for the late window.

use std::io::{BufRead, BufReader};
use std::process::{Child, ChildStderr, Stdio};
use std::time::{Duration, Instant};

use crate::server::{Sim, ferrobus, stdout};

/// `ferrobus get CODE` against `sim` with the request traced (`-vvv`), stderr piped.
fn traced_get(sim: &Sim, code: &str, timeout: &str) -> (Child, BufReader<ChildStderr>) {
    let mut child = ferrobus()
        .args(["-vvv", "--port", &sim.path, "--parity", "none", "--timeout", timeout])
        .args(["--device", "omron-3g3rx", "get", code])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("ferrobus get starts");
    let stderr = BufReader::new(child.stderr.take().expect("piped stderr"));
    (child, stderr)
}

/// Reads `stderr` up to the first line that contains `text`; all it read, if it found one.
fn read_until(stderr: &mut BufReader<ChildStderr>, text: &str) -> Result<String, String> {
    let mut seen = String::new();
    loop {
        let mut line = String::new();
        match stderr.read_line(&mut line) {
            Ok(0) | Err(_) => return Err(seen),
            Ok(_) => {
                seen.push_str(&line);
                if line.contains(text) {
                    return Ok(seen);
                }
            }
        }
    }
}

/// Sends SIGINT to `child`, as Ctrl-C or `timeout -s INT` would.
fn interrupt(child: &Child) {
    let status = std::process::Command::new("kill").args(["-INT", &child.id().to_string()]).status();
    assert!(status.is_ok_and(|s| s.success()), "kill -INT {} failed", child.id());
}

/// The value cell of `code`'s row in `get`'s table.
fn value_of(out: &str, code: &str) -> String {
    let row = out.lines().find(|l| l.split_whitespace().next() == Some(code));
    let row = row.unwrap_or_else(|| panic!("no row {code} in:\n{out}"));
    let cells: Vec<&str> = row.split("  ").map(str::trim).filter(|c| !c.is_empty()).collect();
    cells.get(2).unwrap_or_else(|| panic!("no value in {row:?}")).to_string()
}

#[test]
fn a_reply_in_flight_when_get_is_interrupted_never_answers_the_next_get() {
    // 150 ms of reply wait: the reply to F002 is still coming when the first get is stopped.
    let sim = Sim::pty(&["--profile", "omron-3g3rx", "--response-wait", "150ms"]);
    let set = |code: &str, value: &str| sim.run(1, &["--device", "omron-3g3rx", "set", code, value]).success();
    set("F002", "33s");
    set("F003", "12s");
    for round in 0..3 {
        let (mut first, mut stderr) = traced_get(&sim, "F002", "1s");
        let traced = read_until(&mut stderr, " tx ").unwrap_or_else(|seen| panic!("no request traced:\n{seen}"));
        interrupt(&first);
        let rest = read_until(&mut stderr, "waiting up to")
            .unwrap_or_else(|seen| panic!("round {round}: no note of the reply in flight:\n{traced}{seen}"));
        assert!(rest.contains("for the reply in flight"), "{rest}");
        let status = first.wait().unwrap();
        assert_eq!(status.code(), Some(130), "round {round}: an interrupted get exits 130");
        // At once after it, on the same port: F003's own value, never F002's reply.
        let next = sim.run(1, &["--device", "omron-3g3rx", "get", "F003"]).success();
        assert_eq!(value_of(&stdout(&next), "F003"), "12.00 s", "round {round}");
    }
}

#[test]
fn a_second_ctrl_c_ends_the_wait_for_the_reply_in_flight_at_once() {
    // A unit that never answers: its reply is owed for the whole timeout and late window
    // (5 s and 10 s), far longer than the process takes to exit on a second Ctrl-C.
    let sim = Sim::pty(&["--profile", "omron-3g3rx", "--fault", "1:silent"]);
    let (mut child, mut stderr) = traced_get(&sim, "F002", "5s");
    read_until(&mut stderr, " tx ").unwrap_or_else(|seen| panic!("no request traced:\n{seen}"));
    interrupt(&child);
    let note = read_until(&mut stderr, "waiting up to").unwrap_or_else(|seen| panic!("no note:\n{seen}"));
    let ms = announced(&note);
    assert!(ms >= 14_000, "a request with a 5 s timeout and a 10 s late window may keep the line {ms} ms");
    let asked = Instant::now();
    interrupt(&child);
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(130));
    // Not a timed assertion of how fast: only that it did not sit out the wait it announced.
    assert!(asked.elapsed() < Duration::from_millis(ms / 2), "the second Ctrl-C was not taken");
}

/// The wait `note` announces, in ms.
fn announced(note: &str) -> u64 {
    note.rsplit("waiting up to ")
        .next()
        .and_then(|rest| rest.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no wait in {note:?}"))
}

#[test]
fn a_get_that_timed_out_keeps_the_port_for_its_late_reply_for_the_late_window() {
    let sim = Sim::pty(&["--profile", "omron-3g3rx", "--fault", "1:silent"]);
    let get = |extra: &[&str]| {
        let assert = sim.run(1, &[extra, &["--device", "omron-3g3rx", "get", "F002"]].concat()).code(3);
        crate::server::stderr(&assert)
    };
    // By default twice the timeout (300 ms): the reply is owed up to 600 ms after it.
    let default = get(&[]);
    let waited = announced(&default);
    assert!((300..=600).contains(&waited), "{default}");
    let set = get(&["--late-window", "150ms"]);
    assert!(announced(&set) <= 150, "{set}");
    assert!(set.contains("no reply from unit 1 within 300 ms"), "{set}");
}

#[test]
fn a_bridge_stopped_with_a_poll_on_a_serial_line_keeps_the_port_for_the_reply_in_flight() {
    use tokio::io::AsyncReadExt;
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let _inside = runtime.enter();
    // The device's end of the line is the test's: it hears the poll and never answers.
    let mut pty = ferrobus::Pty::open().unwrap();
    let dir = std::env::temp_dir().join(format!("ferrobus-bridge-owed-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let plant = dir.join("plant.toml");
    std::fs::write(
        &plant,
        format!(
            "[broker]\naddress = \"127.0.0.1:1\"\nclient_id = \"owed\"\nreconnect = \"10s\"\n\n\
             [plain]\nprefix = \"owed\"\n\n\
             [[line]]\nname = \"line\"\nport = \"{}\"\nbaud = 19200\nparity = \"none\"\ntimeout = \"5s\"\nretries = 0\n\n\
             [[line.device]]\nid = \"counter\"\nunit = 1\nprofile = \"generic\"\n\
             [[line.device.raw]]\ntable = \"holding\"\naddress = 0\ncount = 1\ntype = \"u16\"\nname = \"counter\"\n\
             every = \"100ms\"\n",
            pty.path.display()
        ),
    )
    .unwrap();
    let mut child = ferrobus()
        .args(["bridge", "--config", plant.to_str().unwrap()])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("ferrobus bridge starts");
    let mut stderr = BufReader::new(child.stderr.take().expect("piped stderr"));
    // The poll is on the line, its reply owed for the 5 s timeout and the late window.
    let mut request = [0u8; 8];
    runtime.block_on(pty.read_exact(&mut request)).unwrap();
    assert_eq!(request[..2], [0x01, 0x03]);
    interrupt(&child);
    let note = read_until(&mut stderr, "waiting up to").unwrap_or_else(|seen| panic!("no note:\n{seen}"));
    assert!(note.contains("for the reply in flight"), "{note}");
    interrupt(&child);
    child.wait().unwrap();
    drop(pty);
    let _ = std::fs::remove_dir_all(&dir);
}
