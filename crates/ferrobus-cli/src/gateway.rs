//! `ferrobus gateway`: Modbus/TCP clients to RTU serial lines, or to one device over TCP.
//!
//! The first line is `--port` with the usual line options; `--line PATH` adds more lines with
//! the same settings (numbered 1, 2, ... in the order given; `--port` is line 0). `--tcp
//! HOST[:PORT]` or `--rtu-tcp HOST:PORT` in place of `--port` makes the one line a device over
//! TCP, shared by every client of the gateway (a multiplexer for a device that takes one
//! connection); several such lines, or a mix with serial ones, come from `--lines-file`. `--route
//! UNITS=LINE[:UNIT]` says which units go where (with one line and no `--route`, units 1-247
//! go to it under their own addresses, and every unit id 0-255 to a `--tcp` line); a unit in
//! no route gets exception 0x0A. The library
//! ([`ferrobus_tools::gateway`]) documents every answer the gateway gives and why. The counters of
//! every line and unit, and the requests the front end refused by reason, are printed on
//! SIGUSR1 and at exit. `--reverse` turns it around: a
//! slave on `--port` for the units of `--route UNIT=HOST:PORT[/UNIT]`, each forwarded to its
//! Modbus/TCP server. `--lines-file FILE` gives every line its own settings and units instead
//! (see [`lines`]); SIGHUP reads it again and changes what changed, the rest running on
//! ([`ferrobus_tools::gateway::reload`]; Unix only: Windows has no SIGHUP).

mod lines;

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, SystemTime};

use clap::Args;
use ferrobus::server::TcpCounts;
use ferrobus::{Client, Transport};
use ferrobus_tools::gateway::config::LinesFile;
use ferrobus_tools::gateway::status::GatewayStatus;
use ferrobus_tools::gateway::{
    AllowAll, Authorize, FrontConfig, Gateway, GatewayConfig, GatewayLine, Inbound, OnFailure, Route, Routes, Rules,
    Upstream, serve_reverse,
};
use ferrobus_tools::status::{Reloads, Summary};

use crate::connect::{ConnectArgs, Target, parse_duration};
use crate::exit::CliError;
use crate::interrupt::{Hangup, Interrupt};
use crate::metrics::{self, MetricsArgs};
use crate::server_limits::ServerLimitsArgs;
use crate::server_tls::ServerTlsArgs;
use crate::systemd;

