//! The gateway's lines file: its lines — serial ports, and devices over TCP — each with its
//! own settings and the units it serves, from a TOML file of `[[line]]` tables.
//!
//! ```toml
//! [[line]]                      # line 0
//! port = "/dev/ttyUSB0"
//! baud = 9600
//! parity = "even"               # even, odd, none
//! timeout = "300ms"
//! response-wait = "20ms"        # the drives' own wait (3G3RX C078): added to the timeout
//! units = [1, 2, "10-20"]       # served under their own addresses
//!
//! [[line]]                      # line 1
//! port = "/dev/ttyUSB1"
//! baud = 115200
//! parity = "none"
//! stop-bits = 1
//! t35 = "2ms"
//! renumber = { 30 = 3, "41-50" = "1-10" }   # client unit 30 is unit 3 on this line
//!
//! [[line]]                      # line 2: an inverter that takes one Modbus/TCP client
//! tcp = "192.168.1.50"          # port 502 unless given
//! timeout = "1s"
//! in-flight = 4                 # up to 4 requests outstanding on its connection
//! renumber = { 100 = 1 }
//!
//! [[line]]                      # line 3: a serial server that carries RTU frames over TCP
//! rtu-tcp = "192.168.1.60:4001"
//! units = ["60-69"]
//! ```
//!
//! A line is exactly one of `port` (a serial port), `tcp` (a Modbus/TCP device, `HOST[:PORT]`,
//! port 502 unless given) and `rtu-tcp` (RTU frames over TCP, `HOST:PORT`). The keys: `port`,
//! `tcp`, `rtu-tcp`, `ascii`, `baud`, `parity`, `data-bits`, `stop-bits`, `rs485`,
//! `low-latency`, `timeout`, `retries`, `t15`, `t35`, `turnaround`, `echo`, `reopen`, `queue`,
//! `late-guard`, `late-window` (after a timeout, how long its reply is still awaited and the
//! line kept closed; default twice the timeout: [`ClientConfig::late_window`]), `in-flight` (on a `tcp` line only: how many requests may be outstanding on
//! the device's connection at once, 1 to 16, matched by transaction id; see
//! [`ClientConfig::in_flight`]), and `response-wait`: the time the devices of the line hold
//! their reply, added to the line's reply timeout. A line's routes are `units` (numbers and `"A-B"` ranges) and
//! `renumber` (client units to the units on the line; a range to a range of the same length,
//! or to its first unit). Durations are strings such as `"300ms"`, or whole numbers of
//! milliseconds. A serial port's own keys (`ascii`, `baud`, `parity`, `data-bits`,
//! `stop-bits`, `rs485`, `low-latency`, `echo`) on a `tcp` or `rtu-tcp` line are a mistake, and
//! so are `t15`, `t35` and `turnaround` on a `tcp` line (Modbus/TCP has no silent intervals and
//! no broadcast); `reopen = false` there means a lost connection is not made again.
//!
//! Every line starts from the [`LineDefaults`] the caller gives (a command line's options,
//! say); a key of a `[[line]]` beats them. One line without `units` or `renumber` serves units
//! 1–247 under their own addresses; a `tcp` line alone, every unit id 0-255
//! ([`Routes::every_id_on`]: a Modbus/TCP device has no broadcast, and 0xFF is the spec's id for
//! a device addressed by its IP address).
//!
//! The whole file is checked before anything is opened. A [`LinesFileError`] names the file,
//! the line and column, the `[[line]]` (numbered from 0, as the gateway numbers its lines) and
//! the key: an unknown key, a value of the wrong type or out of range, a line that is none or
//! more than one of `port`, `tcp` and `rtu-tcp`, a serial key on a TCP line, a port or TCP
//! device given twice, a unit routed twice (with where it was routed first), a line with no
//! units when there are several, or with empty `units` and `renumber`. Its places and excerpts are
//! [`ferrobus_profile::source`]'s: bounded, whatever the file holds.

