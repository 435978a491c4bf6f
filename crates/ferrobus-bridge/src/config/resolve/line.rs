//! A `[[line]]`: its connection, the client's settings, and the ids and units of its devices.

use std::collections::HashMap;
use std::ops::Range;

use ferrobus::{ClientConfig, Rs485, SerialConfig};
use ferrobus_proto::frame::{DataBits, LineConfig, Parity, StopBits};
use ferrobus_proto::master::pipeline::MAX_IN_FLIGHT;
use toml::Spanned;

use super::super::raw::{self, Text};
use super::super::text::{duration, host_port};
use super::super::{Connection, LineMode, LineSpec};
use super::{Cx, device};

/// Device ids (plant-wide) and line names seen so far, with where.
#[derive(Default)]
pub(super) struct Ids {
    devices: HashMap<String, Range<usize>>,
    lines: HashMap<String, Range<usize>>,
}

/// Registers `name` in `seen`; a name seen before is reported at its second place, as
/// `said` (`device id "pump"`) with the `rule` it breaks.
fn first_use(cx: &mut Cx<'_>, seen: &mut HashMap<String, Range<usize>>, name: &Text, said: &str, rule: &str) {
    if let Some(first) = seen.get(name.get_ref()) {
        let line = cx.line_of(first);
        cx.at(name.span(), format!("{said} is used twice (first at line {line}); {rule}"));
    } else {
        seen.insert(name.get_ref().clone(), name.span());
    }
}

pub(super) fn resolve(cx: &mut Cx<'_>, line: &raw::Line, devices: &[raw::Device], ids: &mut Ids) -> Option<LineSpec> {
    let name = line.name.get_ref();
    first_use(cx, &mut ids.lines, &line.name, &format!("line name {name:?}"), "each line has its own");
    let connection = resolve_connection(cx, line);
    let client = resolve_client(cx, line);
    let mode = resolve_mode(cx, line, devices);
    let simulated = matches!(connection, Some(Connection::Simulated { .. }));
    let mut units: HashMap<String, Range<usize>> = HashMap::new();
    let mut specs = Vec::new();
    for device in devices {
        let id = device.id.get_ref();
        first_use(cx, &mut ids.devices, &device.id, &format!("device id {id:?}"), "ids are unique in a plant");
        let unit = Spanned::new(device.unit.span(), device.unit.get_ref().to_string());
        let said = format!("unit {}", unit.get_ref());
        first_use(cx, &mut units, &unit, &said, "each device on a line has its own");
        if let Some(spec) = device::resolve(cx, device) {
            if simulated && spec.profile.is_none() {
                cx.at(
                    device.id.span(),
                    format!(
                        "device {:?}: a simulated line simulates each device from its profile; give it one",
                        spec.id
                    ),
                );
            }
            specs.push(spec);
        }
    }
    let (connection, client, mode) = (connection?, client?, mode?);
    Some(LineSpec { name: line.name.get_ref().clone(), connection, client, mode, devices: specs })
}

/// `mode`: `poll` (the default) or `listen`. A listen line is a serial RTU port that is never
/// written: what needs transmitting (the client's timing, poll rates) is refused where it is
/// written, saying why.
fn resolve_mode(cx: &mut Cx<'_>, line: &raw::Line, devices: &[raw::Device]) -> Option<LineMode> {
    let Some(mode) = &line.mode else { return Some(LineMode::Poll) };
    match mode.get_ref().to_ascii_lowercase().as_str() {
        "poll" => return Some(LineMode::Poll),
        "listen" => {}
        other => {
            cx.at(mode.span(), format!("mode = {other:?}: a line's mode is poll (the default) or listen"));
            return None;
        }
    }
    let errors = cx.errors.len();
    let name = line.name.get_ref();
    let other = [("tcp", line.tcp.as_ref()), ("rtu_tcp", line.rtu_tcp.as_ref())];
    if let Some((key, _)) = other.iter().find(|(_, v)| v.is_some()) {
        cx.at(mode.span(), format!("line {name:?} listens: that is a serial port's, not {key}'s; give port"));
    }
    if line.simulated.as_ref().is_some_and(|s| *s.get_ref()) {
        cx.at(mode.span(), format!("line {name:?} listens: a simulated line has no master of its own to listen to"));
    }
    if let Some(ascii) = line.ascii.as_ref().filter(|a| *a.get_ref()) {
        cx.at(ascii.span(), "ascii: a listen line decodes RTU only");
    }
    let never = |key: &str| format!("{key}: a listen line never transmits, so it has no {key}; leave it out");
    let timing = [
        ("timeout", line.timeout.as_ref().map(Spanned::span)),
        ("retries", line.retries.as_ref().map(Spanned::span)),
        ("connect_timeout", line.connect_timeout.as_ref().map(Spanned::span)),
        ("late_window", line.late_window.as_ref().map(Spanned::span)),
        ("echo_suppression", line.echo_suppression.map(|_| mode.span())),
    ];
    for (key, span) in timing {
        if let Some(span) = span {
            cx.at(span, never(key));
        }
    }
    let pace = "a listen line publishes each value as its master reads it, at the master's pace; leave it out";
    for device in devices {
        let rates = device.every.iter().map(Spanned::span).chain(device.poll.iter().map(Spanned::span));
        let raw_rates = device.raw.iter().filter_map(|r| r.get_ref().every.as_ref().map(Spanned::span));
        for span in rates.chain(raw_rates).collect::<Vec<_>>() {
            cx.at(span, format!("a poll rate: {pace} (points and groups name what is published)"));
        }
    }
    (cx.errors.len() == errors).then_some(LineMode::Listen)
}

