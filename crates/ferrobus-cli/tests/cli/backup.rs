//! `backup`, `diff`, `restore` against `ferrobus sim` over Modbus/TCP: the round trip, an
//! injected refusal in the middle of a restore, the dry run and the refusals that send
//! nothing (checked in the simulator's `-v` log of every request it decoded), and broken files.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use assert_cmd::assert::OutputAssertExt;
use serde_json::Value;

use crate::server::{ferrobus, stderr, stdout};

/// A `ferrobus -v sim --tcp` on a free port, with its log of requests.
pub(crate) struct TcpSim {
    child: Child,
    pub(crate) addr: String,
    log: Arc<Mutex<Vec<String>>>,
}

impl TcpSim {
    pub(crate) fn start(args: &[&str]) -> TcpSim {
        // A free port: the simulator reports the address it was given, so it cannot take :0.
        let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
        let given = format!("127.0.0.1:{port}");
        let mut child = Command::new("env")
            .arg("--default-signal=INT")
            .arg(env!("CARGO_BIN_EXE_ferrobus"))
            .args(["-v", "--tcp", &given, "sim", "--duration", "120s"])
            .args(args)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("ferrobus sim starts");
        let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
        let addr = loop {
            let line = lines.next().expect("the sim says where it listens").unwrap();
            if let Some(rest) = line.strip_prefix("sim: listening on ") {
                break rest.split_whitespace().next().unwrap().to_string();
            }
        };
        let log = Arc::new(Mutex::new(Vec::new()));
        let keep = Arc::clone(&log);
        std::thread::spawn(move || {
            for line in lines.map_while(Result::ok) {
                keep.lock().unwrap().push(line);
            }
        });
        TcpSim { child, addr, log }
    }

    /// `ferrobus --tcp ADDR --device PROFILE ARGS`.
    pub(crate) fn run(&self, device: &str, args: &[&str]) -> assert_cmd::assert::Assert {
        ferrobus().args(["--tcp", &self.addr, "--timeout", "2s", "--device", device]).args(args).assert()
    }

    /// The function codes of the requests the simulator has decoded so far. The log of a
    /// request is written before its reply, so once a command has its replies it is here.
    pub(crate) fn functions(&self) -> Vec<u8> {
        // The log thread may lag the reply by a moment.
        let deadline = Instant::now() + Duration::from_secs(5);
        let mut last = usize::MAX;
        loop {
            let now = self.log.lock().unwrap().len();
            if now == last || Instant::now() > deadline {
                break;
            }
            last = now;
            std::thread::sleep(Duration::from_millis(50));
        }
        self.log
            .lock()
            .unwrap()
            .iter()
            .filter(|l| l.contains("request: reply due"))
            .filter_map(|l| l.split("function=0x").nth(1).and_then(|f| u8::from_str_radix(f.get(..2)?, 16).ok()))
            .collect()
    }

    pub(crate) fn writes(&self) -> usize {
        self.functions().iter().filter(|f| matches!(f, 0x05 | 0x06 | 0x0F | 0x10)).count()
    }
}

impl Drop for TcpSim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

pub(crate) fn temp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("ferrobus-backup-{}-{name}", std::process::id()))
}

/// Writes through the plain `write` command (FC10, so that a fault rule on FC06 spares it).
pub(crate) fn change(sim: &TcpSim, number: &str, value: &str, kind: &str) {
    ferrobus()
        .args(["--tcp", &sim.addr, "write", "register", "--one-based", number, value, "--multiple", "--type", kind])
        .assert()
        .success();
}

