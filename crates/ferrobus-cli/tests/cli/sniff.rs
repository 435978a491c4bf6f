//! `ferrobus sniff` on the tap of a `ferrobus line`: a session of every public function code,
//! exceptions, a broadcast and a frame with a bad CRC, sniffed without a byte sent; tshark
//! decodes the pcapng with the documented command and agrees with sniff's own decode, frame by
//! frame; the filters, and `--pcap -` streamed into `tshark -i -` while the sniffer runs.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use assert_cmd::assert::OutputAssertExt;
use serde_json::Value;

use crate::server::{ferrobus, stderr};

/// Kills the child it holds when dropped.
pub(crate) struct Running(pub(crate) Child);

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

impl Running {
    /// SIGTERM, its normal end, then its exit status.
    pub(crate) fn stop(&mut self) -> std::process::ExitStatus {
        let pid = self.0.id().to_string();
        assert!(Command::new("kill").args(["-TERM", &pid]).status().unwrap().success());
        self.0.wait().unwrap()
    }
}

/// Lines of a child's stream, as they come.
pub(crate) fn lines(stream: impl std::io::Read + Send + 'static) -> mpsc::Receiver<String> {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stream).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                return;
            }
        }
    });
    rx
}

/// Waits (at most 10 s a line) for `n` lines, or for one containing `until`.
pub(crate) fn wait_for(rx: &mpsc::Receiver<String>, n: usize, until: &str, what: &str) -> Vec<String> {
    let mut got = Vec::new();
    while got.len() < n && (until.is_empty() || !got.iter().any(|l: &String| l.contains(until))) {
        match rx.recv_timeout(Duration::from_secs(10)) {
            Ok(line) => got.push(line),
            Err(e) => panic!("{what} said only {got:#?} ({e})"),
        }
    }
    got
}

/// A line with a tap and a simulated drive on its second drop; returns the master's drop
/// and the tap.
pub(crate) struct Bus {
    line: Running,
    _sim: Running,
    pub(crate) master: String,
    pub(crate) tap: String,
    stats: PathBuf,
}

impl Bus {
    /// Stops the line (SIGTERM) and returns the statistics it wrote.
    fn stop(&mut self) -> Value {
        assert!(self.line.stop().success());
        let text = std::fs::read_to_string(&self.stats).unwrap();
        serde_json::from_str(&text).unwrap_or_else(|e| panic!("{e}: {text}"))
    }
}

impl Drop for Bus {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.stats);
    }
}

/// A line with a tap and a simulated generic drive.
fn bus() -> Bus {
    bus_of("generic")
}

/// A line with a tap and a drive simulated from `profile`.
pub(crate) fn bus_of(profile: &str) -> Bus {
    static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let stats = temp(&format!("line-{}.json", NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)));
    let mut line = ferrobus();
    line.args(["line", "--tap", "--stats-json"]).arg(&stats);
    line.stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::null());
    let mut line = Running(line.spawn().unwrap());
    let paths = wait_for(&lines(line.0.stdout.take().unwrap()), 3, "", "ferrobus line --tap");
    let mut sim = ferrobus();
    sim.args(["--port", &paths[1], "sim", "--profile", profile]);
    let mut sim = Running(sim.stdin(Stdio::null()).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap());
    let said = lines(sim.0.stderr.take().unwrap());
    wait_for(&said, usize::MAX, "serving on", "ferrobus sim");
    Bus { line, _sim: sim, master: paths[0].clone(), tap: paths[2].clone(), stats }
}

/// Starts `ferrobus --port TAP sniff ARGS` and waits until it listens.
pub(crate) fn sniff(tap: &str, args: &[&str], stdout: Stdio) -> (Running, mpsc::Receiver<String>) {
    let mut command = ferrobus();
    command.args(["--port", tap, "sniff"]).args(args).stdin(Stdio::null()).stdout(stdout).stderr(Stdio::piped());
    let mut child = Running(command.spawn().unwrap());
    let said = lines(child.0.stderr.take().unwrap());
    wait_for(&said, usize::MAX, "listening on", "ferrobus sniff");
    (child, said)
}

