//! `gateway --lines-file FILE`: the gateway's serial lines, each with its own settings and the
//! units it serves, from a TOML file of `[[line]]` tables.
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
//! ```
//!
//! The keys are the line options of the command line under their long names (`data-bits`): `port`, `ascii`, `baud`, `parity`, `data-bits`, `stop-bits`, `rs485`,
//! `low-latency`, `timeout`, `retries`, `t15`, `t35`, `turnaround`, `echo`, `reopen`, the
//! gateway's `queue` and `late-guard`, and `response-wait`, which the line options lack: the
//! time the devices of the line hold their reply, added to the line's reply timeout. A line's
//! routes are `units` (numbers and `"A-B"` ranges) and `renumber` (client units to the units
//! on the line; a range to a range of the same length, or to its first unit). Durations are
//! strings such as `"300ms"`, or whole numbers of milliseconds.
//!
//! Precedence: a key of a `[[line]]` beats the same option given on the command line (or from
//! the settings file's `[defaults]` or `--conn`), which is what every line of the file starts
//! from. The lines themselves and their routes come from the file alone: `--port`, `--line`
//! and `--route` are refused beside it, so the command line and the file cannot name two
//! different sets of lines or send a unit two ways.
//!
//! The whole file is checked before any port is opened. An error names the file, the line and
//! column, the `[[line]]` (numbered from 0, as the gateway numbers its lines) and the key: an
//! unknown key, a value of the wrong type or out of range, a port given twice, a unit routed
//! twice (with where it was routed first), a line with no units when there are several, or
//! with empty `units` and `renumber`.

use std::collections::BTreeMap;
use std::ops::Range;
use std::path::Path;
use std::time::Duration;

use clap::ValueEnum;
use ferrobus::Backoff;
use ferrobus::gateway::{GatewayLine, Route, Routes};
use ferrobus_profile::source::{self, Located, Place, ReadError};
use serde::Deserialize;
use toml::Spanned;

use crate::connect::{ConnectArgs, ParityArg, Rs485Arg, Target, parse_duration};
use crate::exit::CliError;

/// What every line of the file takes from the gateway's own options.
#[derive(Clone, Copy, Debug)]
pub(super) struct Base {
    /// `--backoff-after`, `--backoff-skip`, `--backoff-max`.
    pub(super) backoff: Option<Backoff>,
    /// `--queue`, unless the line says `queue`.
    pub(super) queue: usize,
    /// `--late-guard`, unless the line says `late-guard`.
    pub(super) late_guard: Duration,
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
    units: Option<Vec<Spanned<Item>>>,
    renumber: Option<BTreeMap<Spanned<String>, Spanned<Item>>>,
}

/// A unit or a range of units: `5`, `"1-10"` (decimal or 0x hex).
#[derive(Deserialize)]
#[serde(untagged)]
enum Item {
    Number(i64),
    Text(String),
}

/// What is wrong, and where in the file.
type Problem = (Range<usize>, String);

/// Reads `path`: the lines, with their settings on top of `connection`'s and `base`'s, and
/// the routes. Nothing is opened.
pub(super) fn read(path: &Path, connection: &ConnectArgs, base: Base) -> Result<(Vec<GatewayLine>, Routes), CliError> {
    let text = source::read(path).map_err(|e| match e {
        ReadError::Io(e) => CliError::Usage(format!("cannot read the lines file {}: {e}", path.display())),
        not_text @ ReadError::NotText(_) => CliError::Usage(not_text.located().in_file(&path.display().to_string())),
    })?;
    parse(path, &text, connection, base)
}

/// Line and column (both from 1) of a byte offset.
fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let place = Place::of(text, offset);
    (place.line, place.column)
}

