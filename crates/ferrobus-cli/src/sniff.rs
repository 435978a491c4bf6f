//! `ferrobus sniff`: decode a live RTU bus passively, from a spare adapter or a `ferrobus line`
//! tap, and optionally write pcapng that tshark and Wireshark decode.
//!
//! The port is opened and only ever read: nothing is written to it, so the sniffer cannot
//! disturb the bus. A thread of its own reads it and stamps each chunk the moment the read
//! returns, so that printing and writing the capture never delay a timestamp; the decoder
//! ([`ferrobus_proto::sniff`]) takes it from there: the chunk's last byte ended at that
//! instant, the ones before it back to back. The error of a timestamp is how late the OS hands
//! over the bytes: on a pty (the virtual line) `bench/SNIFF.md` measured a median of 81 µs from
//! the line's write to the stamp (release build, 2 shared vCPUs, load 1.7), more under load; on
//! a USB adapter up to its latency timer (16 ms on an FTDI by default, 1 ms with --low-latency), plus
//! the USB poll interval (1 ms at full speed). Bytes delivered together look back to back, so
//! behind an adapter a short silence before a frame may be a delivery artefact.
//!
//! On Ctrl-C or SIGTERM (its normal end, exit 0) or after `--duration`, it settles what it
//! holds and prints per-unit statistics.

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::PathBuf;
use std::time::Duration;

use clap::Args;
use ferrobus::SerialConfig;
use ferrobus::pcapng::PcapngWriter;
use ferrobus_proto::Instant;
use ferrobus_proto::frame::timing::PC_INCOMPLETE_TIMEOUT;
use ferrobus_proto::sniff::Sniffer;
use tokio::io::AsyncReadExt;
use tokio::sync::mpsc;

use crate::connect::{ConnectArgs, Rs485Arg, Target, parse_duration};
use crate::exit::CliError;
use crate::interrupt::Interrupt;
use crate::output;

mod show;

use show::{Capture, Heard, Sinks, Stats, own};

/// Arguments of `ferrobus sniff`.
#[derive(Args, Clone, Debug)]
#[command(after_help = "Filter by unit with the global --unit (repeat it for several). Decode a capture with:\n  \
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
    /// the statistics at the end
    #[arg(long)]
    json: bool,

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

fn function_code(text: &str) -> Result<u8, String> {
    let t = text.trim();
    let parsed = match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(hex) => u8::from_str_radix(hex, 16),
        None => t.parse(),
    };
    match parsed {
        Ok(fc) if (1..0x80).contains(&fc) => Ok(fc),
        _ => Err(format!("'{text}': a function code is 1 to 127 (0x01 to 0x7F)")),
    }
}

/// What the reading thread sends.
enum Read {
    /// Bytes, and the instant the read returned.
    Bytes(Vec<u8>, std::time::Instant),
    /// The port failed (or could not be opened).
    Failed(io::Error),
}

/// Monotonic instants as nanoseconds since the Unix epoch, from one reading of both clocks.
#[derive(Clone, Copy, Debug)]
pub(crate) struct WallClock {
    mono: std::time::Instant,
    unix_ns: u64,
}

impl WallClock {
    /// Both clocks, now.
    pub(crate) fn now() -> Self {
        let mono = std::time::Instant::now();
        let unix = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
        WallClock { mono, unix_ns: u64::try_from(unix.as_nanos()).unwrap_or(u64::MAX) }
    }

    /// `t` as nanoseconds since the Unix epoch.
    pub(crate) fn unix_ns(&self, t: std::time::Instant) -> u64 {
        let since = u64::try_from(t.saturating_duration_since(self.mono).as_nanos()).unwrap_or(u64::MAX);
        let before = u64::try_from(self.mono.saturating_duration_since(t).as_nanos()).unwrap_or(u64::MAX);
        self.unix_ns.saturating_add(since).saturating_sub(before)
    }

