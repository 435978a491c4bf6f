//! Connection options shared by every client command, and opening the client.
//!
//! One of `--port` (serial RTU, or ASCII with `--ascii`), `--tcp` (Modbus/TCP) or `--rtu-tcp`
//! (RTU frames over TCP) names the bus; the rest tune the line and the requests.

use std::path::PathBuf;
use std::time::Duration;

use clap::{Args, ValueEnum};
use ferrobus::tls::ClientTls;
use ferrobus::{Client, ClientConfig, Rs485, SerialConfig, Transport};
use ferrobus_proto::codes::unit;
use ferrobus_proto::frame::{DataBits, LineConfig, Parity, StopBits};

use crate::address::{Address, AddressArgs, Table, split};
use crate::exit::{CliError, Numbering};
use crate::value::ValueArgs;

/// The `--device` name whose profile is discovered from the device: its SunSpec models
/// ([`crate::sunspec`]).
pub(crate) const SUNSPEC: &str = "sunspec";

/// Options that say how to reach the device.
#[derive(Args, Clone, Debug)]
#[command(next_help_heading = "Connection")]
#[expect(clippy::struct_excessive_bools, reason = "each bool is a command-line flag")]
pub(crate) struct ConnectArgs {
    /// Serial port, e.g. /dev/ttyUSB0 (RTU unless --ascii)
    #[arg(long, global = true, value_name = "PATH", conflicts_with_all = ["tcp", "rtu_tcp"])]
    pub(crate) port: Option<String>,

    /// Modbus/TCP server, HOST[:PORT] (port 502 if omitted)
    #[arg(long, global = true, value_name = "HOST:PORT", conflicts_with = "rtu_tcp")]
    pub(crate) tcp: Option<String>,

    /// RTU frames over TCP (a serial gateway), HOST:PORT
    #[arg(long = "rtu-tcp", global = true, value_name = "HOST:PORT")]
    pub(crate) rtu_tcp: Option<String>,

    /// Modbus ASCII framing on the serial port (usually with --data-bits 7)
    #[arg(long, global = true)]
    pub(crate) ascii: bool,

    /// Baud rate
    #[arg(long, global = true, default_value_t = 19_200, value_parser = clap::value_parser!(u32).range(1..))]
    pub(crate) baud: u32,

    /// Parity (8E1 is the spec's default; many drives ship 8N1)
    #[arg(long, global = true, value_enum, default_value_t = ParityArg::Even)]
    pub(crate) parity: ParityArg,

    /// Data bits (7 only with --ascii)
    #[arg(long = "data-bits", global = true, default_value_t = 8, value_parser = clap::value_parser!(u8).range(7..=8))]
    pub(crate) data_bits: u8,

    /// Stop bits
    #[arg(long = "stop-bits", global = true, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=2))]
    pub(crate) stop_bits: u8,

    /// RS-485 direction control: by the adapter, the kernel (TIOCSRS485) or RTS
    #[arg(long, global = true, value_enum, default_value_t = Rs485Arg::Auto)]
    pub(crate) rs485: Rs485Arg,

    /// Set the USB adapter's latency timer to 1 ms (FTDI default: 16 ms)
    #[arg(long = "low-latency", global = true)]
    pub(crate) low_latency: bool,

    /// Unit (slave) address; 0 = broadcast on serial lines (`sim`: once per simulated device)
    #[arg(long, short = 'u', global = true, default_value = "1", action = clap::ArgAction::Append)]
    pub(crate) unit: Vec<u8>,

    /// Reply timeout per attempt: 500ms, 1.5s, 2s (a plain number is ms)
    #[arg(long, global = true, value_name = "DURATION", default_value = "1s", value_parser = parse_timeout)]
    pub(crate) timeout: Duration,

    /// Resend a request this many times when no usable reply comes
    #[arg(long, global = true, default_value_t = 0)]
    pub(crate) retries: u32,

    /// Override t1.5, the longest gap inside a frame
    #[arg(long, global = true, value_name = "DURATION", value_parser = parse_duration)]
    pub(crate) t15: Option<Duration>,

    /// Override t3.5, the silence between frames (some servos want 10ms)
    #[arg(long, global = true, value_name = "DURATION", value_parser = parse_duration)]
    pub(crate) t35: Option<Duration>,

    /// Drop the echo of our own transmission (adapters that hear themselves)
    #[arg(long, global = true)]
    pub(crate) echo: bool,