/// Arguments of `ferrobus gateway`.
#[derive(Args, Clone, Debug)]
#[expect(clippy::struct_excessive_bools, reason = "each bool is a command-line flag")]
pub(crate) struct GatewayArgs {
    /// Where Modbus/TCP clients connect (binds 127.0.0.1 unless told otherwise; 127.0.0.1:802
    /// with --tls-cert)
    #[arg(
        long,
        value_name = "ADDR:PORT",
        default_value = "127.0.0.1:502",
        default_value_if("tls_cert", clap::builder::ArgPredicate::IsPresent, "127.0.0.1:802")
    )]
    listen: String,

    /// Clients send RTU frames over TCP (CRC and all) instead of Modbus/TCP
    #[arg(long = "rtu-in")]
    rtu_in: bool,

    /// Another serial line with the same settings as --port (line 1, 2, ... in order; not
    /// beside --tcp or --rtu-tcp: several TCP lines come from --lines-file)
    #[arg(long = "line", value_name = "PATH")]
    lines: Vec<String>,

    /// Lines from a TOML file instead of --port/--tcp/--rtu-tcp, --line and --route: [[line]]
    /// tables, each with its port (or tcp = "HOST[:PORT]", rtu-tcp = "HOST:PORT"), line options
    /// (baud, parity, timeout, response-wait, ...) and units (units, renumber); what a line
    /// leaves out comes from the connection options. SIGHUP reads it again: a line whose
    /// settings are unchanged runs on, a changed one restarts, the routes change for new
    /// requests; a file with a mistake is refused and logged, the running lines stay (not on
    /// Windows, which has no SIGHUP)
    #[arg(long = "lines-file", value_name = "FILE", conflicts_with_all = ["lines", "routes", "reverse"])]
    pub(crate) lines_file: Option<PathBuf>,

    /// Route units to a line, optionally renumbered: 5=0, 1-10=1, 20=0:3 (unit 20 is unit 3
    /// on line 0; a range renumbered keeps its order: 11-20=1:1 is units 1-10 on line 1)
    #[arg(long = "route", value_name = "UNITS=LINE[:UNIT]")]
    routes: Vec<String>,

    /// Requests that may wait for each line; past it a request gets 0x06 (busy) at once
    #[arg(long, default_value_t = 64, value_parser = clap::value_parser!(u32).range(1..))]
    queue: u32,

    /// Requests one connection may have outstanding, queued or on the line (1 to 16, the
    /// slave engine's slots); past it the gateway stops reading that connection until a reply
    /// has gone out (TCP holds it back)
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u32).range(1..=16))]
    pipeline: u32,

    /// On a Modbus/TCP line (--tcp, or tcp = in --lines-file): requests outstanding on the
    /// device's connection at once (1 to 16), each matched to its reply by transaction id; 1
    /// sends the next only once the last has ended. More hides the round trip for a device
    /// that answers every request of its connection in order (libmodbus's server does; one
    /// that answers only the first of several that reach it together, as pymodbus's, wants 1)
    #[arg(long = "in-flight", value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=16))]
    in_flight: u32,

    /// Answer a broadcast (unit 0) with its echo once it has gone out (the spec: no reply)
    #[arg(long = "broadcast-ack")]
    broadcast_ack: bool,

    /// Answer reads from a cache of replies younger than this (e.g. 200ms); writes go through
    /// and drop the cached reads they touch
    #[arg(long = "cache-max-age", value_name = "DURATION", value_parser = parse_duration)]
    cache_max_age: Option<Duration>,

    /// Refuse every request that may change a device, with exception 0x01
    #[arg(long = "read-only")]
    read_only: bool,

    /// Let only these units through (as clients address them): 1,2,10-20; others get 0x0A
    #[arg(long = "allow-units", value_name = "LIST")]
    allow_units: Option<String>,

    /// Let only these function codes through: 3,4,0x10; others get 0x01
    #[arg(long = "allow-functions", value_name = "LIST")]
    allow_functions: Option<String>,

    /// Skip a unit after this many timed-out requests in a row, probing it now and then (0: never skip)
    #[arg(long = "backoff-after", default_value_t = 3)]
    backoff_after: u32,

    /// How long a unit that stopped answering is skipped before the first probe; each failed
    /// probe doubles it, up to --backoff-max
    #[arg(long = "backoff-skip", value_name = "DURATION", default_value = "5s", value_parser = parse_duration)]
    backoff_skip: Duration,

    /// The longest a unit is skipped between two probes
    #[arg(long = "backoff-max", value_name = "DURATION", default_value = "60s", value_parser = parse_duration)]
    backoff_max: Duration,

    /// After a request that got no usable reply, keep the line quiet at least this long (a
    /// timed-out request's own late reply is awaited and dropped besides, for up to twice
    /// --timeout). Not on a Modbus/TCP line: its transaction ids tell a late reply apart
    #[arg(long = "late-guard", value_name = "DURATION", default_value = "100ms", value_parser = parse_duration)]
    late_guard: Duration,

    #[command(flatten)]
    limits: ServerLimitsArgs,

    /// Reverse: a slave on the serial --port for the units of --route UNIT=HOST:PORT[/UNIT],
    /// forwarding each request to that Modbus/TCP server
    #[arg(long)]
    reverse: bool,

    /// Reverse: when the TCP server gives no answer, stay silent or answer 0x0B (0x0A if it
    /// cannot be reached)
    #[arg(long = "on-failure", value_enum, default_value_t = OnFailureArg::Silent)]
    on_failure: OnFailureArg,

    /// Stop after this long (and print the counters), instead of running until interrupted
    #[arg(long, value_name = "DURATION", value_parser = parse_duration)]
    duration: Option<Duration>,

    /// Modbus/TCP Security: TLS with client certificates and roles.
    #[command(flatten)]
    tls: ServerTlsArgs,

    #[command(flatten)]
    metrics: MetricsArgs,
}

