//! # ferrobus: the command line
//!
//! A thin dispatcher over the `ferrobus` library. Each command lives in its own file, checks
//! its arguments, then opens the bus through [`connect::ConnectArgs::open`] (offline
//! commands such as `crc` never do); the shared pieces are:
//!
//! - [`connect`]: the connection options (`--port`, `--tcp`, `--rtu-tcp`, line settings,
//!   timeouts) and opening the client;
//! - [`address`]: wire addresses, `--one-based` numbers and `--modicon` references;
//! - [`value`]: typed values (`--type`, `--word-order`);
//! - [`output`]: tables, `--csv` and `--json`;
//! - [`exit`]: error reports with hints, and the exit codes;
//! - [`stderr`]: every write to stderr checked (the crate's `eprintln!` shadows std's);
//! - [`interrupt`] and [`progress`]: Ctrl-C caught by long commands, progress bars on a terminal;
//! - [`hex`]: hex input as people type it;
//! - [`config`]: the settings file (`--config`, `--conn NAME`, `[defaults]`) under the command
//!   line: every option of `ConnectArgs` is a key there by itself, checked by its own parser.
//!
//! To add a command: a file with an `Args` struct and an `async fn run(&ConnectArgs, &Args)`,
//! a variant in [`Command`], and an arm in [`dispatch`] (and in [`Command::needs_bus`] if it
//! works offline).

