//! A full or closed stderr never makes the binary panic (exit 101): every write to stderr is
//! checked. A command that succeeded but could not write its notes or its log ends with the
//! output error's code, 6; a command that failed keeps its own code.

use std::fs::File;
use std::process::{Command, Output, Stdio};

use crate::backup::TcpSim;
use crate::server::no_settings;

/// Runs the binary with stderr on /dev/full.
fn with_full_stderr(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ferrobus"))
        .env("XDG_CONFIG_HOME", no_settings())
        .args(args)
        .stdout(Stdio::piped())
        .stderr(File::options().write(true).open("/dev/full").unwrap())
        .output()
        .unwrap()
}

/// Runs the binary with stderr closed (`2>&-`).
fn with_closed_stderr(args: &[&str]) -> Output {
    Command::new("sh")
        .args(["-c", "exec \"$0\" \"$@\" 2>&-", env!("CARGO_BIN_EXE_ferrobus")])
        .env("XDG_CONFIG_HOME", no_settings())
        .args(args)
        .stdout(Stdio::piped())
        .output()
        .unwrap()
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn a_full_stderr_keeps_a_failures_exit_code_and_turns_a_success_with_notes_or_a_log_into_exit_6() {
    let sim = TcpSim::start(&["--profile", "omron-3g3rx"]);
    // A usage error: its report cannot be written, its code stands.
    let unknown = with_full_stderr(&["--tcp", &sim.addr, "--device", "omron-3g3rx", "get", "no-such-parameter"]);
    assert_eq!(unknown.status.code(), Some(2));
    // A profile with mistakes: they cannot be listed, the file is still refused as a usage error.
    let bad = std::env::temp_dir().join(format!("ferrobus-cli-full-stderr-{}.toml", std::process::id()));
    std::fs::write(&bad, "[device]\nname = 3\n").unwrap();
    let checked = with_full_stderr(&["profile", "check", bad.to_str().unwrap()]);
    std::fs::remove_file(&bad).unwrap();
    assert_eq!(checked.status.code(), Some(2), "{}", text(&checked.stdout));
    // A success that writes nothing to stderr is a success.
    let quiet = with_full_stderr(&["--tcp", &sim.addr, "--device", "omron-3g3rx", "get", "F002"]);
    assert_eq!(quiet.status.code(), Some(0));
    assert!(text(&quiet.stdout).contains("10.00 s"), "{}", text(&quiet.stdout));
    // backup's summary goes to stderr: the backup is on stdout, and the lost summary is exit 6.
    let noted = with_full_stderr(&["--tcp", &sim.addr, "--device", "omron-3g3rx", "backup"]);
    assert_eq!(noted.status.code(), Some(6));
    assert!(text(&noted.stdout).contains("F002 = { raw = 1000, value = \"10.00 s\" }"), "{}", text(&noted.stdout));
    // The log (-v) is written through the same check.
    let logged = with_full_stderr(&["-v", "--tcp", &sim.addr, "--device", "omron-3g3rx", "get", "F002"]);
    assert_eq!(logged.status.code(), Some(6));
    assert!(text(&logged.stdout).contains("10.00 s"));
}

#[test]
fn a_closed_stderr_is_as_if_it_were_dev_null_and_each_outcome_keeps_its_exit_code() {
    let sim = TcpSim::start(&["--profile", "omron-3g3rx"]);
    let ok = with_closed_stderr(&["-v", "--tcp", &sim.addr, "--device", "omron-3g3rx", "backup"]);
    assert_eq!(ok.status.code(), Some(0));
    assert!(text(&ok.stdout).contains("F002 = { raw = 1000, value = \"10.00 s\" }"), "{}", text(&ok.stdout));
    let unknown = with_closed_stderr(&["--tcp", &sim.addr, "--device", "omron-3g3rx", "get", "no-such-parameter"]);
    assert_eq!(unknown.status.code(), Some(2));
    // No reply: the connection refused is exit 4, not a panic when its report is written.
    let refused = with_closed_stderr(&["--tcp", "127.0.0.1:1", "--device", "omron-3g3rx", "get", "F002"]);
    assert_eq!(refused.status.code(), Some(4));
}

#[test]
fn with_log_format_json_every_log_line_is_one_json_object_with_its_time_level_and_message() {
    let args = ["--log-format", "json", "-v", "--tcp", "127.0.0.1:1", "--timeout", "100ms", "read", "holding", "0"];
    let err = crate::server::stderr(&crate::server::offline(&args).failure());
    let logged: Vec<serde_json::Value> =
        err.lines().filter(|l| l.starts_with('{')).map(|l| serde_json::from_str(l).expect(l)).collect();
    assert!(!logged.is_empty(), "{err}");
    for line in &logged {
        assert!(line["timestamp"].as_str().is_some_and(|t| t.ends_with('Z')), "{line}");
        assert!(["INFO", "WARN", "ERROR", "DEBUG"].contains(&line["level"].as_str().unwrap_or_default()), "{line}");
        assert!(line["message"].is_string(), "{line}");
    }
    // The command's own error is for people, after the log.
    assert!(err.lines().any(|l| l.starts_with("error: ")), "{err}");
    let refused = crate::server::stderr(&crate::server::offline(&["--log-format", "xml", "crc", "01"]).code(2));
    assert!(refused.contains("invalid value 'xml' for '--log-format <FORMAT>'"), "{refused}");
}