/// What the reverse gateway does when the TCP side gives no answer, as typed.
#[derive(clap::ValueEnum, Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum OnFailureArg {
    // No reply: the serial master times out.
    Silent,
    // Exception 0x0B (0x0A when the server cannot be reached).
    Exception,
}

/// Runs `ferrobus gateway`.
pub(crate) async fn run(connection: &ConnectArgs, args: &GatewayArgs) -> Result<(), CliError> {
    if args.reverse {
        return reverse(connection, args).await;
    }
    let (config, mut running) = config(connection, args)?;
    let rules = rules(args)?;
    if args.tls.enabled() && args.rtu_in {
        return Err(CliError::Usage("--tls-cert serves Modbus/TCP Security (MBAP frames): not with --rtu-in".into()));
    }
    let tls = args.tls.load()?;
    let secure = tls.is_some();
    let mut interrupt = Interrupt::listen()?;
    let mut hangup = Hangup::listen()?;
    #[cfg(unix)]
    let mut usr1 = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::user_defined1())
        .map_err(|e| CliError::from(ferrobus::Error::io("listening for SIGUSR1", e)))?;
    let listener = tokio::net::TcpListener::bind(&args.listen)
        .await
        .map_err(|e| ferrobus::Error::io(format!("listening on {}", args.listen), e))?;
    let bound = listener.local_addr().map_err(|e| ferrobus::Error::io("listening", e))?;
    let status = args.metrics.bind().await?;
    let front = format!(
        "listening on {bound} ({})",
        if args.rtu_in {
            "RTU over TCP"
        } else if secure {
            "Modbus/TCP Security"
        } else {
            "Modbus/TCP"
        }
    );
    let text = summary(&front, &config.lines);
    let described = Described {
        front,
        summary: Arc::new(Mutex::new(if running.is_some() { Summary::reloadable(text) } else { Summary::fixed(text) })),
    };
    let gateway = Gateway::start(config).await?;
    // A request a line has in flight when the gateway stops is owed its reply: the process
    // keeps the port until it has come or its window has passed.
    gateway.releases().into_iter().for_each(crate::interrupt::keep);
    let inbound = if args.rtu_in { Inbound::RtuOverTcp } else { Inbound::Mbap };
    eprintln!("gateway: {}", described.text());
    let pipeline = usize::try_from(args.pipeline).unwrap_or(usize::MAX);
    let limits = args.limits.limits(pipeline);
    let tcp = Arc::clone(&limits.stats);
    if let Some(listener) = status {
        let source = GatewayStatus::new(gateway.clone(), Arc::clone(&tcp), Arc::clone(&described.summary));
        metrics::spawn(listener, Arc::new(source), "gateway");
    }
    let front = FrontConfig { inbound, limits };
    let serving = {
        let gateway = gateway.clone();
        tokio::spawn(async move {
            let authorize = move |_: SocketAddr| -> Box<dyn Authorize> {
                if rules.allows_all() { Box::new(AllowAll) } else { Box::new(rules.clone()) }
            };
            match tls {
                Some(tls) => gateway.serve_tls(listener, front, authorize, tls).await,
                None => gateway.serve_tcp(listener, front, authorize).await,
            }
        })
    };
    let until = async {
        match args.duration {
            Some(d) => tokio::time::sleep(d).await,
            None => std::future::pending().await,
        }
    };
    tokio::pin!(until);
    let watchdog = systemd::ready(&format!("gateway: listening on {bound}"));
    loop {
        #[cfg(unix)]
        let usr1 = usr1.recv();
        #[cfg(not(unix))]
        let usr1 = std::future::pending::<Option<()>>();
        tokio::select! {
            () = interrupt.wait() => break,
            () = &mut until => break,
            _ = usr1 => print(&gateway, &tcp.counts(), secure, described.reloads().as_ref()),
            () = hangup.wait() => watchdog.feeding(reload(connection, args, &gateway, &mut running, &described)).await,
            () = watchdog.tick() => watchdog.feed(),
        }
    }
    systemd::stopping();
    serving.abort();
    print(&gateway, &tcp.counts(), secure, described.reloads().as_ref());
    Ok(())
}

