//! `ferrobus gateway --lines-file`: two `ferrobus line` buses at their own baud rates, a
//! simulated device on each at its line's settings, one gateway serving both from a file, each
//! unit reached at its own line's settings; the mix with `--port` or `--route` refused; a
//! broken file refused with its file:line:column before any port is opened; `--in-flight` (and
//! `in-flight =`) refused on a line without transaction ids.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use serde_json::Value;

use crate::server::{ferrobus, offline, stderr};

/// A child process and the lines of its stdout or stderr, as they come.
pub(crate) struct Proc {
    child: Child,
    lines: mpsc::Receiver<String>,
    seen: Vec<String>,
}

impl Proc {
    /// `ferrobus ARGS`, reading its stdout (`stdout`) or its stderr line by line.
    pub(crate) fn ferrobus(args: &[&str], stdout: bool) -> Proc {
        let mut command: Command = ferrobus();
        command.args(args).stdin(Stdio::null());
        if stdout {
            command.stdout(Stdio::piped()).stderr(Stdio::null());
        } else {
            command.stdout(Stdio::null()).stderr(Stdio::piped());
        }
        let mut child = command.spawn().unwrap();
        let reader: Box<dyn Read + Send> =
            if stdout { Box::new(child.stdout.take().unwrap()) } else { Box::new(child.stderr.take().unwrap()) };
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(reader).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    return;
                }
            }
        });
        Proc { child, lines, seen: Vec::new() }
    }

    /// The next line, waiting at most 20 s.
    fn line(&mut self) -> String {
        let line = self.lines.recv_timeout(Duration::from_secs(20));
        let line = line.unwrap_or_else(|_| panic!("no further line; so far {:#?}", self.seen));
        self.seen.push(line.clone());
        line
    }

    /// Reads lines until one contains `text`, and returns it.
    pub(crate) fn until(&mut self, text: &str) -> String {
        loop {
            let line = self.line();
            if line.contains(text) {
                return line;
            }
        }
    }

    /// Sends it `signal` (`HUP`, `TERM`, ...).
    pub(crate) fn signal(&self, signal: &str) {
        let status = Command::new("kill").args([&format!("-{signal}"), &self.child.id().to_string()]).status().unwrap();
        assert!(status.success(), "kill -{signal}");
    }

    /// SIGTERM, then waits for the end; every line it printed after.
    pub(crate) fn stop(&mut self) -> Vec<String> {
        self.signal("TERM");
        let exit = self.child.wait().unwrap();
        assert!(exit.success(), "{exit}; it printed {:#?}", self.seen);
        self.lines.iter().collect()
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A fresh directory under the target dir for one test's files.
pub(crate) fn dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("gateway-lines-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A `ferrobus line` of two pty drops at `settings` (line options), its statistics to `stats`;
/// the drops' paths.
pub(crate) fn bus(settings: &[&str], stats: &Path) -> (Proc, [String; 2]) {
    let args = [settings, &["line", "--drops", "2", "--stats-json", stats.to_str().unwrap()]].concat();
    let mut line = Proc::ferrobus(&args, true);
    let drops = [line.line(), line.line()];
    (line, drops)
}

/// `ferrobus sim` on `port` at `settings`, once it serves.
pub(crate) fn sim(port: &str, settings: &[&str], args: &[&str]) -> Proc {
    let all = [&["--port", port][..], settings, &["sim", "--profile", "generic"], args].concat();
    let mut sim = Proc::ferrobus(&all, false);
    sim.until("serving on");
    sim
}

/// Sends one Modbus/TCP request (unit, PDU) and returns the reply's PDU.
pub(crate) fn ask(stream: &mut TcpStream, transaction: u16, unit: u8, pdu: &[u8]) -> Vec<u8> {
    let length = u16::try_from(pdu.len() + 1).unwrap();
    let mut adu = [&transaction.to_be_bytes()[..], &[0, 0], &length.to_be_bytes(), &[unit], pdu].concat();
    stream.write_all(&adu).unwrap();
    adu.resize(7, 0);
    stream.read_exact(&mut adu).unwrap();
    assert_eq!(adu[..2], transaction.to_be_bytes(), "transaction id");
    assert_eq!(adu[6], unit, "unit");
    let length = usize::from(u16::from_be_bytes([adu[4], adu[5]]));
    let mut reply = vec![0; length - 1];
    stream.read_exact(&mut reply).unwrap();
    reply
}

/// GET `/status.json` on the status endpoint at `addr`, parsed.
pub(crate) fn status_json(addr: &str) -> Value {
    let mut stream = TcpStream::connect(addr).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(stream, "GET /status.json HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n").unwrap();
    let mut answer = String::new();
    stream.read_to_string(&mut answer).unwrap();
    let (head, body) = answer.split_once("\r\n\r\n").unwrap();
    assert!(head.starts_with("HTTP/1.1 200"), "{head}");
    serde_json::from_str(body).unwrap()
}

/// `/status.json` at `addr` once its `Reloads` table says `checked` files were read again
/// (the command counts a reload just after it logs it), waiting at most 10 s; and that table's
/// one row.
pub(crate) fn status_after(addr: &str, checked: u64) -> (Value, Vec<String>) {
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    loop {
        let status = status_json(addr);
        let table = status["tables"].as_array().unwrap().iter().find(|t| t["title"] == "Reloads").cloned();
        let row: Vec<String> = table
            .and_then(|t| t["rows"][0].as_array().cloned())
            .unwrap_or_default()
            .iter()
            .map(|c| c.as_str().unwrap().to_string())
            .collect();
        if row.first().map(String::as_str) == Some(checked.to_string().as_str()) {
            return (status, row);
        }
        assert!(std::time::Instant::now() < deadline, "no {checked} reloads checked: {status:#}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

pub(crate) const LINE_A: [&str; 6] = ["--baud", "9600", "--parity", "none", "--stop-bits", "2"];
pub(crate) const LINE_B: [&str; 4] = ["--baud", "38400", "--parity", "none"];

#[test]
fn two_lines_at_their_own_baud_rates_serve_their_units_each_at_its_lines_settings() {
    let dir = dir("two");
    let (mut bus_a, a) = bus(&LINE_A, &dir.join("a.json"));
    let (mut bus_b, b) = bus(&LINE_B, &dir.join("b.json"));
    let _sim_a = sim(&a[1], &LINE_A, &["--unit", "1"]);
    // Unit 2 holds its reply 300 ms: more than line 1's timeout, less than timeout + response-wait.
    let _sim_b = sim(&b[1], &LINE_B, &["--unit", "2", "--response-wait", "300ms"]);
    let file = dir.join("lines.toml");
    let text = format!(
        "[[line]]\nport = \"{}\"\nbaud = 9600\nparity = \"none\"\nstop-bits = 2\nunits = [1]\n\n[[line]]\nport = \
         \"{}\"\nbaud = 38400\nparity = \"none\"\ntimeout = \"200ms\"\nresponse-wait = \"300ms\"\nrenumber = {{ 12 = 2 \
         }}\n",
        a[0], b[0]
    );
    std::fs::write(&file, text).unwrap();
    // The command line's line options (19200 8E1 by default) are neither line's.
    let args = ["gateway", "--lines-file", file.to_str().unwrap(), "--listen", "127.0.0.1:0", "--duration", "60s"];
    let mut gateway = Proc::ferrobus(&args, false);
    let listening = gateway.until("gateway: listening on");
    assert!(listening.contains(&format!("0={} at 9600 8N2", a[0])), "{listening}");
    assert!(listening.contains(&format!("1={} at 38400 8N1", b[0])), "{listening}");
    let addr = listening.split_whitespace().nth(3).unwrap().to_string();
    let mut stream = TcpStream::connect(&addr).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    // Each unit's register written and read back through its own line, turn about.
    for (round, value) in [0x1234u16, 0xBEEF, 0x0042].into_iter().enumerate() {
        for (unit, register) in [(1u8, 0x0010u16), (12, 0x0020)] {
            let [rh, rl] = register.to_be_bytes();
            let [vh, vl] = value.to_be_bytes();
            let id = u16::try_from(round).unwrap() * 10 + u16::from(unit);
            assert_eq!(ask(&mut stream, id, unit, &[0x06, rh, rl, vh, vl]), [0x06, rh, rl, vh, vl], "unit {unit}");
            assert_eq!(ask(&mut stream, id + 1, unit, &[0x03, rh, rl, 0, 1]), [0x03, 2, vh, vl], "unit {unit}");
        }
    }
    drop(stream);
    let report = gateway.stop().join("\n");
    assert!(report.contains(&format!("line {} at 9600 8N2", a[0])), "{report}");
    assert!(report.contains("  unit 1: requests 6 replies 6 timeouts 0 crc-errors 0"), "{report}");
    assert!(report.contains(&format!("line {} at 38400 8N1", b[0])), "{report}");
    assert!(report.contains("  unit 12: requests 6 replies 6 timeouts 0 crc-errors 0"), "{report}");
    // Each bus: the gateway's drop kept t3.5 of its line before every frame.
    for (bus, stats, drops) in [(&mut bus_a, "a.json", &a), (&mut bus_b, "b.json", &b)] {
        bus.stop();
        let stats: Value = serde_json::from_str(&std::fs::read_to_string(dir.join(stats)).unwrap()).unwrap();
        let gateway = &stats["endpoints"][0];
        assert_eq!(gateway["name"], drops[0].as_str(), "{stats:#}");
        assert!(gateway["characters"].as_u64().unwrap() > 0, "{stats:#}");
        assert_eq!(gateway["gap_violations"], 0, "{stats:#}");
    }
}

#[test]
fn a_line_whose_file_gives_the_wrong_baud_rate_gets_0b_and_the_other_line_still_answers() {
    let dir = dir("wrong");
    let (_bus_a, a) = bus(&LINE_A, &dir.join("a.json"));
    let (_bus_b, b) = bus(&LINE_B, &dir.join("b.json"));
    let _sim_a = sim(&a[1], &LINE_A, &["--unit", "1"]);
    let _sim_b = sim(&b[1], &LINE_B, &["--unit", "2"]);
    let file = dir.join("lines.toml");
    let text = format!(
        "[[line]]\nport = \"{}\"\nbaud = 9600\nparity = \"none\"\nstop-bits = 2\nunits = [1]\n\n[[line]]\nport = \
         \"{}\"\nbaud = 9600\nparity = \"none\"\ntimeout = \"200ms\"\nunits = [2]\n",
        a[0], b[0]
    );
    std::fs::write(&file, text).unwrap();
    let args = ["gateway", "--lines-file", file.to_str().unwrap(), "--listen", "127.0.0.1:0", "--duration", "60s"];
    let mut gateway = Proc::ferrobus(&args, false);
    let listening = gateway.until("gateway: listening on");
    let addr = listening.split_whitespace().nth(3).unwrap().to_string();
    let mut stream = TcpStream::connect(&addr).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    assert_eq!(ask(&mut stream, 1, 1, &[0x03, 0, 0, 0, 1]).first(), Some(&0x03));
    // At 9600 on a 38400 bus the device hears garbage and stays silent.
    assert_eq!(ask(&mut stream, 2, 2, &[0x03, 0, 0, 0, 1]), [0x83, 0x0B]);
    assert_eq!(ask(&mut stream, 3, 1, &[0x03, 0, 0, 0, 1]).first(), Some(&0x03));
}

#[test]
fn lines_file_beside_port_or_route_is_refused_and_a_broken_file_is_named_before_any_port_opens() {
    let dir = dir("refused");
    let file = dir.join("lines.toml");
    // Line 0's port does not exist: the error is line 1's baud, found before anything opens.
    let text = "[[line]]\nport = \"/dev/null-no-such-port\"\nunits = [1]\n\n[[line]]\nport = \"/dev/null-other\"\nbaud \
                = 0\nunits = [2]\n";
    std::fs::write(&file, text).unwrap();
    let path = file.to_str().unwrap();
    let err = stderr(&offline(&["gateway", "--lines-file", path]).code(2));
    assert!(err.contains(&format!("{path}:7:8: [[line]] 1, baud: 0 is out of range")), "{err}");
    assert!(!err.contains("null-no-such-port"), "{err}");
    let err = stderr(&offline(&["--port", "/dev/null-x", "gateway", "--lines-file", path]).code(2));
    assert!(err.contains("--lines-file names every line of the gateway: not with --port /dev/null-x"), "{err}");
    let err = stderr(&offline(&["gateway", "--lines-file", path, "--route", "1=0"]).code(2));
    assert!(err.contains("'--lines-file <FILE>' cannot be used with '--route"), "{err}");
    let err = stderr(&offline(&["gateway", "--lines-file", path, "--line", "/dev/null-y"]).code(2));
    assert!(err.contains("'--lines-file <FILE>' cannot be used with '--line"), "{err}");
    let missing = dir.join("missing.toml");
    let err = stderr(&offline(&["gateway", "--lines-file", missing.to_str().unwrap()]).code(2));
    assert!(err.contains("cannot read the lines file"), "{err}");
}

#[test]
fn in_flight_past_one_is_refused_on_a_serial_or_rtu_over_tcp_line_before_anything_opens() {
    let err = stderr(&offline(&["--port", "/dev/null-no-such-port", "gateway", "--in-flight", "4"]).code(2));
    assert!(
        err.contains(
            "--in-flight 4: only a Modbus/TCP line (--tcp) keeps several requests in flight, and this is a serial line"
        ),
        "{err}"
    );
    assert!(!err.contains("null-no-such-port"), "refused before the port is opened: {err}");
    let err = stderr(&offline(&["--rtu-tcp", "127.0.0.1:1", "gateway", "--in-flight", "2"]).code(2));
    assert!(err.contains("this is RTU over TCP (--rtu-tcp): RTU frames carry no transaction id"), "{err}");
    let err = stderr(&offline(&["--tcp", "127.0.0.1:1", "gateway", "--in-flight", "17"]).code(2));
    assert!(err.contains("17 is not in 1..=16"), "{err}");
    let dir = dir("in-flight");
    let file = dir.join("lines.toml");
    std::fs::write(&file, "[[line]]\nport = \"/dev/null-no-such-port\"\nin-flight = 3\n").unwrap();
    let path = file.to_str().unwrap();
    let err = stderr(&offline(&["gateway", "--lines-file", path]).code(2));
    assert!(err.contains(&format!("{path}:3:13: [[line]] 0, in-flight: only a Modbus/TCP line")), "{err}");
}
