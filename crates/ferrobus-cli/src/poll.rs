//! `ferrobus poll`: read groups of registers or named points for ever, each at its own rate,
//! and write one record per poll — a table refreshed in place on a terminal, else CSV or JSON
//! lines — optionally to a rotated log file; a summary on Ctrl-C or SIGTERM.
//!
//! What to poll is written as groups, in the order given: `--unit 3 holding 0x1000 --count 4
//! --every 100ms --unit 5 input 0 --every 1s`; a `--count`, `--every` or `--format` after a group
//! is that group's, before the first group every group's. With `--device PROFILE`, names
//! (codes, labels, globs) and `--group`s are named points, read in the profile planner's
//! fewest requests. `--session FILE` adds the groups of a session file (what `monitor`
//! saves). The scheduling, the failure kinds and the counters are the library's
//! ([`ferrobus_tools::poll`]); this file turns its samples into records.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::io::{IsTerminal, Write as _};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use clap::Args;
use ferrobus::Client;
use ferrobus_tools::poll::session::{Session, period};
use ferrobus_tools::poll::{Event, FailureKind, Format, Group, Layout, Order, PollConfig, Poller, Sample, iso8601_ms};
use serde_json::json;

use crate::address::{AddressArgs, RangeWord};
use crate::connect::{ConnectArgs, parse_duration};
use crate::exit::CliError;
use crate::interrupt::Interrupt;
use crate::metrics::{self, MetricsArgs};
use crate::output;

mod status;

use status::{Latest, PollStatus};

/// `poll [--unit N] TABLE ADDRESS [--count N] [--every D] ... | NAME...`.
#[derive(Args, Debug)]
#[command(after_help = "Examples:\n  \
     ferrobus --port /dev/ttyUSB0 poll --unit 3 holding 0x1000 --count 4 --every 100ms --unit 5 input 0 --every 1s\n  \
     ferrobus --port /dev/ttyUSB0 --device omron-3g3rx poll d001 d002 --every 200ms --csv --log run.csv\n  \
     ferrobus --tcp 10.0.0.5 poll --session line3.toml --jsonl --on-change --deadband 0.5\n\n\
     TABLE is holding, input, coils or discrete; ADDRESS a wire address (0x1000 or 4096), numbered as read and \
     write number it: --one-based, --modicon, or the --device profile's numbering (the 3G3RX's from 1). \
     TABLE:ADDRESS[:COUNT] in one word is the same group (monitor's form). A group longer than the device takes \
     in one request (the profile's limit) is read in several. A --count, --every or --format given after a group \
     is that group's; given before the first group, every group's (defaults: 1, 1s, \
     u16). A --unit applies to the groups after it. Records: CSV has one row per point of each poll (a failed \
     poll: one row, its point the group's name); JSON lines one object per poll. status is ok, timeout, crc, \
     garbage, exception, bad-reply, port, backoff or other. The summary goes to stderr.")]
#[expect(clippy::struct_excessive_bools, reason = "each bool is a command-line flag or one fact about them")]
pub(crate) struct PollArgs {
    /// Groups: TABLE ADDRESS pairs or TABLE:ADDRESS[:COUNT]; with --device, also parameter
    /// names (codes, labels, globs)
    #[arg(value_name = "TABLE ADDRESS | NAME", allow_hyphen_values = false)]
    pub(crate) what: Vec<String>,

    /// How ADDRESS is numbered.
    #[command(flatten)]
    pub(crate) address_args: AddressArgs,

    /// Items a group reads (registers or bits)
    #[arg(long, value_name = "N", action = clap::ArgAction::Append)]
    pub(crate) count: Vec<u16>,

    /// A group's period: 100ms, 1s, 250us, 2min (a plain number is ms), at most a day
    #[arg(long, value_name = "DURATION", value_parser = parse_period, action = clap::ArgAction::Append)]
    pub(crate) every: Vec<Duration>,

    /// A raw group's cell format: u16, i16, hex, binary, u32, i32, f32, f64
    #[arg(long, value_name = "FORMAT", action = clap::ArgAction::Append)]
    pub(crate) format: Vec<String>,

    /// The byte order of u32, i32, f32 and f64 cells over their registers: ABCD or high-first,
    /// CDAB or low-first, BADC, DCBA (case-insensitive; as read's --word-order)
    #[arg(long, visible_alias = "word-order", value_name = "ORDER", default_value = "ABCD", value_parser = crate::value::parse_word_order)]
    pub(crate) order: Order,

    /// With --device: every point of this profile group (repeatable)
    #[arg(long, value_name = "GROUP")]
    pub(crate) group: Vec<String>,

    /// Poll the groups of a session file too (TOML; `monitor` saves the same format)
    #[arg(long, value_name = "FILE")]
    pub(crate) session: Option<PathBuf>,

    /// With --tcp: groups read at once on the connection (1 to 16), each request matched to
    /// its reply by transaction id; 1 reads one group at a time. More hides the round trip for a
    /// device that answers every request of its connection in order (as gateway --in-flight)
    #[arg(long = "in-flight", value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=16))]
    pub(crate) in_flight: u32,

    /// CSV records on stdout (the default when stdout is not a terminal)
    #[arg(long, conflicts_with = "jsonl")]
    pub(crate) csv: bool,

    /// JSON lines on stdout: one object per poll
    #[arg(long)]
    pub(crate) jsonl: bool,

    /// Also write the records to FILE (CSV, or JSON lines with --jsonl)
    #[arg(long, value_name = "FILE")]
    pub(crate) log: Option<PathBuf>,

    /// Rotate the log when it reaches this size: 10MB, 500kB, 1GB (powers of 1000), 10MiB
    /// (powers of 1024) or bytes
    #[arg(long = "rotate-size", value_name = "SIZE", value_parser = parse_size, requires = "log")]
    pub(crate) rotate_size: Option<u64>,

    /// Rotate the log after this many records
    #[arg(long = "rotate-records", value_name = "N", requires = "log")]
    pub(crate) rotate_records: Option<u64>,

    /// Rotated logs kept (FILE.1 is the newest)
    #[arg(long, value_name = "N", default_value_t = 5, requires = "log")]
    pub(crate) keep: u32,

    /// Write a point's record only when its value moves by more than --deadband or its status
    /// changes
    #[arg(long = "on-change")]
    pub(crate) on_change: bool,

    /// With --on-change: a scaled value is written when it moves by more than this (a NaN
    /// after a number and a number after a NaN are written, a NaN after a NaN is not)
    #[arg(long, value_name = "X", default_value_t = 0.0, requires = "on_change", value_parser = parse_deadband)]
    pub(crate) deadband: f64,

    /// Stop after this long (scripts, tests); default: until Ctrl-C or SIGTERM
    #[arg(long, value_name = "DURATION", value_parser = parse_duration)]
    pub(crate) duration: Option<Duration>,

    #[command(flatten)]
    pub(crate) metrics: MetricsArgs,

    /// The command line's groups, from the positions of their arguments (set by `main`).
    #[arg(skip)]
    pub(crate) positions: Vec<(usize, Token)>,

    /// `--unit` was written both before and after `poll` (set by `main`): clap keeps only the
    /// later ones, so the earlier would be lost.
    #[arg(skip)]
    pub(crate) units_on_both_sides: bool,
}

/// One argument of the group list, by position.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Token {
    /// `--unit N`.
    Unit(u8),
    /// A positional word.
    What(String),
    /// `--count N`.
    Count(u16),
    /// `--every D`.
    Every(Duration),
    /// `--format F`.
    Format(String),
}