/// What the gateway says of itself (its summary, on stderr at the start and on the status
/// page), and what SIGHUP has done so far, shared with the status page.
#[derive(Debug)]
struct Described {
    /// `listening on 127.0.0.1:502 (Modbus/TCP)`: what no reload changes.
    front: String,
    /// The summary with the lines as applied last, and the reloads.
    summary: Arc<Mutex<Summary>>,
}

impl Described {
    /// The summary now.
    fn text(&self) -> String {
        self.summary.lock().unwrap_or_else(PoisonError::into_inner).text().to_string()
    }

    /// The reloads so far; `None` without a lines file.
    fn reloads(&self) -> Option<Reloads> {
        self.summary.lock().unwrap_or_else(PoisonError::into_inner).reloads().cloned()
    }

    /// A reload was applied: the summary is now `text`, and it did `done`.
    fn applied(&self, text: String, done: String) {
        self.summary.lock().unwrap_or_else(PoisonError::into_inner).applied(text, done, SystemTime::now());
    }

    /// A reload was refused: the lines are as they were.
    fn refused(&self) {
        self.summary.lock().unwrap_or_else(PoisonError::into_inner).refused(SystemTime::now());
    }
}

/// `listening on 127.0.0.1:502 (Modbus/TCP), lines: 0=/dev/ttyUSB0 at 19200 8E1, 1=10.0.0.7:502`:
/// `front` and each line by its number and what it is.
fn summary(front: &str, lines: &[GatewayLine]) -> String {
    let lines: Vec<String> = lines.iter().enumerate().map(|(i, l)| format!("{i}={}", l.transport.describe())).collect();
    format!("{front}, lines: {}", lines.join(", "))
}

/// Reads `--lines-file` again and changes in `gateway` what differs from `running` (the
/// file it runs now, which it then becomes, and the summary its lines); a file with a mistake,
/// or an added serial port that cannot be opened, changes nothing and is logged as an error.
/// Either is counted in `described`. Tells systemd it reloads, and when it is done. Without a
/// lines file there is nothing to read: a warning.
async fn reload(
    connection: &ConnectArgs,
    args: &GatewayArgs,
    gateway: &Gateway,
    running: &mut Option<LinesFile>,
    described: &Described,
) {
    let (Some(path), Some(running)) = (&args.lines_file, running.as_mut()) else {
        tracing::warn!("SIGHUP: the gateway reads no --lines-file, so there is nothing to read again");
        return;
    };
    systemd::reloading();
    let applied = async {
        let (config, file) = lines_file(path, connection, args)?;
        let plan = ferrobus_tools::gateway::reload::plan(running, &file);
        let text = summary(&described.front, &config.lines);
        let started = gateway.reload(&plan, config).await?;
        started.into_iter().for_each(crate::interrupt::keep);
        *running = file;
        Ok::<_, CliError>((plan, text))
    };
    let status = match applied.await {
        Ok((plan, text)) => {
            described.applied(text, plan.to_string());
            tracing::info!("reload: {plan}");
            format!("reloaded: {plan}")
        }
        Err(e) => {
            described.refused();
            let report = crate::exit::report(&e, None, 0);
            tracing::error!("reload refused, the running lines stay as they are: {}", report.message);
            "reload refused: see the log".to_string()
        }
    };
    systemd::reloaded(&status);
}