/// Sends `pdu` (hex) to `unit` through `ferrobus raw`; an exception is an answer too.
fn raw(master: &str, unit: &str, pdu: &str) {
    let mut args = vec!["--port", master, "--unit", unit, "--timeout", "500ms", "raw"];
    args.extend(pdu.split(' '));
    let out = ferrobus().args(&args).assert();
    let code = out.get_output().status.code();
    assert!(matches!(code, Some(0 | 1)), "raw {pdu}: {code:?} {}", stderr(&out));
}

/// Every public function code (0x07, 0x0B, 0x0C and 0x11 have 4-byte requests), two
/// exceptions (a quantity of 0, a FIFO the drive does not have), a broadcast.
const SESSION: [(&str, &str); 22] = [
    ("1", "01 00 00 00 0A"),
    ("1", "02 00 00 00 08"),
    ("1", "03 00 00 00 03"),
    ("1", "04 00 00 00 02"),
    ("1", "05 00 03 FF 00"),
    ("1", "06 00 05 04 D2"),
    ("1", "07"),
    ("1", "08 00 00 12 34"),
    ("1", "0B"),
    ("1", "0C"),
    ("1", "0F 00 00 00 04 01 05"),
    ("1", "10 00 0A 00 02 04 00 01 00 02"),
    ("1", "11"),
    ("1", "14 07 06 00 01 00 00 00 02"),
    ("1", "15 0B 06 00 01 00 00 00 02 00 2A 00 2B"),
    ("1", "16 00 04 00 F2 00 25"),
    ("1", "17 00 00 00 02 00 10 00 01 02 00 07"),
    ("1", "18 00 00"),
    ("1", "2B 0E 01 00"),
    ("1", "03 00 00 00 00"),
    ("0", "06 00 05 00 07"),
    ("1", "03 00 01 00 01"),
];

/// `01 06 00 05 12 34` with its CRC (0xBC94, `94 BC` on the wire) broken: the drive stays
/// silent.
const BAD_CRC: [u8; 8] = [0x01, 0x06, 0x00, 0x05, 0x12, 0x34, 0x94, 0xBC ^ 0x5A];

/// Writes the frame with the bad CRC on the master's drop, as a UART at 19200 would.
fn write_bad_crc(master: &str) {
    let port = serial2::SerialPort::open(master, 19_200).unwrap();
    port.write_all(&BAD_CRC).unwrap();
    // Let it reach the line (it crosses it in 4.6 ms at 19200) before the port closes.
    std::thread::sleep(Duration::from_millis(50));
}

/// tshark, or `None` outside CI when it is not installed (under CI=true that is a failure).
fn tshark(test: &str) -> Option<&'static str> {
    if Command::new("tshark").arg("--version").stdout(Stdio::null()).stderr(Stdio::null()).status().is_ok() {
        return Some("tshark");
    }
    let ci = matches!(std::env::var("CI").as_deref(), Ok("true" | "TRUE" | "True" | "1" | "yes"));
    assert!(!ci, "{test}: tshark is missing; .ci/setup-peers.sh installs it (CI=true: a missing peer is a failure)");
    eprintln!("skipped: {test}: tshark is not installed (apt-get install tshark, or .ci/setup-peers.sh)");
    None
}

/// The documented command (plus the preference that decodes broadcasts), as fields.
const FIELDS: [&str; 14] = [
    "mbrtu.unit_id",
    "modbus.func_code",
    "modbus.reference_num",
    "modbus.word_cnt",
    "modbus.bit_cnt",
    "modbus.read_reference_num",
    "modbus.read_word_cnt",
    "mbrtu.crc16.status",
    "modbus.exception_code",
    "frame.comment",
    "_ws.col.Info",
    "frame.time_epoch",
    "frame.packet_flags_direction",
    "modbus.response_time",
];

fn tshark_fields(tshark: &str, capture: &Path) -> Vec<Vec<String>> {
    let mut command = Command::new(tshark);
    command.arg("-r").arg(capture);
    command.args(["-o", "mbrtu.crc_verification:TRUE", "-o", "mbrtu.tcp.port:5020", "-o", "mbrtu.udp.port:5020"]);
    command.args(["-T", "fields", "-E", "separator=|", "-E", "occurrence=f"]);
    for field in FIELDS {
        command.args(["-e", field]);
    }
    let out = command.output().unwrap();
    assert!(out.status.success(), "tshark: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).lines().map(|l| l.split('|').map(str::to_string).collect()).collect()
}

pub(crate) fn temp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("ferrobus-sniff-{}-{name}", std::process::id()))
}