    /// A core instant counted from the Unix epoch, as a monotonic instant.
    fn to_mono(self, t: Instant) -> std::time::Instant {
        let ns = t.as_nanos();
        if ns >= self.unix_ns {
            // Past what the monotonic clock can hold: as good as never.
            let never = || self.mono.checked_add(Duration::from_secs(1 << 30)).unwrap_or(self.mono);
            self.mono.checked_add(Duration::from_nanos(ns.saturating_sub(self.unix_ns))).unwrap_or_else(never)
        } else {
            self.mono.checked_sub(Duration::from_nanos(self.unix_ns.saturating_sub(ns))).unwrap_or(self.mono)
        }
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
    let pcap = open_capture(args.pcap.as_deref(), to_stdout, &name, &description)?;
    let mut interrupt = Interrupt::listen()?;
    let mut config = SerialConfig::new(&path, line);
    config.rs485 = match connection.rs485 {
        Rs485Arg::Auto => ferrobus::Rs485::Auto,
        Rs485Arg::Kernel => ferrobus::Rs485::Kernel,
        Rs485Arg::Rts => ferrobus::Rs485::Rts,
    };
    config.low_latency = connection.low_latency;
    let (mut heard, stale) = listen(config)?;
    let clock = WallClock::now();
    let mut sinks = Sinks {
        json: args.json,
        print: !to_stdout,
        pcap,
        char_time: timing.char_time(),
        units: args.units.clone(),
        functions: args.function.clone(),
        stats: Stats::default(),
    };
    eprintln!(
        "sniff: listening on {path} at {line} (character {:.1} µs, t1.5 {:.1} µs, t3.5 {:.1} µs), transmitting nothing; \
         Ctrl-C or SIGTERM prints the statistics",
        timing.char_time().as_secs_f64() * 1e6,
        timing.t1_5().as_secs_f64() * 1e6,
        timing.t3_5().as_secs_f64() * 1e6,
    );
    say_predating(stale);
    let mut sniffer = Sniffer::new(timing).with_incomplete_timeout(PC_INCOMPLETE_TIMEOUT);
    let stop = args.duration.map(|d| tokio::time::Instant::now() + d);
    let mut events: Vec<Heard> = Vec::new();
    let mut failure = None;
    loop {
        let deadline = sniffer.poll_timeout();
        let wake = deadline.map(|d| tokio::time::Instant::from_std(clock.to_mono(d)));
        tokio::select! {
            () = interrupt.wait() => break,
            () = sleep_until(stop) => break,
            () = sleep_until(wake) => {
                if let Some(d) = deadline {
                    sniffer.expire(d, |e| events.push(own(e)));
                }
            }
            read = heard.recv() => match read {
                Some(Read::Bytes(bytes, at)) => {
                    let now = Instant::from_nanos(clock.unix_ns(at));
                    sniffer.feed(now, &bytes, |e| events.push(own(e)));
                }
                Some(Read::Failed(e)) => {
                    failure = Some(e);
                    break;
                }
                None => break,
            },
        }
        for event in events.drain(..) {
            sinks.take(&event)?;
        }
    }
    sniffer.finish(|e| events.push(own(e)));
    for event in events.drain(..) {
        sinks.take(&event)?;
    }
    if let Some((pcap, what)) = &mut sinks.pcap {
        pcap.flush().map_err(|source| CliError::Output { what: what.clone(), source })?;
    }
    let stats = if args.json { output::json_line(&sinks.stats_json()) } else { sinks.stats_text() };
    if to_stdout {
        eprint!("{stats}");
    } else {
        output::print(&stats)?;
    }
    match failure {
        Some(e) => Err(ferrobus::Error::io(format!("reading {path}"), e).into()),
        None => Ok(()),
    }
}

/// The capture file (or stdout with `-`), its headers written.
fn open_capture(
    path: Option<&std::path::Path>,
    to_stdout: bool,
    name: &str,
    description: &str,
) -> Result<Option<Capture>, CliError> {
    let Some(path) = path else { return Ok(None) };
    let what = if to_stdout { "stdout".to_string() } else { path.display().to_string() };
    let failed = |source| CliError::Output { what: what.clone(), source };
    let out: Box<dyn Write> =
        if to_stdout { Box::new(io::stdout()) } else { Box::new(BufWriter::new(File::create(path).map_err(failed)?)) };
    // Every frame is flushed, to a file too: a capture cut short by a crash keeps what came.
    let writer = PcapngWriter::new(out, name, description).map_err(failed)?.flush_each(true);
    Ok(Some((writer, what)))
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

/// Opens the port in a thread of its own that only reads it, stamping each chunk as the read
/// returns; also returns how many bytes were waiting in the port when it opened, which
/// predate the capture and are dropped. An error opening it is returned here.
fn listen(config: SerialConfig) -> Result<(mpsc::UnboundedReceiver<Read>, usize), CliError> {
    let (tx, rx) = mpsc::unbounded_channel();
    let (opened_tx, opened_rx) = std::sync::mpsc::channel::<io::Result<usize>>();
    let describe = format!("opening {} at {}", config.path.display(), config.line);
    std::thread::Builder::new()
        .name("sniff-reader".into())
        .spawn(move || {
            let runtime = match tokio::runtime::Builder::new_current_thread().enable_all().build() {
                Ok(r) => r,
                Err(e) => {
                    let _ = opened_tx.send(Err(e));
                    return;
                }
            };
            runtime.block_on(async move {
                // Read only: nothing is ever written to the port.
                // What the port holds already came before the capture: dropped, and said.
                let opened = ferrobus::port::open_serial(&config)
                    .and_then(|mut port| port.discard_input().map(|stale| (port, stale)));
                let mut port = match opened {
                    Ok((port, stale)) => {
                        let _ = opened_tx.send(Ok(stale));
                        port
                    }
                    Err(e) => {
                        let _ = opened_tx.send(Err(e));
                        return;
                    }
                };
                let mut buf = [0u8; 1024];
                loop {
                    match port.read(&mut buf).await {
                        Ok(0) => return,
                        Ok(n) => {
                            let at = std::time::Instant::now();
                            let bytes = buf.get(..n).unwrap_or_default().to_vec();
                            if tx.send(Read::Bytes(bytes, at)).is_err() {
                                return;
                            }
                        }
                        Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                        Err(e) => {
                            let _ = tx.send(Read::Failed(e));
                            return;
                        }
                    }
                }
            });
        })
        .map_err(|e| ferrobus::Error::io("starting the reading thread", e))?;
    match opened_rx.recv() {
        Ok(Ok(stale)) => Ok((rx, stale)),
        Ok(Err(e)) => Err(ferrobus::Error::io(describe, e).into()),
        Err(_) => Err(ferrobus::Error::io(describe, io::Error::other("the reading thread ended")).into()),
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
    fn clock_times_are_utc_to_the_microsecond_and_wall_clock_round_trips() {
        assert_eq!(show::clock_time(1_700_000_000_012_000_123), "22:13:20.012000");
        let clock = WallClock::now();
        let later = clock.mono + Duration::from_millis(5);
        let ns = clock.unix_ns(later);
        assert_eq!(ns, clock.unix_ns + 5_000_000);
        assert_eq!(clock.to_mono(Instant::from_nanos(ns)), later);
    }
}