/// Runs `ferrobus gateway --reverse`.
async fn reverse(connection: &ConnectArgs, args: &GatewayArgs) -> Result<(), CliError> {
    let Target::Serial { path, line, ascii } = connection.target()? else {
        return Err(CliError::Usage("--reverse serves a serial line: give --port PATH".into()));
    };
    if args.metrics.given() {
        return Err(CliError::Usage("--metrics is the forward gateway's: not with --reverse".into()));
    }
    if args.routes.is_empty() {
        return Err(CliError::Usage(
            "--reverse needs the units it stands for: --route 5=10.0.0.7:502 (or 5=10.0.0.7:502/1 to ask the server \
             for unit 1)"
                .into(),
        ));
    }
    let mut upstreams = BTreeMap::new();
    let mut client = connection.client_config();
    client.backoff = None;
    for text in &args.routes {
        let (unit, addr, remote) = reverse_route(text)?;
        let client = Client::spawn(Transport::tcp(addr), client);
        upstreams.insert(unit, Upstream { client, unit: remote });
    }
    let transport = connection.transport(&Target::Serial { path, line, ascii });
    let mut interrupt = Interrupt::listen()?;
    let port = transport.open(std::time::Duration::from_secs(5)).await?;
    let units: Vec<String> = upstreams.keys().map(ToString::to_string).collect();
    eprintln!("gateway: reverse on {}, units {}", transport.describe(), units.join(", "));
    let on_failure = if args.on_failure == OnFailureArg::Exception { OnFailure::Exception } else { OnFailure::Silent };
    let until = async {
        match args.duration {
            Some(d) => tokio::time::sleep(d).await,
            None => std::future::pending().await,
        }
    };
    tokio::select! {
        served = serve_reverse(&transport, port, &upstreams, on_failure) => {
            served.map_err(|e| CliError::from(ferrobus::Error::io(format!("serving {}", transport.describe()), e)))
        }
        () = interrupt.wait() => Ok(()),
        () = until => Ok(()),
    }
}

/// `5=10.0.0.7:502` or `5=10.0.0.7:502/1`: the serial unit, the server, the unit asked there.
fn reverse_route(text: &str) -> Result<(u8, String, u8), CliError> {
    let bad = |why: &str| CliError::Usage(format!("--route '{text}': {why}; with --reverse: 5=10.0.0.7:502[/UNIT]"));
    let (unit, target) = text.split_once('=').ok_or_else(|| bad("no '='"))?;
    let unit = parse_u8(unit).map_err(|e| bad(&e))?;
    if unit == 0 || unit > 247 {
        return Err(bad("a serial unit is 1-247"));
    }
    let (addr, remote) = match target.rsplit_once('/') {
        Some((addr, remote)) => (addr, parse_u8(remote).map_err(|e| bad(&e))?),
        None => (target, unit),
    };
    if !addr.contains(':') {
        return Err(bad(&format!("'{addr}' needs HOST:PORT")));
    }
    Ok((unit, addr.to_string(), remote))
}

/// Prints every line's and unit's counters and the TCP side's on stderr, and with a lines
/// file what SIGHUP did.
fn print(gateway: &Gateway, tcp: &TcpCounts, secure: bool, reloads: Option<&Reloads>) {
    eprint!("{}", ferrobus_tools::gateway::report(&gateway.stats(), &gateway.front_stats()));
    eprintln!(
        "tcp: {} connections served ({} open), {} refused over --max-per-source, {} accept pauses out of file descriptors; \
         closed: {} to make room over --max-connections ({} in their handshake, {} never answered, {} idle longest), {} idle, \
         {} unfinished frame, {} bad MBAP header",
        tcp.accepted,
        tcp.open,
        tcp.refused_source,
        tcp.descriptor_waits,
        tcp.evicted_handshakes.saturating_add(tcp.evicted_unanswered).saturating_add(tcp.evicted_idle),
        tcp.evicted_handshakes,
        tcp.evicted_unanswered,
        tcp.evicted_idle,
        tcp.closed_idle,
        tcp.closed_unfinished,
        tcp.closed_bad_header
    );
    if secure {
        eprintln!(
            "tls: {} handshakes refused, {} connections refused over --tls-max-handshakes-per-source, {} requests \
             denied by the roles (exception 01)",
            tcp.tls_refused, tcp.refused_handshakes, tcp.denied
        );
    }
    if let Some(reloads) = reloads {
        let done = reloads.checked.saturating_sub(reloads.refused);
        eprintln!("reload: {done} done, {} refused", reloads.refused);
    }
}