/// Exactly one of `port`, `tcp`, `rtu_tcp` and `simulated = true`, with the keys it takes.
fn resolve_connection(cx: &mut Cx<'_>, line: &raw::Line) -> Option<Connection> {
    let mut kinds: Vec<(&str, Range<usize>)> = Vec::new();
    if let Some(p) = &line.port {
        kinds.push(("port", p.span()));
    }
    if let Some(t) = &line.tcp {
        kinds.push(("tcp", t.span()));
    }
    if let Some(t) = &line.rtu_tcp {
        kinds.push(("rtu_tcp", t.span()));
    }
    if let Some(s) = line.simulated.as_ref().filter(|s| *s.get_ref()) {
        kinds.push(("simulated", s.span()));
    }
    kinds.sort_by_key(|(_, span)| span.start);
    let name = line.name.get_ref();
    let kind = match kinds.as_slice() {
        [] => {
            cx.at(
                line.name.span(),
                format!("line {name:?} has no connection; give one of port, tcp, rtu_tcp or simulated = true"),
            );
            return None;
        }
        [(kind, _)] => *kind,
        [(first, _), (second, span), ..] => {
            cx.at(span.clone(), format!("line {name:?} has both {first} and {second}; a line has one connection"));
            return None;
        }
    };
    refuse_serial_keys(cx, line, kind);
    match kind {
        "port" => serial(cx, line),
        "simulated" => line_config(cx, line).map(|line| Connection::Simulated { line }),
        "tcp" => tcp_address(cx, "tcp", line.tcp.as_ref()?).map(Connection::Tcp),
        _ => tcp_address(cx, "rtu_tcp", line.rtu_tcp.as_ref()?).map(Connection::RtuTcp),
    }
}

/// The serial keys on a line that is not a port (baud is also a simulated line's).
fn refuse_serial_keys(cx: &mut Cx<'_>, line: &raw::Line, kind: &str) {
    let spans = [
        ("parity", line.parity.as_ref().map(Spanned::span)),
        ("data_bits", line.data_bits.as_ref().map(Spanned::span)),
        ("stop_bits", line.stop_bits.as_ref().map(Spanned::span)),
        ("rs485", line.rs485.as_ref().map(Spanned::span)),
        ("low_latency", line.low_latency.as_ref().map(Spanned::span)),
        ("ascii", line.ascii.as_ref().map(Spanned::span)),
        ("baud", line.baud.as_ref().map(Spanned::span).filter(|_| kind != "simulated")),
    ];
    if kind == "port" {
        return;
    }
    for (key, span) in spans {
        if let Some(span) = span {
            cx.at(span, format!("{key} is a serial port's setting; this line is {kind}"));
        }
    }
}

fn tcp_address(cx: &mut Cx<'_>, key: &str, address: &Text) -> Option<String> {
    match host_port(address.get_ref(), 502) {
        Ok((host, port)) if host.contains(':') => Some(format!("[{host}]:{port}")),
        Ok((host, port)) => Some(format!("{host}:{port}")),
        Err(problem) => {
            cx.at(address.span(), format!("{key}: {problem}"));
            None
        }
    }
}

fn serial(cx: &mut Cx<'_>, line: &raw::Line) -> Option<Connection> {
    let path = line.port.as_ref()?;
    if path.get_ref().trim().is_empty() {
        cx.at(path.span(), "port is empty; name the serial port (\"/dev/ttyUSB0\", \"COM3\")");
    }
    let rs485 = match line.rs485.as_ref() {
        None => Some(Rs485::Auto),
        Some(r) => match r.get_ref().to_ascii_lowercase().as_str() {
            "auto" => Some(Rs485::Auto),
            "kernel" => Some(Rs485::Kernel),
            "rts" => Some(Rs485::Rts),
            _ => {
                cx.at(r.span(), format!("rs485 = {:?}: it is auto (the adapter), kernel or rts", r.get_ref()));
                None
            }
        },
    };
    let config = line_config(cx, line);
    let mut serial = SerialConfig::new(path.get_ref().clone(), config?);
    serial.rs485 = rs485?;
    serial.low_latency = line.low_latency.as_ref().is_some_and(|l| *l.get_ref());
    Some(Connection::Serial { config: serial, ascii: line.ascii.as_ref().is_some_and(|a| *a.get_ref()) })
}

