//! Command-line parsing, by hand to keep the fixture's dependency tree small.
//!
//! The flags mirror `libmodbus_server` / `libmodbus_client` and the pymodbus
//! fixtures exactly; see `tests/peers/README.md`.

use std::time::Duration;

use tokio_serial::{DataBits, Parity, StopBits};

pub const USAGE: &str = "\
usage: tokio-modbus-peer server CONN [--unit U] [--debug]
       tokio-modbus-peer client CONN [--unit U] [--timeout-ms N] [--debug] script
       tokio-modbus-peer client CONN [--unit U] [--timeout-ms N] [--debug] bench --count N
                         [--address A] [--quantity Q]
CONN:  --rtu PATH [--baud B] [--parity N|E|O] [--data-bits 5..8] [--stop-bits 1|2]
       --tcp PORT        (server: binds 127.0.0.1:PORT)
       --tcp HOST:PORT   (client)
Defaults: --unit 1, --baud 19200, --parity N, --data-bits 8, --stop-bits 1,
          --timeout-ms 1000, --address 0, --quantity 10.
The server prints READY on stdout when serving and exits 0 on SIGTERM/SIGINT.
script reads commands from stdin; see tests/peers/README.md for the line format.";

/// Serial line settings for `--rtu`.
#[derive(Debug, Clone)]
pub struct SerialOpts {
    pub path: String,
    pub baud: u32,
    pub parity: Parity,
    pub data_bits: DataBits,
    pub stop_bits: StopBits,
}

/// Where to talk.
#[derive(Debug, Clone)]
pub enum Transport {
    Rtu(SerialOpts),
    /// Server: the port; client: `HOST:PORT`.
    Tcp(String),
}

/// Options shared by both roles.
#[derive(Debug, Clone)]
pub struct Common {
    pub transport: Transport,
    pub unit: u8,
    pub debug: bool,
}

/// Bench parameters.
#[derive(Debug, Clone, Copy)]
pub struct BenchOpts {
    pub count: u64,
    pub address: u16,
    pub quantity: u16,
}

/// What to run.
#[derive(Debug)]
pub enum Command {
    Help,
    Server(Common),
    Script(Common, Duration),
    Bench(Common, Duration, BenchOpts),
}

/// A usage error, printed with the usage text (exit 2).
#[derive(Debug)]
pub struct UsageError(pub String);

/// Parses a decimal or `0x` hexadecimal integer in `lo..=hi` (never octal).
pub fn parse_num(text: &str, lo: u64, hi: u64) -> Option<u64> {
    let value = if let Some(hex) = text.strip_prefix("0x").or_else(|| text.strip_prefix("0X")) {
        if hex.starts_with(['+', '-']) {
            return None;
        }
        u64::from_str_radix(hex, 16).ok()?
    } else {
        if text.starts_with('+') {
            return None;
        }
        text.parse::<u64>().ok()?
    };
    (lo..=hi).contains(&value).then_some(value)
}

fn num<T: TryFrom<u64>>(flag: &str, value: Option<&String>, lo: u64, hi: u64) -> Result<T, UsageError> {
    let text = value.ok_or_else(|| UsageError(format!("{flag} needs a value")))?;
    parse_num(text, lo, hi)
        .and_then(|v| T::try_from(v).ok())
        .ok_or_else(|| UsageError(format!("bad {flag} '{text}' (expected {lo}..{hi})")))
}