/// The gateway's lines and routes from the options; with `--lines-file`, the file too, for
/// a reload to compare.
fn config(connection: &ConnectArgs, args: &GatewayArgs) -> Result<(GatewayConfig, Option<LinesFile>), CliError> {
    if let Some(path) = &args.lines_file {
        return lines_file(path, connection, args).map(|(config, file)| (config, Some(file)));
    }
    Ok((options_config(connection, args)?, None))
}

/// The gateway's lines and routes from `--port` (or `--tcp`, `--rtu-tcp`), `--line` and
/// `--route`.
fn options_config(connection: &ConnectArgs, args: &GatewayArgs) -> Result<GatewayConfig, CliError> {
    let first = match connection.target()? {
        Target::Serial { path, .. } => path,
        Target::Mbaps(addr) => {
            return Err(CliError::Usage(format!(
                "a gateway line is a serial port, a Modbus/TCP server (--tcp) or RTU over TCP (--rtu-tcp), not \
                 Modbus/TCP Security ({addr})"
            )));
        }
        tcp @ (Target::Tcp(_) | Target::RtuTcp(_)) => {
            if !args.lines.is_empty() {
                return Err(CliError::Usage(
                    "--line adds serial lines beside --port; for several TCP lines use --lines-file".into(),
                ));
            }
            let mut client = connection.client_config();
            client.backoff = backoff(args);
            if matches!(tcp, Target::Tcp(_)) {
                client.in_flight = in_flight(args);
            } else {
                no_in_flight(args, "RTU over TCP (--rtu-tcp)")?;
            }
            let line = GatewayLine {
                queue: usize::try_from(args.queue).unwrap_or(usize::MAX),
                late_guard: args.late_guard,
                ..GatewayLine::new(connection.transport(&tcp), client)
            };
            // A Modbus/TCP device takes every unit id (0xFF the spec's for it, 0 no broadcast
            // there); RTU over TCP reaches a serial line, units 1-247.
            let routes = if args.routes.is_empty() && matches!(tcp, Target::Tcp(_)) {
                Routes::every_id_on(0)
            } else {
                routes(&args.routes, 1)?
            };
            return Ok(GatewayConfig {
                lines: vec![line],
                routes,
                broadcast_ack: args.broadcast_ack,
                cache_max_age: args.cache_max_age,
            });
        }
    };
    no_in_flight(args, "a serial line")?;
    let mut client = connection.client_config();
    client.backoff = backoff(args);
    let queue = usize::try_from(args.queue).unwrap_or(usize::MAX);
    let lines = std::iter::once(first)
        .chain(args.lines.iter().cloned())
        .map(|path| {
            let target = Target::Serial { path, line: connection.line(), ascii: connection.ascii };
            GatewayLine {
                queue,
                late_guard: args.late_guard,
                ..GatewayLine::new(connection.transport(&target), client)
            }
        })
        .collect::<Vec<_>>();
    let routes = routes(&args.routes, lines.len())?;
    Ok(GatewayConfig { lines, routes, broadcast_ack: args.broadcast_ack, cache_max_age: args.cache_max_age })
}