fn json_lines(text: &str) -> Vec<Value> {
    text.lines().map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}"))).collect()
}

#[test]
fn tshark_decodes_the_pcapng_of_every_function_code_exceptions_a_broadcast_and_a_bad_crc_as_sniff_does() {
    let Some(tshark) = tshark("sniff vs tshark") else { return };
    let mut bus = bus();
    let capture = temp("session.pcapng");
    let capture_arg = capture.to_str().unwrap();
    let (mut sniffer, _said) = sniff(&bus.tap, &["--json", "--pcap", capture_arg], Stdio::piped());
    let decoded = lines(sniffer.0.stdout.take().unwrap());
    for (unit, pdu) in &SESSION[..SESSION.len() - 1] {
        raw(&bus.master, unit, pdu);
    }
    write_bad_crc(&bus.master);
    // The next request only once the bad frame has been seen: they cannot run together.
    let mut seen = wait_for(&decoded, usize::MAX, "\"crc_ok\":false", "ferrobus sniff");
    let (unit, pdu) = SESSION[SESSION.len() - 1];
    raw(&bus.master, unit, pdu);
    // Stop only once sniff has shown the last reply: the master has it as soon as its bytes
    // are in, the sniffer a silence later, and a loaded machine can put SIGTERM in between.
    seen.extend(wait_for(&decoded, usize::MAX, "\"bytes\":\"01 03 02 ", "ferrobus sniff"));
    assert!(sniffer.stop().success(), "sniff ends well on SIGTERM");
    seen.extend(decoded.iter());
    let docs: Vec<Value> = json_lines(&seen.join("\n"));
    let frames: Vec<&Value> = docs.iter().filter(|d| d["type"] == "frame").collect();
    // 21 requests to unit 1 and their responses, one broadcast, one bad CRC.
    assert_eq!(frames.len(), 21 * 2 + 1 + 1, "{docs:#?}");
    assert!(!docs.iter().any(|d| d["type"] == "noise" || d["type"] == "partial"), "{docs:#?}");
    let rows = tshark_fields(tshark, &capture);
    assert_eq!(rows.len(), frames.len(), "one packet per frame: {rows:#?}");
    let mut timed = 0;
    for (i, (row, doc)) in rows.iter().zip(&frames).enumerate() {
        let at = format!("frame {}: tshark {row:?}, sniff {doc}", i + 1);
        let field = |name: &str| row[FIELDS.iter().position(|f| *f == name).unwrap()].as_str();
        let num = |name: &str| field(name).parse::<u64>().ok();
        // Nanosecond timestamps (if_tsresol 9): tshark reads sniff's instant to the nanosecond.
        let ts = doc["ts_ns"].as_u64().unwrap();
        assert_eq!(field("frame.time_epoch"), format!("{}.{:09}", ts / 1_000_000_000, ts % 1_000_000_000), "{at}");
        // The direction in epb_flags: a request outbound (2), a response inbound (1).
        let direction = if doc["role"] == "request" { "0x00000002" } else { "0x00000001" };
        assert_eq!(field("frame.packet_flags_direction"), direction, "{at}");
        let bytes = doc["bytes"].as_str().unwrap().split(' ').count();
        if bytes < 5 {
            // tshark 4.0's RTU dissector takes no frame under 5 bytes (the requests of 0x07,
            // 0x0B, 0x0C, 0x11): it leaves them undecoded.
            assert_eq!(field("mbrtu.unit_id"), "", "{at}");
            continue;
        }
        assert_eq!(num("mbrtu.unit_id"), doc["unit"].as_u64(), "{at}");
        assert_eq!(num("modbus.func_code"), doc["function"].as_u64(), "{at}");
        assert_eq!(field("mbrtu.crc16.status"), if doc["crc_ok"] == true { "1" } else { "0" }, "{at}");
        let role = if field("_ws.col.Info").trim_start().starts_with("Query") { "request" } else { "response" };
        assert_eq!(role, doc["role"], "{at}");
        assert_eq!(num("modbus.exception_code"), doc["exception"].as_u64(), "{at}");
        // Where tshark paired the response too, both say the same time (sniff's in µs).
        if let Ok(seconds) = field("modbus.response_time").parse::<f64>() {
            let ms = doc["response_time_ms"].as_f64().unwrap_or(f64::NAN);
            assert!((seconds * 1e3 - ms).abs() < 0.001, "{at}");
            timed += 1;
        }
        let reference = num("modbus.reference_num").or(num("modbus.read_reference_num"));
        let count = num("modbus.word_cnt").or(num("modbus.bit_cnt")).or(num("modbus.read_word_cnt"));
        if doc.get("malformed").is_some() {
            // A quantity of 0: tshark shows the fields, sniff says why the PDU is not one.
            assert_eq!((reference, count), (Some(0), Some(0)), "{at}");
            continue;
        }
        assert_eq!(reference, doc["address"].as_u64(), "{at}");
        assert_eq!(count, doc["count"].as_u64(), "{at}");
    }
    // Every response tshark times: not those to the 4-byte requests it does not decode (4),
    // nor the exceptions (2), which it does not time.
    assert_eq!(timed, 21 - 4 - 2, "responses whose time tshark and sniff both gave");
    // The frame with the bad CRC: a request, marked bad, its comment saying what it should be.
    let bad = frames.iter().position(|d| d["crc_ok"] == false).unwrap();
    assert_eq!(frames[bad]["bytes"], "01 06 00 05 12 34 94 E6");
    assert_eq!(frames[bad]["role"], "request");
    assert!(rows[bad][9].starts_with("CRC error: 0xe694, should be 0xbc94"), "{:?}", rows[bad]);
    // The broadcast: a request to unit 0 that waits for nothing.
    let broadcast = frames.iter().find(|d| d["unit"] == 0).unwrap();
    assert_eq!((broadcast["role"].as_str(), broadcast["broadcast"].as_bool()), (Some("request"), Some(true)));
    // Every response is paired, with a response time; the sniffer is the tap: it sent nothing.
    for response in frames.iter().filter(|d| d["role"] == "response") {
        assert!(response["response_time_ms"].as_f64().is_some_and(|t| t > 0.0), "{response}");
    }
    let stats = docs.iter().find(|d| d["type"] == "stats").unwrap();
    let unit1 = stats["units"].as_array().unwrap().iter().find(|u| u["unit"] == 1).unwrap();
    assert_eq!((unit1["requests"].as_u64(), unit1["responses"].as_u64()), (Some(22), Some(21)), "{unit1}");
    assert_eq!((unit1["exceptions"].as_u64(), unit1["crc_errors"].as_u64()), (Some(2), Some(1)), "{unit1}");
    let _ = std::fs::remove_file(&capture);
    // The sniffer transmitted nothing: the tap was given no byte to send.
    let line = bus.stop();
    let tap = &line["endpoints"][2];
    assert_eq!(
        (&tap["tap"], &tap["refused"], &tap["characters"]),
        (&Value::Bool(true), &0.into(), &0.into()),
        "{line}"
    );
}