    /// Quiet time after a broadcast
    #[arg(long, global = true, value_name = "DURATION", value_parser = parse_duration)]
    pub(crate) turnaround: Option<Duration>,

    /// RTU/ASCII: after a timeout, how long its reply is still awaited (and dropped) before the
    /// line is used again; default: twice the timeout. Size it to the device's slowest reply.
    /// A pipelined Modbus/TCP line (gateway --in-flight past 1): how long a timed-out request's id is kept
    /// out of use
    #[arg(long = "late-window", global = true, value_name = "DURATION", value_parser = parse_duration)]
    pub(crate) late_window: Option<Duration>,

    /// Do not reopen a serial port or connection that was lost (by default it is reopened,
    /// a serial port only while its path names the same device)
    #[arg(long = "no-reopen", global = true)]
    pub(crate) no_reopen: bool,

    /// Modbus/TCP Security (mbaps): TLS to the --tcp server (port 802 if omitted), trusting --ca
    #[arg(long, global = true)]
    pub(crate) tls: bool,

    /// --tls: our certificate (PEM; the chain, ours first); mbaps servers require one
    #[arg(long, global = true, value_name = "FILE", requires = "key")]
    pub(crate) cert: Option<PathBuf>,

    /// --tls: the private key of --cert (PEM, unencrypted)
    #[arg(long, global = true, value_name = "FILE", requires = "cert")]
    pub(crate) key: Option<PathBuf>,

    /// --tls: the CA certificate(s) the server's certificate must be issued by (PEM)
    #[arg(long, global = true, value_name = "FILE")]
    pub(crate) ca: Option<PathBuf>,

    /// The device's profile: a built-in name or a TOML file; it sets the device's limits, word
    /// order and numbering, and names its parameters for get and set
    #[arg(long, global = true, value_name = "PROFILE")]
    pub(crate) device: Option<String>,

    /// SunSpec model definitions (a directory of model_*.json, or one file) beside the built-in
    /// ones, for `scan --sunspec` and `--device sunspec` (also FERROBUS_SUNSPEC_MODELS)
    #[arg(long = "sunspec-models", global = true, value_name = "PATH")]
    pub(crate) sunspec_models: Option<PathBuf>,

    /// The profile `--device sunspec` discovered (get, poll and backup discover it first).
    #[arg(skip)]
    pub(crate) sunspec: Option<std::sync::Arc<ferrobus_profile::Profile>>,
}

impl ConnectArgs {
    /// The `--device` profile, if one was given; a profile that does not load is a usage error
    /// naming the file and the line.
    pub(crate) fn profile(&self) -> Result<Option<ferrobus_profile::Profile>, CliError> {
        if self.device.as_deref() == Some(SUNSPEC) {
            return match &self.sunspec {
                Some(profile) => Ok(Some(profile.as_ref().clone())),
                None => Err(CliError::Usage(
                    "--device sunspec works with get, poll and backup, which discover the device's SunSpec models \
                     first; `ferrobus scan --sunspec` lists them"
                        .into(),
                )),
            };
        }
        self.device.as_deref().map(load_profile).transpose()
    }

    /// The `--device` profile, which `command` needs.
    pub(crate) fn require_profile(&self, command: &str) -> Result<ferrobus_profile::Profile, CliError> {
        self.profile()?.ok_or_else(|| {
            CliError::Usage(format!(
                "{command} needs --device PROFILE: a built-in one ({}) or a TOML file",
                ferrobus_profile::BUILTIN.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
            ))
        })
    }
}

impl ConnectArgs {
    /// `given` with the `--device` profile's numbering: one-based when its `[addressing] base`
    /// is 1 and neither --one-based nor --modicon was given.
    pub(crate) fn address_args(&self, given: AddressArgs) -> Result<AddressArgs, CliError> {
        let Some(profile) = self.profile()? else { return Ok(given) };
        Ok(AddressArgs { one_based: given.one_based || (!given.modicon && profile.addressing.base == 1), ..given })
    }

    /// A user's ADDRESS in `table` as the address on the wire: the one rule of every command
    /// that takes addresses (read, write, read-write, mask, poll, monitor). `--modicon` reads
    /// a Modicon reference, `--one-based` a manual's register number; else the `--device`
    /// profile's numbering (from 1 where its `[addressing] base` is 1, as the 3G3RX's);
    /// else the number is the wire address.
    pub(crate) fn address(&self, text: &str, table: Table, given: AddressArgs) -> Result<Address, CliError> {
        Address::parse(text, table, self.address_args(given)?)
    }

