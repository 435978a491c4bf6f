//! Servers on one end of a line (the peer fixtures of tests/peers/ and `ferrobus sim`), the
//! peer clients driven through their `script` contract, and mbpoll.

use std::fmt::Write as _;
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use super::cli::{BAUD, Link, Parity};
use super::env::{self, Need};
use super::process::{Proc, Stream, output_within};
use super::serial::{SocatPair, TempDir};

/// How long a server may take to say it is ready (pymodbus needs about a second).
const READY_WITHIN: Duration = Duration::from_secs(20);

/// One of the three peer stacks.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Stack {
    /// libmodbus 3.1.6 (C).
    Libmodbus,
    /// pymodbus 3.16.1 (asyncio).
    Pymodbus,
    /// tokio-modbus 0.17.0.
    TokioModbus,
}

impl Stack {
    /// What the stack's fixtures need.
    pub(crate) fn need(self) -> Need {
        match self {
            Stack::Libmodbus => Need::Libmodbus,
            Stack::Pymodbus => Need::Pymodbus,
            Stack::TokioModbus => Need::TokioModbus,
        }
    }

    /// The parity its serial links use (see [`Parity`]).
    pub(crate) fn parity(self) -> Parity {
        if self == Stack::Pymodbus { Parity::None } else { Parity::Even }
    }

    /// The fixture program, `role` being `"server"` or `"client"`.
    fn command(self, role: &str) -> Command {
        match self {
            Stack::Libmodbus => Command::new(env::peer_path(&format!("libmodbus_{role}"))),
            Stack::Pymodbus => {
                let mut c = Command::new(env::python());
                c.arg(env::pymodbus_script(&format!("pymodbus_{role}.py")));
                c
            }
            Stack::TokioModbus => {
                let mut c = Command::new(env::tokio_peer());
                c.arg(role);
                c
            }
        }
    }
}

/// The transport between a client and a server.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Over {
    /// RTU over a socat pty pair.
    Rtu,
    /// Modbus/TCP on 127.0.0.1.
    Tcp,
}

/// A port on 127.0.0.1 that was free a moment ago.
///
/// # Panics
/// If no port can be bound.
pub(crate) fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0").and_then(|l| l.local_addr()).expect("a free port").port()
}

/// A running server and the link its clients use. Dropping it stops the server, then the
/// line, then removes the directory.
pub(crate) struct Served {
    /// The server process.
    _proc: Proc,
    /// Its pty pair, for RTU.
    _pair: Option<SocatPair>,
    /// Where the links live.
    _dir: TempDir,
    /// The client's end.
    pub(crate) link: Link,
}

/// The peer fixture server of `stack`, serving the data map of tests/peers/README.md for
/// `unit`, once it has printed `READY`.
pub(crate) fn peer_server(stack: Stack, over: Over, unit: u8) -> Served {
    let dir = TempDir::new();
    let (proc, pair, link) = match over {
        Over::Rtu => {
            let pair = SocatPair::start(dir.path());
            let proc = peer_server_on(stack, &pair.b, unit);
            let link = Link::Serial { path: pair.a.clone(), parity: stack.parity() };
            (proc, Some(pair), link)
        }
        Over::Tcp => {
            let port = free_port();
            let mut command = stack.command("server");
            command.args(["--tcp", &port.to_string(), "--unit", &unit.to_string()]);
            (ready(stack, &mut command), None, Link::Tcp(format!("127.0.0.1:{port}")))
        }
    };
    Served { _proc: proc, _pair: pair, _dir: dir, link }
}

/// The peer fixture server of `stack` on 127.0.0.1:`port` (Modbus/TCP) for `unit`, with
/// `extra` arguments (libmodbus's `--service-us`, say), once it is ready: for a test that
/// stops a server and starts another on the same port.
pub(crate) fn peer_tcp_server_on(stack: Stack, port: u16, unit: u8, extra: &[&str]) -> Proc {
    let mut command = stack.command("server");
    command.args(["--tcp", &port.to_string(), "--unit", &unit.to_string()]).args(extra);
    ready(stack, &mut command)
}

/// The peer fixture server of `stack` on the tty `path` (RTU), once it is ready.
pub(crate) fn peer_server_on(stack: Stack, path: &Path, unit: u8) -> Proc {
    let mut command = stack.command("server");
    command.args(["--rtu", &path.display().to_string(), "--baud", &BAUD.to_string()]);
    command.args(["--parity", stack.parity().letter(), "--unit", &unit.to_string()]);
    ready(stack, &mut command)
}

fn ready(stack: Stack, command: &mut Command) -> Proc {
    let proc = Proc::spawn(&format!("{stack:?} server"), command);
    proc.wait_for(Stream::Out, |l| l == "READY", READY_WITHIN);
    proc
}