/// Parses and checks the text of a lines file.
pub(super) fn parse(
    path: &Path,
    text: &str,
    connection: &ConnectArgs,
    base: Base,
) -> Result<(Vec<GatewayLine>, Routes), CliError> {
    let shown = path.display().to_string();
    let at = |span: Range<usize>, what: &str| CliError::Usage(Located::new(text, Some(span), what).in_file(&shown));
    let shape: FileShape =
        toml::from_str(text).map_err(|e| CliError::Usage(Located::toml(text, &e).in_file(&shown)))?;
    if shape.line.is_empty() {
        return Err(CliError::Usage(format!(
            "{}: no [[line]] table: give one per serial port, with its port = \"/dev/ttyUSB0\" and its units",
            path.display()
        )));
    }
    let several = shape.line.len() > 1;
    let mut lines = Vec::with_capacity(shape.line.len());
    let mut ports: Vec<(String, usize)> = Vec::new();
    // Where each client unit was routed first: its line and the place in the file.
    let mut first_seen: Vec<Option<(usize, usize)>> = vec![None; 256];
    let mut routes = Routes::new();
    for (index, table) in shape.line.iter().enumerate() {
        let what = |(span, message): Problem| at(span, &format!("[[line]] {index}, {message}"));
        let line = table.get_ref();
        let (config, port) = settings(table.span(), line, connection, base).map_err(what)?;
        if let Some((_, first)) = ports.iter().find(|(p, _)| *p == port.0) {
            let (row, col) = line_col(text, *first);
            let message = format!("port: {} is a line already ({}:{row}:{col})", port.0, path.display());
            return Err(what((port.1, message)));
        }
        ports.push((port.0, port.1.start));
        let mut route = |unit: u8, out: u8, span: &Range<usize>| -> Result<(), Problem> {
            let slot = first_seen
                .get_mut(usize::from(unit))
                .ok_or_else(|| (span.clone(), format!("unit {unit}: no such unit")))?;
            if let Some((other, first)) = *slot {
                let (row, col) = line_col(text, first);
                let first = format!("{}:{row}:{col}", path.display());
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
            routes = Routes::all_on(0);
        }
        lines.push(config);
    }
    Ok((lines, routes))
}

/// One line's settings: `connection`'s, with the table's keys on top. Its port and place too.
fn settings(
    table: Range<usize>,
    line: &LineShape,
    connection: &ConnectArgs,
    base: Base,
) -> Result<(GatewayLine, (String, Range<usize>)), Problem> {
    let Some(port) = &line.port else {
        return Err((table, "no port: give the serial port, e.g. port = \"/dev/ttyUSB0\"".into()));
    };
    let path = match port.get_ref() {
        toml::Value::String(s) if !s.trim().is_empty() => s.clone(),
        toml::Value::String(_) => return Err((port.span(), "port: the path is empty".into())),
        other => return Err((port.span(), format!("port: a path in quotes, not a {}", other.type_str()))),
    };
    let mut args = connection.clone();
    args.port = Some(path.clone());
    args.tcp = None;
    args.rtu_tcp = None;
    if let Some(v) = &line.ascii {
        args.ascii = flag(v, "ascii")?;
    }
    if let Some(v) = &line.baud {
        let baud = number(v, "baud", 1, u32::MAX.into(), "bits per second, 1 or more, e.g. 9600")?;
        args.baud = u32::try_from(baud).map_err(|_| (v.span(), "baud: too high".to_string()))?;
    }
    if let Some(v) = &line.parity {
        args.parity = choice::<ParityArg>(v, "parity")?;
    }
    if let Some(v) = &line.data_bits {
        args.data_bits = if number(v, "data-bits", 7, 8, "7 or 8")? == 7 { 7 } else { 8 };
    }
    if let Some(v) = &line.stop_bits {
        args.stop_bits = if number(v, "stop-bits", 1, 2, "1 or 2")? == 1 { 1 } else { 2 };
    }
    if let Some(v) = &line.rs485 {
        args.rs485 = choice::<Rs485Arg>(v, "rs485")?;
    }
    if let Some(v) = &line.low_latency {
        args.low_latency = flag(v, "low-latency")?;
    }
    if let Some(v) = &line.timeout {
        let timeout = duration(v, "timeout")?;
        if timeout.is_zero() {
            return Err((v.span(), "timeout: 0 gives up before any reply can come; e.g. \"500ms\"".into()));
        }
        args.timeout = timeout;
    }
    if let Some(v) = &line.retries {
        let retries = number(v, "retries", 0, u32::MAX.into(), "a count, 0 or more")?;
        args.retries = u32::try_from(retries).map_err(|_| (v.span(), "retries: too many".to_string()))?;
    }
    if let Some(v) = &line.t15 {
        args.t15 = Some(duration(v, "t15")?);
    }
    if let Some(v) = &line.t35 {
        args.t35 = Some(duration(v, "t35")?);
    }
    if let Some(v) = &line.turnaround {
        args.turnaround = Some(duration(v, "turnaround")?);
    }
    if let Some(v) = &line.echo {
        args.echo = flag(v, "echo")?;
    }
    if let Some(v) = &line.reopen {
        args.no_reopen = !flag(v, "reopen")?;
    }
    let response_wait = line.response_wait.as_ref().map(|v| duration(v, "response-wait")).transpose()?;
    let queue = match &line.queue {
        Some(v) => {
            let queue = number(v, "queue", 1, i64::from(u32::MAX), "the requests that may wait, 1 or more")?;
            usize::try_from(queue).map_err(|_| (v.span(), "queue: too long".to_string()))?
        }
        None => base.queue,
    };
    let late_guard = line.late_guard.as_ref().map(|v| duration(v, "late-guard")).transpose()?;
    if args.data_bits == 7 && !args.ascii {
        let span = line.data_bits.as_ref().map_or(table, Spanned::span);
        return Err((span, "data-bits: 7 only with ascii = true (RTU needs 8 data bits)".into()));
    }
    let target = Target::Serial { path: path.clone(), line: args.line(), ascii: args.ascii };
    let mut client = args.client_config();
    client.backoff = base.backoff;
    if let Some(wait) = response_wait {
        client.timeout = client.timeout.saturating_add(wait);
    }
    let config = GatewayLine {
        queue,
        late_guard: late_guard.unwrap_or(base.late_guard),
        ..GatewayLine::new(args.transport(&target), client)
    };
    Ok((config, (path, port.span())))
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

/// A duration: `"300ms"`, `"1.5s"`, or a whole number of milliseconds.
fn duration(value: &Spanned<toml::Value>, key: &str) -> Result<Duration, Problem> {
    let text = match value.get_ref() {
        toml::Value::String(s) => s.clone(),
        toml::Value::Integer(n) if *n >= 0 => n.to_string(),
        toml::Value::Integer(n) => return Err((value.span(), format!("{key}: {n} is negative"))),
        other => {
            return Err((value.span(), format!("{key}: a duration such as \"300ms\", not a {}", other.type_str())));
        }
    };
    parse_duration(&text).map_err(|e| (value.span(), format!("{key}: {e}")))
}

/// One of the names of a command-line value enum (`even`, `odd`, `none`).
fn choice<T: ValueEnum>(value: &Spanned<toml::Value>, key: &str) -> Result<T, Problem> {
    let names: Vec<String> =
        T::value_variants().iter().filter_map(|v| v.to_possible_value().map(|p| p.get_name().to_string())).collect();
    let expected = || names.join(", ");
    match value.get_ref() {
        toml::Value::String(s) => {
            T::from_str(s, true).map_err(|_| (value.span(), format!("{key}: '{s}' is none of {}", expected())))
        }
        other => Err((value.span(), format!("{key}: one of {} in quotes, not a {}", expected(), other.type_str()))),
    }
}

/// `A` or `A-B`, each decimal or 0x hex.
fn range(text: &str) -> Result<(i64, i64), String> {
    let (a, b) = text.split_once('-').unwrap_or((text, text));
    let number = |s: &str| {
        let s = s.trim();
        let parsed = match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
            Some(hex) => i64::from_str_radix(hex, 16),
            None => s.parse(),
        };
        parsed.map_err(|_| format!("'{text}' is neither a unit nor a range A-B"))
    };
    Ok((number(a)?, number(b)?))
}

/// A unit a client addresses, or one on the line: 1-255 (0 is the broadcast, sent to every line).
fn unit_number(n: i64) -> Result<u8, String> {
    match u8::try_from(n) {
        Ok(0) => Err("unit 0 is the broadcast, sent to every line; route units 1-255".into()),
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