    /// How the addresses of a command with `given` are numbered, for the hints of an error.
    pub(crate) fn numbering(&self, given: AddressArgs) -> Numbering {
        match (given.modicon, given.one_based, self.profile().ok().flatten()) {
            (true, _, _) => Numbering::Modicon,
            (false, true, _) => Numbering::OneBased,
            (false, false, Some(profile)) if profile.addressing.base == 1 => Numbering::Device(profile.device.name),
            _ => Numbering::Wire,
        }
    }

    /// The read requests of `count` items of `table` from wire address `start`: each within
    /// `--max-per-request` if given, else the `--device` profile's limit, else the spec's,
    /// and never splitting a value of `width` registers; (start, quantity) pairs.
    pub(crate) fn read_pieces(
        &self,
        start: u16,
        count: usize,
        width: usize,
        table: Table,
        given: Option<u16>,
    ) -> Result<Vec<(u16, u16)>, CliError> {
        let limit = self.max_per_request(given, table, false)?;
        let max = crate::address::per_request(limit, table.max_read(), width, crate::value::ValueType::U16)?;
        Ok(split(start, count, width, max).into_iter().map(|(at, n)| (at, crate::address::quantity(n))).collect())
    }

    /// `--max-per-request` if given, else the `--device` profile's limit for `table` (reads,
    /// or writes with `write`), else none (the spec's).
    pub(crate) fn max_per_request(
        &self,
        given: Option<u16>,
        table: Table,
        write: bool,
    ) -> Result<Option<u16>, CliError> {
        if given.is_some() {
            return Ok(given);
        }
        let Some(profile) = self.profile()? else { return Ok(None) };
        let table = ferrobus_profile::Table::from(table);
        let limits = &profile.limits;
        Ok(match (table.is_bits(), write) {
            (true, false) => limits.read_coils,
            (true, true) => limits.write_coils,
            (false, false) => limits.read_registers,
            (false, true) => limits.write_registers,
        })
    }

    /// `given` with the `--device` profile's word order where none was given (the same type:
    /// all four orders).
    pub(crate) fn values(&self, given: ValueArgs) -> Result<ValueArgs, CliError> {
        let Some(profile) = self.profile()? else { return Ok(given) };
        Ok(given.or_order(Some(profile.order())))
    }
}

impl ConnectArgs {
    /// With `--device`, ADDRESS may be a parameter's code or label (`read holding F002`): its
    /// address, and the options to read or write it whole: its type (when --type was left at
    /// u16) and its word order (when none was given). `None` when `text` is a number.
    pub(crate) fn named(
        &self,
        text: &str,
        table: Table,
        given: ValueArgs,
    ) -> Result<Option<(Address, ValueArgs)>, CliError> {
        use crate::value::ValueType as Cli;
        use ferrobus_profile::ValueType as Profile;
        if text.trim().starts_with(|c: char| c.is_ascii_digit()) {
            return Ok(None);
        }
        let Some(profile) = self.profile()? else { return Ok(None) };
        let point = match profile.find(text).as_slice() {
            [] => return Ok(None),
            [one] => (*one).clone(),
            many => {
                return Err(CliError::Usage(format!(
                    "{text:?} names {} parameters ({}): give one, or use get",
                    many.len(),
                    many.iter().map(|p| p.code.as_str()).collect::<Vec<_>>().join(", ")
                )));
            }
        };
        if point.table != ferrobus_profile::Table::from(table) {
            return Err(CliError::Usage(format!("{} is in the {} table, not {table}", point.code, point.table.name())));
        }
        let kind = match point.value_type {
            Profile::Bit | Profile::U16 => Cli::U16,
            Profile::I16 => Cli::I16,
            Profile::U32 => Cli::U32,
            Profile::I32 => Cli::I32,
            Profile::F32 => Cli::F32,
            other => {
                return Err(CliError::Usage(format!(
                    "{} is a {}, which read and write do not type: use get or set",
                    point.code,
                    other.name()
                )));
            }
        };
        let mut values = given;
        if values.kind == Cli::U16 {
            values.kind = kind;
        }
        if point.width > 1 {
            values = values.or_order(Some(point.order));
        }
        let address = Address { wire: point.address, table, style: crate::address::Style::Wire };
        Ok(Some((address, values)))
    }
}