fn parse_period(text: &str) -> Result<Duration, String> {
    period(Some(text)).map_err(|e| e.to_string())
}

fn parse_deadband(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(x) if x.is_finite() && x >= 0.0 => Ok(x),
        _ => Err(format!("{text:?}: give a number, 0 or more")),
    }
}

/// `--rotate-size`: a size by the one grammar ([`ferrobus::text::size`]: kB, MB, GB are
/// powers of 1000, KiB, MiB, GiB of 1024), above zero.
fn parse_size(text: &str) -> Result<u64, String> {
    match ferrobus::text::size(text).map_err(|e| e.to_string())? {
        0 => Err(format!("'{}': a log cannot rotate at 0 bytes; give e.g. 10MB", ferrobus::log::escape(text.trim()))),
        n => Ok(n),
    }
}

impl PollArgs {
    /// Records the positions of the group arguments: `--unit`s (global, so from `matches` or
    /// `sub`), words, `--count`, `--every`, `--format`.
    pub(crate) fn positions_from(&mut self, sub: &clap::ArgMatches) {
        let mut tokens: Vec<(usize, Token)> = Vec::new();
        let given = sub.value_source("unit") == Some(clap::parser::ValueSource::CommandLine);
        if given && let (Some(at), Some(units)) = (sub.indices_of("unit"), sub.get_many::<u8>("unit")) {
            tokens.extend(at.zip(units).map(|(i, u)| (i, Token::Unit(*u))));
        }
        if let Some(at) = sub.indices_of("what") {
            tokens.extend(at.zip(&self.what).map(|(i, w)| (i, Token::What(w.clone()))));
        }
        if let Some(at) = sub.indices_of("count") {
            tokens.extend(at.zip(&self.count).map(|(i, c)| (i, Token::Count(*c))));
        }
        if let Some(at) = sub.indices_of("every") {
            tokens.extend(at.zip(&self.every).map(|(i, e)| (i, Token::Every(*e))));
        }
        if let Some(at) = sub.indices_of("format") {
            tokens.extend(at.zip(&self.format).map(|(i, f)| (i, Token::Format(f.clone()))));
        }
        tokens.sort_by_key(|(i, _)| *i);
        self.positions = tokens;
        let argv: Vec<String> = std::env::args_os().map(|a| a.to_string_lossy().into_owned()).collect();
        self.units_on_both_sides = units_on_both_sides(&argv);
    }
}

/// Whether `argv` has a `--unit` (or `-u`) both before and after the word `poll`.
fn units_on_both_sides(argv: &[String]) -> bool {
    let is_unit = |a: &&String| {
        a.as_str() == "--unit" || a.starts_with("--unit=") || (a.starts_with("-u") && !a.starts_with("--"))
    };
    let Some(at) = argv.iter().position(|a| a == "poll") else { return false };
    let before = argv.get(1..at).unwrap_or_default().iter().any(|a| is_unit(&a));
    let after = argv.get(at.saturating_add(1)..).unwrap_or_default().iter().any(|a| is_unit(&a));
    before && after
}

/// A group as the command line gives it, before it is checked.
#[derive(Debug, Default)]
struct Spec {
    unit: u8,
    /// A raw range (its address as typed, numbered later), or named points.
    raw: Option<(crate::address::Table, String)>,
    names: Vec<String>,
    count: Option<u16>,
    every: Option<Duration>,
    format: Option<String>,
}