/// The built-in 3G3RX profile as a file, with a run-state rule (`running`, coil 000Fh) and the
/// meaning of 22h, unless it has them already.
fn omron_with_rules(name: &str) -> PathBuf {
    let mut text =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../ferrobus-profile/profiles/omron-3g3rx.toml"))
            .unwrap();
    if !text.contains("[state]") {
        text.push_str("\n[state]\nrunning = { point = \"running\", values = [1] }\n");
    }
    if !text.contains("[[exception_meaning]]") {
        text.push_str("\n[[exception_meaning]]\ncode = 0x22\nmeaning = \"the inverter restricts execution\"\n");
    }
    let path = temp(&format!("{name}-omron.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

fn codes(table: &str) -> Vec<String> {
    table.lines().skip(1).filter_map(|l| l.split_whitespace().next().map(str::to_string)).collect()
}

#[test]
fn backup_then_changes_then_diff_shows_exactly_those_and_restore_apply_makes_diff_empty() {
    let sim = TcpSim::start(&["--profile", "omron-3g3rx"]);
    let path = temp("round-trip.toml");
    let file = path.to_str().unwrap();
    let out = sim.run("omron-3g3rx", &["backup", "-o", file]).success();
    // "backup: N of N parameters of unit 1 in R requests (the plan's R), T.t ms": all read, in the plan.
    let summary = stderr(&out);
    let numbers: Vec<u64> = summary.split(|c: char| !c.is_ascii_digit()).filter_map(|n| n.parse().ok()).collect();
    assert!(summary.starts_with("backup: "), "{summary}");
    assert!(matches!(numbers[..], [n, m, 1, r, q, _, _] if n == m && r == q && r > 0), "{summary}");
    let text = std::fs::read_to_string(&path).unwrap();
    for want in [
        "profile = \"omron-3g3rx\"\n",
        "unit = 1\n",
        &format!("connection = \"{} (Modbus/TCP)\"\n", sim.addr),
        "identification = \"none: the profile says the device has no identification (FC2B/0E, FC11)\"\n",
        "\nF002 = { raw = 1000, value = \"10.00 s\" }\n",
        "A003 = { raw = 60, value = \"60 Hz\" }\n",
    ] {
        assert!(text.contains(want), "{want:?} not in\n{text}");
    }
    assert!(text.lines().any(|l| l.starts_with("time = \"20") && l.ends_with("Z\"")), "{text}");
    // Each parameter under a comment with its label (or its description).
    let lines: Vec<&str> = text.lines().collect();
    let f002 = lines.iter().position(|l| l.starts_with("F002 = ")).unwrap();
    assert!(lines[f002 - 1].to_lowercase().starts_with("# acceleration time 1"), "{text}");
    // The same backup to stdout is the same file but for the time.
    let again = stdout(&sim.run("omron-3g3rx", &["backup"]).success());
    let untimed = |t: &str| t.lines().filter(|l| !l.starts_with("time = ")).collect::<Vec<_>>().join("\n");
    assert_eq!(untimed(&again), untimed(&text));

    change(&sim, "0x1203", "50", "u16");
    change(&sim, "0x1103", "2500", "u32");
    let diff = sim.run("omron-3g3rx", &["diff", file]).code(1);
    let table = stdout(&diff);
    assert_eq!(codes(&table), ["F002", "A003"], "{table}");
    assert!(table.lines().any(|l| l.starts_with("F002") && l.contains("10.00 s") && l.contains("25.00 s")), "{table}");
    assert!(table.lines().any(|l| l.starts_with("A003") && l.contains("60 Hz") && l.contains("50 Hz")), "{table}");
    let json: Value =
        serde_json::from_str(&stdout(&sim.run("omron-3g3rx", &["diff", file, "--json"]).code(1))).unwrap();
    assert_eq!(json["equal"], false);
    assert_eq!(json["differences"][1]["a"]["raw"], 60);
    assert_eq!(json["differences"][1]["b"]["value"], "50 Hz");

    let writes_before = sim.writes();
    let dry = sim.run("omron-3g3rx", &["restore", file]).success();
    assert_eq!(codes(&stdout(&dry)), ["F002", "A003"], "{}", stdout(&dry));
    assert!(stdout(&dry).contains("would write"), "{}", stdout(&dry));
    assert_eq!(sim.writes(), writes_before, "a dry run sends no write");

    let applied = sim.run("omron-3g3rx", &["restore", file, "--apply"]).success();
    let report = stdout(&applied);
    assert_eq!(report.matches("written, verified").count(), 2, "{report}");
    assert!(stderr(&applied).contains("restore: 2 written and verified"), "{}", stderr(&applied));
    assert_eq!(sim.writes(), writes_before + 2, "only what differs is written");
    let same = stdout(&sim.run("omron-3g3rx", &["diff", file]).success());
    assert!(same.contains(&format!("{file} and unit 1 agree on all ")), "{same}");
    std::fs::remove_file(&path).unwrap();
}

#[test]
fn a_restore_meeting_an_injected_exception_reports_exactly_what_was_and_was_not_written() {
    // A003 (register 1203h, frame 1202h) is refused with 22h when written with FC06.
    let profile = omron_with_rules("refused");
    let device = profile.to_str().unwrap();
    let sim = TcpSim::start(&["--profile", device, "--fault", "1:fc=0x06,addr=0x1202,exception=0x22"]);
    let path = temp("refused.toml");
    let file = path.to_str().unwrap();
    sim.run(device, &["backup", "-o", file]).success();
    change(&sim, "0x1203", "50", "u16");
    change(&sim, "0x1202", "1", "u16");
    change(&sim, "0x1103", "2500", "u32");
    let out = sim.run(device, &["restore", file, "--apply"]).code(7);
    let report = stdout(&out);
    let line = |code: &str| report.lines().find(|l| l.starts_with(code)).unwrap_or_default().to_string();
    assert!(line("F002").ends_with("written, verified"), "{report}");
    assert!(line("A002").ends_with("written, verified"), "{report}");
    // The device's code, with the profile's words for it.
    assert!(line("A003").contains("not written: exception 0x22 (vendor-specific): "), "{report}");
    let meaning = line("A003").rsplit("(vendor-specific): ").next().unwrap_or_default().trim().to_string();
    assert!(std::fs::read_to_string(&profile).unwrap().contains(&meaning), "{meaning:?} is not the profile's");
    let err = stderr(&out);
    assert!(
        err.contains("written and verified: F002, A002; written but not verified: none; not written: A003"),
        "{err}"
    );
    let left = stdout(&sim.run(device, &["diff", file]).code(1));
    assert_eq!(codes(&left), ["A003"], "{left}");
    std::fs::remove_file(&path).unwrap();
    std::fs::remove_file(&profile).unwrap();
}

#[test]
fn a_parameter_that_fails_to_read_is_recorded_with_the_reason_and_exit_7() {
    // Reads touching A003's frame address are refused with 02: the request of A001-A003 is
    // read again point by point, so only A003 is marked.
    let sim = TcpSim::start(&["--profile", "omron-3g3rx", "--fault", "1:fc=0x03,addr=0x1202,exception=0x02"]);
    let out = sim.run("omron-3g3rx", &["backup"]).code(7);
    let text = stdout(&out);
    assert!(text.contains("\nA002 = { raw = 3, value = "), "{text}");
    // The spec's name, and the profile's words for it if it has them.
    assert!(text.contains("A003 = { error = \"exception 0x02 Illegal Data Address"), "{text}");
    assert!(stderr(&out).contains("1 parameter could not be read (A003); the backup records why"), "{}", stderr(&out));
}

#[test]
fn a_diff_that_cannot_read_a_parameter_exits_7_and_a_backup_that_cannot_be_written_exits_6() {
    let sim = TcpSim::start(&["--profile", "omron-3g3rx", "--fault", "1:fc=0x03,addr=0x1202,exception=0x02"]);
    let path = temp("unread.toml");
    let file = path.to_str().unwrap();
    // The backup records A003 as unread; a restore of it leaves A003 alone and says so.
    sim.run("omron-3g3rx", &["backup", "-o", file]).code(7);
    let out = sim.run("omron-3g3rx", &["diff", file]).code(7);
    assert!(
        stdout(&out).lines().any(|l| l.starts_with("A003") && l.contains("(not read: exception 0x02")),
        "{}",
        stdout(&out)
    );
    assert!(stderr(&out).contains("1 parameter could not be read from unit 1"), "{}", stderr(&out));
    let restore = sim.run("omron-3g3rx", &["restore", file]).success();
    assert!(stderr(&restore).contains("A003: the backup holds no value"), "{}", stderr(&restore));
    let err = stderr(&sim.run("omron-3g3rx", &["backup", "-o", "/nonexistent/dir/drive.toml"]).code(6));
    assert!(err.contains("cannot write /nonexistent/dir/drive.toml"), "{err}");
    std::fs::remove_file(&path).unwrap();
}

#[test]
fn an_out_of_range_value_in_the_file_is_refused_with_its_line_before_anything_is_sent() {
    let sim = TcpSim::start(&["--profile", "omron-3g3rx"]);
    let path = temp("range.toml");
    let file = path.to_str().unwrap();
    sim.run("omron-3g3rx", &["backup", "-o", file]).success();
    let text = std::fs::read_to_string(&path).unwrap().replace("A003 = { raw = 60,", "A003 = { raw = 500,");
    std::fs::write(&path, &text).unwrap();
    let line = text.lines().position(|l| l.starts_with("A003")).unwrap() + 1;
    let sent = sim.functions().len();
    let err = stderr(&sim.run("omron-3g3rx", &["restore", file, "--apply"]).code(2));
    assert!(err.contains(&format!("{file}:{line}: A003: 500 Hz is out of range: 30 Hz to 400 Hz")), "{err}");
    assert!(err.contains("nothing was sent"), "{err}");
    assert_eq!(sim.functions().len(), sent, "no request at all");
    std::fs::remove_file(&path).unwrap();
}

#[test]
fn a_run_locked_parameter_is_refused_while_the_drive_runs_and_nothing_is_written() {
    let profile = omron_with_rules("running");
    let device = profile.to_str().unwrap();
    let sim = TcpSim::start(&["--profile", device]);
    let path = temp("running.toml");
    let file = path.to_str().unwrap();
    // F001 = 10 Hz, so that the run command makes the drive run.
    change(&sim, "0x0001", "1000", "u32");
    sim.run(device, &["backup", "-o", file]).success();
    change(&sim, "0x1203", "50", "u16");
    ferrobus().args(["--tcp", &sim.addr, "write", "coil", "--one-based", "1", "on"]).assert().success();
    // The drive runs once its output frequency leaves 0: coil 000Fh says so.
    let deadline = Instant::now() + Duration::from_secs(10);
    while !stdout(&ferrobus().args(["--tcp", &sim.addr, "read", "coils", "--one-based", "0x000F"]).assert().success())
        .contains(" ON")
    {
        assert!(Instant::now() < deadline, "the drive never ran");
        std::thread::sleep(Duration::from_millis(20));
    }
    let writes = sim.writes();
    let dry = stderr(&sim.run(device, &["restore", file]).success());
    assert!(dry.contains(&format!("note: --apply would refuse now: {}", crate::guard::REFUSAL)), "{dry}");
    let err = stderr(&sim.run(device, &["restore", file, "--apply"]).code(7));
    assert!(err.contains(&format!("{}; nothing was written", crate::guard::REFUSAL)), "{err}");
    assert_eq!(sim.writes(), writes);
    std::fs::remove_file(&path).unwrap();
    std::fs::remove_file(&profile).unwrap();
}

#[test]
fn a_file_of_another_profile_is_refused_unless_forced() {
    let sim = TcpSim::start(&["--profile", "omron-3g3rx"]);
    let path = temp("other.toml");
    let file = path.to_str().unwrap();
    sim.run("omron-3g3rx", &["backup", "-o", file]).success();
    let text = std::fs::read_to_string(&path).unwrap().replace("profile = \"omron-3g3rx\"", "profile = \"sdp-servo\"");
    std::fs::write(&path, text).unwrap();
    let err = stderr(&sim.run("omron-3g3rx", &["restore", file]).code(2));
    assert!(err.contains("was made with profile sdp-servo, not --device omron-3g3rx: refusing"), "{err}");
    let forced = stdout(&sim.run("omron-3g3rx", &["restore", file, "--force"]).success());
    assert!(forced.contains("nothing to write"), "{forced}");
    std::fs::remove_file(&path).unwrap();
}

#[test]
fn two_files_are_compared_offline_and_a_broken_one_is_named_with_its_line() {
    let sim = TcpSim::start(&["--profile", "omron-3g3rx"]);
    let (a, b) = (temp("a.toml"), temp("b.toml"));
    sim.run("omron-3g3rx", &["backup", "-o", a.to_str().unwrap()]).success();
    change(&sim, "0x1105", "1500", "u32");
    sim.run("omron-3g3rx", &["backup", "-o", b.to_str().unwrap()]).success();
    drop(sim);
    let out = ferrobus().args(["diff", a.to_str().unwrap(), b.to_str().unwrap()]).assert().code(1);
    let table = stdout(&out);
    assert_eq!(codes(&table), ["F003"], "{table}");
    assert!(table.contains("10.00 s") && table.contains("15.00 s"), "{table}");
    let same = ferrobus().args(["diff", a.to_str().unwrap(), a.to_str().unwrap()]).assert().success();
    assert!(stdout(&same).contains(" agree on all "), "{}", stdout(&same));

    let text = std::fs::read_to_string(&b).unwrap().replace("F003 = { raw = 1500,", "F003 = { raw = ,");
    std::fs::write(&b, &text).unwrap();
    let line = text.lines().position(|l| l.starts_with("F003")).unwrap() + 1;
    let err = stderr(&ferrobus().args(["diff", a.to_str().unwrap(), b.to_str().unwrap()]).assert().code(2));
    assert!(err.contains(&format!("{}:{line}: not a backup file", b.display())), "{err}");
    let missing = stderr(&ferrobus().args(["diff", "/nonexistent/x.toml", a.to_str().unwrap()]).assert().code(2));
    assert!(missing.contains("cannot read /nonexistent/x.toml"), "{missing}");
    for p in [a, b] {
        std::fs::remove_file(p).unwrap();
    }
}

#[test]
fn backup_without_a_device_profile_says_what_it_needs() {
    let err = stderr(&ferrobus().args(["--tcp", "127.0.0.1:1", "backup"]).assert().code(2));
    assert!(err.contains("backup needs the device's profile: --device NAME"), "{err}");
}
