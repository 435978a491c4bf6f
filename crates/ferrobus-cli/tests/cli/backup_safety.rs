//! A backup a commissioning engineer can trust, against `ferrobus sim` over Modbus/TCP: an
//! incomplete backup never replaces a complete one (it goes to FILE.incomplete, the previous
//! FILE to FILE.bak), and Ctrl-C in the middle of `backup` or `restore --apply` says exactly
//! what was read, written and verified, and what was not. The simulator delays its replies so
//! that the signal lands mid-way; the test sends it when the command's `-v` log shows the
//! request it waits for, not after a sleep.

use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::process::{Command, Stdio};

use crate::backup::{TcpSim, change, temp};
use crate::server::{no_settings, stderr};

/// What an interrupted command left: its exit code, stdout and stderr.
struct Interrupted {
    code: Option<i32>,
    stdout: String,
    stderr: String,
}

/// Runs `ferrobus -v --tcp SIM --device omron-3g3rx ARGS` and sends it SIGINT once `count`
/// lines of its log contain `marker`.
fn interrupt_after(sim: &TcpSim, args: &[&str], marker: &str, count: usize) -> Interrupted {
    let mut child = Command::new("env")
        .arg("--default-signal=INT")
        .arg(env!("CARGO_BIN_EXE_ferrobus"))
        .env("XDG_CONFIG_HOME", no_settings())
        .args(["-v", "--tcp", &sim.addr, "--timeout", "5s", "--device", "omron-3g3rx"])
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut out = child.stdout.take().unwrap();
    let stdout = std::thread::spawn(move || {
        let mut text = String::new();
        out.read_to_string(&mut text).unwrap();
        text
    });
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    let mut stderr = String::new();
    let mut seen = 0;
    for line in lines.by_ref() {
        let line = line.unwrap();
        stderr.push_str(&line);
        stderr.push('\n');
        seen += usize::from(line.contains(marker));
        if seen == count {
            break;
        }
    }
    assert_eq!(seen, count, "the log never showed {count} x {marker:?}:\n{stderr}");
    let status = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(status.success());
    for line in lines {
        stderr.push_str(&line.unwrap());
        stderr.push('\n');
    }
    let code = child.wait().unwrap().code();
    Interrupted { code, stdout: stdout.join().unwrap(), stderr }
}

/// The `backup: N of M parameters` of a summary line.
fn read_of(stderr: &str) -> (usize, usize) {
    let line = stderr.lines().find(|l| l.starts_with("backup: ") && l.contains(" parameters of unit")).unwrap();
    let numbers: Vec<usize> = line.split(|c: char| !c.is_ascii_digit()).filter_map(|n| n.parse().ok()).collect();
    (numbers[0], numbers[1])
}

fn unread(path: &Path) -> usize {
    std::fs::read_to_string(path).unwrap().lines().filter(|l| l.contains("= { error = ")).count()
}

#[test]
fn an_incomplete_backup_goes_beside_a_complete_one_unless_forced_and_the_previous_is_kept_as_bak() {
    let good_sim = TcpSim::start(&["--profile", "omron-3g3rx"]);
    // Every read of holding registers refused: all but the coils fail.
    let bad_sim = TcpSim::start(&["--profile", "omron-3g3rx", "--fault", "1:fc=0x03,exception=0x04"]);
    let path = temp("kept.toml");
    let file = path.to_str().unwrap();
    let (bak, aside) = (temp("kept.toml.bak"), temp("kept.toml.incomplete"));
    for p in [&path, &bak, &aside] {
        let _ = std::fs::remove_file(p);
    }
    let first = good_sim.run("omron-3g3rx", &["backup", "-o", file]).success();
    assert!(!stderr(&first).contains(".bak"), "{}", stderr(&first));
    let good = std::fs::read_to_string(&path).unwrap();
    assert_eq!(unread(&path), 0);

    let out = bad_sim.run("omron-3g3rx", &["backup", "-o", file]).code(7);
    let err = stderr(&out);
    let (read, of) = read_of(&err);
    assert!(read < of, "{err}");
    assert_eq!(std::fs::read_to_string(&path).unwrap(), good, "the complete backup is untouched");
    assert_eq!(unread(&aside), of - read, "the new backup is kept, with why each is missing");
    assert!(
        err.contains(&format!(
            "backup: kept {file}: it holds {of} of {of} parameters, the new backup only {read} of {of}; \
             the new backup is in {} (--force replaces {file} with it)",
            aside.display()
        )),
        "{err}"
    );
    assert!(!bak.exists(), "nothing replaced, nothing to keep");

    let forced = stderr(&bad_sim.run("omron-3g3rx", &["backup", "-o", file, "--force"]).code(7));
    assert!(forced.contains(&format!("backup: the previous {file} is kept as {}", bak.display())), "{forced}");
    assert_eq!(unread(&path), of - read);
    assert_eq!(std::fs::read_to_string(&bak).unwrap(), good);

    // A complete backup replaces an incomplete one at once; the incomplete one becomes .bak.
    good_sim.run("omron-3g3rx", &["backup", "-o", file]).success();
    assert_eq!(unread(&path), 0);
    assert_eq!(unread(&bak), of - read);
    for p in [&path, &bak, &aside] {
        std::fs::remove_file(p).unwrap();
    }
}

