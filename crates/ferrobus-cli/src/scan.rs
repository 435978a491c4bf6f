//! `ferrobus scan`: every unit address × every line setting on a serial port, most likely first.
//!
//! A thin command over [`ferrobus_tools::scan`]: it parses the lists, opens the port once, shows a
//! progress bar on a terminal, and prints what was found — also after Ctrl-C — as a table or
//! `--json`. Each device comes with its settings, what it answered the probe, its response time,
//! its identification (FC2B/0E basic objects, FC11 as a fallback) and the built-in profile whose
//! vendor and product code (or server id) it gives.

use std::fmt::Write as _;
use std::time::Duration;

use clap::Args;
use ferrobus::SerialConfig;
use ferrobus::port::open_serial;
use ferrobus_proto::codes::unit;
use ferrobus_proto::frame::LineConfig;
use ferrobus_proto::scan::{Answer, CharFormat, Lead, LineActivity, Probe, ProbeFunction, ProbeTiming, rank};
use ferrobus_sim::profile::{BUILTIN, Profile};
use ferrobus_tools::scan::{Device, Event, Identification, LeadFound, Report, ScanConfig, Scanner};
use indicatif::ProgressBar;
use serde_json::{Value, json};

use crate::connect::{ConnectArgs, Rs485Arg, parse_duration};
use crate::exit::CliError;
use crate::hex;
use crate::interrupt::Interrupt;
use crate::output::{self, Align, Format, OutputArgs, Rows};

/// `scan [--units LIST] [--bauds LIST] [--framings LIST] ...`.
#[derive(Args, Debug)]
pub(crate) struct ScanArgs {
    /// Unit addresses to probe: 1-247, or a list such as 1-10,17,0x20-0x2F (decimal or 0x hex;
    /// never 0, the broadcast)
    #[arg(long, default_value = "1-247", value_parser = parse_units)]
    units: UnitList,

    /// Baud rates to try, e.g. 19200,9600,38400,115200
    #[arg(long, value_delimiter = ',', default_value = "19200,9600", value_parser = parse_baud)]
    bauds: Vec<u32>,

    /// Character formats to try: 8E1, 8O1, 8N2, 8N1 (the spec's default is 8E1)
    #[arg(long, value_delimiter = ',', default_value = "8E1,8O1,8N2,8N1", value_parser = parse_format)]
    framings: Vec<CharFormat>,

    /// Probe function code: a read of one item, 1 (coils), 2 (inputs), 3 (holding), 4 (input registers)
    #[arg(long, default_value = "3", value_parser = parse_function)]
    function: ProbeFunction,

    /// Probe address (wire address, 0-based)
    #[arg(long, default_value_t = 0)]
    address: u16,

    /// Wait for a reply's first byte; the reply's own wire time is added (a unit with a longer
    /// response wait needs more: the 3G3RX's C078 can be up to 1 s)
    #[arg(long = "probe-timeout", value_name = "DURATION", default_value = "100ms", value_parser = parse_wait)]
    probe_timeout: Duration,

    /// Wait for the first byte in the second pass (units that gave garbage or bad CRCs) and when
    /// identifying a device
    #[arg(long = "slow-timeout", value_name = "DURATION", default_value = "1s", value_parser = parse_wait)]
    slow_timeout: Duration,

    /// Listen this long at each setting, all of them before the first probe (0: don't); valid
    /// traffic means another master, and then nothing is transmitted unless --force
    #[arg(long, value_name = "DURATION", default_value = "500ms", value_parser = parse_duration)]
    listen: Duration,

    /// Probe even though another master was heard
    #[arg(long)]
    force: bool,

    /// Do not ask the devices found for their identification (FC2B/0E, FC11)
    #[arg(long = "no-identify")]
    no_identify: bool,