/// The gateway's lines and routes from `--lines-file`, the connection options the default of
/// every line, and the file as read; `--port` (or `--tcp`, `--rtu-tcp`) beside it would be a
/// line the file does not name, and is refused.
fn lines_file(
    path: &std::path::Path,
    connection: &ConnectArgs,
    args: &GatewayArgs,
) -> Result<(GatewayConfig, LinesFile), CliError> {
    let given = [("--port", &connection.port), ("--tcp", &connection.tcp), ("--rtu-tcp", &connection.rtu_tcp)];
    if let Some((option, Some(value))) = given.iter().find(|(_, v)| v.is_some()) {
        return Err(CliError::Usage(format!(
            "--lines-file names every line of the gateway: not with {option} {value} (given, or from the settings \
             file's [defaults] or --conn); put that port in a [[line]] of {}",
            path.display()
        )));
    }
    let base = lines::Base {
        backoff: backoff(args),
        queue: usize::try_from(args.queue).unwrap_or(usize::MAX),
        late_guard: args.late_guard,
        in_flight: in_flight(args),
    };
    let file = lines::read(path, connection, base)?;
    let (lines, routes) = (file.lines.clone(), file.routes.clone());
    for (index, line) in lines.iter().enumerate() {
        let units: Vec<String> =
            routes.iter().filter(|(_, r)| r.line == index).map(|(u, r)| format!("{u}->{}", r.unit)).collect();
        tracing::info!(
            "line {index}: {}, timeout {:?}, retries {}, t3.5 {:?}, queue {}, late guard {:?}, in flight {}, units {}",
            line.transport.describe(),
            line.client.timeout,
            line.client.retries,
            line.transport.timing().t3_5(),
            line.queue,
            line.late_guard,
            if line.transport.framing() == ferrobus::Framing::Mbap { line.client.in_flight } else { 1 },
            units.join(" ")
        );
    }
    let config = GatewayConfig { lines, routes, broadcast_ack: args.broadcast_ack, cache_max_age: args.cache_max_age };
    Ok((config, file))
}

/// `--in-flight`.
fn in_flight(args: &GatewayArgs) -> usize {
    usize::try_from(args.in_flight).unwrap_or(1)
}

/// Refuses `--in-flight` past 1 on a line that is `what`: only Modbus/TCP tells replies apart
/// by transaction id.
fn no_in_flight(args: &GatewayArgs, what: &str) -> Result<(), CliError> {
    if args.in_flight == 1 {
        return Ok(());
    }
    Err(CliError::Usage(format!(
        "--in-flight {}: only a Modbus/TCP line (--tcp) keeps several requests in flight, and this is {what}: RTU \
         frames carry no transaction id to tell their replies apart",
        args.in_flight
    )))
}

/// Each line's per-unit backoff from `--backoff-after`, `--backoff-skip`, `--backoff-max`.
fn backoff(args: &GatewayArgs) -> Option<ferrobus::Backoff> {
    (args.backoff_after > 0).then_some(ferrobus::Backoff {
        after: args.backoff_after,
        initial: args.backoff_skip,
        max: args.backoff_max,
    })
}

/// The routing table from `--route`s; none with one line: every unit to it.
fn routes(given: &[String], lines: usize) -> Result<Routes, CliError> {
    if given.is_empty() {
        if lines > 1 {
            return Err(CliError::Usage(format!(
                "with {lines} lines, say which units go where: --route 1-10=0 --route 11-20=1 (lines numbered from 0, \
                 --port first)"
            )));
        }
        return Ok(Routes::all_on(0));
    }
    let mut routes = Routes::new();
    for text in given {
        let bad = |why: &str| CliError::Usage(format!("--route '{text}': {why}; e.g. 5=0, 1-10=1, 20=0:3"));
        let (units, target) = text.split_once('=').ok_or_else(|| bad("no '='"))?;
        let (first, last) = unit_range(units).map_err(|e| bad(&e))?;
        if first == 0 {
            return Err(bad("unit 0 is the broadcast, sent to every serial line; route units 1-255 (a --tcp line \
                            alone takes every unit id, 0 among them)"));
        }
        let (line, renumbered) = match target.split_once(':') {
            Some((line, unit)) => (line, Some(parse_u8(unit).map_err(|e| bad(&e))?)),
            None => (target, None),
        };
        let line: usize = line.trim().parse().map_err(|_| bad(&format!("'{line}' is not a line number")))?;
        if line >= lines {
            return Err(bad(&format!("line {line} does not exist: there are {lines} (numbered from 0, --port first)")));
        }
        for unit in first..=last {
            let offset = unit - first;
            let out = match renumbered {
                Some(start) => start
                    .checked_add(offset)
                    .filter(|u| *u != 0)
                    .ok_or_else(|| bad("the renumbered range runs past unit 255"))?,
                None => unit,
            };
            routes.set(unit, Route { line, unit: out });
        }
    }
    Ok(routes)
}