#[test]
fn the_unit_and_function_filters_keep_only_their_frames_and_count_only_them() {
    let bus = bus();
    let (mut sniffer, _said) = sniff(&bus.tap, &["--unit", "1", "--function", "6", "--json"], Stdio::piped());
    let decoded = lines(sniffer.0.stdout.take().unwrap());
    raw(&bus.master, "1", "03 00 00 00 01");
    raw(&bus.master, "1", "06 00 05 04 D2");
    raw(&bus.master, "0", "06 00 05 00 07");
    assert!(sniffer.stop().success());
    let docs = json_lines(&decoded.iter().collect::<Vec<_>>().join("\n"));
    let frames: Vec<(String, u64, u64)> = docs
        .iter()
        .filter(|d| d["type"] == "frame")
        .map(|d| {
            (d["role"].as_str().unwrap().to_string(), d["unit"].as_u64().unwrap(), d["function"].as_u64().unwrap())
        })
        .collect();
    assert_eq!(frames, [("request".to_string(), 1, 6), ("response".to_string(), 1, 6)]);
    let stats = docs.last().unwrap();
    assert_eq!(stats["type"], "stats");
    assert_eq!(stats["units"].as_array().unwrap().len(), 1, "{stats}");
}

#[test]
fn a_table_line_shows_time_silence_role_unit_function_crc_and_response_time() {
    let bus = bus();
    let (mut sniffer, _said) = sniff(&bus.tap, &[], Stdio::piped());
    let decoded = lines(sniffer.0.stdout.take().unwrap());
    raw(&bus.master, "1", "03 00 00 00 01");
    raw(&bus.master, "1", "03 00 00 00 00");
    assert!(sniffer.stop().success());
    let text: Vec<String> = decoded.iter().collect();
    let frame_lines: Vec<&String> = text.iter().filter(|l| l.contains("0x03 Read Holding Registers")).collect();
    assert_eq!(frame_lines.len(), 4, "{text:#?}");
    assert!(frame_lines[0].contains("req  u1") && frame_lines[0].contains("CRC ok"), "{}", frame_lines[0]);
    assert!(frame_lines[1].contains("resp u1") && frame_lines[1].contains(" ms "), "{}", frame_lines[1]);
    assert!(frame_lines[2].contains("(malformed: "), "{}", frame_lines[2]);
    assert!(frame_lines[3].contains("Exception(ExceptionResponse"), "{}", frame_lines[3]);
    // "   4.2ch": the silence before the reply, in characters.
    assert!(frame_lines[1].split_whitespace().nth(1).is_some_and(|s| s.ends_with("ch")), "{}", frame_lines[1]);
    assert!(text.iter().any(|l| l.starts_with("unit  requests  responses")), "the statistics: {text:#?}");
}

