//! `ferrobus sniff`: decode a live RTU bus passively, from a spare adapter or a `ferrobus line`
//! tap, and optionally write pcapng that tshark and Wireshark decode.
//!
//! The listening, the decoding, the unit filter, the statistics and the capture are the
//! library's ([`ferrobus_tools::sniff`]: nothing is ever written to the port, and each chunk is
//! stamped the moment its read returns). This command parses its arguments and prints: the
//! timestamps' accuracy is measured in `bench/SNIFF.md` (a median of 81 µs from the line's
//! write to the stamp on a pty, release build, 2 shared vCPUs, load 1.7).
//!
//! With `--device PROFILE[:UNIT]` it is a passive second master: what the bus's own master
//! reads and writes is shown as the profile's named values, in `poll`'s records
//! (`sniff/values.rs`, over [`ferrobus_tools::sniff::Pairing`]).
//!
//! On Ctrl-C or SIGTERM (its normal end, exit 0) or after `--duration`, it settles what it
//! holds and prints per-unit statistics.

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::PathBuf;
use std::time::Duration;

use clap::Args;
use ferrobus::SerialConfig;
use ferrobus_proto::frame::LineTiming;
use ferrobus_tools::pcapng::PcapngWriter;
use ferrobus_tools::sniff::{Filter, Listener, SniffCapture, Stats};

use crate::connect::{ConnectArgs, Rs485Arg, Target, parse_duration};
use crate::exit::CliError;
use crate::interrupt::Interrupt;
use crate::output;

mod show;
mod values;

use show::{Capture, Sinks};