/// `5` or `1-10`, by the one list grammar ([`ferrobus::text::list`]).
fn unit_range(text: &str) -> Result<(u8, u8), String> {
    let ranges = ferrobus::text::list(text, u64::from(u8::MAX)).map_err(|e| e.to_string())?;
    match ranges.as_slice() {
        [range] => Ok((narrow(*range.start()), narrow(*range.end()))),
        _ => Err(format!("'{}' is one unit or one range A-B", ferrobus::log::escape(text))),
    }
}

/// A number 0-255 by the one number grammar ([`ferrobus::text::number`]: decimal or 0x hex).
fn parse_u8(text: &str) -> Result<u8, String> {
    ferrobus::text::number(text, u64::from(u8::MAX)).map(narrow).map_err(|e| e.to_string())
}

/// A number the grammar has already held to 0-255.
fn narrow(n: u64) -> u8 {
    u8::try_from(n).unwrap_or(u8::MAX)
}

/// A list such as `1,2,10-20`, by the one list grammar.
fn list(option: &str, text: &str) -> Result<Vec<u8>, CliError> {
    let ranges = ferrobus::text::list(text, u64::from(u8::MAX))
        .map_err(|e| CliError::Usage(format!("{option} '{}': {e}", ferrobus::log::escape(text))))?;
    Ok(ranges.into_iter().flatten().map(narrow).collect())
}

/// The read-only mode and allowlists.
fn rules(args: &GatewayArgs) -> Result<Rules, CliError> {
    let mut rules = Rules::new().read_only(args.read_only);
    if let Some(units) = &args.allow_units {
        rules = rules.units(list("--allow-units", units)?);
    }
    if let Some(functions) = &args.allow_functions {
        rules = rules.functions(list("--allow-functions", functions)?);
    }
    Ok(rules)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn routes_take_units_ranges_and_renumbering_and_refuse_what_cannot_be() {
        let routes = routes(&["5=0".into(), "11-13=1:1".into(), "20=0:3".into()], 2).unwrap();
        assert_eq!(routes.get(5), Some(Route { line: 0, unit: 5 }));
        assert_eq!(routes.get(12), Some(Route { line: 1, unit: 2 }));
        assert_eq!(routes.get(20), Some(Route { line: 0, unit: 3 }));
        assert_eq!(routes.get(6), None);
        for bad in ["5", "5=2", "0=0", "9-3=0", "250-255=0:251", "x=0", "5=0:256"] {
            let err = super::routes(&[bad.into()], 2).unwrap_err();
            assert!(matches!(&err, CliError::Usage(m) if m.contains(bad)), "{bad}: {err:?}");
        }
    }

    #[test]
    fn one_line_without_routes_takes_units_1_to_247_and_several_lines_need_routes() {
        let all = routes(&[], 1).unwrap();
        assert_eq!(all.get(1), Some(Route { line: 0, unit: 1 }));
        assert_eq!(all.get(247), Some(Route { line: 0, unit: 247 }));
        assert_eq!(all.get(248), None);
        assert!(routes(&[], 2).is_err());
    }

    #[test]
    fn reverse_routes_take_a_server_and_an_optional_unit_there() {
        assert_eq!(reverse_route("5=10.0.0.7:502").unwrap(), (5, "10.0.0.7:502".into(), 5));
        assert_eq!(reverse_route("5=10.0.0.7:502/1").unwrap(), (5, "10.0.0.7:502".into(), 1));
        for bad in ["5", "0=h:1", "5=host", "5=h:1/x", "300=h:1"] {
            assert!(reverse_route(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn lists_take_numbers_hex_and_ranges() {
        assert_eq!(list("--allow-functions", "3,0x10,1-2").unwrap(), [3, 16, 1, 2]);
        assert!(list("--allow-units", "1,,2").is_err());
    }
}