#[test]
fn pcap_to_stdout_reaches_tshark_reading_a_pipe_frame_by_frame_while_sniff_runs() {
    let Some(tshark) = tshark("sniff --pcap - | tshark -i -") else { return };
    let bus = bus();
    let (mut sniffer, said) = sniff(&bus.tap, &["--pcap", "-"], Stdio::piped());
    let pipe = sniffer.0.stdout.take().unwrap();
    let mut reader = Command::new(tshark);
    reader.args(["-l", "-i", "-", "-o", "mbrtu.crc_verification:TRUE", "-o", "mbrtu.tcp.port:5020"]);
    reader.args(["-T", "fields", "-e", "mbrtu.unit_id", "-e", "modbus.func_code", "-e", "_ws.col.Info"]);
    let mut reader = Running(reader.stdin(pipe).stdout(Stdio::piped()).stderr(Stdio::null()).spawn().unwrap());
    let live = lines(reader.0.stdout.take().unwrap());
    raw(&bus.master, "1", "06 00 05 04 D2");
    // Both frames reach tshark while the sniffer still runs: it flushed each.
    let got = wait_for(&live, 2, "", "tshark -i -");
    assert!(got[0].contains("Query") && got[1].contains("Response"), "{got:#?}");
    assert!(got.iter().all(|l| l.starts_with("1\t6\t")), "{got:#?}");
    assert!(sniffer.stop().success());
    // The statistics went to stderr, out of the capture's way.
    let rest = wait_for(&said, usize::MAX, "partial frames", "ferrobus sniff");
    assert!(rest.iter().any(|l| l.starts_with("unit  requests")), "{rest:#?}");
}

#[test]
fn sniff_refuses_what_it_cannot_listen_to() {
    let tcp = ferrobus().args(["--tcp", "127.0.0.1:1", "sniff"]).assert().code(2);
    assert!(stderr(&tcp).contains("--tcp is not used by `sniff`"), "{}", stderr(&tcp));
    let timeout = ferrobus().args(["--port", "/dev/null", "--timeout", "2s", "sniff"]).assert().code(2);
    assert!(stderr(&timeout).contains("--timeout is not used by `sniff`"), "{}", stderr(&timeout));
    let missing = ferrobus().args(["--port", "/dev/ferrobus-no-such-port", "sniff"]).assert().code(4);
    assert!(stderr(&missing).contains("/dev/ferrobus-no-such-port"), "{}", stderr(&missing));
    let both = ferrobus().args(["--port", "/dev/null", "sniff", "--pcap", "-", "--json"]).assert().code(2);
    assert!(stderr(&both).contains("--json has nowhere to go"), "{}", stderr(&both));
}