/// Parses `argv[1..]`.
#[allow(clippy::too_many_lines)] // one flat match over all flags reads best
pub fn parse(args: &[String]) -> Result<Command, UsageError> {
    let Some(role) = args.first() else {
        return Err(UsageError("give a role: server or client".into()));
    };
    if role == "--help" || role == "-h" {
        return Ok(Command::Help);
    }
    let is_server = match role.as_str() {
        "server" => true,
        "client" => false,
        other => return Err(UsageError(format!("unknown role '{other}' (server or client)"))),
    };

    let mut rtu: Option<String> = None;
    let mut tcp: Option<String> = None;
    let (mut baud, mut parity, mut data_bits, mut stop_bits) = (19200u32, Parity::None, DataBits::Eight, StopBits::One);
    let mut unit: u8 = 1;
    let mut debug = false;
    let mut timeout_ms: u64 = 1000;
    let mut mode: Option<String> = None;
    let (mut count, mut address, mut quantity): (Option<u64>, u16, u16) = (None, 0, 10);
    let mut client_only: Vec<&str> = Vec::new();

    let mut it = args[1..].iter();
    while let Some(flag) = it.next() {
        match flag.as_str() {
            "--help" | "-h" => return Ok(Command::Help),
            "--rtu" | "--tcp" => {
                if rtu.is_some() || tcp.is_some() {
                    return Err(UsageError("give exactly one of --rtu or --tcp".into()));
                }
                let value = it.next().ok_or_else(|| UsageError(format!("{flag} needs a value")))?;
                if flag == "--rtu" {
                    rtu = Some(value.clone());
                } else {
                    tcp = Some(value.clone());
                }
            }
            "--baud" => baud = num(flag, it.next(), 50, 4_000_000)?,
            "--parity" => {
                parity = match it.next().map(String::as_str) {
                    Some("N") => Parity::None,
                    Some("E") => Parity::Even,
                    Some("O") => Parity::Odd,
                    _ => return Err(UsageError("--parity needs N, E or O".into())),
                }
            }
            "--data-bits" => {
                data_bits = match num::<u8>(flag, it.next(), 5, 8)? {
                    5 => DataBits::Five,
                    6 => DataBits::Six,
                    7 => DataBits::Seven,
                    _ => DataBits::Eight,
                }
            }
            "--stop-bits" => {
                stop_bits = if num::<u8>(flag, it.next(), 1, 2)? == 1 { StopBits::One } else { StopBits::Two }
            }
            "--unit" => unit = if is_server { num(flag, it.next(), 1, 247)? } else { num(flag, it.next(), 0, 255)? },
            "--debug" => debug = true,
            "--timeout-ms" => {
                client_only.push("--timeout-ms");
                timeout_ms = num(flag, it.next(), 1, 600_000)?;
            }
            "--count" => {
                client_only.push("--count");
                count = Some(num(flag, it.next(), 1, 100_000_000)?);
            }
            "--address" => {
                client_only.push("--address");
                address = num(flag, it.next(), 0, 65535)?;
            }
            "--quantity" => {
                client_only.push("--quantity");
                quantity = num(flag, it.next(), 1, 125)?;
            }
            "script" | "bench" if !is_server => {
                if mode.is_some() {
                    return Err(UsageError("give one mode (script or bench)".into()));
                }
                mode = Some(flag.clone());
            }
            other => return Err(UsageError(format!("unknown argument '{other}'"))),
        }
    }

    let transport = match (rtu, tcp) {
        (Some(path), None) => Transport::Rtu(SerialOpts { path, baud, parity, data_bits, stop_bits }),
        (None, Some(tcp)) => {
            if is_server {
                if parse_num(&tcp, 1, 65535).is_none() {
                    return Err(UsageError(format!("bad --tcp '{tcp}' (a port 1..65535)")));
                }
            } else if !tcp.rsplit_once(':').is_some_and(|(h, p)| !h.is_empty() && parse_num(p, 1, 65535).is_some()) {
                return Err(UsageError(format!("bad --tcp '{tcp}' (HOST:PORT)")));
            }
            Transport::Tcp(tcp)
        }
        _ => return Err(UsageError("give --rtu PATH or --tcp ...".into())),
    };
    let common = Common { transport, unit, debug };
    let timeout = Duration::from_millis(timeout_ms);

    if is_server {
        if let Some(flag) = client_only.first() {
            return Err(UsageError(format!("{flag} is a client option")));
        }
        return Ok(Command::Server(common));
    }
    match mode.as_deref() {
        Some("script") => {
            if let Some(flag) = client_only.iter().find(|f| **f != "--timeout-ms") {
                return Err(UsageError(format!("{flag} is for bench mode")));
            }
            Ok(Command::Script(common, timeout))
        }
        Some(_) => {
            let count = count.ok_or_else(|| UsageError("bench needs --count N".into()))?;
            Ok(Command::Bench(common, timeout, BenchOpts { count, address, quantity }))
        }
        None => Err(UsageError("give a client mode: script or bench".into())),
    }
}