use std::collections::BTreeMap;
use std::io;
use std::ops::Range;
use std::path::Path;
use std::time::Duration;

use ferrobus_profile::source::{self, Located, Place, ReadError};
use ferrobus_proto::frame::{DataBits, LineConfig, Parity, StopBits};
use ferrobus_proto::master::pipeline::MAX_IN_FLIGHT;
use serde::Deserialize;
use toml::Spanned;

use super::{GatewayLine, Route, Routes};
use ferrobus::text::Item;
use ferrobus::{ClientConfig, Rs485, SerialConfig, Transport};

/// What every line of a lines file starts from, before its own keys.
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct LineDefaults {
    /// Baud, data bits, parity, stop bits.
    pub framing: LineConfig,
    /// Modbus ASCII instead of RTU.
    pub ascii: bool,
    /// Transmitter direction control.
    pub rs485: Rs485,
    /// Lower the USB adapter's latency timer to 1 ms.
    pub low_latency: bool,
    /// t1.5, if not the line's own.
    pub t1_5: Option<Duration>,
    /// t3.5, if not the line's own.
    pub t3_5: Option<Duration>,
    /// Reopen a port that failed.
    pub reopen: bool,
    /// Each line's master: reply timeout, retries, turnaround, echo suppression, backoff.
    pub client: ClientConfig,
    /// Requests that may wait for a line.
    pub queue: usize,
    /// How long a line stays quiet after a request without a usable reply.
    pub late_guard: Duration,
}

impl Default for LineDefaults {
    /// 19200 8E1 RTU (the spec's default), the adapter driving RS-485, ports reopened, the
    /// client's defaults, and a line's: a queue of 64, a late-reply guard of 100 ms.
    fn default() -> Self {
        LineDefaults {
            framing: LineConfig::default(),
            ascii: false,
            rs485: Rs485::Auto,
            low_latency: false,
            t1_5: None,
            t3_5: None,
            reopen: true,
            client: ClientConfig::default(),
            queue: super::DEFAULT_QUEUE,
            late_guard: super::DEFAULT_LATE_GUARD,
        }
    }
}

/// A lines file, read and checked: the lines in file order, and which unit goes where.
#[derive(Clone, Debug)]
pub struct LinesFile {
    /// The lines, numbered from 0 in file order.
    pub lines: Vec<GatewayLine>,
    /// The routes of every line.
    pub routes: Routes,
    /// What each line is, as the file and the defaults resolve it, beside [`LinesFile::lines`]:
    /// what a reload compares ([`super::reload::plan`]).
    pub settings: Vec<LineSettings>,
}

/// One line's settings as resolved from its `[[line]]` and the defaults, its units apart: two
/// are equal when the line would run the same (its routes may differ; they take effect
/// without restarting it).
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct LineSettings {
    kind: Kind,
    target: String,
    resolved: LineDefaults,
}

impl LineSettings {
    /// What the line is connected to: the serial port, or the device's `HOST:PORT`
    /// (normalised): a line that keeps it is the same line, changed or not.
    pub fn target(&self) -> &str {
        &self.target
    }

    /// Whether `other` is connected to the same port or device.
    pub fn same_target(&self, other: &LineSettings) -> bool {
        self.kind == other.kind && self.target == other.target
    }
}

/// Why a lines file was refused.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LinesFileError {
    /// The file could not be read.
    #[error("cannot read the lines file {file}: {source}")]
    Io {
        /// The file, as named.
        file: String,
        /// The file system's error.
        #[source]
        source: io::Error,
    },
    /// A mistake in the file, displayed `file:line:col: message (in `excerpt`)`: bytes that
    /// are not UTF-8, TOML syntax, an unknown key, a wrong value, a port or a unit given
    /// twice, a line without a port or units, no `[[line]]` at all.
    #[error("{}", .located.in_file(.file))]
    Invalid {
        /// The file, as named.
        file: String,
        /// The `[[line]]` at fault, numbered from 0; `None` for the file as a whole.
        line: Option<usize>,
        /// Where, and what is wrong.
        located: Located,
    },
}