/// `ferrobus sim ARGS` on one end of a socat pair (`--port`, at `parity`) or on TCP, once it
/// says it is serving.
pub(crate) fn sim(over: Over, parity: Parity, args: &[&str]) -> Served {
    let dir = TempDir::new();
    let (proc, pair, link) = match over {
        Over::Rtu => {
            let pair = SocatPair::start(dir.path());
            let proc = sim_on(&pair.b, parity, args);
            let link = Link::Serial { path: pair.a.clone(), parity };
            (proc, Some(pair), link)
        }
        Over::Tcp => {
            let addr = format!("127.0.0.1:{}", free_port());
            let mut command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
            command.arg("sim").args(args).args(["--tcp", &addr]);
            let proc = Proc::spawn("ferrobus sim", &mut command);
            proc.wait_for(Stream::Err, |l| l.starts_with("sim: listening on"), READY_WITHIN);
            (proc, None, Link::Tcp(addr))
        }
    };
    Served { _proc: proc, _pair: pair, _dir: dir, link }
}

/// `ferrobus sim ARGS --port PATH` at `parity`, once it says it is serving.
pub(crate) fn sim_on(path: &Path, parity: Parity, args: &[&str]) -> Proc {
    let mut command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
    command.arg("sim").args(args);
    command.args(["--port", &path.display().to_string(), "--baud", &BAUD.to_string(), "--parity", parity.word()]);
    let proc = Proc::spawn("ferrobus sim", &mut command);
    proc.wait_for(Stream::Err, |l| l.starts_with("sim: serving on"), READY_WITHIN);
    proc
}

/// `ferrobus sim --pty ARGS`: the simulator and the pty it printed.
pub(crate) fn sim_pty(args: &[&str]) -> (Proc, PathBuf) {
    let mut command = Command::new(env!("CARGO_BIN_EXE_ferrobus"));
    command.args(["sim", "--pty"]).args(args);
    let proc = Proc::spawn("ferrobus sim --pty", &mut command);
    let path = proc.wait_for(Stream::Out, |l| l.starts_with('/'), READY_WITHIN);
    (proc, PathBuf::from(path))
}

/// Runs the `script` of `stack`'s client against `link` for `unit` with a 300 ms timeout and
/// checks each result line: `(command, expected line)`. Every mismatch is listed in the panic
/// message.
///
/// # Panics
/// On any mismatch, a client that does not finish within 60 s, or one that exits non-zero.
pub(crate) fn check_script(stack: Stack, link: &Link, unit: u8, steps: &[(&str, &str)]) {
    let script: String = steps.iter().fold(String::new(), |mut script, (command, _)| {
        let _ = writeln!(script, "{command}");
        script
    });
    let mut command = stack.command("client");
    command.args(link.peer_args()).args(["--unit", &unit.to_string(), "--timeout-ms", "300", "script"]);
    let output = output_within(&mut command, &script, Duration::from_secs(60));
    let stdout = String::from_utf8_lossy(&output.stdout);
    let got: Vec<&str> = stdout.lines().collect();
    let mut table = String::new();
    let mut bad = 0;
    for (i, (command, expected)) in steps.iter().enumerate() {
        let result = got.get(i).copied().unwrap_or("<nothing>");
        let ok = result == *expected;
        bad += usize::from(!ok);
        let mark = if ok { "  " } else { "✗ " };
        let _ = writeln!(table, "{mark}{command:<28} expected {expected:<28} got {result}");
    }
    assert!(
        bad == 0 && got.len() == steps.len() && output.status.success(),
        "{stack:?} client over {link:?}: {bad} of {} results differ ({} lines, exit {:?})\n{table}stderr:\n{}",
        steps.len(),
        got.len(),
        output.status.code(),
        String::from_utf8_lossy(&output.stderr)
    );
}

/// What mbpoll printed.
#[derive(Debug)]
pub(crate) struct Polled {
    /// Exit code.
    pub(crate) code: i32,
    /// The values of `[ref]: value` lines, in order.
    pub(crate) values: Vec<(u32, String)>,
    /// stdout.
    pub(crate) stdout: String,
    /// stderr.
    pub(crate) stderr: String,
}

/// `mbpoll -1 -o 0.3 ARGS... DEVICE|HOST WRITES...` against `link` for `unit`, 0-based unless
/// `args` say otherwise (mbpoll is 1-based by default; `-0` is added when `zero_based`).
pub(crate) fn mbpoll(link: &Link, unit: u8, zero_based: bool, args: &[&str], writes: &[&str]) -> Polled {
    let mut command = Command::new("mbpoll");
    command.args(["-1", "-o", "0.3", "-a", &unit.to_string()]);
    if zero_based {
        command.arg("-0");
    }
    command.args(args);
    match link {
        Link::Serial { path, parity } => {
            command.args(["-m", "rtu", "-b", &BAUD.to_string(), "-P", parity.word()]).arg(path);
        }
        Link::Tcp(addr) => {
            let (host, port) = addr.rsplit_once(':').expect("host:port");
            command.args(["-m", "tcp", "-p", port, host]);
        }
    }
    command.args(writes);
    let output = output_within(&mut command, "", Duration::from_secs(20));
    let stdout = String::from_utf8_lossy(&output.stdout).into_owned();
    let values = stdout
        .lines()
        .filter_map(|l| {
            let (reference, value) = l.strip_prefix('[')?.split_once("]:")?;
            Some((reference.parse().ok()?, value.trim().to_string()))
        })
        .collect();
    Polled {
        code: output.status.code().unwrap_or(-1),
        values,
        stdout,
        stderr: String::from_utf8_lossy(&output.stderr).into_owned(),
    }
}