/// A profile by built-in name or path, as a usage error when it does not load.
pub(crate) fn load_profile(name: &str) -> Result<ferrobus_profile::Profile, CliError> {
    ferrobus_profile::Profile::load(name).map_err(|e| CliError::Usage(e.to_string()))
}

/// Parity, as typed. (Plain comments on the variants keep `--help` compact.)
#[derive(ValueEnum, Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum ParityArg {
    // Even parity: the spec's default, 8E1.
    Even,
    // Odd parity.
    Odd,
    // No parity: the spec then asks for two stop bits; many drives ship 8N1.
    None,
}

/// RS-485 direction control, as typed.
#[derive(ValueEnum, Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Rs485Arg {
    // The adapter switches the transmitter itself.
    Auto,
    // The kernel's RS-485 mode.
    Kernel,
    // ferrobus drives RTS around each transmission.
    Rts,
}

pub(crate) use crate::target::Target;

/// The options of a serial line: a TCP connection has none (a serial gateway's line is set
/// on the gateway).
const SERIAL_LINE: [&str; 6] = ["baud", "parity", "data_bits", "stop_bits", "rs485", "low_latency"];

/// The connection options (by clap id) that `bus` (`tcp` or `rtu_tcp`) does not use, and why:
/// a serial line's settings with either, and RTU's gaps and echo with Modbus/TCP, whose frames
/// are delimited by their length and never heard back.
pub(crate) fn unused_by(bus: &str) -> (Vec<&'static str>, &'static str) {
    match bus {
        "tcp" => (
            SERIAL_LINE.into_iter().chain(["t15", "t35", "echo"]).collect(),
            "--tcp is Modbus/TCP, which has no serial line, gaps or echo",
        ),
        "rtu_tcp" => (
            SERIAL_LINE.to_vec(),
            "--rtu-tcp is a TCP connection, which has no serial line (a gateway's line is set on the gateway)",
        ),
        _ => (Vec::new(), ""),
    }
}

impl ConnectArgs {
    /// The bus the options name, or a usage error if they name none or a bad one.
    pub(crate) fn target(&self) -> Result<Target, CliError> {
        self.target_for(if self.tls { MBAPS_PORT } else { MODBUS_TCP_PORT })
    }

    /// [`ConnectArgs::target`], with `default_port` for a `--tcp` host given without one.
    pub(crate) fn target_for(&self, default_port: u16) -> Result<Target, CliError> {
        if self.tls && self.tcp.is_none() {
            return Err(CliError::Usage("--tls is Modbus/TCP Security: it needs --tcp HOST[:PORT]".into()));
        }
        if !self.tls && (self.cert.is_some() || self.ca.is_some()) {
            return Err(CliError::Usage("--cert, --key and --ca are for --tls".into()));
        }
        if self.data_bits == 7 && !self.ascii {
            return Err(CliError::Usage("--data-bits 7 only works with --ascii (RTU needs 8 data bits)".into()));
        }
        if let Some(path) = &self.port {
            return Ok(Target::Serial { path: path.clone(), line: self.line(), ascii: self.ascii });
        }
        if self.ascii && (self.tcp.is_some() || self.rtu_tcp.is_some()) {
            return Err(CliError::Usage("--ascii applies to a serial --port only".into()));
        }
        if let Some(addr) = &self.tcp {
            let addr = with_default_port(addr, default_port)?;
            return Ok(if self.tls { Target::Mbaps(addr) } else { Target::Tcp(addr) });
        }
        if let Some(addr) = &self.rtu_tcp {
            if !has_port(addr) {
                return Err(CliError::Usage(format!(
                    "--rtu-tcp needs HOST:PORT (gateways listen on e.g. 4001 or 502), got '{addr}'"
                )));
            }
            return Ok(Target::RtuTcp(addr.clone()));
        }
        Err(CliError::MissingTarget)
    }

    /// The serial line settings.
    pub(crate) fn line(&self) -> LineConfig {
        let parity = match self.parity {
            ParityArg::Even => Parity::Even,
            ParityArg::Odd => Parity::Odd,
            ParityArg::None => Parity::None,
        };
        // The value parser keeps baud >= 1; the fallback is never used.
        LineConfig::new(self.baud)
            .unwrap_or_default()
            .with_parity(parity)
            .with_data_bits(if self.data_bits == 7 { DataBits::Seven } else { DataBits::Eight })
            .with_stop_bits(if self.stop_bits == 2 { StopBits::Two } else { StopBits::One })
    }

