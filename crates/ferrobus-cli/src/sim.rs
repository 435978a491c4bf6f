//! `ferrobus sim`: simulated drives on a serial line, a pty, or TCP.
//!
//! Each `--profile` is paired with a `--unit`: one profile for every unit, or one per unit in
//! the order given. The simulator answers exactly as its profile says — function codes, limits,
//! timing, vendor exceptions — stays silent for other units, bad CRCs and broadcasts, and
//! injects the faults asked for. Over Modbus/TCP a single device also answers units 0xFF and
//! 0, several units answer a unit not simulated with exception 0x0B, and `--any-unit` answers
//! them all ([`tcp_units`]); the server's limits are `--max-connections`, `--idle-timeout` and
//! `--frame-timeout`. It runs until interrupted, then prints its counters (SIGUSR1
//! prints them at any time), including how late each reply went out after it was due.
//! `--ticker` makes a point count periods of the wall clock ([`ferrobus_sim::ticker`]), for
//! latency measurements.

use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use clap::Args;
#[cfg(unix)]
use ferrobus::Pty;
use ferrobus::server::{
    ConnectionPolicy, ServerEvent, ServerOptions, Shared, TcpCounts, TcpServeConfig, serve_tcp_with, serve_transport,
};
use ferrobus::tls::{ServerTls, serve_tls_with};
use ferrobus::{Framing, Timer, Transport};
use ferrobus_proto::ExceptionCode;
use ferrobus_proto::slave::{Disposition, SlaveConfig, SlaveEvent, UnitSet};
use ferrobus_sim::{Device, FaultFilter, Faults, Profile, ProfileFaults, Sim, Ticker, Unserved, tokio_clock};
use hdrhistogram::Histogram;
use status::SimStatus;

use crate::connect::{ConnectArgs, MBAPS_PORT, MODBUS_TCP_PORT, Target, parse_duration};
use crate::exit::CliError;
use crate::interrupt::Interrupt;
use crate::metrics::{self, MetricsArgs};
use crate::server_limits::ServerLimitsArgs;
use crate::server_tls::ServerTlsArgs;

mod status;

/// Arguments of `ferrobus sim`.
#[derive(Args, Clone, Debug)]
pub(crate) struct SimArgs {
    /// Device profile: omron-3g3rx, sdp-servo, generic, sunspec-inverter, or a .toml file; each
    /// --unit takes the --profile written before it (or the first one)
    #[arg(long, required = true, value_name = "NAME|FILE")]
    profile: Vec<String>,

    /// The profile of each unit, paired by position on the command line.
    #[arg(skip)]
    paired: Option<Vec<String>>,

    /// Make a pty, print its path, and serve on it (instead of --port, --tcp or --rtu-tcp; Unix)
    #[arg(long, conflicts_with_all = ["port", "tcp", "rtu_tcp"])]
    pub(crate) pty: bool,

    /// Fault injection for one unit, e.g. 1:drop=10%,delay=50ms,corrupt=5%,exception=0x06,silent,trip=5s;
    /// or a rule aimed at some requests, e.g. 1:fc=0x03,addr=0x1000-0x100F,share=50%,exception=0x06
    /// (matchers fc, addr, share; one action: exception=CODE, no-reply, delay=D, short[=N],
    /// malformed, unit=N, tid=+N|N, trickle=GAP). Repeat it: a unit's rules are tried in order, and
    /// its --fault options replace its profile's faults
    #[arg(long = "fault", value_name = "UNIT:SPEC")]
    faults: Vec<String>,

    /// Seed of the fault generator (the same seed repeats the same faults)
    #[arg(long, default_value_t = 1)]
    seed: u64,

    /// Reply wait on top of t3.5 for every unit, overriding the profiles (3G3RX: C078, 0-1000 ms)
    #[arg(long = "response-wait", value_name = "DURATION", value_parser = parse_duration)]
    response_wait: Option<Duration>,

    /// Stop after this long (scripts, tests); default: run until interrupted
    #[arg(long, value_name = "DURATION", value_parser = parse_duration)]
    duration: Option<Duration>,

    #[command(flatten)]
    limits: ServerLimitsArgs,

    /// Modbus/TCP: answer every unit id, the units not simulated by the first --unit's device
    #[arg(long = "any-unit")]
    any_unit: bool,

    /// Make POINT of every unit count whole PERIODs of the system clock since the Unix epoch
    /// (wrapping past its type's largest value), so a reader knows when each value began:
    /// latency benches, e.g. d005:1.1s (repeatable)
    #[arg(long = "ticker", value_name = "POINT:PERIOD")]
    tickers: Vec<String>,