/// The groups of the command line, in order.
fn specs(args: &PollArgs, first_unit: u8) -> Result<Vec<Spec>, CliError> {
    let mut specs: Vec<Spec> = Vec::new();
    let mut defaults = Spec::default();
    let mut unit = first_unit;
    let mut table: Option<crate::address::Table> = None;
    let twice = |what: &str| CliError::Usage(format!("{what} is given twice for one group"));
    for (_, token) in &args.positions {
        match token {
            Token::Unit(u) => unit = *u,
            Token::What(word) => {
                if let Some(t) = table.take() {
                    specs.push(Spec { unit, raw: Some((t, word.clone())), ..Spec::default() });
                } else if let Some(t) = crate::address::Table::from_name(word) {
                    table = Some(t);
                } else if let Some(range) = RangeWord::parse(word) {
                    let range = range?;
                    let raw = Some((range.table, range.address.to_string()));
                    specs.push(Spec { unit: range.unit.unwrap_or(unit), raw, count: range.count, ..Spec::default() });
                } else {
                    match specs.last_mut() {
                        Some(last)
                            if last.raw.is_none()
                                && last.unit == unit
                                && last.count.is_none()
                                && last.every.is_none() =>
                        {
                            last.names.push(word.clone());
                        }
                        _ => specs.push(Spec { unit, names: vec![word.clone()], ..Spec::default() }),
                    }
                }
            }
            Token::Count(c) => {
                let s = specs.last_mut().unwrap_or(&mut defaults);
                if s.count.replace(*c).is_some() {
                    return Err(twice("--count"));
                }
            }
            Token::Every(e) => {
                let s = specs.last_mut().unwrap_or(&mut defaults);
                if s.every.replace(*e).is_some() {
                    return Err(twice("--every"));
                }
            }
            Token::Format(f) => {
                let s = specs.last_mut().unwrap_or(&mut defaults);
                if s.format.replace(f.clone()).is_some() {
                    return Err(twice("--format"));
                }
            }
        }
    }
    if let Some(t) = table {
        return Err(CliError::Usage(format!("{} needs an ADDRESS after it", t.name())));
    }
    for s in &mut specs {
        s.count = s.count.or(defaults.count);
        s.every = s.every.or(defaults.every);
        s.format = s.format.take().or_else(|| defaults.format.clone());
    }
    Ok(specs)
}

/// The groups of a raw range (`table`, its address as typed): its address numbered by the one
/// rule ([`ConnectArgs::address`]), read in as many requests as the device's limit needs
/// ([`ConnectArgs::read_pieces`]), never splitting a value of `layout`'s format.
fn raw_groups(
    connection: &ConnectArgs,
    numbering: AddressArgs,
    (table, address): (crate::address::Table, &str),
    spec: &Spec,
    every: Duration,
    layout: &Layout,
) -> Result<Vec<Group>, CliError> {
    let start = connection.address(address, table, numbering)?;
    let count = spec.count.unwrap_or(1);
    if count == 0 {
        return Err(CliError::Usage(format!("{} {address}: a count of 0 reads nothing", table.name())));
    }
    start.check_span(usize::from(count))?;
    let width = if table.is_bits() { 1 } else { usize::from(layout.format.value_type().registers()) };
    let mut groups = Vec::new();
    for (at, n) in connection.read_pieces(start.wire, usize::from(count), width, table, None)? {
        let name = format!("u{} {} {at:#06x}", spec.unit, table.name());
        let range = ferrobus_tools::poll::RawRange { unit: spec.unit, table: table.into(), start: at, count: n, every };
        let group = Group::raw(&name, range, layout).map_err(|e| CliError::Usage(e.to_string()))?;
        groups.push(group);
    }
    Ok(groups)
}

/// Every group to poll: the command line's, then the session file's.
fn groups(connection: &ConnectArgs, args: &PollArgs) -> Result<Vec<Group>, CliError> {
    if args.units_on_both_sides {
        return Err(CliError::Usage(
            "--unit is given both before and after `poll`: write every --unit after `poll`, each before its groups \
             (the ones before `poll` would be lost)"
                .into(),
        ));
    }
    let first_unit = connection.unit.first().copied().unwrap_or(1);
    let order = args.order;
    let mut out = Vec::new();
    let profile = connection.profile()?;
    for spec in specs(args, first_unit)? {
        let every = spec.every.unwrap_or(Duration::from_secs(1));
        if let Some((table, address)) = &spec.raw {
            let format = match &spec.format {
                Some(f) => Format::from_name(f).ok_or_else(|| {
                    let all: Vec<&str> = Format::ALL.iter().map(|f| f.name()).collect();
                    CliError::Usage(format!("--format {f:?}: give one of {}", all.join(", ")))
                })?,
                None => Format::U16,
            };
            let layout = Layout { format, order, ..Layout::default() };
            out.extend(raw_groups(connection, args.address_args, (*table, address), &spec, every, &layout)?);
        } else {
            let Some(profile) = &profile else {
                return Err(CliError::Usage(format!(
                    "{:?} is neither a table (holding, input, coils, discrete) nor, without --device, a parameter name",
                    spec.names.first().cloned().unwrap_or_default()
                )));
            };
            if spec.count.is_some() || spec.format.is_some() {
                return Err(CliError::Usage(
                    "--count and --format are for raw ranges; a named point has its own".into(),
                ));
            }
            let found = Group::points(profile, spec.unit, &spec.names, &[], every)
                .map_err(|e| CliError::Usage(format!("{e} (`ferrobus profile show {}` lists them)", profile.origin)))?;
            out.extend(found);
        }
    }
    if !args.group.is_empty() {
        let profile = profile.as_ref().ok_or_else(|| CliError::Usage("--group needs --device PROFILE".into()))?;
        let every = args.every.first().copied().unwrap_or(Duration::from_secs(1));
        let found =
            Group::points(profile, first_unit, &[], &args.group, every).map_err(|e| CliError::Usage(e.to_string()))?;
        out.extend(found);
    }
    if let Some(path) = &args.session {
        let session = Session::load(path).map_err(|e| CliError::Usage(e.to_string()))?;
        let origin = path.display().to_string();
        let found = session
            .groups(&origin, |name| ferrobus_profile::Profile::load(name).map_err(|e| e.to_string()))
            .map_err(|e| CliError::Usage(e.to_string()))?;
        out.extend(found);
    }
    if out.is_empty() {
        return Err(CliError::Usage(
            "nothing to poll: give TABLE ADDRESS (holding 0x1000), names with --device, or --session FILE".into(),
        ));
    }
    let serial = connection.tcp.is_none();
    if let Some(g) = out.iter().find(|g| serial && g.unit == 0) {
        return Err(CliError::Usage(format!(
            "{}: unit 0 is a broadcast: no device answers it, so there is nothing to read; use --unit 1-247",
            g.name
        )));
    }
    Ok(out)
}

