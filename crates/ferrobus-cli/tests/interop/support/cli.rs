//! Where a client connects ([`Link`]) and the `ferrobus` binary as a client ([`ferrobus`]).

use std::path::PathBuf;
use std::process::Command;
use std::time::Duration;

use serde_json::Value;

use super::process::output_within;

/// The baud rate of every pty line here (stored by the pty, not applied).
pub(crate) const BAUD: u32 = 19200;

/// Parity of a serial link. pymodbus cannot set E or O on a pty opened a second time, so
/// pymodbus pairs use none; the others use the spec's even parity.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Parity {
    /// 8N1.
    None,
    /// 8E1.
    Even,
}

impl Parity {
    /// As `ferrobus --parity` and mbpoll `-P` take it.
    pub(crate) fn word(self) -> &'static str {
        if self == Parity::None { "none" } else { "even" }
    }

    /// As the peer fixtures take it.
    pub(crate) fn letter(self) -> &'static str {
        if self == Parity::None { "N" } else { "E" }
    }
}

/// The client's end of a connection to a server.
#[derive(Clone, PartialEq, Eq, Debug)]
pub(crate) enum Link {
    /// A tty at [`BAUD`] with this parity (RTU).
    Serial {
        /// The tty (a socat link or a pty).
        path: PathBuf,
        /// Its parity.
        parity: Parity,
    },
    /// `127.0.0.1:PORT` (Modbus/TCP).
    Tcp(String),
}

impl Link {
    /// The connection options of a peer fixture client.
    pub(crate) fn peer_args(&self) -> Vec<String> {
        match self {
            Link::Serial { path, parity } => vec![
                "--rtu".into(),
                path.display().to_string(),
                "--baud".into(),
                BAUD.to_string(),
                "--parity".into(),
                parity.letter().into(),
            ],
            Link::Tcp(addr) => vec!["--tcp".into(), addr.clone()],
        }
    }

    /// The connection options of `ferrobus`.
    pub(crate) fn ferrobus_args(&self) -> Vec<String> {
        match self {
            Link::Serial { path, parity } => vec![
                "--port".into(),
                path.display().to_string(),
                "--baud".into(),
                BAUD.to_string(),
                "--parity".into(),
                parity.word().into(),
            ],
            Link::Tcp(addr) => vec!["--tcp".into(), addr.clone()],
        }
    }
}

/// `ferrobus` with connection options, ready to run commands.
#[derive(Clone, Debug)]
pub(crate) struct Ferrobus {
    link: Vec<String>,
    unit: u8,
    timeout_ms: u64,
}

/// The `ferrobus` binary connected through `link` (unit 1, 1 s timeout unless changed).
pub(crate) fn ferrobus(link: &Link) -> Ferrobus {
    Ferrobus { link: link.ferrobus_args(), unit: 1, timeout_ms: 1000 }
}

impl Ferrobus {
    /// The same, for `unit`.
    #[must_use]
    pub(crate) fn unit(&self, unit: u8) -> Ferrobus {
        Ferrobus { unit, ..self.clone() }
    }

    /// The same, with a reply timeout of `ms` milliseconds.
    #[must_use]
    pub(crate) fn timeout_ms(&self, ms: u64) -> Ferrobus {
        Ferrobus { timeout_ms: ms, ..self.clone() }
    }

    fn options(&self) -> Vec<String> {
        let mut options = self.link.clone();
        options.extend(["--unit".into(), self.unit.to_string(), "--timeout".into(), format!("{}ms", self.timeout_ms)]);
        options
    }

    /// Runs `ferrobus OPTIONS ARGS...` (10 s at most).
    pub(crate) fn run(&self, args: &[&str]) -> Run {
        let mut command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
        let options = self.options();
        command.args(&options).args(args);
        let output = output_within(&mut command, "", Duration::from_secs(10));
        Run {
            what: format!("ferrobus {} {}", options.join(" "), args.join(" ")),
            code: output.status.code().unwrap_or(-1),
            stdout: String::from_utf8_lossy(&output.stdout).into_owned(),
            stderr: String::from_utf8_lossy(&output.stderr).into_owned(),
        }
    }

    /// Runs a command with `--json` and returns its `"values"`.
    pub(crate) fn values(&self, args: &[&str]) -> Vec<Value> {
        let mut args = args.to_vec();
        args.push("--json");
        match self.run(&args).json().get("values") {
            Some(Value::Array(values)) => values.clone(),
            other => panic!("ferrobus {}: no \"values\" array: {other:?}", args.join(" ")),
        }
    }
}

/// What a `ferrobus` run did.
#[derive(Debug)]
pub(crate) struct Run {
    what: String,
    /// Exit code.
    pub(crate) code: i32,
    /// stdout.
    pub(crate) stdout: String,
    /// stderr.
    pub(crate) stderr: String,
}

impl Run {
    /// Asserts exit code `code` and returns the run.
    #[track_caller]
    pub(crate) fn code(self, code: i32) -> Run {
        assert_eq!(
            self.code, code,
            "`{}` exited {}, expected {code}\nstdout:\n{}\nstderr:\n{}",
            self.what, self.code, self.stdout, self.stderr
        );
        self
    }

    /// Asserts success and returns stdout.
    #[track_caller]
    pub(crate) fn ok(self) -> String {
        self.code(0).stdout
    }

    /// Asserts success and parses stdout as JSON.
    #[track_caller]
    pub(crate) fn json(self) -> Value {
        let what = self.what.clone();
        let out = self.ok();
        serde_json::from_str(&out).unwrap_or_else(|e| panic!("`{what}`: stdout is not JSON ({e}):\n{out}"))
    }

    /// Asserts exit code 1 (an exception) with `exception 0xNN` on stderr.
    #[track_caller]
    pub(crate) fn exception(self, code: u8) -> Run {
        let run = self.code(1);
        let shown = format!("exception 0x{code:02X}");
        assert!(run.stderr.contains(&shown), "`{}`: stderr does not name {shown}:\n{}", run.what, run.stderr);
        run
    }

    /// Asserts exit code 3 (no reply).
    #[track_caller]
    pub(crate) fn timeout(self) -> Run {
        let run = self.code(3);
        // "no valid reply" when something came instead (a broken frame, another unit's, ...).
        let said = run.stderr.contains("no reply from unit") || run.stderr.contains("no valid reply from unit");
        assert!(said, "`{}`: stderr:\n{}", run.what, run.stderr);
        run
    }
}

/// Bits as JSON values: `"1001"` → `[true, false, false, true]`.
pub(crate) fn bits(pattern: &str) -> Vec<Value> {
    pattern.chars().map(|c| Value::Bool(c == '1')).collect()
}

/// Words as JSON values.
pub(crate) fn words(values: &[u64]) -> Vec<Value> {
    values.iter().map(|&v| Value::from(v)).collect()
}