    /// The transport for `target`, with the timing overrides applied.
    pub(crate) fn transport(&self, target: &Target) -> Transport {
        let mut transport = match target {
            Target::Serial { path, line, ascii } => {
                let mut config = SerialConfig::new(path.clone(), *line);
                config.rs485 = match self.rs485 {
                    Rs485Arg::Auto => Rs485::Auto,
                    Rs485Arg::Kernel => Rs485::Kernel,
                    Rs485Arg::Rts => Rs485::Rts,
                };
                config.low_latency = self.low_latency;
                if *ascii { Transport::ascii(config) } else { Transport::rtu(config) }
            }
            Target::Tcp(addr) | Target::Mbaps(addr) => Transport::tcp(addr.clone()),
            Target::RtuTcp(addr) => Transport::rtu_over_tcp(addr.clone()),
        };
        if let Some(t15) = self.t15 {
            transport = transport.with_t1_5(t15);
        }
        if let Some(t35) = self.t35 {
            transport = transport.with_t3_5(t35);
        }
        transport.with_reopen(!self.no_reopen)
    }

    /// The client settings: timeout, retries, turnaround, late window, echo; no backoff (one-shot commands
    /// should report every timeout, not skip the unit).
    pub(crate) fn client_config(&self) -> ClientConfig {
        let mut config =
            ClientConfig { timeout: self.timeout, retries: self.retries, backoff: None, ..Default::default() };
        config.echo_suppression = self.echo;
        config.connect_timeout = self.timeout.max(Duration::from_secs(1));
        if let Some(turnaround) = self.turnaround {
            config.turnaround_delay = turnaround;
        }
        config.late_window = self.late_window;
        config
    }

    /// The client's transport for `target`: [`ConnectArgs::transport`], or TLS with `--tls`
    /// (its certificates read here: a bad file is a usage error naming it).
    pub(crate) fn client_transport(&self, target: &Target) -> Result<Transport, CliError> {
        let Target::Mbaps(addr) = target else { return Ok(self.transport(target)) };
        let Some(ca) = &self.ca else {
            return Err(CliError::Usage(
                "--tls needs --ca FILE: the CA certificate that issued the server's certificate".into(),
            ));
        };
        let identity = self.cert.as_deref().zip(self.key.as_deref());
        let tls = ClientTls::from_pem_files(ca, identity).map_err(|e| CliError::Usage(e.to_string()))?;
        Ok(Transport::tls(addr.clone(), tls).with_reopen(!self.no_reopen))
    }

    /// Opens the bus. A TCP connect waits at most the reply timeout (at least one second).
    pub(crate) async fn open(&self) -> Result<Session, CliError> {
        let target = self.target()?;
        let transport = self.client_transport(&target)?;
        let unit = self.unit()?;
        tracing::info!(%target, unit, "opening");
        let wait = self.timeout.max(Duration::from_secs(1));
        let client = match tokio::time::timeout(wait, Client::connect(transport, self.client_config())).await {
            Ok(result) => result.map_err(|error| CliError::Modbus { error })?,
            Err(_) => return Err(CliError::ConnectTimeout { target: target.to_string(), waited: wait }),
        };
        crate::interrupt::keep_release(&client);
        Ok(Session { client, unit, target })
    }
}

/// An open bus and the unit the commands talk to.
#[derive(Clone, Debug)]
pub(crate) struct Session {
    /// The client.
    pub(crate) client: Client,
    /// The unit address from `--unit`.
    pub(crate) unit: u8,
    /// What was opened.
    pub(crate) target: Target,
}

impl Session {
    /// Whether requests to the unit are broadcasts (unit 0 on a serial framing).
    pub(crate) fn is_broadcast(&self) -> bool {
        unit::is_broadcast(self.unit, !matches!(self.target, Target::Tcp(_) | Target::Mbaps(_)))
    }
}

impl ConnectArgs {
    /// The one unit a client command talks to.
    pub(crate) fn unit(&self) -> Result<u8, CliError> {
        match self.unit[..] {
            [unit] => Ok(unit),
            _ => Err(CliError::Usage("give --unit once: a client command talks to one unit".into())),
        }
    }