    /// Modbus/TCP Security (`--tls-cert` ...; `--tcp` port 802 if omitted).
    #[command(flatten)]
    tls: ServerTlsArgs,

    #[command(flatten)]
    metrics: MetricsArgs,
}

/// What the simulator has done, kept by its observer.
#[derive(Debug)]
struct Counters {
    requests: u64,
    replies: u64,
    exceptions: u64,
    silent: u64,
    other_units: u64,
    discarded: u64,
    dropped_replies: u64,
    /// How late each reply went out after it was due, in microseconds: see [`lateness_histogram`].
    lateness_us: Histogram<u64>,
}

impl Default for Counters {
    fn default() -> Self {
        Counters {
            requests: 0,
            replies: 0,
            exceptions: 0,
            silent: 0,
            other_units: 0,
            discarded: 0,
            dropped_replies: 0,
            lateness_us: lateness_histogram(),
        }
    }
}

/// The longest lateness the summary tells apart, in microseconds: an hour. A reply later than
/// that is counted as an hour late.
const LATENESS_BOUND_US: u64 = 3_600_000_000;

/// A histogram of lateness in microseconds from 0 to [`LATENESS_BOUND_US`], to three
/// significant digits: a fixed size however long the simulator runs. Its bounds are explicit:
/// a histogram made with `Histogram::new` starts with a range of a few µs and a saturating
/// record clamps to that range instead of growing it, so a reply 21 ms late was counted as
/// 42 µs.
fn lateness_histogram() -> Histogram<u64> {
    Histogram::new_with_bounds(1, LATENESS_BOUND_US, 3)
        .expect("1 µs to an hour at 3 significant digits are bounds hdrhistogram takes")
}

impl Counters {
    fn print(&self) {
        eprintln!(
            "sim: {} requests: {} replies ({} exceptions), {} unanswered; {} frames for other units, {} noise discards, {} replies dropped by faults",
            self.requests,
            self.replies,
            self.exceptions,
            self.silent,
            self.other_units,
            self.discarded,
            self.dropped_replies
        );
        if let Some(line) = self.lateness_line() {
            eprintln!("{line}");
        }
    }

    /// How late the replies went out, for the summary; none before the first reply.
    fn lateness_line(&self) -> Option<String> {
        let late = &self.lateness_us;
        (!late.is_empty()).then(|| {
            format!(
                "sim: reply start after its due time (t3.5 + wait): p50 {} µs, p99 {} µs, max {} µs over {} replies",
                late.value_at_quantile(0.50),
                late.value_at_quantile(0.99),
                late.max(),
                late.len()
            )
        })
    }

    /// Counts a reply that went out `late` after it was due.
    fn record_lateness(&mut self, late: Duration) {
        self.lateness_us.saturating_record(u64::try_from(late.as_micros()).unwrap_or(u64::MAX));
    }
}