#[test]
fn noise_a_frame_cut_short_and_an_unanswered_request_are_shown_as_such_and_noise_is_captured_as_data() {
    let bus = bus();
    let capture = temp("noise.pcapng");
    let (mut sniffer, _said) = sniff(&bus.tap, &["--json", "--pcap", capture.to_str().unwrap()], Stdio::piped());
    let decoded = lines(sniffer.0.stdout.take().unwrap());
    // Noise; then a read cut after 5 of its 8 bytes. Each is written once the sniffer has
    // reported what came before, so that the line cannot carry them back to back.
    let port = serial2::SerialPort::open(&bus.master, 19_200).unwrap();
    port.write_all(&[0xFF, 0xFF, 0x00]).unwrap();
    let mut seen = wait_for(&decoded, usize::MAX, "\"noise\"", "ferrobus sniff");
    port.write_all(&[0x01, 0x03, 0x00, 0x00, 0x00]).unwrap();
    seen.extend(wait_for(&decoded, usize::MAX, "\"partial\"", "ferrobus sniff"));
    drop(port);
    // Unit 9 is not on the line: its request is unanswered when the next one comes.
    let nobody = ["--port", &bus.master, "--unit", "9", "--timeout", "100ms", "raw", "03", "00", "00", "00", "01"];
    assert_eq!(ferrobus().args(nobody).assert().get_output().status.code(), Some(3));
    raw(&bus.master, "1", "03 00 00 00 01");
    // Stopped once the reply is reported: the reply's bytes may still be on their way to the
    // tap when `raw` has it (what the sniffer had read when stopped is its unit tests' case).
    seen.extend(wait_for(&decoded, usize::MAX, "\"response\"", "ferrobus sniff"));
    assert!(sniffer.stop().success());
    seen.extend(decoded.iter());
    let docs = json_lines(&seen.join("\n"));
    let kinds: Vec<&str> = docs.iter().map(|d| d["type"].as_str().unwrap()).collect();
    assert_eq!(kinds, ["noise", "partial", "frame", "unanswered", "frame", "frame", "stats"], "{docs:#?}");
    assert_eq!(docs[0]["bytes"], "FF FF 00");
    assert_eq!((docs[1]["bytes"].as_str(), docs[1]["expected_len"].as_u64()), (Some("01 03 00 00 00"), Some(8)));
    assert_eq!((docs[3]["unit"].as_u64(), docs[3]["function"].as_u64()), (Some(9), Some(3)));
    let stats = &docs[6];
    assert_eq!((stats["partial_frames"].as_u64(), stats["noise_runs"].as_u64()), (Some(1), Some(1)), "{stats}");
    let unit9 = stats["units"].as_array().unwrap().iter().find(|u| u["unit"] == 9).unwrap();
    assert_eq!(unit9["unanswered"], 1, "{unit9}");
    if let Some(tshark) = tshark("sniff noise vs tshark") {
        let rows = tshark_fields(tshark, &capture);
        assert_eq!(rows.len(), 5, "{rows:#?}");
        assert!(rows[0][9].starts_with("noise: 3 bytes") && rows[0][0].is_empty(), "{:?}", rows[0]);
        assert!(rows[1][9].starts_with("partial frame: 5 of 8 bytes"), "{:?}", rows[1]);
    }
    let _ = std::fs::remove_file(&capture);
}

#[test]
fn bytes_waiting_on_the_tap_before_sniff_opened_it_are_dropped_and_said_not_counted_as_noise() {
    let bus = bus();
    // Noise on the line while nobody listens on the tap: it waits in the tap's buffer.
    let port = serial2::SerialPort::open(&bus.master, 19_200).unwrap();
    port.write_all(&[0xFF, 0xFF, 0x00]).unwrap();
    drop(port);
    std::thread::sleep(Duration::from_millis(100)); // for the line to pass it on; not timed
    let (mut sniffer, said) = sniff(&bus.tap, &["--json"], Stdio::piped());
    let decoded = lines(sniffer.0.stdout.take().unwrap());
    let note = wait_for(&said, usize::MAX, "dropped", "ferrobus sniff");
    // How many of the three the line passed on to the tap is the line's business; all of
    // them predate the capture.
    assert!(
        note.iter().any(|l| l.starts_with("sniff: dropped ")
            && l.ends_with(" bytes that were waiting in the port before the capture began")),
        "{note:#?}"
    );
    raw(&bus.master, "1", "03 00 00 00 01");
    wait_for(&decoded, 2, "", "ferrobus sniff");
    assert!(sniffer.stop().success());
    let docs = json_lines(&decoded.iter().collect::<Vec<_>>().join("\n"));
    let stats = docs.iter().find(|d| d["type"] == "stats").unwrap();
    assert_eq!(stats["noise_runs"].as_u64(), Some(0), "{stats}");
}