/// How records are written.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Style {
    Table,
    Csv,
    Jsonl,
}

pub(crate) const CSV_HEADER: &str = "time,seq,unit,group,point,raw,value,meaning,uom,status,response_ms,diagnosis\n";

/// The records of a sample: CSV rows (one per point, or one for a failure) or one JSON line.
/// `keep` says which cells to write (all without --on-change).
pub(crate) fn records(sample: &Sample, group: &Group, style: Style, keep: &[bool]) -> String {
    let time = iso8601_ms(sample.time);
    let ms = sample.response_time.as_secs_f64() * 1e3;
    let mut out = String::new();
    match (style, &sample.result) {
        (Style::Jsonl, result) => {
            let (status, diagnosis, points) = match result {
                Ok(readings) => {
                    let points: Vec<serde_json::Value> = readings
                        .iter()
                        .filter(|r| keep.get(r.cell).copied().unwrap_or(true))
                        .filter_map(|r| {
                            let cell = group.cells.get(r.cell)?;
                            Some(json!({
                                "point": cell.name,
                                "raw": r.raw.as_ref().map_or(serde_json::Value::Null, raw_json),
                                "value": r.raw.as_ref().map_or(serde_json::Value::Null, |v| output::number_json(&cell.point, v)),
                                "meaning": r.raw.as_ref().ok().and_then(|v| cell.point.meaning(v)),
                                "shown": r.shown,
                                "uom": cell.unit(),
                            }))
                        })
                        .collect();
                    ("ok".to_string(), None, points)
                }
                Err(f) => (f.kind.name().to_string(), Some(f.diagnosis.clone()), Vec::new()),
            };
            let doc = json!({
                "time": time,
                "seq": sample.seq,
                "unit": group.unit,
                "group": group.name,
                "status": status,
                "exception": sample.result.as_ref().err().and_then(|f| f.exception),
                "response_ms": (ms * 1000.0).round() / 1000.0,
                "due_ms": millis(sample.due),
                "late_ms": millis(sample.started.saturating_sub(sample.due)),
                "overrun": sample.overrun,
                "points": points,
                "diagnosis": diagnosis,
            });
            out.push_str(&output::json_line(&doc));
        }
        (_, Ok(readings)) => {
            for r in readings.iter().filter(|r| keep.get(r.cell).copied().unwrap_or(true)) {
                let Some(cell) = group.cells.get(r.cell) else { continue };
                let raw = r.raw.as_ref().map(ToString::to_string).unwrap_or_default();
                // The number at the point's resolution (50.00), or the text or why there is none.
                let (value, meaning) = match &r.raw {
                    Ok(v) => (cell.point.number(v), cell.point.meaning(v).unwrap_or_default()),
                    Err(_) => (r.shown.clone(), String::new()),
                };
                let _ = writeln!(
                    out,
                    "{time},{},{},{},{},{},{},{},{},ok,{ms:.3},",
                    sample.seq,
                    group.unit,
                    output::csv_field(&group.name),
                    output::csv_field(&cell.name),
                    output::csv_field(&raw),
                    output::csv_field(&value),
                    output::csv_field(&meaning),
                    output::csv_field(cell.unit().unwrap_or_default()),
                );
            }
        }
        (_, Err(f)) => {
            let _ = writeln!(
                out,
                "{time},{},{},{},{},,,,,{},{ms:.3},{}",
                sample.seq,
                group.unit,
                output::csv_field(&group.name),
                output::csv_field(&group.name),
                f.kind.name(),
                output::csv_field(&f.diagnosis),
            );
        }
    }
    out
}

/// Milliseconds to the microsecond.
fn millis(d: Duration) -> f64 {
    (d.as_secs_f64() * 1e6).round() / 1e3
}

fn raw_json(v: &ferrobus_tools::poll::Value) -> serde_json::Value {
    match v {
        ferrobus_tools::poll::Value::Int(n) => i64::try_from(*n).map_or_else(|_| json!(n.to_string()), |n| json!(n)),
        ferrobus_tools::poll::Value::Float(x) => json!(x),
        ferrobus_tools::poll::Value::Bool(b) => json!(b),
        ferrobus_tools::poll::Value::Text(s) => json!(s),
    }
}

/// `--on-change`: what was last written for each cell and group.
#[derive(Default)]
struct Changes {
    cells: HashMap<(usize, usize), (Option<f64>, String)>,
    status: HashMap<usize, String>,
}

