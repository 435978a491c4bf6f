//! `ferrobus scan` over `ferrobus line` with simulated devices on its other drops: the report
//! names exactly the devices there, with their settings, answers and identification; leads for
//! corrupt replies; another master heard while listening stops the scan before it transmits.

use std::io::{BufRead, BufReader, Read};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use serde_json::Value;

use crate::server::ferrobus;

/// A child process and the lines of one of its outputs, as they come.
struct Proc {
    child: Child,
    lines: mpsc::Receiver<String>,
    seen: Vec<String>,
}

impl Proc {
    /// Starts `command` reading its stdout (`stdout`) or its stderr line by line; the other
    /// goes to `other`.
    fn spawn(mut command: Command, stdout: bool, other: Stdio) -> Proc {
        command.stdin(Stdio::null());
        if stdout {
            command.stdout(Stdio::piped()).stderr(other);
        } else {
            command.stdout(other).stderr(Stdio::piped());
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

    /// `ferrobus ARGS`.
    fn ferrobus(args: &[&str], stdout: bool) -> Proc {
        let mut command = ferrobus();
        command.args(args);
        Proc::spawn(command, stdout, Stdio::null())
    }

    /// The next line, waiting at most 20 s.
    fn line(&mut self) -> String {
        let line = self.lines.recv_timeout(Duration::from_secs(20));
        let line = line.unwrap_or_else(|_| panic!("no further line; so far {:#?}", self.seen));
        self.seen.push(line.clone());
        line
    }

    /// Reads lines until one contains `text`, and returns it.
    fn until(&mut self, text: &str) -> String {
        loop {
            let line = self.line();
            if line.contains(text) {
                return line;
            }
        }
    }

    fn signal(&self, name: &str) {
        let status = Command::new("kill").args([name, &self.child.id().to_string()]).status().unwrap();
        assert!(status.success(), "kill {name}");
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A line of `drops` pty endpoints at `baud`, writing its statistics to `stats`; the paths.
fn line(baud: &str, drops: u8, stats: &std::path::Path) -> (Proc, Vec<String>) {
    let drops_text = drops.to_string();
    let stats = stats.to_str().unwrap();
    let mut line = Proc::ferrobus(&["--baud", baud, "line", "--drops", &drops_text, "--stats-json", stats], true);
    let paths = (0..drops).map(|_| line.line()).collect();
    (line, paths)
}

/// `ferrobus sim` on `port` with `args`, once it serves.
fn sim(port: &str, baud: &str, args: &[&str]) -> Proc {
    let mut all = vec!["--port", port, "--baud", baud, "sim"];
    all.extend_from_slice(args);
    let mut sim = Proc::ferrobus(&all, false);
    sim.until("serving on");
    sim
}

/// Runs `ferrobus --port PORT scan ARGS --json` to its end; its exit code and its document.
fn scan(port: &str, args: &[&str]) -> (Option<i32>, Value) {
    let output = ferrobus().args(["--port", port, "scan", "--json"]).args(args).output().unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    let doc = serde_json::from_str(&stdout).unwrap_or_else(|e| {
        panic!("scan printed no JSON ({e}): {stdout}\nstderr: {}", String::from_utf8_lossy(&output.stderr))
    });
    (output.status.code(), doc)
}

fn devices(doc: &Value) -> Vec<(u64, String)> {
    doc["devices"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| (d["unit"].as_u64().unwrap(), d["settings"].as_str().unwrap().to_string()))
        .collect()
}

fn device(doc: &Value, unit: u64) -> &Value {
    doc["devices"].as_array().unwrap().iter().find(|d| d["unit"] == unit).unwrap()
}

#[test]
fn a_scan_names_exactly_the_devices_on_the_line_with_settings_answers_and_identification() {
    let dir = tempfile_dir("devices");
    let (_line, drops) = line("19200", 5, &dir.join("stats.json"));
    // Unit 1: a generic device (identifies itself); unit 2: a 3G3RX (no identification).
    let _a =
        sim(&drops[1], "19200", &["--profile", "generic", "--unit", "1", "--profile", "omron-3g3rx", "--unit", "2"]);
    // Unit 4 answers after a 200 ms response wait.
    let _b = sim(&drops[2], "19200", &["--profile", "generic", "--unit", "4", "--response-wait", "200ms"]);
    // Unit 5 answers every request with exception 04; unit 6's replies all have a broken CRC.
    let faults = ["--profile", "generic", "--unit", "5", "--unit", "6", "--fault", "5:exception=0x04", "--fault"];
    let _c = sim(&drops[3], "19200", &[&faults[..], &["6:corrupt=100%"]].concat());
    // Unit 3 is at 9600 on the same 19200 line: the wire carries each sender's own settings.
    let _d = sim(&drops[4], "9600", &["--profile", "generic", "--unit", "3"]);
    let args = ["--units", "1-8", "--bauds", "19200,9600", "--framings", "8E1", "--probe-timeout", "300ms", "--listen"];
    let (code, doc) = scan(&drops[0], &[&args[..], &["200ms"]].concat());
    assert_eq!(code, Some(0), "{doc:#}");
    assert_eq!(doc["complete"], true);
    let at = |unit: u64| (unit, "19200 8E1".to_string());
    let slow_unit = (3, "9600 8E1".to_string());
    assert_eq!(devices(&doc), [at(1), at(2), at(4), at(5), slow_unit], "{doc:#}");
    assert_eq!(device(&doc, 3)["identification"]["product_code"], "FB-GENERIC");
    let generic = device(&doc, 1);
    assert_eq!(generic["answer"]["kind"], "reply");
    assert_eq!(generic["identification"]["vendor"], "ferrobus");
    assert_eq!(generic["identification"]["product_code"], "FB-GENERIC");
    assert_eq!(generic["identification"]["revision"], "0.1");
    assert_eq!(generic["profile"], "generic");
    let drive = device(&doc, 2);
    assert_eq!(drive["answer"]["kind"], "reply");
    let refused = &drive["identification"]["refused"];
    assert!(refused["fc2b"].as_str().unwrap().contains("0x01 Illegal Function"), "{drive:#}");
    assert!(refused["fc11"].as_str().unwrap().contains("0x01 Illegal Function"), "{drive:#}");
    assert_eq!(drive["profile"], Value::Null);
    let slow = device(&doc, 4);
    assert!(slow["response_ms"].as_f64().unwrap() >= 200.0, "{slow:#}");
    assert_eq!(slow["profile"], "generic");
    let refusing = device(&doc, 5);
    assert_eq!(refusing["answer"]["kind"], "exception");
    assert_eq!(refusing["answer"]["exception"], 4);
    let leads = doc["leads"].as_array().unwrap();
    assert_eq!(leads.len(), 1, "{doc:#}");
    assert_eq!(leads[0]["unit"], 6);
    assert_eq!(leads[0]["settings"], "19200 8E1");
    assert_eq!(leads[0]["heard"], "a frame with a wrong CRC (address 6, function 0x03)");
    assert_eq!(leads[0]["second_pass"]["kind"], "bad-crc");
    assert_eq!(doc["other_masters"], serde_json::json!([]));
    // 8 units at 2 settings, and the lead again.
    assert_eq!(doc["probes"], 17);
}

#[test]
fn on_one_line_a_device_at_9600_is_found_in_the_9600_pass_and_one_at_19200_in_the_19200_pass() {
    let dir = tempfile_dir("baud");
    let (_line, drops) = line("19200", 3, &dir.join("stats.json"));
    let _slow = sim(&drops[1], "9600", &["--profile", "generic", "--unit", "3"]);
    let _fast = sim(&drops[2], "19200", &["--profile", "generic", "--unit", "1"]);
    let (code, doc) =
        scan(&drops[0], &["--units", "1-4", "--bauds", "19200,9600", "--framings", "8E1", "--listen", "0"]);
    assert_eq!(code, Some(0), "{doc:#}");
    assert_eq!(doc["settings"], serde_json::json!(["19200 8E1", "9600 8E1"]));
    // Each at its own setting only: at the other each hears garbage and stays silent.
    assert_eq!(devices(&doc), [(1, "19200 8E1".to_string()), (3, "9600 8E1".to_string())], "{doc:#}");
    assert_eq!(device(&doc, 1)["baud"], 19200);
    assert_eq!(device(&doc, 3)["baud"], 9600);
    assert_eq!(doc["leads"], serde_json::json!([]), "{doc:#}");
}

#[test]
fn the_settings_are_swept_19200_8e1_then_9600_8e1_then_8n1_then_the_rest() {
    let dir = tempfile_dir("order");
    let (_line, drops) = line("19200", 2, &dir.join("stats.json"));
    let (code, doc) =
        scan(&drops[0], &["--units", "1", "--bauds", "9600,19200", "--probe-timeout", "5ms", "--listen", "0"]);
    assert_eq!(code, Some(0), "{doc:#}");
    let order = ["19200 8E1", "9600 8E1", "19200 8N1", "9600 8N1", "19200 8N2", "19200 8O1", "9600 8N2", "9600 8O1"];
    assert_eq!(doc["settings"], serde_json::json!(order));
    assert_eq!(doc["probes"], 8);
    assert_eq!(devices(&doc), []);
}

#[test]
fn with_another_master_polling_listen_first_reports_it_and_its_units_and_transmits_nothing() {
    let dir = tempfile_dir("master");
    let stats = dir.join("stats.json");
    let (line, drops) = line("19200", 3, &stats);
    let mut device = sim(&drops[1], "19200", &["--profile", "generic", "--unit", "7"]);
    let _master = Proc::ferrobus(&["--port", &drops[2], "--unit", "7", "bench", "--count", "1000000"], true);
    // Wait until the other master's requests are being answered.
    loop {
        device.signal("-USR1");
        let counters = device.until("requests:");
        if !counters.starts_with("sim: 0 requests") {
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    // One format: a pty holds no parity, so at 8N1 and the rest the frames would be valid too.
    let args = ["--units", "1-247", "--bauds", "19200,9600", "--framings", "8E1", "--listen", "1s"];
    let (code, doc) = scan(&drops[0], &args);
    assert_eq!(code, Some(0), "{doc:#}");
    assert_eq!(doc["held_back"], true);
    let masters = doc["other_masters"].as_array().unwrap();
    assert_eq!(masters.len(), 1, "{doc:#}");
    assert_eq!(masters[0]["settings"], "19200 8E1");
    assert_eq!(masters[0]["units"], serde_json::json!([7]));
    assert!(masters[0]["requests"].as_u64().unwrap() > 0 && masters[0]["responses"].as_u64().unwrap() > 0);
    // At 9600 the same traffic is bytes that never frame.
    let noise = doc["noise"].as_array().unwrap();
    assert_eq!(noise.len(), 1, "{doc:#}");
    assert_eq!(noise[0]["settings"], "9600 8E1");
    assert_eq!(doc["probes"], 0);
    assert_eq!(devices(&doc), []);
    // The line's own count: the scanner's endpoint sent not one character.
    line.signal("-TERM");
    let mut line = line;
    let _ = line.child.wait();
    let stats: Value = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    let scanner = &stats["endpoints"][0];
    assert_eq!(scanner["name"], drops[0].as_str());
    assert_eq!(scanner["characters"], 0, "{stats:#}");
    assert!(stats["endpoints"][2]["characters"].as_u64().unwrap() > 0, "{stats:#}");
}

#[test]
fn interrupted_a_scan_prints_what_it_found_so_far_and_exits_130() {
    let dir = tempfile_dir("interrupt");
    let (_line, drops) = line("19200", 2, &dir.join("stats.json"));
    let _sim = sim(&drops[1], "19200", &["--profile", "generic", "--unit", "1"]);
    let mut command = Command::new("env");
    command.args(["--default-signal=INT", env!("CARGO_BIN_EXE_ferrobus"), "-v", "--port", &drops[0], "scan"]);
    command.args(["--units", "1-247", "--listen", "0", "--json"]);
    let mut scan = Proc::spawn(command, false, Stdio::piped());
    let mut stdout = scan.child.stdout.take().unwrap();
    scan.until("unit 1 answers at 19200 8E1");
    scan.signal("-INT");
    let status = scan.child.wait().unwrap();
    assert_eq!(status.code(), Some(130));
    let mut text = String::new();
    stdout.read_to_string(&mut text).unwrap();
    let doc: Value = serde_json::from_str(&text).unwrap_or_else(|e| panic!("{e}: {text}"));
    assert_eq!(doc["complete"], false);
    assert_eq!(devices(&doc), [(1, "19200 8E1".to_string())]);
}

/// A fresh directory under the target dir for one test's files.
fn tempfile_dir(name: &str) -> std::path::PathBuf {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("scan-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn with_sunspec_each_device_found_on_a_serial_line_is_walked_at_its_setting() {
    let dir = tempfile_dir("sunspec");
    let (_line, drops) = line("19200", 3, &dir.join("stats.json"));
    // Unit 3: a SunSpec inverter at 9600; unit 7: a drive that is not SunSpec, at 19200.
    let _inverter = sim(&drops[1], "9600", &["--profile", "sunspec-inverter", "--unit", "3"]);
    let _drive = sim(&drops[2], "19200", &["--profile", "omron-3g3rx", "--unit", "7"]);
    let args = ["--units", "1-8", "--bauds", "19200,9600", "--framings", "8E1", "--listen", "0", "--sunspec"];
    let (code, doc) = scan(&drops[0], &args);
    assert_eq!(code, Some(0), "{doc:#}");
    assert_eq!(devices(&doc), [(7, "19200 8E1".to_string()), (3, "9600 8E1".to_string())], "{doc:#}");
    let walks = doc["sunspec"].as_array().unwrap();
    assert_eq!(walks.len(), 2, "{doc:#}");
    let walk = |unit: u64| walks.iter().find(|w| w["unit"] == unit).unwrap();
    assert_eq!((walk(3)["setting"].as_str(), walk(3)["base"].as_u64()), (Some("9600 8E1"), Some(40000)));
    let models: Vec<(u64, u64)> = walk(3)["models"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| (m["id"].as_u64().unwrap(), m["length"].as_u64().unwrap()))
        .collect();
    assert_eq!(models, [(1, 66), (103, 50)]);
    let not = walk(7)["error"].as_str().unwrap();
    assert!(not.contains("not a SunSpec device"), "{not}");
    // The table says the same, and the CSV is a row per model.
    let table = ferrobus().args(["--port", &drops[0], "scan"]).args(args).output().unwrap();
    let table = String::from_utf8_lossy(&table.stdout);
    assert!(table.contains("unit 3 at 9600 8E1: \"SunS\" at 40000, 2 models"), "{table}");
    assert!(table.contains("unit 7 at 19200 8E1: not a SunSpec device"), "{table}");
    let csv = ferrobus().args(["--port", &drops[0], "scan", "--csv"]).args(args).output().unwrap();
    let csv = String::from_utf8_lossy(&csv.stdout);
    let rows: Vec<&str> = csv.lines().collect();
    assert_eq!(rows.len(), 3, "{csv}");
    assert!(rows[0].starts_with("unit,setting,model,name,start,length,definition"), "{csv}");
    assert!(rows[2].starts_with("3,9600 8E1,103,inverter_three_phase,40070,50,ok"), "{csv}");
}