    /// Walk the SunSpec model chain: of --unit on --tcp or --rtu-tcp, or, on a serial --port,
    /// of every device the sweep finds, at its setting: "SunS" at 40000, 0 or 50000, then each
    /// model's id, name, start and length
    #[arg(long)]
    sunspec: bool,

    /// With --sunspec: write the profile of the models found (named points, scale factors as
    /// read now) to this TOML file, for --device FILE, the bridge's `profile` and the monitor.
    /// On a serial port each SunSpec device found gets its own file, FILE with `-unitN`
    /// before the extension. An existing file is not replaced
    #[arg(long = "save-profile", value_name = "FILE", requires = "sunspec")]
    save_profile: Option<std::path::PathBuf>,

    /// Output format.
    #[command(flatten)]
    output: OutputArgs,
}

/// Unit addresses, in the order given, without repeats.
#[derive(Clone, Debug)]
pub(crate) struct UnitList(Vec<u8>);

/// `--units`: the one list grammar ([`ferrobus::text::list`]: decimal or 0x hex numbers and
/// ranges, `1-10,0x20,247`), each unit 1 to 247.
fn parse_units(text: &str) -> Result<UnitList, String> {
    let ranges = ferrobus::text::list(text, u64::from(u8::MAX)).map_err(|e| match e {
        ferrobus::text::TextError::Backwards { text, first, last } => {
            format!("'{}': the range goes down; write {last}-{first}", ferrobus::log::escape(&text))
        }
        ferrobus::text::TextError::TooLarge { value, .. } => format!("unit {value} is reserved: units are 1-247"),
        other => format!("{other} (a unit address is 1-247)"),
    })?;
    let mut units: Vec<u8> = Vec::new();
    for range in ranges {
        for n in range {
            let u = u8::try_from(n).unwrap_or(u8::MAX);
            if u == unit::BROADCAST {
                return Err("unit 0 is the broadcast address: nothing answers it, and a scan never broadcasts".into());
            }
            if !(unit::MIN..=unit::MAX).contains(&u) {
                return Err(format!("unit {u} is reserved: units are 1-247"));
            }
            if !units.contains(&u) {
                units.push(u);
            }
        }
    }
    Ok(UnitList(units))
}

fn parse_baud(text: &str) -> Result<u32, String> {
    match ferrobus::text::number(text, u64::from(u32::MAX)).map(u32::try_from) {
        Ok(Ok(b)) if b > 0 => Ok(b),
        _ => Err(format!("'{}' is not a baud rate (e.g. 9600, 19200)", ferrobus::log::escape(text))),
    }
}

fn parse_format(text: &str) -> Result<CharFormat, String> {
    CharFormat::parse(text.trim())
        .ok_or_else(|| format!("'{text}' is not a character format: use 8E1, 8O1, 8N2 or 8N1"))
}

fn parse_function(text: &str) -> Result<ProbeFunction, String> {
    let code = ferrobus::text::number(text, u64::from(u8::MAX))
        .ok()
        .and_then(|n| u8::try_from(n).ok())
        .ok_or_else(|| format!("'{}' is not a function code (1-4, or 0x01-0x04)", ferrobus::log::escape(text)))?;
    ProbeFunction::from_code(code).ok_or_else(|| {
        format!("function 0x{code:02X} cannot probe: a scan only reads, with 1, 2, 3 or 4 (and never writes)")
    })
}

fn parse_wait(text: &str) -> Result<Duration, String> {
    let d = parse_duration(text)?;
    if d.is_zero() {
        return Err(format!("'{text}': a wait of 0 gives up before any reply can come; use e.g. 100ms"));
    }
    Ok(d)
}