    /// A usage error for reading from a broadcast address (unit 0 on a serial framing), found
    /// before the bus is opened.
    pub(crate) fn refuse_broadcast_read(&self) -> Result<(), CliError> {
        if unit::is_broadcast(self.unit()?, self.tcp.is_none()) {
            return Err(CliError::Usage(
                "unit 0 is a broadcast: no device answers it, so there is nothing to read; use --unit 1-247".into(),
            ));
        }
        Ok(())
    }
}

fn has_port(addr: &str) -> bool {
    match addr.strip_prefix('[') {
        Some(rest) => rest.contains("]:"),
        None => addr.matches(':').count() == 1,
    }
}

/// The port of Modbus/TCP.
pub(crate) const MODBUS_TCP_PORT: u16 = 502;
pub(crate) use ferrobus::tls::MBAPS_PORT;

/// `host` → `host:502` (or `default_port`); `::1` → `[::1]:502`.
pub(crate) fn with_default_port(addr: &str, default_port: u16) -> Result<String, CliError> {
    if addr.is_empty() {
        return Err(CliError::Usage("--tcp needs a host, e.g. 192.168.1.10 or plc:502".into()));
    }
    if has_port(addr) {
        return Ok(addr.to_string());
    }
    if addr.starts_with('[') {
        return Ok(format!("{addr}:{default_port}"));
    }
    if addr.contains(':') {
        return Ok(format!("[{addr}]:{default_port}"));
    }
    Ok(format!("{addr}:{default_port}"))
}

/// A duration by the one grammar, [`ferrobus::text::duration`] (a plain number is
/// milliseconds; ns, us, ms, s, min, h; at most a year).
pub(crate) fn parse_duration(text: &str) -> Result<Duration, String> {
    ferrobus::text::duration(text).map_err(|e| e.to_string())
}

/// A reply timeout: a duration above zero (a timeout of 0 gives up before any reply can come).
fn parse_timeout(text: &str) -> Result<Duration, String> {
    let timeout = parse_duration(text)?;
    if timeout.is_zero() {
        return Err(format!("'{text}': a timeout of 0 gives up before any reply can come; use e.g. 500ms"));
    }
    Ok(timeout)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_take_units_and_plain_numbers_are_milliseconds() {
        for (typed, want) in ferrobus::text::DURATION_EXAMPLES {
            assert_eq!(parse_duration(typed), Ok(want), "{typed}");
        }
        assert_eq!(parse_duration("500ms"), Ok(Duration::from_millis(500)));
        assert!(parse_duration("-1s").is_err());
        assert!(parse_duration("fast").is_err());
        assert!(parse_duration("1.2.3s").is_err());
        assert_eq!(parse_duration("5h"), Ok(Duration::from_secs(5 * 3600)), "poll --duration may run for hours");
        assert!(parse_duration("99999999999999999999s").is_err());
        assert!(parse_duration("").is_err());
    }

    #[test]
    fn a_zero_timeout_is_refused_and_any_other_accepted() {
        for zero in ["0", "0ms", "0s", "0.0s"] {
            let err = parse_timeout(zero).unwrap_err();
            assert!(err.contains("a timeout of 0 gives up before any reply can come"), "{zero}: {err}");
        }
        assert_eq!(parse_timeout("1us"), Ok(Duration::from_micros(1)));
        assert_eq!(parse_timeout("1.5s"), Ok(Duration::from_millis(1500)));
        assert!(parse_timeout("fast").is_err());
    }

    #[test]
    fn tcp_addresses_get_port_502_unless_they_have_one() {
        assert_eq!(with_default_port("plc", 502).unwrap(), "plc:502");
        assert_eq!(with_default_port("10.0.0.5:1502", 502).unwrap(), "10.0.0.5:1502");
        assert_eq!(with_default_port("::1", 502).unwrap(), "[::1]:502");
        assert_eq!(with_default_port("[::1]", 502).unwrap(), "[::1]:502");
        assert_eq!(with_default_port("[::1]:5020", 502).unwrap(), "[::1]:5020");
        assert!(with_default_port("", 502).is_err());
    }

    #[test]
    fn mbaps_addresses_get_port_802_unless_they_have_one() {
        assert_eq!(with_default_port("plc", MBAPS_PORT).unwrap(), "plc:802");
        assert_eq!(with_default_port("::1", MBAPS_PORT).unwrap(), "[::1]:802");
        assert_eq!(with_default_port("plc:8802", MBAPS_PORT).unwrap(), "plc:8802");
    }
}