/// The file's shape: unknown keys are refused by the TOML reader, with their place.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileShape {
    #[serde(default)]
    line: Vec<Spanned<LineShape>>,
}

/// One `[[line]]`, every value with its place.
#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename_all = "kebab-case")]
struct LineShape {
    port: Option<Spanned<toml::Value>>,
    tcp: Option<Spanned<toml::Value>>,
    rtu_tcp: Option<Spanned<toml::Value>>,
    ascii: Option<Spanned<toml::Value>>,
    baud: Option<Spanned<toml::Value>>,
    parity: Option<Spanned<toml::Value>>,
    data_bits: Option<Spanned<toml::Value>>,
    stop_bits: Option<Spanned<toml::Value>>,
    rs485: Option<Spanned<toml::Value>>,
    low_latency: Option<Spanned<toml::Value>>,
    timeout: Option<Spanned<toml::Value>>,
    retries: Option<Spanned<toml::Value>>,
    t15: Option<Spanned<toml::Value>>,
    t35: Option<Spanned<toml::Value>>,
    response_wait: Option<Spanned<toml::Value>>,
    turnaround: Option<Spanned<toml::Value>>,
    echo: Option<Spanned<toml::Value>>,
    reopen: Option<Spanned<toml::Value>>,
    queue: Option<Spanned<toml::Value>>,
    late_guard: Option<Spanned<toml::Value>>,
    late_window: Option<Spanned<toml::Value>>,
    in_flight: Option<Spanned<toml::Value>>,
    units: Option<Vec<Spanned<Item>>>,
    renumber: Option<BTreeMap<Spanned<String>, Spanned<Item>>>,
}

/// What is wrong, and where in the file.
type Problem = (Range<usize>, String);

/// Reads the lines file at `path`: the lines, with their keys on top of `defaults`, and the
/// routes. Nothing is opened.
pub fn read(path: &Path, defaults: &LineDefaults) -> Result<LinesFile, LinesFileError> {
    let file = path.display().to_string();
    let text = source::read(path).map_err(|e| match e {
        ReadError::Io(source) => LinesFileError::Io { file: file.clone(), source },
        not_text @ ReadError::NotText(_) => {
            LinesFileError::Invalid { file: file.clone(), line: None, located: not_text.located() }
        }
    })?;
    parse(&file, &text, defaults)
}

/// Line and column (both from 1) of a byte offset.
fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let place = Place::of(text, offset);
    (place.line, place.column)
}