/// Runs `scan`.
pub(crate) async fn run(connection: &ConnectArgs, args: &ScanArgs) -> Result<(), CliError> {
    if args.sunspec && connection.port.is_none() {
        return crate::sunspec::scan(connection, args.output.format(), args.save_profile.as_deref()).await;
    }
    // Read before the sweep: a bad --sunspec-models fails before the bus is touched.
    let sunspec = if args.sunspec { Some(crate::sunspec::definitions(connection)?) } else { None };
    if connection.tcp.is_some() || connection.rtu_tcp.is_some() {
        return Err(CliError::Usage(
            "scan sweeps a serial --port; over --tcp or --rtu-tcp it walks a SunSpec device with --sunspec".into(),
        ));
    }
    let Some(path) = connection.port.clone() else {
        return Err(CliError::Usage(
            "scan needs a serial --port: it sweeps line settings and unit addresses (or --tcp HOST --sunspec)".into(),
        ));
    };
    if connection.ascii {
        return Err(CliError::Usage("scan probes with RTU frames; leave --ascii out".into()));
    }
    let mut lines: Vec<LineConfig> = Vec::new();
    for &baud in &args.bauds {
        let Some(base) = LineConfig::new(baud) else { continue };
        for &format in &args.framings {
            let line = format.apply(base);
            if !lines.contains(&line) {
                lines.push(line);
            }
        }
    }
    lines.sort_by_key(rank);
    let probe = Probe { function: args.function, address: args.address };
    let rs485 = match connection.rs485 {
        Rs485Arg::Auto => ferrobus::Rs485::Auto,
        Rs485Arg::Kernel => ferrobus::Rs485::Kernel,
        Rs485Arg::Rts => ferrobus::Rs485::Rts,
    };
    let config = ScanConfig {
        units: args.units.0.clone(),
        lines: lines.clone(),
        probe,
        first_byte: args.probe_timeout,
        slow_first_byte: args.slow_timeout,
        listen: args.listen,
        force: args.force,
        identify: !args.no_identify,
        rs485,
        echo_suppression: connection.echo,
        timer: ferrobus::Timer::Precise,
        t1_5: connection.t15,
        t3_5: connection.t35,
    };
    let first = lines.first().copied().unwrap_or_default();
    let mut serial = SerialConfig::new(path.clone(), first);
    serial.rs485 = rs485;
    serial.low_latency = connection.low_latency;
    let port = open_serial(&serial).map_err(|e| ferrobus::Error::io(format!("opening {path}"), e))?;
    let mut scanner = Scanner::new(port, path.clone(), config).map_err(|e| CliError::Usage(e.to_string()))?;
    let mut interrupt = Interrupt::listen()?;
    let bar = crate::progress::bar(usize::try_from(scanner.first_pass_probes()).unwrap_or(usize::MAX), "probes");
    let started = std::time::Instant::now();
    let mut report = Report::default();
    let outcome = interrupt.unless(scanner.run(&mut report, |event| show(&bar, event))).await;
    bar.finish_and_clear();
    let elapsed = started.elapsed();
    let walks = match (&sunspec, &outcome) {
        (Some(defs), Some(Ok(()))) => Some(walk_found(&scanner, &report, defs, connection).await),
        _ => None,
    };
    if let (Some(walks), Some(path), Some(defs)) = (&walks, &args.save_profile, &sunspec) {
        save_walks(walks, path, defs, connection)?;
    }
    let text = render(args.output.format(), &path, &lines, &report, elapsed, scanner.config(), walks.as_deref());
    output::print(&text)?;
    match outcome {
        None => {
            eprintln!("scan: interrupted; the report above is what was found so far");
            Err(CliError::Interrupted)
        }
        Some(Err(e)) => Err(e.into()),
        Some(Ok(())) => {
            if report.held_back {
                eprintln!(
                    "scan: another master is active on the bus, so nothing was transmitted; --force scans anyway \
                     (its requests and ours will collide)"
                );
            }
            Ok(())
        }
    }
}