/// Arguments of `ferrobus sniff`.
#[derive(Args, Clone, Debug)]
#[command(after_help = "Filter by unit with the global --unit (repeat it for several).\n\n\
                        --device PROFILE[:UNIT] (a built-in profile such as omron-3g3rx, or a TOML file) names what \
                        the bus's own master reads and writes: each read reply and each acknowledged write of UNIT \
                        (default: the --unit ones, else 1) is decoded through the profile as `poll` decodes it, a \
                        point only when the frame holds all of it, at the reply's time on the wire; stdout then \
                        carries the values (a line each; --csv and --json: `poll`'s records), not the frames, \
                        --pcap FILE still captures every frame and the statistics go to stderr:\n  \
                        ferrobus --port /dev/ttyUSB1 sniff --device omron-3g3rx:1 --csv\n\n\
                        Decode a capture with:\n  \
                        tshark -r cap.pcapng -o mbrtu.crc_verification:TRUE -o mbrtu.tcp.port:5020\n\
                        or live: ferrobus --port /dev/ttyUSB1 sniff --pcap - | tshark -i - -o mbrtu.crc_verification:TRUE -o mbrtu.tcp.port:5020")]
pub(crate) struct SniffArgs {
    /// Show only these function codes (repeat it): 3, 0x03, 0x10; an exception counts as its
    /// function
    #[arg(long, value_name = "FC", value_parser = function_code)]
    function: Vec<u8>,

    /// Also write the frames as pcapng to FILE, or to stdout with `-` (flushed per frame, for
    /// `| tshark -i -`; the decode then goes nowhere and the statistics to stderr)
    #[arg(long, value_name = "FILE")]
    pcap: Option<PathBuf>,

    /// One JSON object per line for each frame, fragment and unanswered request, and one for
    /// the statistics at the end; with --device, one per value heard, as `poll --jsonl` writes
    #[arg(long)]
    json: bool,

    /// With --device: the values as CSV, as `poll --csv` writes them
    #[arg(long, conflicts_with = "json")]
    csv: bool,

    /// Stop after this long; default: run until interrupted
    #[arg(long, value_name = "DURATION", value_parser = parse_duration)]
    duration: Option<Duration>,

    /// The units to show, from the global --unit if it was given (set in `main`).
    #[arg(skip)]
    units: Vec<u8>,
}

impl SniffArgs {
    /// Takes the global `--unit`s as the unit filter if they were given on the command line
    /// (its default, unit 1, is no filter).
    pub(crate) fn units_from(&mut self, matches: &clap::ArgMatches, sub: &clap::ArgMatches) {
        let given =
            [matches, sub].iter().any(|m| m.value_source("unit") == Some(clap::parser::ValueSource::CommandLine));
        if given {
            self.units = sub.get_many::<u8>("unit").map(|u| u.copied().collect()).unwrap_or_default();
        }
    }
}

/// A function code 1-127 by the one number grammar ([`ferrobus::text::number`]).
fn function_code(text: &str) -> Result<u8, String> {
    match ferrobus::text::number(text, 0x7F).map(u8::try_from) {
        Ok(Ok(fc)) if fc >= 1 => Ok(fc),
        _ => Err(format!("'{}': a function code is 1 to 127 (0x01 to 0x7F)", ferrobus::log::escape(text))),
    }
}

/// Runs `ferrobus sniff`.
pub(crate) async fn run(connection: &ConnectArgs, args: &SniffArgs) -> Result<(), CliError> {
    let Target::Serial { path, line, ascii } = connection.target()? else {
        return Err(CliError::Usage(
            "sniff listens on a serial line: give --port PATH (a spare adapter, or a `ferrobus line --tap` pty)".into(),
        ));
    };
    if ascii {
        return Err(CliError::Usage("sniff decodes RTU only; leave --ascii out".into()));
    }
    let to_stdout = args.pcap.as_deref() == Some(std::path::Path::new("-"));
    if to_stdout && args.json {
        return Err(CliError::Usage("--pcap - writes the capture to stdout: --json has nowhere to go".into()));
    }
    let watch = watch(connection, args, to_stdout)?;
    let mut timing = ferrobus_proto::frame::LineTiming::new(&line);
    if let Some(t15) = connection.t15 {
        timing = timing.with_t1_5(t15);
    }
    if let Some(t35) = connection.t35 {
        timing = timing.with_t3_5(t35);
    }
    let name = path.rsplit('/').next().unwrap_or(&path).to_string();
    let description = format!("RS-485 {line} (ferrobus sniff {path})");
    // The capture is opened before the port, so that a path that cannot be written fails at once.
    let pcap = open_capture(args.pcap.as_deref(), to_stdout, &name, &description, &timing)?;
    let mut interrupt = Interrupt::listen()?;
    let mut config = SerialConfig::new(&path, line);
    config.rs485 = match connection.rs485 {
        Rs485Arg::Auto => ferrobus::Rs485::Auto,
        Rs485Arg::Kernel => ferrobus::Rs485::Kernel,
        Rs485Arg::Rts => ferrobus::Rs485::Rts,
    };
    config.low_latency = connection.low_latency;
    let mut listener = Listener::open(config, timing).map_err(ferrobus::Error::from)?;
    let mut sinks = Sinks {
        json: args.json,
        print: !to_stdout,
        pcap,
        char_time: timing.char_time(),
        filter: Filter { units: args.units.clone(), functions: args.function.clone() },
        stats: Stats::default(),
        values: watch,
    };
    if let Some(watch) = &sinks.values {
        output::print(&watch.header())?;
    }
    eprintln!(
        "sniff: listening on {path} at {line} (character {:.1} µs, t1.5 {:.1} µs, t3.5 {:.1} µs), transmitting nothing; \
         Ctrl-C or SIGTERM prints the statistics",
        timing.char_time().as_secs_f64() * 1e6,
        timing.t1_5().as_secs_f64() * 1e6,
        timing.t3_5().as_secs_f64() * 1e6,
    );
    say_predating(listener.predating());
    let stop = args.duration.map(|d| tokio::time::Instant::now() + d);
    let mut failure = None;
    loop {
        let heard = tokio::select! {
            () = interrupt.wait() => break,
            () = sleep_until(stop) => break,
            heard = listener.next() => heard,
        };
        match heard {
            Ok(Some(event)) => sinks.take(&event)?,
            Ok(None) => break,
            Err(e) => {
                failure = Some(e);
                break;
            }
        }
    }
    let (rest, late_failure) = listener.finish();
    for event in rest {
        sinks.take(&event)?;
    }
    failure = failure.or(late_failure);
    if let Some((pcap, what)) = &mut sinks.pcap {
        pcap.flush().map_err(|source| CliError::Output { what: what.clone(), source })?;
    }
    let stats = if args.json { output::json_line(&sinks.stats_json()) } else { sinks.stats_text() };
    // With --device, stdout carries the values alone.
    if to_stdout || sinks.values.is_some() {
        eprint!("{stats}");
    } else {
        output::print(&stats)?;
    }
    match failure {
        Some(e) => Err(ferrobus::Error::from(e).into()),
        None => Ok(()),
    }
}

/// `--device PROFILE[:UNIT]`: the values heard, in the style asked; `None` without it.
fn watch(connection: &ConnectArgs, args: &SniffArgs, to_stdout: bool) -> Result<Option<values::Watch>, CliError> {
    let Some(device) = connection.device.as_deref() else {
        return if args.csv {
            Err(CliError::Usage("--csv writes the values of --device PROFILE[:UNIT]; give --device".into()))
        } else {
            Ok(None)
        };
    };
    if to_stdout {
        return Err(CliError::Usage(
            "--pcap - writes the capture to stdout, where --device writes the values: give --pcap a FILE".into(),
        ));
    }
    let style = if args.json {
        crate::poll::Style::Jsonl
    } else if args.csv {
        crate::poll::Style::Csv
    } else {
        crate::poll::Style::Table
    };
    values::Watch::new(device, &args.units, style).map(Some)
}

/// The capture file (or stdout with `-`), its headers written.
fn open_capture(
    path: Option<&std::path::Path>,
    to_stdout: bool,
    name: &str,
    description: &str,
    timing: &LineTiming,
) -> Result<Option<Capture>, CliError> {
    let Some(path) = path else { return Ok(None) };
    let what = if to_stdout { "stdout".to_string() } else { path.display().to_string() };
    let failed = |source| CliError::Output { what: what.clone(), source };
    let out: Box<dyn Write> =
        if to_stdout { Box::new(io::stdout()) } else { Box::new(BufWriter::new(File::create(path).map_err(failed)?)) };
    // Every frame is flushed, to a file too: a capture cut short by a crash keeps what came.
    let writer = PcapngWriter::new(out, name, description).map_err(failed)?.flush_each(true);
    Ok(Some((SniffCapture::new(writer, timing), what)))
}

/// Says how many bytes were waiting in the port when it opened: dropped, as they predate the
/// capture (they would show as noise).
fn say_predating(stale: usize) {
    if stale > 0 {
        eprintln!("sniff: dropped {stale} bytes that were waiting in the port before the capture began");
    }
}

async fn sleep_until(at: Option<tokio::time::Instant>) {
    match at {
        Some(at) => tokio::time::sleep_until(at).await,
        None => std::future::pending().await,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn function_codes_are_decimal_or_hex_from_1_to_127() {
        assert_eq!(function_code("3"), Ok(3));
        assert_eq!(function_code("0x10"), Ok(0x10));
        assert_eq!(function_code("0X2B"), Ok(0x2B));
        assert!(function_code("0").is_err());
        assert!(function_code("0x83").is_err());
        assert!(function_code("read").is_err());
    }

    #[test]
    fn clock_times_are_utc_to_the_microsecond() {
        assert_eq!(show::clock_time(1_700_000_000_012_000_123), "22:13:20.012000");
    }
}