/// Runs `ferrobus sim`.
pub(crate) async fn run(connection: &ConnectArgs, args: &SimArgs) -> Result<(), CliError> {
    let mut sim = build(connection, args)?;
    let tls = server_tls(connection, args)?;
    let status = args.metrics.bind().await?;
    // Listened for before it says where it serves, so that no early signal kills it.
    let mut signals = Signals::listen()?;
    let (transport, port) = open(connection, args).await?;
    let framing = transport.framing();
    let units = if matches!(port, Served::Listener(_)) && framing == Framing::Mbap {
        tcp_units(&mut sim, args.any_unit)
    } else {
        if args.any_unit {
            return Err(CliError::Usage("--any-unit is for Modbus/TCP (--tcp)".into()));
        }
        sim.unit_set()
    };
    let counters = Arc::new(Mutex::new(Counters::default()));
    let sim = Shared::new(sim);
    let limits = args.limits.limits(ConnectionPolicy::TCP.max_pending);
    let tcp_stats = Arc::clone(&limits.stats);
    if let Some(listener) = status {
        let tcp = matches!(port, Served::Listener(_)).then(|| Arc::clone(&tcp_stats));
        let summary = format!("serving {} ({:?})", transport.describe(), framing);
        let source = SimStatus { counters: Arc::clone(&counters), tcp, summary };
        metrics::spawn(listener, Arc::new(source), "sim");
    }
    let options = {
        let (sim, counters, transport) = (sim.clone(), Arc::clone(&counters), transport.clone());
        move || {
            let mut options = ServerOptions::for_transport(&transport);
            options.filter = Some(Box::new(FaultFilter::new(sim.clone(), framing)));
            let counters = Arc::clone(&counters);
            options.observer = Some(Box::new(move |event| observe(&counters, event)));
            options
        }
    };
    let config = SlaveConfig { units, response_wait: Duration::ZERO };
    let reopen = !args.pty && transport.reopens();
    let serve_config = TcpServeConfig { limits, ..TcpServeConfig::new(transport.clone(), config) };
    // Its own task: a request wakes the server alone, not the signal handlers below.
    let mut serving = tokio::spawn(async move {
        match port {
            Served::Port(port) => serve_port(&transport, port, reopen, config, &sim, &options).await,
            Served::Listener(listener) => match tls {
                Some(tls) => serve_tls_with(listener, serve_config, sim.clone(), options, tls)
                    .await
                    .map_err(|e| ferrobus::Error::io("serving", e).into()),
                None => serve_tcp_with(listener, serve_config, sim.clone(), options)
                    .await
                    .map_err(|e| ferrobus::Error::io("serving", e).into()),
            },
        }
    });
    // A --duration ends the run early; Ctrl-C and SIGTERM end it too, with the counters.
    let stop = async {
        let until = async {
            match args.duration {
                Some(d) => tokio::time::sleep(d).await,
                None => std::future::pending().await,
            }
        };
        tokio::select! {
            () = until => {}
            () = signals.interrupted(&counters) => {}
        }
    };
    let result = tokio::select! {
        ended = &mut serving => ended.unwrap_or_else(|e| Err(ferrobus::Error::io("serving", std::io::Error::other(e)).into())),
        () = stop => Ok(()),
    };
    serving.abort();
    counters.lock().unwrap_or_else(PoisonError::into_inner).print();
    print_tcp(&tcp_stats.counts(), args.tls.enabled());
    result
}

/// The mbaps server's TLS setup, if `--tls-cert` asks for one: its certificate, key, client
/// CA and roles file read now, so a bad file is an error before anything is served.
fn server_tls(connection: &ConnectArgs, args: &SimArgs) -> Result<Option<ServerTls>, CliError> {
    if connection.tls {
        return Err(CliError::Usage(
            "--tls is the client's; the simulator serves mbaps with --tls-cert, --tls-key and --tls-ca".into(),
        ));
    }
    if args.tls.enabled() && (connection.tcp.is_none() || args.pty) {
        return Err(CliError::Usage("--tls-cert serves Modbus/TCP Security: it needs --tcp HOST[:PORT]".into()));
    }
    args.tls.load()
}

/// The units the engine passes on over Modbus/TCP, and who answers them. A single device
/// also answers unit 0xFF (the spec's choice for a device addressed directly over TCP, and
/// libmodbus's default) and unit 0; with several, a unit not simulated gets exception 0x0B,
/// as from a gateway whose target does not respond; with `any_unit`, every unit is answered,
/// those not simulated by the first device.
fn tcp_units(sim: &mut Sim, any_unit: bool) -> UnitSet {
    let served = sim.unit_set();
    let Some(first) = served.iter().next() else { return served };
    let mut units = served;
    if any_unit {
        sim.set_unserved(Unserved::Device(first));
        return (0..=u8::MAX).collect();
    }
    if served.iter().count() == 1 {
        for unit in [0, 0xFF] {
            sim.alias(unit, first);
            units.insert(unit);
        }
        return units;
    }
    sim.set_unserved(Unserved::Refuse(ExceptionCode::GatewayTargetDeviceFailedToRespond));
    (0..=u8::MAX).collect()
}

fn print_tcp(c: &TcpCounts, tls: bool) {
    let refused = c.refused.saturating_add(c.refused_source).saturating_add(c.refused_handshakes);
    if c.accepted == 0 && refused == 0 && c.descriptor_waits == 0 && c.accept_errors == 0 {
        return;
    }
    if tls {
        eprintln!(
            "sim: tls: {} handshakes refused, {} connections refused over --tls-max-handshakes-per-source, {} requests denied by the roles (exception 01)",
            c.tls_refused, c.refused_handshakes, c.denied
        );
    }
    eprintln!(
        "sim: tcp: {} connections served ({} open), {} refused over --max-per-source, {} accept pauses out of file descriptors, {} other accept errors, {} socket-option errors; closed: {} to make room over --max-connections ({} in their handshake, {} never answered, {} idle longest), {} idle, {} unfinished frame, {} bad MBAP header",
        c.accepted,
        c.open,
        c.refused_source,
        c.descriptor_waits,
        c.accept_errors,
        c.socket_errors,
        c.evicted_handshakes.saturating_add(c.evicted_unanswered).saturating_add(c.evicted_idle),
        c.evicted_handshakes,
        c.evicted_unanswered,
        c.evicted_idle,
        c.closed_idle,
        c.closed_unfinished,
        c.closed_bad_header
    );
}