/// The report in `format`, with the SunSpec walks when there are any.
fn render(
    format: Format,
    path: &str,
    lines: &[LineConfig],
    report: &Report,
    elapsed: Duration,
    config: &ScanConfig,
    walks: Option<&[Walk]>,
) -> String {
    match format {
        Format::Json => {
            let mut doc = as_json(path, lines, report, elapsed);
            if let (Some(walks), Some(object)) = (walks, doc.as_object_mut()) {
                object.insert("sunspec".into(), walks_json(walks));
            }
            output::json_line(&doc)
        }
        Format::Csv => walks.map_or_else(|| device_rows(report).csv(), |w| walks_rows(w).csv()),
        Format::Table => {
            let mut text = as_table(path, lines, report, elapsed, config);
            if let Some(walks) = walks {
                text.push_str(&walks_table(walks));
            }
            text
        }
    }
}

/// A device found, and what walking its SunSpec models gave: the chain, or why there is none.
type Walk = (u8, LineConfig, Result<ferrobus_sunspec::Discovery, String>);

/// `--sunspec` on a serial port: each device the sweep found, walked at the setting it
/// answered at, over the scanner's own port (it is not reopened), one after the other.
async fn walk_found(
    scanner: &Scanner<ferrobus::port::TtyPort>,
    report: &Report,
    defs: &ferrobus_sunspec::Definitions,
    connection: &ConnectArgs,
) -> Vec<Walk> {
    let limit = connection.max_per_request(None, crate::address::Table::Holding, false).ok().flatten().unwrap_or(125);
    let mut walks = Vec::new();
    for device in &report.devices {
        let found = match scanner.client_at(device.line, connection.timeout).await {
            Ok(client) => {
                ferrobus_sunspec::discover(&client, device.unit, defs, limit).await.map_err(|e| e.to_string())
            }
            Err(e) => Err(e.to_string()),
        };
        walks.push((device.unit, device.line, found));
    }
    walks
}

fn walks_json(walks: &[Walk]) -> Value {
    Value::Array(
        walks
            .iter()
            .map(|(unit, line, found)| match found {
                Ok(found) => json!({
                    "unit": unit, "setting": line.to_string(), "base": found.base,
                    "models": crate::sunspec::models_json(found),
                }),
                Err(why) => json!({ "unit": unit, "setting": line.to_string(), "error": why }),
            })
            .collect(),
    )
}

/// `--save-profile FILE` on a serial port: each SunSpec device's profile to `FILE-unitN.EXT`.
fn save_walks(
    walks: &[Walk],
    path: &std::path::Path,
    defs: &ferrobus_sunspec::Definitions,
    connection: &ConnectArgs,
) -> Result<(), CliError> {
    let limit = connection.max_per_request(None, crate::address::Table::Holding, false).ok().flatten().unwrap_or(125);
    for (unit, line, found) in walks {
        if let Ok(found) = found {
            let origin = format!("sunspec at {} unit {unit}, {line}", connection.port.as_deref().unwrap_or("?"));
            crate::sunspec::save(found, defs, &origin, limit, &path.with_file_name(unit_file(path, *unit)))?;
        }
    }
    Ok(())
}

/// `FILE-unitN.EXT`: the name of the profile saved for `unit` of a serial scan.
fn unit_file(path: &std::path::Path, unit: u8) -> String {
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    match path.extension() {
        Some(ext) => format!("{stem}-unit{unit}.{}", ext.to_string_lossy()),
        None => format!("{stem}-unit{unit}"),
    }
}

/// `--csv`: one row per model found, with the unit and setting.
fn walks_rows(walks: &[Walk]) -> Rows {
    let columns = [("unit", Align::Right), ("setting", Align::Left)];
    let mut rows = Rows::new(&[&columns[..], &crate::sunspec::MODEL_COLUMNS[..]].concat());
    for (unit, line, found) in walks {
        for m in found.iter().flat_map(|f| &f.models) {
            let mut cells = vec![unit.to_string(), line.to_string()];
            cells.extend(crate::sunspec::model_cells(m));
            rows.push(cells);
        }
    }
    rows
}