impl Changes {
    /// Which cells of `sample` to write, and whether to write its record at all.
    fn filter(&mut self, sample: &Sample, deadband: f64) -> (Vec<bool>, bool) {
        let status = match &sample.result {
            Ok(_) => "ok".to_string(),
            Err(f) => format!("{}:{}", f.kind.name(), f.diagnosis),
        };
        let changed_status = self.status.insert(sample.group, status.clone()).as_ref() != Some(&status);
        let Ok(readings) = &sample.result else { return (Vec::new(), changed_status) };
        let keep: Vec<bool> = readings
            .iter()
            .map(|r| {
                let key = (sample.group, r.cell);
                let moved = match (self.cells.get(&key), r.scaled) {
                    (None, _) => true,
                    (Some((Some(last), _)), Some(now)) => ferrobus_profile::beyond_deadband(*last, now, deadband),
                    (Some((_, last)), _) => *last != r.shown,
                };
                let moved = moved || changed_status;
                if moved {
                    self.cells.insert(key, (r.scaled, r.shown.clone()));
                }
                moved
            })
            .collect();
        let any = keep.iter().any(|k| *k);
        (keep, any)
    }
}

/// The log file, rotated by size or record count.
struct Log {
    path: PathBuf,
    file: std::io::BufWriter<std::fs::File>,
    header: Option<&'static str>,
    bytes: u64,
    records: u64,
    max_bytes: Option<u64>,
    max_records: Option<u64>,
    keep: u32,
}

impl Log {
    fn open(path: &Path, header: Option<&'static str>, args: &PollArgs) -> Result<Log, CliError> {
        let mut log = Log {
            path: path.to_path_buf(),
            file: std::io::BufWriter::new(create(path)?),
            header,
            bytes: 0,
            records: 0,
            max_bytes: args.rotate_size,
            max_records: args.rotate_records,
            keep: args.keep,
        };
        log.start()?;
        Ok(log)
    }

    fn failed(&self, source: std::io::Error) -> CliError {
        CliError::Output { what: self.path.display().to_string(), source }
    }

    fn start(&mut self) -> Result<(), CliError> {
        self.bytes = 0;
        self.records = 0;
        if let Some(h) = self.header {
            self.file.write_all(h.as_bytes()).map_err(|e| self.failed(e))?;
            self.bytes = h.len() as u64;
        }
        Ok(())
    }

    /// Writes one sample's records (`lines` lines) and flushes them, rotating first if the
    /// file is full.
    fn write(&mut self, text: &str, lines: u64) -> Result<(), CliError> {
        let full = self.max_bytes.is_some_and(|m| self.bytes.saturating_add(text.len() as u64) > m && self.records > 0)
            || self.max_records.is_some_and(|m| self.records.saturating_add(lines) > m && self.records > 0);
        if full {
            self.rotate()?;
        }
        self.file.write_all(text.as_bytes()).and_then(|()| self.file.flush()).map_err(|e| self.failed(e))?;
        self.bytes = self.bytes.saturating_add(text.len() as u64);
        self.records = self.records.saturating_add(lines);
        Ok(())
    }

    fn rotate(&mut self) -> Result<(), CliError> {
        self.file.flush().map_err(|e| self.failed(e))?;
        let numbered = |n: u32| {
            let mut p = self.path.clone().into_os_string();
            p.push(format!(".{n}"));
            PathBuf::from(p)
        };
        if self.keep == 0 {
            std::fs::remove_file(&self.path).map_err(|e| self.failed(e))?;
        } else {
            for n in (1..self.keep).rev() {
                let from = numbered(n);
                if from.exists() {
                    std::fs::rename(&from, numbered(n.saturating_add(1))).map_err(|e| self.failed(e))?;
                }
            }
            std::fs::rename(&self.path, numbered(1)).map_err(|e| self.failed(e))?;
        }
        self.file = std::io::BufWriter::new(create(&self.path)?);
        self.start()
    }
}

fn create(path: &Path) -> Result<std::fs::File, CliError> {
    std::fs::File::create(path).map_err(|source| CliError::Output { what: path.display().to_string(), source })
}

/// The table shown on a terminal, redrawn in place.
#[derive(Default)]
struct Screen {
    /// The lines drawn last time.
    drawn: usize,
}

impl Screen {
    /// The table of what the groups last gave, preceded after the first time by the escape
    /// that moves back to its top.
    fn draw(&mut self, groups: &[Group], counters: &[ferrobus_tools::poll::Counters], latest: &Latest) -> String {
        let mut rows = output::Rows::new(&[
            ("group", output::Align::Left),
            ("point", output::Align::Left),
            ("value", output::Align::Right),
            ("status", output::Align::Left),
            ("polls", output::Align::Right),
            ("errors", output::Align::Right),
            ("last ms", output::Align::Right),
        ]);
        for (i, g) in groups.iter().enumerate() {
            let (status, values) = latest.shown(i);
            let c = counters.get(i).cloned().unwrap_or_default();
            for (k, cell) in g.cells.iter().enumerate() {
                let first = k == 0;
                rows.push(vec![
                    if first { g.name.clone() } else { String::new() },
                    cell.name.clone(),
                    values.get(k).cloned().unwrap_or_else(|| "-".into()),
                    if first { status.clone() } else { String::new() },
                    if first { c.polls.to_string() } else { String::new() },
                    if first { c.failed().to_string() } else { String::new() },
                    match (first, c.last_response) {
                        (true, Some(t)) => format!("{:.1}", t.as_secs_f64() * 1e3),
                        _ => String::new(),
                    },
                ]);
            }
        }
        let table = rows.table();
        let mut text = String::new();
        if self.drawn > 0 {
            // Back to the table's first line, then each line cleared as it is rewritten.
            let _ = write!(text, "\x1b[{}F", self.drawn);
        }
        for line in table.lines() {
            let _ = writeln!(text, "{line}\x1b[K");
        }
        self.drawn = table.lines().count();
        text
    }
}