#[test]
fn ctrl_c_during_a_backup_saves_what_was_read_beside_the_complete_file_and_names_the_rest() {
    let sim = TcpSim::start(&["--profile", "omron-3g3rx", "--fault", "1:fc=0x03,delay=200ms"]);
    let path = temp("interrupted.toml");
    let file = path.to_str().unwrap();
    let aside = temp("interrupted.toml.incomplete");
    let _ = std::fs::remove_file(&aside);
    sim.run("omron-3g3rx", &["backup", "-o", file]).success();
    let good = std::fs::read_to_string(&path).unwrap();

    let run = interrupt_after(&sim, &["backup", "-o", file], "read request", 3);
    assert_eq!(run.code, Some(130), "{}", run.stderr);
    let (read, of) = read_of(&run.stderr);
    assert!(read > 0 && read < of, "{}", run.stderr);
    let line = run.stderr.lines().find(|l| l.starts_with("backup: interrupted: ")).unwrap_or_default();
    assert!(line.starts_with(&format!("backup: interrupted: {read} of {of} parameters read; not read: ")), "{line}");
    let named = line.rsplit("not read: ").next().unwrap().split(", ").count();
    assert_eq!(named, of - read, "{line}");
    assert!(run.stderr.contains("error: interrupted"), "{}", run.stderr);
    // What was read is saved, beside the complete backup, with why the rest is missing.
    assert_eq!(std::fs::read_to_string(&path).unwrap(), good);
    let partial = std::fs::read_to_string(&aside).unwrap();
    assert_eq!(partial.matches("error = \"not read: interrupted (Ctrl-C or SIGTERM)\"").count(), of - read);
    assert!(run.stdout.is_empty(), "{}", run.stdout);
    std::fs::remove_file(&path).unwrap();
    std::fs::remove_file(&aside).unwrap();
}

#[test]
fn ctrl_c_during_restore_apply_lists_what_was_written_and_verified_and_what_was_not() {
    // Writes answer 200 ms late, so that Ctrl-C lands while one is under way.
    let sim = TcpSim::start(&[
        "--profile",
        "omron-3g3rx",
        "--fault",
        "1:fc=0x06,delay=200ms",
        "--fault",
        "1:fc=0x10,delay=200ms",
    ]);
    let path = temp("restore-interrupted.toml");
    let file = path.to_str().unwrap();
    sim.run("omron-3g3rx", &["backup", "-o", file]).success();
    // Ten parameters away from the backup's values.
    let changes = [
        ("0x1103", "1234", "u32"), // F002
        ("0x1105", "1235", "u32"), // F003
        ("0x120B", "1236", "u32"), // A011
        ("0x120D", "1237", "u32"), // A012
        ("0x120F", "11", "u16"),   // A013
        ("0x1210", "88", "u16"),   // A014
        ("0x1212", "7", "u16"),    // A016
        ("0x1216", "1238", "u32"), // A020
        ("0x1251", "1239", "u32"), // A062
        ("0x1255", "77", "u16"),   // A064
    ];
    for (number, value, kind) in changes {
        change(&sim, number, value, kind);
    }
    let dry = crate::server::stdout(&sim.run("omron-3g3rx", &["restore", file]).success());
    assert_eq!(dry.matches("would write").count(), 10, "{dry}");
    let writes_before = sim.writes();

    let run = interrupt_after(&sim, &["restore", file, "--apply"], " writing", 6);
    assert_eq!(run.code, Some(130), "{}\n{}", run.stdout, run.stderr);
    let rows: Vec<&str> = run.stdout.lines().skip(1).collect();
    assert_eq!(rows.len(), 10, "{}", run.stdout);
    let verified: Vec<&str> =
        rows.iter().filter(|r| r.ends_with("written, verified")).filter_map(|r| r.split(' ').next()).collect();
    let not_written: Vec<&str> =
        rows.iter().filter(|r| r.contains("not written: ")).filter_map(|r| r.split(' ').next()).collect();
    // Five writes were done when the sixth began; the sixth was under way (verified if the
    // device took it); nothing after it was sent.
    assert!(verified.len() == 5 || verified.len() == 6, "{}", run.stdout);
    assert_eq!(verified.len() + not_written.len(), 10, "{}", run.stdout);
    assert!(
        rows[7..].iter().all(|r| r.ends_with("not written: not attempted: the writes stopped after Ctrl-C or SIGTERM"))
    );
    let summary = format!(
        "restore: interrupted, so incomplete: written and verified: {}; written but not verified: none; not written: {}",
        verified.join(", "),
        not_written.join(", ")
    );
    assert!(run.stderr.contains(&summary), "{summary}\nnot in\n{}", run.stderr);
    // The sixth was sent before the signal came, or (on a slow machine) not yet.
    let sent = sim.writes() - writes_before;
    assert!(sent == 6 || sent == 5 && verified.len() == 5, "{sent} writes sent:\n{}", run.stdout);
    // What the report says is not written is exactly what still differs.
    let left = crate::server::stdout(&sim.run("omron-3g3rx", &["diff", file]).code(1));
    let mut differing: Vec<&str> = left.lines().skip(1).filter_map(|l| l.split(' ').next()).collect();
    let mut not_written = not_written;
    differing.sort_unstable();
    not_written.sort_unstable();
    assert_eq!(differing, not_written, "{left}");
    std::fs::remove_file(&path).unwrap();
}