/// The table's SunSpec part: per device its chain, or why it has none.
fn walks_table(walks: &[Walk]) -> String {
    let mut text = String::from("\nSunSpec:\n");
    if walks.is_empty() {
        text.push_str("  no device found to walk\n");
    }
    for (unit, line, found) in walks {
        match found {
            Ok(found) => {
                let _ =
                    writeln!(text, "unit {unit} at {line}: \"SunS\" at {}, {} models", found.base, found.models.len());
                text.push_str(&crate::sunspec::model_rows(found).table());
            }
            Err(why) => {
                let _ = writeln!(text, "unit {unit} at {line}: {why}");
            }
        }
    }
    text
}

fn show(bar: &ProgressBar, event: &Event) {
    match *event {
        Event::Setting { line, .. } => bar.set_message(format!("at {line}")),
        Event::Listened { line, heard } => bar.println(format!("listened at {line}: {}", describe_heard(&heard))),
        Event::Probed { line, unit, answer, second_pass } => {
            bar.inc(1);
            if answer.proves_presence() {
                bar.println(format!(
                    "unit {unit} answers at {line}{}",
                    if second_pass { " (second pass)" } else { "" }
                ));
            }
        }
        Event::SecondPass { leads } => {
            bar.inc_length(u64::try_from(leads).unwrap_or(0));
            bar.set_message(format!("second pass, {leads} lead{}", if leads == 1 { "" } else { "s" }));
        }
    }
}

fn describe_answer(answer: &Answer) -> String {
    match answer {
        Answer::Reply => "reply".into(),
        Answer::Exception(code) => format!("exception {code}"),
        Answer::Mismatch => "a frame that does not answer the probe".into(),
        Answer::Lead(lead) => describe_lead(lead),
        Answer::OtherTraffic { unit, function } => format!("a frame from unit {unit} (function 0x{function:02X})"),
        Answer::Silence => "silence".into(),
    }
}

fn describe_lead(lead: &Lead) -> String {
    match *lead {
        Lead::BadChecksum { head: Some((address, function)) } => {
            format!("a frame with a wrong CRC (address {address}, function 0x{function:02X})")
        }
        Lead::BadChecksum { head: None } => "a frame with a wrong CRC".into(),
        Lead::Garbage { bytes, reason } => format!("{bytes} byte{} that made no frame ({reason})", plural(bytes)),
    }
}

fn describe_heard(heard: &LineActivity) -> String {
    match heard {
        LineActivity::Traffic { units, requests, responses, either } => format!(
            "another master: CRC-valid frames to/from unit{} {} ({requests} requests, {responses} responses{})",
            if units.iter().count() == 1 { "" } else { "s" },
            units.iter().map(|u| u.to_string()).collect::<Vec<_>>().join(", "),
            if *either > 0 { format!(", {either} either") } else { String::new() }
        ),
        LineActivity::Noise { bad_checksums, bytes } => format!(
            "{bytes} byte{} that made no valid frame ({bad_checksums} with a wrong CRC): something talks at other settings",
            plural(usize::try_from(*bytes).unwrap_or(usize::MAX))
        ),
        LineActivity::Quiet => "quiet".into(),
    }
}

fn plural(n: usize) -> &'static str {
    if n == 1 { "" } else { "s" }
}

/// The built-in profile whose vendor and product code (FC2B/0E), or server id (FC11), the
/// device gives.
fn matching_profile(identification: &Identification) -> Option<&'static str> {
    BUILTIN.iter().find_map(|&(name, text)| {
        let profile = Profile::parse(text, name).ok()?;
        let device = &profile.device;
        let matches = match identification {
            Identification::Objects(_) => {
                identification.object(0x00) == Some(device.vendor.as_str())
                    && identification.object(0x01) == Some(device.product_code.as_str())
            }
            // The server id bytes, then the run indicator (00 or FF).
            Identification::ServerId(data) => device.server_id.as_ref().is_some_and(|id| {
                data.split_last().is_some_and(|(run, rest)| matches!(run, 0x00 | 0xFF) && rest == id.as_bytes())
            }),
            Identification::Refused { .. } => false,
        };
        matches.then_some(name)
    })
}