/// The summary on stderr: polls, successes, each failure kind, overruns; response times per
/// unit.
fn summary(
    groups: &[Group],
    counters: &[ferrobus_tools::poll::Counters],
    times: &[ferrobus_tools::poll::UnitTimes],
) -> String {
    let mut total = ferrobus_tools::poll::Counters::default();
    for c in counters {
        total.polls += c.polls;
        total.ok += c.ok;
        total.overruns += c.overruns;
        for (k, n) in &c.failures {
            *total.failures.entry(*k).or_insert(0) += n;
        }
    }
    let kinds = |c: &ferrobus_tools::poll::Counters| -> String {
        FailureKind::ALL.iter().filter(|k| c.of(**k) > 0).fold(String::new(), |mut s, k| {
            let _ = write!(s, ", {} {}", c.of(*k), k.name());
            s
        })
    };
    let mut out =
        format!("poll: {} polls, {} ok{}, {} overruns\n", total.polls, total.ok, kinds(&total), total.overruns);
    for (g, c) in groups.iter().zip(counters) {
        let _ = writeln!(out, "  {}: {} polls, {} ok{}, {} overruns", g.name, c.polls, c.ok, kinds(c), c.overruns);
    }
    for t in times {
        let _ = writeln!(
            out,
            "  unit {}: response time p50 {:.3} ms, p99 {:.3} ms, max {:.3} ms ({} replies)",
            t.unit,
            t.p50.as_secs_f64() * 1e3,
            t.p99.as_secs_f64() * 1e3,
            t.max.as_secs_f64() * 1e3,
            t.count
        );
    }
    out
}

/// The client of `poll`: `transport` to `target` opened (within the timeout, at least a
/// second), with `--in-flight` requests at once on a Modbus/TCP connection and refused on any
/// other, whose frames carry no transaction id.
async fn connect(
    connection: &ConnectArgs,
    args: &PollArgs,
    target: &crate::target::Target,
    transport: ferrobus::Transport,
) -> Result<Client, CliError> {
    if args.in_flight > 1 && transport.framing() != ferrobus::Framing::Mbap {
        return Err(CliError::Usage(format!(
            "--in-flight {}: only a Modbus/TCP connection (--tcp) keeps several requests in flight, and this is \
             {target}: its frames carry no transaction id to tell their replies apart",
            args.in_flight
        )));
    }
    let wait = connection.timeout.max(Duration::from_secs(1));
    let config = ferrobus::ClientConfig {
        in_flight: usize::try_from(args.in_flight).unwrap_or(1),
        ..connection.client_config()
    };
    match tokio::time::timeout(wait, Client::connect(transport, config)).await {
        Ok(result) => result.map_err(|error| CliError::Modbus { error }),
        Err(_) => Err(CliError::ConnectTimeout { target: target.to_string(), waited: wait }),
    }
}