/// Serves on `port` until it fails. A serial port that fails or closes — a USB adapter
/// unplugged, the socat of a virtual pair gone — is reopened once a second and served again,
/// the devices keeping their state, as drives on a bus keep theirs, but only while its path
/// names the same device (see `ferrobus::port`); a raw `/dev/pts/N`, a pty of our own, or
/// `--no-reopen` cannot come back, and the port's end is an error.
async fn serve_port<O: Fn() -> ServerOptions>(
    transport: &Transport,
    mut port: ferrobus::port::BoxPort,
    reopen: bool,
    config: SlaveConfig,
    sim: &Shared<Sim>,
    options: &O,
) -> Result<(), CliError> {
    let place = transport.describe();
    loop {
        let mut handler = sim.clone();
        let ended = serve_transport(transport, port, config, &mut handler, &mut options()).await;
        let why = ended.err().unwrap_or_else(|| std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "port closed"));
        if !reopen {
            return Err(ferrobus::Error::io(format!("serving on {place}"), why).into());
        }
        eprintln!("sim: {place}: {why}; reopening it every second");
        let mut refused = None;
        port = loop {
            tokio::time::sleep(Duration::from_secs(1)).await;
            match transport.open(Duration::from_secs(5)).await {
                Ok(port) => break port,
                Err(e @ ferrobus::Error::NotSameDevice { lasting: true, .. }) => return Err(e.into()),
                Err(e @ ferrobus::Error::NotSameDevice { .. }) => {
                    // Another device under the name: say so once, and wait for ours.
                    let said = e.to_string();
                    if refused.as_ref() != Some(&said) {
                        eprintln!("sim: {said}; waiting for the device first opened");
                        refused = Some(said);
                    }
                }
                Err(_) => {}
            }
        };
        eprintln!("sim: serving on {place} again");
    }
}

impl SimArgs {
    /// Gives each `--unit` the `--profile` written before it on the command line, or the
    /// first profile for units written before any.
    pub(crate) fn pair_by_position(&mut self, matches: &clap::ArgMatches) {
        let (Some(profile_at), Some(unit_at)) = (matches.indices_of("profile"), matches.indices_of("unit")) else {
            return;
        };
        let profiles: Vec<(usize, &String)> = profile_at.zip(&self.profile).collect();
        let paired = unit_at
            .map(|at| {
                profiles.iter().rev().find(|(p, _)| *p < at).or(profiles.first()).map(|(_, name)| (*name).clone())
            })
            .collect::<Option<Vec<String>>>();
        self.paired = paired;
    }
}