fn describe_identification(identification: Option<&Identification>) -> String {
    match identification {
        None => "-".into(),
        Some(id @ Identification::Objects(_)) => {
            let parts: Vec<&str> = [0x00, 0x01, 0x02].iter().filter_map(|&i| id.object(i)).collect();
            if parts.is_empty() { "FC2B/0E: no readable basic objects".into() } else { parts.join(" ") }
        }
        Some(Identification::ServerId(data)) => format!("server id {}", hex::format(data)),
        Some(Identification::Refused { device_id, server_id }) => {
            format!("none (FC2B/0E: {device_id}; FC11: {server_id})")
        }
    }
}

fn millis(d: Duration) -> String {
    format!("{:.1} ms", d.as_secs_f64() * 1000.0)
}

fn device_rows(report: &Report) -> Rows {
    let mut rows = Rows::new(&[
        ("unit", Align::Right),
        ("settings", Align::Left),
        ("answer", Align::Left),
        ("response", Align::Right),
        ("identification", Align::Left),
        ("profile", Align::Left),
    ]);
    for d in &report.devices {
        let answer = if d.second_pass {
            format!("{} (second pass)", describe_answer(&d.answer))
        } else {
            describe_answer(&d.answer)
        };
        rows.push(vec![
            d.unit.to_string(),
            d.line.to_string(),
            answer,
            millis(d.response_time),
            describe_identification(d.identification.as_ref()),
            d.identification.as_ref().and_then(matching_profile).unwrap_or("-").to_string(),
        ]);
    }
    rows
}

fn as_table(path: &str, lines: &[LineConfig], report: &Report, elapsed: Duration, config: &ScanConfig) -> String {
    let mut out = String::new();
    let done: Vec<String> = lines.iter().take(report.settings_done).map(ToString::to_string).collect();
    let timing = ferrobus_proto::frame::LineTiming::new(&lines.first().copied().unwrap_or_default());
    let wait = ProbeTiming::new(&timing, &config.probe, config.first_byte);
    let _ = writeln!(
        out,
        "scan of {path}: {} unit{} at {} of {} setting{} ({}), {} probes in {:.1} s{}",
        config.units.len(),
        plural(config.units.len()),
        report.settings_done,
        lines.len(),
        plural(lines.len()),
        if done.is_empty() { "none".to_string() } else { done.join(", ") },
        report.probes,
        elapsed.as_secs_f64(),
        if report.complete { "" } else { "; NOT COMPLETE" },
    );
    let _ = writeln!(
        out,
        "probe: FC{:02X} at address {}, first-byte wait {} + the reply's wire time (timeout {} at {})",
        config.probe.function.code(),
        config.probe.address,
        millis(config.first_byte),
        millis(wait.timeout()),
        lines.first().copied().unwrap_or_default()
    );
    for master in &report.masters {
        let _ = writeln!(out, "at {}: {}", master.line, describe_heard(&master.heard));
    }
    if report.held_back {
        let _ = writeln!(out, "nothing was transmitted: another master is active (--force scans anyway)");
    }
    if report.devices.is_empty() {
        if !report.held_back {
            let _ = writeln!(out, "no device answered");
        }
    } else {
        let _ = write!(out, "\n{}", device_rows(report).table());
    }
    if !report.leads.is_empty() {
        let _ = writeln!(out, "\nleads (bytes that did not frame: a device at other settings, or a bad line):");
        for lead in &report.leads {
            let _ = writeln!(out, "  {}", describe_lead_found(lead, report));
        }
    }
    if !report.other_traffic.is_empty() {
        let _ = writeln!(out, "\nother traffic while probing (another master, or a device answering for another):");
        for t in &report.other_traffic {
            let _ = writeln!(
                out,
                "  at {}, probing unit {}: a valid frame from unit {} (function 0x{:02X})",
                t.line, t.probed, t.unit, t.function
            );
        }
    }
    for (line, heard) in &report.noise {
        let _ = writeln!(out, "listening at {line}: {}", describe_heard(heard));
    }
    out
}