/// Runs `poll`.
pub(crate) async fn run(connection: &ConnectArgs, args: &PollArgs) -> Result<(), CliError> {
    let groups = groups(connection, args)?;
    let style = if args.jsonl {
        Style::Jsonl
    } else if args.csv || !std::io::stdout().is_terminal() {
        Style::Csv
    } else {
        Style::Table
    };
    let log_style = if args.jsonl { Style::Jsonl } else { Style::Csv };
    let mut log = match &args.log {
        Some(path) => Some(Log::open(path, (log_style == Style::Csv).then_some(CSV_HEADER), args)?),
        None => None,
    };
    let status = args.metrics.bind().await?;
    let mut interrupt = Interrupt::listen()?;
    let target = connection.target()?;
    let transport = connection.transport(&target);
    // The wire time of a cycle can be predicted on an RTU serial line only.
    let line = matches!(target, crate::target::Target::Serial { ascii: false, .. }).then(|| *transport.timing());
    let client = connect(connection, args, &target, transport).await?;
    crate::interrupt::keep_release(&client);
    if style == Style::Csv {
        output::print(CSV_HEADER)?;
    }
    let mut poller = Poller::start(client, groups.clone(), PollConfig { line, raw_only: false });
    let handle = poller.handle();
    let latest = Arc::new(Mutex::new(Latest::new(groups.len())));
    if let Some(listener) = status {
        let summary = format!("polling {} groups on {target}", groups.len());
        let source =
            PollStatus { handle: handle.clone(), groups: groups.clone(), latest: Arc::clone(&latest), summary };
        metrics::spawn(listener, Arc::new(source), "poll");
    }
    let mut changes = Changes::default();
    let mut screen = Screen::default();
    let end = args.duration.map(|d| tokio::time::Instant::now() + d);
    let mut write = |event: Event, screen: &mut Screen| -> Result<(), CliError> {
        match event {
            Event::Overload(o) => {
                eprintln!("poll: {}", o.detail);
                Ok(())
            }
            Event::Sample(sample) => {
                let Some(group) = groups.get(sample.group) else { return Ok(()) };
                let table = {
                    let mut latest = latest.lock().unwrap_or_else(PoisonError::into_inner);
                    latest.update(&sample);
                    (style == Style::Table).then(|| screen.draw(&groups, &handle.counters(), &latest))
                };
                let (keep, any) =
                    if args.on_change { changes.filter(&sample, args.deadband) } else { (Vec::new(), true) };
                if let Some(table) = table {
                    output::print(&table)?;
                } else if any {
                    output::print(&records(&sample, group, style, &keep))?;
                }
                if let (Some(log), true) = (log.as_mut(), any) {
                    let text = records(&sample, group, log_style, &keep);
                    let lines = text.lines().count() as u64;
                    log.write(&text, lines)?;
                }
                Ok(())
            }
        }
    };
    let result = loop {
        let next = tokio::select! {
            biased;
            () = interrupt.wait() => None,
            () = async {
                match end {
                    Some(end) => tokio::time::sleep_until(end).await,
                    None => std::future::pending().await,
                }
            } => None,
            event = poller.next() => event,
        };
        let Some(event) = next else { break Ok(()) };
        if let Err(e) = write(event, &mut screen) {
            break Err(e);
        }
    };
    handle.stop();
    let result = result.and_then(|()| {
        // What was polled before the stop, flushed.
        while let Some(event) = poller.try_next() {
            write(event, &mut screen)?;
        }
        Ok(())
    });
    eprint!("{}", summary(&groups, &handle.counters(), &handle.response_times()));
    result
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::address::Table;

    fn sample(
        group: usize,
        result: Result<Vec<ferrobus_tools::poll::Reading>, ferrobus_tools::poll::Failure>,
    ) -> Sample {
        Sample {
            group,
            seq: 0,
            time: std::time::SystemTime::UNIX_EPOCH,
            due: Duration::ZERO,
            started: Duration::ZERO,
            response_time: Duration::ZERO,
            overrun: false,
            result,
            traffic: ferrobus_tools::poll::Traffic::default(),
        }
    }

    fn reading(cell: usize, x: f64) -> ferrobus_tools::poll::Reading {
        ferrobus_tools::poll::Reading {
            cell,
            raw: Ok(ferrobus_tools::poll::Value::Float(x)),
            scaled: Some(x),
            shown: x.to_string(),
        }
    }

    #[test]
    fn on_change_writes_a_cell_only_past_the_deadband_and_every_status_change() {
        let mut c = Changes::default();
        assert_eq!(c.filter(&sample(0, Ok(vec![reading(0, 10.0), reading(1, 5.0)])), 0.5), (vec![true, true], true));
        // 10.4 is within 0.5 of the 10.0 written; 5.6 is not.
        assert_eq!(c.filter(&sample(0, Ok(vec![reading(0, 10.4), reading(1, 5.6)])), 0.5), (vec![false, true], true));
        // Drift adds up against the value last written, not the last seen.
        assert_eq!(c.filter(&sample(0, Ok(vec![reading(0, 10.6), reading(1, 5.6)])), 0.5), (vec![true, false], true));
        assert_eq!(c.filter(&sample(0, Ok(vec![reading(0, 10.6), reading(1, 5.6)])), 0.5), (vec![false, false], false));
        let timeout = || ferrobus_tools::poll::Failure {
            kind: FailureKind::Timeout,
            exception: None,
            diagnosis: "no reply".into(),
        };
        assert_eq!(c.filter(&sample(0, Err(timeout())), 0.5), (vec![], true));
        assert_eq!(c.filter(&sample(0, Err(timeout())), 0.5), (vec![], false));
        // Back to ok: every cell is written again.
        assert_eq!(c.filter(&sample(0, Ok(vec![reading(0, 10.6), reading(1, 5.6)])), 0.5), (vec![true, true], true));
    }

    #[test]
    fn on_change_writes_every_change_between_nan_and_a_number_and_nan_after_nan_once() {
        // (last, now, deadband, written): the table of ferrobus_profile::beyond_deadband, as the bridge.
        for (last, now, deadband, written) in [
            (1.0, f64::NAN, 5.0, true),
            (f64::NAN, 1.0, 5.0, true),
            (f64::NAN, f64::NAN, 5.0, false),
            (f64::NAN, f64::NAN, 0.0, false),
            (10.0, 10.5, 0.5, false),
            (10.0, 10.6, 0.5, true),
            (f64::INFINITY, f64::INFINITY, 0.5, false),
        ] {
            let mut c = Changes::default();
            c.filter(&sample(0, Ok(vec![reading(0, last)])), deadband);
            let (cells, _) = c.filter(&sample(0, Ok(vec![reading(0, now)])), deadband);
            assert_eq!(cells, [written], "{last} -> {now} (deadband {deadband})");
        }
    }

    #[test]
    fn the_terminal_table_is_redrawn_over_itself() {
        let range = ferrobus_tools::poll::RawRange { count: 2, ..ferrobus_tools::poll::RawRange::default() };
        let g = Group::raw("u1 holding 0x0000", range, &Layout::default()).unwrap();
        let mut screen = Screen::default();
        let mut latest = Latest::new(1);
        let first = screen.draw(std::slice::from_ref(&g), &[], &latest);
        assert!(first.starts_with("group"), "{first:?}");
        assert!(first.contains("0x0001"));
        latest.update(&sample(0, Ok(vec![reading(0, 7.0), reading(1, 8.0)])));
        let second = screen.draw(std::slice::from_ref(&g), &[], &latest);
        assert!(second.starts_with("\x1b[3F"), "back up over the header and two rows: {second:?}");
        assert!(second.lines().all(|l| l.ends_with("\x1b[K")), "each line cleared to its end");
        assert!(second.contains(" 7 ") || second.contains(" 7\x1b"), "{second:?}");
    }

    #[test]
    fn a_failed_poll_keeps_the_last_values_read_and_says_how_it_failed() {
        let mut latest = Latest::new(2);
        assert_eq!(latest.shown(0), (String::new(), vec![]), "nothing polled yet");
        latest.update(&sample(0, Ok(vec![reading(0, 7.0)])));
        assert_eq!(latest.shown(0), ("ok".to_string(), vec!["7".to_string()]));
        let timeout =
            ferrobus_tools::poll::Failure { kind: FailureKind::Timeout, exception: None, diagnosis: "no reply".into() };
        latest.update(&sample(0, Err(timeout)));
        assert_eq!(latest.shown(0), ("timeout".to_string(), vec!["7".to_string()]));
        assert_eq!(latest.shown(1), (String::new(), vec![]), "the other group is its own");
        assert_eq!(latest.shown(5), (String::new(), vec![]), "no such group");
    }

    #[test]
    fn a_unit_on_both_sides_of_poll_is_found() {
        let argv = |s: &str| s.split(' ').map(String::from).collect::<Vec<_>>();
        assert!(units_on_both_sides(&argv("ferrobus --unit 7 poll holding 0 --unit 3 input 0")));
        assert!(units_on_both_sides(&argv("ferrobus -u7 poll holding 0 --unit=3 input 0")));
        assert!(!units_on_both_sides(&argv("ferrobus --unit 7 poll holding 0")));
        assert!(!units_on_both_sides(&argv("ferrobus poll --unit 7 holding 0 --unit 3 input 0")));
    }

    #[test]
    fn sizes_are_si_and_iec_by_the_one_grammar_and_refuse_zero_and_overflow() {
        // The inputs every user of ferrobus::text::size is tested with (the bridge's store too).
        for (typed, want) in [("500k", 500_000), ("10MB", 10_000_000), ("10MiB", 10 << 20), ("64KiB", 65_536)] {
            assert_eq!(parse_size(typed), Ok(want), "{typed}");
        }
        assert_eq!(parse_size("10M"), Ok(10_000_000));
        assert_eq!(parse_size("4096"), Ok(4096));
        assert!(parse_size("0").is_err());
        assert!(parse_size("99999999999G").is_err());
        assert!(parse_size("3 parsecs").is_err());
    }

    #[test]
    fn the_four_order_table_through_polls_order_option_and_its_cells() {
        // 0x11223344 as A=11 B=22 C=33 D=44: the table of ferrobus_proto::words, read/write and get/set.
        for (name, registers) in [
            ("ABCD", [0x1122, 0x3344]),
            ("cdab", [0x3344, 0x1122]),
            ("BADC", [0x2211, 0x4433]),
            ("dcba", [0x4433, 0x2211]),
        ] {
            let order = crate::value::parse_word_order(name).unwrap();
            let layout = Layout { format: Format::U32, order, ..Layout::default() };
            let range = ferrobus_tools::poll::RawRange { count: 2, ..ferrobus_tools::poll::RawRange::default() };
            let group = Group::raw("g", range, &layout).unwrap();
            assert_eq!(group.decode(&registers), [Ok(ferrobus_tools::poll::Value::Int(0x1122_3344))], "{name}");
        }
        assert_eq!(crate::value::parse_word_order("low-first"), Ok(Order::Cdab), "the aliases of --word-order");
    }

    fn args(tokens: Vec<Token>) -> PollArgs {
        PollArgs {
            what: Vec::new(),
            count: Vec::new(),
            every: Vec::new(),
            format: Vec::new(),
            order: Order::Abcd,
            group: Vec::new(),
            session: None,
            in_flight: 1,
            csv: false,
            jsonl: false,
            log: None,
            rotate_size: None,
            rotate_records: None,
            keep: 5,
            on_change: false,
            deadband: 0.0,
            duration: None,
            metrics: MetricsArgs::default(),
            address_args: AddressArgs::default(),
            positions: tokens.into_iter().enumerate().collect(),
            units_on_both_sides: false,
        }
    }

    #[test]
    fn options_after_a_group_are_its_own_and_before_the_first_every_groups() {
        let w = |s: &str| Token::What(s.into());
        let a = args(vec![
            Token::Every(Duration::from_millis(500)),
            Token::Unit(3),
            w("holding"),
            w("0x1000"),
            Token::Count(4),
            Token::Every(Duration::from_millis(100)),
            Token::Unit(5),
            w("input"),
            w("7"),
        ]);
        let s = specs(&a, 1).unwrap();
        assert_eq!(s.len(), 2);
        assert_eq!(
            (s[0].unit, s[0].raw.clone(), s[0].count, s[0].every),
            (3, Some((Table::Holding, "0x1000".into())), Some(4), Some(Duration::from_millis(100)))
        );
        assert_eq!(
            (s[1].unit, s[1].raw.clone(), s[1].count, s[1].every),
            (5, Some((Table::Input, "7".into())), None, Some(Duration::from_millis(500)))
        );
        let twice = args(vec![w("holding"), w("0"), Token::Count(1), Token::Count(2)]);
        assert!(matches!(specs(&twice, 1), Err(CliError::Usage(m)) if m.contains("--count is given twice")));
        let dangling = args(vec![w("holding")]);
        assert!(matches!(specs(&dangling, 1), Err(CliError::Usage(m)) if m.contains("needs an ADDRESS")));
    }

    #[test]
    fn monitors_one_word_form_is_a_raw_group_too_with_its_unit_and_count() {
        let w = |s: &str| Token::What(s.into());
        let a = args(vec![w("holding:0:4"), Token::Every(Duration::from_millis(100)), w("3:input:0x10")]);
        let s = specs(&a, 1).unwrap();
        let got: Vec<_> = s.iter().map(|s| (s.unit, s.raw.clone(), s.count, s.every)).collect();
        assert_eq!(
            got,
            [
                (1, Some((Table::Holding, "0".into())), Some(4), Some(Duration::from_millis(100))),
                (3, Some((Table::Input, "0x10".into())), None, None),
            ]
        );
        let twice = args(vec![w("holding:0:4"), Token::Count(2)]);
        assert!(matches!(specs(&twice, 1), Err(CliError::Usage(m)) if m.contains("--count is given twice")));
        let bad = args(vec![w("holding:0:0")]);
        assert!(matches!(specs(&bad, 1), Err(CliError::Usage(m)) if m.contains("the count '0'")));
    }
}