/// The devices, paired with their units and faults.
fn build(connection: &ConnectArgs, args: &SimArgs) -> Result<Sim, CliError> {
    let units = &connection.unit;
    // Without positions (the default --unit 1), the first profile serves every unit.
    let profiles: Vec<&String> = match &args.paired {
        Some(paired) if paired.len() == units.len() => paired.iter().collect(),
        _ => vec![&args.profile[0]; units.len()],
    };
    if let Some(unused) = args.profile.iter().find(|p| !profiles.contains(p)) {
        return Err(CliError::Usage(format!("--profile {unused} is given to no --unit")));
    }
    if let Some(unit) = units.iter().enumerate().find_map(|(i, u)| units.get(..i)?.contains(u).then_some(u)) {
        return Err(CliError::Usage(format!("--unit {unit} is given twice: one simulated device per address")));
    }
    // Every --fault for a unit, in order: its rules add up.
    let mut faults: Vec<(u8, Faults)> = Vec::new();
    for spec in &args.faults {
        let (unit, spec) = spec
            .split_once(':')
            .and_then(|(u, s)| Some((u.trim().parse::<u8>().ok()?, s)))
            .ok_or_else(|| CliError::Usage(format!("--fault {spec:?}: expected UNIT:SPEC, e.g. 1:drop=10%")))?;
        let parsed: Faults =
            spec.parse().map_err(|e: ferrobus_sim::fault::FaultError| CliError::Usage(e.to_string()))?;
        match faults.iter_mut().find(|(u, _)| *u == unit) {
            Some((_, earlier)) => earlier.merge(parsed),
            None => faults.push((unit, parsed)),
        }
    }
    let mut sim = Sim::new(tokio_clock(), args.seed);
    for (&unit, name) in units.iter().zip(profiles) {
        if !(ferrobus_proto::codes::unit::MIN..=ferrobus_proto::codes::unit::MAX).contains(&unit) {
            return Err(CliError::Usage(format!("--unit {unit}: a simulated device needs an address from 1 to 247")));
        }
        let mut profile = Profile::load(name).map_err(|e| CliError::Usage(e.to_string()))?;
        if let Some(wait) = args.response_wait {
            profile.comm.response_wait_ms = u32::try_from(wait.as_millis()).unwrap_or(u32::MAX);
        }
        let from_profile = profile.faults().map_err(|e| CliError::Usage(e.to_string()))?;
        let unit_faults = faults.iter().find(|(u, _)| *u == unit).map_or(from_profile, |(_, f)| f.clone());
        eprintln!(
            "sim: unit {unit}: {profile} from {name}, reply wait {} ms, faults: {unit_faults}",
            profile.comm.response_wait_ms
        );
        sim.add(unit, Device::new(profile), unit_faults);
    }
    if let Some((unit, _)) = faults.iter().find(|(u, _)| !units.contains(u)) {
        return Err(CliError::Usage(format!("--fault for unit {unit}, which is not simulated")));
    }
    for spec in &args.tickers {
        let ticker = Ticker::parse(spec).map_err(|e| CliError::Usage(format!("--ticker: {e}")))?;
        eprintln!("sim: every unit's {} counts {:?} periods of the system clock", ticker.point(), ticker.period());
        sim.add_ticker(ticker).map_err(|e| CliError::Usage(format!("--ticker: {e}")))?;
    }
    Ok(sim)
}

/// Where the simulator serves.
enum Served {
    Port(ferrobus::port::BoxPort),
    Listener(tokio::net::TcpListener),
}

async fn open(connection: &ConnectArgs, args: &SimArgs) -> Result<(Transport, Served), CliError> {
    #[cfg(not(unix))]
    if args.pty {
        return Err(CliError::Usage(format!("--pty needs a Unix pty (Linux, macOS); {}", crate::unix_only::INSTEAD)));
    }
    #[cfg(unix)]
    if args.pty {
        let pty = Pty::open().map_err(|e| ferrobus::Error::io("making a pty", e))?;
        let framing = if connection.ascii { Framing::Ascii } else { Framing::Rtu };
        let timing = ferrobus_proto::frame::LineTiming::new(&connection.line());
        let transport = Transport::custom(framing, timing, Unused).with_timer(Timer::Spin);
        // The path is the one line on stdout, for scripts to read.
        crate::output::print(&format!("{}\n", pty.path.display()))?;
        return Ok((transport, Served::Port(Box::new(pty))));
    }
    let default_port = if args.tls.enabled() { MBAPS_PORT } else { MODBUS_TCP_PORT };
    let target = connection.target_for(default_port)?;
    let transport = connection.transport(&target);
    match &target {
        Target::Serial { .. } => {
            // A device answers on time to the microsecond; the simulator has its thread to
            // itself, and spins the last 200 µs before each reply for it.
            let transport = transport.with_timer(Timer::Spin);
            let port = transport.open(Duration::from_secs(5)).await?;
            eprintln!("sim: serving on {}", transport.describe());
            Ok((transport, Served::Port(port)))
        }
        // The sim's own TLS is --tls-cert: the client's --tls (Mbaps) was refused before.
        Target::Tcp(addr) | Target::RtuTcp(addr) | Target::Mbaps(addr) => {
            let listener = tokio::net::TcpListener::bind(addr)
                .await
                .map_err(|e| ferrobus::Error::io(format!("listening on {addr}"), e))?;
            let security = if args.tls.enabled() { ", TLS: Modbus/TCP Security" } else { "" };
            eprintln!("sim: listening on {addr} ({:?}{security})", transport.framing());
            Ok((transport, Served::Listener(listener)))
        }
    }
}

/// The connector of a pty transport: the pty is already open, and is not reopened.
#[cfg(unix)]
struct Unused;

#[cfg(unix)]
impl ferrobus::port::Connector for Unused {
    fn connect(&self) -> ferrobus::port::Connecting {
        Box::pin(async { Err(std::io::ErrorKind::Unsupported.into()) })
    }
    fn describe(&self) -> String {
        "pty".into()
    }
}