fn describe_lead_found(lead: &LeadFound, report: &Report) -> String {
    let elsewhere: Vec<String> = report
        .devices
        .iter()
        .filter(|d| d.unit == lead.unit && d.line != lead.line)
        .map(|d| d.line.to_string())
        .collect();
    let mut text = format!("unit {} at {}: {}", lead.unit, lead.line, describe_lead(&lead.lead));
    match &lead.second {
        Some(second) => {
            let _ = write!(text, "; second pass: {}", describe_answer(second));
        }
        None => text.push_str("; no second pass"),
    }
    if !elsewhere.is_empty() {
        let _ = write!(text, "; unit {} answers at {}", lead.unit, elsewhere.join(", "));
    }
    text
}

fn answer_json(answer: &Answer) -> Value {
    let mut o = json!({ "kind": match answer {
        Answer::Reply => "reply",
        Answer::Exception(_) => "exception",
        Answer::Mismatch => "mismatch",
        Answer::Lead(Lead::BadChecksum { .. }) => "bad-crc",
        Answer::Lead(Lead::Garbage { .. }) => "garbage",
        Answer::OtherTraffic { .. } => "other-unit",
        Answer::Silence => "silence",
    }, "text": describe_answer(answer) });
    if let Answer::Exception(code) = answer {
        o["exception"] = code.value().into();
    }
    o
}