/// `eprintln!` with its write checked: shadows std's in every module below (see [`stderr`]).
macro_rules! eprintln {
    () => {
        $crate::stderr::print(format_args!("\n"))
    };
    ($($arg:tt)*) => {
        $crate::stderr::print(format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// `eprint!` with its write checked: shadows std's in every module below (see [`stderr`]).
macro_rules! eprint {
    ($($arg:tt)*) => {
        $crate::stderr::print(format_args!($($arg)*))
    };
}

mod address;
mod backup;
mod bench;
mod bridge;
mod completions;
mod config;
mod connect;
mod crc;
mod demo;
mod diag;
mod exit;
mod gateway;
mod get;
mod hex;
mod info;
mod interrupt;
#[cfg(unix)]
mod line;
mod man;
mod mask;
mod metrics;
mod monitor;
mod output;
mod poll;
mod ports;
mod profile;
mod progress;
mod raw;
mod read;
mod readwrite;
mod run_lock;
mod scan;
mod server_limits;
mod server_tls;
mod set;
mod sim;
mod sniff;
mod stderr;
mod sunspec;
mod systemd;
mod target;
#[cfg(not(unix))]
mod unix_only;
mod value;
mod write;

#[cfg(not(unix))]
use unix_only::line;

use std::io::IsTerminal;
use std::process::ExitCode;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

use crate::connect::ConnectArgs;
use crate::exit::{CliError, Exit};

/// Long help shown after the options of `ferrobus --help`.
const AFTER_HELP: &str = concat!(
    "ADDRESS is the wire address (0-based, as on the bus); use --one-based for a manual's register numbers, \
     or --modicon for a Modicon reference like 40001 (= holding register 1, wire 0). A plain 40001 is wire \
     address 40001 (SunSpec devices live at 40000 and up), with a warning.\n\n",
    "Examples:\n",
    "  ferrobus --port /dev/ttyUSB0 --baud 9600 --unit 5 read holding 0x0011 --count 2\n",
    "  ferrobus --tcp 192.168.1.10 write register --one-based 0x1203 50\n",
    "  ferrobus --port /dev/ttyUSB0 read holding 0x1102 --type u32 --max-per-request 4\n",
    "  ferrobus --port /dev/ttyUSB0 --device omron-3g3rx get d001 F002 'd0*'\n",
    "  ferrobus --port /dev/ttyUSB0 --device omron-3g3rx set F002 12.5s\n",
    "  ferrobus --port /dev/ttyUSB0 --device omron-3g3rx backup -o drive-07.toml\n",
    "  ferrobus --port /dev/ttyUSB0 --unit 3 poll holding 0x1000 --count 4 --every 100ms --jsonl\n",
    "  ferrobus --port /dev/ttyUSB0 scan\n",
    "  ferrobus --port /dev/ttyUSB0 gateway --listen 0.0.0.0:502\n",
    "  ferrobus bridge --config plant.toml\n",
    "  ferrobus crc 01 10 01 12 00 02\n\n",
);

/// Modbus toolkit for commissioning drives and field devices over RS-485 and TCP.
#[derive(Parser, Debug)]
#[command(name = "ferrobus", version)]
#[command(about = "Modbus toolkit for commissioning drives and field devices over RS-485 and TCP")]
#[command(after_help = format!("{AFTER_HELP}{}", exit::EXIT_CODES_HELP))]
pub(crate) struct Cli {
    /// The bus and how to talk on it.
    #[command(flatten)]
    connection: ConnectArgs,

    /// The settings file and a saved connection from it.
    #[command(flatten)]
    settings: config::ConfigArgs,

    /// The effective settings and where each came from (filled after parsing).
    #[arg(skip)]
    layered: config::Layered,

    /// More logging on stderr: -v info, -vv debug, -vvv trace (RUST_LOG overrides)
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    verbose: u8,

    /// How the log on stderr is written: text for people, or json, one object a line
    /// (timestamp, level, message and fields) for a log collector
    #[arg(long = "log-format", value_name = "FORMAT", value_enum, default_value_t = LogFormat::Text, global = true)]
    log_format: LogFormat,

    /// What to do.
    #[command(subcommand)]
    command: Command,
}

/// The commands.
#[derive(Subcommand, Debug)]
enum Command {
    /// Read coils, discrete inputs, holding or input registers (FC01-04)
    Read(read::ReadArgs),
    /// Write coils or registers (FC05, FC0F, FC06, FC10)
    Write(write::WriteArgs),
    /// Mask-write a holding register: (value AND and) OR (or AND NOT and) (FC16)
    Mask(mask::MaskArgs),
    /// Write registers, then read registers, in one transaction (FC17)
    #[command(name = "readwrite")]
    ReadWrite(readwrite::ReadWriteArgs),
    /// Serial line diagnostics: echo, counters, event log (FC08, FC0B, FC0C)
    Diag(diag::DiagArgs),
    /// Device identification (FC2B/0E), or the server id (FC11)
    Info(info::InfoArgs),
    /// Send any PDU and show the reply
    Raw(raw::RawArgs),
    /// Read named parameters of a --device profile, scaled with their units
    Get(get::GetArgs),
    /// Write one named parameter of a --device profile, in its unit, checked first, read back
    Set(set::SetArgs),
    /// Save every parameter of a device (--device PROFILE) to a diffable TOML file
    Backup(backup::BackupArgs),
    /// Compare the device with a backup, two backups, or either with the factory defaults; exit 1 if they differ
    Diff(backup::diff::DiffArgs),
    /// Write back what differs from a backup (a dry run unless --apply)
    Restore(backup::restore::RestoreArgs),
    /// Device profiles: list the built-in ones, show a parameter table, check a file (offline)
    Profile(profile::ProfileArgs),
    /// Poll registers or named points for ever, each group at its own rate: a live table, CSV or JSON lines, a log
    Poll(poll::PollArgs),
    /// A terminal UI: live grids of read definitions or --device points, traffic, trends, writes in place
    Monitor(monitor::MonitorArgs),
    /// Find every device on a serial bus: unit addresses × baud rates and formats, most likely first
    Scan(scan::ScanArgs),
    /// Decode a live RTU bus passively (transmits nothing); pcapng for tshark/Wireshark
    Sniff(sniff::SniffArgs),
    /// Modbus/TCP clients to RTU serial lines: routing by unit, one queue per line, the gateway exceptions
    Gateway(gateway::GatewayArgs),
    /// The plant's devices to an MQTT broker as Sparkplug B (or JSON), commands back, store and forward (--config plant.toml, --demo)
    Bridge(bridge::BridgeArgs),
    /// Simulate drives (Omron 3G3RX, SDP servo, generic) on a serial port, a pty or TCP
    Sim(sim::SimArgs),
    /// A virtual RS-485 bus of ptys, with real character timing and seeded faults (Unix)
    Line(line::LineArgs),
    /// A tour: a simulated 3G3RX on a virtual line, driven by the client (no hardware needed)
    Demo(demo::DemoArgs),
    /// FC03 reads back to back: transactions/s, latency and CPU time (the peer benchmark's format)
    Bench(bench::BenchArgs),
    /// The serial ports the OS knows: USB ids, manufacturer, product, serial number, /dev/serial/by-id
    Ports(ports::PortsArgs),
    /// Saved connections and defaults: `config show` prints the effective settings and their sources
    Config(config::ConfigCommandArgs),
    /// A completion script for bash, zsh, fish, powershell or elvish (see README: Install)
    Completions(completions::CompletionsArgs),
    /// Manual pages in roff: ferrobus(1) on stdout, or every page into --dir
    Man(man::ManArgs),
    /// CRC-16 and LRC of bytes, and the framed RTU and ASCII frames (offline)
    Crc(crc::CrcArgs),
}

impl Command {
    /// How the command's addresses are numbered, if it takes any (`--one-based`, `--modicon`).
    fn address_args(&self) -> Option<address::AddressArgs> {
        match self {
            Command::Read(args) => Some(args.address_args),
            Command::Write(args) => Some(args.address_args()),
            Command::Mask(args) => Some(args.address_args),
            Command::ReadWrite(args) => Some(args.address_args),
            Command::Poll(args) => Some(args.address_args),
            Command::Monitor(args) => Some(args.address_args),
            _ => None,
        }
    }

    /// Whether the command talks to a device.
    fn needs_bus(&self) -> bool {
        !matches!(
            self,
            Command::Crc(_)
                | Command::Line(_)
                | Command::Demo(_)
                | Command::Sim(sim::SimArgs { pty: true, .. })
                | Command::Profile(_)
                | Command::Diff(
                    backup::diff::DiffArgs { other: Some(_), .. }
                        | backup::diff::DiffArgs { defaults: true, file: Some(_), .. }
                )
                | Command::Ports(_)
                | Command::Config(_)
                | Command::Completions(_)
                | Command::Man(_)
                | Command::Gateway(gateway::GatewayArgs { lines_file: Some(_), .. })
                | Command::Bridge(_)
        )
    }
}

/// Runs a command.
async fn dispatch(cli: &Cli) -> Result<(), CliError> {
    if let Command::Crc(args) = &cli.command {
        return crc::run(args);
    }
    // Each command checks its own arguments, then opens the bus with `connection.open()`.
    let connection = &cli.connection;
    match &cli.command {
        Command::Read(args) => read::run(connection, args).await,
        Command::Write(args) => write::run(connection, args).await,
        Command::Mask(args) => mask::run(connection, args).await,
        Command::ReadWrite(args) => readwrite::run(connection, args).await,
        Command::Diag(args) => diag::run(connection, args).await,
        Command::Info(args) => info::run(connection, args).await,
        Command::Raw(args) => raw::run(connection, args).await,
        Command::Get(args) => get::run(&sunspec::resolve(connection).await?, args).await,
        Command::Set(args) => set::run(connection, args).await,
        Command::Backup(args) => backup::run(&sunspec::resolve(connection).await?, args).await,
        Command::Diff(args) if args.defaults => {
            backup::defaults::run(connection, args.file.as_deref(), args.output.format()).await
        }
        Command::Diff(args) => backup::diff::run(connection, args).await,
        Command::Restore(args) => backup::restore::run(connection, args).await,
        Command::Profile(args) => profile::run(args),
        Command::Poll(args) => poll::run(&sunspec::resolve(connection).await?, args).await,
        Command::Monitor(args) => monitor::run(connection, args).await,
        Command::Scan(args) => scan::run(connection, args).await,
        Command::Sniff(args) => sniff::run(connection, args).await,
        Command::Gateway(args) => gateway::run(connection, args).await,
        Command::Bridge(args) => bridge::run(cli.settings.config.as_deref(), args).await,
        Command::Sim(args) => sim::run(connection, args).await,
        Command::Line(args) => line::run(connection, args).await,
        Command::Demo(args) => demo::run(args).await,
        Command::Bench(args) => bench::run(connection, args).await,
        Command::Ports(args) => ports::run(args),
        Command::Config(args) => config::run(&cli.layered, args),
        Command::Completions(args) => completions::run(args),
        Command::Man(args) => man::run(args),
        Command::Crc(args) => crc::run(args),
    }
}

/// clap's error, or for a missing argument after a `-1`, which clap takes as the flag
/// `--one-based` even where a negative address or value was meant, one that says so.
fn explain_parse_error(error: clap::Error) -> clap::Error {
    if error.kind() != clap::error::ErrorKind::MissingRequiredArgument || !std::env::args_os().any(|a| a == "-1") {
        return error;
    }
    let missing = match error.get(clap::error::ContextKind::InvalidArg) {
        Some(clap::error::ContextValue::Strings(args)) => args.join(", "),
        _ => "an argument".to_string(),
    };
    Cli::command().error(
        clap::error::ErrorKind::MissingRequiredArgument,
        format!(
            "{missing} missing: '-1' is the flag -1 (--one-based), not a number; addresses are 0 to 65535, \
             and a negative value goes after the address (write register 5 -1 --type i16)"
        ),
    )
}

/// The connection options, by clap id (the long option is the id with `-` for `_`).
const CONNECTION_OPTIONS: [&str; 24] = [
    "port",
    "tcp",
    "rtu_tcp",
    "ascii",
    "baud",
    "parity",
    "data_bits",
    "stop_bits",
    "rs485",
    "low_latency",
    "unit",
    "timeout",
    "retries",
    "t15",
    "t35",
    "echo",
    "turnaround",
    "late_window",
    "tls",
    "cert",
    "key",
    "ca",
    "device",
    "sunspec_models",
];

/// The connection options a command takes (by clap id) and why it takes no others; `None`
/// for the commands that take them all. `--help` shows a command only those it takes
/// ([`command`]), and the command line refuses the others ([`refuse_ignored_options`]).
fn connection_options_of(name: &str) -> Option<(&'static [&'static str], &'static str)> {
    Some(match name {
        "crc" => (&[], "crc works offline and opens no bus"),
        "demo" => (&[], "demo runs its own virtual line (its baud rate is --line-baud)"),
        "bridge" => (&[], "bridge takes its lines, devices and broker from the plant file (--config FILE) or --demo"),
        "ports" => (&[], "ports lists what the OS knows and opens no port"),
        "profile" => (&[], "profile works offline on the profile it is given as its argument"),
        "completions" | "man" => (&[], "it writes text made from the command definition and opens no bus"),
        // `line --echo` is the line's own option.
        "line" => (
            &["baud", "parity", "data_bits", "stop_bits", "echo"],
            "line makes its own ptys and takes only the line settings --baud, --parity, --data-bits, --stop-bits",
        ),
        "scan" => (
            &[
                "port",
                "rs485",
                "low_latency",
                "t15",
                "t35",
                "echo",
                "tcp",
                "rtu_tcp",
                "unit",
                "timeout",
                "retries",
                "sunspec_models",
            ],
            "scan sweeps its own settings and units (--bauds, --framings, --units, --probe-timeout); \
             it takes --port, --rs485, --low-latency, --t15, --t35 and --echo, and with --sunspec \
             --tcp, --rtu-tcp, --unit, --timeout, --retries and --sunspec-models",
        ),
        "sniff" => (
            &[
                "port",
                "baud",
                "parity",
                "data_bits",
                "stop_bits",
                "rs485",
                "low_latency",
                "unit",
                "t15",
                "t35",
                "device",
            ],
            "sniff only listens: it takes the port, the line settings, --t15/--t35, --unit as a filter and \
             --device PROFILE[:UNIT] to name the values it hears",
        ),
        _ => return None,
    })
}

/// The command line's definition, each command's `--help` listing only the connection
/// options it takes (the global ones it does not are hidden there, and refused if given).
pub(crate) fn command() -> clap::Command {
    let mut command = Cli::command();
    // Propagates the global options into each command, where they can then be hidden.
    command.build();
    let names: Vec<String> = command.get_subcommands().map(|s| s.get_name().to_string()).collect();
    for name in names {
        let Some((used, _)) = connection_options_of(&name) else { continue };
        command = command.mut_subcommand(&name, |sub| hide_connection_options(sub, used));
    }
    command
}

/// `command` and the commands under it with the connection options not in `used` hidden.
fn hide_connection_options(command: clap::Command, used: &[&str]) -> clap::Command {
    let ignored = |id: &str| CONNECTION_OPTIONS.contains(&id) && !used.contains(&id);
    // In place: `mut_arg` would move the option to the end, past the built index of names.
    let mut command = command.mut_args(|arg| {
        let hide = ignored(arg.get_id().as_str()) || arg.is_hide_set();
        arg.hide(hide)
    });
    let names: Vec<String> = command.get_subcommands().map(|s| s.get_name().to_string()).collect();
    for name in names {
        command = command.mut_subcommand(&name, |sub| hide_connection_options(sub, used));
    }
    command
}

/// Refuses the connection options that a command opening no bus, or a bus of its own making,
/// would ignore (see [`connection_options_of`]).
fn refuse_ignored_options(matches: &clap::ArgMatches) -> Result<(), CliError> {
    let Some((name, sub)) = matches.subcommand() else { return Ok(()) };
    let Some((used, why)) = connection_options_of(name) else { return Ok(()) };
    let given: Vec<String> = CONNECTION_OPTIONS
        .iter()
        .filter(|id| !used.contains(id))
        .filter(|id| {
            [matches, sub].iter().any(|m| {
                m.try_get_raw(id).is_ok_and(|v| v.is_some())
                    && m.value_source(id) == Some(clap::parser::ValueSource::CommandLine)
            })
        })
        .map(|id| format!("--{}", id.replace('_', "-")))
        .collect();
    if given.is_empty() {
        return Ok(());
    }
    let verb = if given.len() == 1 { "is" } else { "are" };
    Err(CliError::Usage(format!(
        "{} {verb} not used by `{name}`: {why}; leave {} out",
        given.join(", "),
        if given.len() == 1 { "it" } else { "them" }
    )))
}

/// How the log is written ([`Cli::log_format`]).
#[derive(clap::ValueEnum, Clone, Copy, PartialEq, Eq, Debug)]
enum LogFormat {
    Text,
    Json,
}

fn init_logging(verbose: u8, format: LogFormat) {
    use tracing_subscriber::layer::SubscriberExt as _;
    use tracing_subscriber::util::SubscriberInitExt as _;
    let level = match verbose {
        0 => "warn",
        1 => "info",
        2 => "debug",
        _ => "trace",
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(level));
    let log = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(stderr::Log)
        // A failed write is kept by stderr::Log; reporting it on stderr would panic.
        .log_internal_errors(false)
        .with_target(false);
    // The warnings are kept for a status page too (`--metrics`).
    match format {
        LogFormat::Text => log.with_ansi(std::io::stderr().is_terminal()).finish().with(metrics::RecentWarnings).init(),
        LogFormat::Json => log.json().flatten_event(true).finish().with(metrics::RecentWarnings).init(),
    }
}

fn main() -> ExitCode {
    // At a Tab, the shell's completion script runs ferrobus with FERROBUS_COMPLETE set: answer, exit.
    clap_complete::CompleteEnv::with_factory(completions::command).var(completions::VAR).complete();
    let matches = command().try_get_matches().unwrap_or_else(|e| explain_parse_error(e).exit());
    if let Err(error) = refuse_ignored_options(&matches) {
        exit::report(&error, None, 1).print();
        return error.exit().into();
    }
    // The settings file's connection and defaults, under the command line's options.
    let (matches, layered) = match config::layer(matches, std::env::args_os().collect()) {
        Ok(layered) => layered,
        Err(error) => {
            exit::report(&error, None, 1).print();
            return error.exit().into();
        }
    };
    let mut cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    cli.layered = layered;
    if let (Command::Sim(args), Some(sim)) = (&mut cli.command, matches.subcommand_matches("sim")) {
        args.pair_by_position(sim);
    }
    if let (Command::Sniff(args), Some(sniff)) = (&mut cli.command, matches.subcommand_matches("sniff")) {
        args.units_from(&matches, sniff);
    }
    if let (Command::Poll(args), Some(poll)) = (&mut cli.command, matches.subcommand_matches("poll")) {
        args.positions_from(poll);
    }
    init_logging(cli.verbose, cli.log_format);
    cli.layered.log();
    if cli.command.needs_bus()
        && cli.connection.port.is_none()
        && cli.connection.tcp.is_none()
        && cli.connection.rtu_tcp.is_none()
    {
        Cli::command()
            .error(
                clap::error::ErrorKind::MissingRequiredArgument,
                "one of --port PATH, --tcp HOST[:PORT] or --rtu-tcp HOST:PORT is required",
            )
            .exit();
    }
    let runtime = match tokio::runtime::Builder::new_current_thread().enable_all().build() {
        Ok(runtime) => runtime,
        Err(e) => {
            eprintln!("error: cannot start the async runtime: {e}");
            return Exit::Io.into();
        }
    };
    let outcome = runtime.block_on(async {
        let outcome = dispatch(&cli).await;
        // A reply still on its way must reach no one else, whatever ended the command.
        interrupt::release_ports().await;
        outcome
    });
    if let Err(error) = &outcome {
        let target = cli.connection.target().ok();
        let unit = cli.connection.unit.first().copied().unwrap_or(1);
        let numbering = cli.command.address_args().map(|a| cli.connection.numbering(a)).unwrap_or_default();
        exit::report_numbered(error, target.as_ref(), unit, &numbering).print();
    }
    exit_code(outcome.as_ref().err(), stderr::failure()).into()
}

/// The exit code of a command that ended with `error` (or succeeded) while writing to stderr
/// failed with `stderr_failure` (or did not): a failure's own code; for a success whose notes
/// could not be written, the output error's (6, or 141 for a closed pipe).
fn exit_code(error: Option<&CliError>, stderr_failure: Option<std::io::Error>) -> Exit {
    match (error, stderr_failure) {
        (Some(error), _) => error.exit(),
        (None, Some(source)) => CliError::Output { what: "stderr".into(), source }.exit(),
        (None, None) => Exit::Success,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_command_line_definition_is_consistent() {
        Cli::command().debug_assert();
        command().debug_assert();
    }

    /// The long options an option line of `help` names (`  -u, --unit <UNIT>  ...`).
    fn listed_options(help: &str) -> Vec<String> {
        help.lines()
            .map(str::trim_start)
            .filter(|line| line.starts_with('-'))
            .filter_map(|line| line.split_whitespace().find(|w| w.starts_with("--")))
            .map(|w| {
                w.trim_start_matches("--").trim_end_matches(',').split(['=', '[']).next().unwrap_or("").to_string()
            })
            .collect()
    }

    /// `command` and every command under it, with the top-level command's name.
    fn with_children<'a>(top: &'a str, command: &'a clap::Command, out: &mut Vec<(&'a str, &'a clap::Command)>) {
        out.push((top, command));
        // clap's own `help` subcommand lists no options.
        for sub in command.get_subcommands().filter(|s| s.get_name() != "help") {
            with_children(top, sub, out);
        }
    }

    #[test]
    fn every_connection_option_a_commands_help_lists_is_one_it_takes_and_every_other_is_unlisted() {
        let mut cli = command();
        cli.build();
        let mut all = Vec::new();
        for sub in cli.get_subcommands().filter(|s| s.get_name() != "help") {
            with_children(sub.get_name(), sub, &mut all);
        }
        let mut checked = 0;
        for (top, sub) in all {
            let listed = listed_options(&sub.clone().render_long_help().to_string());
            assert!(listed.iter().any(|o| o == "help"), "{top}: {listed:?}");
            let taken = |id: &str| connection_options_of(top).is_none_or(|(used, _)| used.contains(&id));
            for id in CONNECTION_OPTIONS {
                let long = id.replace('_', "-");
                let shown = listed.contains(&long);
                assert_eq!(shown, taken(id), "`{top}` (`{}`): --{long} listed {shown}", sub.get_name());
                checked += 1;
            }
        }
        assert!(checked > 30 * CONNECTION_OPTIONS.len(), "{checked}");
    }

    #[test]
    fn scan_help_lists_port_but_not_baud_or_parity_which_it_refuses() {
        let mut cli = command();
        cli.build();
        let scan = cli.find_subcommand_mut("scan").unwrap();
        let listed = listed_options(&scan.render_long_help().to_string());
        assert!(listed.contains(&"port".to_string()) && listed.contains(&"t35".to_string()), "{listed:?}");
        assert!(!listed.contains(&"baud".to_string()) && !listed.contains(&"parity".to_string()), "{listed:?}");
        let matches = command().try_get_matches_from(["ferrobus", "--baud", "9600", "scan"]).unwrap();
        let refused = refuse_ignored_options(&matches).unwrap_err();
        assert!(matches!(refused, CliError::Usage(m) if m.starts_with("--baud is not used by `scan`")));
    }

    #[test]
    fn a_failed_stderr_turns_only_a_success_into_an_output_error() {
        let full = || Some(std::io::Error::from(std::io::ErrorKind::StorageFull));
        assert_eq!(exit_code(None, full()), Exit::Output);
        assert_eq!(exit_code(None, Some(std::io::ErrorKind::BrokenPipe.into())), Exit::BrokenPipe);
        assert_eq!(exit_code(Some(&CliError::Usage("x".into())), full()), Exit::Usage);
        assert_eq!(exit_code(None, None), Exit::Success);
    }
}