fn observe(counters: &Mutex<Counters>, event: ServerEvent) {
    let mut c = counters.lock().unwrap_or_else(PoisonError::into_inner);
    match event {
        ServerEvent::Slave { event: SlaveEvent::Request { unit, function, end, disposition, .. }, .. } => {
            c.requests += 1;
            // How long after the request's last byte the reply is due: t3.5 + the wait.
            let due_us = |due: ferrobus_proto::Instant| due.saturating_duration_since(end).as_micros();
            match disposition {
                Disposition::Replied(due) => {
                    tracing::info!(unit, %function, due_us = due_us(due), "request: reply due");
                }
                Disposition::Refused(code, due) => {
                    c.exceptions += 1;
                    tracing::info!(unit, %function, %code, due_us = due_us(due), "request: exception due");
                }
                Disposition::Executed | Disposition::Silent => {
                    c.silent += 1;
                    tracing::info!(unit, %function, ?disposition, "request: no reply");
                }
            }
        }
        ServerEvent::Slave { event: SlaveEvent::Ignored { unit, function, why }, .. } => {
            c.other_units += 1;
            tracing::info!(unit, %function, ?why, "frame not for us");
        }
        ServerEvent::Slave { event: SlaveEvent::Discarded { bytes, reason, .. }, .. } => {
            c.discarded += 1;
            tracing::info!(bytes, %reason, "discarded");
        }
        ServerEvent::Slave { event: SlaveEvent::Restart { clear_log }, .. } => tracing::info!(clear_log, "restart"),
        ServerEvent::Sent { frame, due, at } => {
            c.replies += 1;
            let late = at.saturating_duration_since(due);
            c.record_lateness(late);
            tracing::info!(frame = %crate::hex::format(&frame), late_us = late.as_micros(), "reply sent");
        }
        ServerEvent::Dropped { frame } => {
            c.dropped_replies += 1;
            tracing::info!(frame = %crate::hex::format(&frame), "reply dropped (fault)");
        }
    }
}

/// The signals the simulator takes: Ctrl-C and SIGTERM end it, SIGUSR1 prints its counters
/// (Windows has Ctrl-C alone). Listened for from the start: the default action of each would
/// end the process without its counters.
struct Signals {
    interrupt: Interrupt,
    #[cfg(unix)]
    usr1: tokio::signal::unix::Signal,
}

impl Signals {
    fn listen() -> Result<Signals, CliError> {
        let interrupt = Interrupt::listen()?;
        #[cfg(unix)]
        {
            use tokio::signal::unix::{SignalKind, signal};
            let usr1 = signal(SignalKind::user_defined1())
                .map_err(|e| CliError::from(ferrobus::Error::io("listening for SIGUSR1", e)))?;
            Ok(Signals { interrupt, usr1 })
        }
        #[cfg(not(unix))]
        Ok(Signals { interrupt })
    }

    /// Waits for Ctrl-C or SIGTERM, printing the counters on each SIGUSR1 meanwhile.
    async fn interrupted(&mut self, counters: &Mutex<Counters>) {
        #[cfg(unix)]
        loop {
            tokio::select! {
                () = self.interrupt.wait() => return,
                _ = self.usr1.recv() => counters.lock().unwrap_or_else(PoisonError::into_inner).print(),
            }
        }
        #[cfg(not(unix))]
        {
            let _ = counters;
            self.interrupt.wait().await;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_summary_reports_a_reply_21_ms_late_as_21_ms_not_clamped_to_microseconds() {
        let mut counters = Counters::default();
        counters.record_lateness(Duration::from_micros(40));
        counters.record_lateness(Duration::from_millis(21));
        let max = counters.lateness_us.max();
        assert!(counters.lateness_us.equivalent(max, 21_000), "max {max} µs");
        let line = counters.lateness_line().expect("two replies were counted");
        assert!(line.ends_with(&format!("max {max} µs over 2 replies")), "{line}");
    }

    #[test]
    fn a_reply_later_than_an_hour_counts_as_an_hour_late() {
        let mut counters = Counters::default();
        counters.record_lateness(Duration::from_secs(5 * 3600));
        let max = counters.lateness_us.max();
        assert!(counters.lateness_us.equivalent(max, LATENESS_BOUND_US), "max {max} µs");
    }

    #[test]
    fn no_reply_gives_no_lateness_line() {
        assert_eq!(Counters::default().lateness_line(), None);
    }
}