fn as_json(path: &str, lines: &[LineConfig], report: &Report, elapsed: Duration) -> Value {
    let devices: Vec<Value> = report
        .devices
        .iter()
        .map(|d: &Device| {
            let identification = match &d.identification {
                None => Value::Null,
                Some(id @ Identification::Objects(objects)) => json!({
                    "function": 0x2B,
                    "vendor": id.object(0x00),
                    "product_code": id.object(0x01),
                    "revision": id.object(0x02),
                    "objects": objects.iter().map(|(i, v)| json!({ "id": i, "hex": hex::format(v) })).collect::<Vec<_>>(),
                }),
                Some(Identification::ServerId(data)) => json!({ "function": 0x11, "server_id": hex::format(data) }),
                Some(Identification::Refused { device_id, server_id }) => {
                    json!({ "refused": { "fc2b": device_id, "fc11": server_id } })
                }
            };
            json!({
                "unit": d.unit,
                "settings": d.line.to_string(),
                "baud": d.line.baud(),
                "answer": answer_json(&d.answer),
                "response_ms": d.response_time.as_secs_f64() * 1000.0,
                "second_pass": d.second_pass,
                "identification": identification,
                "profile": d.identification.as_ref().and_then(matching_profile),
            })
        })
        .collect();
    let leads: Vec<Value> = report
        .leads
        .iter()
        .map(|l| {
            json!({
                "unit": l.unit,
                "settings": l.line.to_string(),
                "heard": describe_lead(&l.lead),
                "second_pass": l.second.as_ref().map(answer_json),
            })
        })
        .collect();
    let masters: Vec<Value> = report
        .masters
        .iter()
        .map(|m| match m.heard {
            LineActivity::Traffic { units, requests, responses, either } => json!({
                "settings": m.line.to_string(),
                "units": units.iter().collect::<Vec<_>>(),
                "requests": requests,
                "responses": responses,
                "either": either,
            }),
            other => json!({ "settings": m.line.to_string(), "heard": describe_heard(&other) }),
        })
        .collect();
    let other: Vec<Value> = report
        .other_traffic
        .iter()
        .map(|t| json!({ "settings": t.line.to_string(), "probed": t.probed, "unit": t.unit, "function": t.function }))
        .collect();
    let noise: Vec<Value> = report
        .noise
        .iter()
        .map(|(line, heard)| json!({ "settings": line.to_string(), "heard": describe_heard(heard) }))
        .collect();
    json!({
        "port": path,
        "complete": report.complete,
        "held_back": report.held_back,
        "settings": lines.iter().map(ToString::to_string).collect::<Vec<_>>(),
        "settings_done": report.settings_done,
        "probes": report.probes,
        "seconds": elapsed.as_secs_f64(),
        "devices": devices,
        "leads": leads,
        "other_masters": masters,
        "other_traffic": other,
        "noise": noise,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_lists_take_ranges_and_refuse_the_broadcast_and_reserved_addresses() {
        assert_eq!(parse_units("1-3,7,2").unwrap().0, [1, 2, 3, 7]);
        assert_eq!(parse_units("1-247").unwrap().0.len(), 247);
        assert!(parse_units("0-5").unwrap_err().contains("broadcast"));
        assert!(parse_units("248").unwrap_err().contains("reserved"));
        assert!(parse_units("9-3").unwrap_err().contains("write 3-9"));
        assert!(parse_units("x").unwrap_err().contains("'x' is not a number"), "{:?}", parse_units("x"));
        assert!(parse_units("").is_err());
        // The one number and list grammar: hex as everywhere else.
        assert_eq!(parse_units("0x10-0x12,0xF7").unwrap().0, [16, 17, 18, 247]);
        assert_eq!(parse_units("1-10,0x20,247").unwrap().0.len(), 12);
        assert!(parse_units("0x0").unwrap_err().contains("broadcast"));
        assert!(parse_units("300").unwrap_err().contains("reserved"));
        assert_eq!(parse_baud("0x2580"), Ok(9600));
    }

    #[test]
    fn only_reads_probe_and_waits_are_above_zero() {
        assert_eq!(parse_function("3"), Ok(ProbeFunction::HoldingRegisters));
        assert_eq!(parse_function("0x04"), Ok(ProbeFunction::InputRegisters));
        assert!(parse_function("6").unwrap_err().contains("never writes"));
        assert!(parse_format("8e2").unwrap_err().contains("8E1, 8O1, 8N2 or 8N1"));
        assert!(parse_baud("0").is_err());
        assert!(parse_wait("0").is_err());
        assert_eq!(parse_wait("250ms"), Ok(Duration::from_millis(250)));
    }

    #[test]
    fn the_default_waits_are_the_cores_defaults() {
        use clap::CommandFactory;
        let command = crate::Cli::command();
        let scan = command.find_subcommand("scan").unwrap();
        let default = |id: &str| {
            let arg = scan.get_arguments().find(|a| a.get_id() == id).unwrap();
            parse_wait(arg.get_default_values()[0].to_str().unwrap()).unwrap()
        };
        assert_eq!(default("probe_timeout"), ferrobus_proto::scan::DEFAULT_FIRST_BYTE);
        assert_eq!(default("slow_timeout"), ferrobus_proto::scan::DEFAULT_SLOW_FIRST_BYTE);
    }

    #[test]
    fn a_device_is_matched_to_a_built_in_profile_by_vendor_and_product_code_or_server_id() {
        let objects = |vendor: &str, product: &str| {
            Identification::Objects(vec![(0, vendor.as_bytes().to_vec()), (1, product.as_bytes().to_vec())])
        };
        assert_eq!(matching_profile(&objects("ferrobus", "FB-GENERIC")), Some("generic"));
        assert_eq!(matching_profile(&objects("ferrobus", "OTHER")), None);
        assert_eq!(matching_profile(&Identification::ServerId(b"FB\xFF".to_vec())), Some("generic"));
        assert_eq!(matching_profile(&Identification::ServerId(b"FB".to_vec())), None);
        let refused = Identification::Refused { device_id: "x".into(), server_id: "y".into() };
        assert_eq!(matching_profile(&refused), None);
    }
}