/// Parses and checks `text`, the lines file called `file` in errors.
pub fn parse(file: &str, text: &str, defaults: &LineDefaults) -> Result<LinesFile, LinesFileError> {
    let invalid =
        |line: Option<usize>, located: Located| LinesFileError::Invalid { file: file.to_string(), line, located };
    let shape: FileShape = toml::from_str(text).map_err(|e| invalid(None, Located::toml(text, &e)))?;
    if shape.line.is_empty() {
        let message = "no [[line]] table: give one per serial port, with its port = \"/dev/ttyUSB0\" and its units";
        return Err(invalid(None, Located::at(None, message)));
    }
    let several = shape.line.len() > 1;
    let mut lines = Vec::with_capacity(shape.line.len());
    let mut settled = Vec::with_capacity(shape.line.len());
    let mut ports: Vec<(String, usize)> = Vec::new();
    // Where each client unit was routed first: its line and the place in the file.
    let mut first_seen: Vec<Option<(usize, usize)>> = vec![None; 256];
    let mut routes = Routes::new();
    for (index, table) in shape.line.iter().enumerate() {
        let what = |(span, message): Problem| {
            invalid(Some(index), Located::new(text, Some(span), &format!("[[line]] {index}, {message}")))
        };
        let line = table.get_ref();
        let (config, target, resolved) = settings(table.span(), line, defaults).map_err(what)?;
        if let Some((_, first)) = ports.iter().find(|(p, _)| *p == target.name) {
            let (row, col) = line_col(text, *first);
            let message = format!("{}: {} is a line already ({file}:{row}:{col})", target.key, target.name);
            return Err(what((target.span, message)));
        }
        ports.push((target.name.clone(), target.span.start));
        settled.push(resolved);
        let mut route = |unit: u8, out: u8, span: &Range<usize>| -> Result<(), Problem> {
            let slot = first_seen
                .get_mut(usize::from(unit))
                .ok_or_else(|| (span.clone(), format!("unit {unit}: no such unit")))?;
            if let Some((other, first)) = *slot {
                let (row, col) = line_col(text, first);
                let first = format!("{file}:{row}:{col}");
                return Err((span.clone(), format!("unit {unit} is routed twice: to line {other} already ({first})")));
            }
            *slot = Some((index, span.start));
            routes.set(unit, Route { line: index, unit: out });
            Ok(())
        };
        let mut any = false;
        for item in line.units.iter().flatten() {
            let (first, last) = units(item).map_err(|m| what((item.span(), format!("units: {m}"))))?;
            for unit in first..=last {
                route(unit, unit, &item.span()).map_err(|(s, m)| what((s, format!("units: {m}"))))?;
            }
            any = true;
        }
        let mut renumbered: Vec<_> = line.renumber.iter().flatten().collect();
        renumbered.sort_by_key(|(key, _)| key.span().start);
        for (key, value) in renumbered {
            let bad = |span: Range<usize>| move |m: String| what((span, format!("renumber: {m}")));
            let (first, last) = range(key.get_ref()).map_err(bad(key.span()))?;
            let (first, last) = client_units(first, last).map_err(bad(key.span()))?;
            let count = last - first;
            let start = match value.get_ref() {
                Item::Number(n) => unit_number(*n).map_err(bad(value.span()))?,
                Item::Text(t) => {
                    let (a, b) = range(t).map_err(bad(value.span()))?;
                    let (a, b) = client_units(a, b).map_err(bad(value.span()))?;
                    if b - a != count {
                        return Err(bad(value.span())(format!(
                            "{} units ({}) cannot be renumbered to {} ({t})",
                            u16::from(count) + 1,
                            key.get_ref(),
                            u16::from(b - a) + 1
                        )));
                    }
                    a
                }
            };
            if start.checked_add(count).is_none() {
                return Err(bad(value.span())(format!("units {first}-{last} from {start} run past unit 255")));
            }
            for offset in 0..=count {
                route(first + offset, start + offset, &key.span())
                    .map_err(|(s, m)| what((s, format!("renumber: {m}"))))?;
            }
            any = true;
        }
        if !any && (line.units.is_some() || line.renumber.is_some()) {
            return Err(what((table.span(), "routes no unit: its units and renumber are empty".into())));
        }
        if !any {
            if several {
                return Err(what((
                    table.span(),
                    "routes no unit: with several lines, each says which are its (units = [1, \"10-20\"], or renumber)"
                        .into(),
                )));
            }
            // A Modbus/TCP device takes every unit id; a serial line units 1-247.
            let tcp = config.transport.framing() == ferrobus::Framing::Mbap;
            routes = if tcp { Routes::every_id_on(0) } else { Routes::all_on(0) };
        }
        lines.push(config);
    }
    Ok(LinesFile { lines, routes, settings: settled })
}

/// What a line is connected to: the key that said it, the port or address (normalised, for
/// telling two lines on one device apart) and where.
struct Target {
    key: &'static str,
    name: String,
    span: Range<usize>,
}

/// Which kind of line a `[[line]]` is.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Kind {
    Serial,
    Tcp,
    RtuTcp,
}