/// Baud (19200 unless given), parity (even), data bits (8, or 7 with ascii) and stop bits
/// (1, as the command line's default: the spec asks for 2 without parity, most 8N1 devices
/// do not).
fn line_config(cx: &mut Cx<'_>, line: &raw::Line) -> Option<LineConfig> {
    let errors = cx.errors.len();
    let baud = line.baud.as_ref().map_or(Some(19_200), |b| {
        let baud = u32::try_from(*b.get_ref()).ok().filter(|baud| (50..=10_000_000).contains(baud));
        if baud.is_none() {
            cx.at(b.span(), format!("baud = {}: a line's baud is 50 to 10000000", b.get_ref()));
        }
        baud
    });
    let parity = line.parity.as_ref().map_or(Parity::Even, |p| match p.get_ref().to_ascii_lowercase().as_str() {
        "even" | "e" => Parity::Even,
        "odd" | "o" => Parity::Odd,
        "none" | "n" => Parity::None,
        _ => {
            cx.at(p.span(), format!("parity = {:?}: it is even, odd or none", p.get_ref()));
            Parity::Even
        }
    });
    let ascii = line.ascii.as_ref().is_some_and(|a| *a.get_ref());
    let data_bits = match line.data_bits.as_ref().map(|d| (d, *d.get_ref())) {
        None if ascii => DataBits::Seven,
        None | Some((_, 8)) => DataBits::Eight,
        Some((_, 7)) => DataBits::Seven,
        Some((d, n)) => {
            cx.at(d.span(), format!("data_bits = {n}: it is 8 (RTU) or 7 (ASCII)"));
            DataBits::Eight
        }
    };
    let stop_bits = match line.stop_bits.as_ref().map(|s| (s, *s.get_ref())) {
        None | Some((_, 1)) => StopBits::One,
        Some((_, 2)) => StopBits::Two,
        Some((s, n)) => {
            cx.at(s.span(), format!("stop_bits = {n}: it is 1 or 2"));
            StopBits::One
        }
    };
    let config = LineConfig::new(baud?)?.with_parity(parity).with_data_bits(data_bits).with_stop_bits(stop_bits);
    (cx.errors.len() == errors).then_some(config)
}

/// The client's timeout, retries, connect timeout, late window and requests in flight (the
/// library's defaults unless given).
fn resolve_client(cx: &mut Cx<'_>, line: &raw::Line) -> Option<ClientConfig> {
    let errors = cx.errors.len();
    let mut client = ClientConfig::default();
    if let Some(timeout) = line.timeout.as_ref().and_then(|t| cx.period("timeout", t)) {
        client.timeout = timeout;
    }
    if let Some(timeout) = line.connect_timeout.as_ref().and_then(|t| cx.period("connect_timeout", t)) {
        client.connect_timeout = timeout;
    }
    if let Some(window) = &line.late_window {
        // Zero is a choice: a late reply is not waited for (it is still never taken for another).
        match duration(window.get_ref()) {
            Ok(window) => client.late_window = Some(window),
            Err(problem) => cx.at(window.span(), format!("late_window: {problem}")),
        }
    }
    if let Some(retries) = &line.retries {
        match u32::try_from(*retries.get_ref()) {
            Ok(r @ 0..=100) => client.retries = r,
            _ => cx.at(retries.span(), format!("retries = {}: it is 0 to 100", retries.get_ref())),
        }
    }
    if let Some(echo) = line.echo_suppression {
        client.echo_suppression = echo;
    }
    if let Some(in_flight) = &line.in_flight {
        let n = *in_flight.get_ref();
        match usize::try_from(n) {
            _ if line.tcp.is_none() => cx.at(
                in_flight.span(),
                "in_flight: only a Modbus/TCP line (tcp) matches replies to requests by transaction id; every \
                 other line carries one request at a time",
            ),
            Ok(n @ 1..=MAX_IN_FLIGHT) => client.in_flight = n,
            _ => cx.at(in_flight.span(), format!("in_flight = {n}: it is 1 to {MAX_IN_FLIGHT}")),
        }
    }
    (cx.errors.len() == errors).then_some(client)
}