/// The keys that only a serial port has, and those that Modbus/TCP also lacks (it has no
/// silent intervals, and no broadcast to wait after).
fn serial_only(line: &LineShape, kind: Kind) -> Vec<(&'static str, &Spanned<toml::Value>)> {
    let mut keys = vec![
        ("ascii", &line.ascii),
        ("baud", &line.baud),
        ("parity", &line.parity),
        ("data-bits", &line.data_bits),
        ("stop-bits", &line.stop_bits),
        ("rs485", &line.rs485),
        ("low-latency", &line.low_latency),
        ("echo", &line.echo),
    ];
    if kind == Kind::Tcp {
        keys.extend([("t15", &line.t15), ("t35", &line.t35), ("turnaround", &line.turnaround)]);
    }
    keys.into_iter().filter_map(|(key, value)| value.as_ref().map(|v| (key, v))).collect()
}

/// The line's target: exactly one of `port`, `tcp` and `rtu-tcp`.
fn target(table: Range<usize>, line: &LineShape) -> Result<(Kind, Target), Problem> {
    let given: Vec<(Kind, &'static str, &Spanned<toml::Value>)> =
        [(Kind::Serial, "port", &line.port), (Kind::Tcp, "tcp", &line.tcp), (Kind::RtuTcp, "rtu-tcp", &line.rtu_tcp)]
            .into_iter()
            .filter_map(|(kind, key, value)| value.as_ref().map(|v| (kind, key, v)))
            .collect();
    let (kind, key, value) = match given.as_slice() {
        [] => {
            return Err((
                table,
                "no port: give the serial port (port = \"/dev/ttyUSB0\") or the device over TCP (tcp = \
                 \"10.0.0.7:502\", rtu-tcp = \"10.0.0.8:4001\")"
                    .into(),
            ));
        }
        [one] => *one,
        [(_, first, _), (_, second, value), ..] => {
            return Err((
                value.span(),
                format!("{second}: a line is one of port, tcp and rtu-tcp, and this one has {first} already"),
            ));
        }
    };
    let text = match value.get_ref() {
        toml::Value::String(s) if !s.trim().is_empty() => s.trim().to_string(),
        toml::Value::String(_) if kind == Kind::Serial => return Err((value.span(), "port: the path is empty".into())),
        toml::Value::String(_) => return Err((value.span(), format!("{key}: the address is empty"))),
        other if kind == Kind::Serial => {
            return Err((value.span(), format!("port: a path in quotes, not a {}", other.type_str())));
        }
        other => return Err((value.span(), format!("{key}: HOST:PORT in quotes, not a {}", other.type_str()))),
    };
    let name = match kind {
        Kind::Serial => text,
        Kind::Tcp => with_default_port(&text, 502),
        Kind::RtuTcp if has_port(&text) => text,
        Kind::RtuTcp => {
            return Err((
                value.span(),
                format!("rtu-tcp: '{text}' needs its port, HOST:PORT (serial servers listen on e.g. 4001 or 502)"),
            ));
        }
    };
    Ok((kind, Target { key, name, span: value.span() }))
}

/// Whether `addr` ends in `:PORT` (an IPv6 address only in brackets: `[::1]:502`).
fn has_port(addr: &str) -> bool {
    match addr.rsplit_once(':') {
        Some((host, port)) => {
            !port.is_empty()
                && port.bytes().all(|b| b.is_ascii_digit())
                && (!host.contains(':') || (host.starts_with('[') && host.ends_with(']')))
        }
        None => false,
    }
}

/// `host` → `host:502`, `::1` → `[::1]:502`; an address with its port as it is.
fn with_default_port(addr: &str, port: u16) -> String {
    if has_port(addr) {
        addr.to_string()
    } else if addr.starts_with('[') || !addr.contains(':') {
        format!("{addr}:{port}")
    } else {
        format!("[{addr}]:{port}")
    }
}

/// Refuses a serial port's key on a line to a device over TCP.
fn no_serial_keys(kind: Kind, target: &Target, line: &LineShape) -> Result<(), Problem> {
    if kind == Kind::Serial {
        return Ok(());
    }
    let Some((key, value)) = serial_only(line, kind).into_iter().next() else { return Ok(()) };
    let what = if kind == Kind::Tcp { "a Modbus/TCP line" } else { "an RTU-over-TCP line" };
    Err((
        value.span(),
        format!(
            "{key}: a serial port's setting, and {what} ({} = \"{}\") has none: the device's own serial side, if \
             any, is set on the device",
            target.key, target.name
        ),
    ))
}

/// A line to the device at `addr` over TCP (Modbus/TCP, or RTU frames), with `d`'s settings.
fn network_line(kind: Kind, addr: String, d: &LineDefaults) -> GatewayLine {
    let mut transport = if kind == Kind::Tcp { Transport::tcp(addr) } else { Transport::rtu_over_tcp(addr) };
    if kind == Kind::RtuTcp {
        if let Some(t15) = d.t1_5 {
            transport = transport.with_t1_5(t15);
        }
        if let Some(t35) = d.t3_5 {
            transport = transport.with_t3_5(t35);
        }
    }
    GatewayLine {
        queue: d.queue,
        late_guard: d.late_guard,
        ..GatewayLine::new(transport.with_reopen(d.reopen), d.client)
    }
}

/// One line's settings: `defaults`, with the table's keys on top. What it is connected to,
/// and where that was said, too, and the settings as a reload compares them.
fn settings(
    table: Range<usize>,
    line: &LineShape,
    defaults: &LineDefaults,
) -> Result<(GatewayLine, Target, LineSettings), Problem> {
    let (kind, target) = target(table.clone(), line)?;
    no_serial_keys(kind, &target, line)?;
    let path = target.name.clone();
    let mut d = defaults.clone();
    if let Some(v) = &line.ascii {
        d.ascii = flag(v, "ascii")?;
    }
    if let Some(v) = &line.baud {
        let baud = number(v, "baud", 1, u32::MAX.into(), "bits per second, 1 or more, e.g. 9600")?;
        let baud = u32::try_from(baud).map_err(|_| (v.span(), "baud: too high".to_string()))?;
        let framing = LineConfig::new(baud).ok_or_else(|| (v.span(), format!("baud: {baud} is no baud rate")))?;
        d.framing = framing
            .with_parity(d.framing.parity)
            .with_data_bits(d.framing.data_bits)
            .with_stop_bits(d.framing.stop_bits);
    }
    if let Some(v) = &line.parity {
        let parity = choice(v, "parity", &[("even", Parity::Even), ("odd", Parity::Odd), ("none", Parity::None)])?;
        d.framing = d.framing.with_parity(parity);
    }
    if let Some(v) = &line.data_bits {
        let bits = if number(v, "data-bits", 7, 8, "7 or 8")? == 7 { DataBits::Seven } else { DataBits::Eight };
        d.framing = d.framing.with_data_bits(bits);
    }
    if let Some(v) = &line.stop_bits {
        let bits = if number(v, "stop-bits", 1, 2, "1 or 2")? == 1 { StopBits::One } else { StopBits::Two };
        d.framing = d.framing.with_stop_bits(bits);
    }
    if let Some(v) = &line.rs485 {
        d.rs485 = choice(v, "rs485", &[("auto", Rs485::Auto), ("kernel", Rs485::Kernel), ("rts", Rs485::Rts)])?;
    }
    if let Some(v) = &line.low_latency {
        d.low_latency = flag(v, "low-latency")?;
    }
    if let Some(v) = &line.timeout {
        let timeout = duration(v, "timeout")?;
        if timeout.is_zero() {
            return Err((v.span(), "timeout: 0 gives up before any reply can come; e.g. \"500ms\"".into()));
        }
        d.client.timeout = timeout;
        d.client.connect_timeout = timeout.max(Duration::from_secs(1));
    }
    if let Some(v) = &line.retries {
        let retries = number(v, "retries", 0, u32::MAX.into(), "a count, 0 or more")?;
        d.client.retries = u32::try_from(retries).map_err(|_| (v.span(), "retries: too many".to_string()))?;
    }
    if let Some(v) = &line.t15 {
        d.t1_5 = Some(duration(v, "t15")?);
    }
    if let Some(v) = &line.t35 {
        d.t3_5 = Some(duration(v, "t35")?);
    }
    if let Some(v) = &line.turnaround {
        d.client.turnaround_delay = duration(v, "turnaround")?;
    }
    if let Some(v) = &line.echo {
        d.client.echo_suppression = flag(v, "echo")?;
    }
    if let Some(v) = &line.reopen {
        d.reopen = flag(v, "reopen")?;
    }
    if let Some(v) = &line.response_wait {
        d.client.timeout = d.client.timeout.saturating_add(duration(v, "response-wait")?);
    }
    if let Some(v) = &line.queue {
        let queue = number(v, "queue", 1, i64::from(u32::MAX), "the requests that may wait, 1 or more")?;
        d.queue = usize::try_from(queue).map_err(|_| (v.span(), "queue: too long".to_string()))?;
    }
    if let Some(v) = &line.late_guard {
        d.late_guard = duration(v, "late-guard")?;
    }
    if let Some(v) = &line.late_window {
        d.client.late_window = Some(duration(v, "late-window")?);
    }
    d.client.in_flight = in_flight(line.in_flight.as_ref(), kind, d.client.in_flight)?;
    let resolved = LineSettings { kind, target: target.name.clone(), resolved: d.clone() };
    if kind != Kind::Serial {
        return Ok((network_line(kind, path, &d), target, resolved));
    }
    if d.framing.data_bits == DataBits::Seven && !d.ascii {
        let span = line.data_bits.as_ref().map_or(table, Spanned::span);
        return Err((span, "data-bits: 7 only with ascii = true (RTU needs 8 data bits)".into()));
    }
    let serial = SerialConfig { rs485: d.rs485, low_latency: d.low_latency, ..SerialConfig::new(&path, d.framing) };
    let mut transport = if d.ascii { Transport::ascii(serial) } else { Transport::rtu(serial) };
    if let Some(t15) = d.t1_5 {
        transport = transport.with_t1_5(t15);
    }
    if let Some(t35) = d.t3_5 {
        transport = transport.with_t3_5(t35);
    }
    let config = GatewayLine {
        queue: d.queue,
        late_guard: d.late_guard,
        ..GatewayLine::new(transport.with_reopen(d.reopen), d.client)
    };
    Ok((config, target, resolved))
}

/// A line's requests in flight: its `in-flight` key on a Modbus/TCP line, else `default` there;
/// one on every other line, where the key is a mistake.
fn in_flight(value: Option<&Spanned<toml::Value>>, kind: Kind, default: usize) -> Result<usize, Problem> {
    match (value, kind) {
        (Some(v), Kind::Tcp) => {
            let limit = i64::try_from(MAX_IN_FLIGHT).unwrap_or(i64::MAX);
            let n = number(v, "in-flight", 1, limit, &format!("the requests outstanding at once, 1 to {limit}"))?;
            Ok(usize::try_from(n).unwrap_or(1))
        }
        (Some(v), _) => {
            let message = "in-flight: only a Modbus/TCP line (tcp = ...) keeps several requests in flight; RTU \
                           frames carry no transaction id to tell their replies apart";
            Err((v.span(), message.into()))
        }
        (None, Kind::Tcp) => Ok(default),
        (None, _) => Ok(1),
    }
}

/// A whole number from `min` to `max`.
fn number(value: &Spanned<toml::Value>, key: &str, min: i64, max: i64, what: &str) -> Result<i64, Problem> {
    match value.get_ref() {
        toml::Value::Integer(n) if (min..=max).contains(n) => Ok(*n),
        toml::Value::Integer(n) => Err((value.span(), format!("{key}: {n} is out of range ({what})"))),
        other => Err((value.span(), format!("{key}: {what}, not a {}", other.type_str()))),
    }
}

/// `true` or `false`.
fn flag(value: &Spanned<toml::Value>, key: &str) -> Result<bool, Problem> {
    match value.get_ref() {
        toml::Value::Boolean(b) => Ok(*b),
        other => Err((value.span(), format!("{key}: true or false, not a {}", other.type_str()))),
    }
}

/// A duration by the one grammar ([`ferrobus::text::duration`]): `"300ms"`, `"1.5s"`, or a whole
/// number of milliseconds.
fn duration(value: &Spanned<toml::Value>, key: &str) -> Result<Duration, Problem> {
    let text = match value.get_ref() {
        toml::Value::String(s) => s.clone(),
        toml::Value::Integer(n) if *n >= 0 => n.to_string(),
        toml::Value::Integer(n) => return Err((value.span(), format!("{key}: {n} is negative"))),
        other => {
            return Err((value.span(), format!("{key}: a duration such as \"300ms\", not a {}", other.type_str())));
        }
    };
    ferrobus::text::duration(&text).map_err(|e| (value.span(), format!("{key}: {e}")))
}

/// One of `names` (any case).
fn choice<T: Copy>(value: &Spanned<toml::Value>, key: &str, names: &[(&str, T)]) -> Result<T, Problem> {
    let expected = || names.iter().map(|(name, _)| *name).collect::<Vec<_>>().join(", ");
    match value.get_ref() {
        toml::Value::String(s) => names
            .iter()
            .find(|(name, _)| name.eq_ignore_ascii_case(s.trim()))
            .map(|(_, v)| *v)
            .ok_or_else(|| (value.span(), format!("{key}: '{s}' is none of {}", expected()))),
        other => Err((value.span(), format!("{key}: one of {} in quotes, not a {}", expected(), other.type_str()))),
    }
}

/// `A` or `A-B`, each by the one number grammar ([`ferrobus::text::number`]: decimal or 0x hex).
fn range(text: &str) -> Result<(i64, i64), String> {
    let (a, b) = text.split_once('-').unwrap_or((text, text));
    let number = |s: &str| {
        ferrobus::text::number(s, i64::MAX.unsigned_abs())
            .map(|n| i64::try_from(n).unwrap_or(i64::MAX))
            .map_err(|_| format!("'{}' is neither a unit nor a range A-B", ferrobus::log::escape(text)))
    };
    Ok((number(a)?, number(b)?))
}

/// A unit a client addresses, or one on the line: 1-255 (0 is the broadcast, sent to every
/// serial line).
fn unit_number(n: i64) -> Result<u8, String> {
    match u8::try_from(n) {
        Ok(0) => Err("unit 0 is the broadcast, sent to every serial line; route units 1-255 (a tcp line alone \
                      takes every unit id, 0 among them)"
            .into()),
        Ok(unit) => Ok(unit),
        Err(_) => Err(format!("{n} is no unit: units are 1-255")),
    }
}

/// A range of units, first to last.
fn client_units(first: i64, last: i64) -> Result<(u8, u8), String> {
    let (a, b) = (unit_number(first)?, unit_number(last)?);
    if a > b {
        return Err(format!("the range {a}-{b} runs backwards"));
    }
    Ok((a, b))
}

/// The units of one `units` item.
fn units(item: &Spanned<Item>) -> Result<(u8, u8), String> {
    let (first, last) = match item.get_ref() {
        Item::Number(n) => (*n, *n),
        Item::Text(t) => range(t)?,
    };
    client_units(first, last)
}

#[cfg(test)]
mod tests;
